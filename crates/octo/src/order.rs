//! Whether the order of a coloured scan's updates can change the map.
//!
//! OctoMap applies a scan voxel by voxel in its `KeySet`'s order, pruning the path after each
//! voxel ([`super::tree`]). Log-odds do not depend on that order: each voxel is updated once
//! per scan, and pruning ends in the same tree. Colours can: a node whose eight children become
//! leaves of equal log-odds is pruned and takes their mean colour (`ColorOcTree::pruneNode`),
//! and when a later update of the same scan reaches a voxel below it, the node is expanded
//! again and its eight children all copy that mean. Applied in another order, those children
//! keep their own colours.
//!
//! That needs, in some order, a node pruned while an update below it is still to come and will
//! change something (not at its clamp in the update's direction, OctoMap's early abort), with
//! children whose colours are not all one colour. [`order_can_matter`] looks for such a node in
//! one read-only pass over the tree along the scan's updates in Morton order, and says no only
//! when no order of the updates can give one. Then the scan can be applied in any order, in
//! particular the plain tree's one recursive pass in Morton order, with OctoMap's result. When
//! it says yes (or cannot tell), the scan is applied in OctoMap's own order; [`order_risk`]
//! also says where, so that a phase whose risk lies inside a few subtrees goes in one pass
//! outside them and in OctoMap's order inside them ([`Risk::Within`]).
//!
//! The test per node: each child gets the set of log-odds it may hold as a leaf at some moment
//! of the scan (a voxel: before and after its update; a pruned node: its value, or what its
//! children may all share; an inner node: what its children may all share). A node can be
//! pruned at a value only if every child may hold it, and a later update can then change
//! something only if some child has an update still to come that is not clamped at that value.
//! Each set over-approximates what the scan can do, so the answer errs towards yes.
//!
//! Nothing here panics; the pass reads the tree only.

use super::cast::Upd;
use super::tree::{NodeRef, OcTree, TREE_DEPTH, WHITE, digit_run};

/// Most distinct values a node's set holds before the pass gives up and says the order may
/// matter (under a pruned node every value is its value, after a hit or after a miss: 3).
const VALUES_MAX: usize = 6;

/// Most nodes a subtree's colours are read from before the pass says the order may matter.
const COLOR_NODES_MAX: usize = 4096;

/// The order may matter (or the pass cannot tell).
struct MayMatter;

/// A node before the scan.
#[derive(Clone, Copy)]
enum Before {
    /// Unknown space: created by the scan, with no colour.
    Absent,
    /// A leaf of this log-odds (a voxel, or a pruned node whose children would copy it).
    Leaf(f32),
    /// A node with children.
    Inner(NodeRef),
}

/// Log-odds a node may hold as a leaf at some moment of the scan, compared bit for bit.
#[derive(Clone, Copy, Default)]
struct Values {
    bits: [u32; VALUES_MAX],
    len: usize,
}

impl Values {
    fn one(v: f32) -> Self {
        let mut s = Values::default();
        s.bits[0] = v.to_bits();
        s.len = 1;
        s
    }

    fn iter(&self) -> impl Iterator<Item = f32> + '_ {
        self.bits[..self.len].iter().map(|b| f32::from_bits(*b))
    }

    fn contains(&self, v: f32) -> bool {
        self.bits[..self.len].contains(&v.to_bits())
    }

    fn add(&mut self, v: f32) -> Result<(), MayMatter> {
        if self.contains(v) {
            return Ok(());
        }
        let slot = self.bits.get_mut(self.len).ok_or(MayMatter)?;
        *slot = v.to_bits();
        self.len += 1;
        Ok(())
    }

    fn intersect(&self, other: &Values) -> Values {
        let mut s = Values::default();
        for v in self.iter().filter(|v| other.contains(*v)) {
            s.bits[s.len] = v.to_bits();
            s.len += 1;
        }
        s
    }
}

