//! modem-bench: characterise a modem link, real or simulated, and turn the measurement into a model.
#![forbid(unsafe_code)]

use std::fs::File;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Parser;
use rovlink::cli::model::ModelArgs;
use rovlink::cli::port::PortArgs;
use rovlink::gll::Endpoint;
use rovlink::gll::PortError;
use rovlink::io::{AtomicFile, EXIT_CHECK_FAILED, EXIT_OK, IoError};
use rovlink::link::pipe::Pace;
use rovlink::link::{Distance, Link};
use rovlink::measure::live::{self, Ended, Plan, Ports};
use rovlink::measure::sim;
use rovlink::measure::{ROW_HEADER, Row, Summary, Tally, probe_total};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "modem-bench";

/// Says something on stderr (never panics, even with stderr closed).
macro_rules! say {
    ($($arg:tt)*) => {
        rovlink::io::warn(TOOL, &format!($($arg)*))
    };
}

const EXAMPLES: &str = "\
Examples:
  modem-bench --sim s100 --count 2000 --size 57 -o packets.csv        virtual time, well under a second
  modem-bench --sim s100 --sizes 16,57,100 --count 2000 --summary s.json --fit fitted.json
  modem-bench --model-file fitted.json --count 2000 --summary check.json
  modem-bench --tx /dev/ttyUSB0 --rx /dev/ttyUSB1 --sizes 16,57,100 --count 60 --interval 700 -o p.csv
  modem-bench --tx A --rx B --dialect evologics --sizes 16,57 --count 60 --interval 3000
  modem-bench --port /dev/ttyUSB0 --echo --count 100 --interval 2000     round trips via a far-end echo

DEV is a serial port or pseudo-terminal, tcp:HOST:PORT (a modem's TCP interface, e.g. an
EvoLogics modem on Ethernet), or udp:BIND_ADDR=PEER_ADDR (one datagram per packet).

Size = bytes written to the modem per packet: a whole wire.md frame (header and CRC included)
whose payload carries the sequence number and the send time; 15 to 260 bytes.

packets.csv, one row per packet, flushed as it goes:
  seq,size_bytes,t_tx_s,t_rx_s,delay_ms,delivered,corrupted
The summary (stderr, and --summary JSON): count, delivered, loss_ratio, delay_ms_mean/p50/p99,
jitter_ms (standard deviation of the delay), jitter_rfc3550_ms, iat_ms_mean, iat_ms_std,
throughput_bps, and with two sizes or more fit_bitrate_bps, fit_intrinsic_delay_ms and
fit_jitter_ms (least squares of delay on size, and the spread around it): the columns of the
paper's Table 3. With a size sweep, jitter_ms includes the sizes' own spread; fit_jitter_ms
does not.

Exit codes: 0 ok, 1 a port closed or failed during the run (rows so far kept), 2 bad usage or input.";

/// Characterise a modem link (real or simulated) and turn the measurement into a model.
///
/// Sends numbered, timestamped probe packets and records when each arrives: one CSV row per
/// packet, a summary with the figures of the paper's Table 3, and optionally a model file that
/// link-sim and tdma-run accept.
#[derive(Parser, Debug)]
#[command(version, after_help = EXAMPLES)]
struct Args {
    /// Simulate in virtual time through this preset (default s100; or --model-file).
    #[arg(long, value_name = "NAME", num_args = 0..=1, default_missing_value = "s100",
          conflicts_with_all = ["tx", "port"])]
    sim: Option<String>,

    #[command(flatten)]
    model: ModelArgs,

    /// Seed of the simulation's random streams.
    #[arg(long, default_value_t = 1)]
    seed: u64,

    /// Distance between the simulated modems, m.
    #[arg(long, value_name = "M", default_value_t = 1.0)]
    distance: f64,

    /// Real modems: the sending modem's serial port (both modems on this host: one clock).
    #[arg(
        long,
        value_name = "DEV",
        requires = "rx",
        conflicts_with = "port",
        help_heading = "Real modems"
    )]
    tx: Option<String>,

    /// Real modems: the receiving modem's serial port.
    #[arg(
        long,
        value_name = "DEV",
        requires = "tx",
        help_heading = "Real modems"
    )]
    rx: Option<String>,

    /// Real modem whose far end echoes every packet: delays are round trips.
    #[arg(
        long,
        value_name = "DEV",
        requires = "echo",
        help_heading = "Real modems"
    )]
    port: Option<String>,

    /// With --port: the far end echoes.
    #[arg(long, requires = "port", help_heading = "Real modems")]
    echo: bool,

    #[command(flatten)]
    port_args: PortArgs,

    /// Real modems: a packet that has not arrived this long after its send is lost, s.
    #[arg(
        long,
        value_name = "S",
        default_value_t = 10.0,
        help_heading = "Real modems"
    )]
    timeout: f64,

    /// Packets per size.
    #[arg(long, short = 'n', default_value_t = 100)]
    count: u32,

    /// Packet size, bytes (a whole frame).
    #[arg(long, value_name = "BYTES", conflicts_with = "sizes")]
    size: Option<usize>,

    /// Sweep packet sizes (interleaved), bytes, e.g. 16,57,100.
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    sizes: Vec<usize>,

    /// Time between sends, ms [default: simulated, back to back (each when the transmitter is
    /// free); real, 1000].
    #[arg(long, value_name = "MS")]
    interval: Option<f64>,

    /// packets.csv; `-` or nothing writes standard output.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,

    /// Write the summary as JSON here.
    #[arg(long, value_name = "FILE")]
    summary: Option<PathBuf>,

    /// Write a model file fitted to the measurement here.
    #[arg(long, value_name = "FILE")]
    fit: Option<PathBuf>,

    /// No progress bar and no summary table on stderr.
    #[arg(short, long)]
    quiet: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    rovlink::io::finish_main(TOOL, run(&args))
}

