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
//! cells a walk may overshoot its end), a 64-bit word per 4 x 4 x 4 cells, so that draining the
//! set in Morton order sorts only the words that hold a cell (each word's bits are put in
//! Morton order as it is drained).
//!
//! A lane's key is one integer ([`pack`]: 21 bits an axis), so that a step is one add, the end
//! test one comparison, and every quantity of a lane is 64 bits wide, as its `f64`s are: the
//! compiler then keeps each quantity of four lanes in one AVX2 register, with no packing or
//! unpacking between widths.
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

/// The Morton code inside a word's 4 x 4 x 4 cells of each cell's bit (`x | y << 2 | z << 4`).
const LOCAL: [u8; 64] = {
    let mut t = [0u8; 64];
    let mut i = 0;
    while i < 64 {
        t[i] = local_morton(i, 2) as u8;
        i += 1;
    }
    t
};

/// A word's bits moved to their cells' Morton order inside the word ([`LOCAL`]), a byte at a
/// time: entry `[b][v]` holds the Morton bits of the cells of byte `b`'s set bits `v`.
static TO_MORTON: [[u64; 256]; 8] = {
    let mut t = [[0u64; 256]; 8];
    let mut b = 0;
    while b < 8 {
        let mut v = 0;
        while v < 256 {
            let mut m = 0u64;
            let mut j = 0;
            while j < 8 {
                if v >> j & 1 == 1 {
                    m |= 1 << LOCAL[8 * b + j];
                }
                j += 1;
            }
            t[b][v] = m;
            v += 1;
        }
        b += 1;
    }
    t
};

/// Word `w`'s bits in Morton order: bit `m` set when the cell whose Morton code inside the
/// word is `m` is in `w`.
#[inline]
fn to_morton(w: u64) -> u64 {
    (0..8).fold(0, |acc, b| {
        acc | TO_MORTON[b][(w >> (8 * b) & 0xff) as usize]
    })
}

/// Bits of each axis in a packed key ([`pack`]).
const FIELD_BITS: u32 = 21;

/// One axis's bits of a packed key, shifted down.
const FIELD: u64 = (1 << FIELD_BITS) - 1;

/// Key `k` as one integer, `x | y << 21 | z << 42`: a step along an axis is one add, and two
/// keys are equal when their integers are. A walk that stays in its scan's key box (every
/// lanes walk does, or the box reports it) never carries between the axes, whose keys are at
/// most 16 bits.
#[inline(always)]
pub(crate) fn pack(k: Key) -> u64 {
    k[0] as u64 | (k[1] as u64) << FIELD_BITS | (k[2] as u64) << (2 * FIELD_BITS)
}

/// The key of a packed key ([`pack`]).
#[inline(always)]
pub(crate) fn unpack(p: u64) -> Key {
    [0, 1, 2].map(|i| (p >> (i as u32 * FIELD_BITS) & FIELD) as u16)
}

/// How a key box's cells are numbered ([`BoxBits`]' bits, [`super::firstray::FirstRay`]'s
/// slots): a word of 64 per 4 x 4 x 4 cells, `x | y << 2 | z << 4` inside it (the low two
/// bits of each key); a power of two of words along each axis, x fastest, so that a cell's
/// number is found with shifts and masks.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct BoxLayout {
    /// Lowest key of the box on each axis, a multiple of 4.
    pub(crate) low: [u16; 3],
    /// Log2 of the words along each axis.
    pub(crate) shift: [u32; 3],
    /// `low`, packed ([`pack`]).
    low_packed: u64,
    /// The bits of a packed key less `low_packed` that are set only outside the box: on each
    /// axis those from `shift + 2` up (a key past the box's high side sets one; one below its
    /// low side borrows, setting the field's top bit), and the top bit.
    outside: u64,
    /// How far a packed key less `low_packed` goes down on each axis for that axis's part of
    /// the word number (its key over 4, shifted up by the lower axes' shifts).
    word_down: [u32; 3],
    /// Each axis's part of the word number, after `word_down`.
    word_mask: [u64; 3],
}

