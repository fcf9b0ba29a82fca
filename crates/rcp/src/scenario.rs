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
//! Its waypoints are orders: a file owned by another user, or writable by group or others, is
//! refused before it is read ([`rovlink_base::secret::open_command_source`]).
//!
//! The TDMA cycle ([`Scenario::cycle`]) gives each vehicle, in address order, one slot; an
//! `auto` slot is the time its exchange takes along its routed path: on every hop out, the
//! operator frame's air time, the modem's intrinsic delay and the propagation over the hop's
//! distance at the start; on every hop back, the same for the ROV's frame; plus a guard of
//! three jitter standard deviations per hop each way. For one vehicle one hop away this is the
//! single-vehicle session's automatic IPG.

use std::path::Path;

use serde_json::{Map, Value};

use crate::ImageSettings;
use crate::Role;
use crate::config::{
    MAX_DURATION_S, MAX_IPG_S, MAX_POSITION_M, MIN_IMAGE_BYTES, MIN_IPG_S, Waypoint, bound_ipg,
};
use crate::routing::{MAX_VEHICLE, Routes, RoutesError};
use crate::rules;
use rovlink_base::secret::SecretFileError;
use rovlink_link::{Model, ModelError};

/// Largest scenario file read, bytes.
pub const MAX_SCENARIO_FILE_BYTES: u64 = 1 << 20;
/// A scenario's length when it gives none, s.
pub const DEFAULT_DURATION_S: f64 = 600.0;

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
    /// The file is owned by another user or writable by group or others: its waypoints are
    /// GoTo orders, and whoever can write to it could command the vehicles.
    #[error(transparent)]
    Refused(SecretFileError),
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
    /// Bytes every frame carries beyond the plain one: 0, or the secured frame's overhead when
    /// the session runs with keys (set by the caller, not the file); the slot rule counts them.
    pub frame_overhead_bytes: usize,
}

impl Scenario {
    /// Parses and checks a scenario; model files are found relative to `base_dir`.
    pub fn parse(text: &str, base_dir: &Path) -> Result<Scenario, ScenarioError> {
        let value: Value = rovlink_base::strict_json::from_str(text)
            .map_err(|e| field(".", format!("not JSON: {e}")))?;
        let Value::Object(top) = &value else {
            return Err(field(
                ".",
                format!("expected an object, found {}", kind(&value)),
            ));
        };
        only_keys(
            ".",
            top,
            &["duration_s", "seed", "nodes", "media", "routes", "image"],
        )?;
        let duration_s = match top.get("duration_s") {
            None => DEFAULT_DURATION_S,
            Some(v) => number_in("duration_s", v, f64::MIN_POSITIVE, MAX_DURATION_S, "s")?,
        };
        let seed = match top.get("seed") {
            None => 1,
            Some(v) => v.as_u64().ok_or_else(|| {
                field(
                    "seed",
                    format!("expected an integer 0 ..= {}, found {v}", u64::MAX),
                )
            })?,
        };
        let settings = image_settings(top.get("image"))?;
        let nodes = nodes(top.get("nodes"))?;
        let addresses: Vec<u8> = nodes.iter().map(|n| n.address).collect();
        let media = media(top.get("media"), &addresses, base_dir)?;
        for node in &nodes {
            if !media.iter().any(|m| m.nodes.contains(&node.address)) {
                return Err(field(
                    format!("nodes[{}]", index_of(&nodes, node.address)),
                    format!("node {} is on no medium", node.address),
                ));
            }
        }
        let routes = match top.get("routes") {
            None => Routes::direct(),
            Some(v) => Routes::from_json(v)?,
        };
        let scenario = Scenario {
            duration_s,
            seed,
            nodes,
            media,
            routes,
            settings,
            frame_overhead_bytes: 0,
        };
        scenario
            .routes
            .check(&addresses, &|a, b| scenario.medium_between(a, b).is_some())?;
        Ok(scenario)
    }

