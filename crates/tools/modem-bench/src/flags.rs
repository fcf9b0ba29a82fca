//! modem-bench's command line: its flags (doc comments are the help), their ranges, and the
//! outputs they name.

use std::path::{Path, PathBuf};
use std::time::Duration;

use clap::Parser;
use rovlink_base::UsageError;
use rovlink_base::io::Output;
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_cli::model::ModelArgs;
use rovlink_cli::port::PortArgs;
use rovlink_cli::value::{self, MAX_COUNT, WEEK_S};
use rovlink_link::gll::{Endpoint, PortError};
use rovlink_link::measure::{MAX_PROBE_BYTES, MIN_PROBE_BYTES, live, sim};
use rovlink_link::model::MAX_RANGE_M;
use rovlink_link::pipe::Pace;

const EXAMPLES: &str = "\
Examples:
  modem-bench --sim s100 --count 2000 --size 57 -o packets.csv        virtual time, well under a second
  modem-bench --sim s100 --sizes 16,57,100 --count 2000 --summary s.json --fit fitted.json
  modem-bench --model-file fitted.json --count 2000 --summary check.json
  modem-bench --sim s100 --count 100000 -o /dev/null --summary -      the summary alone, on stdout
  modem-bench --tx /dev/ttyUSB0 --rx /dev/ttyUSB1 --sizes 16,57,100 --count 60 --interval 700 -o p.csv
  modem-bench --tx A --rx B --dialect evologics --sizes 16,57 --count 60 --interval 3000
  modem-bench --port /dev/ttyUSB0 --echo --count 100 --interval 2000     round trips via a far-end echo

DEV is a device (see Devices below): a serial port or pseudo-terminal, tcp:HOST:PORT (a
modem's TCP interface, e.g. an EvoLogics modem on Ethernet), udp:BIND=PEER (one datagram per
packet), or any other form of the grammar; the spellings modem-bench took before are its
forms.

Size = bytes written to the modem per packet: a whole wire.md frame (header and CRC included)
whose payload carries the sequence number and the send time; 15 to 260 bytes.

packets.csv, one row per packet, flushed as it goes (times and delays to the microsecond):
  seq,size_bytes,t_tx_s,t_rx_s,delay_ms,delivered,corrupted
The summary (stderr, and --summary JSON): count, delivered, loss_ratio, delay_ms_mean/p50/p99,
jitter_ms (standard deviation of the delay), jitter_rfc3550_ms, iat_ms_mean, iat_ms_std,
throughput_bps, and with two sizes or more fit_bitrate_bps, fit_intrinsic_delay_ms and
fit_jitter_ms (least squares of delay on size, and the spread around it): the columns of the
paper's Table 3, and `interrupted` (null, or the signal that cut the run short). With a size
sweep, jitter_ms includes the sizes' own spread; fit_jitter_ms does not. Memory does not grow
with --count: means and standard deviations are exact, p50/p99 come from a fixed-size sketch
(within 0.1 %, or 1 us). `-` as --summary or --fit writes standard output (then give -o a file).

Exit codes: 0 ok (also Ctrl-C on real modems: the summary covers what was measured), 1 a port
closed or failed during the run (rows so far kept), 2 bad usage or input; --sim stopped by
SIGINT, SIGTERM or SIGHUP: 130, 143 or 129, rows, summary and fit covering what was done.";