impl BoxLayout {
    /// The layout of the cells from `low` to `high` (inclusive, each axis) and its number of
    /// words; `None` if the box is empty or too large (more than [`BOX_WORDS_MAX`] words).
    pub(crate) fn fit(low: Key, high: Key) -> Option<(BoxLayout, usize)> {
        let mut lo = low.map(|k| k & !3);
        let shift = [0, 1, 2].map(|i| {
            let words = (high[i].saturating_sub(lo[i]) as u32 >> 2) + 1;
            words.next_power_of_two().trailing_zeros()
        });
        let words = 1u64 << shift.iter().sum::<u32>();
        if high.iter().zip(&low).any(|(h, l)| h < l) || words > BOX_WORDS_MAX {
            return None;
        }
        // The box stays inside the key range: moved down when its power-of-two size would take
        // it past key 65535 (it is at most the range's 65 536 cells). A walk's key then leaves
        // the box before it could wrap (OctoMap's keys are 16-bit and wrap; a packed key does
        // not), and the box reports it.
        for i in 0..3 {
            let cells = 4u32 << shift[i];
            if lo[i] as u32 + cells > 1 << 16 {
                lo[i] = u16::try_from((1u32 << 16).checked_sub(cells)?).ok()?;
            }
        }
        // Below: how a packed key's bits map to the cell's number. A box is at most 2^16 cells
        // an axis (shift at most 14), so the field's top bit (20) is never a key's.
        let up = [0, shift[0], shift[0] + shift[1]];
        let field_low = |i: usize| i as u32 * FIELD_BITS;
        let outside = (0..3).fold(1u64 << 63, |acc, i| {
            acc | (FIELD & !((4u64 << shift[i]) - 1)) << field_low(i)
        });
        let layout = BoxLayout {
            low: lo,
            shift,
            low_packed: pack(lo),
            outside,
            word_down: [0, 1, 2].map(|i| field_low(i) + 2 - up[i]),
            word_mask: [0, 1, 2].map(|i| ((1u64 << shift[i]) - 1) << up[i]),
        };
        Some((layout, words as usize))
    }

    /// Whether packed key `key` ([`pack`]) is outside the box.
    #[inline(always)]
    pub(crate) fn outside(&self, key: u64) -> bool {
        key.wrapping_sub(self.low_packed) & self.outside != 0
    }

    /// The cell of packed key `key` ([`pack`]), a key inside the box: its word and its bit in
    /// the word. A key outside the box gives some cell of the box (the masks keep the word
    /// inside it): the caller tells apart with [`BoxLayout::outside`]. No branch, no table, a
    /// few operations: the lanes compute it side by side.
    #[inline(always)]
    fn parts(&self, key: u64) -> (u64, u64) {
        let rel = key.wrapping_sub(self.low_packed);
        // x0 x1 y0 y1 z0 z1: bits 0, 1, 21, 22, 42, 43 of `rel`.
        let local = (rel & 3) | (rel >> 19 & 12) | (rel >> 38 & 48);
        let [dx, dy, dz] = self.word_down;
        let [mx, my, mz] = self.word_mask;
        let word = (rel >> dx & mx) | (rel >> dy & my) | (rel >> dz & mz);
        (word, local)
    }

    /// The numbers of the cells of the lanes whose bit is set in `keep` (lane `l`'s cell being
    /// `keys[l]`, packed), side by side without a branch; a lane not kept has number 0. A
    /// lane's key outside the box gives some cell of the box ([`BoxLayout::parts`]).
    #[inline(always)]
    pub(crate) fn lane_cells(&self, keys: &[u64; LANES], keep: u32) -> [u32; LANES] {
        let mut cells = [0u32; LANES];
        for l in 0..LANES {
            let (word, local) = self.parts(keys[l]);
            let take = (keep >> l & 1) as u64;
            cells[l] = ((word << 6 | local) & take.wrapping_neg()) as u32;
        }
        cells
    }

