//! The occupancy octree: OctoMap's semantics on an arena of 8-node blocks.
//!
//! A voxel's state is a log-odds value (`f32`): every scan adds `prob_hit_log` to the voxels
//! its points end in and `prob_miss_log` to the voxels its rays cross, clamped to
//! `[clamp_min_log, clamp_max_log]`; a voxel is occupied when its log-odds is >= 0. Keys are 16
//! bits per axis (`key = floor(c / res) + 32768`), so the tree has 16 levels below the root and
//! a child's index at depth `d` takes bit `15 - d` of each key: `x | y << 1 | z << 2`. That
//! arithmetic (keys, Morton codes, log-odds, poses, the ray walk, the colour order) is
//! [`super::math`]'s; this module holds the tree and its updates.
//!
//! The arithmetic, the ray cells (Amanatides & Woo's 3D DDA, with OctoMap's stopping rule), the
//! order of the updates (a voxel hit by a point is updated as occupied only, whatever rays
//! crossed it) and pruning (eight equal leaf children collapse into their parent; an inner
//! node holds the maximum of its children) are OctoMap 1.9's, so the same scans give the same
//! tree, node for node and bit for bit, as `graph2tree` builds.
//!
//! Speed comes from doing the same work in a different order, which gives the same result:
//! OctoMap updates voxel by voxel from a hash set, descending from the root and trying to prune
//! the whole path after every voxel. Here a scan's voxels are sorted in Morton order (depth-first
//! order of the tree) and applied in one recursive pass, so each touched inner node is visited
//! once and pruned once, after all its children are final. Because every voxel is updated at
//! most once per scan and pruning always ends in the same fully pruned tree, the outcome is
//! OctoMap's. That holds for log-odds, not for colours: a coloured tree is updated voxel by
//! voxel in OctoMap's own order ([`super::hashorder`]).
//!
//! Colour is OctoMap 1.9's `ColorOcTree`, driven by the calls a colour mapper makes after each
//! `insertPointCloud`: `search` the node that holds each point's voxel and, when the point's
//! colour is brighter than the node's (or the node has none), `setNodeColor`. Brighter means a
//! higher BT.601 luma, ties broken by r, then g, then b, so the outcome does not depend on the
//! order of the points. White (255, 255, 255) is `ColorOcTree`'s "no colour": a white point
//! colours nothing. Occupancy decides pruning alone (`ColorOcTree::isNodeCollapsible`): eight
//! leaf children of equal log-odds collapse whatever their colours, and the collapsed node takes
//! child 0's colour, replaced, when that one is set, by the integer mean of the children's set
//! colours (`ColorOcTree::pruneNode`); an expanded node's children copy its colour. So a
//! coloured tree has exactly the structure of the `OcTree` of the same scans, and its colours
//! are those `ColorOcTree` holds after the same calls (`tests/octomap_color.rs` checks both
//! against liboctomap). Inner colours are written as `updateInnerOccupancy()` sets them: the
//! mean of the children's set colours, from the leaves up.
//!
//! [`OcTree::set_node`] (the operator's views, built voxel by voxel from delta messages) prunes
//! only children equal in value and colour, so no voxel's colour sent over the link is lost.
//!
//! Nothing here panics on any input: points and colours of any value are inserted or skipped.

use std::sync::atomic::AtomicBool;

use super::Scan;
use super::cast::Upd;
pub use super::cast::{PreparedScan, ScanCaster};
use super::math::{Grid, NO_COLOR, brighter, color_slot, mean_color, push_voxels};
use super::order::{Region, Risk, inside};

pub use super::math::{
    ColorSlot, KEY_CENTER, Key, Params, TREE_DEPTH, WHITE, brightness_key, logodds, luma, morton,
    probability, unmorton, world_points,
};

/// Updates below which a child's run is found by scanning rather than by bisection.
const SHORT_RUN_SCAN: usize = 32;

const NONE: u32 = u32::MAX;

#[derive(Clone)]
struct Block {
    value: [f32; 8],
    child: [u32; 8],
    mask: u8,
}

impl Block {
    fn empty() -> Self {
        Block {
            value: [0.0; 8],
            child: [NONE; 8],
            mask: 0,
        }
    }
}

/// A voxel whose state changed in a scan (OctoMap's change detection: it was unknown, or its
/// occupancy flipped), or, with `recolor`, an occupied voxel whose colour changed (a brighter
/// point fell in it, or its node was pruned with siblings of other colours).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Change {
    /// Morton code of the depth-16 voxel.
    pub code: u64,
    /// Occupied after the scan.
    pub occupied: bool,
    /// Its colour after the scan, if it has one.
    pub color: Option<[u8; 3]>,
    /// Only the colour changed (the voxel was and is occupied).
    pub recolor: bool,
}

/// What inserting one scan did.
#[derive(Debug, Clone, Default)]
pub struct ScanUpdate {
    /// Points in the scan.
    pub points: usize,
    /// Points skipped: not finite, or outside the tree's key range (never wrapped).
    pub points_skipped: usize,
    /// Points beyond the maximum range (their ray marks free space up to the range only).
    pub points_beyond_range: usize,
    /// Distinct voxels updated as free.
    pub free_voxels: usize,
    /// Distinct voxels updated as occupied.
    pub occupied_voxels: usize,
    /// Voxels whose state changed, in Morton order.
    pub changes: Vec<Change>,
}

/// What one scan's structural pass found besides the occupancy flips: voxels whose colour may
/// have changed (a pruned node took its children's mean colour).
#[derive(Default)]
struct PassLog {
    flips: Vec<Change>,
    recolored: Vec<u64>,
}

/// One node as a view: its value and whether it has children.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeView {
    /// Log-odds.
    pub log_odds: f32,
    /// Colour, if any.
    pub color: Option<[u8; 3]>,
    /// Index of its children's block, if it has children.
    children: u32,
    /// Which children exist.
    mask: u8,
}

impl NodeView {
    /// Whether the node has children (is an inner node).
    pub fn has_children(&self) -> bool {
        self.children != NONE
    }
    /// Which of the eight children exist (bit i: child i).
    pub fn child_mask(&self) -> u8 {
        if self.children == NONE { 0 } else { self.mask }
    }
}

/// The occupancy octree.
#[derive(Clone)]
pub struct OcTree {
    grid: Grid,
    params: Params,
    blocks: Vec<Block>,
    colors: Option<Vec<[ColorSlot; 8]>>,
    free_list: Vec<u32>,
    nodes: usize,
    caster: ScanCaster,
}

impl std::fmt::Debug for OcTree {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OcTree")
            .field("resolution_m", &self.grid.resolution_m())
            .field("nodes", &self.nodes)
            .field("colored", &self.colors.is_some())
            .finish()
    }
}

impl OcTree {
    /// An empty tree of voxel edge `resolution_m` metres with OctoMap's default sensor model.
    pub fn new(resolution_m: f64) -> Self {
        Self::with_params(resolution_m, Params::default())
    }

    /// An empty tree with the given sensor model.
    pub fn with_params(resolution_m: f64, params: Params) -> Self {
        let mut root = Block::empty();
        root.mask = 0;
        OcTree {
            grid: Grid::new(resolution_m),
            params,
            blocks: vec![root],
            colors: None,
            free_list: Vec::new(),
            nodes: 0,
            caster: ScanCaster::new(resolution_m, false, 1),
        }
    }

    /// Makes the tree keep colours (a `ColorOcTree`).
    pub fn enable_color(&mut self) {
        if self.colors.is_none() {
            self.colors = Some(vec![[NO_COLOR; 8]; self.blocks.len()]);
        }
    }

    /// Forgets the colours (the tree becomes an `OcTree`); nodes are not re-pruned.
    pub fn drop_colors(&mut self) {
        self.colors = None;
    }

    /// Whether the tree keeps colours.
    pub fn is_colored(&self) -> bool {
        self.colors.is_some()
    }

    /// Voxel edge in metres.
    pub fn resolution_m(&self) -> f64 {
        self.grid.resolution_m()
    }

    /// The sensor model.
    pub fn params(&self) -> Params {
        self.params
    }

    /// Number of nodes (inner and leaves), as OctoMap's `size()`.
    pub fn num_nodes(&self) -> usize {
        self.nodes
    }

    /// Bytes held by the tree's arrays.
    pub fn memory_bytes(&self) -> usize {
        self.blocks.capacity() * std::mem::size_of::<Block>()
            + self.colors.as_ref().map_or(0, |c| c.capacity() * 32)
    }

