//! Two-dimensional discrete wavelet transforms by lifting, in place, Mallat layout, for any
//! image size (odd sizes included) with whole-sample symmetric extension at the borders:
//! - CDF 9/7 (JPEG 2000's irreversible filter) on `f32`, for lossy coding;
//! - LeGall 5/3 (JPEG 2000's reversible filter) on `i32`, for lossless coding.
//!
//! One level transforms the current low-pass region: rows, then columns; the low half goes
//! first (left, top). Both directions run the same 1-D lifting code on "lanes": a column pass
//! lifts whole rows at once (vectorisable), a row pass lifts single samples.

/// A lifting kernel on samples of type `T`, over `lanes` interleaved lanes.
trait Kernel<T> {
    /// Low (`s`, `ns` elements) and high (`d`, `nd` elements) halves, forward.
    fn forward(s: &mut [T], d: &mut [T], lanes: usize);
    /// The exact inverse of [`forward`](Self::forward).
    fn inverse(s: &mut [T], d: &mut [T], lanes: usize);
}

/// Index of the right neighbour of low sample `i` for high sample `i` (mirrored at the end).
#[inline]
fn next_low(i: usize, ns: usize) -> usize {
    if i + 1 < ns { i + 1 } else { ns - 1 }
}

/// The two high samples around low sample `i` (mirrored at both ends).
#[inline]
fn high_pair(i: usize, nd: usize) -> (usize, usize) {
    (i.saturating_sub(1).min(nd - 1), i.min(nd - 1))
}

fn predict_f32(d: &mut [f32], s: &[f32], lanes: usize, coef: f32) {
    let (ns, nd) = (s.len() / lanes, d.len() / lanes);
    if lanes == 1 {
        // One lane (a row): plain slices, so the loop vectorises.
        let pairs = nd.min(ns - 1);
        for ((x, &p), &q) in d[..pairs].iter_mut().zip(&s[..pairs]).zip(&s[1..=pairs]) {
            *x += coef * (p + q);
        }
        for i in pairs..nd {
            d[i] += coef * (s[i] + s[next_low(i, ns)]);
        }
        return;
    }
    for i in 0..nd {
        let (a, b) = (i * lanes, next_low(i, ns) * lanes);
        let (sa, sb) = (&s[a..a + lanes], &s[b..b + lanes]);
        for ((x, &p), &q) in d[i * lanes..(i + 1) * lanes].iter_mut().zip(sa).zip(sb) {
            *x += coef * (p + q);
        }
    }
}

fn update_f32(s: &mut [f32], d: &[f32], lanes: usize, coef: f32) {
    let (ns, nd) = (s.len() / lanes, d.len() / lanes);
    if lanes == 1 {
        // s[i] uses d[i-1] and d[i]; the first and (for odd lengths) last are mirrored.
        s[0] += coef * (d[0] + d[0]);
        let inner = ns.min(nd);
        for ((x, &p), &q) in s[1..inner]
            .iter_mut()
            .zip(&d[..inner - 1])
            .zip(&d[1..inner])
        {
            *x += coef * (p + q);
        }
        if ns > nd.max(1) {
            // Odd length: the last low sample mirrors its one high neighbour.
            s[ns - 1] += coef * (d[nd - 1] + d[nd - 1]);
        }
        return;
    }
    for i in 0..ns {
        let (a, b) = high_pair(i, nd);
        let (da, db) = (
            &d[a * lanes..(a + 1) * lanes],
            &d[b * lanes..(b + 1) * lanes],
        );
        for ((x, &p), &q) in s[i * lanes..(i + 1) * lanes].iter_mut().zip(da).zip(db) {
            *x += coef * (p + q);
        }
    }
}

/// CDF 9/7 lifting constants (JPEG 2000 Annex F).
const ALPHA: f32 = -1.586_134_3;
const BETA: f32 = -0.052_980_118;
const GAMMA: f32 = 0.882_911_1;
const DELTA: f32 = 0.443_506_87;
const K: f32 = 1.230_174_1;

