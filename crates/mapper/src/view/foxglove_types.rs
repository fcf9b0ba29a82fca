//! Foxglove's message types the view writes, shaped as their JSON Schemas
//! (`foxglove.SceneUpdate` and the types it holds), and that schema itself.

use serde::Serialize;

/// The schema's name: Foxglove's well-known scene update.
pub const SCHEMA_NAME: &str = "foxglove.SceneUpdate";
/// The official JSON Schema of `foxglove.SceneUpdate`.
pub const SCENE_UPDATE_SCHEMA: &str = include_str!("../foxglove/SceneUpdate.json");

/// A time as Foxglove's schemas carry it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: u64,
    /// Nanoseconds, 0 ..= 999 999 999.
    pub nsec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch.
    pub fn from_ns(ns: u64) -> Time {
        Time {
            sec: ns / 1_000_000_000,
            nsec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// `foxglove.Vector3` (positions and sizes, m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `foxglove.Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

/// `foxglove.Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PoseJson {
    /// Centre, m.
    pub position: Vector3,
    /// Always the identity: voxels are axis-aligned.
    pub orientation: Quaternion,
}

/// `foxglove.Color`, each channel 0 ..= 1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Color {
    /// Red.
    pub r: f64,
    /// Green.
    pub g: f64,
    /// Blue.
    pub b: f64,
    /// Opacity.
    pub a: f64,
}

/// `foxglove.CubePrimitive`: one occupied leaf of the view (or the part of one in a class).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Cube {
    /// Centre, identity orientation.
    pub pose: PoseJson,
    /// Edges along x, y, z, m.
    pub size: Vector3,
    /// Colour.
    pub color: Color,
}

/// `foxglove.SceneEntity`: the occupied voxels of one class in one unit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Entity {
    /// When the view took this state.
    pub timestamp: Time,
    /// [`FRAME_ID`](super::FRAME_ID).
    pub frame_id: &'static str,
    /// `fine/<depth>/<x>,<y>,<z>` or `coarse/...`.
    pub id: String,
    /// Zero: until replaced or deleted.
    pub lifetime: Time,
    /// False: the voxels stay where they are in the map frame.
    pub frame_locked: bool,
    /// None.
    pub metadata: [(); 0],
    /// None.
    pub arrows: [(); 0],
    /// The voxels.
    pub cubes: Vec<Cube>,
    /// None.
    pub spheres: [(); 0],
    /// None.
    pub cylinders: [(); 0],
    /// None.
    pub lines: [(); 0],
    /// None.
    pub triangles: [(); 0],
    /// None.
    pub texts: [(); 0],
    /// None.
    pub models: [(); 0],
}

/// `foxglove.SceneEntityDeletion` of one entity by id.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Deletion {
    /// Entities older than this go: one nanosecond after the message's own time.
    pub timestamp: Time,
    /// 0: `MATCHING_ID`.
    #[serde(rename = "type")]
    pub kind: u8,
    /// The entity.
    pub id: String,
}

/// `foxglove.SceneUpdate`: what one stream message changed in the scene.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SceneUpdate {
    /// Entities that no longer exist.
    pub deletions: Vec<Deletion>,
    /// Entities new or replaced.
    pub entities: Vec<Entity>,
}