    /// OctoMap's `coordToKeyChecked` for one axis: `None` outside the key range.
    pub fn coord_to_key(&self, c: f32) -> Option<u16> {
        self.grid.coord_to_key(c)
    }

    /// The key of a point, `None` outside the key range.
    pub fn key_of(&self, p: [f32; 3]) -> Option<Key> {
        self.grid.key_of(p)
    }

    /// The centre coordinate of a key on one axis.
    pub fn key_to_coord(&self, k: u16) -> f64 {
        self.grid.key_to_coord(k)
    }

    /// Sets how many threads cast a scan's rays (1: none besides the caller; a coloured tree's
    /// scan uses two at most, and its cells keep the order of the points).
    pub fn set_threads(&mut self, threads: usize) {
        self.caster.set_threads(threads);
    }

    /// A caster for this tree's scans (its resolution, kind and threads), to cast them on
    /// another thread ([`ScanCaster::prepare`]) and apply them here ([`OcTree::apply_scan`]).
    pub fn caster(&self) -> ScanCaster {
        let mut c = ScanCaster::new(
            self.resolution_m(),
            self.is_colored(),
            self.caster.threads(),
        );
        c.set_max_cells(self.caster.max_cells());
        c
    }

    /// The tree's own caster (what [`insert_scan`](Self::insert_scan) casts with), its kind
    /// made the tree's.
    pub fn caster_mut(&mut self) -> &mut ScanCaster {
        if self.caster.is_colored() != self.is_colored() {
            self.caster = self.caster();
        }
        &mut self.caster
    }

    /// Inserts one scan as `graph2tree` does (`insertPointCloud` with the scan's pose, no lazy
    /// evaluation, no discretisation), with an optional maximum range, and returns what changed.
    pub fn insert_scan(&mut self, scan: &Scan, max_range_m: Option<f64>) -> ScanUpdate {
        let never = AtomicBool::new(false);
        self.insert_scan_until(scan, max_range_m, &never)
            .unwrap_or_default()
    }

    /// [`insert_scan`](Self::insert_scan), abandoned (`None`, the tree unchanged) when `stop`
    /// is set before its rays are cast: checked every few thousand points, so a large scan
    /// stops within milliseconds.
    pub fn insert_scan_until(
        &mut self,
        scan: &Scan,
        max_range_m: Option<f64>,
        stop: &AtomicBool,
    ) -> Option<ScanUpdate> {
        let prepared = self.caster_mut().prepare(scan, max_range_m, stop).ok()??;
        Some(self.apply_scan(&prepared))
    }

    /// Applies a scan cast by [`ScanCaster::prepare`] (for a tree of this resolution): a plain
    /// tree in one recursive pass over the cells in Morton order. A coloured tree the same way
    /// when the order of the updates cannot change its colours ([`super::order`]); else cell
    /// by cell in OctoMap's order (the scan cast again in that order if it was cast in Morton
    /// order), each update OctoMap's `updateNode` (pruning the path after it); then the colour
    /// calls. A scan prepared for the other kind of tree gives the same log-odds (the order
    /// decides colours only).
    pub fn apply_scan(&mut self, scan: &PreparedScan) -> ScanUpdate {
        let mut report = ScanUpdate {
            points: scan.points,
            points_skipped: scan.points_skipped,
            points_beyond_range: scan.points_beyond_range,
            free_voxels: scan.free_voxels(),
            occupied_voxels: scan.occupied_voxels(),
            changes: Vec::new(),
        };
        if scan.ups.is_empty() {
            return report;
        }
        let created = self.ensure_root();
        let mut log = PassLog {
            // Most of a scan's voxels change (new space): room for all, made once.
            flips: Vec::with_capacity(scan.ups.len()),
            recolored: Vec::new(),
        };
        if self.colors.is_none() {
            if scan.octomap_order || scan.source.is_some() {
                let mut ups = scan.ups.clone();
                ups.sort_unstable_by_key(|u| u.code);
                self.apply(0, 0, 0, &ups, created, &mut log);
            } else {
                self.apply(0, 0, 0, &scan.ups, created, &mut log);
            }
            report.changes = log.flips;
            return report;
        }
        if let (false, Some(src)) = (scan.octomap_order, &scan.source) {
            // OctoMap updates the free cells (its free `KeySet` less the hit cells), then the
            // hit cells (its occupied `KeySet`): each part in Morton order when its order
            // cannot matter. The hit cells' order is cheap to find (the points' end cells, in
            // the points' order); the free cells' needs every ray walked again.
            let (misses, hits) = scan.ups.split_at(scan.free_voxels());
            if super::order::order_can_matter(self, misses) {
                let again = self.caster_mut().prepare_keyset_order(src);
                report.changes = self.apply_in_order(&again, created, log);
                return report;
            }
            let mut created = created;
            if !misses.is_empty() {
                self.apply(0, 0, 0, misses, created, &mut log);
                created = false;
            }
            match super::order::order_risk(self, hits) {
                Risk::Nowhere => {
                    if !hits.is_empty() {
                        self.apply(0, 0, 0, hits, created, &mut log);
                    }
                }
                Risk::Whole => {
                    let hits = self.caster_mut().hits_in_keyset_order(src);
                    self.update_voxels(&hits, created, &mut log);
                }
                Risk::Within(risky) => {
                    let ordered = self.caster_mut().hits_in_keyset_order(src);
                    self.apply_within(hits, ordered, &risky, created, &mut log);
                }
            }
            // Ascending runs (the free cells', the hit cells' unless in `KeySet` order): the
            // stable sort finds and merges them.
            log.flips.sort_by_key(|c| c.code);
            report.changes = self.color_pass(&scan.hits, log);
            return report;
        }
        report.changes = self.apply_in_order(scan, created, log);
        report
    }

    /// Applies `ups` (no colour calls after them): voxel by voxel in their order, or, with
    /// `one_pass`, in one recursive pass (`ups` then in Morton order); the changes.
    #[cfg(test)]
    pub(crate) fn apply_ups(&mut self, ups: &[Upd], one_pass: bool) -> Vec<Change> {
        if ups.is_empty() {
            return Vec::new();
        }
        let created = self.ensure_root();
        let mut log = PassLog::default();
        if one_pass {
            self.apply(0, 0, 0, ups, created, &mut log);
        } else {
            self.update_voxels(ups, created, &mut log);
        }
        log.flips.sort_unstable_by_key(|c| c.code);
        self.color_pass(&[], log)
    }

    /// A phase whose order may matter only inside the subtrees `risky` ([`Risk::Within`]):
    /// its updates outside them (of `sorted`, the phase in Morton order) in one pass, then those
    /// inside voxel by voxel in the order `ordered` (the whole phase in OctoMap's order) holds
    /// them.
    fn apply_within(
        &mut self,
        sorted: &[Upd],
        mut ordered: Vec<Upd>,
        risky: &[Region],
        created: bool,
        log: &mut PassLog,
    ) {
        let outside: Vec<Upd> = sorted
            .iter()
            .filter(|u| !inside(risky, u.code))
            .copied()
            .collect();
        let mut created = created;
        if !outside.is_empty() {
            self.apply(0, 0, 0, &outside, created, log);
            created = false;
        }
        ordered.retain(|u| inside(risky, u.code));
        self.update_voxels(&ordered, created, log);
    }

    /// [`OcTree::apply_ups`] of a phase whose order may matter only inside `risky`, as a scan
    /// applies it: `sorted` (the phase in Morton order) outside them in one pass, inside in the
    /// order `ordered` holds them.
    #[cfg(test)]
    pub(crate) fn apply_ups_within(
        &mut self,
        sorted: &[Upd],
        ordered: &[Upd],
        risky: &[Region],
    ) -> Vec<Change> {
        if sorted.is_empty() {
            return Vec::new();
        }
        let created = self.ensure_root();
        let mut log = PassLog::default();
        self.apply_within(sorted, ordered.to_vec(), risky, created, &mut log);
        log.flips.sort_unstable_by_key(|c| c.code);
        self.color_pass(&[], log)
    }

    /// A coloured scan's updates voxel by voxel in the order `scan` holds them, then the colour
    /// calls.
    fn apply_in_order(
        &mut self,
        scan: &PreparedScan,
        created: bool,
        mut log: PassLog,
    ) -> Vec<Change> {
        self.update_voxels(&scan.ups, created, &mut log);
        log.flips.sort_unstable_by_key(|c| c.code);
        self.color_pass(&scan.hits, log)
    }

