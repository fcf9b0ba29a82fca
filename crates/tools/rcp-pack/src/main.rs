//! rcp-pack: RCP messages as JSON Lines -> link frames (bytes), or a file cut into image trunks.
#![forbid(unsafe_code)]

mod flags;

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use flags::Args;
use rovlink_base::io::StopReader;
use rovlink_base::io::{EXIT_BAD_INPUT, EXIT_OK, Output};
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_cli::say;
use rovlink_cli::{only_with, stop};
use rovlink_wire::pack::{self, Lines};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "rcp-pack";

fn pack_lines(args: &Args, out: &mut Output) -> Result<u8> {
    // Read on a thread of its own, so that a signal ends a run on a quiet pipe.
    stop::install()?;
    let name = rovlink_base::io::display_name(args.input.as_deref(), "<stdin>");
    if let Some(path) = args
        .input
        .as_deref()
        .filter(|p| !rovlink_base::io::is_std(Some(p)))
    {
        std::fs::metadata(path).map_err(|source| rovlink_base::io::IoError::Open {
            path: path.to_path_buf(),
            source,
        })?;
    }
    let input = StopReader::open(args.input.as_deref(), stop::flag());
    let (mut bad, mut frames) = (0usize, 0usize);
    for (number, parsed) in Lines::new(std::io::BufReader::new(input)) {
        match parsed {
            Err(_) if stop::requested() => break,
            Ok(repr) => {
                out.write_bytes(&pack::frame(&repr, args.hex)?)?;
                frames += 1;
            }
            Err(e) if args.keep_going && !e.is_fatal() => {
                say!("{name}:{number}: {e} (line skipped)");
                bad += 1;
            }
            Err(e) => bail!("{name}:{number}: {e}"),
        }
    }
    if bad > 0 {
        say!("{name}: {frames} frames packed, {bad} bad lines skipped");
        return Ok(EXIT_BAD_INPUT);
    }
    Ok(EXIT_OK)
}

fn pack_image(args: &Args, path: &Path, dest: &Dest) -> Result<u8> {
    let name = path.display().to_string();
    // Read up to a bound: a file longer than any image's trunks is refused, not held whole.
    let data = match rovlink_base::io::read_at_most(path, pack::MAX_IMAGE_BYTES as u64) {
        Err(e) if e.kind() == std::io::ErrorKind::InvalidData => {
            Err(pack::ImageError::TooLarge).with_context(|| name.clone())?
        }
        read => read.with_context(|| format!("{name}: cannot read"))?,
    };
    let trunk = args.trunk.unwrap_or(39) as usize;
    let (src, dst, isn) = (
        args.src.unwrap_or(1) as u8,
        args.dst.unwrap_or(0) as u8,
        args.isn == Some(1),
    );
    let messages =
        pack::image_messages(&data, trunk, src, dst, isn).with_context(|| name.clone())?;
    // Opened only now: a signal while a pipe is read leaves no temporary file behind.
    let mut out = dest.open()?;
    for repr in &messages {
        out.write_bytes(&pack::frame(repr, args.hex)?)?;
    }
    out.finish()?;
    Ok(EXIT_OK)
}

fn run(args: &Args) -> Result<u8> {
    only_with(
        args.image.is_some(),
        "--image FILE",
        &[
            ("--trunk", args.trunk.is_some()),
            ("--src", args.src.is_some()),
            ("--dst", args.dst.is_some()),
            ("--isn", args.isn.is_some()),
        ],
    )?;
    let mut outs = Outputs::new();
    outs.input(args.input.as_deref());
    outs.input(args.image.as_deref());
    let kind = if args.hex { Kind::Text } else { Kind::Binary };
    let dest = outs.claim("-o", args.output.as_deref().unwrap_or(Path::new("-")), kind)?;
    match &args.image {
        Some(path) => pack_image(args, path, &dest),
        None => {
            let mut out = dest.open()?;
            let code = pack_lines(args, &mut out)?;
            // Written whole or not at all: a stopped run leaves no file.
            if let Some(note) = stop::note() {
                say!("{note}: nothing written");
                return Ok(stop::code_or(code));
            }
            out.finish()?;
            Ok(code)
        }
    }
}

fn main() -> ExitCode {
    let args: Args = rovlink_cli::parse(TOOL);
    rovlink_cli::finish(TOOL, run(&args))
}
