//! Many rays walked at once, for a plain scan's free cells.
//!
//! A scan's rays all start at the sensor and are short (tens of cells), and one ray's walk is a
//! chain of data-dependent choices (which axis to step next) that a processor mispredicts about
//! every other cell. [`walk_lanes`] walks [`LANES`] rays side by side instead, choosing each
//! ray's axis with comparisons and selects rather than branches: the rays' steps are
//! independent, so they overlap in the processor, and nothing is mispredicted but a ray's end.
//! Every ray takes exactly the steps [`RayWalk::step`] takes (the same comparisons, in the same
//! `f64` arithmetic), so the cells are the same; only the order in which the rays' cells come
//! out is interleaved, which a set does not see.
//!
//! The cells go into a [`BoxBits`]: one bit per cell of the scan's key box (padded by the few
//! cells a walk may overshoot its end), a 64-bit word per 4 x 4 x 4 cells with its bits in
//! Morton order, so that draining the set in Morton order sorts only the words that hold a
//! cell.
//!
//! Nothing here panics: a key outside the box is reported (the caller falls back to the
//! general [`super::cellset::CellSet`]) rather than written out of bounds.

use super::math::{Key, RayWalk, local_morton, morton};

/// Rays walked side by side.
pub(crate) const LANES: usize = 16;

/// Cells a walk may go past its end's key on an axis (its step bound allows 3 extra steps).
pub(crate) const OVERSHOOT_CELLS: u16 = 4;

/// Most words (64 cells each) a [`BoxBits`] holds (2 MiB: a box of 256 x 256 x 256 cells).
const BOX_WORDS_MAX: u64 = 1 << 18;

/// Morton code of each cell inside a word's 4 x 4 x 4 cells, indexed by `x | y << 2 | z << 4`.
const LOCAL: [u8; 64] = {
    let mut t = [0u8; 64];
    let mut i = 0;
    while i < 64 {
        t[i] = local_morton(i, 2) as u8;
        i += 1;
    }
    t
};

/// How a key box's cells are numbered ([`BoxBits`]' bits, [`super::firstray::FirstRay`]'s
/// slots): a word of 64 per 4 x 4 x 4 cells, numbered in Morton order inside it; a power of
/// two of words along each axis, x fastest, so that a cell's number is found with shifts.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct BoxLayout {
    /// Lowest key of the box on each axis, a multiple of 4.
    pub(crate) low: [u16; 3],
    /// Log2 of the words along each axis.
    pub(crate) shift: [u32; 3],
}

impl BoxLayout {
    /// The layout of the cells from `low` to `high` (inclusive, each axis) and its number of
    /// words; `None` if the box is empty or too large (more than [`BOX_WORDS_MAX`] words).
    pub(crate) fn fit(low: Key, high: Key) -> Option<(BoxLayout, usize)> {
        let lo = low.map(|k| k & !3);
        let shift = [0, 1, 2].map(|i| {
            let words = (high[i].saturating_sub(lo[i]) as u32 >> 2) + 1;
            words.next_power_of_two().trailing_zeros()
        });
        let words = 1u64 << shift.iter().sum::<u32>();
        if high.iter().zip(&low).any(|(h, l)| h < l) || words > BOX_WORDS_MAX {
            return None;
        }
        Some((BoxLayout { low: lo, shift }, words as usize))
    }

