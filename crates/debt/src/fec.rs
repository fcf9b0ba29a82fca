//! Erasure-coded trunks: parity after the stream, so that lost trunks come back.
//!
//! A link carries a stream in trunks of `T` bytes (39 in the paper's ROV frames). A plain DEBT
//! stream is one embedded segment: a lost trunk makes everything after it useless. With FEC,
//! the encoder spends part of the budget on `m` parity trunks of a systematic Reed-Solomon
//! erasure code over GF(2^8) (crate `reed-solomon-erasure`) and puts them after the `k` data
//! trunks of the stream, which is unchanged otherwise: a receiver shows the data trunks as they
//! arrive, exactly as without FEC, and once the parity has arrived any `k` of the `k + m` trunks
//! give back the whole stream.
//!
//! Layout (`docs/debt-format.md`, version 5): the stream's header says the trunk size `T`, the
//! protected length `D` (header included) and `m`; the data trunks are `D` cut into `T`-byte
//! pieces, the last one padded with zeros, then `m` parity trunks: `(k + m) T` bytes in all,
//! so that the link's trunks are the code's. A code over GF(2^8) has at most 256 shards, so a longer stream is
//! split into `B = ceil((k + m) / 250)` interleaved blocks: data trunk `i` is in block `i % B`,
//! parity trunk `j` in block `j % B`.
//!
//! The header travels in the first data trunk. When that trunk is lost, [`repair`] finds the
//! layout by trying the parity counts the encoder's rule ([`parity_trunks`]) gives for
//! `--fec 1` to `--fec 50` at the received length, and keeps the one whose recovered header
//! states that same layout.
//!
//! No-panic contract: [`repair`] takes any bytes and any trunk list.

use std::ops::Range;

use reed_solomon_erasure::galois_8::ReedSolomon;

use super::Error;

mod erasure;

/// Most parity, in percent of the trunks, that `--fec` takes.
pub const MAX_PERCENT: u32 = 50;
/// Most trunks (data and parity) in one code block: GF(2^8) allows 256, less the rounding of
/// the interleave.
const BLOCK_TRUNKS: usize = 250;
/// The largest protected length the header can state (3 bytes).
pub const MAX_DATA_BYTES: usize = (1 << 24) - 1;
/// The most parity trunks the header can state (2 bytes).
pub const MAX_PARITY_TRUNKS: usize = u16::MAX as usize;

/// The erasure code of a stream, as its header states it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fec {
    /// Trunk size in bytes, 1..=255.
    pub trunk_bytes: usize,
    /// Bytes of the protected stream (the data trunks), header included.
    pub data_bytes: usize,
    /// Parity trunks after the data, 1..=65535.
    pub parity_trunks: usize,
}

/// Parity trunks for a stream of `total_trunks` trunks (data and parity) at `percent` parity:
/// `round(total_trunks * percent / 100)`, at least 1.
pub fn parity_trunks(total_trunks: usize, percent: u32) -> usize {
    (total_trunks
        .saturating_mul(percent as usize)
        .saturating_add(50)
        / 100)
        .max(1)
}

impl Fec {
    /// Bytes the code takes in the header.
    pub const LEN: usize = 6;

    /// Data trunks (the last may be shorter than a trunk).
    pub fn data_trunks(&self) -> usize {
        self.data_bytes.div_ceil(self.trunk_bytes.max(1))
    }

    /// Bytes of the whole stream: the data trunks (the last one padded with zeros), then the
    /// parity trunks: a whole number of trunks, so that the link's trunks are the code's.
    pub fn total_bytes(&self) -> usize {
        (self.data_trunks() + self.parity_trunks) * self.trunk_bytes
    }

    /// Interleaved code blocks.
    fn blocks(&self) -> usize {
        (self.data_trunks() + self.parity_trunks)
            .div_ceil(BLOCK_TRUNKS)
            .max(1)
    }

    /// The 6 header bytes: trunk size, protected bytes (24 bits), parity trunks (16 bits).
    pub(super) fn write(&self, out: &mut Vec<u8>) {
        out.push(self.trunk_bytes as u8);
        out.extend_from_slice(&(self.data_bytes.min(MAX_DATA_BYTES) as u32).to_be_bytes()[1..]);
        out.extend_from_slice(&(self.parity_trunks.min(MAX_PARITY_TRUNKS) as u16).to_be_bytes());
    }

