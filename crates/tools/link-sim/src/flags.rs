//! link-sim's command line: its flags (doc comments are the help), their ranges, and what they
//! mean for the library (ports, framing, pace).

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use clap::Parser;
use rovlink_base::UsageError;
use rovlink_base::io::Output;
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_cli::model::ModelArgs;
use rovlink_cli::port::DialectFlag;
use rovlink_cli::rows::{RowFormat, RowWriter};
use rovlink_cli::say;
use rovlink_cli::value::{self, CountParser};
use rovlink_link::SimTime;
use rovlink_link::device::DeviceSpec;
use rovlink_link::emulate::Emulation;
use rovlink_link::model::MAX_RANGE_M;
use rovlink_link::pipe::Pace;
use rovlink_link::realtime::{Framing, MAX_PORTS, SideOptions, priority_allowed};
use rovlink_link::stats::{Mode, RunFacts};
use rovlink_link::{Distance, Link, Medium};

use crate::TOOL;

const EXAMPLES: &str = "\
Examples:
  link-sim --model s100 < frames.bin > out.bin          frames through an S100 link in virtual time
  link-sim --model s100 --ber 7e-4 --trace t.csv --stats s.json < frames.bin > out.bin
  link-sim --print-model s2cr-burst > m.json            a preset as a file to edit
  link-sim --model-file m.json --interval 500 < frames.bin > out.bin
  link-sim --model s100 --pty                           two pseudo-terminals (paths on stdout, A then B)
  link-sim --model s100 --a /dev/ttyUSB0 --b /dev/ttyUSB1 --baud 9600
  link-sim --model s100 --a pty --b tcp:192.168.0.209:9200  a program on a new pty, a modem on TCP
  link-sim --model satellite-up --reverse-model satellite-down --a udpin:127.0.0.1:9001 --b udpin:127.0.0.1:9002
  link-sim --model s100 --pty --raw --idle-ms 20 --distance-file dive.csv
  link-sim --model s2cr-burst --pty --dialect evologics  programs speak AT*SEND / RECV to it
  link-sim --model s100 --pty 3 --position 0,0,0 --position 3,0,1 --position 7,0,1
                          three nodes on one S100 medium (paths on stdout, ports 1, 2, 3): the
                          middle one hears both ends, the ends (7.07 m apart) never hear each other

Modes: with no port option, frames (wire.md) from INPUT or stdin go from side A to side B in
virtual time and the frames that arrive go to stdout (or -o), in arrival order. With --a/--b
(each a device, see Devices below; a new pseudo-terminal's path is printed on stdout, A then
B), --pty or --udp-a/--udp-b, the link runs in real time between the two sides until a side
closes (exit 1), or SIGINT/SIGTERM/SIGHUP (exit 0).

Aliases (the flags of earlier versions): --pty is --a pty --b pty; --udp-a ADDR is --a
udpin:ADDR (packets to its first sender), and with --udp-a-peer PEER it is --a udp:ADDR=PEER
(likewise --udp-b, --udp-b-peer); --a PATH is a serial port at --baud, as before.

Shared medium: --pty N (3 ..= 16) creates N pseudo-terminals on one medium with one model:
a frame written to a port reaches every other port in range (from the distance between their
--position, given once per port in port order; default: all at the origin), each after its
own propagation delay, and collides at each receiver separately. The summary and --stats
count each (from, to) pair of ports (numbered from 1); --trace, --reverse-model, --distance,
--distance-file and --dialect evologics apply to two ports only. --pty 2 with --position is
the two-port link at the distance between the two positions.

Trace (--trace): one row per frame, in the order fates are decided:
  seq,bytes,t_offered_s,t_tx_start_s,t_rx_s,fate      (real time adds a last column: side)
fate: delivered, corrupted, ber, collision, overflow, range, loss (a duplicated frame has a
second row with the same seq). t_tx_start_s is when the frame went on air; times are seconds
from the start. Every model field can be set in the file or as a flag. `-` as --trace or
--stats writes standard output (only one output may).