#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct UsageError(String);

fn usage(message: String) -> anyhow::Error {
    anyhow::Error::new(UsageError(message))
}

/// Where rows go: written and flushed one by one, and counted into the summary.
struct RowSink {
    out: Box<dyn Write>,
    name: String,
    tally: Tally,
}

impl RowSink {
    fn open(path: Option<&Path>) -> Result<RowSink> {
        let (out, name): (Box<dyn Write>, String) = match path {
            Some(p) if p.as_os_str() != "-" => (
                Box::new(File::create(p).map_err(|source| IoError::Open {
                    path: p.to_path_buf(),
                    source,
                })?),
                p.display().to_string(),
            ),
            _ => (Box::new(std::io::stdout()), "<stdout>".into()),
        };
        let mut sink = RowSink {
            out,
            name,
            tally: Tally::new(),
        };
        sink.line(ROW_HEADER)?;
        Ok(sink)
    }

    fn line(&mut self, text: &str) -> Result<(), IoError> {
        writeln!(self.out, "{text}")
            .and_then(|()| self.out.flush())
            .map_err(|source| IoError::Write {
                name: self.name.clone(),
                source,
            })
    }

    fn push(&mut self, row: Row) -> Result<(), IoError> {
        self.line(&row.to_csv())?;
        self.tally.push(&row);
        Ok(())
    }
}

fn run(args: &Args) -> Result<u8> {
    let sizes = if !args.sizes.is_empty() {
        args.sizes.clone()
    } else {
        vec![args.size.unwrap_or(57)]
    };
    let total = probe_total(&sizes, args.count)?;
    if let Some(ms) = args.interval
        && !(ms.is_finite() && ms > 0.0)
    {
        bail!(usage(format!(
            "--interval: expected milliseconds > 0, found {ms}"
        )));
    }
    let real = args.tx.is_some() || args.port.is_some();
    if !real && args.port_args.any_set() {
        bail!(usage(
            "--dialect, --instant and --chunk-bytes apply to real modems (--tx/--rx or --port)"
                .into()
        ));
    }
    // Files are created before anything is measured, so a bad path fails at once.
    let summary_file = args
        .summary
        .as_deref()
        .map(AtomicFile::create)
        .transpose()?;
    let fit_file = args.fit.as_deref().map(AtomicFile::create).transpose()?;
    let mut sink = RowSink::open(args.output.as_deref())?;
    let progress = progress_bar(args.quiet, total);

    let (code, assumed_rate) = if real {
        let code = run_real(args, &sizes, &mut sink, &progress)?;
        (code, args.port_args.chunk_rate_bps)
    } else {
        let model = run_sim(args, &sizes, &mut sink, &progress)?;
        (EXIT_OK, model)
    };
    progress.finish_and_clear();

    let summary = sink.tally.summary();
    if !args.quiet {
        print_summary(&summary);
    }
    if let Some(file) = summary_file {
        file.commit_json(&summary)?;
    }
    if let (Some(file), Some(path)) = (fit_file, &args.fit) {
        let name = path
            .file_stem()
            .map_or("fitted".into(), |s| s.to_string_lossy().into_owned());
        let Some(model) = summary.to_model(&name, assumed_rate) else {
            bail!(rovlink::io::CheckFailed(format!(
                "--fit: no model from this measurement ({} of {} packets delivered)",
                summary.delivered, summary.count
            )));
        };
        file.commit_with(model.to_json().as_bytes())?;
        if !args.quiet {
            say!(
                "model written to {}: {:.1} bit/s, intrinsic delay {:.2} ms, jitter {:.2} ms, BER {:.3e}",
                path.display(),
                model.bitrate_bps,
                model.intrinsic_delay_ms,
                model.jitter_ms,
                model.ber
            );
        }
    }
    Ok(code)
}

