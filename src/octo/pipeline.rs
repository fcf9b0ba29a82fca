//! octo-delta's work as a library: building the map and its delta stream from point-cloud
//! files, applying, listing and making streams, and the synthetic survey, each with its
//! configuration checked here (so a tool, a test or another program gets the same limits).
//!
//! - [`build`]: scans from every input ([`InputFormat`]: `.graph`, PCD, PLY, XYZ, MCAP) into
//!   one [`OcTree`], one delta message per scan written to a stream as it is made, a
//!   [`StatsRow`] per scan to a sink, a stop flag looked at between scans (and every few
//!   thousand points inside one): an interrupted build ends after its last whole message, with
//!   the map as it was then.
//! - [`apply`], [`dump`], [`full`]: the operator's view of a stream, its listing, a whole map as
//!   a one-message stream.
//! - [`synth`]: a synthetic survey as `.graph` or MCAP bytes.
//!
//! Every number comes with a range ([`BuildConfig::validate`], [`synth::SurveyParams::validate`])
//! whose errors name the option, the range with its unit, and what was found.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use serde::Serialize;

use super::cloud::{self, CloudFormat, McapOptions};
use super::delta::{self, Message, Receiver, Roi, Sender, ViewSpec};
use super::recording::{Item, Recording, RecordingError, RecordingOptions};
use super::tree::{OcTree, TREE_DEPTH, unmorton};
use super::{ParseError, Pose, Scan, files, graph, synth, transfer};
use crate::io::StopReader;
use crate::io::{Input, IoError};

/// Finest voxel edge accepted, m (0.1 mm).
pub const RESOLUTION_MIN_M: f64 = 1e-4;
/// Coarsest voxel edge accepted, m (1 km: the map then spans 65 536 km a side).
pub const RESOLUTION_MAX_M: f64 = 1e3;
/// Longest `--max-range`, m (100 km, beyond any sensor).
pub const MAX_RANGE_M: f64 = 1e5;
/// Largest coordinate of an ROI corner or a sensor origin, m (10 000 km).
pub const COORDINATE_MAX_M: f64 = 1e7;
/// Most threads casting rays.
pub const THREADS_MAX: usize = 64;
/// Largest `--coarse-res` as a multiple of the resolution (coarse depth 1).
pub const COARSE_FACTOR_MAX: f64 = 32768.0;

/// A wrong number in a configuration: which option, what was expected (with its unit) and what
/// was found. Displays as `--res: expected 0.0001 m ..= 1000 m, found 0`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{option}: expected {expected}, found {found}")]
pub struct ConfigError {
    /// The option, as the command line names it (`--res`).
    pub option: &'static str,
    /// The accepted values, with units.
    pub expected: String,
    /// The value given.
    pub found: String,
}

impl ConfigError {
    fn new(option: &'static str, expected: impl Into<String>, found: impl ToString) -> Self {
        ConfigError {
            option,
            expected: expected.into(),
            found: found.to_string(),
        }
    }
}

/// A number as messages show it: plain, or in exponent form when very large or small
/// (`1e300`, `1e-9`, not 300 digits).
pub fn shown(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && a.is_finite() && !(1e-4..1e7).contains(&a) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// Checks that `v` is finite and within `lo ..= hi` (`unit` for the message).
pub fn check_range(
    option: &'static str,
    v: f64,
    lo: f64,
    hi: f64,
    unit: &str,
) -> Result<f64, ConfigError> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        let u = if unit.is_empty() {
            String::new()
        } else {
            format!(" {unit}")
        };
        Err(ConfigError::new(
            option,
            format!("{}{u} ..= {}{u}", shown(lo), shown(hi)),
            shown(v),
        ))
    }
}

/// An input's format: OctoMap's `.graph` or one of the point-cloud formats of [`cloud`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum InputFormat {
    /// OctoMap scan graph (`.graph`): scans with poses, streamed from disk.
    Graph,
    /// Point Cloud Library `.pcd`.
    Pcd,
    /// Polygon File Format `.ply`.
    Ply,
    /// Text, one `x y z [r g b]` point per line.
    Xyz,
    /// MCAP with ROS 2 `PointCloud2` messages, posed by TF or a pose topic
    /// ([`recording`](super::recording)).
    Mcap,
    /// A rosbag2 bag: its directory, its `metadata.yaml` or one `.db3` (sqlite3 or mcap storage).
    Rosbag2,
}

impl InputFormat {
    /// Every format.
    pub const ALL: [InputFormat; 6] = [
        InputFormat::Graph,
        InputFormat::Pcd,
        InputFormat::Ply,
        InputFormat::Xyz,
        InputFormat::Mcap,
        InputFormat::Rosbag2,
    ];