Exit codes: 0 ok, 1 a side's port closed or failed, 2 bad usage or input; the pipe stopped by
SIGINT, SIGTERM or SIGHUP: 130, 143 or 129, with every output holding what was done and the
summary saying it was interrupted.";

/// Simulate an underwater modem link (or a netem-like link) between two ports, or on a pipe.
///
/// The model (a preset or a JSON file, every field overridable by a flag) gives each frame its
/// air time, intrinsic delay and jitter, propagation, range, bit errors, collisions and losses.
/// The same seed gives the same bytes and the same trace.
#[derive(Parser, Debug)]
#[command(version, after_help = format!("{EXAMPLES}\n\n{}", rovlink_link::device::HELP))]
pub struct Args {
    /// Frame byte stream for the virtual-time pipe; `-` or nothing reads standard input.
    pub input: Option<PathBuf>,

    /// Output of the pipe: the frames that arrive; `-` or nothing writes standard output.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,

    /// Print the model (the preset NAME, or --model/--model-file with the flags applied) as
    /// JSON to standard output (or -o) and exit.
    #[arg(long, value_name = "NAME", num_args = 0..=1, default_missing_value = "",
          conflicts_with_all = ["input", "trace", "stats", "interval", "pty", "a", "b", "udp_a",
                                "udp_b", "reverse_model", "reverse_model_file", "distance_file"])]
    pub print_model: Option<String>,

    #[command(flatten)]
    pub model: ModelArgs,

    /// The model of frames from B to A, when it differs (a preset); the flags apply to it too.
    #[arg(
        long,
        value_name = "NAME",
        conflicts_with = "reverse_model_file",
        help_heading = "Link model"
    )]
    pub reverse_model: Option<String>,

    /// The model of frames from B to A, as a file.
    #[arg(long, value_name = "FILE", help_heading = "Link model")]
    pub reverse_model_file: Option<PathBuf>,

    /// Seed of every random stream.
    #[arg(long, default_value_t = 1, value_parser = value::count(0, u64::MAX))]
    pub seed: u64,

    /// Distance between the two sides, m (0 ..= 1e9) [default: 1].
    #[arg(long, value_name = "M", conflicts_with = "distance_file",
          value_parser = value::real(0.0, MAX_RANGE_M, "m"))]
    pub distance: Option<f64>,

    /// Distance over time: CSV with columns t_s,distance_m (linear between rows).
    #[arg(long, value_name = "FILE")]
    pub distance_file: Option<PathBuf>,

    /// Pipe: offer one frame every MS milliseconds instead of back to back (1 µs ..= 1 h).
    #[arg(long, value_name = "MS", value_parser = value::millis(1e-3, 3_600_000.0))]
    pub interval: Option<f64>,

    /// Write one CSV row per frame here (`-`: standard output), each row flushed as it goes.
    #[arg(long, value_name = "FILE")]
    pub trace: Option<PathBuf>,

    /// Write the counters of both directions as JSON here (`-`: standard output) when the run
    /// ends: one line that also carries every parameter of the run and its seed (--metrics is
    /// the same flag, the name every tool's figures share).
    #[arg(long, value_name = "FILE", visible_alias = "metrics")]
    pub stats: Option<PathBuf>,

    /// Real time: create N pseudo-terminals (2 ..= 16; none given: 2, sides A and B, the
    /// same as --a pty --b pty) and print their paths, one per line in port order; more than
    /// 2 share one medium.
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "2",
          help_heading = "Real time", conflicts_with_all = ["a", "udp_a"],
          value_parser = CountParser { min: 2, max: MAX_PORTS as u64, unit: "ports" })]
    pub pty: Option<u64>,

    /// Real time, with --pty: a port's position, NED m (each within 100 km), once per port in
    /// port order.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, requires = "pty",
          conflicts_with_all = ["distance", "distance_file"], help_heading = "Real time",
          value_parser = value::point3())]
    pub position: Vec<[f64; 3]>,

    /// Real time: side A's device (see Devices below): a serial port or someone's
    /// pseudo-terminal (as before), pty (a new one), serial:PATH:BAUD, tcp:, tcpin:, udp:,
    /// udpin: or udpout:.
    #[arg(long, value_name = "DEV", requires = "b", help_heading = "Real time")]
    pub a: Option<DeviceSpec>,

    /// Real time: side B's device, as --a.
    #[arg(long, value_name = "DEV", requires = "a", help_heading = "Real time")]
    pub b: Option<DeviceSpec>,

    /// Baud rate of a side given as a path (50 ..= 4000000).
    #[arg(long, default_value_t = 9600, help_heading = "Real time",
          value_parser = value::baud())]
    pub baud: u32,

    /// Real time: side A's UDP address (bound here; each datagram is a frame). An alias: --a
    /// udpin:ADDR:PORT, or with --udp-a-peer, --a udp:ADDR:PORT=PEER.
    #[arg(
        long,
        value_name = "ADDR:PORT",
        requires = "udp_b",
        conflicts_with = "a",
        help_heading = "Real time"
    )]
    pub udp_a: Option<SocketAddr>,

    /// Real time: side B's UDP address (an alias, as --udp-a).
    #[arg(
        long,
        value_name = "ADDR:PORT",
        requires = "udp_a",
        help_heading = "Real time"
    )]
    pub udp_b: Option<SocketAddr>,

    /// Where side A's program listens [default: the source of its last datagram].
    #[arg(
        long,
        value_name = "ADDR:PORT",
        requires = "udp_a",
        help_heading = "Real time"
    )]
    pub udp_a_peer: Option<SocketAddr>,

    /// Where side B's program listens [default: the source of its last datagram].
    #[arg(
        long,
        value_name = "ADDR:PORT",
        requires = "udp_b",
        help_heading = "Real time"
    )]
    pub udp_b_peer: Option<SocketAddr>,

    /// Real time: run link-sim's threads under real-time (SCHED_FIFO) scheduling, when allowed
    /// (root or CAP_SYS_NICE), so other processes cannot delay deliveries. Measure before relying
    /// on it (scripts/pty-latency.py): on a virtual machine whose processor time is stolen by
    /// the host it does not help, and the kernel's own pseudo-terminal work can then wait.
    #[arg(long, help_heading = "Real time")]
    pub rt_priority: bool,

    /// Real time: what the programs on the ports speak: bare packets, or the EvoLogics AT
    /// dialect (AT*SEND / AT*SENDIM in, RECV / RECVIM / DELIVEREDIM / FAILEDIM out; side A is
    /// address 1, side B address 2).
    #[arg(long, value_enum, default_value_t = DialectFlag::TRANSPARENT, help_heading = "Real time")]
    pub dialect: DialectFlag,

    /// Real time: packets are bytes separated by silence (a modem's transparent mode), not
    /// wire.md frames.
    #[arg(long, requires = "idle_ms", help_heading = "Real time")]
    pub raw: bool,

    /// Silence that ends a packet with --raw; with frames, the silence after which an
    /// incomplete frame is given up (1 ..= 600000) [default with frames: 1000].
    #[arg(long, value_name = "MS", help_heading = "Real time",
          value_parser = CountParser { min: 1, max: 600_000, unit: "ms" })]
    pub idle_ms: Option<u64>,
}

