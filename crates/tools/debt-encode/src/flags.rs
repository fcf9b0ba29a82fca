//! debt-encode's command line.

use std::path::PathBuf;

use clap::Parser;
use rovlink_cli::value;
use rovlink_debt::{self as debt, EncodeOptions, Rect};

const EXAMPLES: &str = "\
Examples:
  debt-encode photo.png --bytes 1000 -o photo.debt      exactly 1000 bytes
  debt-encode photo.png --bytes 500 --roi 100,80,420,300 --roi-shift 4 -o roi.debt
  debt-encode --gray --scale 1 --bytes 250 < photo.png > tiny.debt
  debt-encode photo.png --lossless --bytes 10000000 -o exact.debt   (shorter when complete)
  debt-encode --sweep 250,500,1000,2000,8000 --csv trials.csv a.png b.png   compression trials
  debt-encode photo.png --bytes 2000 --fec 15 --trunk-size 39 -o parity.debt   15 % parity trunks

Exit codes: 0 ok, 2 bad usage or an unreadable image; a --sweep stopped by SIGINT or SIGTERM
keeps its whole rows and exits 130 or 143.";

/// Most budgets one --sweep takes.
const MAX_SWEEP_BUDGETS: usize = 10_000;

/// The budgets of a --sweep, parsed from one comma list (an alias, so that clap takes the list
/// as one value).
pub type Budgets = Vec<u64>;

/// Encode an image with DEBT, the embedded wavelet codec for narrow links.
///
/// The stream is exactly --bytes long (shorter only if the image codes completely, as with
/// --lossless and a large budget), and every prefix of it decodes: cut it anywhere and the
/// decoder shows what those bytes can.
#[derive(Parser, Debug)]
#[command(version, after_help = EXAMPLES)]
#[command(group(clap::ArgGroup::new("trunked").args(["segments", "fec"]).multiple(true)))]
pub struct Args {
    /// Image file (PNG, JPEG, PNM, BMP, TIFF, GIF, WebP, TGA, QOI; at most 4096 pixels a
    /// side); `-` or nothing reads stdin. With --sweep, any number of images, a directory
    /// standing for the pictures in it.
    pub inputs: Vec<PathBuf>,

    /// Output file (written whole or not at all); `-` or nothing writes stdout.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,

