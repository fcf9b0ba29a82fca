//! octo-delta: an OctoMap-compatible occupancy map built from point clouds, whose changes stream
//! over a narrow link (fine and coloured inside a region of interest, coarse outside).
#![forbid(unsafe_code)]

use std::fs::File;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Result, bail};
use clap::{Args as ClapArgs, Parser, Subcommand, ValueEnum};
use rovlink::io::{AtomicFile, EXIT_OK, Input, IoError, Output};
use rovlink::octo::cloud::{self, CloudFormat, McapOptions};
use rovlink::octo::delta::{self, Message, Receiver, Roi, Sender, ViewSpec};
use rovlink::octo::tree::{OcTree, TREE_DEPTH};
use rovlink::octo::{ParseError, Scan, files, graph, synth};

const TOOL: &str = "octo-delta";

macro_rules! say {
    ($($arg:tt)*) => {
        rovlink::io::warn(TOOL, &format!($($arg)*))
    };
}

const EXAMPLES: &str = "\
Examples:
  octo-delta synth -o survey.graph                     a synthetic seabed survey to try things on
  octo-delta synth -o survey.mcap                      the same, coloured, as ROS 2 MCAP
  octo-delta build survey.graph --res 0.1 -o deltas.odl --stats bandwidth.csv --ot map.ot
  octo-delta build scan*.pcd --roi -2,-2,-5,2,2,0 --coarse-depth 13 -o deltas.odl
  octo-delta build survey.graph -o deltas.odl --link satellite-up   when each scan reaches shore
  octo-delta apply deltas.odl -o view.ot               the operator's view
  octo-delta dump deltas.odl --format csv              one line per message
  octo-delta full map.ot --roi -1,-1,-1,1,1,1 -o full.odl

Exit codes: 0 ok, 2 bad usage or bad input (the message names the file and the offset).";

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
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Build the map from point clouds and write the delta stream.
    Build(Box<BuildArgs>),
    /// Apply a delta stream: write the operator's view as a .ot file.
    Apply(ApplyArgs),
    /// List a delta stream's messages.
    Dump(DumpArgs),
    /// A whole map (.ot or .bt) as a one-message stream (the operator's "full map" request).
    Full(FullArgs),
    /// Write a synthetic seabed survey (scans with poses) as a .graph or MCAP file.
    Synth(SynthArgs),
}

/// The view the operator gets: coarse depth and region of interest.
#[derive(ClapArgs, Debug, Clone)]
struct ViewArgs {
    /// Region of interest x0,y0,z0,x1,y1,z1 in metres: voxels there are sent at full resolution
    /// with colour [default: everywhere, as in the paper's experiment].
    #[arg(long, value_name = "BOX", value_parser = parse_roi, allow_hyphen_values = true)]
    roi: Option<Roi>,

    /// Depth of the coarse voxels sent outside the ROI (1..=16; 13 = 8x the fine edge).
    #[arg(long, value_name = "D", default_value_t = 13,
          value_parser = clap::value_parser!(u32).range(1..=16), conflicts_with = "coarse_res")]
    coarse_depth: u32,

    /// Coarse voxel edge in metres instead of a depth (rounded to the nearest power-of-two
    /// multiple of --res).
    #[arg(long, value_name = "M")]
    coarse_res: Option<f64>,
}

impl ViewArgs {
    fn spec(&self, resolution_m: f64) -> Result<ViewSpec> {
        let coarse_depth = match self.coarse_res {
            None => self.coarse_depth,
            Some(m) => {
                if !(m.is_finite() && m >= resolution_m) {
                    bail!(usage(format!(
                        "--coarse-res {m}: expected a size >= the resolution {resolution_m} m"
                    )));
                }
                let k = (m / resolution_m).log2().round();
                if k > 15.0 {
                    bail!(usage(format!(
                        "--coarse-res {m}: at most 2^15 x the resolution ({} m)",
                        resolution_m * 32768.0
                    )));
                }
                TREE_DEPTH - k.max(0.0) as u32
            }
        };
        Ok(ViewSpec {
            resolution_m,
            coarse_depth,
            roi: self.roi,
        })
    }
}