    /// The short name: `graph`, `pcd`, `ply`, `xyz`, `mcap`, `rosbag2`.
    pub fn name(self) -> &'static str {
        match self {
            InputFormat::Graph => "graph",
            InputFormat::Pcd => "pcd",
            InputFormat::Ply => "ply",
            InputFormat::Xyz => "xyz",
            InputFormat::Mcap => "mcap",
            InputFormat::Rosbag2 => "rosbag2",
        }
    }

    /// The format a file name names (`.graph`, `.db3` or `metadata.yaml`, or one of
    /// [`CloudFormat::from_path`]); a directory is not looked at here (see [`build`]).
    pub fn from_path(path: &Path) -> Option<InputFormat> {
        let ext = |e: &str| path.extension().is_some_and(|x| x.eq_ignore_ascii_case(e));
        if ext("graph") {
            return Some(InputFormat::Graph);
        }
        if super::bag::is_rosbag2_file_name(path) {
            return Some(InputFormat::Rosbag2);
        }
        CloudFormat::from_path(path).map(InputFormat::from)
    }

    /// The point-cloud reader of this format (`None` for `.graph`).
    pub fn cloud(self) -> Option<CloudFormat> {
        match self {
            InputFormat::Graph => None,
            InputFormat::Pcd => Some(CloudFormat::Pcd),
            InputFormat::Ply => Some(CloudFormat::Ply),
            InputFormat::Xyz => Some(CloudFormat::Xyz),
            InputFormat::Mcap => Some(CloudFormat::Mcap),
            InputFormat::Rosbag2 => None,
        }
    }

    /// Whether the format carries the sensor's pose (`.graph`, bags); the others get
    /// [`BuildConfig::origin_m`] (a bag without any pose source does too).
    pub fn has_poses(self) -> bool {
        matches!(
            self,
            InputFormat::Graph | InputFormat::Mcap | InputFormat::Rosbag2
        )
    }

    /// Whether inputs of this format are robot logs read by [`Recording`].
    pub fn is_bag(self) -> bool {
        matches!(self, InputFormat::Mcap | InputFormat::Rosbag2)
    }

    /// Reads every scan of `bytes` in this format.
    pub fn read(self, bytes: &[u8], mcap: &McapOptions) -> Result<Vec<Scan>, ParseError> {
        match self.cloud() {
            None if self == InputFormat::Rosbag2 => Err(ParseError::new(
                0,
                "rosbag2: expected a bag directory, its metadata.yaml or a .db3 file, found bytes",
            )),
            None => graph::read_scans(bytes),
            Some(f) => cloud::read(f, bytes, mcap),
        }
    }
}

impl From<CloudFormat> for InputFormat {
    fn from(f: CloudFormat) -> Self {
        match f {
            CloudFormat::Pcd => InputFormat::Pcd,
            CloudFormat::Ply => InputFormat::Ply,
            CloudFormat::Xyz => InputFormat::Xyz,
            CloudFormat::Mcap => InputFormat::Mcap,
        }
    }
}

impl std::str::FromStr for InputFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        InputFormat::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown format {s:?} (graph, pcd, ply, xyz, mcap or rosbag2)"))
    }
}

impl std::fmt::Display for InputFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How coarse the voxels sent outside the ROI are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Coarse {
    /// A tree depth, 1..=16 (16 - k: voxels 2^k times the fine edge).
    Depth(u32),
    /// An edge in metres, rounded to the nearest power-of-two multiple of the resolution.
    Edge(f64),
}

impl Default for Coarse {
    /// Depth 13: coarse voxels 8 times the fine edge.
    fn default() -> Self {
        Coarse::Depth(13)
    }
}

/// Checks an ROI: finite corners within [`COORDINATE_MAX_M`], the lower not above the upper.
pub fn check_roi(roi: &Roi) -> Result<(), ConfigError> {
    let all = roi.min_m.iter().chain(&roi.max_m);
    if all
        .clone()
        .any(|c| !(c.is_finite() && c.abs() <= COORDINATE_MAX_M))
    {
        return Err(ConfigError::new(
            "--roi",
            format!("corners within +-{COORDINATE_MAX_M} m"),
            format!("{:?}..{:?}", roi.min_m, roi.max_m),
        ));
    }
    if (0..3).any(|i| roi.min_m[i] > roi.max_m[i]) {
        return Err(ConfigError::new(
            "--roi",
            "x0,y0,z0 not above x1,y1,z1",
            format!("{:?}..{:?}", roi.min_m, roi.max_m),
        ));
    }
    Ok(())
}

/// The operator's view: `resolution_m` (checked), the coarse depth of `coarse` and the ROI.
pub fn view_spec(
    resolution_m: f64,
    coarse: Coarse,
    roi: Option<Roi>,
) -> Result<ViewSpec, ConfigError> {
    check_range(
        "--res",
        resolution_m,
        RESOLUTION_MIN_M,
        RESOLUTION_MAX_M,
        "m",
    )?;
    if let Some(r) = &roi {
        check_roi(r)?;
    }
    let coarse_depth = match coarse {
        Coarse::Depth(d) => {
            if !(1..=TREE_DEPTH).contains(&d) {
                return Err(ConfigError::new("--coarse-depth", "1 ..= 16", d));
            }
            d
        }
        Coarse::Edge(m) => {
            let max = resolution_m * COARSE_FACTOR_MAX;
            check_range("--coarse-res", m, resolution_m, max, "m")?;
            let k = (m / resolution_m).log2().round().clamp(0.0, 15.0);
            TREE_DEPTH - k as u32
        }
    };
    Ok(ViewSpec {
        resolution_m,
        coarse_depth,
        roi,
    })
}

/// Everything [`build`] needs besides its inputs and outputs.
#[derive(Debug, Clone)]
pub struct BuildConfig {
    /// Voxel edge, m ([`RESOLUTION_MIN_M`] ..= [`RESOLUTION_MAX_M`]).
    pub resolution_m: f64,
    /// Coarse voxels outside the ROI.
    pub coarse: Coarse,
    /// The region sent at full resolution with colour; `None`: everywhere.
    pub roi: Option<Roi>,
    /// Rays longer than this mark free space up to it only, no hit, m (`None`: no limit).
    pub max_range_m: Option<f64>,
    /// The inputs' format; `None`: from each file's name, else its first bytes.
    pub format: Option<InputFormat>,
    /// Sensor origin for inputs without poses (PCD without VIEWPOINT, PLY, XYZ), m.
    pub origin_m: Option<[f64; 3]>,
    /// Bag topics (MCAP and rosbag2): the clouds' and the poses'.
    pub mcap: McapOptions,
    /// Bags posed by TF: the frame the map is built in (`None`: the root of the TF tree).
    pub fixed_frame: Option<String>,
    /// Build an `OcTree` even when the scans have colour.
    pub no_color: bool,
    /// Also resend an occupied voxel when a brighter colour is found for it.
    pub color_updates: bool,
    /// Threads casting rays (1 ..= [`THREADS_MAX`]); `None`: the machine's cores, at most 8.
    pub threads: Option<usize>,
}

