//! octo-delta's command line: subcommands and flags, every number range-checked with its unit.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use rovlink_cli::value::{self, MAX_COUNT};
use rovlink_link::device::DeviceSpec;
use rovlink_mapper::pipeline::ros2_input::Ros2Input;
use rovlink_mapper::pipeline::{
    BuildConfig, CELLS_PER_SCAN_DEFAULT, COARSE_FACTOR_MAX, COORDINATE_MAX_M, Coarse, DumpFormat,
    InputFormat, MAX_RANGE_M, RESOLUTION_MAX_M, RESOLUTION_MIN_M, THREADS_MAX,
};
use rovlink_octo::delta::Roi;
use rovlink_octo::{synth, transfer};
use rovlink_scans::cloud::McapOptions;

const EXAMPLES: &str = "\
Examples:
  octo-delta synth -o survey.graph                     a synthetic seabed survey to try things on
  octo-delta synth -o survey.mcap                      the same, coloured, as ROS 2 MCAP
  octo-delta build survey.graph --res 0.1 -o deltas.odl --stats bandwidth.csv --ot map.ot
  octo-delta build scan*.pcd --roi -2,-2,-5,2,2,0 --coarse-depth 13 -o deltas.odl
  octo-delta build run.mcap --fixed-frame odom -o deltas.odl   a ROS 2 bag posed by /tf
  octo-delta build rosbag2_2026_12_01/ --pose-topic /odom --bt map.bt   a rosbag2 directory
  octo-delta build survey.graph -o deltas.odl --link satellite-up   when each scan reaches shore
  octo-delta apply deltas.odl -o view.ot               the operator's view
  octo-delta apply deltas.odl --mcap view.mcap --arrivals arrivals.csv   the view as it grew, for Foxglove
  octo-delta dump deltas.odl --format csv              one line per message
  octo-delta full map.ot --roi -1,-1,-1,1,1,1 -o full.odl
  octo-delta map survey.graph --follow --port /dev/ttyUSB1 --ot map.ot   on the vehicle, live
  octo-delta view --port /dev/ttyUSB0 --foxglove 127.0.0.1:8765 --orders requests -o view.ot
  octo-delta synth --pace 0.5 -o live.graph                a survey as it is recorded, 2 scans/s
  octo-delta map ros2:/points --fixed-frame map --port /dev/ttyUSB1   clouds and TF from ROS 2
  octo-delta view --port /dev/ttyUSB0 --ros2 -o view.ot    the view on ROS 2 too (RViz: Octomap)

Any output may be - (standard output), one per run. SIGINT, SIGTERM or SIGHUP stop a build
after its current scan: the stream holds every whole message so far, --bt/--ot the map so far;
they stop map (its --ot/--bt whole) and view (its -o, --mcap and --metrics written).

Exit codes: 0 ok, 2 bad usage or bad input (the message names the file and the offset),
130/143/129 a build stopped by SIGINT/SIGTERM/SIGHUP.";

/// The progress bar of a build.
pub const PROGRESS: &str = "scan {pos}/{len} [{bar:30}] {elapsed_precise} (eta {eta})";

/// Occupancy maps (OctoMap-compatible) whose changes stream over a narrow link.
///
/// `build` inserts point clouds into an octree exactly as OctoMap does (same maps, same .bt and
/// .ot files) and writes, after each scan, one message with what changed: newly occupied and
/// newly free voxels, at full resolution with colour inside the region of interest, at a
/// coarse depth without colour outside it. `apply` rebuilds the operator's view from the
/// stream, `dump` lists it, `full` sends a whole map. The stream format is in
/// docs/octo-delta-format.md.
#[derive(Parser, Debug)]
#[command(version, after_help = EXAMPLES)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Build the map from point clouds and write the delta stream.
    Build(Box<BuildArgs>),
    /// Apply a delta stream: write the operator's view as a .ot file and/or a Foxglove MCAP.
    Apply(ApplyArgs),
    /// List a delta stream's messages.
    Dump(DumpArgs),
    /// A whole map (.ot or .bt) as a one-message stream (the operator's "full map" request).
    Full(FullArgs),
    /// Write a synthetic seabed survey (scans with poses) as a .graph or MCAP file.
    Synth(SynthArgs),
    /// On the vehicle: map clouds as they come and stream the changes over a link to `view`,
    /// answering the operator's requests.
    Map(Box<MapArgs>),
    /// On the operator's side: the live view of `map`'s stream (a .ot at exit, Foxglove live,
    /// an MCAP), and the operator's requests to the vehicle.
    View(Box<ViewRunArgs>),
}

