//! link-sim: a statistical modem link between two ports, or on a pipe in virtual time.
#![forbid(unsafe_code)]

use std::fs::File;
use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Parser;
use rovlink::cli::model::ModelArgs;
use rovlink::io::{AtomicFile, EXIT_CHECK_FAILED, EXIT_OK, IoError, Output};
use rovlink::link::pipe::{self, FrameReader, Pace};
use rovlink::link::realtime::{Ended, Endpoints, Framing, PortSpec};
use rovlink::link::stats::{Counters, Mode, RunFacts, TraceRow, real_time_lines};
use rovlink::link::{Distance, Link, Report};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "link-sim";

/// Says something on stderr (never panics, even with stderr closed).
macro_rules! say {
    ($($arg:tt)*) => {
        rovlink::io::warn(TOOL, &format!($($arg)*))
    };
}

const EXAMPLES: &str = "\
Examples:
  link-sim --model s100 < frames.bin > out.bin          frames through an S100 link in virtual time
  link-sim --model s100 --ber 7e-4 --trace t.csv --stats s.json < frames.bin > out.bin
  link-sim --print-model s2cr-burst > m.json            a preset as a file to edit
  link-sim --model-file m.json --interval 500 < frames.bin > out.bin
  link-sim --model s100 --pty                           two pseudo-terminals (paths on stdout, A then B)
  link-sim --model s100 --a /dev/ttyUSB0 --b /dev/ttyUSB1 --baud 9600
  link-sim --model satellite-up --reverse-model satellite-down --udp-a 127.0.0.1:9001 --udp-b 127.0.0.1:9002
  link-sim --model s100 --pty --raw --idle-ms 20 --distance-file dive.csv
  link-sim --model s2cr-burst --pty --dialect evologics  programs speak AT*SEND / RECV to it

Modes: with no port option, frames (wire.md) from INPUT or stdin go from side A to side B in
virtual time and the frames that arrive go to stdout, in arrival order. With --pty, --a/--b or
--udp-a/--udp-b, the link runs in real time between the two sides until a side closes (exit 1),
or SIGINT/SIGTERM (exit 0).

Trace (--trace): one row per frame, in the order fates are decided:
  seq,bytes,t_offered_s,t_tx_start_s,t_rx_s,fate      (real time adds a last column: side)
fate: delivered, corrupted, ber, collision, overflow, range, loss (a duplicated frame has a
second row with the same seq). t_tx_start_s is when the frame went on air; times are seconds
from the start. Every model field can be set in the file or as a flag.

Exit codes: 0 ok, 1 a side's port closed or failed, 2 bad usage or input.";

/// What the programs on the ports speak.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Dialect {
    /// Bare packets: wire.md frames (or --raw packets, or datagrams).
    Transparent,
    /// The EvoLogics AT command set.
    Evologics,
}

/// Simulate an underwater modem link (or a netem-like link) between two ports, or on a pipe.
///
/// The model (a preset or a JSON file, every field overridable by a flag) gives each frame its
/// air time, intrinsic delay and jitter, propagation, range, bit errors, collisions and losses.
/// The same seed gives the same bytes and the same trace.
#[derive(Parser, Debug)]
#[command(version, after_help = EXAMPLES)]
struct Args {
    /// Frame byte stream for the virtual-time pipe; `-` or nothing reads standard input.
    input: Option<PathBuf>,

    /// Output of the pipe: the frames that arrive; `-` or nothing writes standard output.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,

    /// Print the model (the preset NAME, or --model/--model-file with the flags applied) as JSON and exit.
    #[arg(long, value_name = "NAME", num_args = 0..=1, default_missing_value = "")]
    print_model: Option<String>,

    #[command(flatten)]
    model: ModelArgs,

