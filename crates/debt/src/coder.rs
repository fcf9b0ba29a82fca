//! The block-tree bit-plane coder: the heart of DEBT.
//!
//! Every subband of every component is covered by a quadtree whose nodes know the largest
//! coefficient magnitude beneath them. Bit-plane by bit-plane, from the most significant down,
//! three passes, each over the subbands coarse to fine with components interleaved:
//!
//! 1. **Propagation**: insignificant coefficients next to a significant one are tested first:
//!    they are the likeliest to become significant, so their bits buy the most.
//! 2. **Cleanup**: the remaining insignificant nodes of each quadtree level are tested, leaves
//!    first. A node that becomes significant is split at once, depth first, down to the
//!    coefficients; of the children of a significant node, the last is known significant if
//!    the others are not. A coefficient that becomes significant sends its sign.
//! 3. **Refinement**: every coefficient significant before this plane sends one more bit.
//!
//! Each decision is coded by the adaptive range coder in a context made of the subband class,
//! the quadtree level, the significance of neighbours, and the significance of the parent (the
//! same place one level coarser, already coded in this plane). Encoder and decoder run this
//! same traversal: the encoder through a [`BitCoder`] that writes the true bits, the decoder
//! through one that reads them, so the two cannot drift apart. Either stops at the first symbol
//! its byte budget cannot hold ([`Stop`]).

use super::rangecoder::{Context, MARGIN_BITS, RangeDecoder, RangeEncoder};

/// The byte budget is spent: coding stops at this symbol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stop;

/// One side of the coder: writes (encoder) or reads (decoder) binary decisions.
pub trait BitCoder {
    /// True for the encoder: decisions come from the data.
    const ENCODER: bool;
    /// Codes a decision in context `ctx`; the encoder passes the true `bit`, the decoder
    /// ignores it and returns what it read.
    fn bit(&mut self, ctx: usize, bit: bool) -> Result<bool, Stop>;
    /// Codes `bits` bits of `value` at probability one half.
    fn raw(&mut self, value: u32, bits: u32) -> Result<u32, Stop>;
    /// Notes that the pass with this [`pass_index`] is complete (the encoder records where).
    fn mark(&mut self, _pass_index: usize) {}
}

/// Number of distinct pass indices: three passes of 32 planes.
pub const PASS_INDICES: usize = 96;

/// Position of pass `pass` (0 propagation, 1 cleanup, 2 refinement) of bit-plane `plane` in
/// coding order, the same for every stream whatever its number of planes.
pub fn pass_index(plane: u32, pass: usize) -> usize {
    (31 - plane.min(31) as usize) * 3 + pass
}

/// Context counts and offsets.
mod ctx {
    pub const NODE: usize = 0; // origin 4 x class 4 x level 3 x parent 2 x neighbour 2 = 192
    pub const COEF: usize = NODE + 192; // origin 4 x class 4 x neighbourhood 9 x parent 2 = 288
    pub const SIGN: usize = COEF + 288; // class 4 x left 3 x up 3 = 36
    pub const REFINE: usize = SIGN + 36; // class 4 x first 2 x neighbour 2 = 16
    pub const COUNT: usize = REFINE + 16;
}

/// Number of contexts the coder keeps (the length of a priors table).
pub const CONTEXTS: usize = ctx::COUNT;

/// A context's initial state: probability of a 0 in 1/32768, and the number of symbols the
/// context counts as already seen (how slowly it adapts from there); see
/// [`Context::with_prior`].
pub type Prior = (u16, u8);

/// The contexts at the start of a stream: all at one half, or from a priors table. A table
/// may be shorter than [`CONTEXTS`]: the contexts past its end (added to `ctx` after the table
/// was trained) start at one half, so a new context is one edit here and the trained table
/// stays valid; entries past [`CONTEXTS`] are ignored.
fn initial_contexts(priors: Option<&[Prior]>) -> Vec<Context> {
    let table = priors.unwrap_or(&[]);
    (0..CONTEXTS)
        .map(|i| match table.get(i) {
            Some(&(p0, count)) => Context::with_prior(p0, count),
            None => Context::default(),
        })
        .collect()
}