fn coordinate() -> value::RealParser {
    value::real(-COORDINATE_MAX_M, COORDINATE_MAX_M, "m")
}

fn roi(text: &str) -> Result<Roi, String> {
    let v = value::tuple::<6>(coordinate()).parse(text)?;
    let roi = Roi {
        min_m: [v[0], v[1], v[2]],
        max_m: [v[3], v[4], v[5]],
    };
    rovlink_mapper::pipeline::check_roi(&roi).map_err(|e| format!("expected {}", e.expected))?;
    Ok(roi)
}

fn input_format(text: &str) -> Result<InputFormat, String> {
    text.parse()
}

/// `--format`'s help, naming every input format.
fn format_help() -> String {
    let names = InputFormat::names();
    format!("Input format, when the file name does not tell: {names}")
}

fn dump_format(text: &str) -> Result<DumpFormat, String> {
    text.parse()
}

/// The view the operator gets: coarse depth and region of interest.
#[derive(Args, Debug, Clone)]
pub struct ViewArgs {
    /// Region of interest x0,y0,z0,x1,y1,z1 in metres: voxels there are sent at full resolution
    /// with colour [default: everywhere, as in the paper's experiment].
    #[arg(long, value_name = "BOX", value_parser = roi, allow_hyphen_values = true)]
    pub roi: Option<Roi>,

    /// Depth of the coarse voxels sent outside the ROI (1..=16; 13 = 8x the fine edge).
    #[arg(long, value_name = "D", default_value_t = 13,
          value_parser = value::count(1, 16), conflicts_with = "coarse_res", allow_hyphen_values = true)]
    pub coarse_depth: u64,

    /// Coarse voxel edge in metres instead of a depth (rounded to the nearest power-of-two
    /// multiple of --res, at most 2^15 x --res).
    #[arg(long, value_name = "M",
          value_parser = value::positive(RESOLUTION_MAX_M * COARSE_FACTOR_MAX, "m"), allow_hyphen_values = true)]
    pub coarse_res: Option<f64>,
}

impl ViewArgs {
    /// The coarse voxels asked for.
    pub fn coarse(&self) -> Coarse {
        match self.coarse_res {
            Some(m) => Coarse::Edge(m),
            None => Coarse::Depth(self.coarse_depth as u32),
        }
    }
}

