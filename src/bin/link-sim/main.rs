//! link-sim: a statistical modem link between two ports, or on a pipe in virtual time.
#![forbid(unsafe_code)]

mod cli;

use std::process::ExitCode;
use std::time::Instant;

use anyhow::Result;
use rovlink::cli::output::Dest;
use rovlink::cli::stop;
use rovlink::gll::Dialect;
use rovlink::io::Output;
use rovlink::io::{EXIT_CHECK_FAILED, EXIT_OK};
use rovlink::link::Link;
use rovlink::link::dialect::EvoLogicsEmulator;
use rovlink::link::pipe::{self, FrameReader};
use rovlink::link::realtime::{Ended, Endpoints, PortSpec, RunInfo, priority_allowed};
use rovlink::link::stats::{Counters, Mode, RunFacts, TraceRow, real_time_lines};
use rovlink::say;

use cli::{Args, Claimed};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "link-sim";

fn main() -> ExitCode {
    let args: Args = rovlink::cli::parse(TOOL);
    rovlink::cli::finish(TOOL, run(&args))
}

fn run(args: &Args) -> Result<u8> {
    if let Some(model) = args.printed_model() {
        let json = model.resolve()?.to_json();
        let mut out = args.printed_model_dest()?.open()?;
        out.write_bytes(json.as_bytes())?;
        return Ok(out.finish().map(|()| EXIT_OK)?);
    }
    let specs = args.port_specs();
    let mode = specs.as_ref().map_or(Mode::Pipe, |_| Mode::RealTime);
    let claimed = args.claim(mode)?;
    let link = args.link()?;
    stop::install()?;
    match specs {
        None => run_pipe(args, link, claimed),
        Some(specs) => run_realtime(args, link, specs, claimed),
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
    let extra = format!("{:.3} s of wall time", wall.elapsed().as_secs_f64());
    finish(args, &link, &counters, out, Some(output), None, vec![extra])?;
    Ok(stop::code_or(EXIT_OK))
}

fn run_realtime(args: &Args, mut link: Link, specs: [PortSpec; 2], mut out: Claimed) -> Result<u8> {
    let priority = args.rt_priority
        && priority_allowed()
            .map_err(|why| say!("--rt-priority: not allowed ({why}); running without it"))
            .is_ok();
    let endpoints = Endpoints::open(specs, priority)?;
    let names = endpoints.names();
    if args.pty {
        let mut stdout = Dest::Stdout.open()?;
        stdout.write_bytes(format!("{}\n{}\n", names[0], names[1]).as_bytes())?;
        stdout.finish()?;
    }
    say!(
        "forwarding A ({}) <-> B ({}) through the model until a side closes or SIGINT/SIGTERM",
        names[0],
        names[1]
    );
    let (mut counters, mut trace_error) = (Counters::default(), None);
    let mut emulator = EvoLogicsEmulator::new();
    let dialect = (args.dialect == Dialect::Evologics).then_some(&mut emulator);
    let (ended, info) = endpoints.run(&mut link, args.framing(), dialect, stop::flag(), |report| {
        counters.record(report);
        if let Some(trace) = out.trace.as_mut().filter(|_| trace_error.is_none()) {
            trace_error = trace.row(&TraceRow::new(report, Mode::RealTime)).err();
        }
    });
    finish(
        args,
        &link,
        &counters,
        out,
        None,
        Some(&info),
        real_time_lines(&info),
    )?;
    if let Some(error) = trace_error {
        return Err(error.into());
    }
    match ended {
        Ended::Stopped => Ok(EXIT_OK),
        Ended::Closed { side, name, reason } => {
            say!("side {} ({name}) closed: {reason}", side.name());
            Ok(EXIT_CHECK_FAILED)
        }
    }
}

/// Ends a run: the trace's last word, the stats written, the pipe's output and the stats
/// committed (neither before both are complete), the summary on stderr.
fn finish(
    args: &Args,
    link: &Link,
    counters: &Counters,
    mut out: Claimed,
    output: Option<Output>,
    info: Option<&RunInfo>,
    extra: Vec<String>,
) -> Result<()> {
    if let Some(trace) = out.trace {
        trace.finish()?;
    }
    let note = stop::note();
    let facts = RunFacts {
        mode: info.map_or(Mode::Pipe, |_| Mode::RealTime),
        seed: args.seed,
        duration_s: link.now().as_secs_f64(),
        interrupted: note.as_deref(),
    };
    // The files first, so that a file that cannot be written is the one line said.
    if let Some(file) = out.stats.as_mut() {
        let json = counters.stats_json(&facts, link, info);
        file.write_bytes(format!("{json:#}\n").as_bytes())?;
        file.flush_named()?;
    }
    for file in [output, out.stats].into_iter().flatten() {
        file.finish()?;
    }
    let lines = counters.summary_lines(&facts, link);
    lines.iter().chain(&extra).for_each(|line| say!("{line}"));
    Ok(())
}