/// One context-coded decision, as [`Encoder::decisions`] records it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decision {
    /// The context index (below [`CONTEXTS`]).
    pub context: u16,
    /// The bit coded.
    pub bit: bool,
    /// Bits the stream had spent before this decision.
    pub at_bits: u64,
}

/// Zero bytes after a complete stream: enough for the decoder's margin.
pub const COMPLETE_PADDING_BYTES: usize = (MARGIN_BITS as usize).div_ceil(8) + 1;

/// The encoder side.
pub struct Encoder {
    rc: RangeEncoder,
    contexts: Vec<Context>,
    budget_bits: u64,
    /// Each completed pass: its [`pass_index`] and the bits written by its end.
    pub marks: Vec<(usize, u64)>,
    /// When `Some`, every context-coded decision is appended, in coding order (for training
    /// a priors table; raw bits are not recorded).
    pub decisions: Option<Vec<Decision>>,
}

impl Encoder {
    /// An encoder that stops before the symbol that would not fit in `budget_bytes`.
    pub fn new(budget_bytes: usize) -> Encoder {
        Encoder::start(budget_bytes, None)
    }

    /// An encoder whose contexts start from `priors` instead of one half; its stream decodes
    /// only with [`Decoder::with_priors`] and the same table.
    pub fn with_priors(budget_bytes: usize, priors: &[Prior]) -> Encoder {
        Encoder::start(budget_bytes, Some(priors))
    }

    fn start(budget_bytes: usize, priors: Option<&[Prior]>) -> Encoder {
        Encoder {
            rc: RangeEncoder::new(),
            contexts: initial_contexts(priors),
            budget_bits: (budget_bytes as u64).saturating_mul(8),
            marks: Vec::new(),
            decisions: None,
        }
    }

    /// Terminates the stream. A `complete` stream (every plane coded) gets zero bytes appended
    /// so that the decoder's budget rule lets it decode the last symbols too.
    pub fn finish(self, complete: bool) -> Vec<u8> {
        let mut out = self.rc.finish();
        if complete {
            out.resize(out.len() + COMPLETE_PADDING_BYTES, 0);
        }
        out
    }

    fn room(&self) -> Result<(), Stop> {
        if self.rc.tell_bits() + u64::from(MARGIN_BITS) > self.budget_bits {
            Err(Stop)
        } else {
            Ok(())
        }
    }
}

impl BitCoder for Encoder {
    const ENCODER: bool = true;
    fn bit(&mut self, ctx: usize, bit: bool) -> Result<bool, Stop> {
        self.room()?;
        if let Some(log) = self.decisions.as_mut() {
            log.push(Decision {
                context: ctx as u16,
                bit,
                at_bits: self.rc.tell_bits(),
            });
        }
        self.rc.encode(&mut self.contexts[ctx], bit);
        Ok(bit)
    }
    fn raw(&mut self, value: u32, bits: u32) -> Result<u32, Stop> {
        self.room()?;
        self.rc.encode_raw(value, bits);
        Ok(value)
    }
    fn mark(&mut self, pass_index: usize) {
        self.marks.push((pass_index, self.rc.tell_bits()));
    }
}

/// The decoder side.
pub struct Decoder<'a> {
    rc: RangeDecoder<'a>,
    contexts: Vec<Context>,
    budget_bits: u64,
}

