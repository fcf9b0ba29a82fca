//! A coloured scan's free cells in the order OctoMap's `KeySet` first sees them, from rays
//! walked many at a time ([`super::lanes::walk_lanes`]).
//!
//! OctoMap inserts each ray's cells into its free `KeySet` with one range insert, ray after ray
//! in the order of the points, each ray's cells from the sensor out. Which order the set then
//! iterates in ([`super::hashorder`]) depends only on:
//! - each distinct cell's first insertion: the first ray (in point order) that crosses it, and
//!   its place along that ray; and
//! - each ray's length (the range insert's size, which the rehash policy looks at before the
//!   range goes in, repeated cells included).
//!
//! A ray's cells come out of its walk from the sensor's cell, one axis step at a time, each
//! axis always stepping the same way, so a cell's place along any ray that crosses it is its
//! distance in steps from the sensor's cell: the sum over the axes of the key differences.
//! [`FirstRay`] keeps, per cell of the scan's key box, the first walk that crossed it (walks
//! are numbered in the order they come, which is the order of their points), and per walk its
//! length; [`FirstRay::insert_into`] then inserts the distinct cells into a [`KeySet`] ray by
//! ray, each ray's new cells in their order along it, each range with its full length. The
//! set is the one inserting every ray's every cell would give, at a cost per cell of a table
//! look-up rather than a hash-table insert.
//!
//! Nothing here panics: a cell outside the box is reported ([`FirstRay::missed`]; the caller
//! casts the scan the general way) rather than written out of bounds.

use super::hashorder::KeySet;
use super::lanes::{BoxLayout, LANES, LaneSink, unpack};
use super::math::Key;

/// A lane without a walk.
const NO_WALK: u32 = u32::MAX;

/// Per cell of a scan's key box, the first walk that crossed it; per walk, its length.
#[derive(Clone, Debug)]
pub(crate) struct FirstRay {
    layout: BoxLayout,
    /// Per cell number ([`BoxLayout::cell`]): 1 + the first walk that crossed it, 0 for none.
    /// Zeroed pages are the kernel's until written, so a large box costs only the pages its
    /// rays touch; the cells written are zeroed again after each scan.
    first: Vec<u32>,
    /// The cells crossed, each once, with their numbers.
    seen: Vec<(u32, Key)>,
    /// Each walk's cells, repeated ones included (a lane's count goes in when the lane takes
    /// its next walk, and at [`FirstRay::finish`]).
    lengths: Vec<u32>,
    /// The walk in each lane ([`NO_WALK`]: none yet).
    lane_walk: [u32; LANES],
    /// The cells of each lane's walk so far.
    lane_cells: [u32; LANES],
    /// The lane [`LaneSink::insert`] adds to.
    current: usize,
    /// Whether a cell outside the box came.
    missed: bool,
}

impl Default for FirstRay {
    fn default() -> Self {
        FirstRay {
            layout: BoxLayout::default(),
            first: Vec::new(),
            seen: Vec::new(),
            lengths: Vec::new(),
            lane_walk: [NO_WALK; LANES],
            lane_cells: [0; LANES],
            current: 0,
            missed: false,
        }
    }
}

impl FirstRay {
    /// Empties the table and makes it cover the cells from `low` to `high`; false (and the
    /// table unusable) if the box is too large.
    pub(crate) fn reset(&mut self, low: Key, high: Key) -> bool {
        for &(slot, _) in &self.seen {
            if let Some(f) = self.first.get_mut(slot as usize) {
                *f = 0;
            }
        }
        self.seen.clear();
        self.lengths.clear();
        self.lane_walk = [NO_WALK; LANES];
        self.lane_cells = [0; LANES];
        self.missed = false;
        let Some((layout, words)) = BoxLayout::fit(low, high) else {
            self.layout = BoxLayout::default();
            self.missed = true;
            return false;
        };
        self.layout = layout;
        let cells = words * 64;
        if self.first.len() < cells {
            // A fresh zeroed allocation (no copy of the old one, which is all zeros).
            self.first = vec![0; cells];
        }
        true
    }

    /// Whether a cell outside the box came since the last reset (the table is then
    /// incomplete).
    pub(crate) fn missed(&self) -> bool {
        self.missed
    }