/// How clouds go into the map, and the view the operator gets: `build` and `map` alike.
#[derive(Args, Debug)]
pub struct MapConfigArgs {
    /// Voxel edge in metres.
    #[arg(long, value_name = "M", default_value_t = 0.1,
          value_parser = value::real(RESOLUTION_MIN_M, RESOLUTION_MAX_M, "m"), allow_hyphen_values = true)]
    pub res: f64,

    #[command(flatten)]
    pub view: ViewArgs,

    /// Rays longer than this (metres) mark free space up to this range only, no hit (OctoMap's
    /// maxrange) [default: no limit].
    #[arg(long, value_name = "M", value_parser = value::positive(MAX_RANGE_M, "m"), allow_hyphen_values = true)]
    pub max_range: Option<f64>,

    /// Input format, when the file name does not tell (its help lists `InputFormat::names()`).
    #[arg(long, value_name = "FORMAT", value_parser = input_format, help = format_help())]
    pub format: Option<InputFormat>,

    /// Sensor origin x,y,z (metres) for inputs without a pose (PLY, XYZ, PCD without VIEWPOINT,
    /// a bag without TF or pose topic: without --origin such a bag is refused).
    #[arg(long, value_name = "XYZ", value_parser = value::tuple::<3>(coordinate()),
          allow_hyphen_values = true)]
    pub origin: Option<[f64; 3]>,

    /// Bags: the sensor_msgs/msg/PointCloud2 topic [default: the first one].
    #[arg(long, value_name = "TOPIC")]
    pub cloud_topic: Option<String>,

    /// Bags: the sensor's pose from this topic instead of TF: geometry_msgs/msg/PoseStamped,
    /// geometry_msgs/msg/TransformStamped or nav_msgs/msg/Odometry, interpolated at each cloud's
    /// stamp [default: /tf + /tf_static when the bag has them, else the first PoseStamped topic].
    #[arg(long, value_name = "TOPIC")]
    pub pose_topic: Option<String>,

    /// Bags posed by TF: the frame the map is built in; each cloud's header.frame_id is looked
    /// up in it at the cloud's stamp [default: the root of the TF tree].
    #[arg(long, value_name = "FRAME")]
    pub fixed_frame: Option<String>,

    /// Ignore colours (build an OcTree, not a ColorOcTree).
    #[arg(long)]
    pub no_color: bool,

    /// Also resend an occupied voxel when its colour changes (a brighter point, or pruning
    /// averaging it as OctoMap's ColorOcTree does); by default a voxel's colour is sent once,
    /// when it becomes occupied, as in the paper.
    #[arg(long, conflicts_with = "no_color")]
    pub color_updates: bool,

    /// Threads casting scans' rays, a scan each (the last one's rays shared by all); one of
    /// them also puts the cast scans into the map, in order [default: the machine's cores, at
    /// most 8]. The inputs are read on a thread of their own, a few scans ahead; the stream is
    /// the same at any count, each scan's message written as soon as the scan is whole.
    #[arg(long, value_name = "N", value_parser = value::CountParser {
        min: 1, max: THREADS_MAX as u64, unit: "threads" }, allow_hyphen_values = true)]
    pub threads: Option<u64>,

    /// Most cells one scan's rays may cross, counted before casting from the points'
    /// distances to the sensor and --res (with --max-range): a scan over it stops the build
    /// (exit 2, its cells named) rather than exhaust memory. The default, 2^28, is a few GiB of
    /// cell sets and new voxels at worst; a real sensor at a sane resolution stays far below
    /// it (12 288 rays of 20 m at 0.1 m: about 4 M), a resolution too fine for the range
    /// (0.1 mm over metres) does not.
    #[arg(long, value_name = "N", default_value_t = CELLS_PER_SCAN_DEFAULT,
          value_parser = value::CountParser { min: 1, max: 1 << 40, unit: "cells" },
          allow_hyphen_values = true)]
    pub max_cells: u64,

    /// ros2: inputs: the DDS domain to join [default: ROS_DOMAIN_ID, else 0].
    #[arg(long, value_name = "ID", value_parser = value::count(0, rovlink_ros2::names::MAX_DOMAIN_ID as u64))]
    pub ros2_domain: Option<u64>,

    /// ros2: inputs: the cloud topic's reliability; best-effort also hears publishers using
    /// ROS 2's sensor-data profile, reliable loses none from reliable publishers.
    #[arg(long, value_name = "QOS", default_value = "reliable", value_parser = ["reliable", "best-effort"])]
    pub ros2_reliability: String,

    /// ros2: inputs with --pose-topic: its type, geometry_msgs/msg/PoseStamped,
    /// geometry_msgs/msg/TransformStamped or nav_msgs/msg/Odometry.
    #[arg(
        long,
        value_name = "TYPE",
        default_value = "geometry_msgs/msg/PoseStamped"
    )]
    pub ros2_pose_type: String,

    /// ros2: inputs: how long a cloud waits for the transforms at its stamp before it is
    /// skipped (one warning per reason), seconds.
    #[arg(long, value_name = "S", default_value_t = 1.0,
          value_parser = value::seconds(0.0, 3600.0), allow_hyphen_values = true)]
    pub ros2_tf_wait: f64,
}