impl<'a> Decoder<'a> {
    /// Decodes `data`, all of whose bytes count as budget.
    pub fn new(data: &'a [u8]) -> Decoder<'a> {
        Decoder::start(data, None)
    }

    /// Decodes `data` written by [`Encoder::with_priors`] with the same table.
    pub fn with_priors(data: &'a [u8], priors: &[Prior]) -> Decoder<'a> {
        Decoder::start(data, Some(priors))
    }

    fn start(data: &'a [u8], priors: Option<&[Prior]>) -> Decoder<'a> {
        Decoder {
            rc: RangeDecoder::new(data),
            contexts: initial_contexts(priors),
            budget_bits: (data.len() as u64).saturating_mul(8),
        }
    }

    fn room(&self) -> Result<(), Stop> {
        if self.rc.tell_bits() + u64::from(MARGIN_BITS) > self.budget_bits {
            Err(Stop)
        } else {
            Ok(())
        }
    }
}

impl BitCoder for Decoder<'_> {
    const ENCODER: bool = false;
    fn bit(&mut self, ctx: usize, _bit: bool) -> Result<bool, Stop> {
        self.room()?;
        Ok(self.rc.decode(&mut self.contexts[ctx]))
    }
    fn raw(&mut self, _value: u32, bits: u32) -> Result<u32, Stop> {
        self.room()?;
        Ok(self.rc.decode_raw(bits))
    }
}

/// Subband class for contexts: 0 LL, 1 HL, 2 LH, 3 HH.
pub type Class = usize;

/// One subband of one component as the coder sees it.
pub struct Band {
    /// Width in coefficients.
    pub width: usize,
    /// Height in coefficients.
    pub height: usize,
    class: Class,
    /// Index of the parent band (same component and orientation, one level coarser).
    parent: Option<usize>,
    /// Quadtree level sizes; `dims[0]` is the coefficient grid.
    dims: Vec<(usize, usize)>,
    /// Significance per quadtree level.
    sig: Vec<Vec<bool>>,
    /// Encoder: the largest magnitude under each node.
    max: Vec<Vec<u32>>,
    /// Encoder: true magnitudes. Decoder: the bits decoded so far.
    pub mag: Vec<u32>,
    /// Sign of each coefficient (true = negative).
    pub neg: Vec<bool>,
    /// Row of the subband this band's first row is (a segment holds a stripe of rows); the
    /// parent of coefficient row `y` is parent row `(y + row0) / 2 - parent.row0`.
    pub row0: usize,
    /// Decoder: lowest bit-plane known of each significant coefficient (meaningless for the
    /// others; empty when encoding).
    pub known: Vec<u8>,
    lin: Vec<Vec<u32>>,
    lsp: Vec<u32>,
    refine_count: usize,
    /// Coefficients found insignificant by this plane's propagation pass.
    deferred: Vec<u32>,
}

impl Band {
    /// A band of `width` x `height` coefficients. `magnitudes` and `negative` are the data to
    /// encode (the decoder passes `None`).
    pub fn new(
        width: usize,
        height: usize,
        class: Class,
        parent: Option<usize>,
        data: Option<(Vec<u32>, Vec<bool>)>,
    ) -> Band {
        let mut dims = vec![(width, height)];
        while dims.last().is_some_and(|&(w, h)| w > 1 || h > 1) {
            let (w, h) = *dims.last().unwrap_or(&(1, 1));
            dims.push((w.div_ceil(2), h.div_ceil(2)));
        }
        let sig = dims.iter().map(|&(w, h)| vec![false; w * h]).collect();
        let n = width * height;
        let encoding = data.is_some();
        let (mag, neg, max) = match data {
            Some((mag, neg)) => {
                // Level 0 of the tree is the magnitudes themselves: `max[0]` stays empty.
                let mut max: Vec<Vec<u32>> = vec![Vec::new()];
                for l in 1..dims.len() {
                    let (pw, ph) = dims[l - 1];
                    let (w, h) = dims[l];
                    let below = if l == 1 { &mag } else { &max[l - 1] };
                    let mut level = Vec::with_capacity(w * h);
                    // Each node is the maximum of the 2 x 2 (or fewer, at an odd edge) nodes
                    // below it: a pair of rows, two columns at a time.
                    for y in 0..h {
                        let top = &below[2 * y * pw..][..pw];
                        let bottom = if 2 * y + 1 < ph {
                            &below[(2 * y + 1) * pw..][..pw]
                        } else {
                            top
                        };
                        let pairs = top.chunks_exact(2).zip(bottom.chunks_exact(2));
                        level.extend(pairs.map(|(t, b)| t[0].max(t[1]).max(b[0].max(b[1]))));
                        if pw % 2 == 1 {
                            level.push(top[pw - 1].max(bottom[pw - 1]));
                        }
                    }
                    max.push(level);
                }
                (mag, neg, max)
            }
            None => (vec![0; n], vec![false; n], Vec::new()),
        };
        let top = dims.len() - 1;
        let mut lin = vec![Vec::new(); dims.len()];
        if n > 0 {
            lin[top].push(0);
        }
        Band {
            width,
            height,
            class,
            parent,
            dims,
            sig,
            max,
            mag,
            neg,
            row0: 0,
            // Zeroed allocations stay untouched (no page faults) in bands never reached.
            known: if encoding { Vec::new() } else { vec![0; n] },
            lin,
            lsp: Vec::new(),
            refine_count: 0,
            deferred: Vec::new(),
        }
    }

    /// Largest magnitude in the band (encoder side).
    pub fn max_magnitude(&self) -> u32 {
        if self.dims.len() == 1 {
            return self.mag.first().copied().unwrap_or(0);
        }
        self.max
            .last()
            .and_then(|l| l.first())
            .copied()
            .unwrap_or(0)
    }

    /// Largest magnitude under node (`level`, `node`) (encoder side).
    fn node_max(&self, level: usize, node: usize) -> u32 {
        if level == 0 {
            self.mag[node]
        } else {
            self.max[level][node]
        }
    }

    /// The significant coefficients' indices, in the order they became significant.
    pub fn significant(&self) -> &[u32] {
        &self.lsp
    }

    /// True if coefficient `i` is significant.
    pub fn is_significant(&self, i: usize) -> bool {
        self.sig[0][i]
    }

    fn sig_at(&self, level: usize, x: isize, y: isize) -> bool {
        let Some(&(w, h)) = self.dims.get(level) else {
            return false;
        };
        x >= 0
            && y >= 0
            && (x as usize) < w
            && (y as usize) < h
            && self.sig[level][y as usize * w + x as usize]
    }
}

/// Significance of the parent of node (`level`, `x`, `y`): the parent band's node one quadtree
/// level lower at the same index, or for a coefficient, the parent coefficient.
fn parent_sig(bands: &[Band], band: usize, level: usize, x: usize, y: usize) -> bool {
    let Some(p) = bands[band].parent else {
        return false;
    };
    let parent = &bands[p];
    if level == 0 {
        let py = (y + bands[band].row0) / 2;
        parent.sig_at(0, (x / 2) as isize, py as isize - parent.row0 as isize)
    } else {
        parent.sig_at(level - 1, x as isize, y as isize)
    }
}

fn node_context(
    bands: &[Band],
    band: usize,
    level: usize,
    x: usize,
    y: usize,
    origin: usize,
) -> usize {
    let b = &bands[band];
    let (xi, yi) = (x as isize, y as isize);
    if level == 0 {
        // EBCOT's neighbourhood classes: horizontal, vertical and diagonal significant
        // neighbours, read along the direction the subband's detail runs.
        let at = |dx: isize, dy: isize| usize::from(b.sig_at(0, xi + dx, yi + dy));
        let mut h = at(-1, 0) + at(1, 0);
        let mut v = at(0, -1) + at(0, 1);
        let d = at(-1, -1) + at(1, -1) + at(-1, 1) + at(1, 1);
        if b.class == 1 {
            std::mem::swap(&mut h, &mut v);
        }
        let neighbourhood = if b.class == 3 {
            match (d, h + v) {
                (3.., _) => 8,
                (2, 1..) => 7,
                (2, 0) => 6,
                (1, 2..) => 5,
                (1, 1) => 4,
                (1, 0) => 3,
                (0, 2..) => 2,
                (0, 1) => 1,
                _ => 0,
            }
        } else {
            match (h, v, d) {
                (2, _, _) => 8,
                (1, 1.., _) => 7,
                (1, 0, 1..) => 6,
                (1, 0, 0) => 5,
                (0, 2, _) => 4,
                (0, 1, _) => 3,
                (0, 0, 2..) => 2,
                (0, 0, 1) => 1,
                _ => 0,
            }
        };
        let parent = usize::from(parent_sig(bands, band, 0, x, y));
        ctx::COEF + ((origin * 4 + b.class) * 9 + neighbourhood) * 2 + parent
    } else {
        let neighbour = [(-1, 0), (1, 0), (0, -1), (0, 1)]
            .iter()
            .any(|&(dx, dy)| b.sig_at(level, xi + dx, yi + dy));
        let parent = usize::from(parent_sig(bands, band, level, x, y));
        let lev = (level - 1).min(2);
        ctx::NODE + (((origin * 4 + b.class) * 3 + lev) * 2 + parent) * 2 + usize::from(neighbour)
    }
}

fn sign_context(b: &Band, x: usize, y: usize) -> usize {
    // EBCOT's sign contributions: each of the horizontal and the vertical pair of neighbours
    // gives +1, -1 or 0 (none significant, or opposite signs).
    let s = |xx: isize, yy: isize| -> i32 {
        if b.sig_at(0, xx, yy) {
            if b.neg[yy as usize * b.width + xx as usize] {
                -1
            } else {
                1
            }
        } else {
            0
        }
    };
    let (xi, yi) = (x as isize, y as isize);
    let h = (s(xi - 1, yi) + s(xi + 1, yi)).signum() + 1;
    let v = (s(xi, yi - 1) + s(xi, yi + 1)).signum() + 1;
    ctx::SIGN + (b.class * 3 + h as usize) * 3 + v as usize
}

/// A coefficient becomes significant at `plane`: code its sign, set its state.
fn newly_significant<C: BitCoder>(
    bands: &mut [Band],
    band: usize,
    i: usize,
    plane: u32,
    coder: &mut C,
) -> Result<(), Stop> {
    let (x, y) = (i % bands[band].width, i / bands[band].width);
    let sctx = sign_context(&bands[band], x, y);
    let neg = coder.bit(sctx, bands[band].neg[i])?;
    let b = &mut bands[band];
    b.neg[i] = neg;
    if !C::ENCODER {
        b.mag[i] = 1 << plane;
        b.known[i] = plane as u8;
    }
    b.lsp.push(i as u32);
    Ok(())
}

/// Node (`level`, `node`) was found significant: split it down to the coefficients.
fn descend<C: BitCoder>(
    bands: &mut [Band],
    band: usize,
    level: usize,
    node: usize,
    plane: u32,
    coder: &mut C,
) -> Result<(), Stop> {
    let (w, _) = bands[band].dims[level];
    let (x, y) = (node % w, node / w);
    let child_level = level - 1;
    let (cw, ch) = bands[band].dims[child_level];
    let mut children = [0usize; 4];
    let mut count = 0;
    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        let (cx, cy) = (2 * x + dx, 2 * y + dy);
        if cx < cw && cy < ch {
            children[count] = cy * cw + cx;
            count += 1;
        }
    }
    let threshold = 1u32 << plane;
    let mut any = false;
    for (k, &child) in children[..count].iter().enumerate() {
        let significant = if k == count - 1 && !any {
            true
        } else {
            let truth = C::ENCODER && bands[band].node_max(child_level, child) >= threshold;
            let origin = if any {
                3
            } else if k + 2 == count {
                2
            } else {
                1
            };
            let c = node_context(bands, band, child_level, child % cw, child / cw, origin);
            coder.bit(c, truth)?
        };
        if significant {
            any = true;
            bands[band].sig[child_level][child] = true;
            if child_level == 0 {
                newly_significant(bands, band, child, plane, coder)?;
            } else {
                descend(bands, band, child_level, child, plane, coder)?;
            }
        } else {
            bands[band].lin[child_level].push(child as u32);
        }
    }
    Ok(())
}

/// The two significance passes of a bit-plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pass {
    /// Coefficients next to a significant one: the likeliest to become significant, so the
    /// most valuable bits, coded before the refinement pass.
    Propagation,
    /// Everything else, after the refinement pass: the remaining coefficients and the quadtree.
    Cleanup,
}