    /// The numbers of the cells of the lanes whose bit is set in `keep` (lane `l`'s cell being
    /// `[kx[l], ky[l], kz[l]]`), side by side without a branch; the lanes whose cell is in the
    /// box, as bits, and whether a kept lane's cell is outside it. A lane not taken has number 0.
    #[inline(always)]
    pub(crate) fn lane_cells(
        &self,
        kx: &[u16; LANES],
        ky: &[u16; LANES],
        kz: &[u16; LANES],
        keep: u32,
    ) -> ([u32; LANES], u32, bool) {
        let [sx, sy, sz] = self.shift;
        let [lx, ly, lz] = self.low;
        let mut cells = [0u32; LANES];
        let (mut taken, mut outside) = (0u32, 0u32);
        for l in 0..LANES {
            let x = kx[l].wrapping_sub(lx) as u32;
            let y = ky[l].wrapping_sub(ly) as u32;
            let z = kz[l].wrapping_sub(lz) as u32;
            let kept = keep >> l & 1;
            let out = ((x >> (sx + 2)) | (y >> (sy + 2)) | (z >> (sz + 2)) != 0) as u32;
            let take = kept & !out;
            let local =
                (x & 1) | (y & 1) << 1 | (z & 1) << 2 | (x & 2) << 2 | (y & 2) << 3 | (z & 2) << 4;
            let word = (x >> 2) | (y >> 2) << sx | (z >> 2) << (sx + sy);
            cells[l] = (word << 6 | local) & take.wrapping_neg();
            taken |= take << l;
            outside |= kept & out;
        }
        (cells, taken, outside != 0)
    }

    /// Cell `k`'s number (its word times 64 plus its bit); `None` outside the box.
    #[inline(always)]
    pub(crate) fn cell(&self, k: Key) -> Option<usize> {
        let x = k[0].wrapping_sub(self.low[0]) as usize;
        let y = k[1].wrapping_sub(self.low[1]) as usize;
        let z = k[2].wrapping_sub(self.low[2]) as usize;
        let [sx, sy, sz] = self.shift;
        if (x >> (sx + 2)) | (y >> (sy + 2)) | (z >> (sz + 2)) != 0 {
            return None;
        }
        let word = (x >> 2) | (y >> 2) << sx | (z >> 2) << (sx + sy);
        Some(word << 6 | LOCAL[(x & 3) | (y & 3) << 2 | (z & 3) << 4] as usize)
    }
}

/// A set of the cells of one key box, a bit each: a word (64 bits) per 4 x 4 x 4 cells, its
/// bits in Morton order; a power of two of words along each axis, so that a cell's word is
/// found with shifts.
#[derive(Clone, Debug, Default)]
pub(crate) struct BoxBits {
    /// Where each cell's bit is.
    layout: BoxLayout,
    /// The words, x fastest.
    words: Vec<u64>,
    /// Whether a key outside the box was inserted (and dropped).
    missed: bool,
}

impl BoxBits {
    /// An empty set covering the cells from `low` to `high` (inclusive, each axis); `None` if
    /// the box is too large for a table of bits.
    #[cfg(test)]
    pub(crate) fn new(low: Key, high: Key) -> Option<Self> {
        let mut b = BoxBits::default();
        b.reset(low, high).then_some(b)
    }

    /// Empties the set and makes it cover the cells from `low` to `high`; false (and the set
    /// unusable) if the box is too large.
    pub(crate) fn reset(&mut self, low: Key, high: Key) -> bool {
        self.words.clear();
        self.missed = false;
        let Some((layout, words)) = BoxLayout::fit(low, high) else {
            self.layout = BoxLayout::default();
            return false;
        };
        self.layout = layout;
        self.words.resize(words, 0);
        true
    }

    /// Whether the set covers cell `k`.
    #[cfg(test)]
    pub(crate) fn covers(&self, k: Key) -> bool {
        !self.words.is_empty() && self.layout.cell(k).is_some()
    }

