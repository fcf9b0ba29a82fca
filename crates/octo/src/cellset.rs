//! A set of voxel keys built for ray casting: many insertions with heavy repetition (every ray
//! of a scan starts in the same place) and strong locality (consecutive cells of a ray are
//! neighbours), drained once in Morton order.
//!
//! Keys are grouped in blocks of 8 x 8 x 8 cells, each a 512-bit bitmap found through a hash map
//! of block coordinates (with a one-entry cache: most consecutive insertions hit the same
//! block). Inside a block the bit index is the cell's 9-bit Morton code, so draining sorts only
//! the blocks, not the cells: a key's Morton code is its block's Morton code followed by the
//! cell's.
//!
//! A scan's cells lie in a small box (the sensor and its points): given that box
//! ([`CellSet::set_window`]), blocks inside it are found by their place in a dense table instead,
//! and only the blocks outside it go through the hash map.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use super::math::local_morton;
use super::tree::{Key, morton};

/// A multiplicative hash for integer keys (the keys are block coordinates, not attacker input).
#[derive(Default)]
pub struct IntHasher(u64);

impl Hasher for IntHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(5) ^ b as u64).wrapping_mul(0x517c_c1b7_2722_0a95);
        }
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (v ^ (v >> 29)).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
}

/// Morton code of each cell inside a block, indexed by `x | y << 3 | z << 6`.
const LOCAL: [u16; 512] = {
    let mut t = [0u16; 512];
    let mut i = 0;
    while i < 512 {
        t[i] = local_morton(i, 3);
        i += 1;
    }
    t
};

/// Most blocks of 8 x 8 x 8 cells a window's table holds (4 bytes each).
const WINDOW_BLOCKS_MAX: u64 = 1 << 20;

/// No block (in a window's table).
const ABSENT: u32 = u32::MAX;

/// A box of blocks whose indices are kept in a dense table.
#[derive(Clone, Default)]
struct Window {
    /// Lowest block coordinate on each axis.
    low: [u32; 3],
    /// Blocks along each axis.
    size: [u32; 3],
    /// Index into `blocks` of each block of the box (x fastest), or [`ABSENT`].
    slots: Vec<u32>,
}

impl Window {
    /// The table slot of block coordinates `b`, if inside the box.
    #[inline(always)]
    fn slot(&self, b: [u32; 3]) -> Option<usize> {
        let x = b[0].wrapping_sub(self.low[0]);
        let y = b[1].wrapping_sub(self.low[1]);
        let z = b[2].wrapping_sub(self.low[2]);
        (x < self.size[0] && y < self.size[1] && z < self.size[2]).then(|| {
            (x as usize) + self.size[0] as usize * (y as usize + self.size[1] as usize * z as usize)
        })
    }
}

/// A set of keys, drained in Morton order.
#[derive(Clone)]
pub struct CellSet {
    index: HashMap<u64, u32, BuildHasherDefault<IntHasher>>,
    blocks: Vec<(u64, [u64; 8])>,
    last: u64,
    last_idx: u32,
    window: Window,
}

impl Default for CellSet {
    fn default() -> Self {
        CellSet::new()
    }
}

impl CellSet {
    /// An empty set.
    pub fn new() -> Self {
        CellSet {
            index: HashMap::default(),
            blocks: Vec::new(),
            last: u64::MAX,
            last_idx: 0,
            window: Window::default(),
        }
    }

    /// Keeps the blocks of the cells from `low` to `high` (inclusive, each axis) in a dense
    /// table (unless the box is too large): a speed hint, the set holds any key. Empties the set.
    pub fn set_window(&mut self, low: Key, high: Key) {
        self.clear();
        let lo = low.map(|k| (k >> 3) as u32);
        let hi = high.map(|k| (k >> 3) as u32);
        let size = [0, 1, 2].map(|i| (hi[i] + 1).saturating_sub(lo[i]));
        let blocks: u64 = size.iter().map(|&n| n as u64).product();
        let w = &mut self.window;
        w.slots.clear();
        if blocks == 0 || blocks > WINDOW_BLOCKS_MAX {
            w.size = [0; 3];
            return;
        }
        w.low = lo;
        w.size = size;
        w.slots.resize(blocks as usize, ABSENT);
    }

    /// Adds a key.
    #[inline(always)]
    pub fn insert(&mut self, k: Key) {
        self.insert_new(k);
    }