/// Where the octo-delta's ros2: inputs say their problems.
fn ros2_warning(line: &str) {
    eprintln!("octo-delta: warning: {line}");
}

impl MapConfigArgs {
    /// The library's build configuration of these flags.
    pub fn config(&self) -> BuildConfig {
        BuildConfig {
            resolution_m: self.res,
            coarse: self.view.coarse(),
            roi: self.view.roi,
            max_range_m: self.max_range,
            format: self.format,
            origin_m: self.origin,
            mcap: McapOptions {
                cloud_topic: self.cloud_topic.clone(),
                pose_topic: self.pose_topic.clone(),
            },
            fixed_frame: self.fixed_frame.clone(),
            no_color: self.no_color,
            color_updates: self.color_updates,
            threads: self.threads.map(|t| t as usize),
            max_cells_per_scan: self.max_cells,
            ros2: Ros2Input {
                domain: self.ros2_domain.map(|d| d as u16),
                reliability: rovlink_ros2::Reliability::from_name(&self.ros2_reliability)
                    .unwrap_or(rovlink_ros2::Reliability::Reliable),
                pose_type: self.ros2_pose_type.clone(),
                tf_wait_s: self.ros2_tf_wait,
                warn: ros2_warning,
            },
            one_pass_bags: false,
        }
    }
}

#[derive(Args, Debug)]
pub struct BuildArgs {
    /// Point clouds: OctoMap .graph, PCD, PLY, XYZ, or a ROS 2 bag: MCAP (chunks zstd, lz4 or
    /// none) or rosbag2 (the directory, its metadata.yaml or a .db3) with PointCloud2 clouds
    /// posed by /tf + /tf_static or a pose topic; - for standard input; ros2:TOPIC for a live
    /// ROS 2 PointCloud2 topic posed the same way, read until SIGINT/SIGTERM. When every input
    /// and output is a file, a bag is read in one pass (clouds posed as their transforms come, at most 32
    /// clouds or 8 Mi points waiting) and checked at its end; one whose transforms come out of
    /// stamp order or too late is built again, every transform read first (said once).
    #[arg(required = true, value_name = "INPUT")]
    pub inputs: Vec<PathBuf>,

    #[command(flatten)]
    pub map: MapConfigArgs,

    /// The delta stream [default: standard output].
    #[arg(short, long, value_name = "FILE", default_value = "-")]
    pub output: PathBuf,

    /// One CSV row per scan (one whole line each, flushed): points, message bytes, list sizes,
    /// and what sending the full map would cost (computing the .bt size takes a copy of the
    /// map per scan).
    #[arg(long, value_name = "FILE")]
    pub stats: Option<PathBuf>,

    /// Write the build's figures (scans, points, times, map and stream sizes; with --link the
    /// transfer's latencies under `link`) as one line of JSON that also carries every parameter
    /// of the run and its seed (`-`: standard output, then give -o a file).
    #[arg(long, value_name = "FILE")]
    pub metrics: Option<PathBuf>,

    /// Write the final map as OctoMap's maximum-likelihood .bt.
    #[arg(long, value_name = "FILE")]
    pub bt: Option<PathBuf>,

    /// Write the final map as OctoMap's .ot (a ColorOcTree when the input has colour).
    #[arg(long, value_name = "FILE")]
    pub ot: Option<PathBuf>,

