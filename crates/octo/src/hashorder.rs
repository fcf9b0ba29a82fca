//! OctoMap's `KeySet` in the order OctoMap walks it.
//!
//! `insertPointCloud` collects a scan's free and occupied cells in two `KeySet`s and updates
//! the tree cell by cell in the sets' iteration order. The final log-odds do not depend on that
//! order, but a `ColorOcTree`'s colours do: a node pruned after one update and expanded again by
//! a later one in the same scan gives its eight children the mean of their colours.
//!
//! Built with GCC, OctoMap 1.9's `KeySet` is `std::tr1::unordered_set<OcTreeKey, KeyHash>`
//! (`OcTreeKey.h`), and [`KeySet`] reproduces libstdc++'s TR1 hash table:
//! - the hash is `KeyHash`: `k0 + 1447 k1 + 345637 k2`; a key's bucket is the hash modulo the
//!   bucket count;
//! - the buckets are chains; a new key goes first in its bucket's chain; iteration walks the
//!   buckets in order, each chain from its first key;
//! - an empty set has 11 buckets (the default hint 10, rounded up to a listed prime);
//! - before inserting a new key, and before inserting a range (a ray: OctoMap inserts each ray's
//!   cells with one range insert), the rehash policy (`_Prime_rehash_policy`, maximum load factor
//!   1, growth factor 2, its arithmetic in `f32`) may grow the table to the first prime of
//!   [`PRIMES`] at least `max(elements + inserted, 2 * buckets)`; a rehash moves the keys bucket
//!   by bucket, each chain from its first key, each key to the front of its new chain.
//!
//! [`PRIMES`] is libstdc++'s `__prime_list`, as the library holds it (GCC 12). Nothing here
//! panics; memory is 12 bytes a key plus 4 a bucket, and a table never has more than about
//! twice as many buckets as keys (plus the longest ray).

use super::cellset::CellSet;
use super::tree::Key;