/// Characterise a modem link (real or simulated) and turn the measurement into a model.
///
/// Sends numbered, timestamped probe packets and records when each arrives: one CSV row per
/// packet, a summary with the figures of the paper's Table 3, and optionally a model file that
/// link-sim and tdma-run accept.
#[derive(Parser, Debug)]
#[command(version, after_help = format!("{EXAMPLES}\n\n{}", rovlink_link::device::HELP))]
pub struct Args {
    /// Simulate in virtual time through this preset (default s100; or --model-file).
    #[arg(long, value_name = "NAME", num_args = 0..=1, default_missing_value = "s100",
          conflicts_with_all = ["tx", "port"])]
    pub sim: Option<String>,

    #[command(flatten)]
    pub model: ModelArgs,

    /// Seed of the simulation's random streams.
    #[arg(long, default_value_t = 1, value_parser = value::count(0, u64::MAX))]
    pub seed: u64,

    /// Distance between the simulated modems, m (0 ..= 1e9).
    #[arg(long, value_name = "M", default_value_t = 1.0,
          value_parser = value::real(0.0, MAX_RANGE_M, "m"))]
    pub distance: f64,

    /// Real modems: the sending modem's device (both modems on this host: one clock).
    #[arg(long, value_name = "DEV", requires = "rx", conflicts_with = "port",
          help_heading = "Real modems", value_parser = value::device)]
    pub tx: Option<String>,

    /// Real modems: the receiving modem's device.
    #[arg(long, value_name = "DEV", requires = "tx", help_heading = "Real modems",
          value_parser = value::device)]
    pub rx: Option<String>,

    /// Real modem whose far end echoes every packet: delays are round trips.
    #[arg(long, value_name = "DEV", requires = "echo", help_heading = "Real modems",
          value_parser = value::device)]
    pub port: Option<String>,

    /// With --port: the far end echoes.
    #[arg(long, requires = "port", help_heading = "Real modems")]
    pub echo: bool,

    #[command(flatten)]
    pub port_args: PortArgs,

    /// Real modems: a packet that has not arrived this long after its send is lost, s
    /// (1 ms ..= 7 d).
    #[arg(long, value_name = "S", default_value_t = 10.0, help_heading = "Real modems",
          value_parser = value::seconds(1e-3, WEEK_S))]
    pub timeout: f64,

    /// Packets per size (1 ..= 10^9).
    #[arg(long, short = 'n', default_value_t = 100, value_parser = value::count(1, MAX_COUNT))]
    pub count: u64,

    /// Packet size, bytes (a whole frame, 15 ..= 260).
    #[arg(long, value_name = "BYTES", conflicts_with = "sizes",
          value_parser = value::bytes(MIN_PROBE_BYTES as u64, MAX_PROBE_BYTES as u64))]
    pub size: Option<u64>,

    /// Sweep packet sizes (interleaved), bytes, e.g. 16,57,100.
    #[arg(long, value_name = "LIST",
          value_parser = value::count_list(value::bytes(MIN_PROBE_BYTES as u64, MAX_PROBE_BYTES as u64), 256))]
    pub sizes: Option<::std::vec::Vec<u64>>,

    /// Time between sends, ms (1 us ..= 1 h) [default: simulated, back to back (each when the
    /// transmitter is free); real, 1000].
    #[arg(long, value_name = "MS", value_parser = value::millis(1e-3, 3_600_000.0))]
    pub interval: Option<f64>,

    /// packets.csv; `-` or nothing writes standard output.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,

    /// Write the summary as JSON here (`-`: standard output): one line that also carries every
    /// parameter of the run and its seed (--metrics is the same flag, the name every tool's
    /// figures share).
    #[arg(long, value_name = "FILE", visible_alias = "metrics")]
    pub summary: Option<PathBuf>,

    /// Write a model file fitted to the measurement here (`-`: standard output).
    #[arg(long, value_name = "FILE")]
    pub fit: Option<PathBuf>,

    /// No progress bar and no summary table on stderr.
    #[arg(short, long)]
    pub quiet: bool,
}

/// An open modem.
pub type Modem = Box<dyn Endpoint>;

/// The outputs of a run, claimed before it starts.
pub struct Claimed {
    /// packets.csv.
    pub rows: Dest,
    /// The summary document, open (aside) from the start: a file that cannot be created fails
    /// before the run.
    pub summary: Option<Output>,
    /// The fitted model's file, open the same way.
    pub fit: Option<Output>,
    /// The fitted model's name: the file's stem, or `fitted`.
    pub fit_name: String,
}