    /// Send each scan's message over this link model in virtual time (reliable, shaped to 85%
    /// of the link rate) and report when each scan reached the operator.
    #[arg(long, value_name = "MODEL")]
    pub link: Option<String>,

    /// With --link: seconds between scans.
    #[arg(long, value_name = "S", default_value_t = 1.0, requires = "link",
          value_parser = value::seconds(0.0, transfer::MAX_PERIOD_S), allow_hyphen_values = true)]
    pub scan_period: f64,

    /// With --link: one CSV row per scan: bytes, when it was ready, complete and shown.
    #[arg(long, value_name = "FILE", requires = "link")]
    pub arrivals: Option<PathBuf>,

    /// With --link: seed of the link's random streams.
    #[arg(
        long,
        default_value_t = 1,
        requires = "link",
        allow_hyphen_values = true
    )]
    pub seed: u64,

    /// No progress bar, no summary.
    #[arg(short, long)]
    pub quiet: bool,
}

impl BuildArgs {
    /// The library's build configuration of these flags.
    pub fn config(&self) -> BuildConfig {
        self.map.config()
    }
}

fn device(text: &str) -> Result<DeviceSpec, String> {
    text.parse::<DeviceSpec>().map_err(|e| e.to_string())
}

/// The link both ends share: device, addresses, model and transport timing.
#[derive(Args, Debug)]
pub struct LinkArgs {
    /// The link's device: a serial port or PTY path, serial:PATH:BAUD, tcp:HOST:PORT,
    /// tcpin:HOST:PORT, udp:BIND=PEER, udpin:HOST:PORT or udpout:HOST:PORT (each segment is one
    /// wire.md link frame).
    #[arg(long, value_name = "DEV", value_parser = device)]
    pub port: DeviceSpec,

    /// Baud rate of a serial port given as a bare path.
    #[arg(long, value_name = "BPS", default_value_t = 115_200,
          value_parser = value::count(50, 4_000_000), allow_hyphen_values = true)]
    pub baud: u64,

    /// The link's model (a preset such as satellite-up, or a model file): its bit rate and
    /// delay set the shaper and the resend timeout.
    #[arg(long, value_name = "MODEL", default_value = "satellite-up")]
    pub model: String,

    /// Resend timeout in milliseconds [default: twice the model's round trip plus 50 ms].
    #[arg(long, value_name = "MS", value_parser = value::millis(1.0, 3_600_000.0), allow_hyphen_values = true)]
    pub rto_ms: Option<f64>,
}

#[derive(Args, Debug)]
pub struct MapArgs {
    /// Point clouds, as `build` takes them; a .graph may be a pipe (-), a FIFO, or with
    /// --follow a file still being written; ros2:TOPIC is a live ROS 2 PointCloud2 topic posed
    /// by /tf + /tf_static (or --pose-topic).
    #[arg(required = true, value_name = "INPUT")]
    pub inputs: Vec<PathBuf>,

    #[command(flatten)]
    pub map: MapConfigArgs,

    #[command(flatten)]
    pub link: LinkArgs,

    /// Read input files as they grow (as tail -f does), until the scans the .graph announces
    /// have come or the mapper is stopped.
    #[arg(long)]
    pub follow: bool,

    /// Shaped rate of the stream on the link, bit/s, framing included [default: 85% of the
    /// model's bit rate, the rest left for resends].
    #[arg(long, value_name = "BPS", value_parser = value::positive(1e10, "bit/s"), allow_hyphen_values = true)]
    pub rate: Option<f64>,

    /// The most bytes of messages waiting to be sent; past it they are replaced by one full
    /// map (no change is lost) [default: 30 s of the shaped rate, at least 256 KiB].
    #[arg(long, value_name = "BYTES", value_parser = value::count(4096, 1 << 32), allow_hyphen_values = true)]
    pub backlog_bytes: Option<u64>,