/// libstdc++'s bucket counts (`std::tr1::__detail::__prime_list`, 64-bit).
pub const PRIMES: [u64; 304] = [
    2,
    3,
    5,
    7,
    11,
    13,
    17,
    19,
    23,
    29,
    31,
    37,
    41,
    43,
    47,
    53,
    59,
    61,
    67,
    71,
    73,
    79,
    83,
    89,
    97,
    103,
    109,
    113,
    127,
    137,
    139,
    149,
    157,
    167,
    179,
    193,
    199,
    211,
    227,
    241,
    257,
    277,
    293,
    313,
    337,
    359,
    383,
    409,
    439,
    467,
    503,
    541,
    577,
    619,
    661,
    709,
    761,
    823,
    887,
    953,
    1031,
    1109,
    1193,
    1289,
    1381,
    1493,
    1613,
    1741,
    1879,
    2029,
    2179,
    2357,
    2549,
    2753,
    2971,
    3209,
    3469,
    3739,
    4027,
    4349,
    4703,
    5087,
    5503,
    5953,
    6427,
    6949,
    7517,
    8123,
    8783,
    9497,
    10273,
    11113,
    12011,
    12983,
    14033,
    15173,
    16411,
    17749,
    19183,
    20753,
    22447,
    24281,
    26267,
    28411,
    30727,
    33223,
    35933,
    38873,
    42043,
    45481,
    49201,
    53201,
    57557,
    62233,
    67307,
    72817,
    78779,
    85229,
    92203,
    99733,
    107897,
    116731,
    126271,
    136607,
    147793,
    159871,
    172933,
    187091,
    202409,
    218971,
    236897,
    256279,
    277261,
    299951,
    324503,
    351061,
    379787,
    410857,
    444487,
    480881,
    520241,
    562841,
    608903,
    658753,
    712697,
    771049,
    834181,
    902483,
    976369,
    1056323,
    1142821,
    1236397,
    1337629,
    1447153,
    1565659,
    1693859,
    1832561,
    1982627,
    2144977,
    2320627,
    2510653,
    2716249,
    2938679,
    3179303,
    3439651,
    3721303,
    4026031,
    4355707,
    4712381,
    5098259,
    5515729,
    5967347,
    6456007,
    6984629,
    7556579,
    8175383,
    8844859,
    9569143,
    10352717,
    11200489,
    12117689,
    13109983,
    14183539,
    15345007,
    16601593,
    17961079,
    19431899,
    21023161,
    22744717,
    24607243,
    26622317,
    28802401,
    31160981,
    33712729,
    36473443,
    39460231,
    42691603,
    46187573,
    49969847,
    54061849,
    58488943,
    63278561,
    68460391,
    74066549,
    80131819,
    86693767,
    93793069,
    101473717,
    109783337,
    118773397,
    128499677,
    139022417,
    150406843,
    162723577,
    176048909,
    190465427,
    206062531,
    222936881,
    241193053,
    260944219,
    282312799,
    305431229,
    330442829,
    357502601,
    386778277,
    418451333,
    452718089,
    489790921,
    529899637,
    573292817,
    620239453,
    671030513,
    725980837,
    785430967,
    849749479,
    919334987,
    994618837,
    1076067617,
    1164186217,
    1259520799,
    1362662261,
    1474249943,
    1594975441,
    1725587117,
    1866894511,
    2019773507,
    2185171673,
    2364114217,
    2557710269,
    2767159799,
    2993761039,
    3238918481,
    3504151727,
    3791104843,
    4101556399,
    4294967291,
    6442450933,
    8589934583,
    12884901857,
    17179869143,
    25769803693,
    34359738337,
    51539607367,
    68719476731,
    103079215087,
    137438953447,
    206158430123,
    274877906899,
    412316860387,
    549755813881,
    824633720731,
    1099511627689,
    1649267441579,
    2199023255531,
    3298534883309,
    4398046511093,
    6597069766607,
    8796093022151,
    13194139533241,
    17592186044399,
    26388279066581,
    35184372088777,
    52776558133177,
    70368744177643,
    105553116266399,
    140737488355213,
    211106232532861,
    281474976710597,
    562949953421231,
    1125899906842597,
    2251799813685119,
    4503599627370449,
    9007199254740881,
    18014398509481951,
    36028797018963913,
    72057594037927931,
    144115188075855859,
    288230376151711717,
    576460752303423433,
    1152921504606846883,
    2305843009213693951,
    4611686018427387847,
    9223372036854775783,
    18446744073709551557,
];

const NONE: u32 = u32::MAX;

#[derive(Clone, Copy)]
struct Node {
    key: Key,
    next: u32,
}

/// OctoMap's `KeyHash`.
pub fn key_hash(k: Key) -> u64 {
    k[0] as u64 + 1447 * k[1] as u64 + 345_637 * k[2] as u64
}

/// A set of keys that iterates in the order OctoMap's `KeySet` does after the same inserts.
#[derive(Clone)]
pub struct KeySet {
    nodes: Vec<Node>,
    /// First key of each bucket's chain.
    heads: Vec<u32>,
    /// `1 / heads.len()`, for the bucket index without a division.
    inv_buckets: f64,
    /// The rehash policy's `_M_next_resize`.
    next_resize: u64,
    /// A range being inserted (see [`KeySet::begin_range`]).
    pending: Vec<Key>,
    /// The same keys, for a fast membership test (the chains answer it too, slower).
    members: CellSet,
}

impl Default for KeySet {
    fn default() -> Self {
        Self::new()
    }
}

/// `_M_next_bkt`: the first listed prime at least `n` (the last one if none), and the element
/// count at which the table grows again.
fn next_bucket_count(n: u64) -> (u64, u64) {
    // As libstdc++: the search leaves out the last prime, so anything above the one before
    // lands on the last.
    let i = PRIMES[..PRIMES.len() - 1].partition_point(|&p| p < n);
    let p = PRIMES[i];
    (p, (p as f32).ceil() as u64)
}

impl KeySet {
    /// An empty set, as a default-constructed `std::tr1::unordered_set` (11 buckets).
    pub fn new() -> Self {
        let mut s = KeySet {
            nodes: Vec::new(),
            heads: Vec::new(),
            inv_buckets: 1.0,
            next_resize: 0,
            pending: Vec::new(),
            members: CellSet::new(),
        };
        s.clear();
        s
    }

