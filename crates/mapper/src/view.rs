//! The operator's view as Foxglove plays it: an MCAP file with one `foxglove.SceneUpdate` per
//! message of a delta stream, logged when that message reached the operator, so Foxglove's 3D
//! panel shows the map growing as the operator saw it.
//!
//! # Entities
//!
//! The view ([`Receiver`]'s octree) is cut into *units*: a node at [`BLOCK_DEPTH`] (a block of
//! 8 x 8 x 8 fine voxels), or a leaf above that depth (a coarse voxel bigger than a block, a
//! pruned region). Units never overlap. Each unit with occupied space is one entity per class,
//! with id `fine/<depth>/<x>,<y>,<z>` or `coarse/<depth>/<x>,<y>,<z>` (the unit's depth and the
//! key of its first voxel), holding one `CubePrimitive` per occupied leaf of the unit: centre
//! and edge of the leaf (a box, when a leaf bigger than a coarse voxel straddles the ROI's
//! edge and is cut there), in frame [`FRAME_ID`].
//!
//! After each message, every unit the message touched is sent again whole (an entity replaces
//! the one with the same id), and the entities of units that became empty, or were split or
//! merged into other units, are deleted (`deletions`, by id). So at any time the entities are
//! exactly the occupied voxels of the view: voxels that become free disappear. A full message
//! touches everything. A unit holds at most 512 fine voxels, so what one changed voxel costs
//! is bounded.
//!
//! Fine voxels (inside the ROI, widened to whole coarse voxels, as [`ViewSpec::coarse_in_roi`]
//! says) are drawn opaque in their colour, or by height (a hue that runs from red to blue and
//! back every [`HEIGHT_PERIOD_M`]) when the map has none; coarse voxels are translucent grey.
//!
//! # Times
//!
//! Message k is logged (MCAP `log_time` and `publish_time`, and the entities' `timestamp`) at
//! `k x scan_period_s`, or with `build --link ... --arrivals` rows at that scan's `t_shown_s`:
//! when it and every earlier message were complete, which is when the operator's view (which
//! applies messages in order) changed. It equals `t_complete_s` unless a later message
//! completed first; logging at `t_complete_s` then would replay an older state of a unit after
//! a newer one. The arrivals file is read strictly: its header, every field, one row per
//! message in stream order with the scan number and size of that message.
//!
//! # Encoding
//!
//! Messages are JSON (`json` message encoding) with the official JSON Schema of
//! `foxglove.SceneUpdate` (`jsonschema` schema encoding; [`SCENE_UPDATE_SCHEMA`] is
//! `schemas/jsonschema/SceneUpdate.json` of github.com/foxglove/foxglove-sdk at commit
//! 9ed45b16, MIT licence), written with the `mcap` crate, uncompressed, never seeking. Foxglove
//! plays JSON-encoded MCAP with well-known schema names natively; the official `foxglove`
//! crate's protobuf encoding would be smaller on disk but brings its generated types and
//! another MCAP writer for one message type, and the JSON is what other tools here write
//! (`rcp::mcap_log`).
//!
//! Foxglove fetches only the latest message of a topic when it seeks, so an incremental scene
//! is right when played from the start; after a seek backwards, play again from the start.
//!
//! Nothing here panics on any input: the stream and arrivals parsers return errors naming the
//! offset or the line and column, and memory is bounded by the view (which is bounded by the
//! stream) plus one message.

use std::collections::{BTreeMap, BTreeSet, HashSet};
use std::io::Write;

use serde::Serialize;

use crate::pipeline::{self, ARRIVAL_COLUMNS, ConfigError, PipelineError};
use rovlink_octo::delta::{Framed, Message, Receiver, ViewSpec};
use rovlink_octo::tree::{KEY_CENTER, NodeRef, OcTree, TREE_DEPTH, unmorton};

/// The topic of the scene updates.
pub const TOPIC: &str = "/octo_delta/view";
/// The frame every entity is in.
pub const FRAME_ID: &str = "map";
/// The schema's name: Foxglove's well-known scene update.
pub const SCHEMA_NAME: &str = "foxglove.SceneUpdate";
/// The official JSON Schema of `foxglove.SceneUpdate`.
pub const SCENE_UPDATE_SCHEMA: &str = include_str!("foxglove/SceneUpdate.json");
/// Depth of a block unit: 8 x 8 x 8 fine voxels.
pub const BLOCK_DEPTH: u32 = 13;
/// Latest log time, s (about 32 years: a log time in ns stays far inside 64 bits).
pub const MAX_TIME_S: f64 = 1e9;
/// Height over which the colours of uncoloured fine voxels go from red to blue and back, m.
pub const HEIGHT_PERIOD_M: f64 = 20.0;

/// Colour of coarse voxels: grey, translucent.
const COARSE_RGBA: [f64; 4] = [0.55, 0.55, 0.55, 0.35];

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
    /// [`FRAME_ID`].
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

/// Which class a voxel is drawn in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
enum Class {
    Fine = 0,
    Coarse = 1,
}

impl Class {
    fn name(self) -> &'static str {
        match self {
            Class::Fine => "fine",
            Class::Coarse => "coarse",
        }
    }
}

/// A box of fine-voxel keys, `lo` inclusive, `hi` exclusive (up to 65 536).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct KeyBox {
    lo: [u32; 3],
    hi: [u32; 3],
}

impl KeyBox {
    /// The box of the node of depth-16 code `code` at `depth`.
    fn of_node(code: u64, depth: u32) -> KeyBox {
        let k = unmorton(code);
        let n = 1u32 << (TREE_DEPTH - depth.min(TREE_DEPTH));
        let lo = k.map(|c| c as u32 & !(n - 1));
        KeyBox {
            lo,
            hi: lo.map(|c| c + n),
        }
    }

    fn is_empty(&self) -> bool {
        (0..3).any(|a| self.lo[a] >= self.hi[a])
    }
}