/// The CDF 9/7 kernel.
struct Cdf97;

impl Kernel<f32> for Cdf97 {
    fn forward(s: &mut [f32], d: &mut [f32], lanes: usize) {
        predict_f32(d, s, lanes, ALPHA);
        update_f32(s, d, lanes, BETA);
        predict_f32(d, s, lanes, GAMMA);
        update_f32(s, d, lanes, DELTA);
        s.iter_mut().for_each(|x| *x *= 1.0 / K);
        d.iter_mut().for_each(|x| *x *= K / 2.0);
    }

    fn inverse(s: &mut [f32], d: &mut [f32], lanes: usize) {
        s.iter_mut().for_each(|x| *x *= K);
        d.iter_mut().for_each(|x| *x *= 2.0 / K);
        update_f32(s, d, lanes, -DELTA);
        predict_f32(d, s, lanes, -GAMMA);
        update_f32(s, d, lanes, -BETA);
        predict_f32(d, s, lanes, -ALPHA);
    }
}

/// The LeGall 5/3 integer kernel. Wrapping arithmetic: exact for any image (no sum comes near
/// 2^31), and garbage coefficients from a corrupt stream give garbage, not a panic.
struct Legall53;

impl Kernel<i32> for Legall53 {
    fn forward(s: &mut [i32], d: &mut [i32], lanes: usize) {
        let (ns, nd) = (s.len() / lanes, d.len() / lanes);
        for i in 0..nd {
            let (a, b) = (i * lanes, next_low(i, ns) * lanes);
            for j in 0..lanes {
                d[i * lanes + j] =
                    d[i * lanes + j].wrapping_sub(s[a + j].wrapping_add(s[b + j]) >> 1);
            }
        }
        for i in 0..ns {
            let (a, b) = high_pair(i, nd);
            for j in 0..lanes {
                s[i * lanes + j] = s[i * lanes + j].wrapping_add(
                    d[a * lanes + j]
                        .wrapping_add(d[b * lanes + j])
                        .wrapping_add(2)
                        >> 2,
                );
            }
        }
    }

    fn inverse(s: &mut [i32], d: &mut [i32], lanes: usize) {
        let (ns, nd) = (s.len() / lanes, d.len() / lanes);
        for i in 0..ns {
            let (a, b) = high_pair(i, nd);
            for j in 0..lanes {
                s[i * lanes + j] = s[i * lanes + j].wrapping_sub(
                    d[a * lanes + j]
                        .wrapping_add(d[b * lanes + j])
                        .wrapping_add(2)
                        >> 2,
                );
            }
        }
        for i in 0..nd {
            let (a, b) = (i * lanes, next_low(i, ns) * lanes);
            for j in 0..lanes {
                d[i * lanes + j] =
                    d[i * lanes + j].wrapping_add(s[a + j].wrapping_add(s[b + j]) >> 1);
            }
        }
    }
}

/// Size of the low-pass region after `levels` levels.
pub fn low_size(width: usize, height: usize, levels: u32) -> (usize, usize) {
    let mut w = width;
    let mut h = height;
    for _ in 0..levels {
        w = w.div_ceil(2);
        h = h.div_ceil(2);
    }
    (w, h)
}

/// Widest strip of columns a column pass lifts at once: 64 `f32` lanes are four 512-bit
/// vectors per row, and a strip of a 720-row plane (184 KB) stays in a core's L2 cache.
const STRIP_COLUMNS: usize = 64;

/// Lifts `line` (its low half, `ns` samples, then its high half) back into the samples of one
/// row, interleaved into `out`.
fn inverse_row<T: Copy, K: Kernel<T>>(line: &mut [T], ns: usize, out: &mut [T]) {
    let (s, d) = line.split_at_mut(ns);
    K::inverse(s, d, 1);
    for (x, &v) in out.iter_mut().step_by(2).zip(s.iter()) {
        *x = v;
    }
    for (x, &v) in out.iter_mut().skip(1).step_by(2).zip(d.iter()) {
        *x = v;
    }
}