    /// End once the inputs are read and the operator has acknowledged everything [default:
    /// keep answering the operator's requests until stopped].
    #[arg(long)]
    pub exit_when_done: bool,

    /// With --exit-when-done: once the inputs are read, end anyway after this many seconds
    /// without any acknowledgement (the view has gone), saying what was left unacknowledged.
    #[arg(long, value_name = "S", default_value_t = 60.0, requires = "exit_when_done",
          value_parser = value::seconds(0.0, 86_400.0), allow_hyphen_values = true)]
    pub linger: f64,

    /// This vehicle's link address (1..=14); the operator is 0.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = value::count(1, 14))]
    pub address: u64,

    /// Write the map as OctoMap's .bt at exit (also when stopped).
    #[arg(long, value_name = "FILE")]
    pub bt: Option<PathBuf>,

    /// Write the map as OctoMap's .ot at exit (also when stopped).
    #[arg(long, value_name = "FILE")]
    pub ot: Option<PathBuf>,

    /// One CSV row per scan, flushed as it goes: arrival time, points, message bytes, bytes on
    /// the link with the transport, and the full map's .bt size (a copy of the map per scan).
    #[arg(long, value_name = "FILE")]
    pub stats: Option<PathBuf>,

    /// The run's figures as one line of JSON at exit: scans, transport (segments, resends,
    /// link bytes, use of the shaped rate), requests answered, bad bytes counted.
    #[arg(long, value_name = "FILE")]
    pub metrics: Option<PathBuf>,

    /// Say nothing but warnings.
    #[arg(short, long)]
    pub quiet: bool,
}

#[derive(Args, Debug)]
pub struct ViewRunArgs {
    #[command(flatten)]
    pub link: LinkArgs,

    /// The view as a .ot file, written at exit (also when stopped) and on a {"type":"save"}
    /// order.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,

    /// Record the view as it grew: foxglove.SceneUpdate on /octo_delta/view, the pose on
    /// /octo_delta/vehicle and the log on /octo_delta/log, committed at exit.
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,

    /// One CSV row per message applied, at exit: scan, kind, bytes, when its scan came to the
    /// mapper, when it was shown, latency.
    #[arg(long, value_name = "FILE")]
    pub arrivals: Option<PathBuf>,

    /// The run's figures as one line of JSON at exit: messages, latencies (p50/p95/max),
    /// requests and how fast each was answered, transport counters, bad bytes counted.
    #[arg(long, value_name = "FILE")]
    pub metrics: Option<PathBuf>,

    /// Requests to the vehicle, JSON Lines (a file or a FIFO; yours, not writable by group or
    /// others): {"type":"full"}, {"type":"full","box":[x0,y0,z0,x1,y1,z1]},
    /// {"type":"roi","box":[...]} or null, {"type":"coarse_depth","depth":12},
    /// {"type":"resync"}, and {"type":"save"} (write -o now).
    #[arg(long, value_name = "FILE")]
    pub orders: Option<PathBuf>,

    /// Serve the live view to Foxglove on HOST:PORT (loopback unless you say otherwise),
    /// e.g. --foxglove 127.0.0.1:8765. The port carries at most 256 connections, 8 from one
    /// address (in handshake or open), each upgrade request whole within 5 s of connecting;
    /// one more, or one slower, is closed and said once per address.
    #[arg(long, value_name = "HOST:PORT")]
    pub foxglove: Option<String>,

    /// With --foxglove: the control token file (as tdma-run's; yours, mode 0600): clients
    /// whose URL carries ?token= may publish requests on /octo_delta/requests; the others view.
    #[arg(long, value_name = "FILE", requires = "foxglove")]
    pub foxglove_token_file: Option<PathBuf>,

    /// With --foxglove: also let browser pages from this Origin connect (repeatable).
    #[arg(long, value_name = "ORIGIN", requires = "foxglove")]
    pub foxglove_origin: Vec<String>,