    /// Reads, parses and checks the scenario file at `path`.
    pub fn from_file(path: &Path) -> Result<Scenario, ScenarioError> {
        let name = path.display();
        regular_file(path).map_err(|what| field(name.to_string(), what))?;
        let cannot_read = |e: std::io::Error| field(name.to_string(), format!("cannot read: {e}"));
        let (file, _) =
            rovlink_base::secret::open_command_source(path, false).map_err(|e| match e {
                SecretFileError::Read { source, .. } => cannot_read(source),
                refused => ScenarioError::Refused(refused),
            })?;
        let bytes = rovlink_base::io::read_bounded(file, MAX_SCENARIO_FILE_BYTES)
            .map_err(cannot_read)?
            .ok_or_else(|| {
                field(
                    name.to_string(),
                    format!("larger than {MAX_SCENARIO_FILE_BYTES} bytes: not a scenario"),
                )
            })?;
        let text = std::str::from_utf8(&bytes)
            .map_err(|e| field(name.to_string(), format!("not UTF-8 text: {e}")))?;
        let base_dir = path.parent().unwrap_or(Path::new("."));
        Scenario::parse(text, base_dir).map_err(|e| match e {
            ScenarioError::Field { at, what } => field(format!("{name}: {at}"), what),
            ScenarioError::Model { at, error } => ScenarioError::Model {
                at: format!("{name}: {at}"),
                error,
            },
            ScenarioError::Routes(error) => field(name.to_string(), error.to_string()),
            refused @ ScenarioError::Refused(_) => refused,
        })
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
        let hops = |src: u8, dst: u8| -> Vec<rules::Hop<'_>> {
            let path = self.routes.path(src, dst).unwrap_or_else(|| vec![src, dst]);
            path.windows(2)
                .filter_map(|pair| {
                    let model = self.hop_model(pair[0], pair[1])?;
                    let distance_m = self.distance_m(pair[0], pair[1]);
                    Some(rules::Hop { model, distance_m })
                })
                .collect()
        };
        let slot_s = rules::slot_s(
            &hops(0, vehicle),
            &hops(vehicle, 0),
            self.settings.trunk_bytes,
            self.frame_overhead_bytes,
        );
        bound_ipg(slot_s).ipg_s
    }

    /// The model of the hop from `a` to `b`: their shared medium's, else `a`'s first.
    fn hop_model(&self, a: u8, b: u8) -> Option<&Model> {
        self.medium_between(a, b)
            .or_else(|| self.interfaces(a).first().copied())
            .map(|k| &self.media[k].model)
    }

    /// The distance between two nodes' positions at the start, m.
    pub fn distance_m(&self, a: u8, b: u8) -> f64 {
        let at = |n: u8| self.node(n).map_or([0.0; 3], |n| n.position_m);
        rovlink_base::geometry::distance_m(at(a), at(b))
    }

    /// The operator's cycle: one slot per vehicle, in address order.
    pub fn cycle(&self) -> Vec<Slot> {
        let mut start_s = 0.0;
        self.nodes
            .iter()
            .filter(|n| n.role == Role::Rov)
            .map(|n| {
                let length_s = n.slot_s.unwrap_or_else(|| self.auto_slot_s(n.address));
                let slot = Slot {
                    address: n.address,
                    start_s,
                    length_s,
                };
                start_s += length_s;
                slot
            })
            .collect()
    }

    /// The cycle's length, s.
    pub fn cycle_s(&self) -> f64 {
        self.cycle().iter().map(|s| s.length_s).sum()
    }
}

/// Refuses what is not a regular file (after symbolic links) before it is opened: opening a
/// FIFO with no writer would block the session forever, and a directory or a device is no
/// scenario or model.
fn regular_file(path: &Path) -> Result<(), String> {
    match std::fs::metadata(path) {
        Ok(meta) if meta.is_file() => Ok(()),
        Ok(_) => Err("cannot read: not a regular file".into()),
        Err(e) => Err(format!("cannot read: {e}")),
    }
}

fn field(at: impl Into<String>, what: impl Into<String>) -> ScenarioError {
    ScenarioError::Field {
        at: at.into(),
        what: what.into(),
    }
}

/// What a JSON value is, for messages.
fn kind(value: &Value) -> String {
    match value {
        Value::Null => "null".into(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) => n.to_string(),
        Value::String(s) => format!("{:?}", s.chars().take(40).collect::<String>()),
        Value::Array(_) => "an array".into(),
        Value::Object(_) => "an object".into(),
    }
}

fn only_keys(at: &str, object: &Map<String, Value>, known: &[&str]) -> Result<(), ScenarioError> {
    match object.keys().find(|k| !known.contains(&k.as_str())) {
        Some(key) => Err(field(
            at,
            format!(
                "unknown field {key:?}: expected one of {}",
                known.join(", ")
            ),
        )),
        None => Ok(()),
    }
}