impl Default for BuildConfig {
    fn default() -> Self {
        BuildConfig {
            resolution_m: 0.1,
            coarse: Coarse::default(),
            roi: None,
            max_range_m: None,
            format: None,
            origin_m: None,
            mcap: McapOptions::default(),
            fixed_frame: None,
            no_color: false,
            color_updates: false,
            threads: None,
        }
    }
}

impl BuildConfig {
    /// Checks every number; returns the view the stream will carry.
    pub fn validate(&self) -> Result<ViewSpec, ConfigError> {
        let spec = view_spec(self.resolution_m, self.coarse, self.roi)?;
        if let Some(r) = self.max_range_m
            && !(r.is_finite() && r > 0.0 && r <= MAX_RANGE_M)
        {
            return Err(ConfigError::new(
                "--max-range",
                format!("a range > 0 m ..= {MAX_RANGE_M} m"),
                shown(r),
            ));
        }
        if let Some(o) = self.origin_m
            && o.iter()
                .any(|c| !(c.is_finite() && c.abs() <= COORDINATE_MAX_M))
        {
            return Err(ConfigError::new(
                "--origin",
                format!("coordinates within +-{COORDINATE_MAX_M} m"),
                format!("{o:?}"),
            ));
        }
        if let Some(t) = self.threads
            && !(1..=THREADS_MAX).contains(&t)
        {
            return Err(ConfigError::new(
                "--threads",
                format!("1 ..= {THREADS_MAX} threads"),
                t,
            ));
        }
        Ok(spec)
    }
}

/// Largest cloud, stream or map file read whole, bytes (1 GiB; a `.graph` streams, unbounded).
pub const MAX_INPUT_BYTES: u64 = 1 << 30;

/// Reads all of `input` up to `max_bytes`: a longer one (an endless one such as `/dev/zero`)
/// is an error naming `name`, after reading `max_bytes + 1` bytes at most.
pub fn read_limited(input: &mut dyn Read, name: &str, max_bytes: u64) -> Result<Vec<u8>, IoError> {
    let read_err = |source| IoError::Read {
        name: name.to_string(),
        source,
    };
    crate::io::read_bounded(input, max_bytes)
        .map_err(read_err)?
        .ok_or_else(|| {
            read_err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("more than {max_bytes} bytes: not a file octo-delta reads whole"),
            ))
        })
}

/// An input file (`-`: standard input) read whole, at most [`MAX_INPUT_BYTES`], and the name
/// its errors carry.
pub fn read_input(path: &Path) -> Result<(Vec<u8>, String), PipelineError> {
    let mut input = Input::open(Some(path))?;
    let name = input.name.clone();
    let bytes = read_limited(input.reader(), &name, MAX_INPUT_BYTES)?;
    Ok((bytes, name))
}

/// Checks a transfer's time between scans (0 ..= [`transfer::MAX_PERIOD_S`]).
pub fn check_scan_period(period_s: f64) -> Result<f64, ConfigError> {
    check_range("--scan-period", period_s, 0.0, transfer::MAX_PERIOD_S, "s")
}

/// One row of `--stats`: a scan's message and what sending the whole map would have cost.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatsRow {
    /// Scan number, from 0.
    pub scan: u32,
    /// Points in the scan.
    pub points: usize,
    /// The scan's message, bytes.
    pub delta_bytes: usize,
    /// Newly occupied voxels at full resolution.
    pub fine_occupied: usize,
    /// Newly free voxels at full resolution.
    pub fine_free: usize,
    /// Newly occupied coarse voxels.
    pub coarse_occupied: usize,
    /// Newly free coarse voxels.
    pub coarse_free: usize,
    /// The whole map as `.bt`, bytes.
    pub full_bt_bytes: u64,
    /// The whole map as `.ot`, bytes.
    pub full_ot_bytes: u64,
    /// Messages so far, bytes.
    pub cum_delta_bytes: u64,
    /// A `.bt` after every scan so far, bytes.
    pub cum_full_bt_bytes: u64,
    /// A `.ot` after every scan so far, bytes.
    pub cum_full_ot_bytes: u64,
    /// Points skipped (non-finite, or outside the map's key range).
    pub points_skipped: usize,
    /// Time inserting the scan and making its message, ms (to the microsecond).
    pub insert_ms: f64,
}

/// The `--stats` columns, in order.
pub const STATS_COLUMNS: [&str; 14] = [
    "scan",
    "points",
    "delta_bytes",
    "fine_occupied",
    "fine_free",
    "coarse_occupied",
    "coarse_free",
    "full_bt_bytes",
    "full_ot_bytes",
    "cum_delta_bytes",
    "cum_full_bt_bytes",
    "cum_full_ot_bytes",
    "points_skipped",
    "insert_ms",
];

/// An error a row sink returns.
pub type SinkError = Box<dyn std::error::Error + Send + Sync>;

/// Where [`build`] sends its [`StatsRow`]s.
pub type StatsSink<'a> = &'a mut dyn FnMut(&StatsRow) -> Result<(), SinkError>;

/// What [`build`] reports to and asks of its caller while it runs.
pub struct Hooks<'a> {
    /// Set (by a signal handler, say) to stop at the next scan.
    pub stop: &'a AtomicBool,
    /// Gets each scan's [`StatsRow`] (computing the full-map sizes costs a copy of the map
    /// per scan, so only when there is a sink).
    pub stats: Option<StatsSink<'a>>,
    /// Gets (scans done, scans known so far) after each scan and each input opened.
    pub progress: Option<&'a mut dyn FnMut(u64, u64)>,
}

/// What a build did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BuildReport {
    /// Scans inserted (each with its message in the stream).
    pub scans: u32,
    /// Points in them.
    pub points: usize,
    /// Points skipped: non-finite or outside the key range.
    pub points_skipped: usize,
    /// Points beyond the maximum range (their rays mark free space only).
    pub points_beyond_range: usize,
    /// Wall-clock time, s.
    pub elapsed_s: f64,
    /// Time inserting scans and making messages, s.
    pub insert_s: f64,
    /// The stream's bytes, header included.
    pub stream_bytes: u64,
    /// (scan number, message bytes) of every message, for a transfer.
    pub messages: Vec<(u32, usize)>,
    /// Whether the stop flag ended the build early.
    pub interrupted: bool,
    /// Clouds of robot logs skipped for want of a pose: (reason naming the frames, count).
    pub skipped: Vec<(String, u64)>,
    /// What a user should know about how robot logs were read (`FILE: poses from TF ...`).
    pub notes: Vec<String>,
}