fn progress_bar(quiet: bool, total: u64) -> indicatif::ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(total);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{spinner} {pos}/{len} packets [{bar:30}] {elapsed_precise} (eta {eta})",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// The simulated campaign; returns the model's bit rate (for a one-size fit).
fn run_sim(
    args: &Args,
    sizes: &[usize],
    sink: &mut RowSink,
    progress: &indicatif::ProgressBar,
) -> Result<f64> {
    let mut model_args = args.model.clone();
    if let Some(name) = &args.sim
        && model_args.model_file.is_none()
    {
        model_args.model = Some(name.clone());
    }
    let model = model_args.resolve()?;
    if !(args.distance.is_finite() && args.distance >= 0.0) {
        bail!(usage(format!(
            "--distance: expected metres >= 0, found {}",
            args.distance
        )));
    }
    let rate = model.bitrate_bps;
    let mut link = Link::symmetric(model, args.seed, Distance::Fixed(args.distance))?;
    let pace = match args.interval {
        Some(ms) => Pace::IntervalNs((ms * 1e6).round() as u64),
        None => Pace::BackToBack,
    };
    let plan = sim::Plan {
        sizes: sizes.to_vec(),
        count_per_size: args.count,
        pace,
    };
    let stop = AtomicBool::new(false);
    sim::run::<anyhow::Error>(
        &mut link,
        &plan,
        &stop,
        |row| Ok(sink.push(row)?),
        |done| progress.set_position(done),
    )?;
    Ok(rate)
}

/// Opens a modem as the flags say; a bad device name is bad usage.
fn open(args: &Args, device: &str) -> Result<Box<dyn Endpoint>> {
    args.port_args.open(device).map_err(|e| match e {
        PortError::Usage(message) => usage(message),
        PortError::Open(error) => error.into(),
    })
}

fn run_real(
    args: &Args,
    sizes: &[usize],
    sink: &mut RowSink,
    progress: &indicatif::ProgressBar,
) -> Result<u8> {
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        bail!(usage(format!(
            "--timeout: expected seconds > 0, found {}",
            args.timeout
        )));
    }
    let plan = Plan {
        sizes: sizes.to_vec(),
        count_per_size: args.count,
        interval: Duration::from_secs_f64(args.interval.unwrap_or(1000.0) / 1e3),
        timeout: Duration::from_secs_f64(args.timeout),
    };
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .context("cannot install the Ctrl-C handler")?;
    let (mut tx_port, mut rx_port) = match (&args.tx, &args.rx, &args.port) {
        (Some(tx), Some(rx), _) => (open(args, tx)?, Some(open(args, rx)?)),
        (_, _, Some(port)) => (open(args, port)?, None),
        _ => bail!(usage("give --tx and --rx, or --port with --echo".into())),
    };
    let ports = match rx_port.as_mut() {
        Some(rx) => Ports::Pair {
            tx: tx_port.as_mut(),
            rx: rx.as_mut(),
        },
        None => Ports::Echo(tx_port.as_mut()),
    };
    if !args.quiet {
        say!(
            "sending {} packets, one every {:.0} ms (about {:.0} s)",
            plan.total(),
            plan.interval.as_secs_f64() * 1e3,
            plan.total() as f64 * plan.interval.as_secs_f64() + plan.timeout.as_secs_f64().min(5.0)
        );
    }
    let (ended, extras) = live::run(
        ports,
        &plan,
        &stop,
        |row| sink.push(row),
        |done| progress.set_position(done),
    )?;
    if extras.foreign > 0 || extras.duplicates > 0 {
        say!(
            "{} packets received that were not this run's probes, {} probes received twice",
            extras.foreign,
            extras.duplicates
        );
    }
    match ended {
        Ended::Done => Ok(EXIT_OK),
        Ended::Stopped { unresolved } => {
            say!("stopped: {unresolved} packets still on their way are not in the rows");
            Ok(EXIT_OK)
        }
        Ended::Failed { error, unresolved } => {
            say!(
                "{error}; {} rows kept, {unresolved} packets on their way not recorded",
                sink.tally.count()
            );
            Ok(EXIT_CHECK_FAILED)
        }
    }
}

fn print_summary(s: &Summary) {
    let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    say!(
        "{} packets, {} delivered ({} corrupted), loss ratio {:.4}",
        s.count,
        s.delivered,
        s.corrupted,
        s.loss_ratio
    );
    say!(
        "delay ms: mean {}  p50 {}  p99 {}  jitter (std) {}  RFC 3550 jitter {}",
        ms(s.delay_ms_mean),
        ms(s.delay_ms_p50),
        ms(s.delay_ms_p99),
        ms(s.jitter_ms),
        ms(s.jitter_rfc3550_ms)
    );
    say!(
        "inter-arrival ms: mean {}  std {};  throughput {} bit/s",
        ms(s.iat_ms_mean),
        ms(s.iat_ms_std),
        ms(s.throughput_bps)
    );
    if let (Some(rate), Some(intrinsic)) = (s.fit_bitrate_bps, s.fit_intrinsic_delay_ms) {
        say!(
            "fit of delay on size: bit rate {rate:.1} bit/s, intrinsic delay {intrinsic:.2} ms, jitter around the fit {} ms",
            ms(s.fit_jitter_ms)
        );
    }
    if s.sizes.len() > 1 {
        for size in &s.sizes {
            say!(
                "  {:>4} bytes: {} sent, {} delivered, delay {} ms, jitter {} ms",
                size.size_bytes,
                size.count,
                size.delivered,
                ms(size.delay_ms_mean),
                ms(size.jitter_ms)
            );
        }
    }
}