fn number_in(
    at: &str,
    value: &Value,
    min: f64,
    max: f64,
    unit: &str,
) -> Result<f64, ScenarioError> {
    match value.as_f64() {
        Some(v) if v.is_finite() && (min..=max).contains(&v) => Ok(v),
        _ => Err(field(
            at,
            format!(
                "expected a number {} ..= {max} {unit}, found {}",
                if min == f64::MIN_POSITIVE {
                    "more than 0".to_string()
                } else {
                    min.to_string()
                },
                kind(value)
            ),
        )),
    }
}

fn position(at: &str, value: &Value) -> Result<[f64; 3], ScenarioError> {
    let items = value.as_array().filter(|a| a.len() == 3);
    let numbers: Option<Vec<f64>> = items.and_then(|a| a.iter().map(Value::as_f64).collect());
    match numbers {
        Some(v) if v.iter().all(|x| x.is_finite() && x.abs() <= MAX_POSITION_M) => {
            Ok([v[0], v[1], v[2]])
        }
        _ => Err(field(
            at,
            format!(
                "expected [x, y, z], NED m, each within ±{MAX_POSITION_M}, found {}",
                compact(value)
            ),
        )),
    }
}

/// A value as short JSON text, for messages.
fn compact(value: &Value) -> String {
    let text = value.to_string();
    if text.len() > 60 {
        format!("{}...", text.chars().take(57).collect::<String>())
    } else {
        text
    }
}

fn address(at: &str, value: &Value) -> Result<u8, ScenarioError> {
    match value.as_u64() {
        Some(a) if a <= u64::from(MAX_VEHICLE) => Ok(a as u8),
        _ => Err(field(
            at,
            format!(
                "expected an address 0 ..= {MAX_VEHICLE} (0 the operator), found {}",
                kind(value)
            ),
        )),
    }
}

fn index_of(nodes: &[Node], address: u8) -> usize {
    nodes.iter().position(|n| n.address == address).unwrap_or(0)
}

fn nodes(value: Option<&Value>) -> Result<Vec<Node>, ScenarioError> {
    let Some(Value::Array(items)) = value else {
        return Err(field(
            "nodes",
            format!(
                "expected an array of nodes, found {}",
                value.map_or("nothing".into(), kind)
            ),
        ));
    };
    let mut nodes: Vec<Node> = Vec::new();
    for (k, item) in items.iter().enumerate() {
        let at = format!("nodes[{k}]");
        let Value::Object(object) = item else {
            return Err(field(
                at,
                format!("expected an object, found {}", kind(item)),
            ));
        };
        only_keys(
            &at,
            object,
            &[
                "address",
                "role",
                "position",
                "start",
                "waypoints",
                "slot_s",
            ],
        )?;
        let address = address(
            &format!("{at}.address"),
            object.get("address").unwrap_or(&Value::Null),
        )?;
        let role = match object.get("role").and_then(Value::as_str) {
            Some("operator") => Role::Operator,
            Some("rov") => Role::Rov,
            _ => {
                return Err(field(
                    format!("{at}.role"),
                    format!(
                        "expected \"operator\" or \"rov\", found {}",
                        object.get("role").map_or("nothing".into(), kind)
                    ),
                ));
            }
        };
        if (role == Role::Operator) != (address == 0) {
            return Err(field(
                format!("{at}.address"),
                format!(
                    "the operator is address 0 and vehicles 1 ..= {MAX_VEHICLE}, found a {} at {address}",
                    role.name()
                ),
            ));
        }
        if nodes.iter().any(|n| n.address == address) {
            return Err(field(
                format!("{at}.address"),
                format!("address {address} given twice"),
            ));
        }
        let (key, other) = match role {
            Role::Operator => ("position", "start"),
            Role::Rov => ("start", "position"),
        };
        let position_m = match object.get(key).or_else(|| object.get(other)) {
            Some(v) => position(&format!("{at}.{key}"), v)?,
            None => [0.0; 3],
        };
        let mut waypoints = Vec::new();
        let mut slot_s = None;
        if role == Role::Rov {
            if let Some(v) = object.get("waypoints") {
                waypoints = waypoints_of(&format!("{at}.waypoints"), v)?;
            }
            match object.get("slot_s") {
                None => {}
                Some(Value::String(s)) if s == "auto" => {}
                Some(v) => {
                    slot_s = Some(number_in(
                        &format!("{at}.slot_s"),
                        v,
                        MIN_IPG_S,
                        MAX_IPG_S,
                        "s (or \"auto\")",
                    )?)
                }
            }
        } else if let Some(key) = ["waypoints", "slot_s"]
            .into_iter()
            .find(|k| object.contains_key(*k))
        {
            return Err(field(
                format!("{at}.{key}"),
                "only a vehicle has waypoints or a slot",
            ));
        }
        nodes.push(Node {
            address,
            role,
            position_m,
            waypoints,
            slot_s,
        });
    }
    if !nodes.iter().any(|n| n.role == Role::Operator) {
        return Err(field(
            "nodes",
            "expected one operator (address 0), found none",
        ));
    }
    if !nodes.iter().any(|n| n.role == Role::Rov) {
        return Err(field("nodes", "expected at least one vehicle, found none"));
    }
    nodes.sort_by_key(|n| n.address);
    Ok(nodes)
}