    /// Reads the 6 header bytes at the start of `data`, which sits at offset `at` in the stream.
    pub(super) fn read(data: &[u8], at: usize) -> Result<Fec, Error> {
        let Some(&[t, d0, d1, d2, m0, m1]) = data.get(..Self::LEN) else {
            return Err(Error::Truncated {
                expected: at + Self::LEN,
                found: at + data.len(),
            });
        };
        let fec = Fec {
            trunk_bytes: usize::from(t),
            data_bytes: u32::from_be_bytes([0, d0, d1, d2]) as usize,
            parity_trunks: usize::from(u16::from_be_bytes([m0, m1])),
        };
        if fec.trunk_bytes == 0 || fec.parity_trunks == 0 {
            return Err(Error::Setting {
                field: "FEC trunk size and parity trunks",
                expected: "both at least 1",
                found: (fec.trunk_bytes as u64) << 16 | fec.parity_trunks as u64,
            });
        }
        Ok(fec)
    }

    /// Data and parity trunks of block `b`, as stream trunk indices (data first).
    fn block_trunks(&self, b: usize) -> (Vec<usize>, Vec<usize>) {
        let blocks = self.blocks();
        let k = self.data_trunks();
        let data = (b..k).step_by(blocks).collect();
        let parity = (b..self.parity_trunks)
            .step_by(blocks)
            .map(|j| k + j)
            .collect();
        (data, parity)
    }

    /// Byte range of stream trunk `i` (data or parity) in the stream.
    fn trunk_range(&self, i: usize) -> Range<usize> {
        let t = self.trunk_bytes;
        let k = self.data_trunks();
        if i < k {
            i * t..((i + 1) * t).min(self.data_bytes)
        } else {
            i * t..(i + 1) * t
        }
    }

    /// The parity trunks of `data` (the protected stream, `data_bytes` long), concatenated.
    pub(super) fn parity(&self, data: &[u8]) -> Vec<u8> {
        let t = self.trunk_bytes;
        let mut out = vec![0u8; self.parity_trunks * t];
        for b in 0..self.blocks() {
            let (data_trunks, parity) = self.block_trunks(b);
            if data_trunks.is_empty() || parity.is_empty() {
                continue;
            }
            let Ok(rs) = ReedSolomon::new(data_trunks.len(), parity.len()) else {
                continue;
            };
            let mut shards: Vec<Vec<u8>> = data_trunks
                .iter()
                .map(|&i| {
                    let mut shard = data.get(self.trunk_range(i)).unwrap_or_default().to_vec();
                    shard.resize(t, 0);
                    shard
                })
                .chain(parity.iter().map(|_| vec![0u8; t]))
                .collect();
            if rs.encode(&mut shards).is_err() {
                continue;
            }
            for (&i, shard) in parity.iter().zip(&shards[data_trunks.len()..]) {
                let at = (i - self.data_trunks()) * t;
                out[at..at + t].copy_from_slice(shard);
            }
        }
        out
    }
}

/// A stream after [`repair`]: the protected bytes with what the parity brought back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Repaired {
    /// The stream's protected bytes (all of a stream without FEC), lost ones as zeros.
    pub data: Vec<u8>,
    /// Byte ranges of `data` still lost.
    pub lost: Vec<Range<usize>>,
    /// The code, when the stream has one and its layout was found.
    pub fec: Option<Fec>,
}

impl Repaired {
    /// The whole stream (data trunks, then parity computed again) when nothing is still lost
    /// and the stream has parity.
    pub fn whole(&self) -> Option<Vec<u8>> {
        let fec = self.fec.filter(|_| self.lost.is_empty())?;
        let mut out = self.data.clone();
        out.resize(fec.data_trunks() * fec.trunk_bytes, 0);
        out.extend_from_slice(&fec.parity(&self.data));
        Some(out)
    }
}

/// Repairs a stream as received: `stream` holds every byte (a lost trunk's bytes are ignored),
/// `lost` lists the trunks (of `trunk_bytes`) that never arrived, and a stream shorter than its
/// code says lacks its tail. For a stream with FEC, each block whose lost trunks do not
/// outnumber its parity comes back whole; otherwise (or without FEC) the result is the stream
/// with its lost ranges, for the decoder to decode up to the first gap.
///
/// Bounded whatever the list: it becomes a set once (repeats count once, trunks past the
/// stream's end are ignored), and a lost header costs at most [`MAX_PERCENT`] layout guesses,
/// each rebuilding only the blocks the header's bytes reach into.
pub fn repair(stream: &[u8], trunk_bytes: usize, lost: &[usize]) -> Repaired {
    Received::new(stream, trunk_bytes, lost).repair()
}