/// The column lifting of one level, forward or inverse, on the top-left `cw` x `ch` region of
/// a `stride`-wide buffer.
fn columns<T: Copy + Default, K: Kernel<T>>(
    buf: &mut [T],
    stride: usize,
    cw: usize,
    ch: usize,
    fwd: bool,
    tmp: &mut Vec<T>,
) {
    if ch < 2 {
        return;
    }
    let ns = ch.div_ceil(2);
    // Strips of at most STRIP_COLUMNS columns, each gathered into the scratch (low rows
    // first), lifted there with the strip's columns as lanes, and put back: the strip stays
    // in cache through the lifting steps, the scratch holds one strip only, and every
    // column sees the same arithmetic as in one block.
    for x0 in (0..cw).step_by(STRIP_COLUMNS) {
        let sw = STRIP_COLUMNS.min(cw - x0);
        let row = |r: usize| &buf[r * stride + x0..r * stride + x0 + sw];
        tmp.clear();
        if fwd {
            for r in (0..ch).step_by(2).chain((1..ch).step_by(2)) {
                tmp.extend_from_slice(row(r));
            }
        } else {
            for r in 0..ch {
                tmp.extend_from_slice(row(r));
            }
        }
        let (s, d) = tmp.split_at_mut(ns * sw);
        if fwd {
            K::forward(s, d, sw);
        } else {
            K::inverse(s, d, sw);
        }
        for r in 0..ch {
            let from = match (fwd, r % 2) {
                (true, _) => r,
                (false, 0) => r / 2,
                (false, _) => ns + r / 2,
            };
            buf[r * stride + x0..r * stride + x0 + sw]
                .copy_from_slice(&tmp[from * sw..(from + 1) * sw]);
        }
    }
}

/// One level, forward or inverse, on the top-left `cw` x `ch` region of a `stride`-wide buffer.
fn level<T: Copy + Default, K: Kernel<T>>(
    buf: &mut [T],
    stride: usize,
    cw: usize,
    ch: usize,
    forward: bool,
    tmp: &mut Vec<T>,
) {
    let rows = |buf: &mut [T], tmp: &mut Vec<T>, fwd: bool| {
        if cw < 2 {
            return;
        }
        let ns = cw.div_ceil(2);
        // The line is overwritten before it is read: grown once, never cleared.
        if tmp.len() < cw {
            tmp.resize(cw, T::default());
        }
        for r in 0..ch {
            let row = &mut buf[r * stride..r * stride + cw];
            let line = &mut tmp[..cw];
            if fwd {
                let (s, d) = line.split_at_mut(ns);
                for (dst, &x) in s.iter_mut().zip(row.iter().step_by(2)) {
                    *dst = x;
                }
                for (dst, &x) in d.iter_mut().zip(row.iter().skip(1).step_by(2)) {
                    *dst = x;
                }
                K::forward(s, d, 1);
                row.copy_from_slice(line);
            } else {
                line.copy_from_slice(row);
                inverse_row::<T, K>(line, ns, row);
            }
        }
    };
    if forward {
        rows(buf, tmp, true);
        columns::<T, K>(buf, stride, cw, ch, true, tmp);
    } else {
        columns::<T, K>(buf, stride, cw, ch, false, tmp);
        rows(buf, tmp, false);
    }
}

fn transform<T: Copy + Default, K: Kernel<T>>(
    buf: &mut [T],
    width: usize,
    height: usize,
    levels: u32,
    forward: bool,
    tmp: &mut Vec<T>,
) {
    assert_eq!(buf.len(), width * height, "buffer is not width x height");
    if forward {
        for l in 0..levels {
            let (cw, ch) = low_size(width, height, l);
            level::<T, K>(buf, width, cw, ch, true, tmp);
        }
    } else {
        for l in (0..levels).rev() {
            let (cw, ch) = low_size(width, height, l);
            level::<T, K>(buf, width, cw, ch, false, tmp);
        }
    }
}