/// The outputs of a run, claimed before it starts.
pub struct Claimed {
    /// The pipe's frames (none in real time).
    pub output: Option<Dest>,
    /// The trace, as rows.
    pub trace: Option<RowWriter>,
    /// The stats document, open (aside) from the start, so that a file that cannot be
    /// created fails before the run.
    pub stats: Option<Output>,
}

impl Args {
    /// The model flags `--print-model` prints (with its preset, when it names one).
    pub fn printed_model(&self) -> Option<ModelArgs> {
        let name = self.print_model.as_ref()?;
        let mut model = self.model.clone();
        if !name.is_empty() {
            (model.model, model.model_file) = (Some(name.clone()), None);
        }
        Some(model)
    }

    /// Where `--print-model` writes: `-o` (not the model file it reads), or standard output.
    pub fn printed_model_dest(&self) -> Result<Dest, UsageError> {
        let mut outs = Outputs::new();
        outs.input(self.model.model_file.as_deref());
        let path = self.output.as_deref().unwrap_or(Path::new("-"));
        outs.claim("-o", path, Kind::Text)
    }

    /// Checks that the flags fit the mode and claims every output (inputs registered first,
    /// so that none is overwritten); only the stats file is opened (aside: it is removed
    /// unless the run commits it).
    pub fn claim(&self, mode: Mode) -> anyhow::Result<Claimed> {
        let pipe_only = self.interval.is_some() || self.output.is_some() || self.input.is_some();
        match mode {
            Mode::Pipe if self.raw => {
                return Err(
                    UsageError("--raw applies to real-time ports, not the pipe".into()).into(),
                );
            }
            Mode::RealTime if pipe_only => {
                return Err(UsageError(
                    "INPUT, --output and --interval apply to the pipe, not to real-time ports"
                        .into(),
                )
                .into());
            }
            _ => {}
        }
        let mut outs = Outputs::new();
        let inputs = [
            &self.input,
            &self.model.model_file,
            &self.reverse_model_file,
            &self.distance_file,
        ];
        outs.inputs(inputs.into_iter().flatten().map(PathBuf::as_path));
        self.check_ports()?;
        if self
            .sides()
            .is_some_and(|sides| sides.contains(&DeviceSpec::Pty))
        {
            let flag = if self.pty.is_some() {
                "--pty"
            } else {
                "a pty side"
            };
            outs.claim_stdout(flag, Kind::Text)?;
        }
        let trace = outs.claim_opt("--trace", self.trace.as_deref(), Kind::Text)?;
        let stats = outs.claim_opt("--stats", self.stats.as_deref(), Kind::Text)?;
        let output = match mode {
            Mode::Pipe => {
                let path = self.output.as_deref().unwrap_or(Path::new("-"));
                Some(outs.claim("-o", path, Kind::Binary)?)
            }
            Mode::RealTime => None,
        };
        Ok(Claimed {
            output,
            trace: trace.map(|dest| RowWriter::new(dest, RowFormat::Csv, mode.trace_columns())),
            stats: stats.map(|dest| dest.open()).transpose()?,
        })
    }

