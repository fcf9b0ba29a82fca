//! rcp-pack's command line.

use std::path::PathBuf;

use clap::Parser;
use rovlink_cli::value;
use rovlink_wire::rov;

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
pub struct Args {
    /// JSON Lines input; `-` or nothing reads standard input.
    pub input: Option<PathBuf>,

    /// Output file (written whole or not at all); `-` or nothing writes standard output.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,

    /// Skip bad lines, reporting each on stderr; the exit code is still 2 if any was bad.
    #[arg(long)]
    pub keep_going: bool,

    /// Write each frame as a line of lowercase hex instead of raw bytes.
    #[arg(long)]
    pub hex: bool,

    /// Cut this file (e.g. an encoded image) into ROV messages carrying image trunks, instead
    /// of reading JSON.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["input", "keep_going"])]
    pub image: Option<PathBuf>,

    /// Trunk size in bytes for --image (1 ..= 242) [default: 39, the paper's 57-byte frame].
    #[arg(long, value_name = "BYTES", value_parser = value::bytes(1, rov::MAX_TRUNK_BYTES as u64))]
    pub trunk: Option<u64>,

    /// Source address of the ROV for --image (1 ..= 15) [default: 1].
    #[arg(long, value_parser = value::count(1, 15))]
    pub src: Option<u64>,

    /// Destination address for --image (0 ..= 15) [default: 0].
    #[arg(long, value_parser = value::count(0, 15))]
    pub dst: Option<u64>,

    /// Image sequence number (ISN) for --image, 0 or 1 [default: 0].
    #[arg(long, value_parser = value::count(0, 1))]
    pub isn: Option<u64>,
}