/// The inverse 9/7 transform of `buf`, whose last step (the finest level's row lifting) hands
/// each row of samples, top to bottom, to `row_out` instead of writing it back into `buf`:
/// a caller that only reads the rows once saves a pass over the plane. `scratch` as in
/// [`run_97`]; the rows are the same numbers [`inverse_97`] would leave in `buf`.
pub fn inverse_97_rows(
    buf: &mut [f32],
    width: usize,
    height: usize,
    levels: u32,
    scratch: &mut Vec<f32>,
    mut row_out: impl FnMut(usize, &[f32]),
) {
    assert_eq!(buf.len(), width * height, "buffer is not width x height");
    for l in (1..levels).rev() {
        let (cw, ch) = low_size(width, height, l);
        level::<f32, Cdf97>(buf, width, cw, ch, false, scratch);
    }
    // The finest level: its columns as [`level`] lifts them, then each row from a line (a
    // row one sample wide, or an image without levels, has no row lifting).
    if levels > 0 {
        columns::<f32, Cdf97>(buf, width, width, height, false, scratch);
    }
    if levels == 0 || width < 2 {
        for (r, row) in buf.chunks_exact(width).enumerate() {
            row_out(r, row);
        }
        return;
    }
    let ns = width.div_ceil(2);
    let mut line = vec![0.0; width];
    let mut out = vec![0.0; width];
    for (r, row) in buf.chunks_exact(width).enumerate() {
        line.copy_from_slice(row);
        inverse_row::<f32, Cdf97>(&mut line, ns, &mut out);
        row_out(r, &out);
    }
}

/// Forward 9/7 transform, `levels` levels, in place.
pub fn forward_97(buf: &mut [f32], width: usize, height: usize, levels: u32) {
    run_97(buf, width, height, levels, true, &mut Vec::new());
}

/// Inverse 9/7 transform.
pub fn inverse_97(buf: &mut [f32], width: usize, height: usize, levels: u32) {
    run_97(buf, width, height, levels, false, &mut Vec::new());
}

/// The 9/7 transform, forward or inverse, with a scratch buffer the caller keeps for the next
/// plane (it grows to the plane's size; its contents do not matter).
pub fn run_97(
    buf: &mut [f32],
    width: usize,
    height: usize,
    levels: u32,
    forward: bool,
    scratch: &mut Vec<f32>,
) {
    transform::<f32, Cdf97>(buf, width, height, levels, forward, scratch);
}

/// Forward 5/3 integer transform, in place.
pub fn forward_53(buf: &mut [i32], width: usize, height: usize, levels: u32) {
    run_53(buf, width, height, levels, true, &mut Vec::new());
}

/// Inverse 5/3 integer transform.
pub fn inverse_53(buf: &mut [i32], width: usize, height: usize, levels: u32) {
    run_53(buf, width, height, levels, false, &mut Vec::new());
}

/// The 5/3 transform, forward or inverse, with a reusable scratch buffer (see [`run_97`]).
pub fn run_53(
    buf: &mut [i32],
    width: usize,
    height: usize,
    levels: u32,
    forward: bool,
    scratch: &mut Vec<i32>,
) {
    transform::<i32, Legall53>(buf, width, height, levels, forward, scratch);
}

/// Subband orientation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Orientation {
    /// Low-pass in both directions (only at the coarsest level).
    Ll,
    /// High-pass horizontally (vertical edges).
    Hl,
    /// High-pass vertically (horizontal edges).
    Lh,
    /// High-pass in both directions.
    Hh,
}