    /// Cell `k`'s number (its word times 64 plus its bit); `None` outside the box.
    #[inline(always)]
    pub(crate) fn cell(&self, k: Key) -> Option<usize> {
        let key = pack(k);
        let (word, local) = self.parts(key);
        (!self.outside(key)).then_some((word << 6 | local) as usize)
    }
}

/// A set of the cells of one key box, a bit each, numbered as [`BoxLayout`] says: a word (64
/// bits) per 4 x 4 x 4 cells; a power of two of words along each axis, so that a cell's word
/// is found with shifts.
#[derive(Clone, Debug, Default)]
pub(crate) struct BoxBits {
    /// Where each cell's bit is.
    layout: BoxLayout,
    /// The words, x fastest.
    words: Vec<u64>,
    /// Whether a key outside the box came (dropped, or put in some cell of the box).
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

    /// Whether a key outside the box came since the last reset: a cell inserted one by one
    /// is dropped, a lane's cell may have gone into some cell of the box
    /// ([`LaneSink::end_lane`]). The set is then wrong, and the scan is cast the general way.
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
            let hit = to_morton(hits.words.get(i).copied().unwrap_or(0));
            let mut word = to_morton(self.words[i]) | hit;
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

    /// The walk in lane `lane` ended, its key at `key` (packed): the cell after its last one
    /// (or its last, when the walks run out). Each axis's key only ever steps one way, so every
    /// cell the walk gave [`LaneSink::insert_lanes`] lies between its first cell and `key` on
    /// each axis: if both are inside a box, so are they all. A sink that cannot hold cells
    /// outside its box checks `key` here rather than every cell (its first is checked on
    /// [`LaneSink::insert`]).
    #[inline(always)]
    fn end_lane(&mut self, _key: u64) {}

    /// Adds the cell of every lane whose bit is set in `keep`, lane `l`'s cell being
    /// `keys[l]`, packed ([`pack`]). A sink with a box may put a cell outside it anywhere in
    /// the box, provided the walk's end ([`LaneSink::end_lane`]) then tells it was outside.
    #[inline(always)]
    fn insert_lanes(&mut self, keys: &[u64; LANES], keep: u32) {
        for (l, &key) in keys.iter().enumerate() {
            if keep >> l & 1 == 1 {
                self.insert(unpack(key));
            }
        }
    }
}

impl LaneSink for BoxBits {
    #[inline(always)]
    fn insert(&mut self, k: Key) {
        BoxBits::insert(self, k);
    }

    /// A walk ending outside the box sets [`BoxBits::missed`]: one of its cells may have been
    /// outside, and put in the wrong word.
    #[inline(always)]
    fn end_lane(&mut self, key: u64) {
        self.missed |= self.layout.outside(key);
    }

