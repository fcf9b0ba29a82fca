//! debt-decode: a DEBT stream (or any prefix of one) -> an image file.
#![forbid(unsafe_code)]

mod cli;

use std::io::Read;
use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use cli::Args;
use rovlink::cli::output::{Dest, Kind, Outputs};
use rovlink::debt::{self, picture::OutputFormat};
use rovlink::io::{EXIT_OK, Input};

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
    let mut lost = Vec::new();
    if let (Some(trunk), Some(erased)) = (args.trunk_size, &args.erase) {
        // The header travels in trunk 0: without it nothing decodes.
        if erased.contains(&0) {
            bail!(
                "{}: trunk 0 (the header) is erased: nothing to decode",
                input.name
            );
        }
        let trunk = trunk as usize;
        for &e in erased {
            let start = usize::try_from(e)
                .unwrap_or(usize::MAX)
                .saturating_mul(trunk);
            lost.push(start..start.saturating_add(trunk));
        }
    }
    let img = debt::decode_with_priors(&stream, &lost, args.priors)
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
    let args: Args = rovlink::cli::parse(TOOL);
    rovlink::cli::finish(TOOL, run(&args))
}