    /// With --foxglove-token-file on an address other than loopback: serve control over
    /// plain ws:// anyway.
    #[arg(long, requires = "foxglove_token_file")]
    pub foxglove_insecure: bool,

    /// With --foxglove: serve wss:// with this PEM certificate and --foxglove-tls-key.
    #[arg(long, value_name = "FILE", requires_all = ["foxglove", "foxglove_tls_key"])]
    pub foxglove_tls_cert: Option<PathBuf>,

    /// The private key of --foxglove-tls-cert (PEM; yours, mode 0600).
    #[arg(long, value_name = "FILE", requires = "foxglove_tls_cert")]
    pub foxglove_tls_key: Option<PathBuf>,

    /// End once a message after this scan number is applied (a survey of N scans: N - 1)
    /// [default: run until stopped].
    #[arg(long, value_name = "N", value_parser = value::count(0, u32::MAX as u64))]
    pub exit_after_scan: Option<u64>,

    /// The mapper's link address (1..=14); this end is 0, the operator.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = value::count(1, 14))]
    pub mapper_address: u64,

    /// Say nothing but warnings.
    #[arg(short, long)]
    pub quiet: bool,

    #[command(flatten)]
    pub ros2: Ros2ViewArgs,
}

/// The view on a ROS 2 graph.
#[derive(Args, Debug)]
pub struct Ros2ViewArgs {
    /// Publish the view on ROS 2: an octomap_msgs/msg/Octomap (binary OcTree, for RViz's
    /// occupancy display) and a coloured sensor_msgs/msg/PointCloud2 of the occupied voxels'
    /// centres, reliable and transient-local (keep-last 1): a viewer started late gets the
    /// latest map. These topics move nothing: the view takes no orders from ROS 2.
    #[arg(long)]
    pub ros2: bool,

    /// With --ros2: the DDS domain [default: ROS_DOMAIN_ID, else 0].
    #[arg(long, value_name = "ID", requires = "ros2",
          value_parser = value::count(0, rovlink_ros2::names::MAX_DOMAIN_ID as u64))]
    pub ros2_domain: Option<u64>,

    /// With --ros2: the binary OcTree's topic.
    #[arg(
        long,
        value_name = "TOPIC",
        requires = "ros2",
        default_value = "/octo_delta/octomap"
    )]
    pub ros2_octomap_topic: String,

    /// With --ros2: also publish the full map (a ColorOcTree when it has colour, every node's
    /// probability) on this topic.
    #[arg(long, value_name = "TOPIC", requires = "ros2")]
    pub ros2_full_topic: Option<String>,

    /// With --ros2: the voxel-centre cloud's topic.
    #[arg(
        long,
        value_name = "TOPIC",
        requires = "ros2",
        default_value = "/octo_delta/voxels"
    )]
    pub ros2_voxels_topic: String,

    /// With --ros2: the frame_id of the map's messages.
    #[arg(long, value_name = "FRAME", requires = "ros2", default_value = "map")]
    pub ros2_frame: String,

    /// With --ros2: the least time between two maps published, seconds (the last one is
    /// always published).
    #[arg(long, value_name = "S", requires = "ros2", default_value_t = 1.0,
          value_parser = value::seconds(0.0, 3600.0), allow_hyphen_values = true)]
    pub ros2_period: f64,
}

