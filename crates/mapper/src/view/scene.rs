//! The scene builder: applies each stream message to the operator's view and says, as one
//! `foxglove.SceneUpdate`, which units' entities changed (their occupied leaves as cubes,
//! coloured by class) and which went.

use std::collections::{BTreeMap, BTreeSet, HashSet};

use super::foxglove_types::{
    Color, Cube, Deletion, Entity, PoseJson, Quaternion, SceneUpdate, Time, Vector3,
};
use super::key_box::{KeyBox, code_span, fine_region, node_code, split_box};
use rovlink_octo::delta::{Message, Receiver, ViewSpec};
use rovlink_octo::tree::{KEY_CENTER, NodeRef, OcTree, TREE_DEPTH, unmorton};

/// The frame every entity is in.
pub const FRAME_ID: &str = "map";
/// Depth of a block unit: 8 x 8 x 8 fine voxels.
pub const BLOCK_DEPTH: u32 = 13;
/// Height over which the colours of uncoloured fine voxels go from red to blue and back, m.
pub const HEIGHT_PERIOD_M: f64 = 20.0;

/// Colour of coarse voxels: grey, translucent.
pub(super) const COARSE_RGBA: [f64; 4] = [0.55, 0.55, 0.55, 0.35];

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

    /// The view it receives.
    pub fn spec(&self) -> &ViewSpec {
        &self.spec
    }

    /// Takes a new region of interest (same resolution and coarse depth), keeping the view:
    /// the blocks whose colouring changes are sent again by the region message that follows.
    pub fn set_roi(&mut self, roi: Option<rovlink_octo::delta::Roi>) {
        self.spec.roi = roi;
        self.rx.set_roi(roi);
        self.fine_region = fine_region(&self.spec);
    }

    /// The whole scene now, stamped `time_ns`, for a client that just subscribed (scene
    /// updates are incremental): every entity, built afresh from the view.
    pub fn snapshot(&self, time_ns: u64) -> SceneUpdate {
        let mut leaves = Vec::new();
        self.view().for_each_leaf(|code, depth, v| {
            leaves.push((code, depth, v.log_odds >= 0.0, v.color));
        });
        let mut fresh = SceneBuilder::new(self.spec);
        fresh.apply(&Message::Full { scan: 0, leaves }, time_ns)
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
            Message::Region { coarse, .. } => {
                let depth = self.spec.coarse_depth.min(BLOCK_DEPTH);
                let shift = self.spec.coarse_shift();
                for &c in coarse {
                    out.insert((node_code(c << shift, depth), depth));
                }
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

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::super::test_support::{assert_same, messages, replay, scene_voxels};
    use super::*;
    use rovlink_octo::delta::{Delta, Roi};
    use rovlink_octo::tree::morton;

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
}