/// A build's outcome: the map and the report.
#[derive(Debug)]
pub struct Built {
    /// The map after the last scan inserted.
    pub tree: OcTree,
    /// What was done.
    pub report: BuildReport,
}

impl Built {
    /// The build's figures as JSON (`octo-delta build --metrics`): scans, points, times, the
    /// map's nodes and .ot size, the stream's and the largest message's bytes.
    pub fn figures(&self) -> serde_json::Value {
        let r = &self.report;
        let message_bytes = r.messages.iter().map(|&(_, bytes)| bytes);
        serde_json::json!({
            "scans": r.scans,
            "points": r.points,
            "points_skipped": r.points_skipped,
            "points_beyond_range": r.points_beyond_range,
            "elapsed_s": r.elapsed_s,
            "insert_s": r.insert_s,
            "map_nodes": self.tree.num_nodes(),
            "ot_bytes": files::ot_size(&self.tree),
            "stream_bytes": r.stream_bytes,
            "message_bytes_max": message_bytes.clone().max().unwrap_or(0),
            "message_bytes_total": message_bytes.sum::<usize>(),
            "interrupted": r.interrupted,
        })
    }

    /// The one-line summary: scans, points, times, map and stream sizes; `interrupted` says by
    /// what when the build was stopped.
    pub fn summary(&self, interrupted: &str) -> String {
        let r = &self.report;
        let mut s = format!(
            "{} scans, {} points ({} outside the map's key range skipped, {} beyond max range) in {:.3} s ({:.3} s inserting); map {} nodes ({} bytes as .ot); stream {} bytes",
            r.scans,
            r.points,
            r.points_skipped,
            r.points_beyond_range,
            r.elapsed_s,
            r.insert_s,
            self.tree.num_nodes(),
            files::ot_size(&self.tree),
            r.stream_bytes
        );
        if r.interrupted {
            s.push_str(&format!("; {interrupted} after {} scans", r.scans));
        }
        s
    }
}

/// Why a build (or another pipeline) failed.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// A number out of range.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// An input that does not parse.
    #[error("{name}: {source}")]
    Input {
        /// The file.
        name: String,
        /// Where and what.
        source: ParseError,
    },
    /// An input whose format neither its name nor its bytes tell.
    #[error(
        "{name}: unknown input format (expected .graph, .pcd, .ply, .xyz, .mcap, a rosbag2 directory or .db3; or --format)"
    )]
    UnknownFormat {
        /// The file.
        name: String,
    },
    /// An input holding a number this module does not work with (a map's resolution).
    #[error("{name}: {source}")]
    OutOfRange {
        /// The file.
        name: String,
        /// Which number, the range and what was found.
        source: ConfigError,
    },
    /// A robot log that cannot be read (its file and where), or that lacks what a map needs.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// A robot log none of whose clouds could be posed.
    #[error("{name}: no cloud could be posed ({skipped} skipped): {reason}")]
    NoPosedCloud {
        /// The bag.
        name: String,
        /// Clouds skipped.
        skipped: u64,
        /// Why the first one was.
        reason: String,
    },
    /// Reading an input or writing an output failed.
    #[error(transparent)]
    Io(#[from] IoError),
    /// The stats sink failed.
    #[error(transparent)]
    Sink(SinkError),
}

/// The scans of one input: a stream of scans (a `.graph` file is streamed from disk, so a large
/// survey never sits in memory whole; cloud files are read whole), or a robot log read cloud by
/// cloud ([`Recording`]).
enum ScanSource<'a> {
    /// Scans, how many there will be, and the format.
    Scans(
        Box<dyn Iterator<Item = Result<Scan, ParseError>> + 'a>,
        usize,
        InputFormat,
    ),
    /// A bag, its poses read.
    Bag(Box<Recording>),
}

/// The scans of one input, read through a [`StopReader`]: a read waiting on a silent pipe
/// gives up once `stop` is set.
fn open_scans<'a>(
    path: &Path,
    cfg: &BuildConfig,
    stop: &'a AtomicBool,
) -> Result<ScanSource<'a>, PipelineError> {
    let name = path.display().to_string();
    let bad = |source| PipelineError::Input {
        name: name.clone(),
        source,
    };
    let by_name = InputFormat::from_path(path);
    // Looked up, not opened (a named pipe would wait for a writer): a missing file is named.
    let meta = match crate::io::is_std(Some(path)) {
        true => None,
        false => Some(std::fs::metadata(path).map_err(|source| IoError::Open {
            path: path.to_path_buf(),
            source,
        })?),
    };
    let options = RecordingOptions {
        cloud_topic: cfg.mcap.cloud_topic.clone(),
        pose_topic: cfg.mcap.pose_topic.clone(),
        fixed_frame: cfg.fixed_frame.clone(),
        origin_given: cfg.origin_m.is_some(),
    };
    let is_dir = meta.as_ref().is_some_and(|m| m.is_dir());
    let format = cfg
        .format
        .or(by_name)
        .or(is_dir.then_some(InputFormat::Rosbag2));
    if let Some(meta) = &meta {
        if format == Some(InputFormat::Graph) {
            let len = if meta.is_file() { meta.len() } else { u64::MAX };
            let stream = graph::ScanStream::new(StopReader::open(Some(path), stop), len);
            let stream = stream.map_err(bad)?;
            let n = stream.node_count() as usize;
            return Ok(ScanSource::Scans(Box::new(stream), n, InputFormat::Graph));
        }
        // A rosbag2 file is read in place (SQLite, or its directory's metadata), never as a
        // stream: a FIFO or a device there is refused at once, not waited on.
        if format == Some(InputFormat::Rosbag2) && !(meta.is_file() || is_dir) {
            crate::io::open_regular(path).map_err(|source| IoError::Open {
                path: path.to_path_buf(),
                source,
            })?;
        }
        if format.is_some_and(InputFormat::is_bag) && (meta.is_file() || is_dir) {
            let rec = Recording::open(path, &options, stop)?;
            return Ok(ScanSource::Bag(Box::new(rec)));
        }
    }
    let bytes = read_limited(
        &mut StopReader::open(Some(path), stop),
        &name,
        MAX_INPUT_BYTES,
    )?;
    let format = format
        .or_else(|| cloud::sniff(&bytes).map(InputFormat::from))
        .ok_or_else(|| PipelineError::UnknownFormat { name: name.clone() })?;
    if format == InputFormat::Mcap {
        let rec = Recording::from_mcap_bytes(&name, bytes, &options, stop)?;
        return Ok(ScanSource::Bag(Box::new(rec)));
    }
    let scans = format.read(&bytes, &cfg.mcap).map_err(bad)?;
    let n = scans.len();
    Ok(ScanSource::Scans(
        Box::new(scans.into_iter().map(Ok)),
        n,
        format,
    ))
}

