//! Decoder-side restoration: a small linear (Wiener) filter per image, fitted by the encoder on
//! its own decode and sent in a few bytes, that the decoder applies to the picture it rebuilt.
//!
//! A wavelet coder at a few kilobytes leaves blur and ringing whose shape depends on the image;
//! one fixed filter gains nothing on average, a filter fitted to the image does. The filter of
//! one channel is point-symmetric over a 5 x 5 window with unit DC gain:
//!
//! `out(p) = x(p) + sum_k a_k * (x(p + d_k) + x(p - d_k) - 2 x(p))`
//!
//! over the 12 offsets `d_k` of [`OFFSETS`] (half of the window without its centre), so zero
//! taps are the identity and a flat area is left as it is. The encoder fits the `a_k` by least
//! squares against the original (ridge-regularised, [`fit`]), quantises them to steps of
//! 1/[`TAP_SCALE`] in an `i8` each, and keeps a channel's filter only when the quantised taps
//! still lower its error. The decoder filters in integers ([`apply`]), so every decoder gives
//! the same picture.
//!
//! Nothing here panics: a filter whose channel count does not match the picture leaves the
//! extra channels (or the missing ones) unfiltered; samples past the border are the border's.

use super::Image;

/// The filter's offsets (dx, dy): the half of the 5 x 5 window after its centre in raster
/// order; each stands for itself and its mirror.
pub const OFFSETS: [(i32, i32); 12] = [
    (1, 0),
    (2, 0),
    (-2, 1),
    (-1, 1),
    (0, 1),
    (1, 1),
    (2, 1),
    (-2, 2),
    (-1, 2),
    (0, 2),
    (1, 2),
    (2, 2),
];

/// The smallest budget a version 3 stream is written for: below, the filter's bytes are worth
/// more as payload (measured in docs/debt-format.md's log).
pub const MIN_BUDGET_BYTES: usize = 2000;

/// Taps per channel.
pub const TAPS: usize = OFFSETS.len();

/// A quantised tap `q` is the weight `q / TAP_SCALE`.
pub const TAP_SCALE: i32 = 256;

/// One image's restoration filter: per channel, its quantised taps (all zero: unfiltered).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Filter {
    /// Taps of each channel, in the order of [`OFFSETS`].
    pub channels: Vec<[i8; TAPS]>,
}

impl Filter {
    /// True when no channel is filtered.
    pub fn is_identity(&self) -> bool {
        self.channels
            .iter()
            .all(|taps| taps.iter().all(|&t| t == 0))
    }

    /// The filter as bytes: the taps of each channel in turn, two's complement.
    pub fn to_bytes(&self) -> Vec<u8> {
        self.channels
            .iter()
            .flat_map(|taps| taps.iter().map(|&t| t as u8))
            .collect()
    }

    /// The filter of `channels` channels from [`Filter::to_bytes`]'s output; none when there
    /// are too few bytes.
    pub fn from_bytes(bytes: &[u8], channels: usize) -> Option<Filter> {
        let taps = bytes.get(..channels * TAPS)?;
        Some(Filter {
            channels: taps
                .chunks_exact(TAPS)
                .map(|c| std::array::from_fn(|k| c[k] as i8))
                .collect(),
        })
    }

    /// Bytes of a filter of `channels` channels.
    pub fn len_for(channels: usize) -> usize {
        channels * TAPS
    }
}

/// Channel `c` of `img` padded by 2 samples on every side (the border's samples repeated), so
/// that every pixel's window is in it: width `img.width + 4`.
fn padded(img: &Image, c: usize) -> Vec<i16> {
    let (w, h, n) = (img.width, img.height, img.channels);
    let pw = w + 4;
    let mut plane = Vec::with_capacity(pw * (h + 4));
    for py in 0..h + 4 {
        let y = py.saturating_sub(2).min(h - 1);
        let row = &img.data[y * w * n..(y + 1) * w * n];
        let at = |x: usize| i16::from(row[x * n + c]);
        plane.extend([at(0), at(0)]);
        plane.extend((0..w).map(at));
        plane.extend([at(w - 1), at(w - 1)]);
    }
    plane
}

/// The 12 feature rows of row `y` of a padded plane `pw` wide holding `w` samples a row: for
/// each offset, each pixel's mirrored pair's sum less twice its centre.
fn feature_rows(plane: &[i16], pw: usize, w: usize, y: usize, rows: &mut [Vec<i32>; TAPS]) {
    let start = (y + 2) * pw + 2;
    let centre = &plane[start..start + w];
    for (k, row) in rows.iter_mut().enumerate() {
        let (dx, dy) = OFFSETS[k];
        let s = dy as isize * pw as isize + dx as isize;
        let ahead = &plane[start.wrapping_add_signed(s)..][..w];
        let behind = &plane[start.wrapping_add_signed(-s)..][..w];
        row.clear();
        row.extend(
            ahead
                .iter()
                .zip(behind)
                .zip(centre)
                .map(|((&p, &q), &c)| i32::from(p) + i32::from(q) - 2 * i32::from(c)),
        );
    }
}

