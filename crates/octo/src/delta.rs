//! The map-delta stream: after each scan, what changed, fine and coloured inside the operator's
//! region of interest, coarse and colourless outside it (the second paper's scheme).
//!
//! The sender ([`Sender`]) turns a scan's [`Change`]s into a [`Delta`] of four lists: newly
//! occupied and newly free voxels at full resolution inside the ROI (occupied ones with their
//! colour), and newly occupied and newly free voxels at the coarse depth outside it. A coarse
//! voxel's state is its octree node's (occupied when any voxel in it is, OctoMap's inner-node
//! rule); it is sent when it differs from what the sender last sent for it. The ROI is widened
//! to whole coarse voxels, so the receiver's view never mixes resolutions inside one coarse
//! voxel. The receiver ([`Receiver`]) applies messages to its view, an octree of
//! maximum-likelihood leaves, which it can write as a `.ot` file.
//!
//! Byte layout (all integers little-endian; `docs/octo-delta-format.md` is the reference):
//! a stream header, then messages, each with a CRC-32 so a damaged message is detected. Voxel
//! lists are coded as the tree of their paths: for every node above the list's depth that
//! contains a voxel of the list, one byte whose bit i says child i does, in pre-order. Dense
//! sets cost a fraction of a byte per voxel.
//!
//! Decoding never panics on any input; errors name the offset and what was expected, and
//! allocation is bounded by the input (every coded node costs at least one byte).

use std::collections::{HashMap, HashSet};

use super::ParseError;
use super::tree::{Change, OcTree, Params, TREE_DEPTH, unmorton};

/// Stream magic.
pub const MAGIC: &[u8; 4] = b"ODL1";
/// Format version.
pub const VERSION: u8 = 1;
/// Message kind: the changes of one scan.
pub const KIND_DELTA: u8 = 1;
/// Message kind: the whole view, replacing the receiver's.
pub const KIND_FULL: u8 = 2;

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// An axis-aligned box in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Roi {
    /// Lower corner x, y, z.
    pub min_m: [f64; 3],
    /// Upper corner x, y, z.
    pub max_m: [f64; 3],
}

/// What the operator sees: resolution, coarse depth and region of interest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSpec {
    /// Voxel edge at full resolution, metres.
    pub resolution_m: f64,
    /// Depth of coarse voxels (1..=16; 16 - k means voxels 2^k times the fine edge).
    pub coarse_depth: u32,
    /// The region sent at full resolution with colour; `None`: everywhere.
    pub roi: Option<Roi>,
}

impl ViewSpec {
    /// Whether the coarse voxel with Morton code `coarse` (at `coarse_depth`) meets the ROI.
    pub fn coarse_in_roi(&self, coarse: u64) -> bool {
        let Some(roi) = self.roi else { return true };
        let shift = TREE_DEPTH - self.coarse_depth;
        let k = unmorton(coarse << (3 * shift));
        let edge = self.resolution_m * (1u64 << shift) as f64;
        (0..3).all(|i| {
            let lo = (k[i] as i64 - 32768) as f64 * self.resolution_m;
            lo <= roi.max_m[i] && lo + edge >= roi.min_m[i]
        })
    }

    /// Bits a depth-16 Morton code is shifted right to give its coarse voxel's code.
    pub fn coarse_shift(&self) -> u32 {
        3 * (TREE_DEPTH - self.coarse_depth)
    }

    /// The key of the first fine voxel of a coarse voxel (code at `coarse_depth`).
    pub fn coarse_key(&self, coarse: u64) -> super::tree::Key {
        unmorton(coarse << self.coarse_shift())
    }
}

/// The changes of one scan, as four lists (codes are Morton codes at their list's depth).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Delta {
    /// Newly occupied voxels at full resolution inside the ROI, with colour.
    pub fine_occupied: Vec<(u64, Option<[u8; 3]>)>,
    /// Newly free voxels at full resolution inside the ROI.
    pub fine_free: Vec<u64>,
    /// Newly occupied coarse voxels outside the ROI.
    pub coarse_occupied: Vec<u64>,
    /// Newly free coarse voxels outside the ROI.
    pub coarse_free: Vec<u64>,
}

impl Delta {
    /// Total voxels in the four lists.
    pub fn len(&self) -> usize {
        self.fine_occupied.len()
            + self.fine_free.len()
            + self.coarse_occupied.len()
            + self.coarse_free.len()
    }
    /// Whether nothing changed.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The vehicle side: turns each scan's changes into a [`Delta`].
#[derive(Debug, Clone)]
pub struct Sender {
    spec: ViewSpec,
    coarse_sent: HashMap<u64, bool>,
    color_updates: bool,
}

impl Sender {
    /// A sender for a view.
    pub fn new(spec: ViewSpec) -> Self {
        Sender {
            spec,
            coarse_sent: HashMap::new(),
            color_updates: false,
        }
    }

    /// Also resend an occupied fine voxel when a brighter colour was found for it (off by
    /// default: the paper sends a voxel's colour when its state changes).
    pub fn set_color_updates(&mut self, on: bool) {
        self.color_updates = on;
    }

    /// The view it sends.
    pub fn spec(&self) -> &ViewSpec {
        &self.spec
    }

    /// Sends a new region of interest from now on (same resolution and coarse depth); the
    /// caller sends the coarse voxels that change sides ([`region`](super::region)) and says
    /// what it sent for them with [`Sender::note_coarse`].
    pub fn set_roi(&mut self, roi: Option<Roi>) {
        self.spec.roi = roi;
    }

    /// Records what the receiver now has for a coarse voxel outside the ROI (`Some(occupied)`),
    /// or forgets it (`None`: the voxel is now inside the ROI, sent fine).
    pub fn note_coarse(&mut self, coarse: u64, occupied: Option<bool>) {
        match occupied {
            Some(occ) => self.coarse_sent.insert(coarse, occ),
            None => self.coarse_sent.remove(&coarse),
        };
    }