/// Inputs without a pose get the sensor origin of `--origin`: the points stay where they are in
/// the map frame, shifted into the sensor frame.
fn with_origin(mut scan: Scan, origin: Option<[f32; 3]>) -> Scan {
    if let Some(o) = origin
        && scan.pose == Pose::IDENTITY
    {
        scan.pose.translation_m = o;
        for p in &mut scan.points {
            *p = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        }
    }
    scan
}

/// Builds the map from the scans of `inputs` (in order; `-` is standard input) and writes the
/// delta stream to `stream` (named `stream_name` in errors): the header, then one message per
/// scan as soon as it is made. The map keeps colours when the first scan has them, unless
/// [`BuildConfig::no_color`].
///
/// When `hooks.stop` is set the build ends before the next scan (or inside a scan, before it
/// changes the map): the stream then holds whole messages for every scan in the map, and
/// [`BuildReport::interrupted`] says so. An input that does not parse fails the build, as does
/// a write error; the caller should then drop its outputs.
pub fn build(
    cfg: &BuildConfig,
    inputs: &[PathBuf],
    stream: &mut dyn Write,
    stream_name: &str,
    hooks: &mut Hooks<'_>,
) -> Result<Built, PipelineError> {
    let spec = cfg.validate()?;
    let started = Instant::now();
    let write = |w: &mut dyn Write, bytes: &[u8]| {
        w.write_all(bytes)
            .and_then(|()| w.flush())
            .map_err(|source| IoError::Write {
                name: stream_name.to_string(),
                source,
            })
    };
    let threads = cfg
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get().min(8)));
    let origin = cfg.origin_m.map(|o| o.map(|c| c as f32));
    let mut sender = Sender::new(spec);
    sender.set_color_updates(cfg.color_updates);
    let header = delta::encode_header(&spec);
    write(stream, &header)?;
    let mut report = BuildReport {
        stream_bytes: header.len() as u64,
        ..BuildReport::default()
    };
    let mut tree: Option<OcTree> = None;
    let (mut cum_bt, mut cum_ot, mut known) = (0u64, 0u64, 0u64);
    'inputs: for path in inputs {
        if hooks.stop.load(Ordering::Relaxed) {
            report.interrupted = true;
            break;
        }
        // A read that gave up because the flag was set is a stop, not a bad input.
        let stop = hooks.stop;
        let name = path.display().to_string();
        let source = match open_scans(path, cfg, stop) {
            Err(_) if stop.load(Ordering::Relaxed) => {
                report.interrupted = true;
                break;
            }
            opened => opened?,
        };
        // A bag's clouds borrow it: it lives here, beside the loop over them.
        let mut recording: Option<Box<Recording>> = None;
        type Items<'s> = Box<dyn Iterator<Item = Result<Item, PipelineError>> + 's>;
        let (items, count, needs_origin): (Items<'_>, u64, bool) = match source {
            ScanSource::Scans(scans, n, format) => {
                let name = name.clone();
                let items = scans.map(move |r| {
                    r.map(Item::Scan).map_err(|source| PipelineError::Input {
                        name: name.clone(),
                        source,
                    })
                });
                (Box::new(items), n as u64, !format.has_poses())
            }
            ScanSource::Bag(rec) => {
                let rec = recording.insert(rec);
                let n = rec.cloud_count().unwrap_or(0);
                let needs_origin = !rec.has_poses();
                let items = rec.scans(stop)?.map(|r| r.map_err(PipelineError::from));
                (Box::new(items), n, needs_origin)
            }
        };
        known += count;
        if let Some(p) = hooks.progress.as_mut() {
            p(report.scans as u64, known);
        }
        let origin = origin.filter(|_| needs_origin);
        let (mut posed, mut skipped, mut first_reason) = (0u64, 0u64, None);
        for item in items {
            if stop.load(Ordering::Relaxed) {
                report.interrupted = true;
                break 'inputs;
            }
            let scan = match item {
                Err(_) if stop.load(Ordering::Relaxed) => {
                    report.interrupted = true;
                    break 'inputs;
                }
                Ok(Item::Skipped(reason)) => {
                    let reason = format!("{name}: {reason}");
                    skipped += 1;
                    match report.skipped.iter_mut().find(|(r, _)| *r == reason) {
                        Some((_, n)) => *n += 1,
                        None => report.skipped.push((reason.clone(), 1)),
                    }
                    first_reason.get_or_insert(reason);
                    continue;
                }
                Ok(Item::Scan(scan)) => scan,
                Err(e) => return Err(e),
            };
            posed += 1;
            let scan = with_origin(scan, origin);
            let tree = tree.get_or_insert_with(|| {
                let mut t = OcTree::new(cfg.resolution_m);
                t.set_threads(threads);
                if scan.colors.is_some() && !cfg.no_color {
                    t.enable_color();
                }
                t
            });
            let t0 = Instant::now();
            let Some(up) = tree.insert_scan_until(&scan, cfg.max_range_m, hooks.stop) else {
                report.interrupted = true;
                break 'inputs;
            };
            let d = sender.delta(tree, &up.changes);
            let msg = delta::encode_delta(&spec, report.scans, &d);
            let dt = t0.elapsed().as_secs_f64();
            report.insert_s += dt;
            write(stream, &msg)?;
            report.points += up.points;
            report.points_skipped += up.points_skipped;
            report.points_beyond_range += up.points_beyond_range;
            report.stream_bytes += msg.len() as u64;
            report.messages.push((report.scans, msg.len()));
            if let Some(sink) = hooks.stats.as_mut() {
                let full_bt_bytes = files::write_bt(tree).len() as u64;
                let full_ot_bytes = files::ot_size(tree) as u64;
                cum_bt += full_bt_bytes;
                cum_ot += full_ot_bytes;
                sink(&StatsRow {
                    scan: report.scans,
                    points: up.points,
                    delta_bytes: msg.len(),
                    fine_occupied: d.fine_occupied.len(),
                    fine_free: d.fine_free.len(),
                    coarse_occupied: d.coarse_occupied.len(),
                    coarse_free: d.coarse_free.len(),
                    full_bt_bytes,
                    full_ot_bytes,
                    cum_delta_bytes: report.stream_bytes - header.len() as u64,
                    cum_full_bt_bytes: cum_bt,
                    cum_full_ot_bytes: cum_ot,
                    points_skipped: up.points_skipped,
                    insert_ms: (dt * 1e6).round() / 1e3,
                })
                .map_err(PipelineError::Sink)?;
            }
            report.scans += 1;
            if let Some(p) = hooks.progress.as_mut() {
                p(report.scans as u64, known);
            }
        }
        if let Some(rec) = &recording {
            // A bag that says it has clouds but gives none (its metadata.yaml lists a topic its
            // .db3 lacks) is not an empty survey.
            if posed == 0
                && skipped == 0
                && let Some(n) = rec.cloud_count().filter(|&n| n > 0)
            {
                return Err(PipelineError::Recording(RecordingError::Unusable {
                    file: name,
                    message: format!(
                        "cloud topic {:?}: expected {n} messages (as the bag says), found none",
                        rec.cloud_topic()
                    ),
                }));
            }
            if posed == 0
                && let Some(reason) = first_reason
            {
                return Err(PipelineError::NoPosedCloud {
                    name,
                    skipped,
                    reason,
                });
            }
            report
                .notes
                .extend(rec.notes.iter().map(|n| format!("{name}: {n}")));
        }
    }
    report.elapsed_s = started.elapsed().as_secs_f64();
    let tree = tree.unwrap_or_else(|| OcTree::new(cfg.resolution_m));
    Ok(Built { tree, report })
}