/// Fits the filter that brings `decoded` closest to `original` (same size and channels; else
/// the identity), from every `row_step`-th row.
pub fn fit(decoded: &Image, original: &Image, row_step: usize) -> Filter {
    let same = decoded.width == original.width
        && decoded.height == original.height
        && decoded.channels == original.channels
        && decoded.data.len() == original.data.len()
        && decoded.data.len() == decoded.width * decoded.height * decoded.channels;
    if !same || decoded.data.is_empty() {
        return Filter {
            channels: vec![[0; TAPS]; decoded.channels],
        };
    }
    let (w, n) = (decoded.width, decoded.channels);
    let pw = w + 4;
    let step = row_step.max(1);
    let mut rows: [Vec<i32>; TAPS] = std::array::from_fn(|_| Vec::with_capacity(w));
    let mut residual = Vec::with_capacity(w);
    let channels = (0..n)
        .map(|c| {
            let plane = padded(decoded, c);
            // Normal equations of the residual, in integers: A a = b, and e.e for the error.
            // A row's sums fit in i32 (|f| <= 510, |e| <= 255, 4096 samples a row at most).
            let mut a = [[0i64; TAPS]; TAPS];
            let mut b = [0i64; TAPS];
            let mut ee = 0i64;
            for y in (0..decoded.height).step_by(step) {
                feature_rows(&plane, pw, w, y, &mut rows);
                let row = y * w * n;
                let (o, d) = (&original.data[row..], &decoded.data[row..]);
                residual.clear();
                residual.extend((0..w).map(|x| i32::from(o[x * n + c]) - i32::from(d[x * n + c])));
                ee += residual.iter().map(|&e| i64::from(e * e)).sum::<i64>();
                for j in 0..TAPS {
                    let fj = &rows[j];
                    let fe: i32 = fj.iter().zip(&residual).map(|(&f, &e)| f * e).sum();
                    b[j] += i64::from(fe);
                    for k in j..TAPS {
                        let dot: i32 = fj.iter().zip(&rows[k]).map(|(&f, &g)| f * g).sum();
                        a[j][k] += i64::from(dot);
                    }
                }
            }
            let a: [[f64; TAPS]; TAPS] =
                std::array::from_fn(|j| std::array::from_fn(|k| a[j.min(k)][j.max(k)] as f64));
            quantised(&a, &b.map(|v| v as f64), ee as f64)
        })
        .collect();
    Filter { channels }
}

/// [`fit`], then each channel's taps dropped unless filtering (in integers, as the decoder
/// does) really lowers that channel's squared error against `original`: the filtered picture
/// is never further from the original than the unfiltered one.
pub fn fit_checked(decoded: &Image, original: &Image) -> Filter {
    let mut filter = fit(decoded, original, 1);
    if filter.is_identity() {
        return filter;
    }
    let filtered = apply(decoded, &filter);
    let n = decoded.channels;
    for (c, taps) in filter.channels.iter_mut().enumerate() {
        let sse = |img: &Image| -> u64 {
            img.data
                .iter()
                .zip(&original.data)
                .skip(c)
                .step_by(n)
                .map(|(&a, &b)| u64::from(a.abs_diff(b)).pow(2))
                .sum()
        };
        if sse(&filtered) >= sse(decoded) {
            *taps = [0; TAPS];
        }
    }
    filter
}

/// The least-squares taps of `A a = b` (ridge-regularised), quantised; all zero unless the
/// quantised taps lower the error `e.e - 2 a.b + a.A.a` below `ee`.
fn quantised(a: &[[f64; TAPS]; TAPS], b: &[f64; TAPS], ee: f64) -> [i8; TAPS] {
    let Some(weights) = ridge_solve(a, b) else {
        return [0; TAPS];
    };
    let scale = f64::from(TAP_SCALE);
    let q: [i8; TAPS] =
        std::array::from_fn(|k| (weights[k] * scale).round().clamp(-127.0, 127.0) as i8);
    let w: [f64; TAPS] = std::array::from_fn(|k| f64::from(q[k]) / scale);
    let mut error = ee;
    for j in 0..TAPS {
        error -= 2.0 * w[j] * b[j];
        for k in 0..TAPS {
            error += w[j] * a[j][k] * w[k];
        }
    }
    if error < ee { q } else { [0; TAPS] }
}

