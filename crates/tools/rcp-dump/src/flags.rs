//! rcp-dump's command line.

use std::path::PathBuf;

use clap::{Parser, ValueEnum};
use rovlink_cli::value;

const EXAMPLES: &str = "\
Examples:
  rcp-dump frames.bin                          one line per frame, for people
  rcp-dump --format ndjson frames.bin | rcp-pack > same.bin   JSON Lines, packs back byte for byte
  rcp-dump --format csv -o frames.csv frames.bin              a table for analysis
  rcp-dump --port /dev/ttyUSB0 --baud 9600     watch a modem's serial line until Ctrl-C
  rcp-dump --port tcp:192.168.0.209:9200       a modem's TCP console
  rcp-dump --port udp:127.0.0.1:5000=127.0.0.1:5001   datagrams from 127.0.0.1:5001 only
  link-sim ... | rcp-dump -                    read a pipe
  rcp-dump --key-file rov.key sealed.bin       verify and open secured frames
  rcp-dump --key-file rov.key -f csv -o frames.csv --port tcp:192.168.0.209:9200

Secured frames (docs/wire-extensions.md): without --key-file a secured frame is printed as a
raw payload marked `secured, ctr low bits N: unverified`. With --key-file every frame gets
`secured`, `encrypted`, `ctr` (the full counter, when verified) or `ctr_low`, and `verdict`: ok,
or why a receiving node would refuse it: bad_tag (forged, damaged or another key), replay
(authentic, but at or below the highest counter accepted from that SRC to that DST earlier in the
stream; a copy more than 2^14 counters older reads as bad_tag), no_key, malformed, unsecured (a
plain frame). A refused frame is still printed, as its raw payload; an
ok frame as the message inside, decrypted. CSV adds these columns only with --key-file (without
it the note is in the error column).

Corrupted frames (CRC failures, truncated frames, skipped bytes) are reported on stderr with
their stream offset; a summary ends every run. They are data, not errors: the exit code is 0
unless --strict asks for a clean stream.

Exit codes: 0 ok (also Ctrl-C on --port), 1 --strict and the stream was not clean, or
--key-file and a frame failed verification (any verdict but ok), or the port closed, 2 bad usage,
unreadable input or a refused key file.";

/// Output format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// One human-readable line per frame.
    Text,
    /// JSON Lines in wire.md's form, plus "offset" (and "t_s" on a port); rcp-pack reads it.
    Ndjson,
    /// CSV with a header row, every field a column.
    Csv,
}

/// Print the messages in a stream of link frames.
///
/// Finds every frame in a byte stream (garbage and corrupted frames in between are skipped and
/// reported) and prints the ROV or operator message each carries. A frame with a good CRC but a
/// payload that is not a valid message is printed as type "raw" with the reason.
#[derive(Parser, Debug)]
#[command(version, after_help = format!("{EXAMPLES}\n\n{}", rovlink_link::device::HELP))]
pub struct Args {
    /// Frame byte stream; `-` or nothing reads standard input.
    #[arg(conflicts_with = "port")]
    pub input: Option<PathBuf>,

    /// Read from a device until it closes (exit 1) or Ctrl-C (exit 0): a serial port or
    /// pseudo-terminal, `tcp:HOST:PORT`, `udp:BIND=PEER`, or any device of the grammar below.
    #[arg(long, value_name = "DEV", value_parser = value::device)]
    pub port: Option<String>,

    /// Baud rate of a serial --port (50 ..= 4000000) [default: 9600].
    #[arg(long, value_parser = value::baud())]
    pub baud: Option<u32>,

    /// On --port, give up on an incomplete frame after the line has been quiet this long
    /// (0: wait forever; at most 1 h) [default: 1000]. A false preamble in line noise can
    /// announce up to 260 bytes; this keeps it from holding back the frames behind it. Set it
    /// above the longest pause your modem makes inside one frame.
    #[arg(long, value_name = "MS", value_parser = value::millis(0.0, 3_600_000.0))]
    pub idle_ms: Option<f64>,

    /// Output format.
    #[arg(long, short = 'f', value_enum, default_value_t = Format::Text)]
    pub format: Format,

    /// Output file; `-` or nothing writes standard output. Text is written whole when the run
    /// ends, JSON Lines and CSV a whole line at a time.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,

    /// Also write the run's counters (frames, CRC failures, bytes skipped, ...) as JSON here
    /// (`-`: standard output): one line that also carries every parameter of the run
    /// (--metrics is the same flag, the name every tool's figures share).
    #[arg(long, value_name = "FILE", visible_alias = "metrics")]
    pub summary: Option<PathBuf>,

    /// Exit 1 unless every byte of the stream was part of a valid message.
    #[arg(long)]
    pub strict: bool,

    /// Do not report each corrupted frame on stderr (the summary is still printed).
    #[arg(short, long)]
    pub quiet: bool,

    /// Verify every frame with the keys in FILE (lines `ADDRESS KEY`, the file yours and
    /// private: chmod 600), open the encrypted ones, and give each its verdict (see below);
    /// exit 1 if any frame fails. Example: `--key-file rov.key`.
    #[arg(long, value_name = "FILE")]
    pub key_file: Option<PathBuf>,
}