#[derive(ClapArgs, Debug)]
struct BuildArgs {
    /// Point clouds: OctoMap .graph, PCD, PLY, XYZ, or MCAP (ROS 2 PointCloud2 + PoseStamped).
    #[arg(required = true, value_name = "INPUT")]
    inputs: Vec<PathBuf>,

    /// Voxel edge in metres.
    #[arg(long, value_name = "M", default_value_t = 0.1)]
    res: f64,

    #[command(flatten)]
    view: ViewArgs,

    /// Rays longer than this (metres) mark free space up to this range only, no hit (OctoMap's
    /// maxrange) [default: no limit].
    #[arg(long, value_name = "M")]
    max_range: Option<f64>,

    /// The delta stream ("-" for standard output).
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,

    /// One CSV row per scan (flushed as it goes): points, message bytes, list sizes, and what
    /// sending the full map would cost (computing the .bt size takes a copy of the map per scan).
    #[arg(long, value_name = "FILE")]
    stats: Option<PathBuf>,

    /// Write the final map as OctoMap's maximum-likelihood .bt.
    #[arg(long, value_name = "FILE")]
    bt: Option<PathBuf>,

    /// Write the final map as OctoMap's .ot (a ColorOcTree when the input has colour).
    #[arg(long, value_name = "FILE")]
    ot: Option<PathBuf>,

    /// Input format, when the file name does not tell.
    #[arg(long, value_enum)]
    format: Option<InputFormat>,

    /// Sensor origin x,y,z (metres) for inputs without a pose (PLY, XYZ, PCD without VIEWPOINT).
    #[arg(long, value_name = "XYZ", value_parser = parse_xyz, allow_hyphen_values = true)]
    origin: Option<[f32; 3]>,

    /// MCAP: the sensor_msgs/msg/PointCloud2 topic [default: the first one].
    #[arg(long, value_name = "TOPIC")]
    cloud_topic: Option<String>,

    /// MCAP: the geometry_msgs/msg/PoseStamped topic with the sensor's pose [default: the first].
    #[arg(long, value_name = "TOPIC")]
    pose_topic: Option<String>,

    /// Ignore colours (build an OcTree, not a ColorOcTree).
    #[arg(long)]
    no_color: bool,

    /// Also resend an occupied voxel when a brighter colour is found for it (by default a
    /// voxel's colour is sent once, when it becomes occupied, as in the paper).
    #[arg(long, conflicts_with = "no_color")]
    color_updates: bool,

    /// Send each scan's message over this link model in virtual time (reliable, shaped to 85%
    /// of the link rate) and report when each scan reached the operator.
    #[arg(long, value_name = "MODEL")]
    link: Option<String>,

    /// With --link: seconds between scans.
    #[arg(long, value_name = "S", default_value_t = 1.0, requires = "link")]
    scan_period: f64,

    /// With --link: one CSV row per scan: bytes, when it was ready, complete and shown.
    #[arg(long, value_name = "FILE", requires = "link")]
    arrivals: Option<PathBuf>,

    /// With --link: seed of the link's random streams.
    #[arg(long, default_value_t = 1, requires = "link")]
    seed: u64,

    /// Threads casting each scan's rays [default: the machine's cores, at most 8].
    #[arg(long, value_name = "N")]
    threads: Option<usize>,