    /// The lanes' words and bits computed side by side (no branch, no table: the compiler
    /// turns the first loop into a few vector operations), then or-ed into the words one lane
    /// after the other, so that two lanes in the same word both land. A lane not kept ors
    /// nothing (bit mask 0) into word 0. A cell outside the box is not looked for here: it
    /// lands in some word of the box, and [`LaneSink::end_lane`] reports its walk.
    #[inline(always)]
    fn insert_lanes(&mut self, keys: &[u64; LANES], keep: u32) {
        let mut word = [0u64; LANES];
        let mut bits = [0u64; LANES];
        for l in 0..LANES {
            let (w, local) = self.layout.parts(keys[l]);
            let take = (keep >> l & 1) as u64;
            word[l] = w & take.wrapping_neg();
            bits[l] = take << local;
        }
        // Every word index is inside the table (the masks of `parts`), unless the table is
        // empty (a box too large, which the caller does not walk into).
        self.missed |= self.words.is_empty();
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

/// [`LANES`] walks side by side, one array per quantity, each 64 bits a lane.
///
/// A lane's keys are kept packed ([`pack`]) and mirrored on each axis its walk steps down
/// (that axis's bits complemented, `FIELD - k`), so that every walk steps up on every axis:
/// a step adds the same constant to any lane (1, `1 << 21` or `1 << 42`), and no lane needs
/// its own steps. The walk's bound is a step number (`deadline`) against a count shared by
/// all lanes (`now`), not a count of its own written back every step.
struct Lanes {
    tx: [f64; LANES],
    ty: [f64; LANES],
    tz: [f64; LANES],
    dx: [f64; LANES],
    dy: [f64; LANES],
    dz: [f64; LANES],
    length: [f64; LANES],
    /// The current cell, packed and mirrored.
    key: [u64; LANES],
    /// The bits that mirror the key: [`FIELD`] on each axis the walk steps down.
    flip: [u64; LANES],
    /// The current cell, packed (`key ^ flip`): what the sink gets.
    cell: [u64; LANES],
    /// The end's cell, packed and mirrored.
    end: [u64; LANES],
    /// The value of `now` at which the walk has used up its steps.
    deadline: [u64; LANES],
    /// Steps the lanes have taken.
    now: u64,
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
            key: [0; LANES],
            flip: [0; LANES],
            cell: [0; LANES],
            end: [0; LANES],
            deadline: [0; LANES],
            now: 0,
        }
    }

    #[inline(always)]
    fn load(&mut self, l: usize, w: &RayWalk) {
        [self.tx[l], self.ty[l], self.tz[l]] = w.t_max;
        [self.dx[l], self.dy[l], self.dz[l]] = w.t_delta;
        // An axis the ray does not move along (step 0) is never stepped (its ray parameter
        // is f64::MAX, never the least of the three), so it needs no mirroring.
        let flip = (0..3).fold(0, |acc, i| {
            acc | if w.step[i] == u16::MAX {
                FIELD << (i as u32 * FIELD_BITS)
            } else {
                0
            }
        });
        self.flip[l] = flip;
        self.cell[l] = pack(w.key);
        self.key[l] = self.cell[l] ^ flip;
        self.end[l] = pack(w.end) ^ flip;
        self.length[l] = w.length;
        self.deadline[l] = self.now + w.steps_left as u64;
    }

    /// Lane `l`'s walk, to go on one step at a time. Its key is unpacked: a key outside the
    /// scan's box (which a packed key may not hold) is reported by the box at the walk's end
    /// ([`LaneSink::end_lane`]), and the scan is then cast again the general way. An axis not
    /// mirrored steps up: if the ray does not move along it, it is never stepped.
    fn walk(&self, l: usize) -> RayWalk {
        let flip = self.flip[l];
        let step = |i: u32| {
            if flip >> (i * FIELD_BITS) & 1 == 1 {
                u16::MAX
            } else {
                1
            }
        };
        RayWalk {
            t_max: [self.tx[l], self.ty[l], self.tz[l]],
            t_delta: [self.dx[l], self.dy[l], self.dz[l]],
            step: [step(0), step(1), step(2)],
            key: unpack(self.cell[l]),
            end: unpack(self.end[l] ^ flip),
            length: self.length[l],
            steps_left: self.deadline[l].saturating_sub(self.now) as u32,
        }
    }