/// The least-squares solution of the normal equations `A x = b`, ridge-regularised (1e-3 of
/// `A`'s mean diagonal added to it) and solved by Gaussian elimination with partial pivoting;
/// none when singular or not finite.
pub fn ridge_solve<const N: usize>(a: &[[f64; N]; N], b: &[f64; N]) -> Option<[f64; N]> {
    let trace: f64 = (0..N).map(|j| a[j][j]).sum();
    let ridge = 1e-3 * trace / N as f64 + 1e-9;
    let (mut m, mut v) = (*a, *b);
    for (j, row) in m.iter_mut().enumerate() {
        row[j] += ridge;
    }
    for col in 0..N {
        let pivot = (col..N).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        if m[pivot][col].abs() < 1e-12 || !m[pivot][col].is_finite() {
            return None;
        }
        m.swap(col, pivot);
        v.swap(col, pivot);
        let (pivot_row, pivot_v) = (m[col], v[col]);
        for (row, value) in m.iter_mut().zip(v.iter_mut()).skip(col + 1) {
            let f = row[col] / pivot_row[col];
            for (r, p) in row.iter_mut().zip(&pivot_row).skip(col) {
                *r -= f * p;
            }
            *value -= f * pivot_v;
        }
    }
    let mut x = [0f64; N];
    for row in (0..N).rev() {
        let s: f64 = (row + 1..N).map(|k| m[row][k] * x[k]).sum();
        x[row] = (v[row] - s) / m[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// `img` filtered: each channel with its taps (a channel without taps as it was).
pub fn apply(img: &Image, filter: &Filter) -> Image {
    let mut out = img.clone();
    let (w, n) = (img.width, img.channels);
    if img.data.len() != w * img.height * n || img.data.is_empty() {
        return out;
    }
    let pw = w + 4;
    let mut rows: [Vec<i32>; TAPS] = std::array::from_fn(|_| Vec::with_capacity(w));
    let mut acc = vec![0i32; w];
    for (c, taps) in filter.channels.iter().enumerate().take(n) {
        if taps.iter().all(|&t| t == 0) {
            continue;
        }
        let plane = padded(img, c);
        for y in 0..img.height {
            feature_rows(&plane, pw, w, y, &mut rows);
            acc.fill(TAP_SCALE / 2);
            for (row, &t) in rows.iter().zip(taps) {
                let t = i32::from(t);
                for (a, &f) in acc.iter_mut().zip(row) {
                    *a += f * t;
                }
            }
            let line = &mut out.data[y * w * n..(y + 1) * w * n];
            let centre = &plane[(y + 2) * pw + 2..][..w];
            for ((pixel, &a), &x) in line.chunks_exact_mut(n).zip(&acc).zip(centre) {
                pixel[c] = (i32::from(x) + a.div_euclid(TAP_SCALE)).clamp(0, 255) as u8;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(width: usize, height: usize, f: impl Fn(usize, usize) -> u8) -> Image {
        let mut data = Vec::new();
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y));
            }
        }
        Image {
            width,
            height,
            channels: 1,
            data,
        }
    }

    #[test]
    fn zero_taps_are_the_identity_and_a_flat_picture_stays_flat() {
        let img = image(9, 7, |x, y| (x * 20 + y * 3) as u8);
        let none = Filter {
            channels: vec![[0; TAPS]],
        };
        assert!(none.is_identity());
        assert_eq!(apply(&img, &none), img);
        let flat = image(9, 7, |_, _| 100);
        let sharp = Filter {
            channels: vec![[-40; TAPS]],
        };
        assert_eq!(apply(&flat, &sharp), flat);
    }

    #[test]
    fn a_fitted_filter_undoes_a_blur_and_its_bytes_round_trip() {
        // A sharp pattern, and the same after a 3-tap horizontal blur.
        let sharp = image(
            64,
            48,
            |x, y| if (x / 3 + y / 5) % 2 == 0 { 40 } else { 200 },
        );
        let blurred = {
            let mut b = sharp.clone();
            for y in 0..48 {
                for x in 0..64usize {
                    let at = |x: usize| u32::from(sharp.data[y * 64 + x.min(63)]);
                    let l = at(x.saturating_sub(1));
                    b.data[y * 64 + x] = ((l + 2 * at(x) + at(x + 1) + 2) / 4) as u8;
                }
            }
            b
        };
        let filter = fit(&blurred, &sharp, 1);
        assert!(!filter.is_identity());
        let restored = apply(&blurred, &filter);
        let before = super::super::metrics::psnr(&blurred, &sharp);
        let after = super::super::metrics::psnr(&restored, &sharp);
        assert!(after > before + 1.0, "{before} -> {after}");
        let bytes = filter.to_bytes();
        assert_eq!(bytes.len(), Filter::len_for(1));
        assert_eq!(Filter::from_bytes(&bytes, 1), Some(filter));
        assert_eq!(Filter::from_bytes(&bytes[1..], 1), None);
    }

    #[test]
    fn mismatched_pictures_fit_the_identity() {
        let a = image(4, 4, |x, _| x as u8);
        let b = image(5, 4, |x, _| x as u8);
        assert!(fit(&a, &b, 1).is_identity());
    }
}
