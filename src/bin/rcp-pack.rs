//! rcp-pack: RCP messages as JSON Lines -> link frames (bytes), or a file cut into image trunks.
#![forbid(unsafe_code)]

use std::io::BufRead;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::Parser;
use rovlink::io::{EXIT_BAD_INPUT, EXIT_OK, Input, Output};
use rovlink::wire::{Message, MessageRepr, frame, json, rov};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "rcp-pack";

/// Says something on stderr (never panics, even with stderr closed).
macro_rules! say {
    ($($arg:tt)*) => {
        rovlink::io::warn(TOOL, &format!($($arg)*))
    };
}

const EXAMPLES: &str = "\
Examples:
  rcp-pack messages.jsonl -o frames.bin      pack a file of messages
  rcp-pack --hex < messages.jsonl            one frame per line, in hex
  rcp-dump --format ndjson in.bin | rcp-pack > out.bin   round trip, byte for byte
  rcp-pack --image photo.debt --trunk 39 -o image.bin    cut a file into ROV trunks

Exit codes: 0 ok, 2 bad usage or a bad input line.";

/// Pack remote-control-protocol messages into link frames.
///
/// Reads JSON Lines, one message per line in the form of wire.md (the form `rcp-dump --format
/// ndjson` writes; extra fields such as "offset" are ignored), and writes one link frame per
/// line. A bad line stops the run with an error naming the line, the field, and what was
/// expected; nothing after it is written, and an output file is not created at all.
#[derive(Parser, Debug)]
#[command(version, after_help = EXAMPLES)]
struct Args {
    /// JSON Lines input; `-` or nothing reads standard input.
    input: Option<PathBuf>,

    /// Output file (written whole or not at all); `-` or nothing writes standard output.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,

    /// Skip bad lines, reporting each on stderr; the exit code is still 2 if any was bad.
    #[arg(long)]
    keep_going: bool,

    /// Write each frame as a line of lowercase hex instead of raw bytes.
    #[arg(long)]
    hex: bool,

    /// Cut this file (e.g. an encoded image) into ROV messages carrying image trunks, instead
    /// of reading JSON.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["input", "keep_going"])]
    image: Option<PathBuf>,

    /// Trunk size in bytes for --image (1..=242) [default: 39, the paper's 57-byte frame].
    #[arg(long, value_name = "BYTES", requires = "image",
          value_parser = clap::value_parser!(u16).range(1..=rov::MAX_TRUNK_BYTES as i64))]
    trunk: Option<u16>,

    /// Source address of the ROV for --image (1..=15) [default: 1].
    #[arg(long, requires = "image",
          value_parser = clap::value_parser!(u8).range(1..=15))]
    src: Option<u8>,

    /// Destination address for --image (0..=15) [default: 0].
    #[arg(long, requires = "image",
          value_parser = clap::value_parser!(u8).range(0..=15))]
    dst: Option<u8>,

    /// Image sequence number (ISN) for --image, 0 or 1 [default: 0].
    #[arg(long, requires = "image",
          value_parser = clap::value_parser!(u8).range(0..=1))]
    isn: Option<u8>,
}

/// Writes one frame in the chosen form.
fn put(out: &mut Output, bytes: &[u8], hex: bool) -> Result<()> {
    if hex {
        let mut line = json::encode_hex(bytes);
        line.push('\n');
        out.write_bytes(line.as_bytes())?;
    } else {
        out.write_bytes(bytes)?;
    }
    Ok(())
}

fn pack_lines(args: &Args, out: &mut Output) -> Result<u8> {
    let mut input = Input::open(args.input.as_deref())?;
    let name = input.name.clone();
    let reader = std::io::BufReader::new(input.reader());
    let (mut bad, mut frames) = (0usize, 0usize);
    let mut bytes = Vec::with_capacity(frame::MAX_FRAME_BYTES);
    for (index, line) in reader.split(b'\n').enumerate() {
        let number = index + 1;
        let line = line.with_context(|| format!("{name}: read failed"))?;
        let parsed = std::str::from_utf8(&line)
            .map_err(|e| anyhow::anyhow!("not UTF-8 at byte {}", e.valid_up_to()))
            .and_then(|text| {
                let text = text.trim();
                if text.is_empty() {
                    Ok(None)
                } else {
                    json::parse_line(text)
                        .map(Some)
                        .map_err(anyhow::Error::from)
                }
            });
        match parsed {
            Ok(None) => {}
            Ok(Some(repr)) => {
                bytes.clear();
                repr.emit_to_vec(&mut bytes)?;
                put(out, &bytes, args.hex)?;
                frames += 1;
            }
            Err(e) if args.keep_going => {
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

fn pack_image(args: &Args, path: &std::path::Path, out: &mut Output) -> Result<u8> {
    let mut input = Input::open(Some(path))?;
    let data = input.read_all()?;
    let trunk = usize::from(args.trunk.unwrap_or(39));
    if data.is_empty() {
        bail!("{}: empty file, nothing to cut into trunks", input.name);
    }
    let count = data.len().div_ceil(trunk);
    if count > 64 {
        let smallest = data.len().div_ceil(64);
        bail!(
            "{}: {} bytes need {count} trunks of {trunk} bytes, at most 64 fit (ITSN is 6 bits); \
             use --trunk {smallest} or more",
            input.name,
            data.len()
        );
    }
    let mut bytes = Vec::with_capacity(frame::MAX_FRAME_BYTES);
    for (itsn, piece) in data.chunks(trunk).enumerate() {
        let repr = MessageRepr {
            src: args.src.unwrap_or(1),
            dst: args.dst.unwrap_or(0),
            message: Message::Rov(rov::Repr {
                ft: itsn == 0,
                lt: itsn == count - 1,
                isn: args.isn == Some(1),
                ci: false,
                itsn: itsn as u8,
                status: rov::Status::Basic(rov::BasicStatus::default()),
                trunk: piece.to_vec(),
            }),
        };
        bytes.clear();
        repr.emit_to_vec(&mut bytes)?;
        put(out, &bytes, args.hex)?;
    }
    Ok(EXIT_OK)
}

fn run(args: &Args) -> Result<u8> {
    let mut out = Output::open(args.output.as_deref(), !args.hex)?;
    let code = match &args.image {
        Some(path) => pack_image(args, path, &mut out)?,
        None => pack_lines(args, &mut out)?,
    };
    out.finish()?;
    Ok(code)
}

fn main() -> ExitCode {
    let args: Args = rovlink::cli::parse(TOOL);
    if let Err(err) = rovlink::cli::only_with(
        args.image.is_some(),
        "--image FILE",
        &[
            ("--trunk", args.trunk.is_some()),
            ("--src", args.src.is_some()),
            ("--dst", args.dst.is_some()),
            ("--isn", args.isn.is_some()),
        ],
    ) {
        rovlink::io::warn(TOOL, &err.0);
        return ExitCode::from(rovlink::io::EXIT_BAD_INPUT);
    }
    rovlink::io::finish_main(TOOL, run(&args))
}