    /// `ups` voxel by voxel in their order ([`OcTree::update_voxel`]); `created`: the root was
    /// just created. Each voxel's descent starts where its path leaves the previous voxel's.
    fn update_voxels(&mut self, ups: &[Upd], created: bool, log: &mut PassLog) {
        let mut created = created;
        let mut path = VoxelPath::default();
        for u in ups {
            self.update_voxel(u, created, log, &mut path);
            created = false;
        }
    }

    /// The colour calls after a scan's occupancy updates (`ColorOcTree`'s `search` and
    /// `setNodeColor`): each hit voxel's brightest colour goes to the node that holds the voxel
    /// (the voxel itself or a pruned ancestor) if it is brighter than that node's, or the node
    /// has none. Then the changes get their final colours, and the occupied voxels whose colour
    /// changed without a flip are added as recolours, all in Morton order.
    fn color_pass(&mut self, occ: &[(u64, ColorSlot)], log: PassLog) -> Vec<Change> {
        let PassLog {
            flips,
            mut recolored,
        } = log;
        let mut walk = Descent::default();
        for &(code, c) in occ {
            if c[3] == 0 {
                continue;
            }
            let Some((r, depth)) = walk.search(self, code) else {
                continue;
            };
            let old = self.color(r.blk, r.slot as usize);
            if old[3] == 1 && !brighter(c, old) {
                continue;
            }
            self.set_color(r.blk, r.slot as usize, c);
            if self.blocks[r.blk as usize].value[r.slot as usize] >= 0.0 {
                push_voxels(&mut recolored, code, depth);
            }
        }
        recolored.sort_unstable();
        recolored.dedup();
        // The changes are looked up in ascending order too (colours changed, not structure).
        let mut walk = Descent::default();
        let mut color_at =
            |t: &OcTree, code: u64| walk.search(t, code).and_then(|(r, _)| t.node(r).color);
        let mut out = Vec::with_capacity(flips.len() + recolored.len());
        let mut k = 0;
        for f in flips {
            while k < recolored.len() && recolored[k] < f.code {
                out.push(Change {
                    code: recolored[k],
                    occupied: true,
                    color: color_at(self, recolored[k]),
                    recolor: true,
                });
                k += 1;
            }
            if k < recolored.len() && recolored[k] == f.code {
                k += 1;
            }
            let color = if f.occupied {
                color_at(self, f.code)
            } else {
                None
            };
            out.push(Change { color, ..f });
        }
        for &code in &recolored[k..] {
            out.push(Change {
                code,
                occupied: true,
                color: color_at(self, code),
                recolor: true,
            });
        }
        out
    }

    /// Creates the root (log-odds 0, no colour) if the tree is empty; true if it did.
    fn ensure_root(&mut self) -> bool {
        let created = self.blocks[0].mask & 1 == 0;
        if created {
            self.blocks[0].mask = 1;
            self.blocks[0].value[0] = 0.0;
            self.blocks[0].child[0] = NONE;
            self.set_color(0, 0, NO_COLOR);
            self.nodes += 1;
        }
        created
    }

    fn set_color(&mut self, blk: u32, slot: usize, c: ColorSlot) {
        if let Some(cs) = &mut self.colors {
            cs[blk as usize][slot] = c;
        }
    }

    fn color(&self, blk: u32, slot: usize) -> ColorSlot {
        self.colors
            .as_ref()
            .map_or(NO_COLOR, |cs| cs[blk as usize][slot])
    }

    fn alloc_block(&mut self) -> u32 {
        if let Some(b) = self.free_list.pop() {
            self.blocks[b as usize] = Block::empty();
            if let Some(cs) = &mut self.colors {
                cs[b as usize] = [NO_COLOR; 8];
            }
            b
        } else {
            self.blocks.push(Block::empty());
            if let Some(cs) = &mut self.colors {
                cs.push([NO_COLOR; 8]);
            }
            (self.blocks.len() - 1) as u32
        }
    }

    /// OctoMap's early abort: a value already clamped in the update's direction stays as it is.
    pub(crate) fn at_clamp(&self, v: f32, hit: bool) -> bool {
        if hit {
            v >= self.params.clamp_max_log
        } else {
            v <= self.params.clamp_min_log
        }
    }

    /// A voxel's log-odds after a hit or a miss from `v` (`updateNodeLogOdds` with its
    /// clamping; unchanged when already clamped in that direction).
    pub(crate) fn updated_log_odds(&self, v: f32, hit: bool) -> f32 {
        if self.at_clamp(v, hit) {
            return v;
        }
        let p = self.params;
        let nv = v + if hit { p.hit_log } else { p.miss_log };
        if nv < p.clamp_min_log {
            p.clamp_min_log
        } else if nv > p.clamp_max_log {
            p.clamp_max_log
        } else {
            nv
        }
    }

    /// The block of a node's children, allocated if it has none yet. A node that existed
    /// (`expand`: a pruned leaf, known space) gets eight children copying its value and colour;
    /// a node just created gets an empty block.
    fn children_block(&mut self, blk: u32, slot: usize, expand: bool) -> u32 {
        let cb = self.blocks[blk as usize].child[slot];
        if cb != NONE {
            return cb;
        }
        let v = self.blocks[blk as usize].value[slot];
        let c = self.color(blk, slot);
        let cb = self.alloc_block();
        self.blocks[blk as usize].child[slot] = cb;
        if expand {
            let b = &mut self.blocks[cb as usize];
            b.value = [v; 8];
            b.mask = 0xff;
            if let Some(cs) = &mut self.colors {
                cs[cb as usize] = [c; 8];
            }
            self.nodes += 8;
        }
        cb
    }

    /// Creates child `digit` of block `cb` (log-odds 0, no colour) if it does not exist; true if
    /// it did not.
    fn create_child(&mut self, cb: u32, digit: usize) -> bool {
        let b = &mut self.blocks[cb as usize];
        let created = b.mask & (1 << digit) == 0;
        if created {
            b.mask |= 1 << digit;
            b.value[digit] = 0.0;
            b.child[digit] = NONE;
            self.set_color(cb, digit, NO_COLOR);
            self.nodes += 1;
        }
        created
    }

    fn apply(
        &mut self,
        blk: u32,
        slot: usize,
        depth: u32,
        ups: &[Upd],
        just_created: bool,
        log: &mut PassLog,
    ) {
        if depth == TREE_DEPTH {
            self.update_leaf(blk, slot, &ups[0], just_created, log);
            return;
        }
        if self.blocks[blk as usize].child[slot] == NONE && !just_created {
            // A pruned node: expand it unless every update finds it clamped (OctoMap's early
            // abort in `updateNode`).
            let v = self.blocks[blk as usize].value[slot];
            if ups.iter().all(|u| self.at_clamp(v, u.hit)) {
                return;
            }
        }
        let child_blk = self.children_block(blk, slot, !just_created);
        let mut start = 0;
        while start < ups.len() {
            let (digit, run) = digit_run(&ups[start..], depth);
            let end = start + run;
            let created = self.create_child(child_blk, digit);
            self.apply(child_blk, digit, depth + 1, &ups[start..end], created, log);
            start = end;
        }
        // Prune if the eight children are leaves of equal value (`ColorOcTree::pruneNode`),
        // else hold the maximum of the children.
        if !self.prune_logged(blk, slot, child_blk, depth, ups[0].code, log) {
            self.set_max(blk, slot, child_blk);
        }
    }

    /// OctoMap's update of a depth-16 voxel (`updateNodeLogOdds` with its clamping) and its
    /// change detection: a flip is logged when the voxel is new or its occupancy changed.
    fn update_leaf(
        &mut self,
        blk: u32,
        slot: usize,
        u: &Upd,
        just_created: bool,
        log: &mut PassLog,
    ) {
        let v = self.blocks[blk as usize].value[slot];
        let was_occ = v >= 0.0;
        let nv = self.updated_log_odds(v, u.hit);
        self.blocks[blk as usize].value[slot] = nv;
        let now_occ = nv >= 0.0;
        if just_created || was_occ != now_occ {
            // The colour is the colour pass's to give (`color_pass`).
            log.flips.push(Change {
                code: u.code,
                occupied: now_occ,
                color: None,
                recolor: false,
            });
        }
    }