    /// Empties the set and returns it to its initial state (keeping its memory).
    pub fn clear(&mut self) {
        let (count, next_resize) = next_bucket_count(10);
        self.nodes.clear();
        self.heads.clear();
        self.heads.resize(count as usize, NONE);
        self.inv_buckets = 1.0 / count as f64;
        self.next_resize = next_resize;
        self.pending.clear();
        self.members.clear();
    }

    /// Keeps the keys from `low` to `high` (inclusive, each axis) in a dense table for the
    /// membership test ([`CellSet::set_window`]); a speed hint. Empties the set.
    pub fn set_window(&mut self, low: Key, high: Key) {
        self.clear();
        self.members.set_window(low, high);
    }

    /// Number of keys.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The key's bucket: its hash modulo the bucket count, by a multiplication (the hash is
    /// below 2^35, so the `f64` quotient is off by at most one, and corrected).
    fn bucket_of(&self, k: Key) -> usize {
        let h = key_hash(k) as i64;
        let n = self.heads.len() as i64;
        let q = (h as f64 * self.inv_buckets) as i64;
        let mut r = h - q * n;
        if r < 0 {
            r += n;
        } else if r >= n {
            r -= n;
        }
        r as usize
    }

    /// `_M_need_rehash`: the new bucket count if `inserting` more keys need more buckets.
    fn need_rehash(&mut self, inserting: u64) -> Option<u64> {
        let elements = self.nodes.len() as u64;
        let buckets = self.heads.len() as u64;
        if elements + inserting <= self.next_resize {
            return None;
        }
        let min_buckets = inserting as f32 + elements as f32;
        if min_buckets > buckets as f32 {
            let want = min_buckets.max(2.0 * buckets as f32);
            let (count, next_resize) = next_bucket_count((want as f64).ceil() as u64);
            self.next_resize = next_resize;
            Some(count)
        } else {
            self.next_resize = (buckets as f32).ceil() as u64;
            None
        }
    }

    fn rehash(&mut self, count: u64) {
        let old = std::mem::take(&mut self.heads);
        self.heads = vec![NONE; count as usize];
        self.inv_buckets = 1.0 / count as f64;
        for mut p in old {
            while let Some(&node) = self.nodes.get(p as usize) {
                let b = self.bucket_of(node.key);
                self.nodes[p as usize].next = self.heads[b];
                self.heads[b] = p;
                p = node.next;
            }
        }
    }

    /// Whether `k` is in bucket `b`'s chain.
    fn in_chain(&self, b: usize, k: Key) -> bool {
        let mut p = self.heads[b];
        while let Some(node) = self.nodes.get(p as usize) {
            if node.key == k {
                return true;
            }
            p = node.next;
        }
        false
    }

    /// Whether `k` is in the set.
    pub fn contains(&self, k: Key) -> bool {
        self.in_chain(self.bucket_of(k), k)
    }

    /// Inserts `k` (`insert(value)`); false if it was there already (then, as in libstdc++,
    /// nothing changes).
    pub fn insert(&mut self, k: Key) -> bool {
        if !self.members.insert_new(k) {
            return false;
        }
        if let Some(count) = self.need_rehash(1) {
            self.rehash(count);
        }
        let b = self.bucket_of(k);
        let idx = self.nodes.len() as u32;
        self.nodes.push(Node {
            key: k,
            next: self.heads[b],
        });
        self.heads[b] = idx;
        true
    }

    /// Starts a range insert (`insert(first, last)`): keys given to [`KeySet::add_to_range`]
    /// are inserted by [`KeySet::end_range`].
    pub fn begin_range(&mut self) {
        self.pending.clear();
    }

    /// Adds a key to the range being inserted.
    pub fn add_to_range(&mut self, k: Key) {
        self.pending.push(k);
    }