fn has_significant_neighbour(b: &Band, node: usize) -> bool {
    let (x, y) = ((node % b.width) as isize, (node / b.width) as isize);
    [
        (-1, -1),
        (0, -1),
        (1, -1),
        (-1, 0),
        (1, 0),
        (-1, 1),
        (0, 1),
        (1, 1),
    ]
    .iter()
    .any(|&(dx, dy)| b.sig_at(0, x + dx, y + dy))
}

fn significance_pass<C: BitCoder>(
    bands: &mut [Band],
    band: usize,
    plane: u32,
    pass: Pass,
    coder: &mut C,
) -> Result<(), Stop> {
    let threshold = 1u32 << plane;
    let levels = if pass == Pass::Propagation {
        1
    } else {
        bands[band].dims.len()
    };
    for level in 0..levels {
        let list = std::mem::take(&mut bands[band].lin[level]);
        let (w, _) = bands[band].dims[level];
        let mut keep = Vec::with_capacity(list.len());
        for (k, &node) in list.iter().enumerate() {
            let node = node as usize;
            if pass == Pass::Propagation && !has_significant_neighbour(&bands[band], node) {
                keep.push(node as u32);
                continue;
            }
            let truth = C::ENCODER && bands[band].node_max(level, node) >= threshold;
            let c = node_context(bands, band, level, node % w, node / w, 0);
            let significant = match coder.bit(c, truth) {
                Ok(s) => s,
                Err(stop) => {
                    keep.extend_from_slice(&list[k..]);
                    bands[band].lin[level] = keep;
                    return Err(stop);
                }
            };
            if significant {
                bands[band].sig[level][node] = true;
                if level == 0 {
                    newly_significant(bands, band, node, plane, coder)?;
                } else {
                    descend(bands, band, level, node, plane, coder)?;
                }
            } else if pass == Pass::Propagation {
                // Tested in this plane already: not again in the cleanup pass.
                bands[band].deferred.push(node as u32);
            } else {
                keep.push(node as u32);
            }
        }
        // Children found insignificant while splitting higher levels were pushed to lower
        // lists already processed in this plane; they wait for the next plane.
        let mut pushed = std::mem::take(&mut bands[band].lin[level]);
        keep.append(&mut pushed);
        bands[band].lin[level] = keep;
    }
    if pass == Pass::Cleanup {
        let b = &mut bands[band];
        let mut deferred = std::mem::take(&mut b.deferred);
        b.lin[0].append(&mut deferred);
    }
    Ok(())
}