/// One row of `--arrivals`: when a scan's message reached the operator over the link.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ArrivalRow {
    /// Scan number.
    pub scan: u32,
    /// Message bytes.
    pub bytes: usize,
    /// When it was ready to send, s.
    pub t_ready_s: f64,
    /// When its last segment arrived, s.
    pub t_complete_s: f64,
    /// When it could be shown (it and every earlier message complete), s.
    pub t_shown_s: f64,
    /// From ready to shown, s.
    pub latency_s: f64,
}

/// The `--arrivals` columns, in order.
pub const ARRIVAL_COLUMNS: [&str; 6] = [
    "scan",
    "bytes",
    "t_ready_s",
    "t_complete_s",
    "t_shown_s",
    "latency_s",
];

/// `v` rounded to the microsecond (what the arrival columns carry).
fn micro(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// The arrival rows of a transfer.
pub fn arrival_rows(report: &transfer::TransferReport) -> Vec<ArrivalRow> {
    report
        .arrivals
        .iter()
        .map(|a| ArrivalRow {
            scan: a.scan,
            bytes: a.bytes,
            t_ready_s: micro(a.t_ready_s),
            t_complete_s: micro(a.t_complete_s),
            t_shown_s: micro(a.t_applied_s),
            latency_s: micro(a.t_applied_s - a.t_ready_s),
        })
        .collect()
}

/// A stream's header and messages, or where `bytes` (named `name`) stop being one.
pub fn read_stream(
    bytes: &[u8],
    name: &str,
) -> Result<(delta::StreamHeader, Vec<delta::Framed>), PipelineError> {
    delta::decode_stream(bytes).map_err(|source| PipelineError::Input {
        name: name.to_string(),
        source,
    })
}

/// The operator's view after the first `messages` messages of a stream (all: `usize::MAX`).
pub fn apply(bytes: &[u8], name: &str, messages: usize) -> Result<OcTree, PipelineError> {
    let (h, msgs) = read_stream(bytes, name)?;
    let mut rx = Receiver::new(h.spec);
    for m in msgs.iter().take(messages) {
        rx.apply(&m.message);
    }
    Ok(rx.view().clone())
}

/// A whole map (`.ot` or `.bt` bytes, named `name`) as a one-message stream with this view.
pub fn full(
    bytes: &[u8],
    name: &str,
    coarse: Coarse,
    roi: Option<Roi>,
) -> Result<Vec<u8>, PipelineError> {
    let tree = files::read_map(bytes).map_err(|source| PipelineError::Input {
        name: name.to_string(),
        source,
    })?;
    let res = tree.resolution_m();
    check_range("resolution", res, RESOLUTION_MIN_M, RESOLUTION_MAX_M, "m").map_err(|source| {
        PipelineError::OutOfRange {
            name: name.to_string(),
            source,
        }
    })?;
    let spec = view_spec(res, coarse, roi)?;
    let view = delta::view_of(&tree, &spec);
    let mut out = delta::encode_header(&spec);
    out.extend_from_slice(&delta::encode_full(0, &view));
    Ok(out)
}

/// How [`dump`] lists a stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DumpFormat {
    /// A line for the stream, one per message (and per voxel with `voxels`).
    Text,
    /// One JSON object per message.
    Ndjson,
    /// One CSV row per message.
    Csv,
}

