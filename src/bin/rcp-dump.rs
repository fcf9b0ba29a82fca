//! rcp-dump: link frames (bytes from a file, a pipe or a serial port) -> one message per line.
#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::{Parser, ValueEnum};
use rovlink::io::{AtomicFile, CheckFailed, EXIT_OK, Input, IoError, Output};
use rovlink::wire::frame::Frame;
use rovlink::wire::{DeframeEvent, DeframeStats, Deframer, MessageRepr, json};
use serde_json::{Map, Value};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "rcp-dump";

/// Says something on stderr (never panics, even with stderr closed).
macro_rules! say {
    ($($arg:tt)*) => {
        rovlink::io::warn(TOOL, &format!($($arg)*))
    };
}

const EXAMPLES: &str = "\
Examples:
  rcp-dump frames.bin                          one line per frame, for people
  rcp-dump --format ndjson frames.bin | rcp-pack > same.bin   JSON Lines, packs back byte for byte
  rcp-dump --format csv -o frames.csv frames.bin              a table for analysis
  rcp-dump --port /dev/ttyUSB0 --baud 9600     watch a modem's serial line until Ctrl-C
  link-sim ... | rcp-dump -                    read a pipe

Corrupted frames (CRC failures, truncated frames, skipped bytes) are reported on stderr with
their stream offset; a summary ends every run. They are data, not errors: the exit code is 0
unless --strict asks for a clean stream.

Exit codes: 0 ok, 1 --strict and the stream was not clean, 2 bad usage or unreadable input.";

/// Output format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Format {
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
#[command(version, after_help = EXAMPLES)]
struct Args {
    /// Frame byte stream; `-` or nothing reads standard input.
    #[arg(conflicts_with = "port")]
    input: Option<PathBuf>,

    /// Read from a serial port (or pseudo-terminal) until it closes or Ctrl-C.
    #[arg(long, value_name = "DEV")]
    port: Option<String>,

    /// Baud rate of --port [default: 9600].
    #[arg(long, requires = "port", value_parser = clap::value_parser!(u32).range(1..))]
    baud: Option<u32>,

    /// On --port, give up on an incomplete frame after the line has been quiet this long
    /// (0: wait forever) [default: 1000]. A false preamble in line noise can announce up to 260 bytes; this
    /// keeps it from holding back the frames behind it. Set it above the longest pause your
    /// modem makes inside one frame.
    #[arg(long, value_name = "MS", requires = "port")]
    idle_ms: Option<u64>,

    /// Output format.
    #[arg(long, short = 'f', value_enum, default_value_t = Format::Text)]
    format: Format,

    /// Output file (written whole when the run ends); `-` or nothing writes standard output.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,

    /// Also write the run's counters (frames, CRC failures, bytes skipped, ...) as JSON here.
    #[arg(long, value_name = "FILE")]
    summary: Option<PathBuf>,

    /// Exit 1 unless every byte of the stream was part of a valid message.
    #[arg(long)]
    strict: bool,

    /// Do not report each corrupted frame on stderr (the summary is still printed).
    #[arg(short, long)]
    quiet: bool,
}

/// A CSV writer's error as an I/O error naming the output, so that a closed pipe is seen as
/// one (exit 0) and a full disk names the file.
fn csv_error(name: &str, err: csv::Error) -> anyhow::Error {
    match err.into_kind() {
        csv::ErrorKind::Io(source) => IoError::Write {
            name: name.to_string(),
            source,
        }
        .into(),
        other => anyhow::anyhow!("{name}: CSV error: {other:?}"),
    }
}

/// Where frames are printed.
enum Sink {
    Text(Output),
    Ndjson(Output),
    Csv(Box<csv::Writer<Output>>),
}

impl Sink {
    fn new(format: Format, out: Output) -> Result<Sink> {
        Ok(match format {
            Format::Text => Sink::Text(out),
            Format::Ndjson => Sink::Ndjson(out),
            Format::Csv => {
                let name = out.name();
                let mut w = csv::Writer::from_writer(out);
                w.write_record(json::CSV_COLUMNS)
                    .map_err(|e| csv_error(&name, e))?;
                Sink::Csv(Box::new(w))
            }
        })
    }