    /// Distinct cells crossed.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.seen.len()
    }

    /// The walk lane `lane` holds is done: its length goes in.
    #[inline(always)]
    fn flush(&mut self, lane: usize) {
        let walk = self.lane_walk[lane];
        if let Some(len) = self.lengths.get_mut(walk as usize) {
            *len = self.lane_cells[lane];
        }
        self.lane_cells[lane] = 0;
    }

    /// Every walk is done: the lengths of those still in lanes go in.
    pub(crate) fn finish(&mut self) {
        for lane in 0..LANES {
            self.flush(lane);
            self.lane_walk[lane] = NO_WALK;
        }
    }

    /// Adds cell `k` of walk `walk` (its length counted apart).
    #[inline(always)]
    fn add(&mut self, walk: u32, k: Key) {
        let f = self
            .layout
            .cell(k)
            .and_then(|slot| Some((self.first.get_mut(slot)?, slot)));
        let Some((f, slot)) = f else {
            self.missed = true;
            return;
        };
        lower_first(f, walk, &mut self.seen, slot as u32, k);
    }

    /// Inserts the cells crossed into `set` (emptied first) as OctoMap's range inserts of
    /// every walk's cells, in the order of the walks, would; `origin` is the sensor's cell,
    /// where every walk starts.
    pub(crate) fn insert_into(&self, origin: Key, set: &mut KeySet) {
        let steps = |k: Key| -> u32 {
            (0..3)
                .map(|i| (k[i] as i32 - origin[i] as i32).unsigned_abs())
                .sum()
        };
        // By first walk, then along it.
        let mut order: Vec<(u64, Key)> = self
            .seen
            .iter()
            .map(|&(slot, k)| {
                let walk = self.first[slot as usize] - 1;
                ((walk as u64) << 32 | steps(k) as u64, k)
            })
            .collect();
        order.sort_unstable_by_key(|e| e.0);
        let mut next = order.iter().peekable();
        for (walk, &len) in self.lengths.iter().enumerate() {
            set.insert_range(len as u64, || {
                next.next_if(|e| e.0 >> 32 == walk as u64).map(|e| e.1)
            });
        }
    }
}

/// Walk `walk` crossed cell `k` (number `slot`), whose table entry is `first`: the entry takes
/// the smaller walk (stored plus one, 0 for none), and a cell crossed for the first time is
/// listed in `seen`.
#[inline(always)]
fn lower_first(first: &mut u32, walk: u32, seen: &mut Vec<(u32, Key)>, slot: u32, k: Key) {
    let walk = walk.saturating_add(1);
    let old = *first;
    *first = if old == 0 || walk < old { walk } else { old };
    if old == 0 {
        seen.push((slot, k));
    }
}

impl LaneSink for FirstRay {
    #[inline(always)]
    fn begin(&mut self, lane: usize) {
        let lane = lane % LANES;
        self.flush(lane);
        self.lane_walk[lane] = self.lengths.len() as u32;
        self.lengths.push(0);
        self.current = lane;
    }

    #[inline(always)]
    fn resume(&mut self, lane: usize) {
        self.current = lane % LANES;
    }

    #[inline(always)]
    fn insert(&mut self, k: Key) {
        self.lane_cells[self.current] += 1;
        self.add(self.lane_walk[self.current], k);
    }

    /// A walk ending outside the box sets [`FirstRay::missed`]: one of its cells may have
    /// been outside, and put in the wrong slot.
    #[inline(always)]
    fn end_lane(&mut self, key: u64) {
        self.missed |= self.layout.outside(key);
    }

    /// The lanes' cell numbers computed side by side, then each cell's first walk lowered to
    /// its lane's walk with a select (a cell seen for the first time, rare, is also listed).
    #[inline(always)]
    fn insert_lanes(&mut self, keys: &[u64; LANES], keep: u32) {
        for l in 0..LANES {
            self.lane_cells[l] += keep >> l & 1;
        }
        let cells = self.layout.lane_cells(keys, keep);
        for l in 0..LANES {
            if keep >> l & 1 == 0 {
                continue;
            }
            let Some(f) = self.first.get_mut(cells[l] as usize) else {
                self.missed = true;
                continue;
            };
            lower_first(
                f,
                self.lane_walk[l],
                &mut self.seen,
                cells[l],
                unpack(keys[l]),
            );
        }
    }
}