    /// The model of frames from B to A, when it differs (a preset); the flags apply to it too.
    #[arg(
        long,
        value_name = "NAME",
        conflicts_with = "reverse_model_file",
        help_heading = "Link model"
    )]
    reverse_model: Option<String>,

    /// The model of frames from B to A, as a file.
    #[arg(long, value_name = "FILE", help_heading = "Link model")]
    reverse_model_file: Option<PathBuf>,

    /// Seed of every random stream.
    #[arg(long, default_value_t = 1)]
    seed: u64,

    /// Distance between the two sides, m.
    #[arg(
        long,
        value_name = "M",
        default_value_t = 1.0,
        conflicts_with = "distance_file"
    )]
    distance: f64,

    /// Distance over time: CSV with columns t_s,distance_m (linear between rows).
    #[arg(long, value_name = "FILE")]
    distance_file: Option<PathBuf>,

    /// Pipe: offer one frame every MS milliseconds instead of back to back.
    #[arg(long, value_name = "MS")]
    interval: Option<f64>,

    /// Write one CSV row per frame here (rows flushed as they go in real time).
    #[arg(long, value_name = "FILE")]
    trace: Option<PathBuf>,

    /// Write the counters of both directions as JSON here when the run ends.
    #[arg(long, value_name = "FILE")]
    stats: Option<PathBuf>,

    /// Real time: create a pseudo-terminal pair and print its two paths (A, then B).
    #[arg(long, help_heading = "Real time", conflicts_with_all = ["a", "udp_a"])]
    pty: bool,

    /// Real time: side A's serial port (or pseudo-terminal).
    #[arg(long, value_name = "DEV", requires = "b", help_heading = "Real time")]
    a: Option<String>,

    /// Real time: side B's serial port.
    #[arg(long, value_name = "DEV", requires = "a", help_heading = "Real time")]
    b: Option<String>,

    /// Baud rate of --a and --b.
    #[arg(long, default_value_t = 9600, value_parser = clap::value_parser!(u32).range(1..), help_heading = "Real time")]
    baud: u32,

    /// Real time: side A's UDP address (bound here; each datagram is a frame).
    #[arg(
        long,
        value_name = "ADDR:PORT",
        requires = "udp_b",
        conflicts_with = "a",
        help_heading = "Real time"
    )]
    udp_a: Option<SocketAddr>,

    /// Real time: side B's UDP address.
    #[arg(
        long,
        value_name = "ADDR:PORT",
        requires = "udp_a",
        help_heading = "Real time"
    )]
    udp_b: Option<SocketAddr>,

    /// Where side A's program listens [default: the source of its last datagram].
    #[arg(
        long,
        value_name = "ADDR:PORT",
        requires = "udp_a",
        help_heading = "Real time"
    )]
    udp_a_peer: Option<SocketAddr>,

    /// Where side B's program listens [default: the source of its last datagram].
    #[arg(
        long,
        value_name = "ADDR:PORT",
        requires = "udp_b",
        help_heading = "Real time"
    )]
    udp_b_peer: Option<SocketAddr>,

    /// Real time: run link-sim's threads under real-time (SCHED_FIFO) scheduling, when allowed
    /// (root or CAP_SYS_NICE), so other processes cannot delay deliveries. Measure before relying
    /// on it (scripts/pty-latency.py): on a virtual machine whose processor time is stolen by
    /// the host it does not help, and the kernel's own pseudo-terminal work can then wait.
    #[arg(long, help_heading = "Real time")]
    rt_priority: bool,

    /// Real time: what the programs on the ports speak: bare packets, or the EvoLogics AT
    /// dialect (AT*SEND / AT*SENDIM in, RECV / RECVIM / DELIVEREDIM / FAILEDIM out; side A is
    /// address 1, side B address 2).
    #[arg(long, value_enum, default_value_t = Dialect::Transparent, help_heading = "Real time")]
    dialect: Dialect,

    /// Real time: packets are bytes separated by silence (a modem's transparent mode), not
    /// wire.md frames.
    #[arg(long, requires = "idle_ms", help_heading = "Real time")]
    raw: bool,

    /// Silence that ends a packet with --raw; with frames, the silence after which an
    /// incomplete frame is given up [default with frames: 1000].
    #[arg(long, value_name = "MS", help_heading = "Real time")]
    idle_ms: Option<u64>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    rovlink::io::finish_main(TOOL, run(&args))
}

fn run(args: &Args) -> Result<u8> {
    if let Some(name) = &args.print_model {
        let mut model_args = args.model.clone();
        if !name.is_empty() {
            model_args.model = Some(name.clone());
            model_args.model_file = None;
        }
        let model = model_args.resolve()?;
        let mut out = std::io::stdout().lock();
        out.write_all(model.to_json().as_bytes())
            .map_err(|source| IoError::Write {
                name: "<stdout>".into(),
                source,
            })?;
        return Ok(EXIT_OK);
    }
    let forward = args.model.resolve()?;
    let reverse = match (&args.reverse_model, &args.reverse_model_file) {
        (None, None) => forward.clone(),
        (name, file) => {
            let reverse_args = ModelArgs {
                model: name.clone(),
                model_file: file.clone(),
                ..args.model.clone()
            };
            reverse_args.resolve()?
        }
    };
    if !(args.distance.is_finite() && args.distance >= 0.0) {
        bail!(usage(format!(
            "--distance: expected metres >= 0, found {}",
            args.distance
        )));
    }
    let distance = match &args.distance_file {
        Some(path) => Distance::from_csv_file(path)?,
        None => Distance::Fixed(args.distance),
    };
    let link = Link::new(forward, reverse, args.seed, distance)?;
    let specs = port_specs(args);
    match specs {
        None => {
            if args.raw {
                bail!(usage(
                    "--raw applies to real-time byte streams (--pty, --a/--b), not to the pipe"
                        .into()
                ));
            }
            run_pipe(args, link)
        }
        Some(specs) => {
            if args.interval.is_some() || args.output.is_some() || args.input.is_some() {
                bail!(usage(
                    "INPUT, --output and --interval apply to the pipe, not to real-time ports"
                        .into()
                ));
            }
            run_realtime(args, link, specs)
        }
    }
}

