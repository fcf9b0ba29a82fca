//! debt-encode: an image file -> a DEBT stream of exactly the bytes asked.
#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::Parser;
use rovlink::debt::{self, EncodeOptions, Rect};
use rovlink::io::{EXIT_OK, Input, Output};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "debt-encode";

const EXAMPLES: &str = "\
Examples:
  debt-encode photo.png --bytes 1000 -o photo.debt      exactly 1000 bytes
  debt-encode photo.png --bytes 500 --roi 100,80,420,300 --roi-shift 4 -o roi.debt
  debt-encode --gray --scale 1 --bytes 250 < photo.png > tiny.debt
  debt-encode photo.png --lossless --bytes 10000000 -o exact.debt   (shorter when complete)

Exit codes: 0 ok, 2 bad usage or an unreadable image.";

/// Encode an image with DEBT, the embedded wavelet codec for narrow links.
///
/// The stream is exactly --bytes long (shorter only if the image codes completely, as with
/// --lossless and a large budget), and every prefix of it decodes: cut it anywhere and the
/// decoder shows what those bytes can.
#[derive(Parser, Debug)]
#[command(version, after_help = EXAMPLES)]
struct Args {
    /// Image file (PNG, JPEG, PNM, BMP, TIFF, GIF, WebP, TGA, QOI); `-` or nothing reads stdin.
    input: Option<PathBuf>,

    /// Output file (written whole or not at all); `-` or nothing writes stdout.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,

    /// Size of the stream in bytes.
    #[arg(long, short = 'b', value_name = "N")]
    bytes: usize,

    /// Region of interest in pixels, x0,y0,x1,y1 (x1 and y1 exclusive), coded first.
    #[arg(long, value_name = "X0,Y0,X1,Y1", value_parser = parse_rect)]
    roi: Option<Rect>,

    /// Bit-planes the region of interest is raised by (1..=15).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=15))]
    roi_shift: u32,

    /// Code luma only.
    #[arg(long)]
    gray: bool,

    /// Reversible transforms: with enough bytes the decoded image is exact.
    #[arg(long)]
    lossless: bool,

    /// Encode at 1/2^K of the size (0..=3); the decoder scales back up.
    #[arg(long, value_name = "K", default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=3))]
    scale: u32,

    /// Wavelet levels (0..=7); by default as many as keep the low band at least 8 pixels.
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=7))]
    levels: Option<u32>,
}

fn parse_rect(text: &str) -> Result<Rect, String> {
    let parts: Vec<&str> = text.split(',').collect();
    let nums: Result<Vec<usize>, _> = parts.iter().map(|p| p.trim().parse::<usize>()).collect();
    match nums {
        Ok(n) if n.len() == 4 && n[0] < n[2] && n[1] < n[3] => Ok(Rect {
            x0: n[0],
            y0: n[1],
            x1: n[2],
            y1: n[3],
        }),
        _ => Err(format!(
            "expected x0,y0,x1,y1 with x0 < x1 and y0 < y1, found {text:?}"
        )),
    }
}

/// Reads any image the `image` crate knows into 8-bit grey or RGB.
fn read_image(input: Option<&std::path::Path>) -> Result<debt::Image> {
    let mut src = Input::open(input)?;
    let bytes = src.read_all()?;
    let decoded = image::load_from_memory(&bytes)
        .with_context(|| format!("{}: not a readable image", src.name))?;
    let (width, height) = (decoded.width() as usize, decoded.height() as usize);
    let img = if decoded.color().has_color() {
        debt::Image {
            width,
            height,
            channels: 3,
            data: decoded.into_rgb8().into_raw(),
        }
    } else {
        debt::Image {
            width,
            height,
            channels: 1,
            data: decoded.into_luma8().into_raw(),
        }
    };
    Ok(img)
}

fn run(args: &Args) -> Result<u8> {
    let img = read_image(args.input.as_deref())?;
    let name = rovlink::io::display_name(args.input.as_deref(), "<stdin>");
    if let Some(r) = args.roi
        && (r.x1 > img.width || r.y1 > img.height)
    {
        bail!(
            "--roi {},{},{},{} reaches outside the {}x{} image {name}",
            r.x0,
            r.y0,
            r.x1,
            r.y1,
            img.width,
            img.height
        );
    }
    let options = EncodeOptions {
        bytes: args.bytes,
        levels: args.levels,
        gray: args.gray,
        lossless: args.lossless,
        scale: args.scale,
        roi: args.roi,
        roi_shift: args.roi_shift,
    };
    let stream = debt::encode(&img, &options).with_context(|| name.clone())?;
    let mut out = Output::open(args.output.as_deref(), true)?;
    out.write_bytes(&stream)?;
    out.finish()?;
    Ok(EXIT_OK)
}

fn main() -> ExitCode {
    let args = Args::parse();
    rovlink::io::finish_main(TOOL, run(&args))
}