    /// No progress bar, no summary.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(ValueEnum, Debug, Clone, Copy)]
enum InputFormat {
    Graph,
    Pcd,
    Ply,
    Xyz,
    Mcap,
}

#[derive(ClapArgs, Debug)]
struct ApplyArgs {
    /// The delta stream ("-" for standard input).
    input: Option<PathBuf>,
    /// The view, as a .ot file ("-" for standard output).
    #[arg(short, long, value_name = "FILE", required = true)]
    output: PathBuf,
    /// Apply only the first N messages.
    #[arg(long, value_name = "N")]
    messages: Option<usize>,
}

#[derive(ValueEnum, Debug, Clone, Copy, PartialEq)]
enum DumpFormat {
    Text,
    Ndjson,
    Csv,
}

#[derive(ClapArgs, Debug)]
struct DumpArgs {
    /// The delta stream ("-" for standard input).
    input: Option<PathBuf>,
    /// Output form.
    #[arg(short, long, value_enum, default_value_t = DumpFormat::Text)]
    format: DumpFormat,
    /// List every voxel (text and ndjson), not only the counts.
    #[arg(long)]
    voxels: bool,
}

#[derive(ClapArgs, Debug)]
struct FullArgs {
    /// The map: .ot (OcTree or ColorOcTree) or .bt.
    input: PathBuf,
    #[command(flatten)]
    view: ViewArgs,
    /// The one-message stream.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,
}

#[derive(ClapArgs, Debug)]
struct SynthArgs {
    /// The survey file: a .graph (no colour), or with --format mcap (or a .mcap name) an MCAP of
    /// coloured sensor_msgs/msg/PointCloud2 scans with geometry_msgs/msg/PoseStamped poses.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,
    /// Output format [default: from the file name, else graph].
    #[arg(long, value_enum)]
    format: Option<SynthFormat>,
    /// Number of scans [default: the survey's own].
    #[arg(long)]
    scans: Option<usize>,
    /// Seed of the scene and the path.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

#[derive(ValueEnum, Debug, Clone, Copy, PartialEq)]
enum SynthFormat {
    Graph,
    Mcap,
}

#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct UsageError(String);

fn usage(message: String) -> anyhow::Error {
    anyhow::Error::new(UsageError(message))
}

fn parse_numbers(s: &str, n: usize) -> Result<Vec<f64>, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected {n} comma-separated numbers, found {s:?}"))?;
    if v.len() != n || v.iter().any(|x| !x.is_finite()) {
        return Err(format!(
            "expected {n} comma-separated finite numbers, found {s:?}"
        ));
    }
    Ok(v)
}

fn parse_roi(s: &str) -> Result<Roi, String> {
    let v = parse_numbers(s, 6)?;
    let (min_m, max_m) = ([v[0], v[1], v[2]], [v[3], v[4], v[5]]);
    if (0..3).any(|i| min_m[i] > max_m[i]) {
        return Err(format!("x0,y0,z0 must not exceed x1,y1,z1, found {s:?}"));
    }
    Ok(Roi { min_m, max_m })
}

fn parse_xyz(s: &str) -> Result<[f32; 3], String> {
    let v = parse_numbers(s, 3)?;
    Ok([v[0] as f32, v[1] as f32, v[2] as f32])
}

fn format_of(path: &Path, bytes: &[u8], forced: Option<InputFormat>) -> Option<InputFormat> {
    if let Some(f) = forced {
        return Some(f);
    }
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("graph"))
    {
        return Some(InputFormat::Graph);
    }
    let f = CloudFormat::from_path(path).or_else(|| cloud::sniff(bytes))?;
    Some(match f {
        CloudFormat::Pcd => InputFormat::Pcd,
        CloudFormat::Ply => InputFormat::Ply,
        CloudFormat::Xyz => InputFormat::Xyz,
        CloudFormat::Mcap => InputFormat::Mcap,
    })
}

/// The scans of one input, one at a time (a `.graph` file is streamed from disk, so a large
/// survey never sits in memory whole), how many there will be, and whether the format carries
/// poses (`.graph`, MCAP) or not (PCD without VIEWPOINT, PLY, XYZ: `--origin` applies).
type ScanSource = (
    Box<dyn Iterator<Item = Result<Scan, ParseError>>>,
    usize,
    bool,
);