fn refinement_pass<C: BitCoder>(
    bands: &mut [Band],
    band: usize,
    plane: u32,
    coder: &mut C,
) -> Result<(), Stop> {
    let b = &mut bands[band];
    for k in 0..b.refine_count {
        let i = b.lsp[k] as usize;
        let (x, y) = ((i % b.width) as isize, (i / b.width) as isize);
        let first = if C::ENCODER {
            b.mag[i] >> (plane + 2) == 0
        } else {
            u32::from(b.known[i]) == plane + 1 && b.mag[i] >> (plane + 1) == 1
        };
        let neighbour = [(-1, 0), (1, 0), (0, -1), (0, 1)]
            .iter()
            .any(|&(dx, dy)| b.sig_at(0, x + dx, y + dy));
        let c = ctx::REFINE + (b.class * 2 + usize::from(first)) * 2 + usize::from(neighbour);
        let truth = C::ENCODER && (b.mag[i] >> plane) & 1 == 1;
        let bit = coder.bit(c, truth)?;
        if !C::ENCODER {
            b.mag[i] |= u32::from(bit) << plane;
            b.known[i] = plane as u8;
        }
    }
    Ok(())
}

/// Codes bit-planes `planes - 1` down to 0 of every band, in coding order, until done or the
/// budget stops it.
pub fn code_planes<C: BitCoder>(
    bands: &mut [Band],
    planes: u32,
    coder: &mut C,
) -> Result<(), Stop> {
    for plane in (0..planes).rev() {
        for b in bands.iter_mut() {
            b.refine_count = b.lsp.len();
        }
        for band in 0..bands.len() {
            significance_pass(bands, band, plane, Pass::Propagation, coder)?;
        }
        coder.mark(pass_index(plane, 0));
        for band in 0..bands.len() {
            significance_pass(bands, band, plane, Pass::Cleanup, coder)?;
        }
        coder.mark(pass_index(plane, 1));
        for band in 0..bands.len() {
            refinement_pass(bands, band, plane, coder)?;
        }
        coder.mark(pass_index(plane, 2));
    }
    Ok(())
}