/// Pushes the parts of `b` inside `r` to `inside` and the rest (at most six boxes) to
/// `outside`.
fn split_box(b: KeyBox, r: &KeyBox, inside: &mut Vec<KeyBox>, outside: &mut Vec<KeyBox>) {
    let mut rest = b;
    for a in 0..3 {
        if rest.is_empty() {
            return;
        }
        if rest.lo[a] < r.lo[a] {
            let mut piece = rest;
            piece.hi[a] = rest.hi[a].min(r.lo[a]);
            outside.push(piece);
            rest.lo[a] = rest.lo[a].max(r.lo[a]);
        }
        if rest.is_empty() {
            return;
        }
        if rest.hi[a] > r.hi[a] {
            let mut piece = rest;
            piece.lo[a] = rest.lo[a].max(r.hi[a]);
            outside.push(piece);
            rest.hi[a] = rest.hi[a].min(r.hi[a]);
        }
    }
    if !rest.is_empty() {
        inside.push(rest);
    }
}

/// Bits of the depth-16 Morton code below a node of `depth`.
fn code_span(depth: u32) -> u64 {
    1u64 << (3 * (TREE_DEPTH - depth.min(TREE_DEPTH)))
}

/// The depth-16 code of the node of `depth` holding the voxel `code`.
fn node_code(code: u64, depth: u32) -> u64 {
    code & !(code_span(depth) - 1)
}

/// `v` rounded to `1 / scale` (keeps the JSON short: `1.25`, not `1.2500000000000002`).
fn rounded(v: f64, scale: f64) -> f64 {
    (v * scale).round() / scale
}

/// A unit: the depth-16 code of its first voxel and its depth.
type Unit = (u64, u32);

/// The scene side of a [`Receiver`]: applies each message to the view and says what changed in
/// the scene.
#[derive(Debug, Clone)]
pub struct SceneBuilder {
    spec: ViewSpec,
    rx: Receiver,
    /// The key box of the fine region (the ROI widened to coarse voxels); `None`: everywhere.
    fine_region: Option<KeyBox>,
    /// Units with an entity in the scene: first code -> (depth, classes present, bit per class).
    published: BTreeMap<u64, (u32, u8)>,
}

impl SceneBuilder {
    /// An empty scene for a stream of this view.
    pub fn new(spec: ViewSpec) -> SceneBuilder {
        SceneBuilder {
            spec,
            rx: Receiver::new(spec),
            fine_region: fine_region(&spec),
            published: BTreeMap::new(),
        }
    }

    /// The view so far.
    pub fn view(&self) -> &OcTree {
        self.rx.view()
    }

    /// Entities in the scene now.
    pub fn entities(&self) -> usize {
        self.published
            .values()
            .map(|&(_, mask)| mask.count_ones() as usize)
            .sum()
    }

    /// Applies one message to the view; returns the scene's update, stamped `time_ns`.
    pub fn apply(&mut self, m: &Message, time_ns: u64) -> SceneUpdate {
        let touched = self.touched(m);
        self.rx.apply(m);
        let mut regions: Vec<Unit> = touched
            .into_iter()
            .map(|(c, d)| self.widened(c, d))
            .collect();
        // Regions are octree nodes: two are nested or apart. Sorted by first code and, for the
        // same code, the bigger first, a nested one follows the one that holds it.
        regions.sort_unstable();
        let mut kept: Vec<Unit> = Vec::with_capacity(regions.len());
        for r in regions {
            if kept
                .last()
                .is_none_or(|&(c, d)| r.0 >= c + code_span(d) || r.0 < c)
            {
                kept.push(r);
            }
        }
        let stamp = Time::from_ns(time_ns);
        let mut gone: Vec<(Class, Unit)> = Vec::new();
        let mut update = SceneUpdate::default();
        let mut sent: HashSet<(Class, Unit)> = HashSet::new();
        for (code, depth) in kept {
            let end = code.saturating_add(code_span(depth));
            let old: Vec<(u64, (u32, u8))> = self
                .published
                .range(code..end)
                .map(|(&c, &v)| (c, v))
                .collect();
            for (c, (d, mask)) in old {
                self.published.remove(&c);
                for class in [Class::Fine, Class::Coarse] {
                    if mask & (1 << class as u8) != 0 {
                        gone.push((class, (c, d)));
                    }
                }
            }
            for (unit, node) in self.units_in(code, depth) {
                let cubes = self.render(node, unit);
                let mut mask = 0u8;
                for (class, cubes) in [(Class::Fine, cubes.0), (Class::Coarse, cubes.1)] {
                    if cubes.is_empty() {
                        continue;
                    }
                    mask |= 1 << class as u8;
                    sent.insert((class, unit));
                    update.entities.push(Entity {
                        timestamp: stamp,
                        frame_id: FRAME_ID,
                        id: entity_id(class, unit),
                        lifetime: Time { sec: 0, nsec: 0 },
                        frame_locked: false,
                        metadata: [],
                        arrows: [],
                        cubes,
                        spheres: [],
                        cylinders: [],
                        lines: [],
                        triangles: [],
                        texts: [],
                        models: [],
                    });
                }
                if mask != 0 {
                    self.published.insert(unit.0, (unit.1, mask));
                }
            }
        }
        let after = Time::from_ns(time_ns.saturating_add(1));
        update.deletions = gone
            .into_iter()
            .filter(|e| !sent.contains(e))
            .map(|(class, unit)| Deletion {
                timestamp: after,
                kind: 0,
                id: entity_id(class, unit),
            })
            .collect();
        update
    }

    /// The nodes a message sets, each as the unit-sized (or bigger) region holding it.
    fn touched(&self, m: &Message) -> BTreeSet<Unit> {
        let mut out = BTreeSet::new();
        match m {
            Message::Delta { delta, .. } => {
                let fine = delta
                    .fine_free
                    .iter()
                    .chain(delta.fine_occupied.iter().map(|(c, _)| c));
                for &c in fine {
                    out.insert((node_code(c, BLOCK_DEPTH), BLOCK_DEPTH));
                }
                let depth = self.spec.coarse_depth.min(BLOCK_DEPTH);
                let shift = self.spec.coarse_shift();
                for &c in delta.coarse_free.iter().chain(&delta.coarse_occupied) {
                    out.insert((node_code(c << shift, depth), depth));
                }
            }
            Message::Full { .. } => {
                out.insert((0, 0));
            }
        }
        out
    }