/// The longest header a stream with parity can have (ROI, features, the most multipliers,
/// the code), rounded up: the bytes a search for the layout must recover.
const HEADER_TRUNK_BYTES: usize = 80;

/// The trunks a receiver lost, as a set: sorted, each once, none past the stream's end (such a
/// trunk holds nothing to lose). At most one entry a trunk of the stream, whatever the list.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Erased {
    /// The lost trunks, in increasing order.
    trunks: Vec<usize>,
}

impl Erased {
    /// The trunks of `lost` below `trunks`, the stream's trunk count.
    fn new(lost: &[usize], trunks: usize) -> Erased {
        let mut set: Vec<usize> = lost.iter().copied().filter(|&i| i < trunks).collect();
        set.sort_unstable();
        set.dedup();
        Erased { trunks: set }
    }

    /// Whether trunk `i` was lost: a binary search.
    fn contains(&self, i: usize) -> bool {
        self.trunks.binary_search(&i).is_ok()
    }
}

/// Work a repair did: what its tests bound, whatever the erase list.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
struct Work {
    /// Trunks looked up in the erase set.
    lookups: usize,
    /// Blocks whose lost data trunks were rebuilt, or tried.
    rebuilds: usize,
}

/// What a block's repair gives: the lost data trunks rebuilt (trunk, its bytes, zero-padded to a
/// whole trunk), and those still lost.
type Rebuilt = (Vec<(usize, Vec<u8>)>, Vec<usize>);

/// A stream as received, and the state of its repair.
struct Received<'a> {
    /// Every byte received (a lost trunk's bytes are ignored).
    stream: &'a [u8],
    /// Trunk size in bytes, at least 1.
    trunk_bytes: usize,
    /// The trunks that never arrived.
    erased: Erased,
    /// The parts of the code shared by its blocks.
    codes: erasure::Codes,
    /// Work done so far.
    work: Work,
}