/// A usage error (exit 2) as an anyhow error.
fn usage(message: String) -> anyhow::Error {
    anyhow::Error::new(UsageError(message))
}

#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct UsageError(String);

fn port_specs(args: &Args) -> Option<[PortSpec; 2]> {
    if args.pty {
        return Some([PortSpec::Pty, PortSpec::Pty]);
    }
    if let (Some(a), Some(b)) = (&args.a, &args.b) {
        return Some([
            PortSpec::Serial {
                path: a.clone(),
                baud: args.baud,
            },
            PortSpec::Serial {
                path: b.clone(),
                baud: args.baud,
            },
        ]);
    }
    if let (Some(a), Some(b)) = (args.udp_a, args.udp_b) {
        return Some([
            PortSpec::Udp {
                bind: a,
                peer: args.udp_a_peer,
            },
            PortSpec::Udp {
                bind: b,
                peer: args.udp_b_peer,
            },
        ]);
    }
    None
}

fn say_lines(lines: Vec<String>) {
    lines.iter().for_each(|line| say!("{line}"));
}

fn run_pipe(args: &Args, mut link: Link) -> Result<u8> {
    let pace = match args.interval {
        None => Pace::BackToBack,
        Some(ms) if ms.is_finite() && ms > 0.0 => Pace::IntervalNs((ms * 1e6).round() as u64),
        Some(ms) => bail!(usage(format!(
            "--interval: expected milliseconds > 0, found {ms}"
        ))),
    };
    let input_name = rovlink::io::display_name(args.input.as_deref(), "<stdin>");
    let input: Box<dyn std::io::Read + Send> = match &args.input {
        Some(path) if !rovlink::io::is_std(Some(path)) => {
            Box::new(File::open(path).map_err(|source| IoError::Open {
                path: path.clone(),
                source,
            })?)
        }
        _ => Box::new(std::io::stdin()),
    };
    let mut output = Output::open(args.output.as_deref(), true)?;
    let mut trace = match &args.trace {
        Some(path) => {
            let mut file = AtomicFile::create(path)?;
            file.write_bytes(TRACE_HEADER.as_bytes())?;
            Some(file)
        }
        None => None,
    };
    // Created before anything is measured, so a path that cannot be written fails at once.
    let stats_file = args.stats.as_deref().map(AtomicFile::create).transpose()?;
    let wall = Instant::now();
    let mut counters = Counters::default();
    let mut frames = FrameReader::new(input);
    let stop = AtomicBool::new(false);
    let output_name = output.name();
    let ended = pipe::run(
        &mut link,
        pace,
        &stop,
        |_| -> Result<Option<Vec<u8>>> {
            frames.next_frame(&stop).map_err(|source| {
                anyhow::Error::new(IoError::Read {
                    name: input_name.clone(),
                    source,
                })
            })
        },
        |report: Report| -> Result<()> {
            counters.record(&report);
            if let Some(trace) = trace.as_mut() {
                trace.write_bytes(TraceRow::new(&report, Mode::Pipe).to_csv_line().as_bytes())?;
            }
            if report.fate.arrived() {
                output.write_bytes(&report.bytes)?;
            }
            Ok(())
        },
    )?;
    if ended == pipe::Ended::Horizon {
        bail!(usage(format!(
            "{input_name}: more frames than 100 years of virtual time hold at this --interval"
        )));
    }
    let skipped = frames.stats();
    if skipped.bytes_skipped > 0 {
        if skipped.frames == 0 {
            bail!(BadInput(format!(
                "{input_name}: no link frame in {} bytes (expected wire.md frames starting with 0x55 and a valid CRC)",
                skipped.bytes_in
            )));
        }
        say!(
            "{input_name}: skipped {} bytes that were not good frames ({} CRC failures, {} truncated)",
            skipped.bytes_skipped,
            skipped.crc_failures,
            skipped.truncated
        );
    }
    output
        .finish()
        .with_context(|| format!("writing {output_name}"))?;
    if let Some(trace) = trace {
        trace.commit()?;
    }
    let facts = RunFacts {
        mode: Mode::Pipe,
        seed: args.seed,
        duration_s: link.now().as_secs_f64(),
        interrupted: None,
    };
    say_lines(counters.summary_lines(&facts, &link));
    say!("{:.3} s of wall time", wall.elapsed().as_secs_f64());
    if let Some(file) = stats_file {
        file.commit_json(&counters.stats_json(&facts, &link, None))?;
    }
    Ok(EXIT_OK)
}