    /// The region to send again for a touched region: itself, or the unit of the scene or of
    /// the new view that holds it (a leaf above it).
    fn widened(&self, code: u64, depth: u32) -> Unit {
        let mut best = (code, depth);
        if let Some((&c, &(d, _))) = self.published.range(..=code).next_back()
            && d < best.1
            && code < c.saturating_add(code_span(d))
        {
            best = (c, d);
        }
        if let Some((_, d)) = self.view().search(code, depth)
            && d < best.1
        {
            best = (node_code(code, d), d);
        }
        best
    }

    /// The units of the view inside the region (`code`, `depth`), with their nodes.
    fn units_in(&self, code: u64, depth: u32) -> Vec<(Unit, NodeRef)> {
        let view = self.view();
        let mut out = Vec::new();
        let Some((node, found)) = view.search(code, depth) else {
            return out;
        };
        let mut stack = vec![(node, found, node_code(code, found))];
        while let Some((r, d, c)) = stack.pop() {
            if d >= BLOCK_DEPTH || !view.node(r).has_children() {
                out.push(((c, d), r));
                continue;
            }
            for i in 0..8 {
                if let Some(child) = view.child(r, i) {
                    stack.push((child, d + 1, c | ((i as u64) << (3 * (TREE_DEPTH - 1 - d)))));
                }
            }
        }
        out
    }

    /// The cubes of a unit's occupied leaves: (fine, coarse).
    fn render(&self, node: NodeRef, (code, depth): Unit) -> (Vec<Cube>, Vec<Cube>) {
        let view = self.view();
        let (mut fine, mut coarse) = (Vec::new(), Vec::new());
        let mut stack = vec![(node, depth, code)];
        let (mut inside, mut outside) = (Vec::new(), Vec::new());
        while let Some((r, d, c)) = stack.pop() {
            let v = view.node(r);
            if v.has_children() && d < TREE_DEPTH {
                for i in (0..8).rev() {
                    if let Some(child) = view.child(r, i) {
                        stack.push((child, d + 1, c | ((i as u64) << (3 * (TREE_DEPTH - 1 - d)))));
                    }
                }
                continue;
            }
            if v.log_odds < 0.0 {
                continue;
            }
            let b = KeyBox::of_node(c, d);
            match &self.fine_region {
                None => inside.push(b),
                Some(region) => split_box(b, region, &mut inside, &mut outside),
            }
            for b in inside.drain(..) {
                let color = match v.color {
                    Some(rgb) => {
                        let ch = |x: u8| rounded(f64::from(x) / 255.0, 1e4);
                        Color {
                            r: ch(rgb[0]),
                            g: ch(rgb[1]),
                            b: ch(rgb[2]),
                            a: 1.0,
                        }
                    }
                    None => height_color(self.center_m(&b, 2)),
                };
                fine.push(self.cube(&b, color));
            }
            for b in outside.drain(..) {
                let [r, g, bl, a] = COARSE_RGBA;
                coarse.push(self.cube(&b, Color { r, g, b: bl, a }));
            }
        }
        (fine, coarse)
    }

    fn center_m(&self, b: &KeyBox, axis: usize) -> f64 {
        let mid = (f64::from(b.lo[axis]) + f64::from(b.hi[axis])) / 2.0;
        (mid - KEY_CENTER as f64) * self.spec.resolution_m
    }

    fn cube(&self, b: &KeyBox, color: Color) -> Cube {
        let res = self.spec.resolution_m;
        let at = |a| rounded(self.center_m(b, a), 1e6);
        let edge = |a: usize| rounded(f64::from(b.hi[a] - b.lo[a]) * res, 1e6);
        Cube {
            pose: PoseJson {
                position: Vector3 {
                    x: at(0),
                    y: at(1),
                    z: at(2),
                },
                orientation: Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                    w: 1.0,
                },
            },
            size: Vector3 {
                x: edge(0),
                y: edge(1),
                z: edge(2),
            },
            color,
        }
    }
}

fn entity_id(class: Class, (code, depth): Unit) -> String {
    let k = unmorton(code);
    format!("{}/{depth}/{},{},{}", class.name(), k[0], k[1], k[2])
}

/// The key box of the coarse voxels that meet the ROI (the same test as
/// [`ViewSpec::coarse_in_roi`], axis by axis); `None` without an ROI.
fn fine_region(spec: &ViewSpec) -> Option<KeyBox> {
    let roi = spec.roi?;
    let depth = spec.coarse_depth.clamp(1, TREE_DEPTH);
    let shift = TREE_DEPTH - depth;
    let edge_m = spec.resolution_m * (1u64 << shift) as f64;
    let mut region = KeyBox {
        lo: [0; 3],
        hi: [0; 3],
    };
    for a in 0..3 {
        let meets = |i: u32| {
            let lo_m = ((i << shift) as i64 - KEY_CENTER) as f64 * spec.resolution_m;
            lo_m <= roi.max_m[a] && lo_m + edge_m >= roi.min_m[a]
        };
        let mut hits = (0..1u32 << depth).filter(|&i| meets(i));
        let Some(first) = hits.next() else {
            return Some(KeyBox {
                lo: [0; 3],
                hi: [0; 3],
            });
        };
        let last = hits.next_back().unwrap_or(first);
        region.lo[a] = first << shift;
        region.hi[a] = (last + 1) << shift;
    }
    Some(region)
}

/// A hue by height: red at multiples of [`HEIGHT_PERIOD_M`], blue half way, opaque.
fn height_color(z_m: f64) -> Color {
    let t = (z_m / HEIGHT_PERIOD_M).rem_euclid(1.0);
    let hue = (1.0 - (2.0 * t - 1.0).abs()) * 240.0;
    let x = 1.0 - ((hue / 60.0).rem_euclid(2.0) - 1.0).abs();
    let (r, g, b) = match (hue / 60.0) as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        _ => (0.0, x, 1.0),
    };
    let ch = |v: f64| rounded(v, 1e4);
    Color {
        r: ch(r),
        g: ch(g),
        b: ch(b),
        a: 1.0,
    }
}