    /// Size of the stream in bytes (a budget larger than the image needs gives the complete
    /// stream, shorter).
    #[arg(long, short = 'b', value_name = "N", required_unless_present = "sweep",
          value_parser = value::bytes(1, u64::MAX))]
    pub bytes: Option<u64>,

    /// Compression trials instead of one stream: encode and decode every input at each of
    /// these byte budgets and write one CSV row per image and budget (flushed as it goes):
    /// image,width,height,budget_bytes,bytes,psnr_rgb_db,psnr_y_db,ssim,ms_ssim,encode_ms,decode_ms.
    #[arg(long, value_name = "BYTES,...", conflicts_with_all = ["bytes", "output"],
          value_parser = value::count_list(value::bytes(1, u64::MAX), MAX_SWEEP_BUDGETS))]
    pub sweep: Option<Budgets>,

    /// Write the figures as one line of JSON that also carries every parameter of the run:
    /// with --sweep the number of trials and, per budget, the mean of every CSV column over
    /// the images; else the one stream's bytes, PSNR, SSIM and times (it is decoded to measure
    /// it). `-`: standard output (then give -o or --csv a file).
    #[arg(long, value_name = "FILE")]
    pub metrics: Option<PathBuf>,

    /// Where --sweep writes its CSV; `-` or nothing writes stdout.
    #[arg(long, value_name = "FILE", requires = "sweep")]
    pub csv: Option<PathBuf>,

    /// Region of interest in pixels, x0,y0,x1,y1 (x1 and y1 exclusive), coded first.
    #[arg(long, value_name = "X0,Y0,X1,Y1", value_parser = parse_rect)]
    pub roi: Option<Rect>,

    /// Bit-planes the region of interest is raised by (1 ..= 15).
    #[arg(long, default_value_t = 3, requires = "roi", value_parser = value::count(1, 15))]
    pub roi_shift: u64,

    /// Code luma only.
    #[arg(long)]
    pub gray: bool,

    /// Reversible transforms: with enough bytes the decoded image is exact.
    #[arg(long)]
    pub lossless: bool,

    /// Encode at 1/2^K of the size (0 ..= 3); the decoder scales back up.
    #[arg(long, value_name = "K", default_value_t = 0, value_parser = value::count(0, 3))]
    pub scale: u64,

    /// Wavelet levels (0 ..= 7); by default as many as keep the low band at least 2 pixels a
    /// side.
    #[arg(long, value_parser = value::count(0, 7))]
    pub levels: Option<u64>,

    /// Retired in favour of --fec, which beats it at 1, 5 and 10 % trunk loss
    /// (docs/debt-format.md). Split the stream into K independently decodable segments (2 ..=
    /// 16, stripes of rows) interleaved trunk by trunk: a lost trunk then blurs one stripe
    /// instead of ending the image.
    #[arg(long, value_name = "K", value_parser = value::count(2, debt::MAX_SEGMENTS as u64))]
    pub segments: Option<u64>,

    /// With --segments or --fec: the trunk size in bytes (16 ..= 255; with --segments at
    /// least the header: 8 + K, 3 more with --roi) the link cuts the stream into [default: 39,
    /// the paper's image trunk].
    #[arg(long, value_name = "T", requires = "trunked", value_parser = value::bytes(16, 255))]
    pub trunk_size: Option<u64>,

    /// Spend PERCENT (1 ..= 50) of the budget's trunks on Reed-Solomon parity trunks after the
    /// stream (version 5): `debt-decode --erase` (and tdma-run) gets back any lost trunks up to
    /// the parity's count, the header too; a prefix still decodes as it arrives. The stream is
    /// a whole number of trunks, at most the budget. Not with --lossless or --segments.
    #[arg(long, value_name = "PERCENT", conflicts_with_all = ["lossless", "segments"],
          value_parser = value::count(1, u64::from(debt::fec::MAX_PERCENT)))]
    pub fec: Option<u64>,

    /// End the stream with a restoration filter fitted on its own decode (version 5, 12 bytes
    /// a channel): a shorter prefix decodes unfiltered. From 2000 bytes (below, no filter);
    /// not with --lossless or --segments.
    #[arg(long, conflicts_with_all = ["lossless", "segments"])]
    pub restore: bool,

    /// Do not predict chroma from luma. By default a lossy colour stream of 4000 bytes or more
    /// (without --segments) carries one multiplier per chroma subband in its header (version 5,
    /// 7 to 50 bytes) and codes what the luma does not predict; with this flag and no other
    /// feature it is a version 1 stream, as older decoders read.
    #[arg(long)]
    pub no_cfl: bool,

    /// Start the coder's contexts at one half instead of the trained priors table
    /// (src/debt/priors.rs). By default a lossy stream without --segments starts from the
    /// table (version 5), which gains most in its first hundreds of bytes; with this flag and
    /// no other feature it is a version 1 stream.
    #[arg(long)]
    pub no_priors: bool,
}

fn parse_rect(text: &str) -> Result<Rect, String> {
    let [x0, y0, x1, y1] = value::rect(debt::MAX_SIDE as u64)
        .parse(text)?
        .map(|v| v as usize);
    Ok(Rect { x0, y0, x1, y1 })
}

impl Args {
    /// The encoder's settings for a budget.
    pub fn options(&self, bytes: u64) -> EncodeOptions {
        EncodeOptions {
            bytes: usize::try_from(bytes).unwrap_or(usize::MAX),
            levels: self.levels.map(|l| l as u32),
            gray: self.gray,
            lossless: self.lossless,
            scale: self.scale as u32,
            roi: self.roi,
            roi_shift: self.roi_shift as u32,
            segments: self.segments.map(|count| debt::Segments {
                count: count as usize,
                trunk_bytes: self.trunk_size.unwrap_or(39) as usize,
            }),
            restore: self.restore,
            chroma_from_luma: !self.no_cfl,
            fec: self.fec.map(|percent| debt::FecOptions {
                percent: percent as u32,
                trunk_bytes: self.trunk_size.unwrap_or(39) as usize,
            }),
            priors: !self.no_priors,
        }
    }
}