fn open_scans(path: &Path, args: &BuildArgs) -> Result<ScanSource> {
    let name = path.display().to_string();
    let forced_graph = matches!(args.format, Some(InputFormat::Graph));
    let by_name = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("graph"));
    if (forced_graph || (by_name && args.format.is_none())) && !rovlink::io::is_std(Some(path)) {
        let file = File::open(path).map_err(|source| IoError::Open {
            path: path.to_path_buf(),
            source,
        })?;
        let len = file.metadata().map(|m| m.len()).unwrap_or(u64::MAX);
        let stream =
            graph::ScanStream::new(file, len).map_err(|e| usage(format!("{name}: {e}")))?;
        let n = stream.node_count() as usize;
        return Ok((Box::new(stream), n, true));
    }
    let mut input = Input::open(Some(path))?;
    let bytes = input.read_all()?;
    let format = format_of(path, &bytes, args.format).ok_or_else(|| {
        usage(format!(
            "{name}: unknown input format (expected .graph, .pcd, .ply, .xyz or .mcap; or --format)"
        ))
    })?;
    let opts = McapOptions {
        cloud_topic: args.cloud_topic.clone(),
        pose_topic: args.pose_topic.clone(),
    };
    let parsed = match format {
        InputFormat::Graph => graph::read_scans(&bytes),
        InputFormat::Pcd => cloud::read(CloudFormat::Pcd, &bytes, &opts),
        InputFormat::Ply => cloud::read(CloudFormat::Ply, &bytes, &opts),
        InputFormat::Xyz => cloud::read(CloudFormat::Xyz, &bytes, &opts),
        InputFormat::Mcap => cloud::read(CloudFormat::Mcap, &bytes, &opts),
    };
    let scans = parsed.map_err(|e| usage(format!("{name}: {e}")))?;
    let n = scans.len();
    let posed = matches!(format, InputFormat::Graph | InputFormat::Mcap);
    Ok((Box::new(scans.into_iter().map(Ok)), n, posed))
}

/// Inputs without a pose get the sensor origin of `--origin`: the points stay where they are in
/// the map frame, shifted into the sensor frame.
fn with_origin(mut scan: Scan, origin: Option<[f32; 3]>) -> Scan {
    if let Some(o) = origin
        && scan.pose == rovlink::octo::Pose::IDENTITY
    {
        scan.pose.translation_m = o;
        for p in &mut scan.points {
            *p = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        }
    }
    scan
}

const STATS_HEADER: &str = "scan,points,delta_bytes,fine_occupied,fine_free,coarse_occupied,coarse_free,full_bt_bytes,full_ot_bytes,cum_delta_bytes,cum_full_bt_bytes,cum_full_ot_bytes,points_skipped,insert_ms";

/// CSV rows written and flushed one by one.
struct Rows {
    out: File,
    name: String,
}

impl Rows {
    fn open(path: &Path) -> Result<Rows> {
        let out = File::create(path).map_err(|source| IoError::Open {
            path: path.to_path_buf(),
            source,
        })?;
        let mut r = Rows {
            out,
            name: path.display().to_string(),
        };
        r.line(STATS_HEADER)?;
        Ok(r)
    }
    fn line(&mut self, text: &str) -> Result<(), IoError> {
        writeln!(self.out, "{text}")
            .and_then(|()| self.out.flush())
            .map_err(|source| IoError::Write {
                name: self.name.clone(),
                source,
            })
    }
}

fn progress(quiet: bool) -> indicatif::ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(0);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{spinner} scan {pos}/{len} [{bar:30}] {elapsed_precise} (eta {eta}) {msg}",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