    /// One step of every lane, as [`RayWalk::step`] takes it; the lanes whose walk ended, as
    /// bits. A lane that goes on has its new cell in `cell`.
    #[inline(always)]
    fn step(&mut self) -> u32 {
        self.now += 1;
        let now = self.now;
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
            let step = (fx & 1) | (fy & 1 << FIELD_BITS) | (fz & 1 << (2 * FIELD_BITS));
            let key = self.key[l].wrapping_add(step);
            self.tx[l] = ntx;
            self.ty[l] = nty;
            self.tz[l] = ntz;
            self.key[l] = key;
            self.cell[l] = key ^ self.flip[l];
            let reached = key == self.end[l];
            let m = if nty < ntx { nty } else { ntx };
            let dist = if ntz < m { ntz } else { m };
            let end = reached | (dist > self.length[l]) | (now == self.deadline[l]);
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
        out.insert_lanes(&lanes.cell, !ended & all);
        let mut e = ended;
        while e != 0 {
            let l = e.trailing_zeros() as usize;
            e &= e - 1;
            out.end_lane(lanes.cell[l]);
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
            out.end_lane(lanes.cell[l]);
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

    /// A box never reaches past the key range, where OctoMap's 16-bit keys wrap and packed
    /// keys do not: one at the range's high end is moved down (still covering what it was
    /// asked to), and the keys before 0 and after 65535 are outside.
    #[test]
    fn a_box_stays_inside_the_key_range() {
        // 12 cells from 65524 take 4 words, 16 cells: 65524 + 16 is past the range.
        let (layout, words) = BoxLayout::fit([65524, 10, 300], [65535, 90, 301]).expect("fits");
        assert_eq!(words, 4 * 32);
        let top = 65535;
        for k in [[65524, 10, 300], [top, 90, 301], [65520, 8, 300]] {
            assert!(!layout.outside(pack(k)), "{k:?} inside");
        }
        assert!(
            layout.outside(pack([top, 90, 300]) + 1),
            "the key after 65535"
        );
        assert!(layout.outside(pack([65519, 10, 300])));
        let (layout, _) = BoxLayout::fit([4, 4, 4], [65531, 4, 4]).expect("moved down");
        assert_eq!(layout.low[0], 0);
        let (layout, _) = BoxLayout::fit([0, 0, 0], [65535, 3, 3]).expect("the whole range");
        assert!(
            layout.outside(pack([0, 0, 0]).wrapping_sub(1)),
            "the key before 0"
        );
        assert!(
            layout.outside(pack([65535, 0, 0]) + 1),
            "the key after 65535"
        );
    }

    /// Walks that leave the box are reported, though the box looks only at each walk's end
    /// (every axis steps one way): rays inside it, and rays out of it along each axis and
    /// direction, as many as fill the lanes and more.
    #[test]
    fn a_walk_that_leaves_the_box_is_reported_at_its_end() {
        let grid = Grid::new(0.1);
        let origin = [0.05f32, -0.3, 2.0];
        let ko = grid.key_of(origin).expect("in range");
        let (low, high) = (ko.map(|k| k - 20), ko.map(|k| k + 20));
        for end in [
            [1.0f32, 0.3, 1.8],
            [-0.9, -1.2, 2.6],
            [9.0, 0.3, 1.8],
            [-9.0, 0.3, 1.8],
            [0.2, 8.0, 2.5],
            [0.2, -8.0, 2.5],
            [0.2, 0.1, 11.0],
            [0.2, 0.1, -7.0],
        ] {
            let RayStart::Walk(w) = grid.ray_start(origin, end) else {
                panic!("a walk to {end:?}");
            };
            let mut cells = vec![w.key];
            let mut one = w;
            while let Some(k) = one.step() {
                cells.push(k);
            }
            for n in [1, LANES, 3 * LANES + 1] {
                let mut set = BoxBits::new(low, high).expect("small box");
                walk_lanes(&mut std::iter::repeat_n(w, n), &mut set);
                let outside = cells.iter().any(|&k| !set.covers(k));
                let end_key = grid.key_of(end).expect("in range");
                assert!(
                    outside || set.covers(end_key),
                    "{end:?}: pick an end inside"
                );
                assert_eq!(set.missed(), outside, "{n} rays to {end:?}");
                if !outside {
                    assert_eq!(set.len(), cells.len(), "{n} rays to {end:?}");
                }
            }
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