    /// The delta of one scan: `changes` from [`OcTree::insert_scan`] (in Morton order) on `tree`.
    pub fn delta(&mut self, tree: &OcTree, changes: &[Change]) -> Delta {
        // Room for the fine lists once (all of them when everything is inside the ROI).
        let occupied = changes.iter().filter(|c| c.occupied).count();
        let mut d = Delta {
            fine_occupied: Vec::with_capacity(occupied),
            fine_free: Vec::with_capacity(changes.len() - occupied),
            ..Delta::default()
        };
        let shift = self.spec.coarse_shift();
        let mut last_coarse = None;
        let mut last_in = true;
        for c in changes {
            if c.recolor && !self.color_updates {
                continue;
            }
            let coarse = c.code >> shift;
            if last_coarse != Some(coarse) {
                last_in = self.spec.coarse_in_roi(coarse);
                last_coarse = Some(coarse);
                if !last_in {
                    // The coarse voxel's state is its node's (or its pruned ancestor's).
                    let occ = tree
                        .search(c.code, self.spec.coarse_depth)
                        .is_some_and(|(n, _)| tree.node(n).log_odds >= 0.0);
                    if self.coarse_sent.insert(coarse, occ) != Some(occ) {
                        if occ {
                            d.coarse_occupied.push(coarse);
                        } else {
                            d.coarse_free.push(coarse);
                        }
                    }
                }
            }
            if last_in {
                if c.occupied {
                    d.fine_occupied.push((c.code, c.color));
                } else {
                    d.fine_free.push(c.code);
                }
            }
        }
        d
    }
}

/// Appends `v` as LEB128.
fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    loop {
        let b = (v & 0x7f) as u8;
        v >>= 7;
        if v == 0 {
            out.push(b);
            return;
        }
        out.push(b | 0x80);
    }
}

/// Codes a sorted, duplicate-free list of Morton codes at `depth` as the tree of their paths:
/// depth first, each node a byte of the child digits it has (the digits of a code at `depth`
/// are its `depth` groups of 3 bits, highest first), its children's subtrees after it.
///
/// One pass over the codes: a code shares its nodes with the one before down to the first
/// digit where they differ, where that node gets a child (its byte, already written, is
/// patched), and opens a new node at every level below, written at the end of the output.
/// Since the codes are sorted, every subtree is whole before the next one starts, so this is
/// the depth-first order.
pub fn encode_codes(codes: &[u64], depth: u32, out: &mut Vec<u8>) {
    put_varint(out, codes.len() as u64);
    let depth = depth.min(21) as usize;
    if codes.is_empty() || depth == 0 {
        return;
    }
    let bits = 3 * depth as u32;
    let digit = |c: u64, level: usize| 1u8 << ((c >> (3 * (depth - 1 - level))) & 7);
    // The output position of the open node at each level.
    let mut open = [0usize; 21];
    let mut prev: Option<u64> = None;
    for &c in codes {
        let first_new = match prev {
            None => 0,
            Some(p) => {
                let differ = (p ^ c) & (u64::MAX >> (64 - bits));
                if differ == 0 {
                    continue;
                }
                let shared = depth - 1 - (63 - differ.leading_zeros() as usize) / 3;
                out[open[shared]] |= digit(c, shared);
                shared + 1
            }
        };
        for (level, slot) in open.iter_mut().enumerate().take(depth).skip(first_new) {
            *slot = out.len();
            out.push(digit(c, level));
        }
        prev = Some(c);
    }
}

/// A cursor over untrusted bytes: every read is checked.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
    base: u64,
}