    /// [`collapse_by_value`](Self::collapse_by_value) on the node at `depth` that holds voxel
    /// `code`, logging the occupied voxels whose colour it changed; true if it collapsed.
    fn prune_logged(
        &mut self,
        blk: u32,
        slot: usize,
        cb: u32,
        depth: u32,
        code: u64,
        log: &mut PassLog,
    ) -> bool {
        let Some(children) = self.collapse_by_value(blk, slot, cb) else {
            return false;
        };
        if self.colors.is_some() && self.blocks[blk as usize].value[slot] >= 0.0 {
            let now = self.color(blk, slot);
            let shift = 3 * (TREE_DEPTH - 1 - depth);
            for (i, old) in children.into_iter().enumerate() {
                if old != now {
                    let child = (code & !(0o7u64 << shift)) | ((i as u64) << shift);
                    push_voxels(&mut log.recolored, child, depth + 1);
                }
            }
        }
        true
    }

    /// OctoMap's `updateNode` of one voxel (`lazy_eval` off): nothing if the node holding it is
    /// already clamped in the update's direction; else down from the root, expanding pruned
    /// nodes and creating missing ones, the voxel updated, then back up, each node pruned if it
    /// can be, else set to the maximum of its children. The way up stops at the first node that
    /// neither collapsed nor changed value: nothing above it can change.
    ///
    /// The way down starts at the deepest node `path` (the previous voxel's) shares with this
    /// voxel and still holds: the nodes above it are inner nodes the way down would only pass
    /// through (neither clamped leaves nor new), so starting there changes nothing.
    fn update_voxel(
        &mut self,
        u: &Upd,
        root_created: bool,
        log: &mut PassLog,
        path: &mut VoxelPath,
    ) {
        let start = if root_created {
            0
        } else {
            path.valid.min(shared_depth(path.code, u.code))
        };
        // Per depth: the value before, `None` if the node is new.
        let mut before = [None::<f32>; TREE_DEPTH as usize + 1];
        for (d, b) in before.iter_mut().enumerate().take(start as usize + 1) {
            let (blk, slot) = path.nodes[d];
            *b = Some(self.blocks[blk as usize].value[slot]);
        }
        if root_created {
            before[0] = None;
        }
        path.code = u.code;
        let (mut blk, mut slot) = path.nodes[start as usize];
        let mut just_created = root_created;
        for depth in start..TREE_DEPTH {
            if self.blocks[blk as usize].child[slot] == NONE && !just_created {
                let v = self.blocks[blk as usize].value[slot];
                if self.at_clamp(v, u.hit) {
                    path.valid = depth;
                    return;
                }
            }
            let cb = self.children_block(blk, slot, !just_created);
            let digit = ((u.code >> (3 * (TREE_DEPTH - 1 - depth))) & 7) as usize;
            just_created = self.create_child(cb, digit);
            before[depth as usize + 1] =
                (!just_created).then(|| self.blocks[cb as usize].value[digit]);
            (blk, slot) = (cb, digit);
            path.nodes[depth as usize + 1] = (blk, slot);
        }
        path.valid = TREE_DEPTH;
        self.update_leaf(blk, slot, u, just_created, log);
        for depth in (0..TREE_DEPTH).rev() {
            let (b, s) = path.nodes[depth as usize];
            let cb = self.blocks[b as usize].child[s];
            if self.prune_logged(b, s, cb, depth, u.code, log) {
                // The nodes below are gone: the path holds down to this one, now a leaf.
                path.valid = depth;
                continue;
            }
            self.set_max(b, s, cb);
            if before[depth as usize]
                .is_some_and(|v| v.to_bits() == self.blocks[b as usize].value[s].to_bits())
            {
                break;
            }
        }
    }

    /// The root node, if the tree is not empty.
    pub fn root(&self) -> Option<NodeRef> {
        (self.blocks[0].mask & 1 != 0).then_some(NodeRef { blk: 0, slot: 0 })
    }

    /// The children of a node seen as `v` ([`OcTree::node`]), in child order: what
    /// [`OcTree::child`] gives for each of the eight, without reading the node again.
    pub(crate) fn children_of(&self, v: &NodeView) -> impl Iterator<Item = NodeRef> + use<> {
        let (blk, mut mask) = (v.children, v.child_mask());
        std::iter::from_fn(move || {
            (mask != 0).then(|| {
                let slot = mask.trailing_zeros() as u8;
                mask &= mask - 1;
                NodeRef { blk, slot }
            })
        })
    }

    /// A node's value, colour and children.
    pub fn node(&self, r: NodeRef) -> NodeView {
        let b = &self.blocks[r.blk as usize];
        let c = self.color(r.blk, r.slot as usize);
        let children = b.child[r.slot as usize];
        NodeView {
            log_odds: b.value[r.slot as usize],
            color: (c[3] == 1).then_some([c[0], c[1], c[2]]),
            children,
            mask: if children == NONE {
                0
            } else {
                self.blocks[children as usize].mask
            },
        }
    }

    /// A leaf's log-odds; `None` for a node with children.
    pub(crate) fn leaf_log_odds(&self, r: NodeRef) -> Option<f32> {
        let b = &self.blocks[r.blk as usize];
        (b.child[r.slot as usize] == NONE).then_some(b.value[r.slot as usize])
    }

    /// Child `i` of a node, if it exists.
    pub fn child(&self, r: NodeRef, i: usize) -> Option<NodeRef> {
        let c = self.blocks[r.blk as usize].child[r.slot as usize];
        (c != NONE && self.blocks[c as usize].mask & (1 << i) != 0).then_some(NodeRef {
            blk: c,
            slot: i as u8,
        })
    }

    /// The node that holds the voxel of Morton code `code` (depth-16 code) at `depth` or above
    /// (a pruned leaf), with its depth; `None` if that space is unknown.
    pub fn search(&self, code: u64, depth: u32) -> Option<(NodeRef, u32)> {
        self.descend(self.root()?, 0, code, depth, |_, _| {})
    }

    /// [`OcTree::search`] from node `r` at depth `from` on the way to voxel `code`: down to
    /// `depth`, a pruned leaf, or unknown space (`None`); `visit` sees each node stepped into,
    /// with its depth.
    fn descend(
        &self,
        mut r: NodeRef,
        from: u32,
        code: u64,
        depth: u32,
        mut visit: impl FnMut(u32, NodeRef),
    ) -> Option<(NodeRef, u32)> {
        let depth = depth.min(TREE_DEPTH);
        for d in from..depth {
            let digit = ((code >> (3 * (TREE_DEPTH - 1 - d))) & 7) as usize;
            if self.blocks[r.blk as usize].child[r.slot as usize] == NONE {
                return Some((r, d));
            }
            r = self.child(r, digit)?;
            visit(d + 1, r);
        }
        Some((r, depth))
    }

    /// Builds a tree from a pre-order node stream (the `.ot`/`.bt` readers): `visit` is called
    /// for each node with its depth and must return (log-odds, colour, child mask).
    pub(crate) fn from_preorder<E>(
        resolution_m: f64,
        colored: bool,
        mut visit: impl FnMut(u32) -> Result<(f32, Option<[u8; 3]>, u8), E>,
        empty: bool,
    ) -> Result<OcTree, E> {
        let mut t = OcTree::new(resolution_m);
        if colored {
            t.enable_color();
        }
        if empty {
            return Ok(t);
        }
        let (v, c, mask) = visit(0)?;
        t.blocks[0].mask = 1;
        t.blocks[0].value[0] = v;
        t.set_color(0, 0, color_slot(c));
        t.nodes = 1;
        // Explicit stack: (block, slot, depth, mask, next child index).
        let mut stack: Vec<(u32, usize, u32, u8, usize)> = vec![(0, 0, 0, mask, 0)];
        while let Some(top) = stack.last_mut() {
            let (blk, slot, depth, mask, next) = *top;
            let Some(i) = (next..8).find(|i| mask & (1 << i) != 0) else {
                stack.pop();
                continue;
            };
            top.4 = i + 1;
            let mut cb = t.blocks[blk as usize].child[slot];
            if cb == NONE {
                cb = t.alloc_block();
                t.blocks[blk as usize].child[slot] = cb;
            }
            let (v, c, m) = visit(depth + 1)?;
            let b = &mut t.blocks[cb as usize];
            b.mask |= 1 << i;
            b.value[i] = v;
            t.set_color(cb, i, color_slot(c));
            t.nodes += 1;
            if m != 0 && depth + 1 < TREE_DEPTH {
                stack.push((cb, i, depth + 1, m, 0));
            }
        }
        Ok(t)
    }

