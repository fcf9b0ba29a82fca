//! `octo`: an occupancy octree with OctoMap's semantics, whose changes stream over a narrow link.
//!
//! The map is built on the vehicle side from point clouds (scans with a sensor pose) exactly as
//! OctoMap 1.9 builds it (same log-odds arithmetic in `f32`, same 16-level keys, same 3D-DDA ray
//! cells, free-then-occupied updates, pruning), so its `.bt` and `.ot` files are read by
//! OctoMap's own tools and compare equal with the maps they build. After each scan only the
//! changes are sent: four lists of voxels (newly occupied, newly free) x (fine, with colour,
//! inside the operator's region of interest; coarse, colourless, outside it), in the stream
//! format of `docs/octo-delta-format.md`.
//!
//! Submodules:
//! - [`cloud`]: point-cloud readers (PCD, PLY, XYZ, MCAP with ROS 2 `PointCloud2`).
//! - [`graph`]: OctoMap's `.graph` scan-graph files, read and written.
//! - [`ros`]: ROS 2 messages (CDR) read and written, and rigid transforms.
//! - [`tf`]: the TF buffer and pose tracks that give each scan its pose.
//! - [`tree`]: the occupancy octree, OctoMap's updates and pruning on an arena of blocks.
//! - [`math`]: the tree's arithmetic: keys, Morton codes, log-odds, poses, the ray walk.
//! - [`synth`]: a synthetic seabed survey, scans to test and benchmark with.
//! - [`pipeline`]: octo-delta's build loop and its other commands as library calls, with the
//!   configuration checks (ranges with units) and a stop flag.
//! - [`view`]: the operator's view as it grew, as an MCAP file of `foxglove.SceneUpdate`s.
//!
//! Parsers of untrusted bytes in this module never panic, on any input: they return a
//! [`ParseError`] that carries the byte offset (or line) where the input stopped making sense.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod cast;
pub mod cellset;
pub mod checks;
pub mod delta;
pub mod files;
mod firstray;
pub mod graph;
pub mod hashorder;
mod lanes;
pub mod math;
mod order;
pub mod region;
pub mod synth;
pub mod transfer;
pub mod tree;

/// A sensor pose as OctoMap holds it: translation and rotation quaternion, in `f32`.
///
/// OctoMap reads the `f64` values of its files into `f32`; keeping the same precision and the
/// same arithmetic is what makes the same scans give the same map, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Translation x, y, z in metres.
    pub translation_m: [f32; 3],
    /// Rotation quaternion (w, x, y, z); not necessarily normalised (OctoMap does not either).
    pub rotation: [f32; 4],
}

impl Pose {
    /// The identity pose: no translation, no rotation.
    pub const IDENTITY: Pose = Pose {
        translation_m: [0.0; 3],
        rotation: [1.0, 0.0, 0.0, 0.0],
    };
}

impl Default for Pose {
    fn default() -> Self {
        Pose::IDENTITY
    }
}

/// One scan: points in the sensor frame, optional colours, and the pose of the sensor.
///
/// The sensor origin, where every ray starts, is the pose's translation; the points are
/// transformed into the map frame by the pose before they are inserted.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scan {
    /// Points (x, y, z) in metres, in the sensor frame.
    pub points: Vec<[f32; 3]>,
    /// One colour (r, g, b) per point, when the input carries colour.
    pub colors: Option<Vec<[u8; 3]>>,
    /// Where the sensor was.
    pub pose: Pose,
}

/// Bad bytes in a map, scan or delta input: where and what.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("offset {offset}: {message}")]
pub struct ParseError {
    /// Byte offset (from the start of the input) where the problem was found.
    pub offset: u64,
    /// What was wrong: field, expected vs found.
    pub message: String,
}

impl ParseError {
    /// An error at `offset` saying `message`.
    pub fn new(offset: u64, message: impl Into<String>) -> Self {
        ParseError {
            offset,
            message: message.into(),
        }
    }
}
