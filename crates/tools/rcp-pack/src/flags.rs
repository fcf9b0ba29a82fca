//! rcp-pack's command line.

use std::path::PathBuf;

use clap::Parser;
use clap::builder::{PossibleValuesParser, TypedValueParser};
use rovlink_cli::value;
use rovlink_wire::rov;

const EXAMPLES: &str = "\
Examples:
  rcp-pack messages.jsonl -o frames.bin      pack a file of messages
  rcp-pack --hex < messages.jsonl            one frame per line, in hex
  rcp-dump --format ndjson in.bin | rcp-pack > out.bin   round trip, byte for byte
  rcp-pack --image photo.debt --trunk 39 -o image.bin    cut a file into ROV trunks

Secured frames (docs/wire-extensions.md; the key file as tdma-run --key-file reads it):
  rcp-pack --new-key rov.key                 a new AES-128 key file, mode 0600
  rcp-pack --key-file rov.key messages.jsonl -o sealed.bin            tagged, counters from 1
  rcp-pack --key-file rov.key --encrypt --counter 16385 --hex < messages.jsonl
  rcp-dump --key-file rov.key -f ndjson sealed.bin | rcp-pack --key-file rov.key > again.bin
      (a dump's \"ctr\" fields seal each frame with the counter it had; add --encrypt for an
      encrypted stream)

A line's optional \"ctr\" field (1 ..= 2^48-1) seals that frame with that counter; its (SRC, DST)
goes on from there. A counter at or below one already sealed for the pair is said on stderr: a
receiver refuses that frame as a replay.

Exit codes: 0 ok, 2 bad usage, a bad input line or key file, or a frame with no key.";

/// Pack remote-control-protocol messages into link frames.
///
/// Reads JSON Lines, one message per line in the form of wire.md (the form `rcp-dump --format
/// ndjson` writes; the fields it adds, such as "offset", are read and ignored), and writes one
/// link frame per line. A bad line stops the run with an error naming the line, the field, and
/// what was expected; nothing after it is written, and an output file is not created at all. A
/// field the message does not have (a misspelling such as "wyh") is a bad line, not ignored.
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

    /// Write a new key file here (one random key for every vehicle, `* KEY`, mode 0600) and
    /// exit; an existing file is never replaced. Example: `--new-key rov.key`.
    #[arg(
        long,
        value_name = "FILE",
        conflicts_with_all = ["input", "output", "image", "key_file", "keep_going", "hex"]
    )]
    pub new_key: Option<PathBuf>,

    /// Size of the --new-key key: 128 or 256 bits [default: 128]. Example: `--key-bits 256`.
    #[arg(long, value_name = "BITS",
          value_parser = PossibleValuesParser::new(["128", "256"])
              .map(|bits| if bits == "256" { 256usize } else { 128 }))]
    pub key_bits: Option<usize>,

    /// Seal every frame with the keys in FILE (lines `ADDRESS KEY`, the file yours and
    /// private: chmod 600): a 4-byte tag and the counter's low bits, 6 bytes a frame. Example:
    /// `--key-file rov.key`.
    #[arg(long, value_name = "FILE")]
    pub key_file: Option<PathBuf>,

    /// With --key-file: also encrypt every message (AES-CTR). Example: `--key-file rov.key
    /// --encrypt`.
    #[arg(long)]
    pub encrypt: bool,

    /// With --key-file: the first counter of every (SRC, DST), 1 ..= 2^48-1; each frame takes
    /// the next [default: 1]. Example: `--counter 16385`.
    #[arg(long, value_name = "N", value_parser = value::count(1, rovlink_wire::json::MAX_COUNTER))]
    pub counter: Option<u64>,
}