    /// Sets a voxel at `depth` (a node of edge `res * 2^(16 - depth)`) to a log-odds value and
    /// colour, creating the path and expanding pruned nodes as needed; then prunes and updates
    /// inner values along the path. For building views (the operator's map).
    pub fn set_node(&mut self, code: u64, depth: u32, log_odds: f32, color: Option<[u8; 3]>) {
        let created = self.ensure_root();
        self.set_recurs(
            (0, 0),
            0,
            created,
            code,
            depth.min(TREE_DEPTH),
            log_odds,
            color_slot(color),
        );
    }

    #[allow(clippy::too_many_arguments)]
    fn set_recurs(
        &mut self,
        (blk, slot): (u32, usize),
        depth: u32,
        just_created: bool,
        code: u64,
        target: u32,
        v: f32,
        c: ColorSlot,
    ) {
        if depth == target {
            if let Some(cb) = self.take_children(blk, slot) {
                self.free_subtree(cb);
            }
            self.blocks[blk as usize].value[slot] = v;
            self.set_color(blk, slot, c);
            return;
        }
        let cb = self.children_block(blk, slot, !just_created);
        let digit = ((code >> (3 * (TREE_DEPTH - 1 - depth))) & 7) as usize;
        let created = self.create_child(cb, digit);
        self.set_recurs((cb, digit), depth + 1, created, code, target, v, c);
        self.prune_or_max(blk, slot, cb);
    }

    /// After a view's node's children changed: collapse them if they are eight leaves equal in
    /// value and colour, else set the node to the maximum of its children.
    fn prune_or_max(&mut self, blk: u32, slot: usize, cb: u32) {
        let same_colors = self.colors.as_ref().is_none_or(|cs| {
            let row = &cs[cb as usize];
            row.iter().all(|x| *x == row[0])
        });
        if !(same_colors && self.collapse_by_value(blk, slot, cb).is_some()) {
            self.set_max(blk, slot, cb);
        }
    }

    /// Sets a node to the maximum of its children (block `cb`).
    fn set_max(&mut self, blk: u32, slot: usize, cb: u32) {
        let b = &self.blocks[cb as usize];
        let mut max = -f32::MAX;
        for i in 0..8 {
            if b.mask & (1 << i) != 0 && b.value[i] > max {
                max = b.value[i];
            }
        }
        self.blocks[blk as usize].value[slot] = max;
    }

    /// `ColorOcTree::pruneNode`: if the node's children (block `cb`) are eight leaves of equal
    /// log-odds, whatever their colours (`isNodeCollapsible`), they are deleted and the node
    /// takes child 0's value and colour, the colour then replaced, when it is set, by the mean of
    /// the children's set colours (`getAverageChildColor`). Returns the children's colours when
    /// it collapsed.
    fn collapse_by_value(&mut self, blk: u32, slot: usize, cb: u32) -> Option<[ColorSlot; 8]> {
        let b = &self.blocks[cb as usize];
        let collapsible = b.mask == 0xff
            && b.child.iter().all(|&x| x == NONE)
            && b.value.iter().all(|&x| x == b.value[0]);
        if !collapsible {
            return None;
        }
        let v0 = b.value[0];
        let children = self
            .colors
            .as_ref()
            .map_or([NO_COLOR; 8], |cs| cs[cb as usize]);
        let color = if children[0][3] == 1 {
            mean_color(&children)
        } else {
            children[0]
        };
        self.free_list.push(cb);
        self.nodes -= 8;
        self.blocks[blk as usize].child[slot] = NONE;
        self.blocks[blk as usize].value[slot] = v0;
        self.set_color(blk, slot, color);
        Some(children)
    }

    /// Sets every inner node to the maximum of its children (after reading a `.bt`).
    pub fn recompute_inner_values(&mut self) {
        if self.blocks[0].mask & 1 != 0 {
            self.max_recurs(0, 0);
        }
    }

    fn max_recurs(&mut self, blk: u32, slot: usize) -> f32 {
        let cb = self.blocks[blk as usize].child[slot];
        if cb == NONE {
            return self.blocks[blk as usize].value[slot];
        }
        let mask = self.blocks[cb as usize].mask;
        let mut max = -f32::MAX;
        for i in 0..8 {
            if mask & (1 << i) != 0 {
                max = max.max(self.max_recurs(cb, i));
            }
        }
        self.blocks[blk as usize].value[slot] = max;
        max
    }

    fn take_children(&mut self, blk: u32, slot: usize) -> Option<u32> {
        let cb = self.blocks[blk as usize].child[slot];
        if cb == NONE {
            return None;
        }
        self.blocks[blk as usize].child[slot] = NONE;
        Some(cb)
    }

    fn free_subtree(&mut self, cb: u32) {
        let b = self.blocks[cb as usize].clone();
        for i in 0..8 {
            if b.mask & (1 << i) != 0 {
                self.nodes -= 1;
                if b.child[i] != NONE {
                    self.free_subtree(b.child[i]);
                }
            }
        }
        self.free_list.push(cb);
    }

    /// OctoMap's `toMaxLikelihood()` followed by `prune()`, as many times as `prunes` (OctoMap's
    /// `prune()` walks depths 15..1 and stops at the first depth where nothing was pruned, so a
    /// second call can prune more; `graph2tree`'s `.bt` has had two).
    pub fn to_max_likelihood(&mut self, prunes: usize) {
        let (lo, hi) = (self.params.clamp_min_log, self.params.clamp_max_log);
        for b in &mut self.blocks {
            for v in &mut b.value {
                *v = if *v >= 0.0 { hi } else { lo };
            }
        }
        for _ in 0..prunes {
            self.prune_octomap();
        }
    }

    /// OctoMap's `prune()`: for depth 15 down to 1, prune every collapsible node at that depth;
    /// stop at the first depth where none was.
    pub fn prune_octomap(&mut self) {
        let Some(root) = self.root() else { return };
        for depth in (1..TREE_DEPTH).rev() {
            let mut pruned = 0usize;
            self.prune_at(root.blk, root.slot as usize, 0, depth, &mut pruned);
            if pruned == 0 {
                break;
            }
        }
    }

    fn prune_at(&mut self, blk: u32, slot: usize, depth: u32, target: u32, pruned: &mut usize) {
        let cb = self.blocks[blk as usize].child[slot];
        if cb == NONE {
            return;
        }
        if depth < target {
            let mask = self.blocks[cb as usize].mask;
            for i in 0..8 {
                if mask & (1 << i) != 0 {
                    self.prune_at(cb, i, depth + 1, target, pruned);
                }
            }
            return;
        }
        if self.collapse_by_value(blk, slot, cb).is_some() {
            *pruned += 1;
        }
    }

    /// Calls `f(code, depth, view)` for every leaf (a node without children), in pre-order.
    /// `code` is the depth-16 Morton code of the leaf's first voxel.
    pub fn for_each_leaf(&self, mut f: impl FnMut(u64, u32, NodeView)) {
        let Some(root) = self.root() else { return };
        let mut stack = vec![(root, 0u32, 0u64)];
        while let Some((r, depth, code)) = stack.pop() {
            let view = self.node(r);
            if !view.has_children() {
                f(code, depth, view);
                continue;
            }
            for i in (0..8).rev() {
                if let Some(c) = self.child(r, i) {
                    let shift = 3 * (TREE_DEPTH - 1 - depth);
                    stack.push((c, depth + 1, code | ((i as u64) << shift)));
                }
            }
        }
    }
}

/// The path of the last voxel [`OcTree::update_voxel`] updated: per depth, the node (block,
/// slot), root first; the nodes down to depth `valid` are still the tree's (the one at `valid`
/// may have become a leaf), those below may be gone.
#[derive(Clone, Copy)]
struct VoxelPath {
    nodes: [(u32, usize); TREE_DEPTH as usize + 1],
    /// The voxel.
    code: u64,
    valid: u32,
}

impl Default for VoxelPath {
    /// The root only.
    fn default() -> Self {
        VoxelPath {
            nodes: [(0, 0); TREE_DEPTH as usize + 1],
            code: 0,
            valid: 0,
        }
    }
}

/// How many levels below the root two voxels' paths share: the depth of their deepest common
/// node (16 for the same voxel).
fn shared_depth(a: u64, b: u64) -> u32 {
    // A code is 16 digits of 3 bits: 48 bits, the 16 above them zero (beyond them: the root).
    let differing_bits = 64 - (a ^ b).leading_zeros();
    TREE_DEPTH.saturating_sub(differing_bits.div_ceil(3))
}