/// One row of an arrivals file as the view needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArrivalTime {
    /// Line of the row in the file, from 1 (the header is line 1).
    pub line: u64,
    /// Scan number.
    pub scan: u32,
    /// Message bytes.
    pub bytes: usize,
    /// When the operator's view showed it, s.
    pub t_shown_s: f64,
}

/// What is wrong in an arrivals file: where (line, column) and what.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}, column {column}: {message}")]
pub struct ArrivalsError {
    /// Line, from 1.
    pub line: u64,
    /// Column name (or `header`, `row`).
    pub column: String,
    /// Expected vs found.
    pub message: String,
}

fn arrivals_error(line: u64, column: &str, message: impl Into<String>) -> ArrivalsError {
    ArrivalsError {
        line,
        column: column.to_string(),
        message: message.into(),
    }
}

/// Reads the CSV `build --arrivals` writes: the header exactly [`ARRIVAL_COLUMNS`], then rows
/// of six fields: whole numbers, times in seconds within 0 ..= [`MAX_TIME_S`] with
/// `t_ready_s <= t_complete_s <= t_shown_s` and `t_shown_s` never going back.
pub fn read_arrivals(text: &[u8]) -> Result<Vec<ArrivalTime>, ArrivalsError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(text);
    let mut records = reader.records();
    let header = ARRIVAL_COLUMNS.join(",");
    let first = match records.next() {
        None => {
            return Err(arrivals_error(
                1,
                "header",
                format!("expected `{header}`, found an empty file"),
            ));
        }
        Some(r) => r.map_err(|e| arrivals_error(1, "header", e.to_string()))?,
    };
    let found: Vec<&str> = first.iter().collect();
    if found != ARRIVAL_COLUMNS {
        return Err(arrivals_error(
            1,
            "header",
            format!("expected `{header}`, found `{}`", found.join(",")),
        ));
    }
    let mut rows = Vec::new();
    let mut last_shown = 0.0f64;
    for record in records {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            arrivals_error(line, "row", e.to_string())
        })?;
        let line = record.position().map_or(0, |p| p.line());
        if record.len() != ARRIVAL_COLUMNS.len() {
            return Err(arrivals_error(
                line,
                "row",
                format!(
                    "expected {} fields, found {}",
                    ARRIVAL_COLUMNS.len(),
                    record.len()
                ),
            ));
        }
        let field = |i: usize| record.get(i).unwrap_or("");
        let whole = |i: usize, max: u64| {
            field(i)
                .parse::<u64>()
                .ok()
                .filter(|&v| v <= max)
                .ok_or_else(|| {
                    arrivals_error(
                        line,
                        ARRIVAL_COLUMNS[i],
                        format!("expected a whole number 0 ..= {max}, found `{}`", field(i)),
                    )
                })
        };
        let time = |i: usize| {
            field(i)
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && (0.0..=MAX_TIME_S).contains(v))
                .ok_or_else(|| {
                    arrivals_error(
                        line,
                        ARRIVAL_COLUMNS[i],
                        format!("expected seconds 0 ..= 1e9, found `{}`", field(i)),
                    )
                })
        };
        let scan = whole(0, u64::from(u32::MAX))? as u32;
        let bytes = whole(1, u64::from(u32::MAX))? as usize;
        let (ready, complete, shown) = (time(2)?, time(3)?, time(4)?);
        // latency_s is t_shown_s - t_ready_s: any number of seconds, checked as one.
        time(5)?;
        if complete < ready || shown < complete {
            return Err(arrivals_error(
                line,
                "t_shown_s",
                format!(
                    "expected t_ready_s <= t_complete_s <= t_shown_s, found {ready}, {complete}, {shown}"
                ),
            ));
        }
        if shown < last_shown {
            return Err(arrivals_error(
                line,
                "t_shown_s",
                format!("expected at least the row before's {last_shown} s, found {shown}"),
            ));
        }
        last_shown = shown;
        rows.push(ArrivalTime {
            line,
            scan,
            bytes,
            t_shown_s: shown,
        });
    }
    Ok(rows)
}

/// When each message is logged.
#[derive(Debug, Clone, Copy)]
pub enum Timing<'a> {
    /// Message k at `k x` this many seconds.
    Period(f64),
    /// At the `t_shown_s` of an arrivals file's rows.
    Arrivals {
        /// The file's bytes.
        text: &'a [u8],
        /// Its name, for errors.
        name: &'a str,
    },
}

impl<'a> Timing<'a> {
    /// The timing of an arrivals file (its bytes and name, as [`pipeline::read_input`] gives
    /// them) when there is one, else one message every `period_s` seconds.
    pub fn new(arrivals: Option<&'a (Vec<u8>, String)>, period_s: f64) -> Self {
        match arrivals {
            Some((text, name)) => Timing::Arrivals { text, name },
            None => Timing::Period(period_s),
        }
    }
}

/// Why a view could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The stream does not parse, or a number is out of range.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// A time beyond [`MAX_TIME_S`].
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The arrivals file is wrong, or does not go with the stream.
    #[error("{name}: {source}")]
    Arrivals {
        /// The file.
        name: String,
        /// Where and what.
        source: ArrivalsError,
    },
    /// A scene update did not encode as JSON (it holds only finite numbers and strings).
    #[error("scene update: {0}")]
    Json(serde_json::Error),
    /// The MCAP writer failed (usually the disk).
    #[error("{name}: MCAP: {source}")]
    Mcap {
        /// The output.
        name: String,
        /// The writer's error.
        source: mcap::McapError,
    },
}

