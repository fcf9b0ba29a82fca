//! A set of voxel keys built for ray casting: many insertions with heavy repetition (every ray
//! of a scan starts in the same place) and strong locality (consecutive cells of a ray are
//! neighbours), drained once in Morton order.
//!
//! Keys are grouped in blocks of 8 x 8 x 8 cells, each a 512-bit bitmap found through a hash map
//! of block coordinates (with a one-entry cache: most consecutive insertions hit the same
//! block). Inside a block the bit index is the cell's 9-bit Morton code, so draining sorts only
//! the blocks, not the cells: a key's Morton code is its block's Morton code followed by the
//! cell's.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

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
        let (x, y, z) = (i & 7, (i >> 3) & 7, (i >> 6) & 7);
        let mut m = 0;
        let mut b = 0;
        while b < 3 {
            m |= ((x >> b) & 1) << (3 * b);
            m |= ((y >> b) & 1) << (3 * b + 1);
            m |= ((z >> b) & 1) << (3 * b + 2);
            b += 1;
        }
        t[i] = m as u16;
        i += 1;
    }
    t
};

/// A set of keys, drained in Morton order.
#[derive(Clone)]
pub struct CellSet {
    index: HashMap<u64, u32, BuildHasherDefault<IntHasher>>,
    blocks: Vec<(u64, [u64; 8])>,
    last: u64,
    last_idx: u32,
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
        }
    }

    /// Adds a key.
    #[inline(always)]
    pub fn insert(&mut self, k: Key) {
        self.insert_new(k);
    }

    /// Adds a key; true if it was not in the set.
    #[inline(always)]
    pub fn insert_new(&mut self, k: Key) -> bool {
        let block = (k[0] >> 3) as u64 | ((k[1] >> 3) as u64) << 13 | ((k[2] >> 3) as u64) << 26;
        if block != self.last {
            let next = self.blocks.len() as u32;
            let idx = *self.index.entry(block).or_insert(next);
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

    /// Empties the set.
    pub fn clear(&mut self) {
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
        let mut rng = crate::link::Rng::new(3, 0);
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
}