    /// Adds a key; true if it was not in the set.
    #[inline(always)]
    pub fn insert_new(&mut self, k: Key) -> bool {
        let b = k.map(|c| (c >> 3) as u32);
        let block = b[0] as u64 | (b[1] as u64) << 13 | (b[2] as u64) << 26;
        if block != self.last {
            let next = self.blocks.len() as u32;
            let idx = match self.window.slot(b) {
                Some(slot) => {
                    let idx = &mut self.window.slots[slot];
                    if *idx == ABSENT {
                        *idx = next;
                    }
                    *idx
                }
                None => *self.index.entry(block).or_insert(next),
            };
            if idx == next {
                self.blocks.push((block, [0; 8]));
            }
            self.last = block;
            self.last_idx = idx;
        }
        let local = LOCAL[((k[0] & 7) | (k[1] & 7) << 3 | (k[2] & 7) << 6) as usize];
        let word = &mut self.blocks[self.last_idx as usize].1[(local >> 6) as usize];
        let bit = 1 << (local & 63);
        let new = *word & bit == 0;
        *word |= bit;
        new
    }

    /// Appends every key's Morton code, ascending, to `out`, and empties the set (keeping its
    /// allocations).
    pub fn drain_sorted(&mut self, out: &mut Vec<u64>) {
        let mut order: Vec<(u64, u32)> = self
            .blocks
            .iter()
            .enumerate()
            .map(|(i, (b, _))| {
                let k = [
                    (b & 0x1fff) as u16,
                    ((b >> 13) & 0x1fff) as u16,
                    ((b >> 26) & 0x1fff) as u16,
                ];
                (morton(k), i as u32)
            })
            .collect();
        order.sort_unstable();
        for (m, i) in order {
            let bits = &self.blocks[i as usize].1;
            for (w, &word) in bits.iter().enumerate() {
                let mut word = word;
                while word != 0 {
                    let bit = word.trailing_zeros() as u64;
                    out.push((m << 9) | ((w as u64) << 6) | bit);
                    word &= word - 1;
                }
            }
        }
        self.clear();
    }

    /// Empties the set (its window stays).
    pub fn clear(&mut self) {
        for &(block, _) in &self.blocks {
            let b = [block & 0x1fff, (block >> 13) & 0x1fff, block >> 26].map(|c| c as u32);
            if let Some(slot) = self.window.slot(b) {
                self.window.slots[slot] = ABSENT;
            }
        }
        self.index.clear();
        self.blocks.clear();
        self.last = u64::MAX;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drains_sorted_unique_morton_codes() {
        let mut s = CellSet::new();
        let mut rng = rovlink_base::rng::Rng::new(3, 0);
        let mut want = Vec::new();
        for _ in 0..5000 {
            let k = [
                30000 + (rng.next_u32() % 300) as u16,
                32000 + (rng.next_u32() % 40) as u16,
                (rng.next_u32() % 20) as u16,
            ];
            s.insert(k);
            s.insert(k);
            want.push(morton(k));
        }
        want.sort_unstable();
        want.dedup();
        let mut got = Vec::new();
        s.drain_sorted(&mut got);
        assert_eq!(got, want);
        s.insert([1, 2, 3]);
        got.clear();
        s.drain_sorted(&mut got);
        assert_eq!(got, vec![morton([1, 2, 3])]);
    }

    #[test]
    fn a_window_changes_nothing_but_speed() {
        let mut rng = rovlink_base::rng::Rng::new(9, 0);
        let keys: Vec<Key> = (0..20_000)
            .map(|_| [0, 1, 2].map(|_| 32700 + (rng.next_u32() % 140) as u16))
            .collect();
        let mut plain = CellSet::new();
        let mut windowed = CellSet::new();
        // Keys inside the window and outside it, on every side.
        windowed.set_window([32740; 3], [32800; 3]);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for round in 0..2 {
            for &k in &keys {
                assert_eq!(plain.insert_new(k), windowed.insert_new(k));
            }
            plain.drain_sorted(&mut a);
            windowed.drain_sorted(&mut b);
            assert_eq!(a, b, "round {round}");
        }
        // A box too large for a table: the hash map holds everything.
        windowed.set_window([0; 3], [u16::MAX; 3]);
        for &k in &keys {
            windowed.insert(k);
        }
        b.clear();
        windowed.drain_sorted(&mut b);
        assert_eq!(a[a.len() / 2..], b[..]);
    }
}