/// Builds a band list's parent links: `keys[i]` is (component, orientation code, level) of
/// band `i`; the parent is the band of the same component and orientation one level up.
pub fn parents(keys: &[(usize, u8, u32)]) -> Vec<Option<usize>> {
    keys.iter()
        .map(|&(c, o, l)| {
            keys.iter()
                .position(|&(c2, o2, l2)| c2 == c && o2 == o && l2 == l + 1 && o != 0)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_bands(seed: u64) -> Vec<(usize, usize, Vec<u32>, Vec<bool>)> {
        let mut s = rovlink_base::rng::Rng::new(seed, 0);
        [(5usize, 3usize), (5, 3), (9, 6), (1, 1), (17, 2)]
            .iter()
            .map(|&(w, h)| {
                let mag: Vec<u32> = (0..w * h)
                    .map(|_| {
                        let r = s.next_u32();
                        if r.is_multiple_of(3) { r % 1000 } else { r % 4 }
                    })
                    .collect();
                let neg: Vec<bool> = (0..w * h)
                    .map(|i| mag[i] != 0 && s.next_u32().is_multiple_of(2))
                    .collect();
                (w, h, mag, neg)
            })
            .collect()
    }

    fn make(data: &[(usize, usize, Vec<u32>, Vec<bool>)], encoder: bool) -> Vec<Band> {
        data.iter()
            .enumerate()
            .map(|(i, (w, h, m, n))| {
                let parent = if i == 2 { Some(1) } else { None };
                Band::new(
                    *w,
                    *h,
                    i.min(2),
                    parent,
                    encoder.then(|| (m.clone(), n.clone())),
                )
            })
            .collect()
    }

    fn encoder(budget: usize, priors: Option<&[Prior]>) -> Encoder {
        priors.map_or_else(|| Encoder::new(budget), |p| Encoder::with_priors(budget, p))
    }

    fn decoder<'a>(data: &'a [u8], priors: Option<&[Prior]>) -> Decoder<'a> {
        priors.map_or_else(|| Decoder::new(data), |p| Decoder::with_priors(data, p))
    }

    #[test]
    fn lossless_round_trip_and_budget() {
        round_trip_and_budget(None);
    }

    #[test]
    fn priors_round_trip_and_every_budget_decodes() {
        // Any table will do: random probabilities and counts, extremes included.
        let mut s = rovlink_base::rng::Rng::new(17, 0);
        let mut table = [(0u16, 0u8); CONTEXTS];
        for (i, prior) in table.iter_mut().enumerate() {
            *prior = match i % 5 {
                0 => (0, 0),
                1 => (u16::MAX, 255),
                _ => ((s.next_u32() % 32768) as u16, (s.next_u32() % 8) as u8),
            };
        }
        round_trip_and_budget(Some(&table));
        round_trip_and_budget(Some(&table[..CONTEXTS / 2]));
        round_trip_and_budget(Some(crate::priors::PRIORS));
        assert_eq!(crate::priors::PRIORS.len(), CONTEXTS);
    }

    fn round_trip_and_budget(priors: Option<&[Prior]>) {
        let data = random_bands(5);
        let planes = 10;
        let mut enc_bands = make(&data, true);
        let mut enc = encoder(usize::MAX / 16, priors);
        code_planes(&mut enc_bands, planes, &mut enc).unwrap();
        let bytes = enc.finish(true);
        let mut dec_bands = make(&data, false);
        let mut dec = decoder(&bytes, priors);
        code_planes(&mut dec_bands, planes, &mut dec).unwrap();
        for (b, (_, _, m, n)) in dec_bands.iter().zip(&data) {
            assert_eq!(&b.mag, m);
            for i in 0..m.len() {
                if m[i] != 0 {
                    assert_eq!(b.neg[i], n[i]);
                }
            }
        }
        // Any budget: the encoder fits it, the decoder agrees on what it got.
        for budget in [0, 1, 5, 10, 20, 40, bytes.len() / 2] {
            let mut enc_bands = make(&data, true);
            let mut enc = encoder(budget, priors);
            let complete = code_planes(&mut enc_bands, planes, &mut enc).is_ok();
            let cut = enc.finish(complete);
            assert!(cut.len() <= budget, "budget {budget}: {} bytes", cut.len());
            let mut padded = cut.clone();
            padded.resize(budget, 0);
            let mut dec_bands = make(&data, false);
            let _ = code_planes(&mut dec_bands, planes, &mut decoder(&padded, priors));
            for (b, (_, _, m, _)) in dec_bands.iter().zip(&data) {
                let significant: std::collections::HashSet<u32> =
                    b.significant().iter().copied().collect();
                for (i, (&got, &truth)) in b.mag.iter().zip(m).enumerate() {
                    if significant.contains(&(i as u32)) {
                        // What the decoder knows agrees with the truth down to its known plane.
                        let known = b.known[i];
                        assert_eq!(got >> known, truth >> known);
                    } else {
                        assert_eq!(got, 0);
                    }
                }
            }
        }
    }
}
