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
//!
//! Its parts, each re-exported here: `config` (the checked configuration), `inputs` (input
//! formats and reading), `ros2_input` (`ros2:TOPIC` inputs: a live ROS 2 topic), `reading` (the inputs read in
//! turn, scan by scan, on a thread of their own), `builder` (the build loop and its report), `commands` (apply, dump,
//! full, synth).

mod builder;
mod commands;
mod config;
pub(crate) mod inputs;
mod reading;
pub mod ros2_input;

pub use builder::{
    ARRIVAL_COLUMNS, ArrivalRow, BuildReport, Built, Hooks, STATS_COLUMNS, SinkError, StatsRow,
    StatsSink, arrival_rows, build,
};
pub use commands::{DumpFormat, apply, dump, full, read_stream, synth};
pub use config::{
    BuildConfig, CELLS_PER_SCAN_DEFAULT, COARSE_FACTOR_MAX, COORDINATE_MAX_M, Coarse, ConfigError,
    MAX_RANGE_M, RESOLUTION_MAX_M, RESOLUTION_MIN_M, THREADS_MAX, check_range, check_roi,
    check_scan_period, shown, view_spec,
};
pub use inputs::{InputFormat, MAX_INPUT_BYTES, input_files, read_input, read_limited};
pub use reading::{FOLLOW_POLL, Reading, count_skipped, read_inputs};

use rovlink_base::io::IoError;
use rovlink_octo::ParseError;
use rovlink_scans::recording::RecordingError;

/// Why a build (or another pipeline) failed.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// A live input (`ros2:TOPIC`) that cannot join or read its graph.
    #[error("{0}")]
    Live(String),
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
        "{name}: unknown input format (expected {extensions}, a rosbag2 directory or .db3; or --format)",
        extensions = InputFormat::extensions()
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
    /// A scan whose rays may cross more cells than [`BuildConfig::max_cells_per_scan`].
    #[error(
        "scan {scan}: {source} (--max-cells) at --res {resolution_m} m: use a coarser --res, \
         a --max-range, or a larger --max-cells"
    )]
    TooManyCells {
        /// The scan's number (0: the first).
        scan: u32,
        /// The map's voxel edge, m.
        resolution_m: f64,
        /// The bound and the budget.
        source: rovlink_octo::cast::TooManyCells,
    },
    /// Reading an input or writing an output failed.
    #[error(transparent)]
    Io(#[from] IoError),
    /// The stats sink failed.
    #[error(transparent)]
    Sink(SinkError),
}

impl PipelineError {
    /// Whether a bag read in one pass ([`BuildConfig::one_pass_bags`]) has to be read again in
    /// two: what was built from it is not the map two passes give.
    pub fn is_one_pass(&self) -> bool {
        matches!(
            self,
            PipelineError::Recording(RecordingError::OnePass { .. })
        )
    }
}
