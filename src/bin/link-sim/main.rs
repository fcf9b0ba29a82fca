//! link-sim: a statistical modem link between two ports, a shared medium among N
//! pseudo-terminals, or a link on a pipe in virtual time.
#![forbid(unsafe_code)]

mod cli;

use std::process::ExitCode;
use std::time::Instant;

use anyhow::Result;
use rovlink::cli::metrics;
use rovlink::cli::output::Dest;
use rovlink::cli::stop;
use rovlink::gll::Dialect;
use rovlink::io::Output;
use rovlink::io::{EXIT_CHECK_FAILED, EXIT_OK};
use rovlink::link::channel::DirectionStats;
use rovlink::link::dialect::EvoLogicsEmulator;
use rovlink::link::pipe::{self, FrameReader};
use rovlink::link::realtime::{
    Ended, Endpoints, PortEnded, PortSpec, Ports, PortsInfo, RunInfo, priority_allowed,
};
use rovlink::link::stats::{
    Counters, Mode, RunFacts, TraceRow, model_name, port_lines, real_time_lines,
};
use rovlink::link::{Link, Medium};
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
    if let Some(ports) = args.medium_ports() {
        let medium = args.medium(ports)?;
        stop::install()?;
        return run_medium(args, medium, claimed);
    }
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

/// Whether `--rt-priority` is given and allowed (said when it is not).
fn rt_priority(args: &Args) -> bool {
    args.rt_priority
        && priority_allowed()
            .map_err(|why| say!("--rt-priority: not allowed ({why}); running without it"))
            .is_ok()
}

fn run_realtime(args: &Args, mut link: Link, specs: [PortSpec; 2], mut out: Claimed) -> Result<u8> {
    let priority = rt_priority(args);
    let endpoints = Endpoints::open(specs, priority)?;
    let names = endpoints.names();
    if args.pty.is_some() {
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
        metrics::write(file, TOOL, Some(args.seed), &json)?;
    }
    for file in [output, out.stats].into_iter().flatten() {
        file.finish()?;
    }
    let lines = counters.summary_lines(&facts, link);
    lines.iter().chain(&extra).for_each(|line| say!("{line}"));
    Ok(())
}

/// `--pty N`: N pseudo-terminals on one shared medium until a port closes or a signal.
fn run_medium(args: &Args, mut medium: Medium, mut out: Claimed) -> Result<u8> {
    let ports = medium.nodes();
    let open = Ports::open(vec![PortSpec::Pty; ports], rt_priority(args))?;
    let mut stdout = Dest::Stdout.open()?;
    let paths: String = open
        .names()
        .iter()
        .map(|name| format!("{name}\n"))
        .collect();
    stdout.write_bytes(paths.as_bytes())?;
    stdout.finish()?;
    say!(
        "forwarding among {ports} ports on one medium ({}) until a port closes or SIGINT/SIGTERM",
        model_name(medium.model())
    );
    // Counters per (from, to) pair of ports, row-major.
    let mut pairs = vec![DirectionStats::default(); ports * ports];
    let (ended, info) = open.run(&mut medium, args.framing(), stop::flag(), |report| {
        if let Some(stats) = pairs.get_mut(report.from * ports + report.to) {
            stats.record_medium(report);
        }
    });
    let note = stop::note();
    let facts = RunFacts {
        mode: Mode::RealTime,
        seed: args.seed,
        duration_s: medium.now().as_secs_f64(),
        interrupted: note.as_deref(),
    };
    let pair_name = |k: usize| format!("{}->{}", k / ports + 1, k % ports + 1);
    let used = || (0..ports * ports).filter(|k| k / ports != k % ports);
    if let Some(file) = out.stats.as_mut() {
        let json = medium_stats_json(&facts, &medium, &info, &pairs, pair_name, used());
        metrics::write(file, TOOL, Some(args.seed), &json)?;
    }
    if let Some(file) = out.stats {
        file.finish()?;
    }
    say!(
        "real time: model {}, seed {}, {:.3} s of medium time, {ports} ports",
        model_name(medium.model()),
        facts.seed,
        facts.duration_s
    );
    for k in used().filter(|&k| pairs[k].frames_offered > 0) {
        say!("{}", pairs[k].summary_line(&pair_name(k)));
    }
    let labels: Vec<String> = (1..=ports).map(|p| p.to_string()).collect();
    let labels: Vec<&str> = labels.iter().map(String::as_str).collect();
    for line in port_lines(&info.lateness, &info.not_taken, &labels) {
        say!("{line}");
    }
    if let Some(note) = facts.interrupted {
        say!("{note}: the figures cover the run until then");
    }
    match ended {
        PortEnded::Stopped => Ok(EXIT_OK),
        PortEnded::Closed { port, name, reason } => {
            say!("port {} ({name}) closed: {reason}", port + 1);
            Ok(EXIT_CHECK_FAILED)
        }
    }
}

/// The `--stats` document of a shared medium: mode, seed, duration, the ports' positions,
/// each (from, to) pair's counters, frames in flight, the model and the ports' figures.
fn medium_stats_json(
    facts: &RunFacts<'_>,
    medium: &Medium,
    info: &PortsInfo,
    pairs: &[DirectionStats],
    pair_name: impl Fn(usize) -> String,
    used: impl Iterator<Item = usize>,
) -> serde_json::Value {
    let pairs: serde_json::Map<String, serde_json::Value> = used
        .filter_map(|k| Some((pair_name(k), pairs.get(k)?.to_json())))
        .collect();
    let positions: Vec<[f64; 3]> = (0..medium.nodes()).map(|n| medium.position_m(n)).collect();
    serde_json::json!({
        "mode": facts.mode.name(),
        "seed": facts.seed,
        "duration_s": facts.duration_s,
        "interrupted": facts.interrupted,
        "ports": medium.nodes(),
        "positions_m": positions,
        "pairs": pairs,
        "in_flight_at_end": medium.in_flight(),
        "model": medium.model(),
        "real_time": {
            "bytes_read": info.bytes_read,
            "bytes_skipped": info.bytes_skipped,
            "deliveries_not_taken": info.not_taken,
            "delivery_lateness_ms_p50": info.lateness_quantile_ms(0.5),
            "delivery_lateness_ms_p99": info.lateness_quantile_ms(0.99),
            "delivery_lateness_ms_max": info.lateness_quantile_ms(1.0),
        },
    })
}