impl<'a> Cursor<'a> {
    fn err(&self, msg: impl Into<String>) -> ParseError {
        ParseError::new(self.base + self.pos as u64, msg)
    }
    fn u8(&mut self, what: &str) -> Result<u8, ParseError> {
        let b = *self
            .bytes
            .get(self.pos)
            .ok_or_else(|| self.err(format!("{what}: expected 1 byte, none left")))?;
        self.pos += 1;
        Ok(b)
    }
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ParseError> {
        if self.bytes.len() - self.pos < n {
            return Err(self.err(format!(
                "{what}: expected {n} bytes, {} left",
                self.bytes.len() - self.pos
            )));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn varint(&mut self, what: &str) -> Result<u64, ParseError> {
        let start = self.pos;
        let mut v = 0u64;
        for i in 0..10 {
            let b = self.u8(what)?;
            v |= ((b & 0x7f) as u64) << (7 * i);
            if b & 0x80 == 0 {
                if i > 0 && b == 0 {
                    self.pos = start;
                    return Err(self.err(format!("{what}: varint not in its shortest form")));
                }
                return Ok(v);
            }
        }
        self.pos = start;
        Err(self.err(format!("{what}: varint longer than 10 bytes")))
    }
    fn left(&self) -> usize {
        self.bytes.len() - self.pos
    }
}

fn decode_codes(cur: &mut Cursor, depth: u32, what: &str) -> Result<Vec<u64>, ParseError> {
    let count = cur.varint(&format!("{what} count"))?;
    if count == 0 {
        return Ok(Vec::new());
    }
    // Every voxel needs at least one path byte unless it shares it, and a byte covers at most
    // eight voxels: a count beyond 8 x the bytes left cannot be right.
    if depth == 0 || count > 8 * cur.left() as u64 {
        return Err(cur.err(format!(
            "{what} count {count}: more voxels than {} bytes can code",
            cur.left()
        )));
    }
    let mut codes = Vec::with_capacity(count as usize);
    decode_level(cur, 0, depth, 0, &mut codes, count as usize, what)?;
    if codes.len() as u64 != count {
        return Err(cur.err(format!(
            "{what}: count says {count} voxels, the path tree holds {}",
            codes.len()
        )));
    }
    Ok(codes)
}

fn decode_level(
    cur: &mut Cursor,
    level: u32,
    depth: u32,
    prefix: u64,
    out: &mut Vec<u64>,
    limit: usize,
    what: &str,
) -> Result<(), ParseError> {
    let at = cur.pos;
    let mask = cur.u8(&format!("{what} path byte at level {level}"))?;
    if mask == 0 {
        cur.pos = at;
        return Err(cur.err(format!("{what}: empty path byte at level {level}")));
    }
    for i in 0..8u64 {
        if mask & (1 << i) == 0 {
            continue;
        }
        let code = (prefix << 3) | i;
        if level + 1 == depth {
            if out.len() >= limit {
                return Err(cur.err(format!("{what}: more voxels than the count {limit}")));
            }
            out.push(code);
        } else {
            decode_level(cur, level + 1, depth, code, out, limit, what)?;
        }
    }
    Ok(())
}

/// The stream header.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamHeader {
    /// The view the stream carries.
    pub spec: ViewSpec,
}

/// Bytes of the stream header.
pub fn encode_header(spec: &ViewSpec) -> Vec<u8> {
    let mut out = Vec::with_capacity(64);
    out.extend_from_slice(MAGIC);
    out.push(VERSION);
    out.push(spec.roi.is_some() as u8);
    out.extend_from_slice(&spec.resolution_m.to_le_bytes());
    out.push(spec.coarse_depth as u8);
    if let Some(roi) = spec.roi {
        for v in roi.min_m.iter().chain(roi.max_m.iter()) {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// Reads the stream header; returns it and its length.
pub fn decode_header(bytes: &[u8]) -> Result<(StreamHeader, usize), ParseError> {
    let mut cur = Cursor {
        bytes,
        pos: 0,
        base: 0,
    };
    let magic = cur.take(4, "stream magic")?;
    if magic != MAGIC {
        return Err(ParseError::new(
            0,
            format!("stream magic: expected \"ODL1\", found {magic:02x?}"),
        ));
    }
    let version = cur.u8("version")?;
    if version != VERSION {
        return Err(ParseError::new(
            4,
            format!("version: expected {VERSION}, found {version}"),
        ));
    }
    let flags = cur.u8("flags")?;
    if flags & !1 != 0 {
        return Err(ParseError::new(
            5,
            format!("flags: unknown bits in {flags:#04x}"),
        ));
    }
    let res = f64::from_le_bytes(cur.take(8, "resolution")?.try_into().unwrap_or([0; 8]));
    if !(res.is_finite() && res > 0.0) {
        return Err(ParseError::new(
            6,
            format!("resolution: expected > 0 m, found {res}"),
        ));
    }
    let coarse = cur.u8("coarse depth")? as u32;
    if !(1..=TREE_DEPTH).contains(&coarse) {
        return Err(ParseError::new(
            14,
            format!("coarse depth: expected 1..=16, found {coarse}"),
        ));
    }
    let roi = if flags & 1 != 0 {
        let mut v = [0.0f64; 6];
        for x in &mut v {
            *x = f64::from_le_bytes(cur.take(8, "ROI corner")?.try_into().unwrap_or([0; 8]));
        }
        if v.iter().any(|x| !x.is_finite()) || (0..3).any(|i| v[i] > v[i + 3]) {
            return Err(ParseError::new(15, format!("ROI: not a box: {v:?}")));
        }
        Some(Roi {
            min_m: [v[0], v[1], v[2]],
            max_m: [v[3], v[4], v[5]],
        })
    } else {
        None
    };
    Ok((
        StreamHeader {
            spec: ViewSpec {
                resolution_m: res,
                coarse_depth: coarse,
                roi,
            },
        },
        cur.pos,
    ))
}

/// Frames a payload as a message of `kind` (kind, scan number, length, payload, CRC-32).
pub fn frame_message(kind: u8, scan: u32, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len() + 13);
    out.push(kind);
    out.extend_from_slice(&scan.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    out.extend_from_slice(payload);
    let crc = CRC32.checksum(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// A delta message's bytes (framing included).
pub fn encode_delta(spec: &ViewSpec, scan: u32, d: &Delta) -> Vec<u8> {
    let mut p = Vec::new();
    let fine: Vec<u64> = d.fine_occupied.iter().map(|e| e.0).collect();
    let colored = d.fine_occupied.iter().any(|e| e.1.is_some());
    p.push(colored as u8);
    encode_codes(&fine, TREE_DEPTH, &mut p);
    encode_codes(&d.fine_free, TREE_DEPTH, &mut p);
    encode_codes(&d.coarse_occupied, spec.coarse_depth, &mut p);
    encode_codes(&d.coarse_free, spec.coarse_depth, &mut p);
    if colored {
        let colors: Vec<[u8; 3]> = d
            .fine_occupied
            .iter()
            .map(|e| e.1.unwrap_or([255, 255, 255]))
            .collect();
        encode_colors(&colors, &mut p);
    }
    frame_message(KIND_DELTA, scan, &p)
}

/// Rice codes of a value (0..=255) with parameter `k`: the quotient in unary (capped at
/// [`RICE_ESCAPE`] ones, then the value in 8 plain bits), then `k` remainder bits.
const RICE_ESCAPE: u32 = 16;

fn zigzag(r: i16) -> u32 {
    ((r << 1) ^ (r >> 15)) as u16 as u32
}

fn unzigzag(v: u32) -> i16 {
    ((v >> 1) as i16) ^ -((v & 1) as i16)
}

/// Colour residuals: each channel minus the previous voxel's (the first voxel's from 128),
/// modulo 256, mapped to -128..=127 and zigzagged.
fn residuals(colors: &[[u8; 3]]) -> Vec<u32> {
    let mut prev = [128u8; 3];
    let mut out = Vec::with_capacity(colors.len() * 3);
    for c in colors {
        for ch in 0..3 {
            out.push(zigzag(c[ch].wrapping_sub(prev[ch]) as i8 as i16));
        }
        prev = *c;
    }
    out
}

/// The code parameter that means "plain 8-bit residuals" (noisy colours).
const RAW_K: u32 = 8;

fn rice_bits(v: u32, k: u32) -> u64 {
    if k == RAW_K {
        return 8;
    }
    let q = v >> k;
    if q < RICE_ESCAPE {
        (q + 1 + k) as u64
    } else {
        (RICE_ESCAPE + 8) as u64
    }
}

/// Colours as one byte `k` (0..=7, the Rice parameter that makes the codes shortest, or 8 for
/// plain 8-bit residuals when no Rice code beats them) and the bit stream of the residuals' codes,
/// MSB first, zero-padded to a byte.
fn encode_colors(colors: &[[u8; 3]], out: &mut Vec<u8>) {
    let res = residuals(colors);
    // Each parameter's cost from the residuals' histogram (a residual is 0..=255), not from
    // the residuals again for each of the nine.
    let mut histogram = [0u64; 256];
    for &v in &res {
        histogram[(v & 0xff) as usize] += 1;
    }
    let k = (0..=RAW_K)
        .min_by_key(|&k| {
            (0..256u32)
                .map(|v| histogram[v as usize] * rice_bits(v, k))
                .sum::<u64>()
        })
        .unwrap_or(0);
    out.push(k as u8);
    let (mut acc, mut n) = (0u64, 0u32);
    let mut put = |bits: u64, count: u32, out: &mut Vec<u8>| {
        acc = (acc << count) | bits;
        n += count;
        while n >= 8 {
            out.push((acc >> (n - 8)) as u8);
            n -= 8;
        }
        acc &= (1u64 << n) - 1;
    };
    for v in res {
        let q = v >> k.min(7);
        if k == RAW_K {
            put(v as u64, 8, out);
        } else if q < RICE_ESCAPE {
            put(((1u64 << q) - 1) << 1, q + 1, out);
            put((v & ((1 << k) - 1)) as u64, k, out);
        } else {
            put((1u64 << RICE_ESCAPE) - 1, RICE_ESCAPE, out);
            put(v as u64, 8, out);
        }
    }
    if n > 0 {
        out.push((acc << (8 - n)) as u8);
    }
}

/// Reads `count` colours coded by [`encode_colors`].
fn decode_colors(cur: &mut Cursor, count: usize) -> Result<Vec<[u8; 3]>, ParseError> {
    let k = cur.u8("colour code parameter")? as u32;
    if k > RAW_K {
        return Err(cur.err(format!("colour code parameter: expected 0..=8, found {k}")));
    }
    // Every residual takes at least one bit: the colours cannot need fewer bytes than this.
    if count.saturating_mul(3) > cur.left().saturating_mul(8) {
        return Err(cur.err(format!(
            "colours of {count} voxels: more than {} bytes can code",
            cur.left()
        )));
    }
    let start = cur.pos;
    let bytes = &cur.bytes[start..];
    let mut bit = 0usize;
    let total = bytes.len() * 8;
    let mut read = |n: u32| -> Option<u32> {
        let mut v = 0u32;
        for _ in 0..n {
            if bit >= total {
                return None;
            }
            v = (v << 1) | ((bytes[bit / 8] >> (7 - bit % 8)) & 1) as u32;
            bit += 1;
        }
        Some(v)
    };
    let mut prev = [128u8; 3];
    let mut out = Vec::with_capacity(count);
    let base = cur.base + start as u64;
    let truncated = |_: &Cursor| {
        ParseError::new(
            base + bytes.len() as u64,
            format!("colours of {count} voxels: the bit stream ends early"),
        )
    };
    for _ in 0..count {
        let mut c = [0u8; 3];
        for ch in 0..3 {
            if k == RAW_K {
                let v = read(8).ok_or_else(|| truncated(cur))?;
                c[ch] = prev[ch].wrapping_add(unzigzag(v) as u8);
                continue;
            }
            let mut q = 0;
            while q < RICE_ESCAPE {
                match read(1) {
                    Some(1) => q += 1,
                    Some(_) => break,
                    None => return Err(truncated(cur)),
                }
            }
            let v = if q == RICE_ESCAPE {
                read(8).ok_or_else(|| truncated(cur))?
            } else {
                (q << k) | read(k).ok_or_else(|| truncated(cur))?
            };
            if v > 255 {
                return Err(ParseError::new(
                    base + (bit / 8) as u64,
                    format!("colour residual {v}: expected at most 255"),
                ));
            }
            c[ch] = prev[ch].wrapping_add(unzigzag(v) as u8);
        }
        prev = c;
        out.push(c);
    }
    if !bit.is_multiple_of(8) && bytes[bit / 8] & (0xff >> (bit % 8)) != 0 {
        return Err(ParseError::new(
            base + (bit / 8) as u64,
            "colours: padding bits after the last code are not zero",
        ));
    }
    cur.pos = start + bit.div_ceil(8);
    Ok(out)
}

/// A message of the stream.
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    /// The changes of one scan.
    Delta {
        /// Scan number.
        scan: u32,
        /// The lists.
        delta: Delta,
    },
    /// The whole view.
    Full {
        /// Scan number the view is after.
        scan: u32,
        /// The view's leaves: (depth-16 Morton code of the first voxel, depth, occupied, colour).
        leaves: Vec<(u64, u32, bool, Option<[u8; 3]>)>,
    },
    /// The view inside some coarse voxels, replacing the receiver's there
    /// ([`region`](super::region)).
    Region {
        /// Scan number the view is after.
        scan: u32,
        /// The coarse voxels replaced (codes at the coarse depth, ascending).
        coarse: Vec<u64>,
        /// Their leaves, as a full message's.
        leaves: Vec<Leaf>,
    },
}

/// A message with where it was in the stream and its size.
#[derive(Debug, Clone, PartialEq)]
pub struct Framed {
    /// Offset of the message in the stream.
    pub offset: u64,
    /// Its size in bytes (framing included).
    pub bytes: usize,
    /// The message.
    pub message: Message,
}

/// Reads a whole stream: header and every message.
pub fn decode_stream(bytes: &[u8]) -> Result<(StreamHeader, Vec<Framed>), ParseError> {
    let (h, mut pos) = decode_header(bytes)?;
    let mut out = Vec::new();
    while pos < bytes.len() {
        let (m, n) = decode_message(&h.spec, &bytes[pos..], pos as u64)?;
        out.push(Framed {
            offset: pos as u64,
            bytes: n,
            message: m,
        });
        pos += n;
    }
    Ok((h, out))
}

/// Reads one message at the start of `bytes` (`base`: its offset in the stream); returns it and
/// its length.
pub fn decode_message(
    spec: &ViewSpec,
    bytes: &[u8],
    base: u64,
) -> Result<(Message, usize), ParseError> {
    let mut cur = Cursor {
        bytes,
        pos: 0,
        base,
    };
    let kind = cur.u8("message kind")?;
    let scan = u32::from_le_bytes(cur.take(4, "scan number")?.try_into().unwrap_or([0; 4]));
    let len =
        u32::from_le_bytes(cur.take(4, "payload length")?.try_into().unwrap_or([0; 4])) as usize;
    let payload = cur.take(len, "payload")?;
    let crc_at = cur.pos;
    let carried = u32::from_le_bytes(cur.take(4, "CRC-32")?.try_into().unwrap_or([0; 4]));
    let computed = CRC32.checksum(&bytes[..crc_at]);
    if carried != computed {
        return Err(ParseError::new(
            base + crc_at as u64,
            format!("CRC-32 mismatch (computed {computed:#010x}, carried {carried:#010x})"),
        ));
    }
    let mut p = Cursor {
        bytes: payload,
        pos: 0,
        base: base + 9,
    };
    let message = match kind {
        KIND_DELTA => {
            let at = p.pos;
            let flags = p.u8("delta flags")?;
            if flags > 1 {
                p.pos = at;
                return Err(p.err(format!("delta flags: unknown bits in {flags:#04x}")));
            }
            let fine = decode_codes(&mut p, TREE_DEPTH, "fine occupied list")?;
            let fine_free = decode_codes(&mut p, TREE_DEPTH, "fine free list")?;
            let coarse_occupied = decode_codes(&mut p, spec.coarse_depth, "coarse occupied list")?;
            let coarse_free = decode_codes(&mut p, spec.coarse_depth, "coarse free list")?;
            if flags & 1 != 0 && fine.is_empty() {
                return Err(p.err("delta flags: colours announced for an empty occupied list"));
            }
            let colors = if flags & 1 != 0 {
                decode_colors(&mut p, fine.len())?
                    .into_iter()
                    .map(Some)
                    .collect()
            } else {
                vec![None; fine.len()]
            };
            if p.left() != 0 {
                return Err(p.err(format!("{} bytes after the delta's lists", p.left())));
            }
            Message::Delta {
                scan,
                delta: Delta {
                    fine_occupied: fine.into_iter().zip(colors).collect(),
                    fine_free,
                    coarse_occupied,
                    coarse_free,
                },
            }
        }
        KIND_FULL => Message::Full {
            scan,
            leaves: decode_full(&mut p)?,
        },
        super::region::KIND_REGION => {
            let (coarse, leaves) = decode_region(&mut p, spec)?;
            Message::Region {
                scan,
                coarse,
                leaves,
            }
        }
        other => {
            return Err(ParseError::new(
                base,
                format!("message kind: expected 1 (delta), 2 (full) or 3 (region), found {other}"),
            ));
        }
    };
    Ok((message, cur.pos))
}

/// A full message: the view tree in `.bt` form (2 bits per child, pre-order), then a colour for
/// every occupied leaf in pre-order when the flag byte says so.
pub fn encode_full(scan: u32, view: &OcTree) -> Vec<u8> {
    let mut p = vec![view.is_colored() as u8];
    let mut colors = Vec::new();
    if let Some(root) = view.root() {
        let v = view.node(root);
        if v.has_children() {
            super::region::subtree(view, root, &mut p, &mut colors);
        } else {
            // The whole space is one leaf: flag bit 1 and its code (1 free, 2 occupied).
            p[0] |= 2;
            p.push(if v.log_odds >= 0.0 { 2 } else { 1 });
            if v.log_odds >= 0.0 {
                colors.extend_from_slice(&v.color.unwrap_or([255, 255, 255]));
            }
        }
    }
    if view.is_colored() {
        p.extend_from_slice(&colors);
    }
    frame_message(KIND_FULL, scan, &p)
}

/// A leaf of a view: depth-16 code of its first voxel, depth, occupied, colour.
pub type Leaf = (u64, u32, bool, Option<[u8; 3]>);

fn decode_full(p: &mut Cursor) -> Result<Vec<Leaf>, ParseError> {
    let at = p.pos;
    let flags = p.u8("full flags")?;
    if flags > 3 {
        p.pos = at;
        return Err(p.err(format!("full flags: unknown bits in {flags:#04x}")));
    }
    let mut leaves = Vec::new();
    if flags & 2 != 0 {
        let at = p.pos;
        match p.u8("root leaf code")? {
            1 => leaves.push((0, 0, false, None)),
            2 => leaves.push((0, 0, true, None)),
            other => {
                p.pos = at;
                return Err(p.err(format!("root leaf code: expected 1 or 2, found {other}")));
            }
        }
    } else if p.left() > 0 {
        full_level(p, 0, 0, &mut leaves)?;
    }
    if flags & 1 != 0 {
        leaf_colors(p, &mut leaves)?;
    }
    if p.left() != 0 {
        return Err(p.err(format!("{} bytes after the full view", p.left())));
    }
    Ok(leaves)
}

/// Reads r, g, b of every occupied leaf, in order, into the leaves.
fn leaf_colors(p: &mut Cursor, leaves: &mut [Leaf]) -> Result<(), ParseError> {
    let occ = leaves.iter().filter(|l| l.2).count();
    let raw = p.take(occ * 3, "colours of the occupied leaves")?;
    let mut it = raw.chunks_exact(3);
    for l in leaves.iter_mut().filter(|l| l.2) {
        // White is "no colour" (OctoMap's ColorOcTree default).
        l.3 = it
            .next()
            .map(|c| [c[0], c[1], c[2]])
            .filter(|c| *c != [255, 255, 255]);
    }
    Ok(())
}

/// A region's payload: its coarse voxels and their leaves.
fn decode_region(p: &mut Cursor, spec: &ViewSpec) -> Result<(Vec<u64>, Vec<Leaf>), ParseError> {
    let at = p.pos;
    let flags = p.u8("region flags")?;
    if flags > 1 {
        p.pos = at;
        return Err(p.err(format!("region flags: unknown bits in {flags:#04x}")));
    }
    let d = spec.coarse_depth;
    let coarse = decode_codes(p, d, "region's coarse voxels")?;
    let shift = spec.coarse_shift();
    let mut leaves = Vec::new();
    for &c in &coarse {
        let at = p.pos;
        match p.u8("region content code")? {
            0 => {}
            1 => leaves.push((c << shift, d, false, None)),
            2 => leaves.push((c << shift, d, true, None)),
            3 => full_level(p, d, c << shift, &mut leaves)?,
            other => {
                p.pos = at;
                return Err(p.err(format!(
                    "region content code: expected 0..=3, found {other}"
                )));
            }
        }
    }
    if flags & 1 != 0 {
        leaf_colors(p, &mut leaves)?;
    }
    if p.left() != 0 {
        return Err(p.err(format!("{} bytes after the region", p.left())));
    }
    Ok((coarse, leaves))
}

/// A region message's bytes (framing included): `view` inside the coarse voxels `coarse`
/// (ascending codes at `spec`'s coarse depth), replacing the receiver's there.
pub fn encode_region(spec: &ViewSpec, scan: u32, view: &OcTree, coarse: &[u64]) -> Vec<u8> {
    frame_message(
        super::region::KIND_REGION,
        scan,
        &super::region::encode_payload(view, spec, coarse),
    )
}

fn full_level(
    p: &mut Cursor,
    depth: u32,
    code: u64,
    out: &mut Vec<Leaf>,
) -> Result<(), ParseError> {
    if depth >= TREE_DEPTH {
        return Err(p.err("full view: inner node at depth 16"));
    }
    let b = p.take(2, "full view node")?;
    let b = [b[0], b[1]];
    let shift = 3 * (TREE_DEPTH - 1 - depth);
    for i in 0..8 {
        let c = (b[i / 4] >> (2 * (i % 4))) & 3;
        let child = code | ((i as u64) << shift);
        match c {
            1 => out.push((child, depth + 1, false, None)),
            2 => out.push((child, depth + 1, true, None)),
            3 => full_level(p, depth + 1, child, out)?,
            _ => {}
        }
    }
    Ok(())
}

/// The view of a map as the operator would have it after a full transfer: fine leaves inside
/// the ROI (whole coarse voxels that meet it), coarse ones outside, maximum likelihood.
pub fn view_of(tree: &OcTree, spec: &ViewSpec) -> OcTree {
    let mut view = OcTree::new(spec.resolution_m);
    if tree.is_colored() {
        view.enable_color();
    }
    let p = Params::default();
    let d = spec.coarse_depth;
    let shift = spec.coarse_shift();
    let mut coarse_done: HashSet<u64> = HashSet::new();
    tree.for_each_leaf(|code, depth, v| {
        let occ = v.log_odds >= 0.0;
        let ml = if occ {
            p.clamp_max_log
        } else {
            p.clamp_min_log
        };
        if depth <= d {
            // A leaf as big as a coarse voxel or bigger: the same state everywhere; colour only
            // in the coarse voxels that meet the ROI (the others are sent coarse, colourless).
            let color = if occ { v.color } else { None };
            big_leaf(&mut view, spec, code, depth, ml, color);
            return;
        }
        let coarse = code >> shift;
        if spec.coarse_in_roi(coarse) {
            view.set_node(code, depth, ml, if occ { v.color } else { None });
        } else if coarse_done.insert(coarse) {
            let cocc = tree
                .search(code, d)
                .is_some_and(|(n, _)| tree.node(n).log_odds >= 0.0);
            let cml = if cocc {
                p.clamp_max_log
            } else {
                p.clamp_min_log
            };
            view.set_node(coarse << shift, d, cml, None);
        }
    });
    view
}

/// Sets a leaf of `depth <= coarse_depth` in the view: in one piece where it lies wholly inside
/// or wholly outside the ROI, split into octants only where it straddles the ROI's boundary
/// (down to coarse voxels), so the work follows the ROI's surface, not the leaf's volume.
fn big_leaf(
    view: &mut OcTree,
    spec: &ViewSpec,
    code: u64,
    depth: u32,
    ml: f32,
    color: Option<[u8; 3]>,
) {
    let Some(roi) = spec.roi.filter(|_| color.is_some()) else {
        view.set_node(code, depth, ml, color);
        return;
    };
    let k = unmorton(code);
    let edge = spec.resolution_m * (1u64 << (TREE_DEPTH - depth)) as f64;
    let (mut inside, mut outside) = (true, false);
    for ((&key, &min), &max) in k.iter().zip(&roi.min_m).zip(&roi.max_m) {
        let lo = (key as i64 - 32768) as f64 * spec.resolution_m;
        let hi = lo + edge;
        inside &= min <= lo && hi <= max;
        outside |= lo > max || hi < min;
    }
    if inside || outside || depth == spec.coarse_depth {
        let c = if depth == spec.coarse_depth {
            color.filter(|_| spec.coarse_in_roi(code >> spec.coarse_shift()))
        } else {
            color.filter(|_| inside)
        };
        view.set_node(code, depth, ml, c);
        return;
    }
    let shift = 3 * (TREE_DEPTH - 1 - depth);
    for i in 0..8u64 {
        big_leaf(view, spec, code | (i << shift), depth + 1, ml, color);
    }
}

/// Sets a view's leaves to their maximum-likelihood values (a full or region message's).
fn set_leaves(view: &mut OcTree, leaves: &[Leaf]) {
    let p = Params::default();
    for &(code, depth, occ, col) in leaves {
        let v = if occ {
            p.clamp_max_log
        } else {
            p.clamp_min_log
        };
        view.set_node(code, depth, v, col);
    }
}

/// The operator side: a view built from the messages it received.
#[derive(Debug, Clone)]
pub struct Receiver {
    spec: ViewSpec,
    view: OcTree,
    /// Messages applied.
    pub messages: usize,
}

impl Receiver {
    /// An empty view.
    pub fn new(spec: ViewSpec) -> Self {
        Receiver {
            spec,
            view: OcTree::new(spec.resolution_m),
            messages: 0,
        }
    }

    /// The view so far.
    pub fn view(&self) -> &OcTree {
        &self.view
    }

    /// The view it receives.
    pub fn spec(&self) -> &ViewSpec {
        &self.spec
    }

    /// Takes a new region of interest, keeping the view (the coarse depth and resolution
    /// stay: a new coarse depth is a new stream).
    pub fn set_roi(&mut self, roi: Option<Roi>) {
        self.spec.roi = roi;
    }

    /// Applies one message.
    pub fn apply(&mut self, m: &Message) {
        let p = Params::default();
        let shift = self.spec.coarse_shift();
        self.messages += 1;
        match m {
            Message::Delta { delta, .. } => {
                if !self.view.is_colored() && delta.fine_occupied.iter().any(|e| e.1.is_some()) {
                    self.view.enable_color();
                }
                for &c in &delta.fine_free {
                    self.view.set_node(c, TREE_DEPTH, p.clamp_min_log, None);
                }
                for &(c, col) in &delta.fine_occupied {
                    self.view.set_node(c, TREE_DEPTH, p.clamp_max_log, col);
                }
                for &c in &delta.coarse_free {
                    self.view
                        .set_node(c << shift, self.spec.coarse_depth, p.clamp_min_log, None);
                }
                for &c in &delta.coarse_occupied {
                    self.view
                        .set_node(c << shift, self.spec.coarse_depth, p.clamp_max_log, None);
                }
            }
            Message::Full { leaves, .. } => {
                self.view = OcTree::new(self.spec.resolution_m);
                if leaves.iter().any(|l| l.3.is_some()) {
                    self.view.enable_color();
                }
                set_leaves(&mut self.view, leaves);
            }
            Message::Region { coarse, leaves, .. } => {
                let mut view = OcTree::new(self.spec.resolution_m);
                if self.view.is_colored() || leaves.iter().any(|l| l.3.is_some()) {
                    view.enable_color();
                }
                super::region::keep_outside(&self.view, &self.spec, coarse, &mut view);
                set_leaves(&mut view, leaves);
                self.view = view;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tree::morton;

    /// The tree of `codes` written level by level, recursively: what [`encode_codes`] must
    /// write in one pass.
    fn encode_level_by_level(codes: &[u64], level: u32, depth: u32, out: &mut Vec<u8>) {
        let shift = 3 * (depth - 1 - level);
        let mut mask = 0u8;
        for &c in codes {
            mask |= 1 << ((c >> shift) & 7);
        }
        out.push(mask);
        if level + 1 == depth {
            return;
        }
        let mut start = 0;
        while start < codes.len() {
            let digit = (codes[start] >> shift) & 7;
            let mut end = start + 1;
            while end < codes.len() && (codes[end] >> shift) & 7 == digit {
                end += 1;
            }
            encode_level_by_level(&codes[start..end], level + 1, depth, out);
            start = end;
        }
    }

    proptest::proptest! {
        /// Sorted code lists, sparse and dense, at every depth: the one-pass coder writes the
        /// bytes the level-by-level one writes.
        #[test]
        fn one_pass_tree_coding_is_the_level_by_level_coding(
            depth in 1u32..=16,
            raw in proptest::collection::vec(proptest::prelude::any::<u64>(), 0..300),
            dense in 0u32..3,
        ) {
            let bits = 3 * depth;
            let mask = u64::MAX >> (64 - bits);
            // Dense lists: codes close together, as a scan's cells are.
            let spread = [mask, (1 << 12) - 1, 63][dense as usize] & mask;
            let base = raw.first().copied().unwrap_or(0) & mask & !spread;
            let mut codes: Vec<u64> = raw.iter().map(|r| base | (r & spread)).collect();
            codes.sort_unstable();
            codes.dedup();
            let mut want = Vec::new();
            put_varint(&mut want, codes.len() as u64);
            if !codes.is_empty() {
                encode_level_by_level(&codes, 0, depth, &mut want);
            }
            let mut got = Vec::new();
            encode_codes(&codes, depth, &mut got);
            proptest::prop_assert_eq!(got, want);
        }
    }
    use crate::{Pose, Scan};

    #[test]
    fn code_lists_round_trip_and_are_compact_when_dense() {
        let mut codes: Vec<u64> = (0..512u16)
            .map(|i| morton([32768 + (i & 7), 32768 + ((i >> 3) & 7), 32768 + (i >> 6)]))
            .collect();
        codes.sort_unstable();
        let mut out = Vec::new();
        encode_codes(&codes, 16, &mut out);
        // 512 voxels in an 8x8x8 block: 64 + 8 + 1 bytes below level 13, plus the shared path.
        assert!(out.len() < 100, "{} bytes", out.len());
        let mut cur = Cursor {
            bytes: &out,
            pos: 0,
            base: 0,
        };
        assert_eq!(decode_codes(&mut cur, 16, "t").unwrap(), codes);
    }

    #[test]
    fn colours_round_trip_and_smooth_ones_are_cheap() {
        let mut rng = rovlink_base::rng::Rng::new(5, 0);
        let random: Vec<[u8; 3]> = (0..300)
            .map(|_| {
                [
                    rng.next_u32() as u8,
                    rng.next_u32() as u8,
                    rng.next_u32() as u8,
                ]
            })
            .collect();
        let smooth: Vec<[u8; 3]> = (0..300u32)
            .map(|i| [(100 + i / 10) as u8, (50 + (i % 7)) as u8, 200])
            .collect();
        for (colors, max_bytes) in [(random, 300 * 3 + 1), (smooth, 300)] {
            let mut out = Vec::new();
            encode_colors(&colors, &mut out);
            assert!(out.len() <= max_bytes, "{} bytes", out.len());
            let mut cur = Cursor {
                bytes: &out,
                pos: 0,
                base: 0,
            };
            assert_eq!(decode_colors(&mut cur, colors.len()).unwrap(), colors);
            assert_eq!(cur.pos, out.len());
            let mut cur = Cursor {
                bytes: &out[..out.len() - 1],
                pos: 0,
                base: 0,
            };
            assert!(decode_colors(&mut cur, colors.len()).is_err());
        }
    }

    #[test]
    fn header_round_trip_and_errors() {
        let spec = ViewSpec {
            resolution_m: 0.1,
            coarse_depth: 13,
            roi: Some(Roi {
                min_m: [-1.0, -2.0, -3.0],
                max_m: [1.0, 2.0, 3.0],
            }),
        };
        let h = encode_header(&spec);
        let (back, n) = decode_header(&h).unwrap();
        assert_eq!(back.spec, spec);
        assert_eq!(n, h.len());
        assert!(
            decode_header(&h[..10])
                .unwrap_err()
                .message
                .contains("resolution")
        );
        let mut bad = h.clone();
        bad[14] = 17;
        assert!(
            decode_header(&bad)
                .unwrap_err()
                .message
                .contains("coarse depth")
        );
    }

    fn surface_scan(z: f32, shift: f32) -> Scan {
        let mut pts = Vec::new();
        let mut cols = Vec::new();
        for i in 0..60 {
            for j in 0..60 {
                pts.push([i as f32 * 0.05 - 1.5 + shift, j as f32 * 0.05 - 1.5, z]);
                cols.push([(i * 4) as u8, (j * 4) as u8, 80]);
            }
        }
        Scan {
            points: pts,
            colors: Some(cols),
            pose: Pose::IDENTITY,
        }
    }

    #[test]
    fn receiver_view_equals_the_view_of_the_map() {
        for roi in [
            None,
            Some(Roi {
                min_m: [-0.5, -0.5, -5.0],
                max_m: [0.5, 0.5, 5.0],
            }),
        ] {
            let spec = ViewSpec {
                resolution_m: 0.1,
                coarse_depth: 14,
                roi,
            };
            let mut tree = OcTree::new(0.1);
            tree.enable_color();
            let mut tx = Sender::new(spec);
            let mut rx = Receiver::new(spec);
            let mut stream = encode_header(&spec);
            for (k, (z, s)) in [(-2.0, 0.0), (-2.0, 0.3), (-1.8, 0.6)]
                .into_iter()
                .enumerate()
            {
                let up = tree.insert_scan(&surface_scan(z, s), None);
                let d = tx.delta(&tree, &up.changes);
                stream.extend(encode_delta(&spec, k as u32, &d));
            }
            let (_, msgs) = decode_stream(&stream).unwrap();
            for m in &msgs {
                rx.apply(&m.message);
            }
            let expect = view_of(&tree, &spec);
            let (mut a, mut b) = (Vec::new(), Vec::new());
            rx.view()
                .for_each_leaf(|c, d, v| a.push((c, d, v.log_odds >= 0.0)));
            expect.for_each_leaf(|c, d, v| b.push((c, d, v.log_odds >= 0.0)));
            assert_eq!(a, b, "roi {roi:?}");
            // A full message gives the same view.
            let full = encode_full(9, &expect);
            let (m, n) = decode_message(&spec, &full, 0).unwrap();
            assert_eq!(n, full.len());
            let mut rx2 = Receiver::new(spec);
            rx2.apply(&m);
            let mut c = Vec::new();
            rx2.view()
                .for_each_leaf(|code, d, v| c.push((code, d, v.log_odds >= 0.0)));
            assert_eq!(c, b);
        }
    }

    #[test]
    fn a_huge_coloured_leaf_is_set_in_one_piece_or_split_along_the_roi_only() {
        let mut tree = OcTree::new(0.1);
        tree.enable_color();
        tree.set_node(0, 1, 2.0, Some([10, 20, 30]));
        let spec = ViewSpec {
            resolution_m: 0.1,
            coarse_depth: 16,
            roi: None,
        };
        let v = view_of(&tree, &spec);
        assert_eq!(v.num_nodes(), tree.num_nodes());
        let roi = Some(Roi {
            min_m: [-1.0, -1.0, -1.0],
            max_m: [1.0, 1.0, 1.0],
        });
        let v = view_of(
            &tree,
            &ViewSpec {
                resolution_m: 0.1,
                coarse_depth: 13,
                roi,
            },
        );
        // Split along the ROI's faces only: far fewer nodes than 8^12 coarse voxels.
        assert!(v.num_nodes() < 200_000, "{} nodes", v.num_nodes());
    }

    #[test]
    fn damaged_messages_are_errors() {
        let spec = ViewSpec {
            resolution_m: 0.1,
            coarse_depth: 14,
            roi: None,
        };
        let mut tree = OcTree::new(0.1);
        let mut tx = Sender::new(spec);
        let up = tree.insert_scan(&surface_scan(-2.0, 0.0), None);
        let msg = encode_delta(&spec, 0, &tx.delta(&tree, &up.changes));
        let mut bad = msg.clone();
        bad[12] ^= 1;
        assert!(
            decode_message(&spec, &bad, 100)
                .unwrap_err()
                .message
                .contains("CRC")
        );
        let e = decode_message(&spec, &msg[..msg.len() - 2], 100).unwrap_err();
        assert!(e.message.contains("CRC-32: expected 4 bytes"), "{e}");
    }
}
