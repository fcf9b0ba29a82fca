//! debt-encode: an image file -> a DEBT stream of exactly the bytes asked.
#![forbid(unsafe_code)]

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Parser;
use rovlink::debt::{self, EncodeOptions, Rect, metrics};
use rovlink::io::{EXIT_OK, Output};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "debt-encode";

const EXAMPLES: &str = "\
Examples:
  debt-encode photo.png --bytes 1000 -o photo.debt      exactly 1000 bytes
  debt-encode photo.png --bytes 500 --roi 100,80,420,300 --roi-shift 4 -o roi.debt
  debt-encode --gray --scale 1 --bytes 250 < photo.png > tiny.debt
  debt-encode photo.png --lossless --bytes 10000000 -o exact.debt   (shorter when complete)
  debt-encode --sweep 250,500,1000,2000,8000 --csv trials.csv a.png b.png   compression trials
  debt-encode photo.png --bytes 2000 --segments 4 --trunk-size 39 -o robust.debt   loss-resilient

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
    /// With --sweep, any number of images.
    inputs: Vec<PathBuf>,

    /// Output file (written whole or not at all); `-` or nothing writes stdout.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,

    /// Size of the stream in bytes.
    #[arg(long, short = 'b', value_name = "N", required_unless_present = "sweep")]
    bytes: Option<usize>,

    /// Compression trials instead of one stream: encode and decode every input at each of
    /// these byte budgets and write one CSV row per image and budget (flushed as it goes).
    #[arg(long, value_name = "BYTES,...", value_delimiter = ',', conflicts_with_all = ["bytes", "output"])]
    sweep: Vec<usize>,

    /// Where --sweep writes its CSV; `-` or nothing writes stdout.
    #[arg(long, value_name = "FILE", requires = "sweep")]
    csv: Option<PathBuf>,

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

    /// Wavelet levels (0..=7); by default as many as keep the low band at least 2 pixels a
    /// side.
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=7))]
    levels: Option<u32>,

    /// Split the stream into K independently decodable segments (2..=16, stripes of rows)
    /// interleaved trunk by trunk: a lost trunk then blurs one stripe instead of ending the
    /// image. Costs some quality when nothing is lost (see docs/debt-format.md).
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(2..=16))]
    segments: Option<u64>,

    /// With --segments: the trunk size in bytes (16..=255) the link cuts the stream into
    /// [default: 39, the paper's image trunk].
    #[arg(long, value_name = "T", requires = "segments", value_parser = clap::value_parser!(u64).range(16..=255))]
    trunk_size: Option<u64>,
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
    Ok(match input {
        Some(path) if !rovlink::io::is_std(Some(path)) => debt::picture::open(path)?,
        _ => debt::picture::read("<stdin>", std::io::stdin().lock())?,
    })
}

impl Args {
    fn options(&self, bytes: usize) -> EncodeOptions {
        EncodeOptions {
            bytes,
            levels: self.levels,
            gray: self.gray,
            lossless: self.lossless,
            scale: self.scale,
            roi: self.roi,
            roi_shift: self.roi_shift,
            segments: self.segments.map(|count| debt::Segments {
                count: count as usize,
                trunk_bytes: self.trunk_size.unwrap_or(39) as usize,
            }),
        }
    }
}

/// Reads an image and checks the ROI against it.
fn load(args: &Args, input: Option<&Path>) -> Result<(debt::Image, String)> {
    let img = read_image(input)?;
    let name = rovlink::io::display_name(input, "<stdin>");
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
    Ok((img, name))
}

/// The columns of a --sweep CSV.
const SWEEP_COLUMNS: [&str; 10] = [
    "image",
    "width",
    "height",
    "budget_bytes",
    "bytes",
    "psnr_rgb_db",
    "psnr_y_db",
    "ssim",
    "encode_ms",
    "decode_ms",
];

fn sweep(args: &Args) -> Result<u8> {
    let target = args.csv.as_deref();
    let name = rovlink::io::display_name(target, "<stdout>");
    // Rows are flushed one by one, so a campaign cut short keeps what it measured.
    let sink: Box<dyn Write> = if rovlink::io::is_std(target) {
        Box::new(std::io::stdout())
    } else {
        let path = target.unwrap_or(Path::new("-"));
        Box::new(std::fs::File::create(path).with_context(|| format!("{name}: cannot create"))?)
    };
    let mut csv = csv::Writer::from_writer(sink);
    csv.write_record(SWEEP_COLUMNS)?;
    csv.flush()
        .with_context(|| format!("{name}: write failed"))?;
    let inputs: Vec<Option<&Path>> = if args.inputs.is_empty() {
        vec![None]
    } else {
        args.inputs.iter().map(|p| Some(p.as_path())).collect()
    };
    let progress = std::io::stderr().is_terminal();
    for (k, input) in inputs.iter().enumerate() {
        let (img, image_name) = load(args, *input)?;
        for &budget in &args.sweep {
            if progress {
                eprint!(
                    "\r{TOOL}: image {}/{} ({image_name}), {budget} bytes   ",
                    k + 1,
                    inputs.len()
                );
            }
            let started = Instant::now();
            let stream =
                debt::encode(&img, &args.options(budget)).with_context(|| image_name.clone())?;
            let encode_ms = started.elapsed().as_secs_f64() * 1e3;
            let started = Instant::now();
            let decoded = debt::decode(&stream)
                .with_context(|| format!("{image_name}: decoding its own stream"))?;
            let decode_ms = started.elapsed().as_secs_f64() * 1e3;
            let reference = if decoded.channels == 1 && img.channels == 3 {
                debt::picture::to_gray(&img)
            } else {
                img.clone()
            };
            csv.write_record([
                image_name.clone(),
                img.width.to_string(),
                img.height.to_string(),
                budget.to_string(),
                stream.len().to_string(),
                format!("{:.3}", metrics::psnr(&reference, &decoded)),
                format!("{:.3}", metrics::psnr_y(&reference, &decoded)),
                format!("{:.5}", metrics::ssim(&reference, &decoded)),
                format!("{encode_ms:.2}"),
                format!("{decode_ms:.2}"),
            ])?;
            csv.flush()
                .with_context(|| format!("{name}: write failed"))?;
        }
    }
    if progress {
        eprintln!();
    }
    Ok(EXIT_OK)
}

fn run(args: &Args) -> Result<u8> {
    if !args.sweep.is_empty() {
        return sweep(args);
    }
    if args.inputs.len() > 1 {
        bail!(
            "one input image at a time (several only with --sweep), found {}",
            args.inputs.len()
        );
    }
    let (img, name) = load(args, args.inputs.first().map(PathBuf::as_path))?;
    let bytes = args.bytes.unwrap_or_default();
    let stream = debt::encode(&img, &args.options(bytes)).with_context(|| name.clone())?;
    let mut out = Output::open(args.output.as_deref(), true)?;
    out.write_bytes(&stream)?;
    out.finish()?;
    Ok(EXIT_OK)
}

fn main() -> ExitCode {
    let args = Args::parse();
    rovlink::io::finish_main(TOOL, run(&args))
}