    /// How many cells the set holds.
    pub(crate) fn len(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// Whether a key outside the box was inserted since the last reset (the set is then
    /// incomplete: it dropped that key).
    pub(crate) fn missed(&self) -> bool {
        self.missed
    }

    /// Adds cell `k`; a key outside the box is dropped, and [`BoxBits::missed`] says so.
    #[inline(always)]
    pub(crate) fn insert(&mut self, k: Key) {
        let word = self
            .layout
            .cell(k)
            .and_then(|c| Some((self.words.get_mut(c >> 6)?, c & 63)));
        match word {
            Some((w, bit)) => *w |= 1 << bit,
            None => self.missed = true,
        }
    }

    /// Adds every cell of `other`, a set over the same box.
    pub(crate) fn union_with(&mut self, other: &BoxBits) {
        for (a, b) in self.words.iter_mut().zip(&other.words) {
            *a |= b;
        }
    }

    /// The words holding a cell of `self` or `also` (a set over the same box), as (Morton
    /// code of the word's first cell, word index), in Morton order.
    fn words_in_order(&self, also: Option<&BoxBits>) -> Vec<(u64, usize)> {
        let [sx, sy, _] = self.layout.shift;
        let low = self.layout.low.map(|k| k >> 2);
        let mut order: Vec<(u64, usize)> = Vec::new();
        for (i, &w) in self.words.iter().enumerate() {
            let other = also.and_then(|o| o.words.get(i)).copied().unwrap_or(0);
            if w | other != 0 {
                let k = [
                    low[0] + (i & ((1 << sx) - 1)) as u16,
                    low[1] + ((i >> sx) & ((1 << sy) - 1)) as u16,
                    low[2] + (i >> (sx + sy)) as u16,
                ];
                order.push((morton(k) << 6, i));
            }
        }
        order.sort_unstable();
        order
    }

    /// The cells of `self` (free) and of `hits` (a set over the same box), merged in Morton
    /// order into `out(code, hit)`, a cell in both once, as hit.
    pub(crate) fn merged_codes(&self, hits: &BoxBits, mut out: impl FnMut(u64, bool)) {
        for (base, i) in self.words_in_order(Some(hits)) {
            let hit = hits.words.get(i).copied().unwrap_or(0);
            let mut word = self.words[i] | hit;
            while word != 0 {
                let bit = word.trailing_zeros();
                out(base | bit as u64, hit >> bit & 1 == 1);
                word &= word - 1;
            }
        }
    }
}

/// Where [`walk_lanes`] puts the cells it walks.
pub(crate) trait LaneSink {
    /// The next walk (in the order the walks come) starts in lane `lane`: the cells that
    /// [`LaneSink::insert`] gets until the next call to this or [`LaneSink::resume`] are its
    /// first, and the lane's cells in [`LaneSink::insert_lanes`] are its.
    #[inline(always)]
    fn begin(&mut self, _lane: usize) {}

    /// The cells [`LaneSink::insert`] gets from now are those of the walk in lane `lane`
    /// (finishing the walks one by one).
    #[inline(always)]
    fn resume(&mut self, _lane: usize) {}

    /// Adds one cell.
    fn insert(&mut self, k: Key);

    /// Adds the cell of every lane whose bit is set in `keep`, lane `l`'s cell being
    /// `[kx[l], ky[l], kz[l]]`.
    #[inline(always)]
    fn insert_lanes(&mut self, kx: &[u16; LANES], ky: &[u16; LANES], kz: &[u16; LANES], keep: u32) {
        for l in 0..LANES {
            if keep >> l & 1 == 1 {
                self.insert([kx[l], ky[l], kz[l]]);
            }
        }
    }
}

impl LaneSink for BoxBits {
    #[inline(always)]
    fn insert(&mut self, k: Key) {
        BoxBits::insert(self, k);
    }

