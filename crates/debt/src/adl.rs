//! Adaptive directional lifting (issue 31, step 2; Ding, Wu and Li 2007): the 9/7 transform of
//! the finest levels lifts along a direction chosen per block instead of straight across rows
//! and columns, so that an oblique edge or texture predicts along itself and leaves little
//! high-pass energy.
//!
//! One level is the plain level's two passes with an offset: the horizontal pass predicts an odd
//! column's sample from the even columns beside it at rows `y - d` and `y + d`, the vertical pass
//! an odd row's sample from the even rows at columns `x - d` and `x + d`, `d` one of
//! [`DIRECTIONS`] (quarter samples per line, linear interpolation along the line, positions
//! mirrored at the borders); the updates use the same offsets. A prediction reads only samples
//! of the other parity, so the decoder, running the same steps backwards with the same
//! directions, inverts it exactly up to rounding. With every direction 0 a level is the plain
//! level bit for bit.
//!
//! The encoder picks each block's direction of each pass as the one with the least sum of
//! absolute prediction residuals (the first lifting step's), keeping 0 unless another is better
//! by [`Params::margin`]. The directions ([`DirectionMap`]) are range coded with their own
//! contexts ([`DirectionMap::to_bytes`]): a bit for "same as the block on the left", then the
//! index among the other eight in three bits.
//!
//! A measured prototype: [`super::encode_with_directions`] returns the map beside the stream,
//! which codes the bit-planes in the budget less the map's bytes, and
//! [`super::decode_with_directions`] takes it back out of band. Measured in
//! `docs/debt-format.md` (issue 31, step 2).

use super::colour::from_components;
use super::rangecoder::{Context, RangeDecoder, RangeEncoder};
use super::wavelet::{self, low_size};
use super::{Error, Image};

/// The directions, in quarter samples of offset per line: 0, ±1/4, ±1/2, ±1 and ±2 samples.
pub const DIRECTIONS: [i32; 9] = [-8, -4, -2, -1, 0, 1, 2, 4, 8];
/// Index of direction 0 (the plain transform) in [`DIRECTIONS`].
pub const STRAIGHT: u8 = 4;

/// CDF 9/7 lifting constants, as [`wavelet`] has them.
const ALPHA: f32 = -1.586_134_3;
const BETA: f32 = -0.052_980_118;
const GAMMA: f32 = 0.882_911_1;
const DELTA: f32 = 0.443_506_87;
const K: f32 = 1.230_174_1;

/// How the encoder lays out and picks the directions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Finest levels lifted along directions (the coarser ones are plain).
    pub levels: u32,
    /// A block's side, in samples of its level (the same at every level).
    pub block: usize,
    /// A direction other than 0 is kept only if its residual is below `1 - margin` of
    /// direction 0's.
    pub margin: f32,
    /// Lift the chroma planes along the luma's directions too (else they are plain).
    pub chroma: bool,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            levels: 2,
            block: 32,
            margin: 0.1,
            chroma: false,
        }
    }
}

/// One level's directions: an index into [`DIRECTIONS`] per block, row by row, for each pass.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LevelDirections {
    /// Blocks across.
    pub columns: usize,
    /// Blocks down.
    pub rows: usize,
    /// The horizontal pass's (offsets along columns).
    pub horizontal: Vec<u8>,
    /// The vertical pass's (offsets along rows).
    pub vertical: Vec<u8>,
}

/// The directions of a picture's finest levels, finest first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DirectionMap {
    /// A block's side (see [`Params::block`]).
    pub block: usize,
    /// Whether the chroma planes follow the directions too (see [`Params::chroma`]).
    pub chroma: bool,
    /// Per level, finest first.
    pub levels: Vec<LevelDirections>,
}

/// Block grid of a level `cw` x `ch` samples.
fn grid(cw: usize, ch: usize, block: usize) -> (usize, usize) {
    (cw.div_ceil(block), ch.div_ceil(block))
}

/// Position `k` mirrored into `0..m` (whole-sample symmetric extension).
#[inline]
fn mirror(k: i64, m: usize) -> usize {
    if m == 1 {
        return 0;
    }
    let period = 2 * (m as i64 - 1);
    let k = k.rem_euclid(period);
    (if k >= m as i64 { period - k } else { k }) as usize
}