impl<'a> Received<'a> {
    /// `stream` as received in trunks of `trunk_bytes` (0 counts as 1), the trunks `lost` lost.
    fn new(stream: &'a [u8], trunk_bytes: usize, lost: &[usize]) -> Received<'a> {
        let trunk_bytes = trunk_bytes.max(1);
        Received {
            stream,
            trunk_bytes,
            erased: Erased::new(lost, stream.len().div_ceil(trunk_bytes)),
            codes: erasure::Codes::default(),
            work: Work::default(),
        }
    }

    /// [`repair`].
    fn repair(&mut self) -> Repaired {
        let t = self.trunk_bytes;
        // The header as received, when none of its bytes were lost: its word counts.
        if let Ok(header) = super::header::Header::read(self.stream)
            && self
                .erased
                .trunks
                .first()
                .is_none_or(|&i| i * t >= header.len())
        {
            match header.fec {
                Some(fec) if fec.trunk_bytes == t => return self.repair_with(fec),
                None => return self.plain(),
                // Stated for other trunks: search as if the header were lost.
                Some(_) => {}
            }
        }
        match self.find_layout() {
            Some(fec) => self.repair_with(fec),
            None => self.plain(),
        }
    }

    /// The stream as it is, with the lost trunks' ranges.
    fn plain(&self) -> Repaired {
        let (t, len) = (self.trunk_bytes, self.stream.len());
        Repaired {
            data: self.stream.to_vec(),
            lost: (self.erased.trunks.iter())
                .map(|&i| i * t..((i + 1) * t).min(len))
                .collect(),
            fec: None,
        }
    }

    /// Whether trunk `i` was lost.
    fn erased(&mut self, i: usize) -> bool {
        self.work.lookups += 1;
        self.erased.contains(i)
    }

    /// Whether trunk `i` of layout `fec` arrived whole.
    fn arrived(&mut self, fec: Fec, i: usize) -> bool {
        !self.erased(i) && fec.trunk_range(i).end <= self.stream.len()
    }

    /// Rebuilds the lost data trunks of block `b` of layout `fec` when the parity that arrived
    /// is enough.
    fn rebuild(&mut self, fec: Fec, b: usize) -> Rebuilt {
        let (data, parity) = fec.block_trunks(b);
        let arrived: Vec<bool> = (data.iter().chain(&parity))
            .map(|&i| self.arrived(fec, i))
            .collect();
        let missing: Vec<usize> = (data.iter().zip(&arrived))
            .filter(|&(_, &a)| !a)
            .map(|(&i, _)| i)
            .collect();
        if missing.is_empty() {
            return (Vec::new(), missing);
        }
        self.work.rebuilds += 1;
        let stream = self.stream;
        let shards: Vec<Option<&[u8]>> = (data.iter().chain(&parity).zip(&arrived))
            .map(|(&i, &a)| a.then(|| &stream[fec.trunk_range(i)]))
            .collect();
        let rebuilt: Vec<(usize, Vec<u8>)> = (self.codes)
            .rebuild(&shards, data.len(), fec.trunk_bytes)
            .into_iter()
            .map(|(c, bytes)| (data[c], bytes))
            .collect();
        // All lost data trunks come back, or none.
        if rebuilt.is_empty() {
            (rebuilt, missing)
        } else {
            (rebuilt, Vec::new())
        }
    }

    /// Repairs every block of layout `fec`.
    fn repair_with(&mut self, fec: Fec) -> Repaired {
        let stream = self.stream;
        let mut data = stream.get(..fec.data_bytes).unwrap_or(stream).to_vec();
        data.resize(fec.data_bytes, 0);
        let mut missing = Vec::new();
        for b in 0..fec.blocks() {
            let (rebuilt, still) = self.rebuild(fec, b);
            for (i, shard) in rebuilt {
                let range = fec.trunk_range(i);
                let len = range.len();
                data[range].copy_from_slice(&shard[..len]);
            }
            missing.extend(still);
        }
        missing.sort_unstable();
        let mut lost = Vec::with_capacity(missing.len());
        for i in missing {
            let r = fec.trunk_range(i);
            // A trunk cut short by the end of the stream (not lost) keeps the bytes it has.
            let r = if self.erased(i) {
                r
            } else {
                r.start.max(stream.len()).min(r.end)..r.end
            };
            if !r.is_empty() {
                lost.push(r);
            }
        }
        Repaired {
            data,
            lost,
            fec: Some(fec),
        }
    }

    /// The header was lost: tries each layout the encoder's rule can give at this length, and
    /// returns the code of the first whose header, read back through that layout, states it.
    fn find_layout(&mut self) -> Option<Fec> {
        let t = self.trunk_bytes;
        let total_trunks = self.stream.len().div_ceil(t);
        let mut tried = Vec::new();
        for percent in 1..=MAX_PERCENT {
            let parity = parity_trunks(total_trunks, percent);
            if tried.contains(&parity) || parity >= total_trunks || parity > MAX_PARITY_TRUNKS {
                continue;
            }
            tried.push(parity);
            // The protected length is unknown: its padding is zeros, so take the whole trunks.
            let guess = Fec {
                trunk_bytes: t,
                data_bytes: (total_trunks - parity) * t,
                parity_trunks: parity,
            };
            if let Some(fec) = self.header_code(guess)
                && fec.trunk_bytes == t
                && fec.parity_trunks == parity
                && fec.data_trunks() == guess.data_trunks()
            {
                return Some(fec);
            }
        }
        None
    }

    /// The code the header states, read through layout `guess` one data trunk at a time, each
    /// as received or rebuilt: a block is rebuilt only when the header reaches into one of its
    /// lost trunks, and the reading stops at the first byte no header has, or at a lost trunk
    /// its block does not bring back.
    fn header_code(&mut self, guess: Fec) -> Option<Fec> {
        let header_trunks = HEADER_TRUNK_BYTES.div_ceil(self.trunk_bytes);
        let mut head = Vec::with_capacity(HEADER_TRUNK_BYTES + self.trunk_bytes);
        let mut rebuilt: Vec<(usize, Vec<u8>)> = Vec::new();
        let mut blocks_tried = Vec::new();
        for i in 0..guess.data_trunks().min(header_trunks) {
            let range = guess.trunk_range(i);
            if self.arrived(guess, i) {
                head.extend_from_slice(&self.stream[range]);
            } else {
                let b = i % guess.blocks();
                if !blocks_tried.contains(&b) {
                    blocks_tried.push(b);
                    rebuilt.extend(self.rebuild(guess, b).0);
                }
                let (_, bytes) = rebuilt.iter().find(|(j, _)| *j == i)?;
                head.extend_from_slice(&bytes[..range.len()]);
            }
            match super::header::Header::read(&head) {
                Ok(header) => return header.fec,
                Err(Error::Truncated { .. }) => {}
                Err(_) => return None,
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{EncodeOptions, FecOptions, decode, decode_trunks, decode_with_loss, encode};

    /// A little seeded generator (xorshift), so that the loss patterns are the same every run.
    pub(super) fn rng(mut state: u64) -> impl FnMut() -> u64 {
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        }
    }

    fn stream(bytes: usize, percent: u32, channels: usize) -> Vec<u8> {
        stream_in(bytes, percent, 39, channels)
    }

    /// A stream of the synthetic picture with `percent` parity in trunks of `trunk_bytes`.
    fn stream_in(bytes: usize, percent: u32, trunk_bytes: usize, channels: usize) -> Vec<u8> {
        let img = crate::tests::synthetic(160, 120, channels);
        let options = EncodeOptions {
            bytes,
            fec: Some(FecOptions {
                percent,
                trunk_bytes,
            }),
            ..EncodeOptions::default()
        };
        encode(&img, &options).unwrap()
    }

    #[test]
    fn parity_count_rule() {
        assert_eq!(parity_trunks(51, 15), 8);
        assert_eq!(parity_trunks(51, 10), 5);
        assert_eq!(parity_trunks(3, 1), 1);
        assert_eq!(parity_trunks(0, 50), 1);
        assert_eq!(parity_trunks(usize::MAX, 50), usize::MAX / 100);
    }

    #[test]
    fn a_stream_with_parity_is_whole_trunks_within_the_budget_and_decodes_plainly() {
        for (bytes, percent) in [(2000, 15), (2000, 1), (700, 50), (4100, 10)] {
            let s = stream(bytes, percent, 3);
            let header = crate::Header::read(&s).unwrap();
            let fec = header.fec.unwrap();
            assert_eq!(s[0], 0xd5);
            assert_eq!(s.len() % 39, 0, "{bytes} {percent}");
            assert!(s.len() <= bytes && s.len() + 39 > bytes, "{}", s.len());
            assert_eq!(fec.total_bytes(), s.len());
            assert_eq!(fec.parity_trunks, parity_trunks(s.len() / 39, percent));
            // A prefix is a plain prefix: the parity is never read as payload.
            let whole = decode(&s).unwrap();
            assert_eq!(decode(&s[..fec.data_bytes]).unwrap(), whole);
            for cut in (0..s.len()).step_by(83) {
                let _ = decode(&s[..cut]);
            }
        }
    }

    #[test]
    fn any_lost_trunks_up_to_the_parity_come_back_the_header_too() {
        let s = stream(2000, 15, 3);
        let fec = crate::Header::read(&s).unwrap().fec.unwrap();
        let n = s.len() / 39;
        let whole = decode(&s).unwrap();
        let mut next = rng(7);
        for round in 0..20 {
            let count = 1 + round % fec.parity_trunks;
            let mut lost: Vec<usize> = Vec::new();
            while lost.len() < count {
                let i = (next() % n as u64) as usize;
                if !lost.contains(&i) {
                    lost.push(i);
                }
            }
            if round % 5 == 0 && !lost.contains(&0) {
                lost[0] = 0;
            }
            // What the lost trunks held does not matter.
            let mut received = s.clone();
            for &i in &lost {
                received[i * 39..(i + 1) * 39].fill(0xa5);
            }
            let repaired = repair(&received, 39, &lost);
            assert!(repaired.lost.is_empty(), "{lost:?}");
            assert_eq!(repaired.whole().unwrap(), s, "{lost:?}");
            assert_eq!(decode_trunks(&received, 39, &lost).unwrap(), whole);
        }
    }

    #[test]
    fn beyond_the_parity_the_prefix_before_the_first_gap_decodes() {
        let s = stream(2000, 10, 1);
        let fec = crate::Header::read(&s).unwrap().fec.unwrap();
        let lost: Vec<usize> = (20..20 + fec.parity_trunks + 1).collect();
        let repaired = repair(&s, 39, &lost);
        assert_eq!(repaired.lost.first().map(|r| r.start), Some(20 * 39));
        assert_eq!(
            decode_trunks(&s, 39, &lost).unwrap(),
            decode(&s[..20 * 39]).unwrap()
        );
        // The header lost with too many others: nothing decodes, said so.
        let mut lost = lost;
        lost.push(0);
        assert_eq!(
            decode_trunks(&s, 39, &lost),
            Err(Error::HeaderLost { trunk: 39 })
        );
        // A stream without parity: as decode_with_loss.
        let plain = encode(
            &crate::tests::synthetic(160, 120, 1),
            &EncodeOptions {
                bytes: 2000,
                ..EncodeOptions::default()
            },
        )
        .unwrap();
        assert_eq!(
            decode_trunks(&plain, 39, &[9, 30]).unwrap(),
            decode_with_loss(&plain, std::slice::from_ref(&(9 * 39..10 * 39))).unwrap()
        );
        assert_eq!(
            decode_trunks(&plain, 39, &[0]),
            Err(Error::HeaderLost { trunk: 39 })
        );
    }

    #[test]
    fn a_long_stream_is_interleaved_blocks_each_recovering_its_own() {
        let img = crate::tests::synthetic(320, 240, 3);
        let s = encode(
            &img,
            &EncodeOptions {
                bytes: 39 * 600,
                levels: None,
                fec: Some(FecOptions {
                    percent: 5,
                    trunk_bytes: 39,
                }),
                ..EncodeOptions::default()
            },
        )
        .unwrap();
        let fec = crate::Header::read(&s).unwrap().fec.unwrap();
        assert_eq!(fec.blocks(), 3);
        // Every block loses as many trunks as it has parity (10 each), the header among them.
        let lost: Vec<usize> = (0..30).map(|i| i * 19).collect();
        let repaired = repair(&s, 39, &lost);
        assert!(repaired.lost.is_empty());
        assert_eq!(repaired.whole().unwrap(), s);
    }

    #[test]
    fn repair_takes_any_bytes() {
        let mut next = rng(99);
        for len in [0, 1, 5, 38, 39, 40, 200, 700] {
            for _ in 0..4 {
                let mut bytes: Vec<u8> = (0..len).map(|_| next() as u8).collect();
                if len > 0 && next().is_multiple_of(2) {
                    bytes[0] = 0xd5;
                }
                let lost: Vec<usize> = (0..next() % 6).map(|_| (next() % 80) as usize).collect();
                // One-byte trunks only on short inputs: a search through layouts of thousands of
                // trunks is slow without optimisation.
                for trunk in [1, 16, 39, 255].into_iter().filter(|&t| t > 1 || len <= 40) {
                    // (Decoding such bytes is the decoder's tests' and fuzz target's: a random
                    // header can claim a picture of 4096 x 4096.)
                    let r = repair(&bytes, trunk, &lost);
                    assert!(r.data.len() <= bytes.len().max(r.fec.map_or(0, |f| f.data_bytes)));
                    let _ = r.whole();
                }
            }
        }
    }

    #[test]
    fn an_erase_list_is_a_set_of_the_stream_s_trunks() {
        let erased = Erased::new(&[7, 3, 3, 0, 7, 10, 100, usize::MAX], 10);
        assert_eq!(erased.trunks, [0, 3, 7]);
        assert!(erased.contains(0) && erased.contains(7));
        assert!(!erased.contains(4) && !erased.contains(10) && !erased.contains(usize::MAX));
        assert_eq!(Erased::new(&vec![0; 64_000], 5).trunks, [0]);
        assert!(Erased::new(&[5, 6], 5).trunks.is_empty());
        // Repeats and trunks past the end change nothing, with or without the header.
        let s = stream(2000, 15, 3);
        let far = s.len() / 39;
        for (lost, same) in [
            (vec![9, 9, 30, far, usize::MAX, 30], vec![9, 30]),
            (vec![0, 0, 0, 9, far + 1, 9], vec![0, 9]),
        ] {
            assert_eq!(repair(&s, 39, &lost), repair(&s, 39, &same));
        }
    }

    /// Issue 48: a search for the layout of a stream whose header trunk was lost looked every
    /// trunk up in the erase list in each of its 50 guesses and rebuilt every block of each
    /// (131,070 random bytes, `--trunk-size 1 --erase 0,...,79`: 105 s). The work now has a
    /// bound that depends on neither the stream's length nor the list's.
    #[test]
    fn the_layout_search_does_bounded_work_whatever_the_erase_list() {
        let mut next = rng(48);
        let noise: Vec<u8> = (0..131_070).map(|_| next() as u8).collect();
        let first_80: Vec<usize> = (0..80).collect();
        let zero_once = [0];
        let zeros = vec![0; 64_000];
        // Per guess: each header trunk looked up, each of its blocks (at most one a header
        // trunk) rebuilt from at most BLOCK_TRUNKS + 2 trunks.
        let most = |trunk: usize| {
            let header_trunks = HEADER_TRUNK_BYTES.div_ceil(trunk);
            let lookups = MAX_PERCENT as usize * header_trunks * (1 + BLOCK_TRUNKS + 2);
            (lookups, MAX_PERCENT as usize * header_trunks)
        };
        let mut work = Vec::new();
        for lost in [&first_80[..], &zero_once, &zeros] {
            let mut received = Received::new(&noise, 1, lost);
            assert_eq!(received.find_layout(), None);
            let (lookups, rebuilds) = most(1);
            assert!(received.work.lookups <= lookups, "{:?}", received.work);
            assert!(received.work.rebuilds <= rebuilds, "{:?}", received.work);
            work.push(received.work);
            assert_eq!(
                decode_trunks(&noise, 1, lost),
                Err(Error::HeaderLost { trunk: 1 })
            );
        }
        // A list of 64,000 repeats does the work of the one trunk it names.
        assert_eq!(work[1], work[2]);
        // A real stream with its header lost among others: the search, then each trunk once.
        let s = stream(2000, 15, 3);
        let trunks = s.len() / 39;
        let lost: Vec<usize> = [0, 5, 17].iter().copied().cycle().take(64_000).collect();
        let mut received = Received::new(&s, 39, &lost);
        let repaired = received.repair();
        assert_eq!(
            Some(repaired.data.len()),
            repaired.fec.map(|f| f.data_bytes)
        );
        assert!(repaired.lost.is_empty());
        let (lookups, rebuilds) = most(39);
        assert!(
            received.work.lookups <= lookups + 2 * trunks,
            "{:?}",
            received.work
        );
        assert!(
            received.work.rebuilds <= rebuilds + 1,
            "{:?}",
            received.work
        );
    }

    #[test]
    fn a_header_over_trunks_of_several_blocks_comes_back() {
        // One-byte trunks: the header's 12 bytes are trunks 0 to 11, dealt to 2 blocks in turn.
        let s = stream_in(300, 10, 1, 3);
        let header = crate::Header::read(&s).unwrap();
        let fec = header.fec.unwrap();
        assert_eq!((fec.blocks(), header.len()), (2, 12));
        let lost: Vec<usize> = (0..12).chain([100, 201, 299]).collect();
        let mut received = s.clone();
        for &i in &lost {
            received[i] = !received[i];
        }
        let mut r = Received::new(&received, 1, &lost);
        let repaired = r.repair();
        assert_eq!((repaired.fec, &repaired.lost[..]), (Some(fec), &[][..]));
        assert_eq!(repaired.data, s[..fec.data_bytes]);
        // At most the header's two blocks a guess, then each block once more.
        assert!(
            r.work.rebuilds <= MAX_PERCENT as usize * 2 + 2,
            "{:?}",
            r.work
        );
    }

    /// The crate's codes by their data and parity shard counts.
    type Codes48 =
        std::cell::RefCell<std::collections::HashMap<(usize, usize), Option<ReedSolomon>>>;

    /// The repair as it was before issue 48: the erase list searched trunk by trunk, every block
    /// of a guessed layout rebuilt by the crate's own decoder and the header read from the whole
    /// stream. What the bounded repair must agree with.
    /// (`codes` keeps the crate's codes by shape from call to call, as its decoder keeps its
    /// inverted matrices: only for speed, the crate's matrix algebra being slow unoptimised.)
    fn repair_before_48(stream: &[u8], t: usize, lost: &[usize], codes: &Codes48) -> Repaired {
        let len = stream.len();
        let arrived = |fec: &Fec, i: usize| !lost.contains(&i) && fec.trunk_range(i).end <= len;
        let rebuild = |fec: &Fec, blocks: usize| {
            let mut data = stream.get(..fec.data_bytes).unwrap_or(stream).to_vec();
            data.resize(fec.data_bytes, 0);
            let mut missing: Vec<usize> = (0..fec.data_trunks())
                .filter(|&i| !arrived(fec, i))
                .collect();
            for b in 0..fec.blocks().min(blocks) {
                let (d, p) = fec.block_trunks(b);
                let mut shards: Vec<Option<Vec<u8>>> = (d.iter().chain(&p))
                    .map(|&i| arrived(fec, i).then(|| stream[fec.trunk_range(i)].to_vec()))
                    .map(|s| s.map(|mut s| (s.resize(t, 0), s).1))
                    .collect();
                let mut codes = codes.borrow_mut();
                let code = (codes.entry((d.len(), p.len())))
                    .or_insert_with(|| ReedSolomon::new(d.len(), p.len()).ok());
                if code
                    .as_ref()
                    .is_some_and(|rs| rs.reconstruct_data(&mut shards).is_ok())
                {
                    for (&i, shard) in d.iter().zip(&shards) {
                        if arrived(fec, i) {
                            continue;
                        }
                        let r = fec.trunk_range(i);
                        let n = r.len();
                        data[r].copy_from_slice(&shard.as_ref().unwrap()[..n]);
                        missing.retain(|&m| m != i);
                    }
                }
            }
            let lost = (missing.iter())
                .map(|&i| (i, fec.trunk_range(i)))
                .map(|(i, r)| match lost.contains(&i) {
                    true => r,
                    false => r.start.max(len).min(r.end)..r.end,
                })
                .filter(|r| !r.is_empty())
                .collect();
            Repaired {
                data,
                lost,
                fec: Some(*fec),
            }
        };
        let mut ranges: Vec<Range<usize>> = (lost.iter())
            .map(|&i| i.saturating_mul(t).min(len)..i.saturating_mul(t).saturating_add(t).min(len))
            .filter(|r| !r.is_empty())
            .collect();
        ranges.sort_by_key(|r| r.start);
        let plain = Repaired {
            data: stream.to_vec(),
            lost: ranges,
            fec: None,
        };
        if let Ok(h) = crate::Header::read(stream)
            && plain.lost.iter().all(|r| r.start >= h.len())
        {
            match h.fec {
                Some(fec) if fec.trunk_bytes == t => return rebuild(&fec, usize::MAX),
                None => return plain,
                Some(_) => {}
            }
        }
        let n = len.div_ceil(t);
        for parity in (1..=MAX_PERCENT).map(|p| parity_trunks(n, p)) {
            if parity >= n || parity > MAX_PARITY_TRUNKS {
                continue;
            }
            let guess = Fec {
                trunk_bytes: t,
                data_bytes: (n - parity) * t,
                parity_trunks: parity,
            };
            let r = rebuild(&guess, HEADER_TRUNK_BYTES.div_ceil(t));
            if let Ok(h) = crate::Header::read(&r.data)
                && let Some(fec) = h.fec
                && (fec.trunk_bytes, fec.parity_trunks) == (t, parity)
                && fec.data_trunks() == guess.data_trunks()
                && r.lost.iter().all(|x| x.start >= h.len())
            {
                return rebuild(&fec, usize::MAX);
            }
        }
        plain
    }

    #[test]
    fn the_bounded_repair_is_the_repair_before_48_on_any_bytes_and_losses() {
        let mut next = rng(4848);
        // The reference rebuilds with the crate's matrix inversion, unoptimised in tests: small
        // blocks only. Each stream in its own trunks (8 bytes: the header takes two or three),
        // and in others.
        let streams = [
            (stream(2000, 15, 3), 39, &[39][..]),
            (stream(2000, 50, 1), 39, &[39]),
            (stream(700, 50, 3), 39, &[39, 16]),
            (stream_in(400, 30, 8, 3), 8, &[8]),
        ];
        let codes = Codes48::default();
        let mut found = [0; 2];
        for round in 0..120 {
            let (s, trunk, trunk_sizes) = &streams[round % streams.len()];
            let (mut s, trunk) = (s.clone(), *trunk);
            let n = s.len().div_ceil(trunk);
            let mut lost: Vec<usize> = Vec::new();
            for _ in 0..next() % 14 {
                let i = (next() % (n as u64 + 3)) as usize;
                if !lost.contains(&i) {
                    lost.push(i);
                }
            }
            let pattern = round / streams.len();
            if pattern % 2 == 0 && !lost.contains(&0) {
                lost.push(0);
            }
            // What a lost trunk held is anything; some rounds also corrupt a byte that
            // arrived (parity that disagrees with the data), or cut the stream short.
            for &i in &lost {
                for b in s.iter_mut().skip(i * trunk).take(trunk) {
                    *b = next() as u8;
                }
            }
            match pattern % 10 {
                1 | 6 => {
                    let at = (next() % s.len() as u64) as usize;
                    s[at] ^= 1 + (next() % 255) as u8;
                }
                3 => s.truncate(s.len() - (next() % 100) as usize),
                9 => s.iter_mut().skip(1).for_each(|b| *b = next() as u8),
                _ => {}
            }
            for &t in *trunk_sizes {
                let repaired = repair(&s, t, &lost);
                assert_eq!(
                    repaired,
                    repair_before_48(&s, t, &lost, &codes),
                    "round {round}, {t}-byte trunks, lost {lost:?}"
                );
                if lost.contains(&0) && repaired.fec.is_some() {
                    found[usize::from(t == 8)] += 1;
                }
            }
        }
        // The search found the layout without the header, in one trunk and in two.
        assert!(found.iter().all(|&f| f >= 10), "{found:?}");
    }
}
