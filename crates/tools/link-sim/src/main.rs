//! link-sim: a statistical modem link between two ports, a shared medium among N
//! pseudo-terminals, or a link on a pipe in virtual time.
#![forbid(unsafe_code)]

mod flags;

use std::process::ExitCode;
use std::time::Instant;

use anyhow::Result;
use rovlink_base::io::Output;
use rovlink_base::io::{EXIT_CHECK_FAILED, EXIT_OK};
use rovlink_base::output::Dest;
use rovlink_cli::metrics;
use rovlink_cli::say;
use rovlink_cli::stop;
use rovlink_link::device::DeviceSpec;
use rovlink_link::emulate::{self, Emulation};
use rovlink_link::pipe::{self, FrameReader};
use rovlink_link::stats::{Counters, Mode, Summary, TraceRow};
use rovlink_link::{Link, Medium};

use flags::{Args, Claimed};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "link-sim";

fn main() -> ExitCode {
    let args: Args = rovlink_cli::parse(TOOL);
    rovlink_cli::finish(TOOL, run(&args))
}

fn run(args: &Args) -> Result<u8> {
    if let Some(model) = args.printed_model() {
        let json = model.resolve()?.to_json();
        let mut out = args.printed_model_dest()?.open()?;
        out.write_bytes(json.as_bytes())?;
        return Ok(out.finish().map(|()| EXIT_OK)?);
    }
    let sides = args.sides();
    let mode = sides.as_ref().map_or(Mode::Pipe, |_| Mode::RealTime);
    let claimed = args.claim(mode)?;
    if let Some(ports) = args.medium_ports() {
        let medium = args.medium(ports)?;
        stop::install()?;
        return run_medium(args, medium, claimed);
    }
    let link = args.link()?;
    stop::install()?;
    match sides {
        None => run_pipe(args, link, claimed),
        Some(sides) => run_realtime(args, link, sides, claimed),
    }
}

fn run_pipe(args: &Args, mut link: Link, mut out: Claimed) -> Result<u8> {
    let mut frames = FrameReader::open(args.input.as_deref())?;
    let mut output = out.output.take().unwrap_or(Dest::Stdout).open()?;
    let (wall, stop, mut counters) = (Instant::now(), stop::flag(), Counters::default());
    pipe::run(
        &mut link,
        args.pace(),
        stop,
        |_| frames.next_frame(stop),
        |report| {
            counters.record(&report);
            if let Some(trace) = out.trace.as_mut() {
                trace.row(&TraceRow::new(&report, Mode::Pipe))?;
            }
            match report.fate.arrived() {
                true => output.write_bytes(&report.bytes),
                false => Ok(()),
            }
        },
    )?
    .within_horizon()?;
    // An input cut short by a signal is no verdict on its bytes.
    match frames.skipped_note() {
        Ok(Some(note)) => say!("{note}"),
        Err(error) if !stop::requested() => return Err(error.into()),
        _ => {}
    }
    let note = stop::note();
    let mut summary = counters.summary(&args.facts(Mode::Pipe, link.now(), &note), &link, None);
    let wall_s = wall.elapsed().as_secs_f64();
    summary.lines.push(format!("{wall_s:.3} s of wall time"));
    finish(args, out, Some(output), summary)?;
    Ok(stop::code_or(EXIT_OK))
}

/// Once the devices are open: their paths on standard output when the run created a
/// pseudo-terminal (its program must be told where it is), and what runs, on stderr.
fn announce(config: &Emulation) -> impl FnOnce(&[String], &str) -> Result<()> + '_ {
    move |names, what| {
        if config.creates_ptys() {
            let mut stdout = Dest::Stdout.open()?;
            let paths: String = names.iter().map(|name| format!("{name}\n")).collect();
            stdout.write_bytes(paths.as_bytes())?;
            stdout.finish()?;
        }
        say!("{what}");
        Ok(())
    }
}

fn run_realtime(
    args: &Args,
    mut link: Link,
    sides: Vec<DeviceSpec>,
    mut out: Claimed,
) -> Result<u8> {
    let config = args.emulation(sides);
    let mut trace_error = None;
    let run = emulate::run_link(
        &config,
        &mut link,
        stop::flag(),
        announce(&config),
        |report| {
            if let Some(trace) = out.trace.as_mut().filter(|_| trace_error.is_none()) {
                trace_error = trace.row(&TraceRow::new(report, Mode::RealTime)).err();
            }
        },
    )?;
    let note = stop::note();
    let summary = run.summary(&args.facts(Mode::RealTime, link.now(), &note), &link);
    finish(args, out, None, summary)?;
    if let Some(error) = trace_error {
        return Err(error.into());
    }
    Ok(closed(run.closed_line()))
}

/// `--pty N`: N pseudo-terminals on one shared medium until a port closes or a signal.
fn run_medium(args: &Args, mut medium: Medium, out: Claimed) -> Result<u8> {
    let config = args.emulation(vec![DeviceSpec::Pty; medium.nodes()]);
    let run = emulate::run_medium(&config, &mut medium, stop::flag(), announce(&config))?;
    let note = stop::note();
    let summary = run.summary(&args.facts(Mode::RealTime, medium.now(), &note), &medium);
    finish(args, out, None, summary)?;
    Ok(closed(run.closed_line()))
}

/// Ends a run: the trace's last word, the stats written, the pipe's output and the stats
/// committed (neither before both are complete), the summary on stderr.
fn finish(args: &Args, out: Claimed, output: Option<Output>, summary: Summary) -> Result<()> {
    if let Some(trace) = out.trace {
        trace.finish()?;
    }
    // The files first, so that a file that cannot be written is the one line said.
    let mut stats = out.stats;
    if let Some(file) = stats.as_mut() {
        metrics::write(file, TOOL, Some(args.seed), &summary.stats)?;
    }
    for file in [output, stats].into_iter().flatten() {
        file.finish()?;
    }
    summary.lines.iter().for_each(|line| say!("{line}"));
    Ok(())
}

/// The exit code of a real-time run: 0 when it was stopped, 1 (said why) when a port closed.
fn closed(line: Option<String>) -> u8 {
    match line {
        None => EXIT_OK,
        Some(line) => {
            say!("{line}");
            EXIT_CHECK_FAILED
        }
    }
}
