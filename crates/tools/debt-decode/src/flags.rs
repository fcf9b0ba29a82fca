//! debt-decode's command line.

use std::path::PathBuf;

use clap::Parser;
use rovlink_cli::value;

const EXAMPLES: &str = "\
Examples:
  debt-decode photo.debt -o photo.png             decode to PNG
  debt-decode photo.debt -o photo.jpg             or JPEG, PPM, PGM, BMP, TIFF by extension
  debt-decode photo.debt --bytes 300 -o early.pgm what the first 300 bytes show
  debt-encode in.png -b 800 | debt-decode -o out.ppm
  debt-decode photo.debt --trunk-size 39 --erase 3,7 -o lossy.png   trunks 3 and 7 lost
  debt-encode p.png -b 2000 --fec 15 | debt-decode --trunk-size 39 --erase 0,9 -o back.png

Exit codes: 0 ok, 2 bad usage or a stream that is not DEBT.";

/// Most trunks --erase takes.
const MAX_ERASED: usize = 100_000;

/// The trunks of --erase, parsed from one comma list (an alias, so that clap takes the list as
/// one value).
pub type Trunks = Vec<u64>;

/// Decode a DEBT stream to an image.
///
/// Any prefix of a stream decodes; more bytes never give a worse image.
#[derive(Parser, Debug)]
#[command(version, after_help = EXAMPLES)]
pub struct Args {
    /// DEBT stream; `-` or nothing reads stdin.
    pub input: Option<PathBuf>,

    /// Output image, its format by extension: .png, .jpg/.jpeg, .ppm (RGB), .pgm (grey),
    /// .pnm (as decoded), .bmp, .tif/.tiff; any other extension is refused. `-` or nothing
    /// writes PNG to stdout.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,

    /// Decode only the first N bytes of the stream.
    #[arg(long, short = 'b', value_name = "N", value_parser = value::bytes(1, u64::MAX))]
    pub bytes: Option<u64>,

    /// Trunk size in bytes for --erase (1 ..= 255): the stream as the ROV cuts it into image
    /// trunks.
    #[arg(long, value_name = "T", requires = "erase", value_parser = value::bytes(1, 255))]
    pub trunk_size: Option<u64>,

    /// Decode as if these trunks (0-based ITSN) were lost in transit: at most 100000 numbers,
    /// a repeated trunk counting once and one past the stream's end ignored. A stream with
    /// parity (debt-encode --fec) first recovers them, the header's too (a search of at most 50
    /// layouts, the header's trunks alone rebuilt in each), when a block lost no more trunks
    /// than it has parity. Otherwise a plain stream is one embedded segment: everything
    /// from the first lost trunk on is unusable, so this decodes the prefix before it. A
    /// segmented stream (debt-encode --segments) loses only the segments those trunks
    /// carried, from the lost trunk on. Without trunk 0 (the header) and parity that brings
    /// it back, nothing decodes.
    #[arg(long, value_name = "ITSN,...", requires = "trunk_size",
          value_parser = value::count_list(value::count(0, value::MAX_COUNT), MAX_ERASED))]
    pub erase: Option<Trunks>,
}
