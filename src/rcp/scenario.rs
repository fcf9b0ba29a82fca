//! A multi-vehicle scenario (`tdma-run --scenario FILE`): the nodes, the media they share, the
//! routes between them, and the TDMA cycle that follows.
//!
//! ```json
//! {"duration_s":600,"seed":1,
//!  "nodes":[{"address":0,"role":"operator","position":[0,0,0]},
//!           {"address":1,"role":"rov","start":[3,0,1]},
//!           {"address":2,"role":"rov","start":[7,0,1],"waypoints":[[30,7.5,1,1,90]]}],
//!  "media":[{"name":"rf","model":"s100","nodes":[0,1,2]}],
//!  "routes":{"0":{"2":1},"2":{"0":1}}}
//! ```
//!
//! A medium's `model` is a preset name, a model file (relative to the scenario's folder) or a
//! model object. A vehicle may give `"slot_s"` (seconds, or `"auto"`, the default), its
//! `"waypoints"` (`[t_s, x, y, z, heading_deg]` GoTo orders); the scenario may give `"image"`
//! (`{"size_bytes":2000,"trunk_bytes":39}`).
//!
//! The TDMA cycle ([`Scenario::cycle`]) gives each vehicle, in address order, one slot; an
//! `auto` slot is the time its exchange takes along its routed path: on every hop out, the
//! operator frame's air time, the modem's intrinsic delay and the propagation over the hop's
//! distance at the start; on every hop back, the same for the ROV's frame; plus a guard of
//! three jitter standard deviations per hop each way. For one vehicle one hop away this is the
//! single-vehicle session's automatic IPG.

use std::path::Path;

use super::ImageSettings;
use super::Role;
use super::routing::{Routes, RoutesError};
use super::session::Waypoint;
use crate::link::{Model, ModelError};

/// Largest scenario file read, bytes.
pub const MAX_SCENARIO_FILE_BYTES: u64 = 1 << 20;

/// One node of the network.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Its address: 0 the operator, 1..=14 a vehicle.
    pub address: u8,
    /// Operator or vehicle.
    pub role: Role,
    /// The operator's modem position, or the vehicle's start, NED m.
    pub position_m: [f64; 3],
    /// A vehicle's GoTo orders, sorted by time.
    pub waypoints: Vec<Waypoint>,
    /// A vehicle's slot, s; none for `auto`.
    pub slot_s: Option<f64>,
}

/// One medium: a channel some nodes share, with its model.
#[derive(Debug, Clone, PartialEq)]
pub struct MediumSpec {
    /// Its name (for messages and events).
    pub name: String,
    /// The model every node on it sends with.
    pub model: Model,
    /// The addresses of its nodes.
    pub nodes: Vec<u8>,
}

/// One vehicle's slot in the operator's cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slot {
    /// The vehicle.
    pub address: u8,
    /// When the slot starts within the cycle, s.
    pub start_s: f64,
    /// Its length, s.
    pub length_s: f64,
}

/// Why a scenario is refused: `at` names the field (`nodes[2].start`), `what` says what was
/// expected and what was found.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// A field of the file.
    #[error("{at}: {what}")]
    Field {
        /// Where.
        at: String,
        /// What was wrong.
        what: String,
    },
    /// The routes.
    #[error(transparent)]
    Routes(#[from] RoutesError),
    /// A medium's model.
    #[error("{at}: {error}")]
    Model {
        /// Where.
        at: String,
        /// The model's error.
        error: ModelError,
    },
}

/// A whole multi-vehicle scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Length of the session, s.
    pub duration_s: f64,
    /// Seed of every random stream.
    pub seed: u64,
    /// The nodes, by address.
    pub nodes: Vec<Node>,
    /// The media.
    pub media: Vec<MediumSpec>,
    /// The routes (checked against the media).
    pub routes: Routes,
    /// How every vehicle encodes and cuts its images.
    pub settings: ImageSettings,
}

impl Scenario {
    /// Parses and checks a scenario; model files are found relative to `base_dir`.
    pub fn parse(text: &str, base_dir: &Path) -> Result<Scenario, ScenarioError> {
        let _ = (text, base_dir);
        todo!("lead")
    }

    /// Reads, parses and checks the scenario file at `path`.
    pub fn from_file(path: &Path) -> Result<Scenario, ScenarioError> {
        let _ = path;
        todo!("lead")
    }

    /// The node at `address`.
    pub fn node(&self, address: u8) -> Option<&Node> {
        self.nodes.iter().find(|n| n.address == address)
    }

    /// The vehicles' addresses, ascending.
    pub fn vehicles(&self) -> Vec<u8> {
        self.nodes
            .iter()
            .filter(|n| n.role == Role::Rov)
            .map(|n| n.address)
            .collect()
    }

    /// The media `address` is on (its interfaces, in the order of `media`): indices into
    /// `media`.
    pub fn interfaces(&self, address: u8) -> Vec<usize> {
        (0..self.media.len())
            .filter(|&k| self.media[k].nodes.contains(&address))
            .collect()
    }

    /// Per interface of `address` (as [`Scenario::interfaces`]), the other nodes it reaches.
    pub fn neighbours(&self, address: u8) -> Vec<Vec<u8>> {
        self.interfaces(address)
            .into_iter()
            .map(|k| {
                let nodes = &self.media[k].nodes;
                nodes.iter().copied().filter(|&n| n != address).collect()
            })
            .collect()
    }

    /// The first medium both `a` and `b` are on.
    pub fn medium_between(&self, a: u8, b: u8) -> Option<usize> {
        (0..self.media.len())
            .find(|&k| self.media[k].nodes.contains(&a) && self.media[k].nodes.contains(&b))
    }

    /// The automatic slot of `vehicle`, s (see the module doc).
    pub fn auto_slot_s(&self, vehicle: u8) -> f64 {
        let _ = vehicle;
        todo!("lead")
    }

    /// The operator's cycle: one slot per vehicle, in address order.
    pub fn cycle(&self) -> Vec<Slot> {
        todo!("lead")
    }

    /// The cycle's length, s.
    pub fn cycle_s(&self) -> f64 {
        self.cycle().iter().map(|s| s.length_s).sum()
    }
}