/// What the pass learnt of a node's subtree.
struct Subtree {
    /// Values the node may hold as a leaf at some moment.
    values: Values,
    /// Whether the scan creates a node below it (a new node has no colour).
    creates: bool,
}

/// Whether applying `ups` (one scan's updates, each voxel once, in Morton order) to `tree` in
/// some order other than OctoMap's could give other colours than OctoMap's order gives. False
/// only when no order of the updates prunes a node of mixed colours and then expands it again.
pub(crate) fn order_can_matter(tree: &OcTree, ups: &[Upd]) -> bool {
    !matches!(order_risk(tree, ups), Risk::Nowhere)
}

/// Where the order of a phase's updates can change the map.
#[derive(Debug, PartialEq)]
pub(crate) enum Risk {
    /// Nowhere: every order gives OctoMap's map.
    Nowhere,
    /// Only inside these subtrees (disjoint, in Morton order). Every order gives OctoMap's map
    /// as long as the updates inside each subtree keep OctoMap's order among themselves.
    Within(Vec<Region>),
    /// Anywhere, or the pass cannot tell.
    Whole,
}

/// A node's subtree: the node's depth and the leading `3 * depth` bits of its voxels' Morton
/// codes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Region {
    depth: u32,
    prefix: u64,
}

impl Region {
    /// The bits of a voxel's code below a node at `depth`.
    fn shift(depth: u32) -> u32 {
        3 * (TREE_DEPTH - depth)
    }

    /// The subtree at `depth` that holds voxel `code`.
    fn of(code: u64, depth: u32) -> Self {
        Region {
            depth,
            prefix: code >> Self::shift(depth),
        }
    }

    /// Whether voxel `code` is inside.
    pub(crate) fn contains(&self, code: u64) -> bool {
        code >> Self::shift(self.depth) == self.prefix
    }

    /// The first voxel's code inside.
    fn start(&self) -> u64 {
        self.prefix << Self::shift(self.depth)
    }
}

/// Whether voxel `code` is inside one of `regions` (disjoint, in Morton order).
pub(crate) fn inside(regions: &[Region], code: u64) -> bool {
    let after = regions.partition_point(|r| r.start() <= code);
    after > 0 && regions[after - 1].contains(code)
}

/// [`order_can_matter`], told apart: where in the tree the order of `ups` can matter. A node
/// whose test fails keeps the subtree's order; the nodes above it are judged as before, since
/// what a node may hold does not depend on its colours.
pub(crate) fn order_risk(tree: &OcTree, ups: &[Upd]) -> Risk {
    if ups.is_empty() || !tree.is_colored() {
        return Risk::Nowhere;
    }
    let before = match tree.root() {
        None => Before::Absent,
        Some(r) => before_of(tree, r),
    };
    let pass = Pass {
        tree,
        hits: ups.iter().any(|u| u.hit),
        misses: ups.iter().any(|u| !u.hit),
        risky: std::cell::RefCell::new(Vec::new()),
    };
    if pass.node(before, 0, ups).is_err() {
        return Risk::Whole;
    }
    let risky = pass.risky.into_inner();
    match risky.first() {
        None => Risk::Nowhere,
        Some(r) if r.depth == 0 => Risk::Whole,
        Some(_) => Risk::Within(risky),
    }
}

/// The state before the scan of an existing node.
fn before_of(tree: &OcTree, r: NodeRef) -> Before {
    match tree.leaf_log_odds(r) {
        Some(v) => Before::Leaf(v),
        None => Before::Inner(r),
    }
}

struct Pass<'a> {
    tree: &'a OcTree,
    /// Whether any update is a hit, and whether any is a miss (OctoMap applies the two
    /// apart, so each phase has one kind only).
    hits: bool,
    misses: bool,
    /// The subtrees whose updates' order may matter, found so far: disjoint, in Morton order
    /// (the pass visits the nodes in that order, each after the nodes below it).
    risky: std::cell::RefCell<Vec<Region>>,
}

