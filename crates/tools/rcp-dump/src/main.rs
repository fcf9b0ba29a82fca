//! rcp-dump: link frames (bytes from a file, a pipe or a port) -> one message per line.
#![forbid(unsafe_code)]

mod flags;

use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result};
use flags::{Args, Format};
use rovlink_base::io::{CheckFailed, EXIT_OK, IoError, Output};
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_cli::metrics;
use rovlink_cli::rows::{RowFormat, RowWriter};
use rovlink_cli::say;
use rovlink_cli::{only_with, stop};
use rovlink_link::device::DeviceSpec;
use rovlink_link::gll::PortOptions;
use rovlink_security::KeyRing;
use rovlink_security::stream::Checker;
use rovlink_wire::print::{self, CSV_COLUMNS, CaptureEnd, Printer, Record};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "rcp-dump";

/// Where records go: whole text, or a row stream (JSON Lines, CSV; with the security columns
/// when true).
enum Sink {
    Text(Output),
    Rows(RowWriter, Format, bool),
}

impl print::Sink for Sink {
    type Error = IoError;

    fn record(&mut self, record: &Record) -> Result<(), IoError> {
        match self {
            Sink::Text(out) => out.write_bytes(record.text_line().as_bytes()),
            Sink::Rows(rows, Format::Csv, false) => rows.row(&record.csv_fields()),
            Sink::Rows(rows, Format::Csv, true) => rows.row(&record.csv_fields_secured()),
            Sink::Rows(rows, ..) => rows.row(&record.object()),
        }
    }

    fn notice(&mut self, text: &str) {
        say!("{text}");
    }

    fn flush(&mut self) -> Result<(), IoError> {
        match self {
            Sink::Text(out) => out.flush_named(),
            Sink::Rows(..) => Ok(()),
        }
    }
}

impl Sink {
    fn open(format: Format, dest: Dest, secured: bool) -> Result<Sink, IoError> {
        Ok(match format {
            Format::Text => Sink::Text(dest.open()?),
            Format::Ndjson => {
                Sink::Rows(RowWriter::new(dest, RowFormat::Ndjson, &[]), format, false)
            }
            Format::Csv if secured => Sink::Rows(
                RowWriter::new(dest, RowFormat::Csv, &print::csv_columns_secured()),
                format,
                true,
            ),
            Format::Csv => Sink::Rows(
                RowWriter::new(dest, RowFormat::Csv, &CSV_COLUMNS),
                format,
                false,
            ),
        })
    }

    fn finish(self) -> Result<(), IoError> {
        match self {
            Sink::Text(out) => out.finish(),
            Sink::Rows(rows, ..) => rows.finish(),
        }
    }
}

/// Reads the input (a file, standard input or a port) through the printer: how a port ended.
fn pump(args: &Args, printer: &mut Printer, sink: &mut Sink) -> Result<Option<CaptureEnd>> {
    stop::install()?;
    let Some(dev) = &args.port else {
        print::read_stream(args.input.as_deref(), printer, sink, stop::flag())?;
        return Ok(None);
    };
    let options = PortOptions {
        baud: args.baud.unwrap_or(9600),
        ..PortOptions::default()
    };
    let mut port = options.open_bytes(dev, Duration::from_millis(100))?;
    if !args.quiet {
        // A baud rate is a serial line's only: not said for sockets.
        let at = match dev.parse() {
            Ok(DeviceSpec::Serial { baud, .. }) => format!(" at {baud} baud"),
            Ok(DeviceSpec::Path(_)) => format!(" at {} baud", options.baud),
            _ => String::new(),
        };
        say!("reading {dev}{at} until it closes or Ctrl-C");
    }
    let idle_ms = args.idle_ms.unwrap_or(1000.0);
    let idle = (idle_ms > 0.0).then(|| Duration::from_secs_f64(idle_ms / 1000.0));
    Ok(Some(print::capture(
        &mut port,
        printer,
        sink,
        stop::flag(),
        idle,
    )?))
}

fn run(args: &Args) -> Result<u8> {
    only_with(
        args.port.is_some(),
        "--port DEV",
        &[
            ("--baud", args.baud.is_some()),
            ("--idle-ms", args.idle_ms.is_some()),
        ],
    )?;
    // The key file is read first: a refused one ends the run before anything is written.
    let ring = args
        .key_file
        .as_deref()
        .map(KeyRing::load)
        .transpose()
        .context("--key-file")?;
    let keyed = ring.is_some();
    // Every output is claimed before reading, so a bad path fails before a long capture.
    let mut outs = Outputs::new();
    outs.input(args.input.as_deref());
    let out = outs.claim(
        "-o",
        args.output.as_deref().unwrap_or(Path::new("-")),
        Kind::Text,
    )?;
    let summary = outs.claim_opt("--summary", args.summary.as_deref(), Kind::Text)?;
    let summary = summary.map(|d| d.open()).transpose()?;
    let mut sink = Sink::open(args.format, out, keyed)?;
    let name = match &args.port {
        Some(dev) => dev.clone(),
        None => rovlink_base::io::display_name(args.input.as_deref(), "<stdin>"),
    };
    let mut printer = Printer::new(&name, args.quiet, args.port.is_some())
        .with_inspector(Box::new(Checker::new(ring)));
    let pumped = pump(args, &mut printer, &mut sink);
    // A file or pipe stopped by a signal is an interrupted run (a port's normal end). The
    // summary is said even when the run ends early (a closed pipe, a read error), once
    // anything was read.
    let note = stop::note().filter(|_| args.port.is_none());
    if pumped.is_ok() || printer.summary().stats.bytes_in > 0 {
        let marked = note.as_ref().map(|n| format!(" ({n})")).unwrap_or_default();
        say!("{}{marked}", printer.summary_line());
    }
    let end = pumped?;
    sink.finish()?;
    if let Some(mut file) = summary {
        let mut json = serde_json::json!(printer.summary());
        if note.is_some() {
            json["interrupted"] = stop::signal_name().unwrap_or("a signal").into();
        }
        metrics::write(&mut file, TOOL, None, &json)?;
        file.finish()?;
    }
    if let Some(CaptureEnd::Closed(reason)) = end {
        return Err(CheckFailed(format!("{name}: port closed ({reason})")).into());
    }
    if note.is_some() {
        return Ok(stop::code_or(EXIT_OK));
    }
    let failed = printer.failed_verification();
    if keyed && failed > 0 {
        let text = format!("--key-file: {failed} frames of {name} failed verification");
        return Err(CheckFailed(text).into());
    }
    if args.strict && !printer.clean() {
        let text = format!("--strict: {name} is not a clean frame stream");
        return Err(CheckFailed(text).into());
    }
    Ok(EXIT_OK)
}

fn main() -> ExitCode {
    let args: Args = rovlink_cli::parse(TOOL);
    rovlink_cli::finish(TOOL, run(&args))
}