/// The log time of each of the first `count` messages of `msgs`, ns.
pub fn log_times_ns(
    msgs: &[Framed],
    count: usize,
    timing: Timing<'_>,
) -> Result<Vec<u64>, ViewError> {
    let count = count.min(msgs.len());
    let ns = |t_s: f64| (t_s * 1e9).round() as u64;
    match timing {
        Timing::Period(period_s) => {
            pipeline::check_scan_period(period_s)?;
            let last_s = count.saturating_sub(1) as f64 * period_s;
            if last_s > MAX_TIME_S {
                return Err(ConfigError {
                    option: "--scan-period",
                    expected: format!("message {} logged within {MAX_TIME_S:e} s", count - 1),
                    found: format!("{period_s} s x {} = {last_s:e} s", count - 1),
                }
                .into());
            }
            Ok((0..count).map(|k| ns(k as f64 * period_s)).collect())
        }
        Timing::Arrivals { text, name } => {
            let bad = |source| ViewError::Arrivals {
                name: name.to_string(),
                source,
            };
            let rows = read_arrivals(text).map_err(bad)?;
            if rows.len() > msgs.len() {
                let line = rows[msgs.len()].line;
                return Err(bad(arrivals_error(
                    line,
                    "row",
                    format!(
                        "the stream has {} messages, this is row {}",
                        msgs.len(),
                        msgs.len() + 1
                    ),
                )));
            }
            if rows.len() < count {
                let scan = match &msgs[rows.len()].message {
                    Message::Delta { scan, .. } | Message::Full { scan, .. } => *scan,
                };
                return Err(bad(arrivals_error(
                    rows.last().map_or(1, |r| r.line) + 1,
                    "scan",
                    format!(
                        "expected a row for message {} (scan {scan}), found the end of the file (to view only the {} messages that arrived: --messages {})",
                        rows.len(),
                        rows.len(),
                        rows.len()
                    ),
                )));
            }
            let mut out = Vec::with_capacity(count);
            for (k, (row, m)) in rows.iter().zip(msgs).take(count).enumerate() {
                let scan = match &m.message {
                    Message::Delta { scan, .. } | Message::Full { scan, .. } => *scan,
                };
                if row.scan != scan {
                    return Err(bad(arrivals_error(
                        row.line,
                        "scan",
                        format!(
                            "expected {scan} (message {k} of the stream), found {}",
                            row.scan
                        ),
                    )));
                }
                if row.bytes != m.bytes {
                    return Err(bad(arrivals_error(
                        row.line,
                        "bytes",
                        format!(
                            "expected {} (message {k}'s size in the stream), found {}",
                            m.bytes, row.bytes
                        ),
                    )));
                }
                out.push(ns(row.t_shown_s));
            }
            Ok(out)
        }
    }
}

/// What writing a view did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ViewReport {
    /// Scene updates written (one per message applied).
    pub messages: usize,
    /// Entities sent, replacements included.
    pub entities_sent: u64,
    /// Deletions sent.
    pub deletions: u64,
    /// Cubes sent.
    pub cubes_sent: u64,
    /// Entities in the scene at the end.
    pub entities_at_end: usize,
    /// The largest scene update, bytes of JSON.
    pub largest_message_bytes: usize,
}