fn build(args: &BuildArgs) -> Result<u8> {
    if !(args.res.is_finite() && args.res > 0.0) {
        bail!(usage(format!(
            "--res {}: expected a resolution > 0 m",
            args.res
        )));
    }
    if let Some(r) = args.max_range
        && !(r.is_finite() && r > 0.0)
    {
        bail!(usage(format!("--max-range {r}: expected a range > 0 m")));
    }
    let spec = args.view.spec(args.res)?;
    for (flag, path) in [
        ("--ot", &args.ot),
        ("--bt", &args.bt),
        ("--stats", &args.stats),
        ("--arrivals", &args.arrivals),
    ] {
        file_only(flag, path)?;
    }
    if !(args.scan_period.is_finite()
        && (0.0..=rovlink::octo::transfer::MAX_PERIOD_S).contains(&args.scan_period))
    {
        bail!(usage(format!(
            "--scan-period {}: expected 0..={} s",
            args.scan_period,
            rovlink::octo::transfer::MAX_PERIOD_S
        )));
    }
    let link_model = match &args.link {
        Some(name) => {
            Some(rovlink::octo::transfer::model_by_name(name).map_err(|e| usage(e.to_string()))?)
        }
        None => None,
    };
    let mut out = Output::open(args.output.as_deref(), true)?;
    let mut rows = args.stats.as_deref().map(Rows::open).transpose()?;
    // The tree keeps colours when the first scan has them (a ColorOcTree), unless --no-color.
    let mut tree: Option<OcTree> = None;
    let mut sender = Sender::new(spec);
    sender.set_color_updates(args.color_updates);
    let header = delta::encode_header(&spec);
    out.write_bytes(&header)?;
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get().min(8)));
    let bar = progress(args.quiet);
    let started = Instant::now();
    let (mut scan_no, mut points, mut skipped, mut beyond) = (0u32, 0usize, 0usize, 0usize);
    let (mut cum_delta, mut cum_bt, mut cum_ot) = (0u64, 0u64, 0u64);
    let mut insert_s = 0.0f64;
    let mut messages: Vec<(u32, usize)> = Vec::new();
    for path in &args.inputs {
        let (scans, count, posed) = open_scans(path, args)?;
        bar.inc_length(count as u64);
        for scan in scans {
            let scan = with_origin(
                scan.map_err(|e| usage(format!("{}: {e}", path.display())))?,
                args.origin.filter(|_| !posed),
            );
            let tree = tree.get_or_insert_with(|| {
                let mut t = OcTree::new(args.res);
                t.set_threads(threads);
                if scan.colors.is_some() && !args.no_color {
                    t.enable_color();
                }
                t
            });
            let t0 = Instant::now();
            let up = tree.insert_scan(&scan, args.max_range);
            let d = sender.delta(tree, &up.changes);
            let msg = delta::encode_delta(&spec, scan_no, &d);
            let dt = t0.elapsed().as_secs_f64();
            insert_s += dt;
            out.write_bytes(&msg)?;
            points += up.points;
            skipped += up.points_skipped;
            beyond += up.points_beyond_range;
            cum_delta += msg.len() as u64;
            messages.push((scan_no, msg.len()));
            if let Some(rows) = &mut rows {
                let full_bt = files::write_bt(tree).len() as u64;
                let full_ot = files::ot_size(tree) as u64;
                cum_bt += full_bt;
                cum_ot += full_ot;
                rows.line(&format!(
                    "{scan_no},{},{},{},{},{},{},{full_bt},{full_ot},{cum_delta},{cum_bt},{cum_ot},{},{:.3}",
                    up.points,
                    msg.len(),
                    d.fine_occupied.len(),
                    d.fine_free.len(),
                    d.coarse_occupied.len(),
                    d.coarse_free.len(),
                    up.points_skipped,
                    dt * 1e3
                ))?;
            }
            scan_no += 1;
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    let tree = tree.unwrap_or_else(|| OcTree::new(args.res));
    if let Some(p) = &args.ot {
        AtomicFile::create(p)?.commit_with(&files::write_ot(&tree))?;
    }
    if let Some(p) = &args.bt {
        AtomicFile::create(p)?.commit_with(&files::write_bt(&tree))?;
    }
    out.finish()?;
    if !args.quiet {
        say!(
            "{scan_no} scans, {points} points ({skipped} outside the map's key range skipped, {beyond} beyond max range) in {:.3} s ({:.3} s inserting); map {} nodes ({} bytes as .ot); stream {} bytes",
            started.elapsed().as_secs_f64(),
            insert_s,
            tree.num_nodes(),
            files::ot_size(&tree),
            cum_delta + header.len() as u64
        );
    }
    if let Some(model) = link_model {
        let report =
            rovlink::octo::transfer::send_over(&model, &messages, args.scan_period, args.seed);
        if let Some(path) = &args.arrivals {
            let mut csv = String::from("scan,bytes,t_ready_s,t_complete_s,t_shown_s,latency_s\n");
            for a in &report.arrivals {
                csv.push_str(&format!(
                    "{},{},{:.6},{:.6},{:.6},{:.6}\n",
                    a.scan,
                    a.bytes,
                    a.t_ready_s,
                    a.t_complete_s,
                    a.t_applied_s,
                    a.t_applied_s - a.t_ready_s
                ));
            }
            AtomicFile::create(path)?.commit_with(csv.as_bytes())?;
        }
        if !args.quiet {
            for line in report.lines() {
                say!("{line}");
            }
        }
    }
    Ok(EXIT_OK)
}

fn read_stream(input: Option<&Path>) -> Result<(delta::StreamHeader, Vec<delta::Framed>)> {
    let mut inp = Input::open(input)?;
    let bytes = inp.read_all()?;
    delta::decode_stream(&bytes).map_err(|e| usage(format!("{}: {e}", inp.name)))
}

fn apply(args: &ApplyArgs) -> Result<u8> {
    let (h, msgs) = read_stream(args.input.as_deref())?;
    let mut rx = Receiver::new(h.spec);
    for m in msgs.iter().take(args.messages.unwrap_or(usize::MAX)) {
        rx.apply(&m.message);
    }
    let mut out = Output::open(Some(&args.output), true)?;
    out.write_bytes(&files::write_ot(rx.view()))?;
    out.finish()?;
    Ok(EXIT_OK)
}

/// Side outputs are files: `-` (standard output) belongs to the main output.
fn file_only(flag: &str, path: &Option<PathBuf>) -> Result<()> {
    if path
        .as_deref()
        .is_some_and(|p| rovlink::io::is_std(Some(p)))
    {
        bail!(usage(format!(
            "{flag} -: this output must be a file (standard output is for -o)"
        )));
    }
    Ok(())
}

fn dump(args: &DumpArgs) -> Result<u8> {
    let (h, msgs) = read_stream(args.input.as_deref())?;
    let mut out = Output::open(None, false)?;
    let spec = h.spec;
    match args.format {
        DumpFormat::Text => {
            let roi = spec.roi.map_or("everywhere".to_string(), |r| {
                format!("{:?}..{:?}", r.min_m, r.max_m)
            });
            writeln!(
                out,
                "stream: resolution {} m, coarse depth {} ({} m voxels), ROI {roi}",
                spec.resolution_m,
                spec.coarse_depth,
                spec.resolution_m * (1u64 << (TREE_DEPTH - spec.coarse_depth)) as f64
            )?;
        }
        DumpFormat::Csv => writeln!(
            out,
            "offset,bytes,kind,scan,fine_occupied,fine_free,coarse_occupied,coarse_free,leaves"
        )?,
        DumpFormat::Ndjson => {}
    }
    for f in &msgs {
        match (&f.message, args.format) {
            (Message::Delta { scan, delta: d }, DumpFormat::Text) => {
                writeln!(
                    out,
                    "offset {} ({} bytes): delta of scan {scan}: fine +{} occupied, +{} free; coarse +{} occupied, +{} free",
                    f.offset,
                    f.bytes,
                    d.fine_occupied.len(),
                    d.fine_free.len(),
                    d.coarse_occupied.len(),
                    d.coarse_free.len()
                )?;
                if args.voxels {
                    for (c, col) in &d.fine_occupied {
                        let k = rovlink::octo::tree::unmorton(*c);
                        writeln!(out, "  fine occupied key {k:?} colour {col:?}")?;
                    }
                    for c in &d.fine_free {
                        writeln!(
                            out,
                            "  fine free key {:?}",
                            rovlink::octo::tree::unmorton(*c)
                        )?;
                    }
                    for c in &d.coarse_occupied {
                        let k = spec.coarse_key(*c);
                        writeln!(
                            out,
                            "  coarse occupied key {k:?} (depth {})",
                            spec.coarse_depth
                        )?;
                    }
                    for c in &d.coarse_free {
                        let k = spec.coarse_key(*c);
                        writeln!(out, "  coarse free key {k:?} (depth {})", spec.coarse_depth)?;
                    }
                }
            }
            (Message::Full { scan, leaves }, DumpFormat::Text) => writeln!(
                out,
                "offset {} ({} bytes): full view after scan {scan}: {} leaves ({} occupied)",
                f.offset,
                f.bytes,
                leaves.len(),
                leaves.iter().filter(|l| l.2).count()
            )?,
            (Message::Delta { scan, delta: d }, DumpFormat::Csv) => writeln!(
                out,
                "{},{},delta,{scan},{},{},{},{},",
                f.offset,
                f.bytes,
                d.fine_occupied.len(),
                d.fine_free.len(),
                d.coarse_occupied.len(),
                d.coarse_free.len()
            )?,
            (Message::Full { scan, leaves }, DumpFormat::Csv) => writeln!(
                out,
                "{},{},full,{scan},,,,,{}",
                f.offset,
                f.bytes,
                leaves.len()
            )?,
            (Message::Delta { scan, delta: d }, DumpFormat::Ndjson) => {
                let mut v = serde_json::json!({
                    "offset": f.offset, "bytes": f.bytes, "kind": "delta", "scan": scan,
                    "fine_occupied": d.fine_occupied.len(), "fine_free": d.fine_free.len(),
                    "coarse_occupied": d.coarse_occupied.len(), "coarse_free": d.coarse_free.len(),
                });
                if args.voxels {
                    v["voxels"] = serde_json::json!({
                        "fine_occupied": d.fine_occupied.iter().map(|(c, col)| serde_json::json!({"key": rovlink::octo::tree::unmorton(*c), "rgb": col})).collect::<Vec<_>>(),
                        "fine_free": d.fine_free.iter().map(|c| rovlink::octo::tree::unmorton(*c)).collect::<Vec<_>>(),
                        "coarse_occupied": d.coarse_occupied.iter().map(|c| spec.coarse_key(*c)).collect::<Vec<_>>(),
                        "coarse_free": d.coarse_free.iter().map(|c| spec.coarse_key(*c)).collect::<Vec<_>>(),
                    });
                }
                writeln!(out, "{v}")?;
            }
            (Message::Full { scan, leaves }, DumpFormat::Ndjson) => writeln!(
                out,
                "{}",
                serde_json::json!({"offset": f.offset, "bytes": f.bytes, "kind": "full", "scan": scan,
                    "leaves": leaves.len(), "occupied": leaves.iter().filter(|l| l.2).count()})
            )?,
        }
    }
    out.finish()?;
    Ok(EXIT_OK)
}

fn full(args: &FullArgs) -> Result<u8> {
    let mut inp = Input::open(Some(&args.input))?;
    let bytes = inp.read_all()?;
    let tree = files::read_map(&bytes).map_err(|e| usage(format!("{}: {e}", inp.name)))?;
    let spec = args.view.spec(tree.resolution_m())?;
    let view = delta::view_of(&tree, &spec);
    let mut out = Output::open(args.output.as_deref(), true)?;
    out.write_bytes(&delta::encode_header(&spec))?;
    out.write_bytes(&delta::encode_full(0, &view))?;
    out.finish()?;
    Ok(EXIT_OK)
}

fn synth_cmd(args: &SynthArgs) -> Result<u8> {
    let mut p = synth::SurveyParams {
        seed: args.seed,
        ..synth::SurveyParams::default()
    };
    if let Some(n) = args.scans {
        if n == 0 {
            bail!(usage("--scans 0: expected at least one scan".into()));
        }
        p.scans = n;
    }
    let scans = synth::survey(&p);
    let mcap = args.format == Some(SynthFormat::Mcap)
        || (args.format.is_none()
            && args
                .output
                .as_ref()
                .and_then(|o| o.extension())
                .is_some_and(|e| e.eq_ignore_ascii_case("mcap")));
    if mcap {
        let mut out = Output::open(args.output.as_deref(), true)?;
        out.write_bytes(&cloud::write_clouds_mcap(&scans))?;
        out.finish()?;
        return Ok(EXIT_OK);
    }
    let mut out = Output::open(args.output.as_deref(), true)?;
    out.write_bytes(&graph::write(&scans))?;
    out.finish()?;
    Ok(EXIT_OK)
}

fn run(cli: &Cli) -> Result<u8> {
    match &cli.command {
        Command::Build(a) => build(a),
        Command::Apply(a) => apply(a),
        Command::Dump(a) => dump(a),
        Command::Full(a) => full(a),
        Command::Synth(a) => synth_cmd(a),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    rovlink::io::finish_main(TOOL, run(&cli))
}