fn waypoints_of(at: &str, value: &Value) -> Result<Vec<Waypoint>, ScenarioError> {
    let Value::Array(items) = value else {
        return Err(field(
            at,
            format!(
                "expected an array of [t_s, x, y, z, heading_deg], found {}",
                kind(value)
            ),
        ));
    };
    let mut previous_s = 0.0;
    let mut waypoints = Vec::new();
    for (k, item) in items.iter().enumerate() {
        let at = format!("{at}[{k}]");
        let numbers: Option<Vec<f64>> = item
            .as_array()
            .filter(|a| a.len() == 5)
            .and_then(|a| a.iter().map(Value::as_f64).collect());
        let Some(v) = numbers else {
            return Err(field(
                at,
                format!(
                    "expected [t_s, x, y, z, heading_deg], found {}",
                    compact(item)
                ),
            ));
        };
        let waypoint = Waypoint {
            t_s: v[0],
            position_m: [v[1], v[2], v[3]],
            heading_deg: v[4],
        };
        waypoint.check(at.clone()).map_err(|e| {
            field(
                at.clone(),
                format!("expected {}, found {}", e.expected, e.found),
            )
        })?;
        if waypoint.t_s < previous_s {
            return Err(field(
                at,
                format!(
                    "expected a time at or after {previous_s} s (sorted), found {} s",
                    waypoint.t_s
                ),
            ));
        }
        previous_s = waypoint.t_s;
        waypoints.push(waypoint);
    }
    Ok(waypoints)
}

fn media(
    value: Option<&Value>,
    addresses: &[u8],
    base_dir: &Path,
) -> Result<Vec<MediumSpec>, ScenarioError> {
    let Some(Value::Array(items)) = value else {
        return Err(field(
            "media",
            format!(
                "expected an array of media, found {}",
                value.map_or("nothing".into(), kind)
            ),
        ));
    };
    let mut media: Vec<MediumSpec> = Vec::new();
    for (k, item) in items.iter().enumerate() {
        let at = format!("media[{k}]");
        let Value::Object(object) = item else {
            return Err(field(
                at,
                format!("expected an object, found {}", kind(item)),
            ));
        };
        only_keys(&at, object, &["name", "model", "nodes"])?;
        let name = match object.get("name") {
            None => format!("medium {k}"),
            Some(Value::String(s))
                if (1..=64).contains(&s.chars().count()) && !s.chars().any(char::is_control) =>
            {
                s.clone()
            }
            Some(v) => {
                return Err(field(
                    format!("{at}.name"),
                    format!(
                        "expected a name of 1 ..= 64 characters, none a control character, found {}",
                        kind(v)
                    ),
                ));
            }
        };
        if media.iter().any(|m| m.name == name) {
            return Err(field(
                format!("{at}.name"),
                format!("medium {name:?} given twice"),
            ));
        }
        let model_at = format!("{at}.model");
        let model = match object.get("model") {
            Some(Value::String(s)) => {
                if rovlink_link::model::PRESETS.contains(&s.as_str()) {
                    Model::preset(s)
                } else {
                    let file = base_dir.join(s);
                    regular_file(&file).map_err(|what| field(&model_at, format!("{s}: {what}")))?;
                    Model::from_file(&file)
                }
            }
            Some(v @ Value::Object(_)) => Model::from_json(&v.to_string()),
            other => {
                return Err(field(
                    model_at,
                    format!(
                        "expected a preset name, a model file or a model object, found {}",
                        other.map_or("nothing".into(), kind)
                    ),
                ));
            }
        }
        .map_err(|error| ScenarioError::Model {
            at: model_at,
            error,
        })?;
        let nodes_at = format!("{at}.nodes");
        let Some(Value::Array(list)) = object.get("nodes") else {
            return Err(field(nodes_at, "expected an array of node addresses"));
        };
        let mut nodes = Vec::new();
        for (j, v) in list.iter().enumerate() {
            let a = address(&format!("{nodes_at}[{j}]"), v)?;
            if !addresses.contains(&a) {
                return Err(field(
                    format!("{nodes_at}[{j}]"),
                    format!("expected a node of the scenario, found {a}"),
                ));
            }
            if nodes.contains(&a) {
                return Err(field(
                    format!("{nodes_at}[{j}]"),
                    format!("node {a} given twice"),
                ));
            }
            nodes.push(a);
        }
        if nodes.len() < 2 {
            return Err(field(
                nodes_at,
                format!("expected at least 2 nodes, found {}", nodes.len()),
            ));
        }
        media.push(MediumSpec { name, model, nodes });
    }
    if media.is_empty() {
        return Err(field("media", "expected at least one medium, found none"));
    }
    Ok(media)
}