/// Applies the first `messages` messages of a stream (`stream`, named `name`) and writes the
/// scene as it grew to `out` (named `out_name`) as MCAP; returns the view at the end and what
/// was written. The stream and the arrivals are checked whole before anything is written.
pub fn apply_with_view(
    stream: &[u8],
    name: &str,
    messages: usize,
    timing: Timing<'_>,
    out: &mut dyn Write,
    out_name: &str,
) -> Result<(OcTree, ViewReport), ViewError> {
    let (header, msgs) = pipeline::read_stream(stream, name)?;
    let times = log_times_ns(&msgs, messages, timing)?;
    let wrap = |source| ViewError::Mcap {
        name: out_name.to_string(),
        source,
    };
    let mut writer = rovlink_base::io::json_mcap_writer(out).map_err(wrap)?;
    let spec = header.spec;
    let mut about = BTreeMap::new();
    about.insert("resolution_m".to_string(), spec.resolution_m.to_string());
    about.insert("coarse_depth".to_string(), spec.coarse_depth.to_string());
    let channel = rovlink_base::io::json_mcap_channel(
        &mut writer,
        SCHEMA_NAME,
        SCENE_UPDATE_SCHEMA,
        TOPIC,
        &about,
    )
    .map_err(wrap)?;
    let mut scene = SceneBuilder::new(spec);
    let mut report = ViewReport::default();
    for (k, (m, &t_ns)) in msgs.iter().zip(&times).enumerate() {
        let update = scene.apply(&m.message, t_ns);
        report.entities_sent += update.entities.len() as u64;
        report.deletions += update.deletions.len() as u64;
        report.cubes_sent += update
            .entities
            .iter()
            .map(|e| e.cubes.len() as u64)
            .sum::<u64>();
        let json = serde_json::to_vec(&update).map_err(ViewError::Json)?;
        report.largest_message_bytes = report.largest_message_bytes.max(json.len());
        let h = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: k as u32,
            log_time: t_ns,
            publish_time: t_ns,
        };
        writer.write_to_known_channel(&h, &json).map_err(wrap)?;
        report.messages += 1;
    }
    writer.finish().map_err(wrap)?;
    report.entities_at_end = scene.entities();
    Ok((scene.view().clone(), report))
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;
    use rovlink_octo::delta::{self, Delta, Roi, Sender};
    use rovlink_octo::synth::{self, SurveyParams};
    use rovlink_octo::tree::{Key, morton};

    /// The scene a player has after `updates`: entity id -> cubes.
    fn replay(scene: &mut HashMap<String, Vec<Cube>>, u: &SceneUpdate) {
        for d in &u.deletions {
            assert!(scene.remove(&d.id).is_some(), "deleted {} never sent", d.id);
        }
        for e in &u.entities {
            assert!(!e.cubes.is_empty(), "{} sent empty", e.id);
            scene.insert(e.id.clone(), e.cubes.clone());
        }
    }

    /// Fine voxels of the scene: key -> (fine?, colour); each voxel in one cube only.
    fn scene_voxels(scene: &HashMap<String, Vec<Cube>>, res: f64) -> HashMap<Key, (bool, Color)> {
        let mut out = HashMap::new();
        for (id, cubes) in scene {
            let fine = id.starts_with("fine/");
            for c in cubes {
                let p = [c.pose.position.x, c.pose.position.y, c.pose.position.z];
                let s = [c.size.x, c.size.y, c.size.z];
                let lo: Vec<i64> = (0..3)
                    .map(|a| ((p[a] - s[a] / 2.0) / res).round() as i64 + KEY_CENTER)
                    .collect();
                let n: Vec<i64> = (0..3).map(|a| (s[a] / res).round() as i64).collect();
                for x in 0..n[0] {
                    for y in 0..n[1] {
                        for z in 0..n[2] {
                            let k = [lo[0] + x, lo[1] + y, lo[2] + z].map(|v| v as u16);
                            assert!(out.insert(k, (fine, c.color)).is_none(), "{k:?} twice");
                        }
                    }
                }
            }
        }
        out
    }

    /// Fine voxels of the view's occupied leaves: key -> (in the ROI's coarse voxels?, colour).
    fn view_voxels(view: &OcTree, spec: &ViewSpec) -> HashMap<Key, (bool, Option<[u8; 3]>)> {
        let mut out = HashMap::new();
        view.for_each_leaf(|code, depth, v| {
            if v.log_odds < 0.0 {
                return;
            }
            let b = KeyBox::of_node(code, depth);
            for x in b.lo[0]..b.hi[0] {
                for y in b.lo[1]..b.hi[1] {
                    for z in b.lo[2]..b.hi[2] {
                        let k = [x as u16, y as u16, z as u16];
                        let fine = spec.coarse_in_roi(morton(k) >> spec.coarse_shift());
                        out.insert(k, (fine, v.color));
                    }
                }
            }
        });
        out
    }

    fn assert_same(scene: &HashMap<String, Vec<Cube>>, view: &OcTree, spec: &ViewSpec) {
        let shown = scene_voxels(scene, spec.resolution_m);
        let want = view_voxels(view, spec);
        assert_eq!(shown.len(), want.len());
        for (k, (fine, col)) in &want {
            let (sfine, scol) = shown.get(k).unwrap_or_else(|| panic!("{k:?} not shown"));
            assert_eq!(sfine, fine, "{k:?} class");
            match (fine, col) {
                (true, Some(rgb)) => {
                    let got = [scol.r, scol.g, scol.b].map(|c| (c * 255.0).round() as u8);
                    assert_eq!(&got, rgb, "{k:?} colour");
                    assert_eq!(scol.a, 1.0);
                }
                (true, None) => assert_eq!(scol.a, 1.0),
                (false, _) => assert_eq!(scol.a, COARSE_RGBA[3]),
            }
        }
    }

    /// Deltas of a small coloured survey, then a full view, then deltas that free voxels.
    fn messages(spec: &ViewSpec) -> Vec<Message> {
        let params = SurveyParams {
            scans: 4,
            rays_x: 48,
            rays_y: 36,
            ..SurveyParams::default()
        };
        let mut tree = OcTree::new(spec.resolution_m);
        tree.enable_color();
        let mut tx = Sender::new(*spec);
        let mut out = Vec::new();
        for (k, scan) in synth::survey(&params).iter().enumerate() {
            let up = tree.insert_scan(scan, None);
            let d = tx.delta(&tree, &up.changes);
            out.push(Message::Delta {
                scan: k as u32,
                delta: d,
            });
        }
        let view = delta::view_of(&tree, spec);
        let full = delta::encode_full(4, &view);
        out.push(delta::decode_message(spec, &full, 0).unwrap().0);
        // Every other occupied voxel of the view becomes free.
        let mut freed = Delta::default();
        let mut i = 0;
        view.for_each_leaf(|code, depth, v| {
            i += 1;
            if v.log_odds < 0.0 || i % 2 == 0 {
                return;
            }
            if depth == TREE_DEPTH {
                freed.fine_free.push(code);
            } else if depth == spec.coarse_depth {
                freed.coarse_free.push(code >> spec.coarse_shift());
            }
        });
        assert!(!freed.fine_free.is_empty() || !freed.coarse_free.is_empty());
        out.push(Message::Delta {
            scan: 5,
            delta: freed,
        });
        out
    }

    #[test]
    fn the_replayed_scene_is_the_view_after_every_message() {
        let roi = Roi {
            min_m: [-4.0, -20.0, -5.0],
            max_m: [3.0, 20.0, 5.0],
        };
        for (coarse_depth, roi) in [(13, Some(roi)), (14, Some(roi)), (12, None)] {
            let spec = ViewSpec {
                resolution_m: 0.2,
                coarse_depth,
                roi,
            };
            let mut b = SceneBuilder::new(spec);
            let mut scene = HashMap::new();
            let (mut fine, mut coarse, mut deleted) = (0, 0, 0);
            for (k, m) in messages(&spec).iter().enumerate() {
                let u = b.apply(m, k as u64 * 1_000_000_000);
                for e in &u.entities {
                    assert_eq!(e.timestamp, Time::from_ns(k as u64 * 1_000_000_000));
                    if e.id.starts_with("fine/") {
                        fine += 1;
                    } else {
                        coarse += 1;
                    }
                }
                deleted += u.deletions.len();
                replay(&mut scene, &u);
                assert_same(&scene, b.view(), &spec);
                assert_eq!(b.entities(), scene.len());
            }
            assert!(
                fine > 0 && deleted > 0,
                "{coarse_depth}: {fine} fine, {deleted} deleted"
            );
            assert_eq!(coarse > 0, roi.is_some(), "{coarse_depth}: {coarse} coarse");
        }
    }

    #[test]
    fn merged_and_split_leaves_replace_their_blocks() {
        // Eight fine blocks filled whole merge into one leaf above the block depth; freeing
        // one voxel splits it again: the scene follows both ways.
        let spec = ViewSpec {
            resolution_m: 0.1,
            coarse_depth: 16,
            roi: None,
        };
        let mut b = SceneBuilder::new(spec);
        let mut scene = HashMap::new();
        let base = morton([32768; 3]);
        let all: Vec<(u64, Option<[u8; 3]>)> = (0..4096u64).map(|i| (base + i, None)).collect();
        let fill = Message::Delta {
            scan: 0,
            delta: Delta {
                fine_occupied: all,
                ..Delta::default()
            },
        };
        let u = b.apply(&fill, 0);
        assert_eq!(u.entities.len(), 1);
        assert_eq!(u.entities[0].id, "fine/12/32768,32768,32768");
        assert_eq!(u.entities[0].cubes[0].size.x, 1.6);
        replay(&mut scene, &u);
        let hole = Message::Delta {
            scan: 1,
            delta: Delta {
                fine_free: vec![base + 7],
                ..Delta::default()
            },
        };
        let u = b.apply(&hole, 1);
        assert_eq!(u.deletions.len(), 1);
        assert_eq!(u.entities.len(), 8);
        replay(&mut scene, &u);
        assert_same(&scene, b.view(), &spec);
        assert_eq!(scene_voxels(&scene, 0.1).len(), 4095);
    }

    #[test]
    fn the_fine_region_is_the_coarse_voxels_that_meet_the_roi() {
        for (res, depth, roi) in [
            (0.1, 5u32, ([-1.0e3, -30.0, -0.05], [1.0e3, 12.3, 0.05])),
            (0.3, 4, ([-1.0, -1.0, -1.0], [-1.0, -1.0, -1.0])),
            (0.1, 3, ([5e6, 5e6, 5e6], [6e6, 6e6, 6e6])),
        ] {
            let spec = ViewSpec {
                resolution_m: res,
                coarse_depth: depth,
                roi: Some(Roi {
                    min_m: roi.0,
                    max_m: roi.1,
                }),
            };
            let region = fine_region(&spec).unwrap();
            for c in 0..1u64 << (3 * depth) {
                let k = spec.coarse_key(c);
                let inside =
                    (0..3).all(|a| (region.lo[a]..region.hi[a]).contains(&u32::from(k[a])));
                assert_eq!(inside, spec.coarse_in_roi(c), "{spec:?} {k:?}");
            }
        }
    }

    #[test]
    fn a_box_splits_into_disjoint_pieces_that_cover_it() {
        let r = KeyBox {
            lo: [4, 4, 4],
            hi: [8, 12, 6],
        };
        let boxes = [
            KeyBox::of_node(0, 12),
            KeyBox::of_node(morton([6, 6, 4]), 15),
            KeyBox::of_node(morton([32, 0, 0]), 13),
            KeyBox {
                lo: [0; 3],
                hi: [65536; 3],
            },
        ];
        for b in boxes {
            let (mut inside, mut outside) = (Vec::new(), Vec::new());
            split_box(b, &r, &mut inside, &mut outside);
            assert!(inside.len() <= 1 && outside.len() <= 6);
            let vol = |b: &KeyBox| {
                (0..3)
                    .map(|a| u64::from(b.hi[a] - b.lo[a]))
                    .product::<u64>()
            };
            let total: u64 = inside.iter().chain(&outside).map(vol).sum();
            assert_eq!(total, vol(&b), "{b:?}");
            for p in &inside {
                assert!((0..3).all(|a| p.lo[a] >= r.lo[a] && p.hi[a] <= r.hi[a]));
            }
            for p in &outside {
                assert!(
                    (0..3).any(|a| p.hi[a] <= r.lo[a] || p.lo[a] >= r.hi[a]),
                    "{p:?}"
                );
            }
        }
    }

    const HEADER: &str = "scan,bytes,t_ready_s,t_complete_s,t_shown_s,latency_s\n";

    #[test]
    fn arrivals_are_read_strictly() {
        let ok = format!("{HEADER}0,89,0.0,0.31,0.31,0.31\n1,94,1.0,1.2,1.3,0.3\n");
        let rows = read_arrivals(ok.as_bytes()).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[1].line, rows[1].scan, rows[1].bytes), (3, 1, 94));
        assert_eq!(rows[1].t_shown_s, 1.3);
        let err = |text: &str| read_arrivals(text.as_bytes()).unwrap_err().to_string();
        assert_eq!(
            err(""),
            "line 1, column header: expected `scan,bytes,t_ready_s,t_complete_s,t_shown_s,latency_s`, found an empty file"
        );
        assert_eq!(
            err("scan,bytes\n"),
            "line 1, column header: expected `scan,bytes,t_ready_s,t_complete_s,t_shown_s,latency_s`, found `scan,bytes`"
        );
        assert_eq!(
            err(&format!("{HEADER}0,89,0,0.3,x,0.3\n")),
            "line 2, column t_shown_s: expected seconds 0 ..= 1e9, found `x`"
        );
        assert_eq!(
            err(&format!("{HEADER}0,89,0,0.3,0.3\n")),
            "line 2, column row: expected 6 fields, found 5"
        );
        assert_eq!(
            err(&format!("{HEADER}-1,89,0,0.3,0.3,0.3\n")),
            "line 2, column scan: expected a whole number 0 ..= 4294967295, found `-1`"
        );
        assert!(err(&format!("{HEADER}0,89,0,0.3,NaN,0.3\n")).contains("found `NaN`"));
        assert!(err(&format!("{HEADER}0,89,0,0.3,1e10,0.3\n")).contains("found `1e10`"));
        assert!(err(&format!("{HEADER}0,89,0,0.5,0.3,0.3\n")).starts_with(
            "line 2, column t_shown_s: expected t_ready_s <= t_complete_s <= t_shown_s"
        ));
        assert!(
            err(&format!("{HEADER}0,89,0,2,2,2\n1,9,1,1,1,0\n"))
                .starts_with("line 3, column t_shown_s: expected at least the row before's 2 s")
        );
    }

    fn framed(scans: &[(u32, usize)]) -> Vec<Framed> {
        scans
            .iter()
            .map(|&(scan, bytes)| Framed {
                offset: 0,
                bytes,
                message: Message::Delta {
                    scan,
                    delta: Delta::default(),
                },
            })
            .collect()
    }

    #[test]
    fn log_times_follow_the_arrivals_or_the_period() {
        let msgs = framed(&[(0, 89), (1, 94), (2, 50)]);
        let at = |text: &str, count| {
            log_times_ns(
                &msgs,
                count,
                Timing::Arrivals {
                    text: text.as_bytes(),
                    name: "a.csv",
                },
            )
            .map_err(|e| e.to_string())
        };
        let two = format!("{HEADER}0,89,0,0.31,0.31,0.31\n1,94,1,1.5,1.5,0.5\n");
        assert_eq!(at(&two, 2), Ok(vec![310_000_000, 1_500_000_000]));
        assert_eq!(
            at(&two, usize::MAX),
            Err("a.csv: line 4, column scan: expected a row for message 2 (scan 2), found the end of the file (to view only the 2 messages that arrived: --messages 2)".into())
        );
        let wrong = format!("{HEADER}0,89,0,0.31,0.31,0.31\n2,94,1,1.5,1.5,0.5\n");
        assert_eq!(
            at(&wrong, 2),
            Err("a.csv: line 3, column scan: expected 1 (message 1 of the stream), found 2".into())
        );
        let size = format!("{HEADER}0,90,0,0.31,0.31,0.31\n");
        assert_eq!(
            at(&size, 1),
            Err("a.csv: line 2, column bytes: expected 89 (message 0's size in the stream), found 90".into())
        );
        let four = format!("{two}2,50,2,2,2,0\n3,50,3,3,3,0\n");
        assert_eq!(
            at(&four, 1),
            Err("a.csv: line 5, column row: the stream has 3 messages, this is row 4".into())
        );
        let period = |p, n| log_times_ns(&msgs, n, Timing::Period(p)).map_err(|e| e.to_string());
        assert_eq!(period(0.5, 9), Ok(vec![0, 500_000_000, 1_000_000_000]));
        assert!(period(-1.0, 9).unwrap_err().starts_with("--scan-period"));
        let many = framed(&vec![(0, 1); 20_000]);
        let err = log_times_ns(&many, usize::MAX, Timing::Period(86_400.0)).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("--scan-period: expected message 19999 logged within 1e9 s"),
            "{err}"
        );
    }

    #[test]
    fn height_colours_are_opaque_and_in_range() {
        for z in [-1e6, -20.0, -5.0, 0.0, 3.3, 10.0, 19.9, 1e6] {
            let c = height_color(z);
            assert!(
                [c.r, c.g, c.b].iter().all(|v| (0.0..=1.0).contains(v)),
                "{z}: {c:?}"
            );
            assert_eq!(c.a, 1.0);
        }
        assert_eq!(height_color(0.0), height_color(HEIGHT_PERIOD_M));
        assert_ne!(height_color(0.0), height_color(HEIGHT_PERIOD_M / 2.0));
    }

    #[test]
    fn the_mcap_holds_one_valid_update_per_message() {
        let spec = ViewSpec {
            resolution_m: 0.2,
            coarse_depth: 13,
            roi: None,
        };
        let mut stream = delta::encode_header(&spec);
        for m in messages(&spec).iter().take(2) {
            if let Message::Delta { scan, delta: d } = m {
                stream.extend(delta::encode_delta(&spec, *scan, d));
            }
        }
        let mut out = Vec::new();
        let (view, report) = apply_with_view(
            &stream,
            "s.odl",
            usize::MAX,
            Timing::Period(2.0),
            &mut out,
            "v.mcap",
        )
        .unwrap();
        assert_eq!(report.messages, 2);
        assert!(report.cubes_sent > 0 && report.largest_message_bytes > 0);
        let mut scene = HashMap::new();
        let stream_msgs = mcap::MessageStream::new(&out).unwrap();
        for (k, m) in stream_msgs.enumerate() {
            let m = m.unwrap();
            assert_eq!(m.channel.topic, TOPIC);
            let schema = m.channel.schema.as_ref().unwrap();
            assert_eq!(
                (schema.name.as_str(), schema.encoding.as_str()),
                (SCHEMA_NAME, "jsonschema")
            );
            assert_eq!(m.channel.message_encoding, "json");
            assert_eq!(m.log_time, k as u64 * 2_000_000_000);
            assert_eq!(m.publish_time, m.log_time);
            let u: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            for e in u["entities"].as_array().unwrap() {
                let cubes: Vec<Cube> = e["cubes"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|c| Cube {
                        pose: PoseJson {
                            position: Vector3 {
                                x: c["pose"]["position"]["x"].as_f64().unwrap(),
                                y: c["pose"]["position"]["y"].as_f64().unwrap(),
                                z: c["pose"]["position"]["z"].as_f64().unwrap(),
                            },
                            orientation: Quaternion {
                                x: 0.0,
                                y: 0.0,
                                z: 0.0,
                                w: 1.0,
                            },
                        },
                        size: Vector3 {
                            x: c["size"]["x"].as_f64().unwrap(),
                            y: c["size"]["y"].as_f64().unwrap(),
                            z: c["size"]["z"].as_f64().unwrap(),
                        },
                        color: Color {
                            r: c["color"]["r"].as_f64().unwrap(),
                            g: c["color"]["g"].as_f64().unwrap(),
                            b: c["color"]["b"].as_f64().unwrap(),
                            a: c["color"]["a"].as_f64().unwrap(),
                        },
                    })
                    .collect();
                scene.insert(e["id"].as_str().unwrap().to_string(), cubes);
            }
        }
        assert_same(&scene, &view, &spec);
        // A bad stream writes nothing.
        let mut none = Vec::new();
        let err = apply_with_view(
            b"ODL1",
            "s.odl",
            9,
            Timing::Period(1.0),
            &mut none,
            "v.mcap",
        )
        .unwrap_err();
        assert!(err.to_string().starts_with("s.odl: offset"), "{err}");
        assert!(none.is_empty());
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]

        #[test]
        fn arbitrary_arrivals_and_messages_never_panic(
            text in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..200),
            depth in 1u32..=16,
            kind in 0u8..3,
        ) {
            let _ = read_arrivals(&text);
            let spec = ViewSpec {
                resolution_m: 0.1,
                coarse_depth: depth,
                roi: Some(Roi { min_m: [-0.3, -1.0, -0.5], max_m: [0.3, 2.0, 2.0] }),
            };
            let mut stream = delta::encode_header(&spec);
            stream.extend(delta::frame_message(kind, 7, &text));
            if let Ok((_, msgs)) = delta::decode_stream(&stream) {
                let mut b = SceneBuilder::new(spec);
                let mut scene = HashMap::new();
                for (k, m) in msgs.iter().chain(&msgs).enumerate() {
                    replay(&mut scene, &b.apply(&m.message, k as u64));
                }
                proptest::prop_assert_eq!(b.entities(), scene.len());
            }
        }
    }
}