/// The sample of `line` at `q` quarter samples, linearly interpolated.
#[inline]
fn at(line: &[f32], q: i64) -> f32 {
    let (i, f) = (q >> 2, q & 3);
    let m = line.len();
    // Inside the line no position needs mirroring.
    let (a, b) = if i >= 0 && (i as usize) + 1 < m {
        (line[i as usize], line[i as usize + 1])
    } else {
        (line[mirror(i, m)], line[mirror(i + 1, m)])
    };
    if f == 0 {
        return a;
    }
    (a * (4 - f) as f32 + b * f as f32) * 0.25
}

/// The two neighbouring lines (of the other parity) of line `i` of `n`, mirrored.
#[inline]
fn neighbours(i: usize, n: usize) -> (usize, usize) {
    let prev = if i == 0 { 1 } else { i - 1 };
    let next = if i + 1 < n { i + 1 } else { i - 1 };
    (prev, next)
}

/// One lifting step on `n` interleaved lines of `m` samples: every line of `parity` gets `coef`
/// times its neighbours' samples at `-d` and `+d` quarter samples, `d = dir(line, position)`.
fn step(
    data: &mut [f32],
    n: usize,
    m: usize,
    parity: usize,
    coef: f32,
    dir: &impl Fn(usize, usize) -> i32,
) {
    for i in (parity..n).step_by(2) {
        let (p, q) = neighbours(i, n);
        for j in 0..m {
            let d = i64::from(dir(i, j));
            let c = 4 * j as i64;
            let v = at(&data[p * m..(p + 1) * m], c - d) + at(&data[q * m..(q + 1) * m], c + d);
            data[i * m + j] += coef * v;
        }
    }
}

/// The 9/7 lifting across `n` interleaved lines of `m` samples (even lines low, odd high),
/// forward or inverse, along the directions `dir(line, position)` gives.
fn lift(data: &mut [f32], n: usize, m: usize, forward: bool, dir: &impl Fn(usize, usize) -> i32) {
    if n < 2 || m == 0 {
        return;
    }
    let scale = |data: &mut [f32], low: f32, high: f32| {
        for (i, line) in data.chunks_exact_mut(m).enumerate() {
            let s = if i.is_multiple_of(2) { low } else { high };
            line.iter_mut().for_each(|x| *x *= s);
        }
    };
    if forward {
        step(data, n, m, 1, ALPHA, dir);
        step(data, n, m, 0, BETA, dir);
        step(data, n, m, 1, GAMMA, dir);
        step(data, n, m, 0, DELTA, dir);
        scale(data, 1.0 / K, K / 2.0);
    } else {
        scale(data, K, 2.0 / K);
        step(data, n, m, 0, -DELTA, dir);
        step(data, n, m, 1, -GAMMA, dir);
        step(data, n, m, 0, -BETA, dir);
        step(data, n, m, 1, -ALPHA, dir);
    }
}

/// Adds each block's sum of absolute first-step residuals for every direction to `costs`
/// (`n` interleaved lines of `m` samples; `block_of(line, position)` is the block's index).
fn add_costs(
    data: &[f32],
    n: usize,
    m: usize,
    block_of: &impl Fn(usize, usize) -> usize,
    costs: &mut [[f32; 9]],
) {
    if n < 2 {
        return;
    }
    for i in (1..n).step_by(2) {
        let (p, q) = neighbours(i, n);
        let (lp, lq) = (&data[p * m..(p + 1) * m], &data[q * m..(q + 1) * m]);
        for j in 0..m {
            let cost = &mut costs[block_of(i, j)];
            let c = 4 * j as i64;
            for (k, &d) in DIRECTIONS.iter().enumerate() {
                let d = i64::from(d);
                cost[k] += (data[i * m + j] - 0.5 * (at(lp, c - d) + at(lq, c + d))).abs();
            }
        }
    }
}

