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

/// Lanes of the dot products and filter sums: a multiple of every SIMD width the compiler may
/// use, so that the lane loops below vectorise.
const LANES: usize = 16;

/// Rows of at least this many pixels a thread (below, one thread does the whole picture).
const PIXELS_PER_THREAD: usize = 1 << 16;

/// The rows `0..height` cut into one stripe per thread: as many threads as the machine has
/// cores (at most 8), and no more than leave [`PIXELS_PER_THREAD`] pixels each.
fn stripes(width: usize, height: usize) -> Vec<std::ops::Range<usize>> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get().min(8));
    let threads = cores
        .min((width * height / PIXELS_PER_THREAD).max(1))
        .min(height.max(1));
    (0..threads)
        .map(|t| t * height / threads..(t + 1) * height / threads)
        .collect()
}

/// `work` run on each stripe's item, in parallel when there is more than one; results in
/// stripe order, so a sum over them does not depend on the number of threads.
fn each_stripe<I: Send, T: Send>(items: Vec<I>, work: impl Fn(I) -> T + Sync) -> Vec<T> {
    if items.len() <= 1 {
        return items.into_iter().map(&work).collect();
    }
    std::thread::scope(|scope| {
        let work = &work;
        let handles: Vec<_> = items
            .into_iter()
            .map(|item| scope.spawn(move || work(item)))
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
            })
            .collect()
    })
}

/// The dot product of two rows of `i16`, in lanes the compiler vectorises. Exact while the
/// sum fits in `i32` (rows of at most 4096 samples of magnitude at most 510).
fn dot(a: &[i16], b: &[i16]) -> i32 {
    let mut lanes = [0i32; LANES];
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: i32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(&x, &y)| i32::from(x) * i32::from(y))
        .sum();
    for (x, y) in ca.zip(cb) {
        for l in 0..LANES {
            lanes[l] += i32::from(x[l]) * i32::from(y[l]);
        }
    }
    lanes.iter().sum::<i32>() + tail
}

/// The 12 feature rows of row `y` of a padded plane `pw` wide holding `w` samples a row: for
/// each offset, each pixel's mirrored pair's sum less twice its centre (|f| <= 510).
fn feature_rows(plane: &[i16], pw: usize, w: usize, y: usize, rows: &mut [Vec<i16>; TAPS]) {
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
                .map(|((&p, &q), &c)| p + q - 2 * c),
        );
    }
}

/// One channel's normal equations over some rows, in integers: the upper triangle of `A`,
/// `b`, and the residual's energy `e.e`.
#[derive(Clone, Copy)]
struct Sums {
    a: [[i64; TAPS]; TAPS],
    b: [i64; TAPS],
    ee: i64,
}

impl Sums {
    const ZERO: Sums = Sums {
        a: [[0; TAPS]; TAPS],
        b: [0; TAPS],
        ee: 0,
    };

    fn add(&mut self, other: &Sums) {
        for (row, o) in self.a.iter_mut().zip(&other.a) {
            for (v, o) in row.iter_mut().zip(o) {
                *v += o;
            }
        }
        for (v, o) in self.b.iter_mut().zip(&other.b) {
            *v += o;
        }
        self.ee += other.ee;
    }
}

/// Fits the filter that brings `decoded` closest to `original` (same size and channels; else
/// the identity), from every `row_step`-th row.
pub fn fit(decoded: &Image, original: &Image, row_step: usize) -> Filter {
    fit_sums(decoded, original, row_step).0
}

/// [`fit`], and each channel's residual energy (`e.e` unfiltered) over the rows used.
fn fit_sums(decoded: &Image, original: &Image, row_step: usize) -> (Filter, Vec<i64>) {
    let same = decoded.width == original.width
        && decoded.height == original.height
        && decoded.channels == original.channels
        && decoded.data.len() == original.data.len()
        && decoded.data.len() == decoded.width * decoded.height * decoded.channels;
    if !same || decoded.data.is_empty() {
        let identity = Filter {
            channels: vec![[0; TAPS]; decoded.channels],
        };
        return (identity, vec![0; decoded.channels]);
    }
    let (w, h, n) = (decoded.width, decoded.height, decoded.channels);
    let pw = w + 4;
    let step = row_step.max(1);
    let planes: Vec<Vec<i16>> = (0..n).map(|c| padded(decoded, c)).collect();
    let partial = each_stripe(stripes(w, h), |rows| {
        let mut features: [Vec<i16>; TAPS] = std::array::from_fn(|_| Vec::with_capacity(w));
        let mut residual = Vec::with_capacity(w);
        let mut sums = vec![Sums::ZERO; n];
        // Every `step`-th row of the picture, whichever stripe it falls in.
        for y in rows.filter(|y| y % step == 0) {
            let line = y * w * n;
            let (o, d) = (&original.data[line..], &decoded.data[line..]);
            for (c, (plane, s)) in planes.iter().zip(sums.iter_mut()).enumerate() {
                feature_rows(plane, pw, w, y, &mut features);
                residual.clear();
                residual.extend((0..w).map(|x| i16::from(o[x * n + c]) - i16::from(d[x * n + c])));
                s.ee += i64::from(dot(&residual, &residual));
                for j in 0..TAPS {
                    s.b[j] += i64::from(dot(&features[j], &residual));
                    for k in j..TAPS {
                        s.a[j][k] += i64::from(dot(&features[j], &features[k]));
                    }
                }
            }
        }
        sums
    });
    let mut total = vec![Sums::ZERO; n];
    for sums in &partial {
        for (t, s) in total.iter_mut().zip(sums) {
            t.add(s);
        }
    }
    let channels = total
        .iter()
        .map(|s| {
            let a: [[f64; TAPS]; TAPS] =
                std::array::from_fn(|j| std::array::from_fn(|k| s.a[j.min(k)][j.max(k)] as f64));
            quantised(&a, &s.b.map(|v| v as f64), s.ee as f64)
        })
        .collect();
    (Filter { channels }, total.iter().map(|s| s.ee).collect())
}