impl Args {
    /// True for a campaign over real modems.
    pub fn real(&self) -> bool {
        self.tx.is_some() || self.port.is_some()
    }

    /// The probe sizes, bytes.
    pub fn sizes(&self) -> Vec<usize> {
        match (&self.sizes, self.size) {
            (Some(sizes), _) => sizes.iter().map(|&s| s as usize).collect(),
            (None, size) => vec![size.unwrap_or(57) as usize],
        }
    }

    /// Probes per size (the range keeps it within 32 bits).
    fn count_per_size(&self) -> u32 {
        u32::try_from(self.count).unwrap_or(u32::MAX)
    }

    /// The simulated campaign: back to back unless --interval.
    pub fn sim_plan(&self) -> sim::Plan {
        let pace = self.interval.map_or(Pace::BackToBack, |ms| {
            Pace::IntervalNs((ms * 1e6).round() as u64)
        });
        sim::Plan {
            sizes: self.sizes(),
            count_per_size: self.count_per_size(),
            pace,
        }
    }

    /// The campaign over real modems: one probe a second unless --interval.
    pub fn live_plan(&self) -> live::Plan {
        live::Plan {
            sizes: self.sizes(),
            count_per_size: self.count_per_size(),
            interval: Duration::from_secs_f64(self.interval.unwrap_or(1000.0) / 1e3),
            timeout: Duration::from_secs_f64(self.timeout),
        }
    }

    /// Opens the sending modem and, unless the far end echoes, the receiving one.
    pub fn open_ports(&self) -> anyhow::Result<(Modem, Option<Modem>)> {
        let open = |device: &str| -> anyhow::Result<Modem> {
            self.port_args.open(device).map_err(|e| match e {
                PortError::Usage(message) => UsageError(message).into(),
                PortError::Open(error) => error.into(),
            })
        };
        match (&self.tx, &self.rx, &self.port) {
            (Some(tx), Some(rx), _) => Ok((open(tx)?, Some(open(rx)?))),
            (_, _, Some(port)) => Ok((open(port)?, None)),
            _ => Err(UsageError("give --tx and --rx, or --port with --echo".into()).into()),
        }
    }

    /// The model flags of the simulation: `--sim NAME` as the preset unless a file is given.
    pub fn sim_model(&self) -> ModelArgs {
        let mut model = self.model.clone();
        if model.model_file.is_none() && self.sim.is_some() {
            model.model = self.sim.clone();
        }
        model
    }

    /// Checks the flags against the mode and claims every output; the summary and fit files
    /// are opened (aside: removed unless the run commits them), the rows' file is created at
    /// the first row.
    pub fn claim(&self) -> anyhow::Result<Claimed> {
        if !self.real() && self.port_args.any_set() {
            return Err(UsageError(
                "--dialect, --instant, --address, --baud and --chunk-bytes apply to real modems (--tx/--rx or --port)"
                    .into(),
            )
            .into());
        }
        let mut outs = Outputs::new();
        outs.input(self.model.model_file.as_deref());
        let summary = outs.claim_opt("--summary", self.summary.as_deref(), Kind::Text)?;
        let fit = outs.claim_opt("--fit", self.fit.as_deref(), Kind::Text)?;
        let rows_path = self.output.as_deref().unwrap_or(Path::new("-"));
        let rows = outs.claim("-o", rows_path, Kind::Text)?;
        let stem = fit.as_ref().and_then(|dest| dest.path()?.file_stem());
        let fit_name = stem.map_or("fitted".into(), |s| s.to_string_lossy().into_owned());
        Ok(Claimed {
            rows,
            summary: summary.map(|dest| dest.open()).transpose()?,
            fit: fit.map(|dest| dest.open()).transpose()?,
            fit_name,
        })
    }
}