    /// The lanes' words and bits computed side by side (no branch, no table: the compiler
    /// turns the first loop into a few vector operations), then or-ed into the words one lane
    /// after the other, so that two lanes in the same word both land. A lane not kept, or
    /// outside the box, ors nothing (bit mask 0) into word 0; one outside the box sets
    /// [`BoxBits::missed`].
    #[inline(always)]
    fn insert_lanes(&mut self, kx: &[u16; LANES], ky: &[u16; LANES], kz: &[u16; LANES], keep: u32) {
        let [sx, sy, sz] = self.layout.shift;
        let [lx, ly, lz] = self.layout.low;
        let mut word = [0u32; LANES];
        let mut bits = [0u64; LANES];
        let mut outside = 0u32;
        for l in 0..LANES {
            let x = kx[l].wrapping_sub(lx) as u32;
            let y = ky[l].wrapping_sub(ly) as u32;
            let z = kz[l].wrapping_sub(lz) as u32;
            let kept = keep >> l & 1;
            let out = ((x >> (sx + 2)) | (y >> (sy + 2)) | (z >> (sz + 2)) != 0) as u32;
            let take = kept & !out;
            let local =
                (x & 1) | (y & 1) << 1 | (z & 1) << 2 | (x & 2) << 2 | (y & 2) << 3 | (z & 2) << 4;
            word[l] = ((x >> 2) | (y >> 2) << sx | (z >> 2) << (sx + sy)) & take.wrapping_neg();
            bits[l] = (take as u64) << local;
            outside |= kept & out;
        }
        // Every word index is inside the table (the box test above), unless the table is
        // empty (a box too large, which the caller does not walk into).
        self.missed |= outside != 0 || self.words.is_empty();
        for l in 0..LANES {
            if let Some(w) = self.words.get_mut(word[l] as usize) {
                *w |= bits[l];
            }
        }
    }
}

#[cfg(test)]
impl LaneSink for Vec<Key> {
    fn insert(&mut self, k: Key) {
        self.push(k);
    }
}

/// [`LANES`] walks side by side, one array per quantity.
struct Lanes {
    tx: [f64; LANES],
    ty: [f64; LANES],
    tz: [f64; LANES],
    dx: [f64; LANES],
    dy: [f64; LANES],
    dz: [f64; LANES],
    length: [f64; LANES],
    kx: [u16; LANES],
    ky: [u16; LANES],
    kz: [u16; LANES],
    sx: [u16; LANES],
    sy: [u16; LANES],
    sz: [u16; LANES],
    ex: [u16; LANES],
    ey: [u16; LANES],
    ez: [u16; LANES],
    left: [u32; LANES],
}

impl Lanes {
    #[inline(always)]
    fn new() -> Self {
        Lanes {
            tx: [0.0; LANES],
            ty: [0.0; LANES],
            tz: [0.0; LANES],
            dx: [0.0; LANES],
            dy: [0.0; LANES],
            dz: [0.0; LANES],
            length: [0.0; LANES],
            kx: [0; LANES],
            ky: [0; LANES],
            kz: [0; LANES],
            sx: [0; LANES],
            sy: [0; LANES],
            sz: [0; LANES],
            ex: [0; LANES],
            ey: [0; LANES],
            ez: [0; LANES],
            left: [0; LANES],
        }
    }

    #[inline(always)]
    fn load(&mut self, l: usize, w: &RayWalk) {
        [self.tx[l], self.ty[l], self.tz[l]] = w.t_max;
        [self.dx[l], self.dy[l], self.dz[l]] = w.t_delta;
        [self.kx[l], self.ky[l], self.kz[l]] = w.key;
        [self.sx[l], self.sy[l], self.sz[l]] = w.step;
        [self.ex[l], self.ey[l], self.ez[l]] = w.end;
        self.length[l] = w.length;
        self.left[l] = w.steps_left;
    }

    fn walk(&self, l: usize) -> RayWalk {
        RayWalk {
            t_max: [self.tx[l], self.ty[l], self.tz[l]],
            t_delta: [self.dx[l], self.dy[l], self.dz[l]],
            step: [self.sx[l], self.sy[l], self.sz[l]],
            key: [self.kx[l], self.ky[l], self.kz[l]],
            end: [self.ex[l], self.ey[l], self.ez[l]],
            length: self.length[l],
            steps_left: self.left[l],
        }
    }

