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
pub fn repair(stream: &[u8], trunk_bytes: usize, lost: &[usize]) -> Repaired {
    let trunk_bytes = trunk_bytes.max(1);
    let lost_ranges = |len: usize| -> Vec<Range<usize>> {
        let mut ranges: Vec<Range<usize>> = lost
            .iter()
            .map(|&i| {
                let start = i.saturating_mul(trunk_bytes).min(len);
                start..start.saturating_add(trunk_bytes).min(len)
            })
            .filter(|r| !r.is_empty())
            .collect();
        ranges.sort_by_key(|r| r.start);
        ranges
    };
    let plain = || Repaired {
        data: stream.to_vec(),
        lost: lost_ranges(stream.len()),
        fec: None,
    };
    // The header as received, when none of its bytes were lost: its word counts.
    if let Ok(header) = super::header::Header::read(stream)
        && lost_ranges(stream.len())
            .iter()
            .all(|r| r.start >= header.len())
    {
        match header.fec {
            Some(fec) if fec.trunk_bytes == trunk_bytes => return repair_with(stream, fec, lost),
            None => return plain(),
            // Stated for other trunks: search as if the header were lost.
            Some(_) => {}
        }
    }
    // The header was lost: try each layout the encoder's rule can give at this length.
    let total_trunks = stream.len().div_ceil(trunk_bytes);
    let mut tried = Vec::new();
    for percent in 1..=MAX_PERCENT {
        let parity = parity_trunks(total_trunks, percent);
        if tried.contains(&parity) || parity >= total_trunks || parity > MAX_PARITY_TRUNKS {
            continue;
        }
        tried.push(parity);
        // The protected length is unknown: its padding is zeros, so take the whole trunks.
        let guess = Fec {
            trunk_bytes,
            data_bytes: (total_trunks - parity) * trunk_bytes,
            parity_trunks: parity,
        };
        let repaired = repair_blocks(
            stream,
            guess,
            lost,
            HEADER_TRUNK_BYTES.div_ceil(trunk_bytes),
        );
        let Ok(header) = super::header::Header::read(&repaired.data) else {
            continue;
        };
        let Some(fec) = header.fec else {
            continue;
        };
        let same = fec.trunk_bytes == trunk_bytes
            && fec.parity_trunks == parity
            && fec.data_trunks() == guess.data_trunks()
            && repaired.lost.iter().all(|r| r.start >= header.len());
        if same {
            return repair_with(stream, fec, lost);
        }
    }
    plain()
}

/// The longest header a stream with parity can have (ROI, features, the most multipliers,
/// the code), rounded up: the bytes a search for the layout must recover.
const HEADER_TRUNK_BYTES: usize = 80;

/// [`repair`] with the layout known.
fn repair_with(stream: &[u8], fec: Fec, lost: &[usize]) -> Repaired {
    repair_blocks(stream, fec, lost, usize::MAX)
}

/// [`repair_with`] of only the blocks that hold one of the first `first_trunks` data trunks.
fn repair_blocks(stream: &[u8], fec: Fec, lost: &[usize], first_trunks: usize) -> Repaired {
    let t = fec.trunk_bytes;
    let k = fec.data_trunks();
    let arrived = |i: usize| !lost.contains(&i) && fec.trunk_range(i).end <= stream.len();
    let mut data = stream.get(..fec.data_bytes).unwrap_or(stream).to_vec();
    data.resize(fec.data_bytes, 0);
    let mut missing: Vec<usize> = (0..k).filter(|&i| !arrived(i)).collect();
    for b in 0..fec.blocks().min(first_trunks) {
        let (data_trunks, parity) = fec.block_trunks(b);
        let lost_here = data_trunks.iter().filter(|&&i| !arrived(i)).count();
        let parity_here = parity.iter().filter(|&&i| arrived(i)).count();
        if lost_here == 0 || lost_here > parity_here {
            continue;
        }
        let Ok(rs) = ReedSolomon::new(data_trunks.len(), parity.len()) else {
            continue;
        };
        let mut shards: Vec<Option<Vec<u8>>> = data_trunks
            .iter()
            .chain(&parity)
            .map(|&i| {
                arrived(i).then(|| {
                    let mut shard = stream[fec.trunk_range(i)].to_vec();
                    shard.resize(t, 0);
                    shard
                })
            })
            .collect();
        if rs.reconstruct_data(&mut shards).is_err() {
            continue;
        }
        for (&i, shard) in data_trunks.iter().zip(&shards) {
            if let Some(shard) = shard.as_ref().filter(|_| !arrived(i)) {
                let range = fec.trunk_range(i);
                let len = range.len();
                data[range].copy_from_slice(&shard[..len]);
                missing.retain(|&m| m != i);
            }
        }
    }
    Repaired {
        // A trunk cut short by the end of the stream (not lost) keeps the bytes it has.
        lost: missing
            .iter()
            .map(|&i| {
                let r = fec.trunk_range(i);
                if lost.contains(&i) {
                    r
                } else {
                    r.start.max(stream.len()).min(r.end)..r.end
                }
            })
            .filter(|r| !r.is_empty())
            .collect(),
        data,
        fec: Some(fec),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{EncodeOptions, FecOptions, decode, decode_trunks, decode_with_loss, encode};

    /// A little seeded generator (xorshift), so that the loss patterns are the same every run.
    fn rng(mut state: u64) -> impl FnMut() -> u64 {
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        }
    }

    fn stream(bytes: usize, percent: u32, channels: usize) -> Vec<u8> {
        let img = crate::tests::synthetic(160, 120, channels);
        let options = EncodeOptions {
            bytes,
            fec: Some(FecOptions {
                percent,
                trunk_bytes: 39,
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
}