/// The digit at `depth` of the first of `rest` (updates in Morton order, all below one node at
/// `depth`), and how many updates from the first share it.
///
/// The digits ascend, so the run is a prefix. Near the root it is the whole rest (one test);
/// else it is found by a scan of a short rest, or by bisection of a long one.
#[inline(always)]
pub(crate) fn digit_run(rest: &[Upd], depth: u32) -> (usize, usize) {
    let shift = 3 * (TREE_DEPTH - 1 - depth);
    let digit_of = |u: &Upd| ((u.code >> shift) & 7) as usize;
    let Some(digit) = rest.first().map(digit_of) else {
        return (0, 0);
    };
    let in_run = |u: &Upd| digit_of(u) == digit;
    let run = if rest.last().is_some_and(in_run) {
        rest.len()
    } else if rest.len() <= SHORT_RUN_SCAN {
        rest.iter().position(|u| !in_run(u)).unwrap_or(rest.len())
    } else {
        rest.partition_point(in_run)
    };
    (digit, run)
}

/// [`OcTree::search`] for voxels mostly in ascending Morton order: each search starts from
/// the deepest node the previous one shares with it, not from the root. Valid while the tree's
/// structure does not change (colours and values may).
#[derive(Default)]
struct Descent {
    /// The nodes of the previous search, by depth: `path[..len]`.
    path: [Option<NodeRef>; TREE_DEPTH as usize + 1],
    len: usize,
    /// The previous voxel.
    prev: u64,
}

impl Descent {
    /// The node that holds voxel `code` and its depth, as [`OcTree::search`] gives them.
    fn search(&mut self, t: &OcTree, code: u64) -> Option<(NodeRef, u32)> {
        let shared = shared_depth(code, self.prev) as usize;
        self.prev = code;
        let start = shared.min(self.len.saturating_sub(1));
        let (r, start) = match self.path[start].filter(|_| self.len > 0) {
            Some(r) => (r, start),
            None => (t.root()?, 0),
        };
        self.path[start] = Some(r);
        self.len = start + 1;
        let (path, len) = (&mut self.path, &mut self.len);
        t.descend(r, start as u32, code, TREE_DEPTH, |d, n| {
            path[d as usize] = Some(n);
            *len = d as usize + 1;
        })
    }
}

