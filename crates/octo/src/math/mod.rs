//! The octree's arithmetic, OctoMap 1.9's to the bit: keys and coordinates ([`Grid`]), Morton
//! codes, log-odds ([`Params`]), poses (quaternions in `f32`, in OctoMap's order of operations),
//! the ray walk (Amanatides & Woo's 3D DDA with OctoMap's stopping rule) and the brightest-colour
//! rule of `ColorOcTree`. Pure functions of numbers: the tree ([`super::tree`]) holds the state.
//!
//! Keys are 16 bits per axis (`key = floor(c / res) + 32768`); a Morton code interleaves a
//! key's bits so that its 3-bit groups, root first, are the child indices from the root down
//! (`x | y << 1 | z << 2`), which makes ascending codes the depth-first order of the tree.
//!
//! One file per concept, all re-exported here:
//! - `key`: keys, Morton codes, the voxels of a node;
//! - `logodds`: log-odds and the sensor model ([`Params`]);
//! - `color`: `ColorOcTree`'s colour slots and the brightest-colour rule;
//! - `grid`: coordinates to keys and back ([`Grid`]);
//! - `ray`: the ray walk and its set-up, one ray or a fan of rays from one origin;
//! - `pose`: poses in OctoMap's `f32`, a scan's points in the map frame ([`world_points`]).

mod color;
mod grid;
mod key;
mod logodds;
mod pose;
mod ray;

pub use color::{ColorSlot, WHITE, brightness_key, luma};
pub(crate) use color::{MeanColor, NO_COLOR, brighter, color_slot, mean_color, slot_order};
pub use grid::Grid;
pub use key::{KEY_CENTER, Key, TREE_DEPTH, morton, unmorton};
pub(crate) use key::{local_morton, push_voxels};
pub use logodds::{Params, logodds, probability};
pub use pose::world_points;
pub(crate) use ray::{FAN_BATCH, Fan, RaySink, RayStart, RayWalk, end_at_range, norm_f32};