fn image_settings(value: Option<&Value>) -> Result<ImageSettings, ScenarioError> {
    let mut settings = ImageSettings::default();
    let Some(value) = value else {
        return Ok(settings);
    };
    let Value::Object(object) = value else {
        return Err(field(
            "image",
            format!("expected an object, found {}", kind(value)),
        ));
    };
    only_keys(
        "image",
        object,
        &["size_bytes", "trunk_bytes", "gray", "fec_percent"],
    )?;
    if let Some(v) = object.get("size_bytes") {
        settings.size_bytes = number_in(
            "image.size_bytes",
            v,
            f64::from(MIN_IMAGE_BYTES),
            65535.0,
            "bytes",
        )?
        .round() as u16;
    }
    if let Some(v) = object.get("trunk_bytes") {
        let max = rovlink_wire::rov::MAX_TRUNK_BYTES as f64;
        settings.trunk_bytes = number_in("image.trunk_bytes", v, 1.0, max, "bytes")?.round() as u8;
    }
    if let Some(v) = object.get("fec_percent") {
        let max = f64::from(rovlink_debt::fec::MAX_PERCENT);
        settings.fec_percent =
            number_in("image.fec_percent", v, 0.0, max, "percent")?.round() as u8;
    }
    if let Some(v) = object.get("gray") {
        settings.gray = v.as_bool().ok_or_else(|| {
            field(
                "image.gray",
                format!("expected true or false, found {}", kind(v)),
            )
        })?;
    }
    Ok(settings)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The issue's scenario.
    pub(crate) const THREE: &str = r#"{"duration_s":600,"seed":1,
      "nodes":[{"address":0,"role":"operator","position":[0,0,0]},
               {"address":1,"role":"rov","start":[3,0,1]},
               {"address":2,"role":"rov","start":[7,0,1],"waypoints":[[30,7.5,1,1,90]]}],
      "media":[{"name":"rf","model":"s100","nodes":[0,1,2]}],
      "routes":{"0":{"2":1},"2":{"0":1}}}"#;

    fn parse(text: &str) -> Result<Scenario, ScenarioError> {
        Scenario::parse(text, Path::new("."))
    }

    #[test]
    fn a_model_file_that_is_not_a_regular_file_and_odd_medium_names_are_refused() {
        let dir = std::env::temp_dir();
        let text = THREE.replace(r#""model":"s100""#, r#""model":".""#);
        let error = Scenario::parse(&text, &dir).unwrap_err().to_string();
        assert!(error.contains("media[0].model") && error.contains("not a regular file"));
        for name in [r#""a\nb""#, &format!("{:?}", "é".repeat(65))] {
            let text = THREE.replace(r#""name":"rf""#, &format!(r#""name":{name}"#));
            let error = parse(&text).unwrap_err().to_string();
            assert!(error.starts_with("media[0].name: "), "{error}");
        }
        let text = THREE.replace(r#""name":"rf""#, &format!("\"name\":{:?}", "é".repeat(64)));
        assert_eq!(parse(&text).unwrap().media[0].name.chars().count(), 64);
    }

    #[test]
    fn a_scenario_file_others_may_write_is_refused_and_ours_is_read() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("three.json");
        std::fs::write(&path, THREE).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert_eq!(Scenario::from_file(&path).unwrap().vehicles(), [1, 2]);
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o662)).unwrap();
        let error = Scenario::from_file(&path).unwrap_err();
        assert!(matches!(error, ScenarioError::Refused(_)), "{error}");
        assert!(error.to_string().contains("0662 are too open"), "{error}");
    }

    #[test]
    fn the_issue_scenario_parses_and_its_cycle_follows_the_paths() {
        let s = parse(THREE).unwrap();
        assert_eq!(s.vehicles(), [1, 2]);
        assert_eq!(s.node(2).unwrap().waypoints.len(), 1);
        assert_eq!(s.neighbours(1), vec![vec![0, 2]]);
        let cycle = s.cycle();
        assert_eq!(cycle.len(), 2);
        // One hop: the single-vehicle session's automatic IPG.
        let model = Model::preset("s100").unwrap();
        let single = crate::config::auto_ipg_for(&model, &s.settings, [3.0, 0.0, 1.0], [0.0; 3], 0);
        assert!(
            (cycle[0].length_s - single).abs() < 1e-9,
            "{cycle:?} vs {single}"
        );
        // Two hops: about twice as long, and it starts when vehicle 1's ends.
        assert!(
            (cycle[1].length_s / cycle[0].length_s - 2.0).abs() < 0.05,
            "{cycle:?}"
        );
        assert_eq!(cycle[1].start_s, cycle[0].length_s);
        assert!((s.cycle_s() - cycle[0].length_s - cycle[1].length_s).abs() < 1e-12);
    }

    #[test]
    fn fixed_slots_and_image_settings_are_taken() {
        let text = THREE
            .replace(r#""start":[3,0,1]}"#, r#""start":[3,0,1],"slot_s":1.5}"#)
            .replace(
                r#""seed":1,"#,
                r#""seed":1,"image":{"size_bytes":1000,"trunk_bytes":20},"#,
            );
        let s = parse(&text).unwrap();
        assert_eq!(s.cycle()[0].length_s, 1.5);
        assert_eq!((s.settings.size_bytes, s.settings.trunk_bytes), (1000, 20));
    }

    #[test]
    fn bad_scenarios_name_the_field() {
        let cases = [
            ("[]", ".: expected an object, found an array"),
            (r#"{"nodes":[]}"#, "nodes: expected one operator"),
            (
                &THREE.replace(r#""duration_s":600"#, r#""duration_s":-1"#),
                "duration_s: expected a number more than 0",
            ),
            (
                &THREE.replace(r#""start":[7,0,1]"#, r#""start":[7,0]"#),
                "nodes[2].start: expected [x, y, z]",
            ),
            (
                &THREE.replace(r#""address":2"#, r#""address":15"#),
                "nodes[2].address: expected an address 0 ..= 14",
            ),
            (
                &THREE.replace(r#""address":2"#, r#""address":1"#),
                "nodes[2].address: address 1 given twice",
            ),
            (
                &THREE.replace(r#""role":"rov","start":[3"#, r#""role":"rover","start":[3"#),
                "nodes[1].role: expected \"operator\" or \"rov\"",
            ),
            (&THREE.replace("s100", "nope"), "media[0].model:"),
            (
                &THREE.replace("[0,1,2]", "[0,1,3]"),
                "media[0].nodes[2]: expected a node of the scenario, found 3",
            ),
            (
                &THREE.replace("[0,1,2]", "[0,1]"),
                "nodes[2]: node 2 is on no medium",
            ),
            (
                &THREE.replace("[[30,7.5,1,1,90]]", "[[30,7.5,1,1]]"),
                "nodes[2].waypoints[0]: expected [t_s, x, y, z, heading_deg]",
            ),
            (
                &THREE.replace(r#""seed":1"#, r#""sead":1"#),
                ".: unknown field \"sead\"",
            ),
            (
                // A repeated key is refused, not "the last one wins".
                &THREE.replace(r#""seed":1"#, r#""seed":1,"seed":2"#),
                ".: not JSON: duplicate key \"seed\" (at seed): expected each key once",
            ),
            (
                &THREE
                    .replace(r#""slot_s""#, "x")
                    .replace(r#""start":[3,0,1]}"#, r#""start":[3,0,1],"slot_s":0}"#),
                "nodes[1].slot_s: expected a number 0.001",
            ),
        ];
        for (text, message) in cases {
            let error = parse(text).unwrap_err().to_string();
            assert!(error.starts_with(message), "{error}\nexpected: {message}");
        }
    }
}