/// Each block's direction from its costs: the cheapest, unless it beats direction 0 by less
/// than `margin` of direction 0's cost.
fn pick(costs: &[[f32; 9]], margin: f32) -> Vec<u8> {
    costs
        .iter()
        .map(|c| {
            let (best, &least) = c
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1))
                .unwrap_or((STRAIGHT as usize, &0.0));
            if least < (1.0 - margin) * c[STRAIGHT as usize] {
                best as u8
            } else {
                STRAIGHT
            }
        })
        .collect()
}

/// What a directional level does.
#[derive(Clone, Copy)]
enum Mode {
    /// Picks the level's directions (with this margin, see [`Params::margin`]) and lifts along
    /// them.
    Pick(f32),
    /// Lifts along the given directions.
    Forward,
    /// Undoes [`Mode::Forward`].
    Inverse,
}

/// One directional level on the top-left `cw` x `ch` region of a `stride`-wide buffer, along
/// `dirs` (which must have the level's grid of `block`-sample blocks), picked into it first
/// with [`Mode::Pick`].
fn level(
    buf: &mut [f32],
    stride: usize,
    (cw, ch): (usize, usize),
    dirs: &mut LevelDirections,
    block: usize,
    mode: Mode,
) {
    let choose = match mode {
        Mode::Pick(margin) => Some(margin),
        _ => None,
    };
    let forward = !matches!(mode, Mode::Inverse);
    let (nw, nh) = (cw.div_ceil(2), ch.div_ceil(2));
    let columns = dirs.columns;
    let block_at = move |x: usize, y: usize| (y / block) * columns + x / block;
    // Horizontal pass: lines are the columns (x), positions the rows (y); `t` holds them.
    // Vertical pass: lines are the rows (y), positions the low (`u_low`) or high (`u_high`)
    // columns k, at x = 2k or 2k + 1.
    let mut t = vec![0.0f32; cw * ch];
    let (mut u_low, mut u_high) = (vec![0.0f32; ch * nw], vec![0.0f32; ch * (cw - nw)]);
    let nd = cw - nw;
    // Where row y of the level's output sits: low rows first.
    let out_row = |y: usize| {
        if y.is_multiple_of(2) {
            y / 2
        } else {
            nh + y / 2
        }
    };
    if forward {
        for y in 0..ch {
            for x in 0..cw {
                t[x * ch + y] = buf[y * stride + x];
            }
        }
        if let Some(margin) = choose {
            let mut costs = vec![[0.0f32; 9]; dirs.columns * dirs.rows];
            add_costs(&t, cw, ch, &block_at, &mut costs);
            dirs.horizontal = pick(&costs, margin);
        }
        let h = &dirs.horizontal;
        lift(&mut t, cw, ch, true, &|x, y| {
            DIRECTIONS[h[block_at(x, y)] as usize]
        });
        for y in 0..ch {
            for k in 0..nw {
                u_low[y * nw + k] = t[2 * k * ch + y];
            }
            for k in 0..nd {
                u_high[y * nd + k] = t[(2 * k + 1) * ch + y];
            }
        }
        if let Some(margin) = choose {
            let mut costs = vec![[0.0f32; 9]; dirs.columns * dirs.rows];
            add_costs(&u_low, ch, nw, &|y, k| block_at(2 * k, y), &mut costs);
            add_costs(&u_high, ch, nd, &|y, k| block_at(2 * k + 1, y), &mut costs);
            dirs.vertical = pick(&costs, margin);
        }
        let v = &dirs.vertical;
        lift(&mut u_low, ch, nw, true, &|y, k| {
            DIRECTIONS[v[block_at(2 * k, y)] as usize]
        });
        lift(&mut u_high, ch, nd, true, &|y, k| {
            DIRECTIONS[v[block_at(2 * k + 1, y)] as usize]
        });
        for y in 0..ch {
            let row = &mut buf[out_row(y) * stride..];
            row[..nw].copy_from_slice(&u_low[y * nw..(y + 1) * nw]);
            row[nw..cw].copy_from_slice(&u_high[y * nd..(y + 1) * nd]);
        }
    } else {
        for y in 0..ch {
            let row = &buf[out_row(y) * stride..];
            u_low[y * nw..(y + 1) * nw].copy_from_slice(&row[..nw]);
            u_high[y * nd..(y + 1) * nd].copy_from_slice(&row[nw..cw]);
        }
        let v = &dirs.vertical;
        lift(&mut u_low, ch, nw, false, &|y, k| {
            DIRECTIONS[v[block_at(2 * k, y)] as usize]
        });
        lift(&mut u_high, ch, nd, false, &|y, k| {
            DIRECTIONS[v[block_at(2 * k + 1, y)] as usize]
        });
        for y in 0..ch {
            for k in 0..nw {
                t[2 * k * ch + y] = u_low[y * nw + k];
            }
            for k in 0..nd {
                t[(2 * k + 1) * ch + y] = u_high[y * nd + k];
            }
        }
        let h = &dirs.horizontal;
        lift(&mut t, cw, ch, false, &|x, y| {
            DIRECTIONS[h[block_at(x, y)] as usize]
        });
        for y in 0..ch {
            for x in 0..cw {
                buf[y * stride + x] = t[x * ch + y];
            }
        }
    }
}