/// A rectangle of coefficients in the Mallat layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Subband {
    /// Decomposition level, 1 = finest; the LL band has the coarsest level.
    pub level: u32,
    /// Orientation.
    pub orientation: Orientation,
    /// Left column in the buffer.
    pub x0: usize,
    /// Top row in the buffer.
    pub y0: usize,
    /// Width.
    pub width: usize,
    /// Height.
    pub height: usize,
}

/// The subbands in coding order: LL, then HL, LH, HH from the coarsest level to the finest.
/// Empty subbands (of images smaller than 2^levels) are left out.
pub fn subbands(width: usize, height: usize, levels: u32) -> Vec<Subband> {
    let (lw, lh) = low_size(width, height, levels);
    let mut out = vec![Subband {
        level: levels,
        orientation: Orientation::Ll,
        x0: 0,
        y0: 0,
        width: lw,
        height: lh,
    }];
    for l in (1..=levels).rev() {
        let (pw, ph) = low_size(width, height, l - 1);
        let (lw, lh) = low_size(width, height, l);
        let (hw, hh) = (pw - lw, ph - lh);
        for (orientation, x0, y0, w, h) in [
            (Orientation::Hl, lw, 0, hw, lh),
            (Orientation::Lh, 0, lh, lw, hh),
            (Orientation::Hh, lw, lh, hw, hh),
        ] {
            if w > 0 && h > 0 {
                out.push(Subband {
                    level: l,
                    orientation,
                    x0,
                    y0,
                    width: w,
                    height: h,
                });
            }
        }
    }
    out
}

