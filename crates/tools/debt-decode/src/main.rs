//! debt-decode: a DEBT stream (or any prefix of one) -> an image file.
#![forbid(unsafe_code)]

mod flags;

use std::io::Read;
use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use flags::Args;
use rovlink_base::io::{EXIT_OK, Input};
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_debt::{self as debt, picture::OutputFormat};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "debt-decode";

fn run(args: &Args) -> Result<u8> {
    let mut outs = Outputs::new();
    outs.input(args.input.as_deref());
    let dest = outs.claim(
        "-o",
        args.output.as_deref().unwrap_or(Path::new("-")),
        Kind::Binary,
    )?;
    let format = match &dest {
        Dest::File(path) => OutputFormat::for_path(path)?,
        Dest::Stdout => OutputFormat::Png,
    };
    let mut input = Input::open(args.input.as_deref())?;
    // Read up to a bound (and only the bytes asked for), so that an endless input is refused.
    let most = args
        .bytes
        .unwrap_or(u64::MAX)
        .min(debt::MAX_STREAM_BYTES + 1);
    let mut stream = Vec::new();
    (input.reader().take(most).read_to_end(&mut stream))
        .with_context(|| format!("{}: read failed", input.name))?;
    if stream.len() as u64 > debt::MAX_STREAM_BYTES {
        bail!(
            "{}: more than {} MiB: longer than any DEBT stream",
            input.name,
            debt::MAX_STREAM_BYTES >> 20
        );
    }
    let img = match (args.trunk_size, &args.erase) {
        (Some(trunk), Some(erased)) => {
            let lost: Vec<usize> = erased
                .iter()
                .map(|&e| usize::try_from(e).unwrap_or(usize::MAX))
                .collect();
            debt::decode_trunks(&stream, trunk as usize, &lost)
        }
        _ => debt::decode(&stream),
    }
    .map_err(|e| anyhow::anyhow!("{}: {e}", input.name))?;
    // Opened only now: a signal while a pipe is read leaves no temporary file behind.
    let mut out = dest.open()?;
    // A PNM's samples are written from the image itself, not copied after its header.
    let (head, samples) = debt::picture::encode_parts(&img, format)?;
    out.write_bytes(&head)?;
    out.write_bytes(&samples)?;
    out.finish()?;
    Ok(EXIT_OK)
}

fn main() -> ExitCode {
    let args: Args = rovlink_cli::parse(TOOL);
    rovlink_cli::finish(TOOL, run(&args))
}