    /// Inserts the range: first the policy's look at its whole length, then key by key.
    pub fn end_range(&mut self) {
        let pending = std::mem::take(&mut self.pending);
        let mut keys = pending.iter().copied();
        self.insert_range(pending.len() as u64, || keys.next());
        self.pending = pending;
        self.pending.clear();
    }

    /// A range insert of `len` keys, repeats and keys already in the set included, whose other
    /// keys `keys` gives in their order in the range: the policy's look at the whole length,
    /// then key by key (what [`KeySet::end_range`] does, for a caller that knows the range's
    /// new keys without the range).
    pub fn insert_range(&mut self, len: u64, mut keys: impl FnMut() -> Option<Key>) {
        if let Some(count) = self.need_rehash(len) {
            self.rehash(count);
        }
        while let Some(k) = keys() {
            self.insert(k);
        }
    }

    /// The keys in iteration order.
    pub fn iter(&self) -> impl Iterator<Item = Key> + '_ {
        let mut bucket = 0usize;
        let mut p = NONE;
        std::iter::from_fn(move || {
            loop {
                if let Some(n) = self.nodes.get(p as usize) {
                    p = n.next;
                    return Some(n.key);
                }
                p = *self.heads.get(bucket)?;
                bucket += 1;
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holds_each_key_once_and_iterates_them_all() {
        let mut s = KeySet::new();
        let mut rng = rovlink_base::rng::Rng::new(3, 0);
        let mut want = std::collections::HashSet::new();
        for i in 0..5000 {
            let k = [
                (rng.uniform() * 40.0) as u16,
                (rng.uniform() * 40.0) as u16,
                32768 + (rng.uniform() * 4.0) as u16,
            ];
            if i % 7 == 0 {
                s.begin_range();
                s.add_to_range(k);
                s.end_range();
                want.insert(k);
            } else {
                assert_eq!(s.insert(k), want.insert(k));
            }
            assert!(s.contains(k));
        }
        assert_eq!(s.len(), want.len());
        let got: Vec<Key> = s.iter().collect();
        assert_eq!(got.len(), want.len());
        assert_eq!(
            got.iter()
                .copied()
                .collect::<std::collections::HashSet<_>>(),
            want
        );
        assert!(!s.contains([65535, 65535, 65535]));
        s.clear();
        assert!(s.is_empty() && s.iter().next().is_none());
    }

    #[test]
    fn bucket_index_is_the_remainder() {
        let mut s = KeySet::new();
        let mut rng = rovlink_base::rng::Rng::new(5, 0);
        for &count in PRIMES.iter().filter(|&&p| p <= 1_447_153) {
            s.rehash(count);
            let mut keys = vec![[0u16, 0, 0], [65535, 65535, 65535], [65535, 0, 65535]];
            keys.extend((0..50).map(|_| [0, 1, 2].map(|_| (rng.uniform() * 65535.0) as u16)));
            for k in keys {
                assert_eq!(
                    s.bucket_of(k) as u64,
                    key_hash(k) % count,
                    "{k:?} mod {count}"
                );
            }
        }
    }

    #[test]
    fn order_follows_libstdcxx_tr1() {
        // Worked by hand from the rules: 11 buckets; hashes 0, 11 and 1 fall in buckets 0, 0
        // and 1; the second key goes first in bucket 0's chain.
        let mut s = KeySet::new();
        s.insert([0, 0, 0]);
        s.insert([11, 0, 0]);
        s.insert([1, 0, 0]);
        let got: Vec<Key> = s.iter().collect();
        assert_eq!(got, vec![[11, 0, 0], [0, 0, 0], [1, 0, 0]]);
        // The twelfth key grows the table to 23 buckets (the first prime >= 2 * 11); a range of
        // 40 keys into an empty set to 41 (the first prime >= 40).
        for x in 2..12 {
            s.insert([x, 0, 0]);
        }
        assert_eq!(s.heads.len(), 23);
        let mut r = KeySet::new();
        r.begin_range();
        for x in 0..40 {
            r.add_to_range([x, 0, 0]);
        }
        r.end_range();
        assert_eq!(r.heads.len(), 41);
        assert_eq!(r.iter().next(), Some([0, 0, 0]));
    }
}