    /// The link the flags describe: both models, the seed, the distance.
    pub fn link(&self) -> anyhow::Result<Link> {
        let forward = self.model.resolve()?;
        let reverse = match self.reverse_model_args() {
            Some(reverse) => reverse.resolve()?,
            None => forward.clone(),
        };
        let distance = match (&self.distance_file, &self.position[..]) {
            (Some(path), _) => Distance::from_csv_file(path)?,
            (None, [a, b]) => {
                Distance::Fixed((0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt())
            }
            (None, _) => Distance::Fixed(self.distance.unwrap_or(1.0)),
        };
        Ok(Link::new(forward, reverse, self.seed, distance)?)
    }

    /// The number of ports of a shared medium (`--pty N`, N > 2); none for a two-sided link.
    pub fn medium_ports(&self) -> Option<usize> {
        self.pty.map(|n| n as usize).filter(|&n| n > 2)
    }

    /// The shared medium of `--pty N`: the model, the seed, the ports' positions.
    pub fn medium(&self, ports: usize) -> anyhow::Result<Medium> {
        let positions = match self.position.is_empty() {
            true => vec![[0.0; 3]; ports],
            false => self.position.clone(),
        };
        Ok(Medium::new(self.model.resolve()?, self.seed, positions)?)
    }

    /// Checks the flags of `--pty N` and `--position`: one position per port; with more than
    /// two ports, only the flags a medium has.
    fn check_ports(&self) -> Result<(), UsageError> {
        let Some(ports) = self.pty else {
            return Ok(());
        };
        if !self.position.is_empty() && self.position.len() as u64 != ports {
            return Err(UsageError(format!(
                "--position: expected one per port ({ports}), found {}",
                self.position.len()
            )));
        }
        if ports == 2 {
            return Ok(());
        }
        let dialect = format!("--dialect {}", self.dialect.0.name());
        let two_only = [
            ("--trace", self.trace.is_some()),
            ("--reverse-model", self.reverse_model.is_some()),
            ("--reverse-model-file", self.reverse_model_file.is_some()),
            ("--distance", self.distance.is_some()),
            ("--distance-file", self.distance_file.is_some()),
            (dialect.as_str(), self.dialect.0.two_sides_only()),
        ];
        match two_only.iter().find(|(_, given)| *given) {
            Some((flag, _)) => Err(UsageError(format!(
                "{flag} applies to two ports, not to --pty {ports} (a shared medium)"
            ))),
            None => Ok(()),
        }
    }

    /// The two sides of a real-time run, A then B (the aliases read as devices); none for the
    /// pipe.
    pub fn sides(&self) -> Option<Vec<DeviceSpec>> {
        if self.pty.is_some() {
            return Some(vec![DeviceSpec::Pty, DeviceSpec::Pty]);
        }
        if let (Some(a), Some(b)) = (&self.a, &self.b) {
            return Some(vec![a.clone(), b.clone()]);
        }
        let udp = |bind: SocketAddr, peer: Option<SocketAddr>| match peer {
            Some(peer) => DeviceSpec::Udp { bind, peer },
            None => DeviceSpec::UdpIn(bind.to_string()),
        };
        let (a, b) = (self.udp_a?, self.udp_b?);
        Some(vec![udp(a, self.udp_a_peer), udp(b, self.udp_b_peer)])
    }

    /// The real-time run of `devices`: their baud rate, the framing, the dialect, and
    /// real-time scheduling with `--rt-priority` when it is allowed (said when it is not).
    pub fn emulation(&self, devices: Vec<DeviceSpec>) -> Emulation {
        let realtime_priority = self.rt_priority
            && priority_allowed()
                .map_err(|why| say!("--rt-priority: not allowed ({why}); running without it"))
                .is_ok();
        Emulation {
            devices,
            sides: SideOptions {
                baud: self.baud,
                realtime_priority,
            },
            framing: self.framing(),
            dialect: self.dialect.0,
        }
    }

    /// What the summary and `--stats` say of a run besides its counters: the mode, the seed,
    /// the link's time at the end, and why it was cut short (`note`).
    pub fn facts<'a>(&self, mode: Mode, now: SimTime, note: &'a Option<String>) -> RunFacts<'a> {
        RunFacts {
            mode,
            seed: self.seed,
            duration_s: now.as_secs_f64(),
            interrupted: note.as_deref(),
        }
    }

    /// How a real-time run cuts bytes into packets.
    pub fn framing(&self) -> Framing {
        if self.raw {
            Framing::Raw {
                idle: Duration::from_millis(self.idle_ms.unwrap_or(20)),
            }
        } else {
            Framing::Frames {
                give_up: Duration::from_millis(self.idle_ms.unwrap_or(1000)),
            }
        }
    }

    /// When the pipe offers frames.
    pub fn pace(&self) -> Pace {
        match self.interval {
            None => Pace::BackToBack,
            Some(ms) => Pace::IntervalNs((ms * 1e6).round() as u64),
        }
    }

    /// The model flags for the reverse direction, when it has its own preset or file.
    fn reverse_model_args(&self) -> Option<ModelArgs> {
        (self.reverse_model.is_some() || self.reverse_model_file.is_some()).then(|| ModelArgs {
            model: self.reverse_model.clone(),
            model_file: self.reverse_model_file.clone(),
            ..self.model.clone()
        })
    }
}