/// Bad input (exit 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct BadInput(String);

/// Tries real-time scheduling on a throwaway thread; says on stderr when it is not allowed.
fn raise_priority_check() -> bool {
    match std::thread::spawn(rovlink::link::realtime::raise_priority).join() {
        Ok(Ok(())) => true,
        Ok(Err(reason)) => {
            say!("--rt-priority: real-time scheduling not allowed ({reason}); running without it");
            false
        }
        Err(_) => false,
    }
}

/// The trace's header in the pipe (one direction, A to B).
const TRACE_HEADER: &str = "seq,bytes,t_offered_s,t_tx_start_s,t_rx_s,fate\n";
/// The trace's header in real time (both directions: the sending side is the last column).
const TRACE_HEADER_SIDES: &str = "seq,bytes,t_offered_s,t_tx_start_s,t_rx_s,fate,side\n";

fn run_realtime(args: &Args, mut link: Link, specs: [PortSpec; 2]) -> Result<u8> {
    let framing = if args.raw {
        Framing::Raw {
            idle: Duration::from_millis(args.idle_ms.unwrap_or(20)),
        }
    } else {
        Framing::Frames {
            give_up: Duration::from_millis(args.idle_ms.unwrap_or(1000)),
        }
    };
    let mut trace = match &args.trace {
        Some(path) => {
            let mut file = File::create(path).map_err(|source| IoError::Open {
                path: path.clone(),
                source,
            })?;
            file.write_all(TRACE_HEADER_SIDES.as_bytes())
                .map_err(|source| IoError::Write {
                    name: path.display().to_string(),
                    source,
                })?;
            Some((file, path.display().to_string()))
        }
        None => None,
    };
    let stats_file = args.stats.as_deref().map(AtomicFile::create).transpose()?;
    let realtime_priority = args.rt_priority && raise_priority_check();
    let endpoints = Endpoints::open(specs, realtime_priority)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .context("cannot install the signal handler")?;
    if args.pty {
        let mut out = std::io::stdout().lock();
        let names = endpoints.names();
        writeln!(out, "{}\n{}", names[0], names[1])
            .and_then(|()| out.flush())
            .map_err(|source| IoError::Write {
                name: "<stdout>".into(),
                source,
            })?;
    }
    say!(
        "forwarding A ({}) <-> B ({}) through the model until a side closes or SIGINT/SIGTERM",
        endpoints.names()[0],
        endpoints.names()[1]
    );
    let mut counters = Counters::default();
    let mut trace_error = None;
    let mut emulator = rovlink::link::dialect::EvoLogicsEmulator::new();
    let dialect = (args.dialect == Dialect::Evologics).then_some(&mut emulator);
    let (ended, info) = endpoints.run(&mut link, framing, dialect, &stop, |report| {
        counters.record(report);
        if let Some((file, name)) = trace.as_mut()
            && trace_error.is_none()
            && let Err(source) = file.write_all(
                TraceRow::new(report, Mode::RealTime)
                    .to_csv_line()
                    .as_bytes(),
            )
        {
            trace_error = Some(IoError::Write {
                name: name.clone(),
                source,
            });
        }
    });
    let facts = RunFacts {
        mode: Mode::RealTime,
        seed: args.seed,
        duration_s: link.now().as_secs_f64(),
        interrupted: None,
    };
    say_lines(counters.summary_lines(&facts, &link));
    say_lines(real_time_lines(&info));
    if let Some(file) = stats_file {
        file.commit_json(&counters.stats_json(&facts, &link, Some(&info)))?;
    }
    if let Some(err) = trace_error {
        return Err(err.into());
    }
    match ended {
        Ended::Stopped => Ok(EXIT_OK),
        Ended::Closed { side, name, reason } => {
            say!("side {} ({name}) closed: {reason}", side.name());
            Ok(EXIT_CHECK_FAILED)
        }
    }
}