/// [`fit`], then each channel's taps dropped unless filtering (in integers, as the decoder
/// does) really lowers that channel's squared error against `original`: the filtered picture
/// is never further from the original than the unfiltered one.
pub fn fit_checked(decoded: &Image, original: &Image) -> Filter {
    let (mut filter, unfiltered) = fit_sums(decoded, original, 1);
    if filter.is_identity() {
        return filter;
    }
    let (w, h, n) = (decoded.width, decoded.height, decoded.channels);
    let filtered = Planes::of(decoded, &filter).filter(w, h, n, None, Some(original));
    for ((taps, before), after) in filter.channels.iter_mut().zip(unfiltered).zip(filtered) {
        if after >= before {
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
    apply_in_place(&mut out, filter);
    out
}

/// [`apply`] on the picture itself.
pub fn apply_in_place(img: &mut Image, filter: &Filter) {
    if img.data.len() != img.width * img.height * img.channels || img.data.is_empty() {
        return;
    }
    let planes = Planes::of(img, filter);
    let (w, h, n) = (img.width, img.height, img.channels);
    planes.filter(w, h, n, Some(&mut img.data), None);
}

/// The padded planes of the channels a filter changes, with their taps.
struct Planes {
    channels: Vec<(usize, [i8; TAPS], Vec<i16>)>,
}

impl Planes {
    fn of(img: &Image, filter: &Filter) -> Planes {
        let channels = filter
            .channels
            .iter()
            .take(img.channels)
            .enumerate()
            .filter(|(_, taps)| taps.iter().any(|&t| t != 0))
            .map(|(c, &taps)| (c, taps, padded(img, c)))
            .collect();
        Planes { channels }
    }

    /// Filters the planes (of a `w` x `h` picture of `n` channels), stripe by stripe in
    /// parallel: writes each filtered channel into `out` (interleaved) when given, and returns
    /// each channel's squared error against `original` after filtering when given (zero for
    /// the channels without taps, and without `original`).
    fn filter(
        &self,
        w: usize,
        h: usize,
        n: usize,
        out: Option<&mut [u8]>,
        original: Option<&Image>,
    ) -> Vec<i64> {
        let pw = w + 4;
        let stripes = stripes(w, h);
        // Each stripe's share of the output, cut at its rows.
        let mut items: Vec<(std::ops::Range<usize>, Option<&mut [u8]>)> = Vec::new();
        match out {
            Some(mut rest) => {
                for rows in stripes {
                    let (share, tail) = rest.split_at_mut(rows.len() * w * n);
                    items.push((rows, Some(share)));
                    rest = tail;
                }
            }
            None => items.extend(stripes.into_iter().map(|rows| (rows, None))),
        }
        let errors = each_stripe(items, |(rows, mut share)| {
            let mut acc = vec![0i32; w];
            let mut sse = vec![0i64; n];
            for y in rows.clone() {
                for (c, taps, plane) in &self.channels {
                    let start = (y + 2) * pw + 2;
                    let centre = &plane[start..][..w];
                    // x + (128 + sum_k t_k (x(+d_k) + x(-d_k)) - 2 T x) / 256, T = sum of t_k.
                    let total: i32 = taps.iter().map(|&t| i32::from(t)).sum();
                    for (a, &x) in acc.iter_mut().zip(centre) {
                        *a = TAP_SCALE / 2 - 2 * total * i32::from(x);
                    }
                    for (&(dx, dy), &t) in OFFSETS.iter().zip(taps) {
                        if t != 0 {
                            let s = dy as isize * pw as isize + dx as isize;
                            let ahead = &plane[start.wrapping_add_signed(s)..][..w];
                            let behind = &plane[start.wrapping_add_signed(-s)..][..w];
                            add_pairs(&mut acc, ahead, behind, i32::from(t));
                        }
                    }
                    let values = acc.iter().zip(centre).map(|(&a, &x)| {
                        (i32::from(x) + a.div_euclid(TAP_SCALE)).clamp(0, 255) as u8
                    });
                    if let Some(share) = share.as_deref_mut() {
                        let line = &mut share[(y - rows.start) * w * n..][..w * n];
                        for (pixel, v) in line.chunks_exact_mut(n).zip(values.clone()) {
                            pixel[*c] = v;
                        }
                    }
                    if let Some(original) = original {
                        let o = &original.data[y * w * n..][..w * n];
                        sse[*c] += o
                            .iter()
                            .skip(*c)
                            .step_by(n)
                            .zip(values)
                            .map(|(&o, v)| i64::from(o.abs_diff(v)).pow(2))
                            .sum::<i64>();
                    }
                }
            }
            sse
        });
        let mut total = vec![0i64; n];
        for sse in errors {
            for (t, s) in total.iter_mut().zip(sse) {
                *t += s;
            }
        }
        total
    }
}

/// `acc[x] += t * (ahead[x] + behind[x])`, in lanes the compiler vectorises.
fn add_pairs(acc: &mut [i32], ahead: &[i16], behind: &[i16], t: i32) {
    for ((a, &p), &q) in acc.iter_mut().zip(ahead).zip(behind) {
        *a += t * (i32::from(p) + i32::from(q));
    }
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
