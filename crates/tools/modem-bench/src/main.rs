//! modem-bench: characterise a modem link, real or simulated, and turn the measurement into a model.
#![forbid(unsafe_code)]

mod flags;

use std::process::ExitCode;

use anyhow::{Result, bail};
use indicatif::ProgressBar;
use rovlink_base::io::{CheckFailed, EXIT_CHECK_FAILED, EXIT_OK, IoError, Output};
use rovlink_cli::metrics;
use rovlink_cli::rows::{RowFormat, RowWriter};
use rovlink_cli::say;
use rovlink_cli::{progress, stop};
use rovlink_link::measure::live::{self, Ports};
use rovlink_link::measure::{ROW_COLUMNS, Row, Tally, probe_total, sim};
use rovlink_link::{Distance, Link};

use flags::Args;

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "modem-bench";

fn main() -> ExitCode {
    let args: Args = rovlink_cli::parse(TOOL);
    rovlink_cli::finish(TOOL, run(&args))
}

fn run(args: &Args) -> Result<u8> {
    let total = probe_total(&args.sizes(), u32::try_from(args.count)?)?;
    let out = args.claim()?;
    let mut rows = RowWriter::new(out.rows, RowFormat::Csv, &ROW_COLUMNS);
    let mut tally = Tally::new();
    let template = "{spinner} {pos}/{len} packets [{bar:30}] {elapsed_precise} (eta {eta})";
    let bar = progress::bar(args.quiet, total, template);
    let mut on_row = |row: Row| -> Result<(), IoError> {
        rows.row(&row)?;
        tally.push(&row);
        Ok(())
    };
    stop::install()?;
    let (code, assumed_rate) = match args.real() {
        true => (
            run_real(args, &mut on_row, &bar)?,
            args.port_args.chunk_rate_bps,
        ),
        false => run_sim(args, &mut on_row, &bar)?,
    };
    bar.finish_and_clear();
    rows.finish()?;
    let mut summary = tally.summary();
    summary.interrupted = stop::note();
    // Files first, so that a file that cannot be written is the one line said; none is
    // committed before all are written.
    let mut summary_file = out.summary;
    if let Some(file) = summary_file.as_mut() {
        metrics::write(file, TOOL, (!args.real()).then_some(args.seed), &summary)?;
    }
    let mut fitted = (out.fit).map(|file| (summary.to_model(&out.fit_name, assumed_rate), file));
    if let Some((Some(model), file)) = fitted.as_mut() {
        write_text(file, model.to_json())?;
    }
    summary_file.map(Output::finish).transpose()?;
    // A fit without a model is not committed (its file is removed when dropped).
    let fitted = match fitted {
        Some((Some(model), file)) => {
            let name = file.name();
            file.finish()?;
            Some((Some(model), name))
        }
        other => other.map(|(model, file)| (model, file.name())),
    };
    if !args.quiet {
        summary.lines().iter().for_each(|line| say!("{line}"));
    }
    match fitted {
        Some((Some(model), name)) if !args.quiet => {
            say!("model written to {name}: {}", model.figures());
        }
        Some((None, _)) => {
            let (delivered, count) = (summary.delivered, summary.count);
            bail!(CheckFailed(format!(
                "--fit: no model from this measurement ({delivered} of {count} packets delivered)"
            )));
        }
        _ => {}
    }
    Ok(code)
}

/// Writes `text` to a whole-file output and flushes it (the caller commits it).
fn write_text(file: &mut Output, text: String) -> Result<()> {
    file.write_bytes(text.as_bytes())?;
    Ok(file.flush_named()?)
}

type OnRow<'a> = dyn FnMut(Row) -> Result<(), IoError> + 'a;

/// The simulated campaign; returns the exit code and the model's bit rate (for a one-size fit).
fn run_sim(args: &Args, on_row: &mut OnRow, bar: &ProgressBar) -> Result<(u8, f64)> {
    let model = args.sim_model().resolve()?;
    let rate = model.bitrate_bps;
    let mut link = Link::symmetric(model, args.seed, Distance::Fixed(args.distance))?;
    let progress = |done| bar.set_position(done);
    let plan = args.sim_plan();
    match sim::run::<anyhow::Error>(&mut link, &plan, stop::flag(), |r| Ok(on_row(r)?), progress)? {
        sim::Ended::Done => Ok((EXIT_OK, rate)),
        sim::Ended::Stopped { unresolved } => {
            say!("stopped: {unresolved} packets still in flight are not in the rows");
            Ok((stop::code_or(EXIT_OK), rate))
        }
    }
}

fn run_real(args: &Args, on_row: &mut OnRow, bar: &ProgressBar) -> Result<u8> {
    let plan = args.live_plan();
    let (mut tx_port, mut rx_port) = args.open_ports()?;
    let ports = match rx_port.as_mut() {
        Some(rx) => Ports::Pair {
            tx: tx_port.as_mut(),
            rx: rx.as_mut(),
        },
        None => Ports::Echo(tx_port.as_mut()),
    };
    if !args.quiet {
        say!("{}", plan.describe());
    }
    let progress = |done| bar.set_position(done);
    let (ended, extras) = live::run(ports, &plan, stop::flag(), on_row, progress)?;
    if let Some(note) = extras.note() {
        say!("{note}");
    }
    match ended {
        live::Ended::Done => Ok(EXIT_OK),
        live::Ended::Stopped { unresolved } => {
            say!("stopped: {unresolved} packets still on their way are not in the rows");
            Ok(EXIT_OK)
        }
        live::Ended::Failed { error, unresolved } => {
            say!("{error}; rows so far kept, {unresolved} packets on their way not recorded");
            Ok(EXIT_CHECK_FAILED)
        }
    }
}