impl std::str::FromStr for DumpFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "text" => Ok(DumpFormat::Text),
            "ndjson" => Ok(DumpFormat::Ndjson),
            "csv" => Ok(DumpFormat::Csv),
            _ => Err(format!("unknown format {s:?} (text, ndjson or csv)")),
        }
    }
}

/// Lists a stream's messages to `out` (the voxels too with `voxels`, text and ndjson), each
/// line written whole.
pub fn dump(
    bytes: &[u8],
    name: &str,
    format: DumpFormat,
    voxels: bool,
    out: &mut dyn Write,
) -> Result<(), PipelineError> {
    let (h, msgs) = read_stream(bytes, name)?;
    let spec = h.spec;
    let mut lines = Vec::new();
    match format {
        DumpFormat::Text => {
            let roi = spec.roi.map_or("everywhere".to_string(), |r| {
                format!("{:?}..{:?}", r.min_m, r.max_m)
            });
            lines.push(format!(
                "stream: resolution {} m, coarse depth {} ({} m voxels), ROI {roi}",
                spec.resolution_m,
                spec.coarse_depth,
                spec.resolution_m * (1u64 << (TREE_DEPTH - spec.coarse_depth)) as f64
            ));
        }
        DumpFormat::Csv => lines.push(
            "offset,bytes,kind,scan,fine_occupied,fine_free,coarse_occupied,coarse_free,leaves"
                .into(),
        ),
        DumpFormat::Ndjson => {}
    }
    let emit = |out: &mut dyn Write, lines: &mut Vec<String>| -> Result<(), PipelineError> {
        let mut text = String::new();
        for l in lines.drain(..) {
            text.push_str(&l);
            text.push('\n');
        }
        out.write_all(text.as_bytes())
            .map_err(|source| IoError::Write {
                name: "<stdout>".into(),
                source,
            })
            .map_err(PipelineError::from)
    };
    for f in &msgs {
        dump_message(&spec, f, format, voxels, &mut lines);
        emit(out, &mut lines)?;
    }
    emit(out, &mut lines)
}

fn dump_message(
    spec: &ViewSpec,
    f: &delta::Framed,
    format: DumpFormat,
    voxels: bool,
    lines: &mut Vec<String>,
) {
    let (offset, bytes) = (f.offset, f.bytes);
    match (&f.message, format) {
        (Message::Delta { scan, delta: d }, DumpFormat::Text) => {
            lines.push(format!(
                "offset {offset} ({bytes} bytes): delta of scan {scan}: fine +{} occupied, +{} free; coarse +{} occupied, +{} free",
                d.fine_occupied.len(),
                d.fine_free.len(),
                d.coarse_occupied.len(),
                d.coarse_free.len()
            ));
            if voxels {
                for (c, col) in &d.fine_occupied {
                    lines.push(format!(
                        "  fine occupied key {:?} colour {col:?}",
                        unmorton(*c)
                    ));
                }
                for c in &d.fine_free {
                    lines.push(format!("  fine free key {:?}", unmorton(*c)));
                }
                let depth = spec.coarse_depth;
                for c in &d.coarse_occupied {
                    let k = spec.coarse_key(*c);
                    lines.push(format!("  coarse occupied key {k:?} (depth {depth})"));
                }
                for c in &d.coarse_free {
                    let k = spec.coarse_key(*c);
                    lines.push(format!("  coarse free key {k:?} (depth {depth})"));
                }
            }
        }
        (Message::Full { scan, leaves }, DumpFormat::Text) => lines.push(format!(
            "offset {offset} ({bytes} bytes): full view after scan {scan}: {} leaves ({} occupied)",
            leaves.len(),
            leaves.iter().filter(|l| l.2).count()
        )),
        (Message::Delta { scan, delta: d }, DumpFormat::Csv) => lines.push(format!(
            "{offset},{bytes},delta,{scan},{},{},{},{},",
            d.fine_occupied.len(),
            d.fine_free.len(),
            d.coarse_occupied.len(),
            d.coarse_free.len()
        )),
        (Message::Full { scan, leaves }, DumpFormat::Csv) => {
            lines.push(format!("{offset},{bytes},full,{scan},,,,,{}", leaves.len()))
        }
        (Message::Delta { scan, delta: d }, DumpFormat::Ndjson) => {
            let mut v = serde_json::json!({
                "offset": offset, "bytes": bytes, "kind": "delta", "scan": scan,
                "fine_occupied": d.fine_occupied.len(), "fine_free": d.fine_free.len(),
                "coarse_occupied": d.coarse_occupied.len(), "coarse_free": d.coarse_free.len(),
            });
            if voxels {
                v["voxels"] = serde_json::json!({
                    "fine_occupied": d.fine_occupied.iter()
                        .map(|(c, col)| serde_json::json!({"key": unmorton(*c), "rgb": col}))
                        .collect::<Vec<_>>(),
                    "fine_free": d.fine_free.iter().map(|c| unmorton(*c)).collect::<Vec<_>>(),
                    "coarse_occupied": d.coarse_occupied.iter()
                        .map(|c| spec.coarse_key(*c)).collect::<Vec<_>>(),
                    "coarse_free": d.coarse_free.iter()
                        .map(|c| spec.coarse_key(*c)).collect::<Vec<_>>(),
                });
            }
            lines.push(v.to_string());
        }
        (Message::Full { scan, leaves }, DumpFormat::Ndjson) => lines.push(
            serde_json::json!({"offset": offset, "bytes": bytes, "kind": "full", "scan": scan,
                "leaves": leaves.len(), "occupied": leaves.iter().filter(|l| l.2).count()})
            .to_string(),
        ),
    }
}