    /// One step of every lane, as [`RayWalk::step`] takes it; the lanes whose walk ended, as
    /// bits. A lane that goes on has its new cell in `kx`, `ky`, `kz`.
    #[inline(always)]
    fn step(&mut self) -> u32 {
        let mut ended = 0u32;
        for l in 0..LANES {
            let (tx, ty, tz) = (self.tx[l], self.ty[l], self.tz[l]);
            let x_lt_y = tx < ty;
            let mx = x_lt_y & (tx < tz);
            let my = !x_lt_y & (ty < tz);
            let mz = !(mx | my);
            // Selects written as masks, so that they compile to no branch: adding +0.0 leaves
            // every value as it was (a -0.0 becomes +0.0, which compares and adds the same).
            let (fx, fy, fz) = (mask64(mx), mask64(my), mask64(mz));
            let ntx = tx + f64::from_bits(self.dx[l].to_bits() & fx);
            let nty = ty + f64::from_bits(self.dy[l].to_bits() & fy);
            let ntz = tz + f64::from_bits(self.dz[l].to_bits() & fz);
            let kx = self.kx[l].wrapping_add(self.sx[l] & fx as u16);
            let ky = self.ky[l].wrapping_add(self.sy[l] & fy as u16);
            let kz = self.kz[l].wrapping_add(self.sz[l] & fz as u16);
            self.tx[l] = ntx;
            self.ty[l] = nty;
            self.tz[l] = ntz;
            self.kx[l] = kx;
            self.ky[l] = ky;
            self.kz[l] = kz;
            let reached = (kx == self.ex[l]) & (ky == self.ey[l]) & (kz == self.ez[l]);
            let m = if nty < ntx { nty } else { ntx };
            let dist = if ntz < m { ntz } else { m };
            let left = self.left[l].wrapping_sub(1);
            self.left[l] = left;
            let end = reached | (dist > self.length[l]) | (left == 0);
            ended |= (end as u32) << l;
        }
        ended
    }
}

/// All ones if `b`, else zero.
#[inline(always)]
fn mask64(b: bool) -> u64 {
    (b as u64).wrapping_neg()
}

/// Walks every ray of `walks` (each started at its first cell, which it puts in `out` first),
/// [`LANES`] at a time, putting each cell a ray crosses into `out`: the same cells as walking
/// each with [`RayWalk::step`], interleaved; each walk's cells in its own order, and which walk
/// a cell is of told by [`LaneSink::begin`] and [`LaneSink::resume`].
#[inline(always)]
pub(crate) fn walk_lanes(walks: &mut impl Iterator<Item = RayWalk>, out: &mut impl LaneSink) {
    let mut lanes = Lanes::new();
    let mut live = 0u32;
    for l in 0..LANES {
        let Some(w) = walks.next() else { break };
        out.begin(l);
        out.insert(w.key);
        lanes.load(l, &w);
        live |= 1 << l;
    }
    let all = (1u32 << LANES) - 1;
    while live == all {
        let ended = lanes.step();
        out.insert_lanes(&lanes.kx, &lanes.ky, &lanes.kz, !ended & all);
        let mut e = ended;
        while e != 0 {
            let l = e.trailing_zeros() as usize;
            e &= e - 1;
            match walks.next() {
                Some(w) => {
                    out.begin(l);
                    out.insert(w.key);
                    lanes.load(l, &w);
                }
                None => live &= !(1 << l),
            }
        }
    }
    // Out of rays: the walks still going finish one by one.
    for l in 0..LANES {
        if live & (1 << l) != 0 {
            out.resume(l);
            let mut w = lanes.walk(l);
            while let Some(k) = w.step() {
                out.insert(k);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::math::{Grid, RayStart};
    use super::*;

    /// Rays from a few origins to random ends, some long, some axis-aligned, some on cell
    /// borders: the lanes give each the cells [`RayWalk::step`] gives.
    #[test]
    fn lanes_walk_the_cells_one_walk_at_a_time_walks() {
        let grid = Grid::new(0.1);
        let mut rng = rovlink_base::rng::Rng::new(17, 0);
        let mut u = move || (rng.next_u32() as f64 / u32::MAX as f64) as f32;
        for origin in [[0.05f32, -0.3, 2.0], [0.1, 0.2, 0.3], [-7.33, 4.0, -1.25]] {
            let mut ends: Vec<[f32; 3]> = (0..997)
                .map(|_| {
                    let r = 0.05 + 8.0 * u();
                    [0, 1, 2].map(|i| origin[i] + r * (2.0 * u() - 1.0))
                })
                .collect();
            ends.push([origin[0] + 3.0, origin[1], origin[2]]);
            ends.push([origin[0], origin[1] - 0.3, origin[2]]);
            ends.push([0.2, 0.2, 0.2]);
            ends.push(origin);
            let walks: Vec<RayWalk> = ends
                .iter()
                .filter_map(|&e| match grid.ray_start(origin, e) {
                    RayStart::Walk(w) => Some(w),
                    _ => None,
                })
                .collect();
            let one_by_one = |walks: &[RayWalk]| {
                let mut cells: Vec<Key> = Vec::new();
                for &w in walks {
                    let mut w = w;
                    cells.push(w.key);
                    while let Some(k) = w.step() {
                        cells.push(k);
                    }
                }
                cells
            };
            for n in [0, 1, LANES - 1, LANES, LANES + 1, walks.len()] {
                let mut got = Vec::new();
                walk_lanes(&mut walks[..n].iter().copied(), &mut got);
                let mut one = one_by_one(&walks[..n]);
                got.sort_unstable();
                one.sort_unstable();
                assert_eq!(got, one, "{n} rays from {origin:?}");
            }
            assert!(one_by_one(&walks).len() > 10 * walks.len());
        }
    }

    #[test]
    fn box_bits_drain_in_morton_order_and_merge_hits() {
        let mut rng = rovlink_base::rng::Rng::new(5, 0);
        let low = [32001, 31990, 17];
        let high = [32100, 32030, 40];
        let mut free = BoxBits::new(low, high).expect("small box");
        let mut hits = BoxBits::new(low, high).expect("small box");
        let (mut want_free, mut want_hits) = (Vec::new(), Vec::new());
        for n in 0..4000 {
            let k =
                [0, 1, 2].map(|i| low[i] + (rng.next_u32() % (high[i] - low[i] + 1) as u32) as u16);
            assert!(free.covers(k));
            if n % 5 == 0 {
                hits.insert(k);
                want_hits.push(morton(k));
            } else {
                free.insert(k);
                want_free.push(morton(k));
            }
        }
        assert!(!free.covers([low[0] - 8, low[1], low[2]]));
        assert!(!free.covers([low[0], high[1] + 100, low[2]]));
        want_free.sort_unstable();
        want_free.dedup();
        want_hits.sort_unstable();
        want_hits.dedup();
        // A set's own cells: merged with an empty set, none is a hit.
        let none = BoxBits::new(low, high).expect("small box");
        let codes = |set: &BoxBits| {
            let mut v = Vec::new();
            set.merged_codes(&none, |c, hit| {
                assert!(!hit);
                v.push(c);
            });
            v
        };
        assert_eq!(codes(&free), want_free);
        let mut merged = Vec::new();
        free.merged_codes(&hits, |c, hit| merged.push((c, hit)));
        let mut want: Vec<(u64, bool)> = want_free
            .iter()
            .filter(|c| want_hits.binary_search(c).is_err())
            .map(|&c| (c, false))
            .chain(want_hits.iter().map(|&c| (c, true)))
            .collect();
        want.sort_unstable();
        assert_eq!(merged, want);
        let mut both = free.clone();
        both.union_with(&hits);
        let mut all: Vec<u64> = want_free.iter().chain(&want_hits).copied().collect();
        all.sort_unstable();
        all.dedup();
        assert_eq!(codes(&both), all);
        assert!(!free.missed());
        free.insert([low[0] - 8, low[1], low[2]]);
        assert!(free.missed());
        assert_eq!(codes(&free), want_free);
        assert!(BoxBits::new([0; 3], [u16::MAX; 3]).is_none());
    }
}