/// The plain 9/7 levels `from..levels` of a `width` x `height` plane, on its low-pass region
/// after `from` levels (copied out and back).
fn plain_levels(
    plane: &mut [f32],
    width: usize,
    height: usize,
    from: u32,
    levels: u32,
    forward: bool,
) {
    if from >= levels {
        return;
    }
    let (cw, ch) = low_size(width, height, from);
    let mut region: Vec<f32> = (0..ch)
        .flat_map(|y| plane[y * width..y * width + cw].iter().copied())
        .collect();
    wavelet::run_97(&mut region, cw, ch, levels - from, forward, &mut Vec::new());
    for (y, row) in region.chunks_exact(cw).enumerate() {
        plane[y * width..y * width + cw].copy_from_slice(row);
    }
}

/// The forward transform of a plane, `levels` levels of which the finest `map.levels.len()`
/// are directional, with the directions picked (and stored in `map`) with [`Mode::Pick`].
fn forward_plane(
    plane: &mut [f32],
    width: usize,
    height: usize,
    levels: u32,
    map: &mut DirectionMap,
    mode: Mode,
) {
    for (l, dirs) in map.levels.iter_mut().enumerate() {
        let (cw, ch) = low_size(width, height, l as u32);
        level(plane, width, (cw, ch), dirs, map.block, mode);
    }
    plain_levels(plane, width, height, map.levels.len() as u32, levels, true);
}

/// Forward transform of a `width` x `height` plane, `levels` levels, the finest
/// `map.levels.len()` lifted along `map`'s directions.
pub fn forward(plane: &mut [f32], width: usize, height: usize, levels: u32, map: &DirectionMap) {
    let mut map = map.clone();
    forward_plane(plane, width, height, levels, &mut map, Mode::Forward);
}

/// The inverse of [`forward`].
pub fn inverse(plane: &mut [f32], width: usize, height: usize, levels: u32, map: &DirectionMap) {
    let directional = map.levels.len() as u32;
    plain_levels(plane, width, height, directional, levels, false);
    let mut map = map.clone();
    for (l, dirs) in map.levels.iter_mut().enumerate().rev() {
        let (cw, ch) = low_size(width, height, l as u32);
        level(plane, width, (cw, ch), dirs, map.block, Mode::Inverse);
    }
}

/// A map of `params.levels` (at most `levels`) levels for a `width` x `height` plane, every
/// direction 0.
pub fn straight_map(width: usize, height: usize, levels: u32, params: &Params) -> DirectionMap {
    let levels = (0..params.levels.min(levels))
        .map(|l| {
            let (cw, ch) = low_size(width, height, l);
            let (columns, rows) = grid(cw, ch, params.block);
            LevelDirections {
                columns,
                rows,
                horizontal: vec![STRAIGHT; columns * rows],
                vertical: vec![STRAIGHT; columns * rows],
            }
        })
        .collect();
    DirectionMap {
        block: params.block,
        chroma: params.chroma,
        levels,
    }
}