    fn record(
        &mut self,
        offset: u64,
        t_s: Option<f64>,
        repr: &MessageRepr,
        error: Option<&str>,
    ) -> Result<()> {
        match self {
            Sink::Text(out) => {
                let mut line = match t_s {
                    Some(t) => format!("{t:>10.3}s @{offset:<8} {repr}"),
                    None => format!("@{offset:<8} {repr}"),
                };
                if let Some(e) = error {
                    line.push_str(&format!("  [invalid: {e}]"));
                }
                line.push('\n');
                out.write_bytes(line.as_bytes())?;
            }
            Sink::Ndjson(_) | Sink::Csv(_) => {
                let mut map = Map::new();
                map.insert("offset".into(), offset.into());
                if let Some(t) = t_s {
                    map.insert("t_s".into(), Value::from((t * 1e6).round() / 1e6));
                }
                json::write_fields(repr, &mut map);
                if let Some(e) = error {
                    map.insert("error".into(), e.into());
                }
                match self {
                    Sink::Ndjson(out) => {
                        let mut line = Value::Object(map).to_string();
                        line.push('\n');
                        out.write_bytes(line.as_bytes())?;
                    }
                    Sink::Csv(w) => {
                        let record = json::csv_record(&map);
                        w.write_record(&record)
                            .map_err(|e| csv_error(&w.get_ref().name(), e))?
                    }
                    Sink::Text(_) => {}
                }
            }
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        match self {
            Sink::Text(out) | Sink::Ndjson(out) => out.flush_named()?,
            Sink::Csv(w) => {
                let name = w.get_ref().name();
                w.flush()
                    .map_err(|source| IoError::Write { name, source })?
            }
        }
        Ok(())
    }

    fn finish(self) -> Result<()> {
        let out = match self {
            Sink::Text(out) | Sink::Ndjson(out) => out,
            Sink::Csv(w) => {
                let name = w.get_ref().name();
                w.into_inner().map_err(|e| IoError::Write {
                    name,
                    source: e.into_error(),
                })?
            }
        };
        out.finish()?;
        Ok(())
    }
}

/// Counts and reports what the deframer yields.
struct Dumper {
    name: String,
    quiet: bool,
    invalid: u64,
    started: Instant,
    timestamps: bool,
}

impl Dumper {
    fn drain(&mut self, deframer: &mut Deframer, sink: &mut Sink) -> Result<()> {
        let t_s = self
            .timestamps
            .then(|| self.started.elapsed().as_secs_f64());
        while let Some(event) = deframer.next_event() {
            match event {
                DeframeEvent::Frame { offset, frame } => {
                    let (repr, error) =
                        MessageRepr::parse_lenient(&Frame::new_unchecked(frame.into_inner()));
                    let error = error.map(|e| e.to_string());
                    if let Some(e) = &error {
                        self.invalid += 1;
                        if !self.quiet {
                            say!(
                                "{}: offset {offset}: invalid message from {}: {e}",
                                self.name,
                                repr.src
                            );
                        }
                    }
                    sink.record(offset, t_s, &repr, error.as_deref())?;
                }
                DeframeEvent::BadCrc {
                    offset,
                    payload_len,
                    computed,
                    carried,
                } if !self.quiet => say!(
                    "{}: offset {offset}: CRC failure (LEN {payload_len}, computed 0x{computed:04x}, carried 0x{carried:04x}), resyncing",
                    self.name
                ),
                DeframeEvent::Skipped { offset, len } if !self.quiet => {
                    say!("{}: offset {offset}: skipped {len} bytes", self.name)
                }
                DeframeEvent::Truncated {
                    offset,
                    expected,
                    found,
                    at_end,
                } if !self.quiet => {
                    let when = if at_end {
                        "at end of stream"
                    } else {
                        "after the line went idle"
                    };
                    say!(
                        "{}: offset {offset}: incomplete frame given up {when} (needs {expected} bytes, {found} there)",
                        self.name
                    )
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn summary(&self, stats: &DeframeStats) -> String {
        format!(
            "{}: {} frames ok ({} invalid messages), {} CRC failures, {} truncated, {} of {} bytes skipped",
            self.name,
            stats.frames,
            self.invalid,
            stats.crc_failures,
            stats.truncated,
            stats.bytes_skipped,
            stats.bytes_in
        )
    }
}

/// Reads a serial port until it closes or Ctrl-C, feeding the deframer.
fn read_port(
    args: &Args,
    dev: &str,
    dumper: &mut Dumper,
    deframer: &mut Deframer,
    sink: &mut Sink,
) -> Result<()> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .context("cannot install the Ctrl-C handler")?;
    let baud = args.baud.unwrap_or(9600);
    let idle_ms = args.idle_ms.unwrap_or(1000);
    let mut port = serialport::new(dev, baud)
        .timeout(Duration::from_millis(100))
        .open()
        .with_context(|| format!("{dev}: cannot open serial port"))?;
    if !args.quiet {
        say!("reading {dev} at {} baud until it closes or Ctrl-C", baud);
    }
    let mut buf = [0u8; 4096];
    let mut last_rx = Instant::now();
    while !stop.load(Ordering::SeqCst) {
        match port.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                last_rx = Instant::now();
                deframer.push(&buf[..n]);
                dumper.drain(deframer, sink)?;
                sink.flush()?;
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted
                ) =>
            {
                let idle = Duration::from_millis(idle_ms);
                if idle_ms > 0 && deframer.pending_bytes() > 0 && last_rx.elapsed() >= idle {
                    deframer.abandon_incomplete();
                    dumper.drain(deframer, sink)?;
                    sink.flush()?;
                }
            }
            // A pseudo-terminal whose other side closed reports EIO; a USB adapter unplugged
            // reports an error too: both end the capture like end of file.
            Err(e) => {
                if !args.quiet {
                    say!("{dev}: port closed ({e})");
                }
                break;
            }
        }
    }
    Ok(())
}

/// The run's counters as JSON, for scripts.
#[derive(serde::Serialize)]
struct Summary<'a> {
    input: &'a str,
    #[serde(flatten)]
    stats: &'a DeframeStats,
    invalid_messages: u64,
}

/// Reads the whole input (file, stdin or port) through the deframer into the sink.
fn pump(args: &Args, dumper: &mut Dumper, deframer: &mut Deframer, sink: &mut Sink) -> Result<()> {
    match &args.port {
        Some(dev) => read_port(args, dev, dumper, deframer, sink)?,
        None => {
            let mut input = Input::open(args.input.as_deref())?;
            let mut buf = vec![0u8; 64 * 1024];
            loop {
                let n = input.read_chunk(&mut buf)?;
                if n == 0 {
                    break;
                }
                deframer.push(&buf[..n]);
                dumper.drain(deframer, sink)?;
            }
        }
    }
    deframer.finish();
    dumper.drain(deframer, sink)
}

fn run(args: &Args) -> Result<u8> {
    // Every output is opened before reading, so a bad path fails before a long capture.
    let summary_file = args
        .summary
        .as_deref()
        .map(AtomicFile::create)
        .transpose()?;
    let out = Output::open(args.output.as_deref(), false)?;
    let mut sink = Sink::new(args.format, out)?;
    let mut deframer = Deframer::new();
    let name = match &args.port {
        Some(dev) => dev.clone(),
        None => rovlink::io::display_name(args.input.as_deref(), "<stdin>"),
    };
    let mut dumper = Dumper {
        name,
        quiet: args.quiet,
        invalid: 0,
        started: Instant::now(),
        timestamps: args.port.is_some(),
    };
    let pumped = pump(args, &mut dumper, &mut deframer, &mut sink);
    // The summary is said even when the run ends early (a closed pipe, a read error), once
    // anything was read.
    let stats = deframer.stats();
    if pumped.is_ok() || stats.bytes_in > 0 {
        say!("{}", dumper.summary(&stats));
    }
    pumped?;
    sink.finish()?;
    if let Some(file) = summary_file {
        file.commit_json(&Summary {
            input: &dumper.name,
            stats: &stats,
            invalid_messages: dumper.invalid,
        })?;
    }
    let clean = stats.bytes_skipped == 0 && dumper.invalid == 0;
    if args.strict && !clean {
        return Err(CheckFailed(format!(
            "--strict: {} is not a clean frame stream",
            dumper.name
        ))
        .into());
    }
    Ok(EXIT_OK)
}

fn main() -> ExitCode {
    let args: Args = rovlink::cli::parse(TOOL);
    if let Err(err) = rovlink::cli::only_with(
        args.port.is_some(),
        "--port DEV",
        &[
            ("--baud", args.baud.is_some()),
            ("--idle-ms", args.idle_ms.is_some()),
        ],
    ) {
        rovlink::io::warn(TOOL, &err.0);
        return ExitCode::from(rovlink::io::EXIT_BAD_INPUT);
    }
    rovlink::io::finish_main(TOOL, run(&args))
}