#[derive(Args, Debug)]
pub struct ApplyArgs {
    /// The delta stream [default: standard input].
    #[arg(default_value = "-")]
    pub input: PathBuf,
    /// The view, as a .ot file ("-" for standard output); required unless --mcap is given.
    #[arg(short, long, value_name = "FILE", required_unless_present = "mcap")]
    pub output: Option<PathBuf>,
    /// Apply only the first N messages.
    #[arg(long, value_name = "N", value_parser = value::count(0, MAX_COUNT), allow_hyphen_values = true)]
    pub messages: Option<u64>,
    /// Also write the view as it grew, for Foxglove: an MCAP file with one foxglove.SceneUpdate
    /// (JSON) per message on /octo_delta/view, coloured cubes for fine voxels, translucent grey
    /// ones for coarse voxels, logged when the operator got the message.
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// With --mcap: the CSV of build --link --arrivals; message k is logged at its row's
    /// t_shown_s (when it and every earlier message had arrived).
    #[arg(long, value_name = "FILE", requires = "mcap")]
    pub arrivals: Option<PathBuf>,
    /// With --mcap and no --arrivals: seconds between messages (message k logged at k x S).
    #[arg(long, value_name = "S", default_value_t = 1.0, requires = "mcap", conflicts_with = "arrivals",
          value_parser = value::seconds(0.0, transfer::MAX_PERIOD_S), allow_hyphen_values = true)]
    pub scan_period: f64,
}

#[derive(Args, Debug)]
pub struct DumpArgs {
    /// The delta stream [default: standard input].
    #[arg(default_value = "-")]
    pub input: PathBuf,
    /// Output form: text, ndjson or csv.
    #[arg(short, long, value_parser = dump_format, default_value = "text")]
    pub format: DumpFormat,
    /// List every voxel (text and ndjson), not only the counts.
    #[arg(long)]
    pub voxels: bool,
    /// Where the listing goes [default: standard output].
    #[arg(short, long, value_name = "FILE", default_value = "-")]
    pub output: PathBuf,
}

#[derive(Args, Debug)]
pub struct FullArgs {
    /// The map: .ot (OcTree or ColorOcTree) or .bt.
    pub input: PathBuf,
    #[command(flatten)]
    pub view: ViewArgs,
    /// The one-message stream [default: standard output].
    #[arg(short, long, value_name = "FILE", default_value = "-")]
    pub output: PathBuf,
}

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// The survey file: a .graph (no colour), or with --format mcap (or a .mcap name) an MCAP of
    /// coloured sensor_msgs/msg/PointCloud2 scans with geometry_msgs/msg/PoseStamped poses
    /// [default: standard output].
    #[arg(short, long, value_name = "FILE", default_value = "-")]
    pub output: PathBuf,
    /// Output format [default: from the file name, else graph].
    #[arg(long, value_enum)]
    pub format: Option<SynthFormat>,
    /// Number of scans [default: the survey's own, 80].
    #[arg(long, value_parser = value::CountParser {
        min: 1, max: synth::MAX_SCANS as u64, unit: "scans" }, allow_hyphen_values = true)]
    pub scans: Option<u64>,
    /// Seed of the scene and the path.
    #[arg(long, default_value_t = 1, allow_hyphen_values = true)]
    pub seed: u64,

    /// Write a .graph as a survey being recorded: the node count, then one scan every S
    /// seconds, each flushed as it is written (to feed `map` live); the file is written in
    /// place, not committed at the end.
    #[arg(long, value_name = "S", conflicts_with = "format",
          value_parser = value::seconds(0.0, 3600.0), allow_hyphen_values = true)]
    pub pace: Option<f64>,
}

impl SynthArgs {
    /// The survey these flags ask for.
    pub fn params(&self) -> synth::SurveyParams {
        synth::SurveyParams {
            seed: self.seed,
            scans: self
                .scans
                .map_or(synth::SurveyParams::default().scans, |n| {
                    usize::try_from(n).unwrap_or(usize::MAX)
                }),
            ..synth::SurveyParams::default()
        }
    }

    /// Whether to write MCAP: --format mcap, or a .mcap name without --format.
    pub fn mcap(&self) -> bool {
        let by_name = self
            .output
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
        self.format.map_or(by_name, |f| f == SynthFormat::Mcap)
    }
}

#[derive(ValueEnum, Debug, Clone, Copy, PartialEq)]
pub enum SynthFormat {
    Graph,
    Mcap,
}