/// The encoder's transform of the component planes: luma's directions picked and applied, the
/// chroma planes lifted along them too or plain (`params.chroma`). Returns the directions.
pub(super) fn forward_planes(
    planes: &mut [Vec<f32>],
    width: usize,
    height: usize,
    levels: u32,
    params: &Params,
) -> DirectionMap {
    let mut map = straight_map(width, height, levels, params);
    let (luma, chroma) = planes.split_first_mut().expect("a plane");
    forward_plane(
        luma,
        width,
        height,
        levels,
        &mut map,
        Mode::Pick(params.margin),
    );
    for plane in chroma {
        if params.chroma {
            forward(plane, width, height, levels, &map);
        } else {
            wavelet::forward_97(plane, width, height, levels);
        }
    }
    map
}

/// The lossy picture from its coefficients (per component: index in the plane, value; values
/// at the same index add up, as chroma from luma's predictions do), the luma (and with
/// `map.chroma` the chroma) synthesised along `map`'s directions.
pub(super) fn synthesise(
    coefficients: &[Vec<(u32, f32)>],
    width: usize,
    height: usize,
    levels: u32,
    map: &DirectionMap,
) -> Image {
    let planes: Vec<Vec<f32>> = coefficients
        .iter()
        .enumerate()
        .map(|(c, coefs)| {
            let mut plane = vec![0.0f32; width * height];
            for &(i, v) in coefs {
                plane[i as usize] += v;
            }
            if c == 0 || map.chroma {
                inverse(&mut plane, width, height, levels, map);
            } else {
                wavelet::inverse_97(&mut plane, width, height, levels);
            }
            plane
        })
        .collect();
    from_components(&planes, width, height, false)
}

/// The map's contexts: per pass, "same as the left block" (by whether the block above is the
/// left one's too) and the three-bit index among the other eight.
#[derive(Default)]
struct Contexts {
    same: [[Context; 2]; 2],
    index: [[Context; 8]; 2],
}

/// The prediction of block `i`'s direction in a pass (the left block's, the block above's in
/// the first column, 0 for the first block) and whether the block above agrees with it.
fn predictions(dirs: &[u8], columns: usize, i: usize) -> (u8, usize) {
    let (x, y) = (i % columns, i / columns);
    let up = (y > 0).then(|| dirs[i - columns]);
    let left = if x > 0 { Some(dirs[i - 1]) } else { up };
    let predicted = left.unwrap_or(STRAIGHT);
    (predicted, usize::from(up == Some(predicted)))
}

impl DirectionMap {
    /// The directions range coded: level by level, finest first, each its horizontal then its
    /// vertical pass's blocks in raster order.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut enc = RangeEncoder::new();
        let mut ctx = Contexts::default();
        for level in &self.levels {
            for (pass, dirs) in [&level.horizontal, &level.vertical].into_iter().enumerate() {
                for (i, &d) in dirs.iter().enumerate() {
                    let (p, agree) = predictions(dirs, level.columns, i);
                    enc.encode(&mut ctx.same[pass][agree], d == p);
                    if d != p {
                        let rank = if d > p { d - 1 } else { d };
                        let mut node = 1;
                        for b in (0..3).rev() {
                            let bit = (rank >> b) & 1 == 1;
                            enc.encode(&mut ctx.index[pass][node], bit);
                            node = 2 * node + usize::from(bit);
                        }
                    }
                }
            }
        }
        enc.finish()
    }

    /// Reads what [`to_bytes`](Self::to_bytes) wrote into a map of this map's layout (block,
    /// grids); any bytes give some map.
    pub fn read_bytes(&mut self, data: &[u8]) {
        let mut dec = RangeDecoder::new(data);
        let mut ctx = Contexts::default();
        for level in &mut self.levels {
            let columns = level.columns;
            for (pass, dirs) in [&mut level.horizontal, &mut level.vertical]
                .into_iter()
                .enumerate()
            {
                for i in 0..dirs.len() {
                    let (p, agree) = predictions(dirs, columns, i);
                    dirs[i] = if dec.decode(&mut ctx.same[pass][agree]) {
                        p
                    } else {
                        let mut node = 1;
                        for _ in 0..3 {
                            let bit = dec.decode(&mut ctx.index[pass][node]);
                            node = 2 * node + usize::from(bit);
                        }
                        let rank = (node - 8) as u8;
                        if rank >= p { rank + 1 } else { rank }
                    };
                }
            }
        }
    }

    /// Share of blocks (over levels and passes) with a direction other than 0.
    pub fn oblique_share(&self) -> f64 {
        let all = self
            .levels
            .iter()
            .flat_map(|l| l.horizontal.iter().chain(&l.vertical));
        let (n, oblique) = all.fold((0, 0), |(n, o), &d| (n + 1, o + usize::from(d != STRAIGHT)));
        oblique as f64 / n.max(1) as f64
    }
}

