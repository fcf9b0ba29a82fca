//! debt-decode: a DEBT stream (or any prefix of one) -> an image file.
#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::Parser;
use rovlink::debt;
use rovlink::io::{EXIT_OK, Input, Output};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "debt-decode";

const EXAMPLES: &str = "\
Examples:
  debt-decode photo.debt -o photo.png             decode to PNG
  debt-decode photo.debt --bytes 300 -o early.pgm what the first 300 bytes show
  debt-encode in.png -b 800 | debt-decode -o out.ppm
  debt-decode photo.debt --trunk-size 39 --erase 3,7 -o lossy.png   trunks 3 and 7 lost

Exit codes: 0 ok, 2 bad usage or a stream that is not DEBT.";

/// Decode a DEBT stream to an image.
///
/// Any prefix of a stream decodes; more bytes never give a worse image.
#[derive(Parser, Debug)]
#[command(version, after_help = EXAMPLES)]
struct Args {
    /// DEBT stream; `-` or nothing reads stdin.
    input: Option<PathBuf>,

    /// Output image, its format by extension: .png, .jpg/.jpeg, .ppm (RGB), .pgm (grey),
    /// .pnm (as decoded), .bmp, .tif/.tiff; `-` or nothing writes PNG to stdout.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,

    /// Decode only the first N bytes of the stream.
    #[arg(long, short = 'b', value_name = "N")]
    bytes: Option<usize>,

    /// Trunk size in bytes for --erase: the stream as the ROV cuts it into image trunks.
    #[arg(long, value_name = "T", requires = "erase", value_parser = clap::value_parser!(u64).range(1..))]
    trunk_size: Option<u64>,

    /// Decode as if these trunks (0-based ITSN) were lost in transit. A plain stream is one
    /// embedded segment: everything from the first lost trunk on is unusable, so this decodes
    /// the prefix before it. A segmented stream (debt-encode --segments) loses only the
    /// segments those trunks carried, from the lost trunk on.
    #[arg(
        long,
        value_name = "ITSN,...",
        value_delimiter = ',',
        requires = "trunk_size"
    )]
    erase: Vec<u64>,
}

fn run(args: &Args) -> Result<u8> {
    let format = match args.output.as_deref() {
        Some(path) if !rovlink::io::is_std(Some(path)) => {
            debt::picture::OutputFormat::for_path(path)?
        }
        _ => debt::picture::OutputFormat::Png,
    };
    let mut input = Input::open(args.input.as_deref())?;
    let mut stream = input.read_all()?;
    if let Some(n) = args.bytes {
        stream.truncate(n);
    }
    let mut lost = Vec::new();
    if let Some(trunk) = args.trunk_size {
        // The header travels in trunk 0: without it nothing decodes.
        if args.erase.contains(&0) {
            anyhow::bail!(
                "{}: trunk 0 (the header) is erased: nothing to decode",
                input.name
            );
        }
        for &e in &args.erase {
            let start = usize::try_from(e.saturating_mul(trunk)).unwrap_or(usize::MAX);
            let end = usize::try_from(trunk).map_or(usize::MAX, |t| start.saturating_add(t));
            lost.push(start..end);
        }
    }
    let img = debt::decode_with_loss(&stream, &lost).with_context(|| input.name.clone())?;
    let bytes = debt::picture::encode(&img, format)?;
    let mut out = Output::open(args.output.as_deref(), true)?;
    out.write_bytes(&bytes)?;
    out.finish()?;
    Ok(EXIT_OK)
}

fn main() -> ExitCode {
    let args = Args::parse();
    rovlink::io::finish_main(TOOL, run(&args))
}