impl Pass<'_> {
    /// OctoMap's early abort: an update of a node clamped in its direction changes nothing.
    fn at_clamp(&self, v: f32, hit: bool) -> bool {
        self.tree.at_clamp(v, hit)
    }

    /// A voxel's log-odds after update `u` from `v`, as the tree computes it.
    fn updated(&self, v: f32, u: &Upd) -> f32 {
        self.tree.updated_log_odds(v, u.hit)
    }

    /// The node at `depth` (state `before`) with updates `ups` below it, all sharing its path.
    fn node(&self, before: Before, depth: u32, ups: &[Upd]) -> Result<Subtree, MayMatter> {
        if depth + 1 == TREE_DEPTH {
            return self.voxels(before, ups);
        }
        if let Before::Leaf(a) = before
            && ups.iter().all(|u| self.at_clamp(a, u.hit))
        {
            // Every update stops at this pruned node, which stays as it is.
            return Ok(Subtree {
                values: Values::one(a),
                creates: false,
            });
        }
        let mut runs: [&[Upd]; 8] = [&[]; 8];
        let mut rest = ups;
        let mut next_digit = 0;
        while !rest.is_empty() {
            // Morton order: the digits ascend, each digit's updates in one run, found as the
            // tree's own pass finds them.
            let (d, n) = digit_run(rest, depth);
            if d < next_digit {
                return Err(MayMatter);
            }
            let (run, tail) = rest.split_at(n);
            runs[d] = run;
            rest = tail;
            next_digit = d + 1;
        }
        let mut creates = matches!(before, Before::Absent);
        let child_before = |i: usize| match before {
            Before::Absent => Before::Absent,
            Before::Leaf(a) => Before::Leaf(a),
            Before::Inner(r) => match self.tree.child(r, i) {
                None => Before::Absent,
                Some(c) => before_of(self.tree, c),
            },
        };
        // The children with updates first (each is checked below, whatever this node can
        // do), then the others, looked at only while the children may still share a value.
        let mut shared: Option<Values> = None;
        for (i, run) in runs.iter().enumerate().filter(|(_, run)| !run.is_empty()) {
            let sub = self.node(child_before(i), depth + 1, run)?;
            creates |= sub.creates;
            shared = Some(shared.map_or(sub.values, |s| s.intersect(&sub.values)));
        }
        for (i, _) in runs.iter().enumerate().filter(|(_, run)| run.is_empty()) {
            if shared.is_some_and(|s| s.len == 0) {
                break;
            }
            // Untouched: a leaf stays one; an inner node is not prunable (the tree was pruned)
            // and nothing below it changes; unknown space stays unknown.
            let values = match child_before(i) {
                Before::Leaf(a) => Values::one(a),
                _ => Values::default(),
            };
            shared = Some(shared.map_or(values, |s| s.intersect(&values)));
        }
        let shared = shared.unwrap_or_default();
        let here = Region::of(ups[0].code, depth);
        self.judge(here, before, creates, shared, |v| {
            runs.iter().any(|run| self.may_wait(run, v))
        })
    }

    /// The test at node `here` (state `before`) whose children may all be leaves of each
    /// value in `shared`: for each, whether an update still to come (`pending`) can expand it
    /// again with colours not all one; if so the node's subtree is risky (and takes in the
    /// risky subtrees found below it). What the node may hold as a leaf: those values, and
    /// its own if it is a pruned node.
    fn judge(
        &self,
        here: Region,
        before: Before,
        creates: bool,
        shared: Values,
        pending: impl Fn(f32) -> bool,
    ) -> Result<Subtree, MayMatter> {
        if shared.iter().any(&pending) && !self.one_color(before, creates) {
            let mut risky = self.risky.borrow_mut();
            while risky.last().is_some_and(|r| here.contains(r.start())) {
                risky.pop();
            }
            risky.push(here);
        }
        let mut values = shared;
        if let Before::Leaf(a) = before {
            values.add(a)?;
        }
        Ok(Subtree { values, creates })
    }

    /// Whether an inner child with updates `run` below it may be a leaf of log-odds `v` while
    /// one of its updates, not clamped at `v`, is still to come: some update of a kind the
    /// scan has, not clamped at `v` (the run is not read: the pass would read every update
    /// again at every level).
    fn may_wait(&self, run: &[Upd], v: f32) -> bool {
        !run.is_empty()
            && ((self.hits && !self.at_clamp(v, true)) || (self.misses && !self.at_clamp(v, false)))
    }

    /// A node at depth 15 (state `before`), whose children are voxels, with updates `ups`
    /// (each voxel once, in Morton order): the same test as [`Pass::node`]'s, the children's
    /// values worked out in place (a voxel may hold its value before and after its update).
    fn voxels(&self, before: Before, ups: &[Upd]) -> Result<Subtree, MayMatter> {
        if let Before::Leaf(a) = before
            && ups.iter().all(|u| self.at_clamp(a, u.hit))
        {
            return Ok(Subtree {
                values: Values::one(a),
                creates: false,
            });
        }
        // Each voxel's value before the scan (`None`: unknown) and its update.
        let mut pre = [None::<f32>; 8];
        match before {
            Before::Absent => {}
            Before::Leaf(a) => pre = [Some(a); 8],
            Before::Inner(r) => {
                for (i, p) in pre.iter_mut().enumerate() {
                    if let Some(c) = self.tree.child(r, i) {
                        // A voxel has no children.
                        *p = Some(self.tree.leaf_log_odds(c).ok_or(MayMatter)?);
                    }
                }
            }
        }
        let mut up = [None::<Upd>; 8];
        let mut next_digit = 0;
        for u in ups {
            let d = (u.code & 7) as usize;
            if d < next_digit {
                return Err(MayMatter);
            }
            up[d] = Some(*u);
            next_digit = d + 1;
        }
        let creates = (0..8).any(|i| pre[i].is_none() && up[i].is_some());
        // The values all eight may share, as bits: those of the first voxel (at most two: its
        // value before and after its update), kept while every other voxel may hold them.
        // Plain integers in registers: building a set per voxel and intersecting sets went
        // through memory, partly written and then read whole (a stall per voxel).
        let may_hold = |i: usize| -> [Option<u32>; 2] {
            match (pre[i], up[i]) {
                (None, None) => [None, None],
                (Some(a), None) => [Some(a.to_bits()), None],
                (None, Some(u)) => [Some(self.updated(0.0, &u).to_bits()), None],
                (Some(a), Some(u)) => [Some(a.to_bits()), Some(self.updated(a, &u).to_bits())],
            }
        };
        let mut shared = may_hold(0);
        if shared[0] == shared[1] {
            shared[1] = None;
        }
        for i in 1..8 {
            if shared == [None, None] {
                // No value all eight may share: this node is never pruned in the scan.
                break;
            }
            let held = may_hold(i);
            for c in &mut shared {
                if c.is_some() && !held.contains(c) {
                    *c = None;
                }
            }
        }
        let mut values = Values::default();
        for v in shared.into_iter().flatten() {
            values.add(f32::from_bits(v))?;
        }
        // A voxel holds `v` with its update to come only if it held `v` before.
        let here = Region::of(ups[0].code, TREE_DEPTH - 1);
        self.judge(here, before, creates, values, |v| {
            (0..8).any(|i| {
                pre[i].is_some_and(|a| a.to_bits() == v.to_bits())
                    && up[i].is_some_and(|u| !self.at_clamp(v, u.hit))
            })
        })
    }

    /// Whether every node below a node (state `before`) has one colour throughout the scan, so
    /// that pruning it and expanding it again gives each child its own colour back.
    fn one_color(&self, before: Before, creates: bool) -> bool {
        let r = match before {
            // Created: no colour anywhere below.
            Before::Absent => return true,
            // A pruned node's children copy it, and prune back to its colour.
            Before::Leaf(_) => return true,
            Before::Inner(r) => r,
        };
        let mut seen: Option<[u8; 3]> = None;
        let mut stack = vec![r];
        let mut visited = 0;
        while let Some(n) = stack.pop() {
            visited += 1;
            if visited > COLOR_NODES_MAX {
                return false;
            }
            let view = self.tree.node(n);
            if view.has_children() {
                stack.extend((0..8).filter_map(|i| self.tree.child(n, i)));
                continue;
            }
            let c = view.color.unwrap_or(WHITE);
            match seen {
                None => seen = Some(c),
                Some(s) if s != c => return false,
                Some(_) => {}
            }
        }
        // New nodes have no colour: one colour only if that is none.
        !creates || seen.is_none_or(|c| c == WHITE)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cast::PreparedScan;
    use crate::files::write_ot;
    use crate::math::{ColorSlot, color_slot, morton};
    use proptest::prelude::*;

    /// Voxels of a 4 x 4 x 4 cube (two levels of the tree), so that scans prune and expand.
    fn code_of(cell: u8) -> u64 {
        let k = |i: u8| 32768 + u16::from((cell >> (2 * i)) & 3);
        morton([k(0), k(1), k(2)])
    }

    /// One scan's updates: each cell of the cube missed, hit with a colour, or left alone.
    type Scan = Vec<(u8, Option<[u8; 3]>)>;

    /// A coloured tree after `scans`, each applied in OctoMap's phases (misses, then hits,
    /// then the colour calls) in the order given.
    fn tree_after(scans: &[Scan]) -> OcTree {
        let mut t = OcTree::new(0.1);
        t.enable_color();
        for scan in scans {
            let (misses, hits) = split(scan);
            let mut ups = misses;
            ups.extend(hits);
            let mut colors: Vec<(u64, ColorSlot)> = scan
                .iter()
                .filter_map(|(c, col)| col.map(|col| (code_of(*c), color_slot(Some(col)))))
                .collect();
            colors.sort_unstable_by_key(|h| h.0);
            t.apply_scan(&PreparedScan {
                ups,
                hits: colors,
                octomap_order: true,
                ..PreparedScan::default()
            });
        }
        t
    }

    /// A scan's misses and hits, each voxel once (its first mention), in the scan's order.
    fn split(scan: &Scan) -> (Vec<Upd>, Vec<Upd>) {
        let mut seen = 0u64;
        let (mut misses, mut hits) = (Vec::new(), Vec::new());
        for (c, col) in scan {
            if seen >> c & 1 == 1 {
                continue;
            }
            seen |= 1 << c;
            let u = Upd {
                code: code_of(*c),
                hit: col.is_some(),
            };
            if u.hit { hits.push(u) } else { misses.push(u) }
        }
        (misses, hits)
    }

    fn sorted(ups: &[Upd]) -> Vec<Upd> {
        let mut s = ups.to_vec();
        s.sort_unstable_by_key(|u| u.code);
        s
    }

    /// A tree's `.ot` (colours included) and a scan's changes.
    type Outcome = (Vec<u8>, Vec<Change>);

    /// `ups` in the order given, voxel by voxel, against one pass in Morton order.
    fn both_ways(t: &OcTree, ups: &[Upd]) -> (Outcome, Outcome) {
        let (mut a, mut b) = (t.clone(), t.clone());
        let ca = a.apply_ups(ups, false);
        let cb = b.apply_ups(&sorted(ups), true);
        ((write_ot(&a), ca), (write_ot(&b), cb))
    }

    use crate::tree::Change;

    /// Seven voxels under one node at the lower clamp with colours of their own, one a miss
    /// away from it: the miss then a hit of another prunes the node into its mean colour and
    /// expands it again, which the other order does not.
    #[test]
    fn a_prune_then_expand_of_mixed_colours_is_found() {
        // Child i of the cube's first depth-15 node.
        let child = |i: u8| (i & 1) | (i >> 1 & 1) << 2 | (i >> 2 & 1) << 4;
        let miss = |i: u8| (child(i), None);
        let mut scans: Vec<Scan> = Vec::new();
        // Each child is hit with its own colour (child 0 twice, so that they do not prune),
        // then missed until clamped, all but child 7, left one miss above the clamp.
        let hit = |i: u8| (child(i), Some([10 * i + 5, 40, 200]));
        scans.push((0..4).map(hit).collect());
        scans.push((4..8).chain([0]).map(hit).collect());
        for round in 0..10 {
            scans.push((0..8).filter(|&i| i != 7 || round < 7).map(miss).collect());
        }
        let t = tree_after(&scans);
        let ups = vec![
            Upd {
                code: code_of(child(7)),
                hit: false,
            },
            Upd {
                code: code_of(child(3)),
                hit: true,
            },
        ];
        let ((ot_a, _), (ot_b, _)) = both_ways(&t, &ups);
        assert_ne!(ot_a, ot_b, "the two orders should give other colours here");
        assert!(order_can_matter(&t, &sorted(&ups)));
        // The first depth-15 node holds the risk (the cube's first node at depth 14 is not
        // pruned: its other children are unknown).
        assert_eq!(
            order_risk(&t, &sorted(&ups)),
            Risk::Within(vec![Region::of(code_of(child(0)), TREE_DEPTH - 1)])
        );
        // Either update alone: nothing to expand again.
        assert!(!order_can_matter(&t, &ups[..1]));
        assert!(!order_can_matter(&t, &ups[1..]));
    }

    /// A scan of the cube, node by node (each of its eight depth-15 nodes): its children left
    /// alone, missed or hit (each hit with one of a few colours), mostly all of them, so that
    /// siblings share values, nodes prune, and a scan can leave some children behind.
    fn scan_strategy() -> impl Strategy<Value = Scan> {
        let node = (
            0u8..3,
            prop::bool::weighted(0.5),
            any::<u8>(),
            prop::array::uniform8(0u8..27),
        );
        prop::array::uniform8(node).prop_map(|nodes| {
            let mut scan = Scan::new();
            for (n, (what, all, mask, colors)) in nodes.into_iter().enumerate() {
                for i in 0..8u8 {
                    if what == 0 || (!all && mask >> i & 1 == 0) {
                        continue;
                    }
                    let c = colors[i as usize];
                    let color = [c % 3, c / 3 % 3, c / 9].map(|k| k * 100 + 20);
                    let cell = (i & 1) | (i >> 1 & 1) << 2 | (i >> 2 & 1) << 4;
                    // Node n's origin in the cube: bit 0 of each axis' 2-bit cell index.
                    let base =
                        (n as u8 & 1) << 1 | (n as u8 >> 1 & 1) << 3 | (n as u8 >> 2 & 1) << 5;
                    scan.push((base | cell, (what == 2).then_some(color)));
                }
            }
            scan
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]

        /// When the pass says the order cannot matter, every order of a phase's updates
        /// (the free cells', then the hit cells') gives the one-pass tree and changes. When
        /// it says the order may matter only inside some subtrees, the updates outside them in
        /// one pass and those inside voxel by voxel, in the phase's order among themselves,
        /// give the tree and changes of the whole phase in that order.
        #[test]
        fn every_order_the_pass_allows_gives_the_same_tree(
            before in prop::collection::vec(scan_strategy(), 0..30),
            scan in scan_strategy(),
            shuffles in prop::collection::vec(any::<u64>(), 3),
        ) {
            let mut t = tree_after(&before);
            let (misses, hits) = split(&scan);
            for phase in [misses, hits] {
                let risk = order_risk(&t, &sorted(&phase));
                for seed in &shuffles {
                    let mut order = phase.clone();
                    shuffle(&mut order, *seed);
                    match &risk {
                        Risk::Nowhere => {
                            let (a, b) = both_ways(&t, &order);
                            prop_assert_eq!(a, b);
                        }
                        Risk::Within(risky) => {
                            prop_assert!(within_and_whole(&t, &order, risky).0);
                        }
                        Risk::Whole => {}
                    }
                }
                t.apply_ups(&phase, false);
            }
        }
    }

    /// Whether `order` applied as [`Risk::Within`] `risky` lets a scan apply it gives the tree
    /// and changes of `order` voxel by voxel; and whether that differs from one Morton pass.
    fn within_and_whole(t: &OcTree, order: &[Upd], risky: &[Region]) -> (bool, bool) {
        let (mut a, mut b) = (t.clone(), t.clone());
        let ca = a.apply_ups(order, false);
        let cb = b.apply_ups_within(&sorted(order), order, risky);
        let (_, morton) = both_ways(t, order);
        let whole = (write_ot(&a), ca);
        ((write_ot(&b), cb) == whole, morton != whole)
    }

    /// Each phase (the free cells', then the hit cells') of 3000 seeded random cases: `f`
    /// sees the tree before it, the phase and a shuffled order of it; then the phase goes in.
    fn seeded_phases(mut f: impl FnMut(&OcTree, &[Upd], &[Upd])) {
        use proptest::strategy::ValueTree;
        use proptest::test_runner::TestRunner;
        let mut runner = TestRunner::deterministic();
        let cases = (
            prop::collection::vec(scan_strategy(), 0..30),
            scan_strategy(),
            any::<u64>(),
        );
        for _ in 0..3000 {
            let Ok(tree) = cases.new_tree(&mut runner) else {
                continue;
            };
            let (before, scan, seed) = tree.current();
            let mut t = tree_after(&before);
            let (misses, hits) = split(&scan);
            for phase in [misses, hits] {
                let mut order = phase.clone();
                shuffle(&mut order, seed | 1);
                f(&t, &phase, &order);
                t.apply_ups(&phase, false);
            }
        }
    }

    /// Risky subtrees are found where the order matters, and applying the rest in one pass
    /// keeps OctoMap's map: over many random cases, phases where one Morton pass would give
    /// another tree are applied right with only their risky subtrees in order.
    #[test]
    fn risky_subtrees_carry_every_order_that_matters() {
        let (mut within, mut rescued) = (0, 0);
        seeded_phases(|t, phase, order| {
            if let Risk::Within(risky) = order_risk(t, &sorted(phase)) {
                let (same, morton_differs) = within_and_whole(t, order, &risky);
                assert!(same, "the risky subtrees did not carry the order");
                within += 1;
                rescued += usize::from(morton_differs);
            }
        });
        assert!(
            within >= 50 && rescued >= 3,
            "{within} phases risky in part, {rescued} where one pass would differ: too tame"
        );
    }

    /// The pass is neither vacuous nor blind: over many random cases it clears phases of
    /// several updates, and orders that do give other trees occur, each in a phase it flagged.
    #[test]
    fn the_pass_clears_most_phases_and_flags_every_order_that_matters() {
        let (mut cleared, mut flagged, mut differing) = (0, 0, 0);
        seeded_phases(|t, phase, order| {
            let may = order_can_matter(t, &sorted(phase));
            let (a, b) = both_ways(t, order);
            if a != b {
                assert!(may, "an order that matters was not flagged");
                differing += 1;
            }
            if may {
                flagged += 1;
            } else if phase.len() >= 2 {
                cleared += 1;
            }
        });
        assert!(
            differing >= 5,
            "{differing} orders that matter: the cases are too tame"
        );
        assert!(
            cleared > 10 * flagged,
            "{cleared} cleared against {flagged} flagged"
        );
    }

    /// A Fisher-Yates shuffle from a seed (xorshift).
    fn shuffle(v: &mut [Upd], mut seed: u64) {
        for i in (1..v.len()).rev() {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            v.swap(i, (seed % (i as u64 + 1)) as usize);
        }
    }
}