/// A node of the tree (a handle, valid until the tree changes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NodeRef {
    blk: u32,
    slot: u8,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Pose;
    use crate::cellset::CellSet;
    use crate::math::norm_f32;

    #[test]
    fn keys_follow_octomap_and_refuse_out_of_range() {
        let t = OcTree::new(0.1);
        assert_eq!(t.coord_to_key(0.0), Some(32768));
        assert_eq!(t.coord_to_key(-0.01), Some(32767));
        assert_eq!(t.coord_to_key(0.25), Some(32770));
        assert_eq!(t.coord_to_key(3276.75), Some(65535));
        assert_eq!(t.coord_to_key(3276.9), None);
        assert_eq!(t.coord_to_key(-3276.9), None);
        assert_eq!(t.coord_to_key(f32::NAN), None);
        assert!((t.key_to_coord(32768) - 0.05).abs() < 1e-12);
    }

    fn scan(points: Vec<[f32; 3]>) -> Scan {
        Scan {
            points,
            colors: None,
            pose: Pose::IDENTITY,
        }
    }

    #[test]
    fn one_ray_marks_free_cells_then_the_end() {
        let mut t = OcTree::new(0.1);
        let up = t.insert_scan(&scan(vec![[1.05, 0.05, 0.05]]), None);
        // Origin cell (0) to cell 9 free, cell 10 occupied.
        assert_eq!(up.free_voxels, 10);
        assert_eq!(up.occupied_voxels, 1);
        assert_eq!(up.changes.len(), 11);
        assert_eq!(up.changes.iter().filter(|c| c.occupied).count(), 1);
        let end = morton([32778, 32768, 32768]);
        let (n, d) = t.search(end, 16).unwrap();
        assert_eq!(d, 16);
        assert_eq!(t.node(n).log_odds, Params::default().hit_log);
        // Scanning again changes nothing's state.
        let up = t.insert_scan(&scan(vec![[1.05, 0.05, 0.05]]), None);
        assert!(up.changes.is_empty());
    }

    #[test]
    fn occupied_wins_over_free_in_one_scan() {
        let mut t = OcTree::new(0.1);
        // The first point's ray crosses the second point's cell.
        let up = t.insert_scan(&scan(vec![[1.05, 0.05, 0.05], [0.55, 0.05, 0.05]]), None);
        assert_eq!(up.occupied_voxels, 2);
        assert_eq!(up.free_voxels, 9);
        let (n, _) = t.search(morton([32773, 32768, 32768]), 16).unwrap();
        assert!(t.node(n).log_odds > 0.0);
    }

    #[test]
    fn clamping_and_pruning() {
        let mut t = OcTree::new(0.5);
        // Eight points filling one depth-15 node's children, scanned until clamped.
        let mut pts = Vec::new();
        for i in 0..8 {
            pts.push([
                10.0 + 0.25 + 0.5 * (i & 1) as f32,
                10.0 + 0.25 + 0.5 * ((i >> 1) & 1) as f32,
                10.0 + 0.25 + 0.5 * ((i >> 2) & 1) as f32,
            ]);
        }
        for _ in 0..10 {
            t.insert_scan(&scan(pts.clone()), None);
        }
        let code = morton(t.key_of(pts[0]).unwrap());
        let (n, d) = t.search(code, 16).unwrap();
        assert_eq!(
            d, 15,
            "eight equal clamped leaves are pruned into their parent"
        );
        assert_eq!(t.node(n).log_odds, Params::default().clamp_max_log);
    }

    #[test]
    fn out_of_range_points_are_skipped_not_wrapped() {
        let mut t = OcTree::new(0.1);
        let up = t.insert_scan(&scan(vec![[5000.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0]]), None);
        assert_eq!(up.points_skipped, 2);
        assert_eq!(up.occupied_voxels, 0);
        assert_eq!(up.free_voxels, 0);
    }

    #[test]
    fn max_range_truncates_rays() {
        let mut t = OcTree::new(0.1);
        let up = t.insert_scan(&scan(vec![[5.05, 0.05, 0.05]]), Some(1.0));
        assert_eq!(up.points_beyond_range, 1);
        assert_eq!(up.occupied_voxels, 0);
        assert!(up.free_voxels >= 9 && up.free_voxels <= 11);
    }

    /// A coloured tree after a scan of two points, coloured `colors`, in one voxel; the scan;
    /// the occupied voxel's change.
    fn two_points_in_a_voxel(colors: [[u8; 3]; 2]) -> (OcTree, Scan, Change) {
        let mut t = OcTree::new(0.1);
        t.enable_color();
        let mut s = scan(vec![[1.05, 0.05, 0.05], [1.06, 0.06, 0.06]]);
        s.colors = Some(colors.to_vec());
        let up = t.insert_scan(&s, None);
        let occ: Vec<_> = up.changes.into_iter().filter(|c| c.occupied).collect();
        assert_eq!(occ.len(), 1);
        (t, s, occ[0])
    }

    #[test]
    fn brightest_colour_wins() {
        let (mut t, mut s, occ) = two_points_in_a_voxel([[10, 10, 10], [200, 0, 0]]);
        assert_eq!(occ.color, Some([200, 0, 0]));
        let occ = [occ];
        s.colors = Some(vec![[100, 100, 100], [50, 50, 50]]);
        t.insert_scan(&s, None);
        let (n, _) = t.search(occ[0].code, 16).unwrap();
        assert_eq!(t.node(n).color, Some([100, 100, 100]));
        s.colors = Some(vec![[0, 0, 90], [1, 1, 1]]);
        t.insert_scan(&s, None);
        let (n, _) = t.search(occ[0].code, 16).unwrap();
        assert_eq!(t.node(n).color, Some([100, 100, 100]));
    }

    fn octant_points(n: usize) -> Vec<[f32; 3]> {
        (0..n)
            .map(|i| {
                [
                    10.25 + 0.5 * (i & 1) as f32,
                    10.25 + 0.5 * ((i >> 1) & 1) as f32,
                    10.25 + 0.5 * ((i >> 2) & 1) as f32,
                ]
            })
            .collect()
    }

    #[test]
    fn coloured_leaves_prune_by_value_into_their_mean_colour() {
        let mut t = OcTree::new(0.5);
        t.enable_color();
        let mut plain = OcTree::new(0.5);
        // Seven of a depth-15 node's children, in seven colours: no pruning yet.
        // Rays from below for the seven, from above for the eighth: none crosses another's cell.
        let mut s = scan_at([0.0; 3], octant_points(7));
        s.colors = Some((0..7).map(|i| [10 + 10 * i as u8, 20, 30]).collect());
        t.insert_scan(&s, None);
        plain.insert_scan(&s, None);
        // The eighth, with the same log-odds: the node collapses, whatever the colours, into
        // the mean of the set ones (the new child has none yet); its own darker point does not
        // replace that.
        let mut s = scan_at([20.0; 3], octant_points(8)[7..].to_vec());
        s.colors = Some(vec![[1, 1, 1]]);
        let up = t.insert_scan(&s, None);
        plain.insert_scan(&s, None);
        assert_eq!(t.num_nodes(), plain.num_nodes());
        let code = morton(t.key_of(octant_points(1)[0]).unwrap());
        let (n, d) = t.search(code, 16).unwrap();
        assert_eq!(d, 15);
        assert_eq!(t.node(n).color, Some([40, 20, 30]));
        // The six voxels whose colour the pruning changed are recoloured changes (the fourth
        // had the mean colour already), the new one is a change of state with that colour.
        assert_eq!(up.changes.iter().filter(|c| c.recolor).count(), 6);
        let occupied: Vec<_> = up.changes.iter().filter(|c| c.occupied).collect();
        assert_eq!(occupied.len(), 7);
        assert!(occupied.iter().all(|c| c.color == Some([40, 20, 30])));
    }

    #[test]
    fn white_is_no_colour_and_equal_luma_is_decided_by_rgb() {
        assert_eq!(
            two_points_in_a_voxel([WHITE, [5, 6, 7]]).2.color,
            Some([5, 6, 7])
        );
        // Equal luma (5870): the larger red wins, whatever the order of the points.
        assert_eq!(luma([0, 10, 0]), luma([4, 0, 41]));
        for colors in [[[0, 10, 0], [4, 0, 41]], [[4, 0, 41], [0, 10, 0]]] {
            assert_eq!(two_points_in_a_voxel(colors).2.color, Some([4, 0, 41]));
        }
    }

    /// A tree of five scans of 300 random points from the origin.
    fn random_tree(seed: u64) -> OcTree {
        let mut t = OcTree::new(0.2);
        let mut rng = rovlink_base::rng::Rng::new(seed, 0);
        for _ in 0..5 {
            let pts = (0..300)
                .map(|_| {
                    [
                        (rng.uniform() * 6.0 - 3.0) as f32,
                        (rng.uniform() * 6.0 - 3.0) as f32,
                        (rng.uniform() * 2.0 - 1.0) as f32,
                    ]
                })
                .collect();
            t.insert_scan(&scan(pts), None);
        }
        t
    }

    #[test]
    fn node_count_matches_a_walk() {
        let t = random_tree(7);
        let mut count = 0;
        let mut stack = vec![t.root().unwrap()];
        while let Some(r) = stack.pop() {
            count += 1;
            for i in 0..8 {
                if let Some(c) = t.child(r, i) {
                    stack.push(c);
                }
            }
        }
        assert_eq!(count, t.num_nodes());
    }

    /// A descent that starts where the previous one left off finds what a search from the root
    /// finds, for voxels in ascending order (known, pruned, unknown) and in any order.
    #[test]
    fn a_descent_from_the_previous_path_finds_what_a_search_finds() {
        let t = random_tree(11);
        let mut rng = rovlink_base::rng::Rng::new(12, 0);
        let mut codes = Vec::new();
        t.for_each_leaf(|code, _, _| codes.push(code));
        let known = codes.len();
        for i in 0..known {
            // Neighbours of leaves (often in other nodes, or unknown), and far voxels.
            codes.push(codes[i] ^ 1);
            codes.push(codes[i] ^ (1 << 20));
            codes.push((rng.uniform() * (1u64 << 48) as f64) as u64);
        }
        let check = |codes: &[u64]| {
            let mut walk = Descent::default();
            for &c in codes {
                assert_eq!(walk.search(&t, c), t.search(c, TREE_DEPTH), "voxel {c:#x}");
            }
        };
        check(&codes);
        codes.sort_unstable();
        check(&codes);
        assert!(known > 100, "{known} leaves");
    }

    /// Voxel updates whose descent starts from the previous voxel's path change a coloured
    /// tree as descents from the root do (the same .ot, flips and recoloured voxels), through
    /// rounds of hits and misses in shuffled orders, some voxels twice, that clamp, prune and
    /// expand nodes.
    #[test]
    fn voxel_updates_from_the_previous_path_change_the_tree_as_from_the_root() {
        for seed in 0..4 {
            let mut rng = rovlink_base::rng::Rng::new(seed, 1);
            let mut t = OcTree::new(0.2);
            t.enable_color();
            for _ in 0..3 {
                let points: Vec<[f32; 3]> = (0..200)
                    .map(|_| {
                        [
                            (rng.uniform() * 2.0 - 1.0) as f32,
                            (rng.uniform() * 2.0 - 1.0) as f32,
                            (rng.uniform() - 0.5) as f32,
                        ]
                    })
                    .collect();
                let colors = (0..points.len())
                    .map(|i| [(i * 37 % 251) as u8, (i * 11 % 241) as u8, 9])
                    .collect();
                t.insert_scan(
                    &Scan {
                        points,
                        colors: Some(colors),
                        pose: Pose::IDENTITY,
                    },
                    None,
                );
            }
            let mut codes = Vec::new();
            t.for_each_leaf(|code, _, _| codes.push(code));
            let leaves = codes.len();
            for i in 0..leaves {
                // Every sibling (so that nodes can prune), and a neighbour's.
                let c = codes[i];
                codes.extend((0..8).map(|j| c & !7 | j));
                codes.push(c ^ 0o70);
            }
            codes.sort_unstable();
            codes.dedup();
            let mut prunes = 0;
            for round in 0..12 {
                // Hits until they clamp (pruning), then misses (expanding again), then hits.
                let hit = round != 1 && round != 9;
                // Some voxels twice (update_voxels takes any list), so that a node pruned by
                // one update is expanded again by a later one below it.
                let mut list = codes.clone();
                list.extend(codes.iter().filter(|_| rng.uniform() < 0.3));
                for i in (1..list.len()).rev() {
                    list.swap(i, (rng.uniform() * (i + 1) as f64) as usize % (i + 1));
                }
                let ups: Vec<Upd> = list
                    .iter()
                    .map(|&code| Upd {
                        code,
                        // Mixed at first, then whole rounds of one kind (clamping).
                        hit: hit ^ (round < 3 && rng.uniform() < 0.1),
                    })
                    .collect();
                let (mut a, mut b) = (t.clone(), t.clone());
                let (mut la, mut lb) = (PassLog::default(), PassLog::default());
                a.update_voxels(&ups, false, &mut la);
                for u in &ups {
                    b.update_voxel(u, false, &mut lb, &mut VoxelPath::default());
                }
                assert_eq!(
                    crate::files::write_ot(&a),
                    crate::files::write_ot(&b),
                    "seed {seed} round {round}"
                );
                assert_eq!(la.flips, lb.flips);
                assert_eq!(la.recolored, lb.recolored);
                prunes += usize::from(a.num_nodes() < t.num_nodes());
                t = a;
            }
            assert!(
                leaves > 100 && prunes > 0,
                "seed {seed}: {leaves} leaves, {prunes} prunes"
            );
        }
    }

    /// The naive model: one log-odds per voxel in a hash map, OctoMap's update rule applied to
    /// each scan's free and occupied sets (from a plain, array-indexed port of OctoMap's ray
    /// walk), no tree, no pruning.
    struct Naive {
        cells: std::collections::HashMap<Key, f32>,
    }

    fn naive_ray(t: &OcTree, o: [f32; 3], e: [f32; 3], out: &mut Vec<Key>) {
        let (Some(ko), Some(ke)) = (t.key_of(o), t.key_of(e)) else {
            return;
        };
        if ko == ke {
            return;
        }
        out.push(ko);
        let mut dir = [e[0] - o[0], e[1] - o[1], e[2] - o[2]];
        let length = norm_f32(dir) as f32;
        for d in &mut dir {
            *d /= length;
        }
        let (mut step, mut tm, mut td) = ([0i32; 3], [f64::MAX; 3], [f64::MAX; 3]);
        for i in 0..3 {
            step[i] = if dir[i] > 0.0 {
                1
            } else if dir[i] < 0.0 {
                -1
            } else {
                0
            };
            if step[i] != 0 {
                let border =
                    t.key_to_coord(ko[i]) + (step[i] as f64 * t.resolution_m() * 0.5) as f32 as f64;
                tm[i] = (border - o[i] as f64) / dir[i] as f64;
                td[i] = t.resolution_m() / (dir[i] as f64).abs();
            }
        }
        let mut cur = ko;
        loop {
            let dim = if tm[0] < tm[1] {
                if tm[0] < tm[2] { 0 } else { 2 }
            } else if tm[1] < tm[2] {
                1
            } else {
                2
            };
            cur[dim] = cur[dim].wrapping_add_signed(step[dim] as i16);
            tm[dim] += td[dim];
            if cur == ke || tm[0].min(tm[1]).min(tm[2]) > length as f64 {
                return;
            }
            out.push(cur);
        }
    }

    impl Naive {
        fn insert(&mut self, t: &OcTree, scan: &Scan) {
            let (pts, origin) = world_points(scan);
            let (mut free, mut occ) = (Vec::new(), std::collections::HashSet::new());
            for &p in &pts {
                naive_ray(t, origin, p, &mut free);
                if let Some(k) = t.key_of(p) {
                    occ.insert(k);
                }
            }
            let free: std::collections::HashSet<Key> = free.into_iter().collect();
            let p = t.params();
            let mut upd = |k: Key, u: f32| {
                let v = self.cells.entry(k).or_insert(0.0);
                if (u > 0.0 && *v >= p.clamp_max_log) || (u < 0.0 && *v <= p.clamp_min_log) {
                    return;
                }
                *v = (*v + u).clamp(p.clamp_min_log, p.clamp_max_log);
            };
            for k in free.difference(&occ) {
                upd(*k, p.miss_log);
            }
            for k in &occ {
                upd(*k, p.hit_log);
            }
        }
    }

    /// Every voxel's value in the tree (pruned leaves expanded), and the tree's invariants:
    /// no node left collapsible, inner nodes the maximum of their children.
    fn voxels(t: &OcTree) -> std::collections::HashMap<Key, f32> {
        let mut out = std::collections::HashMap::new();
        fn walk(
            t: &OcTree,
            r: NodeRef,
            depth: u32,
            code: u64,
            out: &mut std::collections::HashMap<Key, f32>,
        ) {
            let v = t.node(r);
            if !v.has_children() {
                let span = 1u64 << (3 * (TREE_DEPTH - depth));
                for c in code..code + span {
                    out.insert(unmorton(c), v.log_odds);
                }
                return;
            }
            let kids: Vec<_> = (0..8)
                .filter_map(|i| t.child(r, i).map(|c| (i, c)))
                .collect();
            let max = kids
                .iter()
                .map(|(_, c)| t.node(*c).log_odds)
                .fold(-f32::MAX, f32::max);
            assert_eq!(v.log_odds, max, "inner node is the max of its children");
            let collapsible = kids.len() == 8
                && kids.iter().all(|(_, c)| {
                    !t.node(*c).has_children() && t.node(*c).log_odds == t.node(kids[0].1).log_odds
                });
            assert!(!collapsible, "a collapsible node was left unpruned");
            for (i, c) in kids {
                walk(
                    t,
                    c,
                    depth + 1,
                    code | ((i as u64) << (3 * (TREE_DEPTH - 1 - depth))),
                    out,
                );
            }
        }
        if let Some(r) = t.root() {
            walk(t, r, 0, 0, &mut out);
        }
        out
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]
        #[test]
        fn tree_equals_the_naive_model(
            seed in 0u64..1000,
            scans in 1usize..5,
            threads in 1usize..3,
        ) {
            let mut rng = rovlink_base::rng::Rng::new(seed, 1);
            let mut t = OcTree::new(0.25);
            t.set_threads(threads);
            let mut naive = Naive { cells: Default::default() };
            for _ in 0..scans {
                let c = [(rng.uniform() * 2.0 - 1.0) as f32, (rng.uniform() * 2.0 - 1.0) as f32, 0.3];
                let pts = (0..9000)
                    .map(|_| {
                        [
                            c[0] + (rng.uniform() * 3.0 - 1.5) as f32,
                            c[1] + (rng.uniform() * 3.0 - 1.5) as f32,
                            (rng.uniform() * 0.6 - 1.5) as f32,
                        ]
                    })
                    .collect();
                // A rotation about a random axis, exercising OctoMap's pose arithmetic.
                let (a, ax) = (rng.uniform() * 0.6, [rng.uniform(), rng.uniform(), rng.uniform()]);
                let n = (ax[0] * ax[0] + ax[1] * ax[1] + ax[2] * ax[2]).sqrt().max(1e-9);
                let (sa, ca) = ((a / 2.0).sin() / n, (a / 2.0).cos());
                let scan = Scan {
                    points: pts,
                    colors: None,
                    pose: Pose {
                        translation_m: c,
                        rotation: [ca as f32, (ax[0] * sa) as f32, (ax[1] * sa) as f32, (ax[2] * sa) as f32],
                    },
                };
                let up = t.insert_scan(&scan, None);
                naive.insert(&t, &scan);
                proptest::prop_assert_eq!(up.points, 9000);
            }
            let got = voxels(&t);
            proptest::prop_assert_eq!(got.len(), naive.cells.len());
            for (k, v) in &naive.cells {
                proptest::prop_assert_eq!(got.get(k).map(|x| x.to_bits()), Some(v.to_bits()), "voxel {:?}", k);
            }
        }
    }

    /// Runs `f` on a thread and fails the test if it has not finished within `limit`.
    fn within<T: Send + 'static>(
        limit: std::time::Duration,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> T {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(f());
        });
        rx.recv_timeout(limit)
            .expect("the insertion did not finish in time (a ray walk that never ends)")
    }

    fn scan_at(origin: [f32; 3], points: Vec<[f32; 3]>) -> Scan {
        // The points are given in the map frame: into the sensor frame of a pose at `origin`.
        Scan {
            points: points
                .into_iter()
                .map(|p| [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]])
                .collect(),
            colors: None,
            pose: Pose {
                translation_m: origin,
                rotation: [1.0, 0.0, 0.0, 0.0],
            },
        }
    }

    #[test]
    fn ray_whose_squared_length_underflows_ends() {
        // Issue 14: (-1e-30, -1e-30, -1e-30) from the origin: the f32 squared length is 0, the
        // direction -inf, and OctoMap's walk stepped along z forever.
        let up = within(std::time::Duration::from_secs(10), || {
            let mut t = OcTree::new(0.1);
            let up = t.insert_scan(&scan_at([0.0; 3], vec![[-1e-30; 3]]), None);
            (up.points, up.occupied_voxels, up.free_voxels, t.num_nodes())
        });
        // The end cell (key 32767 on each axis) is occupied, the origin's cell free.
        assert_eq!((up.0, up.1, up.2), (1, 1, 1));
        assert!(up.3 > 0);
    }

    #[test]
    fn degenerate_rays_end_and_stay_near_their_cells() {
        let limit = std::time::Duration::from_secs(10);
        let cases: Vec<([f32; 3], [f32; 3], f64)> = vec![
            ([0.0; 3], [1e-30, 0.0, 0.0], 0.1),
            ([0.0; 3], [-1e-45, 1e-45, -1e-45], 0.1),
            ([0.0; 3], [f32::MIN_POSITIVE, 0.0, -f32::MIN_POSITIVE], 1e-3),
            ([1e-38, -1e-38, 0.0], [-1e-38, 1e-38, 1e-38], 0.05),
            // Squares that overflow f32: coordinates near the key range of a huge resolution.
            ([-3e37, -3e37, -3e37], [3e37, 3e37, 3e37], 1e33),
            ([0.0; 3], [2e19, -2e19, 2e19], 1e15),
        ];
        for (origin, end, res) in cases {
            let (ko, ke, cells) = within(limit, move || {
                let t = OcTree::new(res);
                let mut set = CellSet::new();
                t.grid.ray_keys(origin, end, &mut set);
                let mut cells = Vec::new();
                set.drain_sorted(&mut cells);
                (t.key_of(origin), t.key_of(end), cells)
            });
            let (Some(ko), Some(ke)) = (ko, ke) else {
                continue;
            };
            // At most one cell per key step, plus the origin's.
            let steps: usize = (0..3).map(|i| ko[i].abs_diff(ke[i]) as usize).sum();
            assert!(
                cells.len() <= steps + 4,
                "{origin:?} -> {end:?}: {} cells",
                cells.len()
            );
        }
    }
}