/// A synthetic survey's file: `.graph` bytes, or with `mcap` an MCAP of coloured scans.
pub fn synth(params: &synth::SurveyParams, mcap: bool) -> Result<Vec<u8>, ConfigError> {
    params.validate()?;
    let scans = synth::survey(params);
    Ok(if mcap {
        cloud::write_clouds_mcap(&scans)
    } else {
        graph::write(&scans)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_out_of_range_are_refused_with_units() {
        let bad = |f: fn(&mut BuildConfig)| {
            let mut c = BuildConfig::default();
            f(&mut c);
            c.validate().unwrap_err().to_string()
        };
        assert_eq!(
            bad(|c| c.resolution_m = 0.0),
            "--res: expected 0.0001 m ..= 1000 m, found 0"
        );
        assert!(bad(|c| c.resolution_m = f64::NAN).starts_with("--res: expected"));
        assert!(bad(|c| c.resolution_m = 1e300).contains("found 1e300"));
        assert!(
            bad(|c| c.max_range_m = Some(-1.0)).starts_with("--max-range: expected a range > 0 m")
        );
        assert!(bad(|c| c.max_range_m = Some(f64::INFINITY)).contains("found inf"));
        assert!(bad(|c| c.coarse = Coarse::Depth(0)).starts_with("--coarse-depth"));
        assert!(bad(|c| c.coarse = Coarse::Edge(0.05)).starts_with("--coarse-res: expected 0.1 m"));
        assert!(bad(|c| c.coarse = Coarse::Edge(1e9)).starts_with("--coarse-res"));
        assert!(bad(|c| c.origin_m = Some([0.0, 1e300, 0.0])).starts_with("--origin"));
        assert!(bad(|c| c.threads = Some(0)).starts_with("--threads"));
        assert!(
            bad(|c| {
                c.roi = Some(Roi {
                    min_m: [1.0, 0.0, 0.0],
                    max_m: [0.0, 1.0, 1.0],
                })
            })
            .starts_with("--roi")
        );
        assert!(check_scan_period(f64::NAN).is_err());
        assert!(check_scan_period(1e300).is_err());
        assert_eq!(check_scan_period(0.0), Ok(0.0));
        let ok = BuildConfig {
            coarse: Coarse::Edge(0.8),
            ..BuildConfig::default()
        };
        assert_eq!(ok.validate().map(|s| s.coarse_depth), Ok(13));
    }

    fn xyz_file(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn a_set_stop_flag_ends_the_build_before_the_next_scan() {
        let dir = tempfile::tempdir().unwrap();
        let a = xyz_file(dir.path(), "a.xyz", "1 0 0\n0 1 0\n");
        let b = xyz_file(dir.path(), "b.xyz", "0 0 1\n");
        let stop = AtomicBool::new(false);
        let mut rows = Vec::new();
        let mut sink = |r: &StatsRow| -> Result<(), SinkError> {
            rows.push(r.clone());
            // Stopped while the first scan is done: the second is not inserted.
            stop.store(true, Ordering::Relaxed);
            Ok(())
        };
        let mut out = Vec::new();
        let built = build(
            &BuildConfig::default(),
            &[a, b],
            &mut out,
            "mem",
            &mut Hooks {
                stop: &stop,
                stats: Some(&mut sink),
                progress: None,
            },
        )
        .unwrap();
        assert!(built.report.interrupted);
        assert_eq!(built.report.scans, 1);
        assert_eq!(rows.len(), 1);
        // The stream holds the header and one whole message.
        let (_, msgs) = delta::decode_stream(&out).unwrap();
        assert_eq!(msgs.len(), 1);
        assert!(
            built
                .summary("interrupted by SIGTERM")
                .ends_with("; interrupted by SIGTERM after 1 scans")
        );
    }

    #[test]
    fn the_issue_point_builds_at_once() {
        // Issue 14: "-1e-30 -1e-30 -1e-30" with --origin 0,0,0 hung forever.
        let dir = tempfile::tempdir().unwrap();
        let t = xyz_file(dir.path(), "t.xyz", "-1e-30 -1e-30 -1e-30\n");
        let cfg = BuildConfig {
            origin_m: Some([0.0; 3]),
            ..BuildConfig::default()
        };
        let never = AtomicBool::new(false);
        let mut out = Vec::new();
        let built = build(
            &cfg,
            &[t],
            &mut out,
            "mem",
            &mut Hooks {
                stop: &never,
                stats: None,
                progress: None,
            },
        )
        .unwrap();
        assert_eq!((built.report.scans, built.report.points), (1, 1));
        assert!(!built.report.interrupted);
    }

    #[test]
    fn a_map_of_an_unusable_resolution_is_named() {
        let map = b"# Octomap OcTree file\nid OcTree\nsize 0\nres 1e-10\ndata\n";
        let err = full(map, "m.ot", Coarse::default(), None).unwrap_err();
        assert_eq!(
            err.to_string(),
            "m.ot: resolution: expected 0.0001 m ..= 1000 m, found 1e-10"
        );
    }

    #[test]
    fn endless_inputs_are_cut_at_the_limit() {
        let mut zeros = std::io::repeat(0);
        let err = read_limited(&mut zeros, "/dev/zero", 1000).unwrap_err();
        assert_eq!(
            err.to_string(),
            "/dev/zero: read failed: more than 1000 bytes: not a file octo-delta reads whole"
        );
        let mut short: &[u8] = b"1 2 3\n";
        assert_eq!(read_limited(&mut short, "x", 6).unwrap(), b"1 2 3\n");
    }

    #[test]
    fn formats_by_name_and_extension() {
        for f in InputFormat::ALL {
            assert_eq!(f.name().parse::<InputFormat>(), Ok(f));
        }
        assert_eq!(
            InputFormat::from_path(Path::new("x.GRAPH")),
            Some(InputFormat::Graph)
        );
        assert_eq!(
            InputFormat::from_path(Path::new("x.txt")),
            Some(InputFormat::Xyz)
        );
        assert!("obj".parse::<InputFormat>().is_err());
    }
}