/// L2 norm of the 9/7 synthesis basis function of each subband (the factor by which a unit
/// error in a coefficient becomes squared error in pixels, square-rooted), for weighting
/// coefficients so that one bit-plane is worth the same distortion in every subband.
pub fn synthesis_norms_97(levels: u32) -> Vec<(u32, Orientation, f32)> {
    // 1-D gains of a low or high coefficient at each level, measured on a signal of 64
    // coefficients at that level: the basis function, centred, stays far from the ends, so a
    // longer signal only adds exact zeros (the same norms as 64 << levels samples for every
    // level, at a fraction of the cost: the decoder computes them for every image).
    let gain = |level: u32, high: bool| -> f32 {
        let n = 64usize << level.min(10);
        let mut x = vec![0.0f32; n];
        let (lw, _) = low_size(n, 1, level);
        let (pw, _) = low_size(n, 1, level - 1);
        let at = if high { lw + (pw - lw) / 2 } else { lw / 2 };
        x[at] = 1.0;
        inverse_97(&mut x, n, 1, level);
        x.iter().map(|v| v * v).sum::<f32>().sqrt()
    };
    let mut out = Vec::new();
    for l in 1..=levels {
        let (lo, hi) = (gain(l, false), gain(l, true));
        if l == levels {
            out.push((l, Orientation::Ll, lo * lo));
        }
        out.push((l, Orientation::Hl, hi * lo));
        out.push((l, Orientation::Lh, lo * hi));
        out.push((l, Orientation::Hh, hi * hi));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_image(w: usize, h: usize) -> Vec<i32> {
        (0..w * h)
            .map(|i| (((i * 7919) % 251) as i32 + (i % w) as i32) % 256)
            .collect()
    }

    #[test]
    fn legall_53_is_lossless_for_any_size() {
        for (w, h) in [(1, 1), (2, 1), (1, 7), (5, 3), (16, 16), (33, 17), (64, 9)] {
            for levels in 0..=5 {
                let orig = test_image(w, h);
                let mut buf = orig.clone();
                forward_53(&mut buf, w, h, levels);
                inverse_53(&mut buf, w, h, levels);
                assert_eq!(buf, orig, "{w}x{h}, {levels} levels");
            }
        }
    }

    #[test]
    fn cdf_97_inverts_for_any_size() {
        for (w, h) in [(1, 1), (3, 2), (5, 3), (16, 16), (33, 17), (64, 9)] {
            for levels in 0..=5 {
                let orig: Vec<f32> = test_image(w, h).iter().map(|&v| v as f32).collect();
                let mut buf = orig.clone();
                forward_97(&mut buf, w, h, levels);
                inverse_97(&mut buf, w, h, levels);
                let err = buf
                    .iter()
                    .zip(&orig)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f32::max);
                assert!(err < 1e-3, "{w}x{h}, {levels} levels: max error {err}");
            }
        }
    }

    #[test]
    fn rows_handed_out_are_the_inverse_exactly() {
        for (w, h, levels) in [
            (1, 1, 0),
            (1, 9, 2),
            (9, 1, 2),
            (7, 5, 0),
            (33, 17, 3),
            (130, 70, 5),
        ] {
            let coefs: Vec<f32> = (0..w * h)
                .map(|i| ((i * 37 % 101) as f32 - 50.0) * if i % 7 == 0 { 3.0 } else { 0.1 })
                .collect();
            let mut whole = coefs.clone();
            inverse_97(&mut whole, w, h, levels);
            let mut rows = Vec::new();
            let mut buf = coefs.clone();
            inverse_97_rows(&mut buf, w, h, levels, &mut Vec::new(), |r, row| {
                assert_eq!((r, row.len()), (rows.len() / w, w));
                rows.extend_from_slice(row);
            });
            assert_eq!(rows, whole, "{w}x{h}, {levels} levels");
        }
    }

    #[test]
    fn constant_image_compacts_into_ll() {
        let (w, h) = (32, 24);
        let mut buf = vec![100.0f32; w * h];
        forward_97(&mut buf, w, h, 3);
        for band in subbands(w, h, 3).iter().skip(1) {
            for y in band.y0..band.y0 + band.height {
                for x in band.x0..band.x0 + band.width {
                    assert!(
                        buf[y * w + x].abs() < 1e-2,
                        "{band:?} at ({x},{y}) = {}",
                        buf[y * w + x]
                    );
                }
            }
        }
    }

    #[test]
    fn subbands_tile_the_image() {
        for (w, h, l) in [(17, 9, 3), (640, 360, 5), (1, 1, 2)] {
            let area: usize = subbands(w, h, l).iter().map(|b| b.width * b.height).sum();
            assert_eq!(area, w * h);
        }
    }

    #[test]
    fn norms_are_sane() {
        let norms = synthesis_norms_97(5);
        assert_eq!(norms.len(), 16);
        // The LL band of five levels carries by far the largest gain; HH1 the smallest.
        let ll = norms.iter().find(|n| n.1 == Orientation::Ll).unwrap().2;
        let hh1 = norms
            .iter()
            .find(|n| n.0 == 1 && n.1 == Orientation::Hh)
            .unwrap()
            .2;
        assert!(ll > 10.0 * hh1, "LL {ll}, HH1 {hh1}");
    }

    #[test]
    fn norms_equal_those_of_a_long_signal() {
        // The weights are part of the format: measured on 64 << levels samples for every level
        // (as first written), they must come out bit for bit the same.
        for levels in 1..=7u32 {
            let n = 64usize << levels;
            let gain = |level: u32, high: bool| -> f32 {
                let mut x = vec![0.0f32; n];
                let (lw, _) = low_size(n, 1, level);
                let (pw, _) = low_size(n, 1, level - 1);
                x[if high { lw + (pw - lw) / 2 } else { lw / 2 }] = 1.0;
                inverse_97(&mut x, n, 1, level);
                x.iter().map(|v| v * v).sum::<f32>().sqrt()
            };
            for (level, orientation, norm) in synthesis_norms_97(levels) {
                let (lo, hi) = (gain(level, false), gain(level, true));
                let long = match orientation {
                    Orientation::Ll => lo * lo,
                    Orientation::Hl | Orientation::Lh => hi * lo,
                    Orientation::Hh => hi * hi,
                };
                assert_eq!(
                    norm.to_bits(),
                    long.to_bits(),
                    "{levels} levels, {level} {orientation:?}"
                );
            }
        }
    }
}