/// Rejects options the prototype does not handle.
pub(super) fn check(lossless: bool, segmented: bool, restore: bool) -> Result<(), Error> {
    if lossless || segmented || restore {
        return Err(Error::Setting {
            field: "directions",
            expected: "a lossy stream without segments or restoration",
            found: 1,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small xorshift generator: the tests need no crate.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
    }

    fn random_map(
        width: usize,
        height: usize,
        levels: u32,
        block: usize,
        rng: &mut Rng,
    ) -> DirectionMap {
        let params = Params {
            levels,
            block,
            ..Params::default()
        };
        let mut map = straight_map(width, height, levels, &params);
        for l in &mut map.levels {
            for d in l.horizontal.iter_mut().chain(l.vertical.iter_mut()) {
                *d = (rng.next() % 9) as u8;
            }
        }
        map
    }

    fn random_plane(n: usize, rng: &mut Rng) -> Vec<f32> {
        (0..n).map(|_| (rng.next() % 256) as f32 - 128.0).collect()
    }

    #[test]
    fn directional_transform_inverts_for_random_directions() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        for (w, h, levels, adl, block) in [
            (1, 1, 0, 0, 4),
            (2, 3, 1, 1, 1),
            (17, 9, 3, 2, 4),
            (64, 48, 4, 3, 8),
            (33, 70, 5, 2, 16),
            (100, 1, 2, 2, 8),
            (1, 57, 3, 2, 8),
        ] {
            let map = random_map(w, h, adl, block, &mut rng);
            let orig = random_plane(w * h, &mut rng);
            let mut buf = orig.clone();
            forward(&mut buf, w, h, levels, &map);
            inverse(&mut buf, w, h, levels, &map);
            let err = buf
                .iter()
                .zip(&orig)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(
                err < 1e-3,
                "{w}x{h}, {adl} of {levels} levels: max error {err}"
            );
        }
    }

    #[test]
    fn straight_directions_are_the_plain_transform() {
        let mut rng = Rng(7);
        let (w, h, levels) = (45, 38, 4);
        let orig = random_plane(w * h, &mut rng);
        let map = straight_map(
            w,
            h,
            levels,
            &Params {
                levels: 3,
                ..Params::default()
            },
        );
        let mut directional = orig.clone();
        forward(&mut directional, w, h, levels, &map);
        let mut plain = orig;
        wavelet::forward_97(&mut plain, w, h, levels);
        assert_eq!(directional, plain);
    }

    #[test]
    fn chosen_directions_follow_an_oblique_edge_and_survive_coding() {
        // Diagonal stripes: direction 0 leaves large residuals, the diagonal none.
        let (w, h) = (64, 64);
        let plane: Vec<f32> = (0..w * h)
            .map(|i| {
                if ((i % w) + (i / w)) % 8 < 4 {
                    60.0
                } else {
                    -60.0
                }
            })
            .collect();
        let mut planes = vec![plane.clone()];
        let map = forward_planes(&mut planes, w, h, 3, &Params::default());
        // The stripes run along x + y = constant: one column on, one row up (index 1, -4
        // quarter samples), which leaves the vertical pass nothing oblique to follow.
        for level in &map.levels {
            assert!(level.horizontal.iter().all(|&d| d == 1), "{map:?}");
        }
        assert!(map.oblique_share() >= 0.5, "{map:?}");
        let mut read = straight_map(w, h, 3, &Params::default());
        read.read_bytes(&map.to_bytes());
        assert_eq!(read, map);
        inverse(&mut planes[0], w, h, 3, &map);
        let err = planes[0]
            .iter()
            .zip(&plane)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(err < 1e-3, "max error {err}");
    }
}
