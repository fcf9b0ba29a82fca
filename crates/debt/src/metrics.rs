//! Image quality figures for compression trials: PSNR over all channels, PSNR of luma, SSIM of
//! luma (Wang et al. 2004: 11x11 Gaussian window, sigma 1.5, K1 0.01, K2 0.03) and MS-SSIM of
//! luma (Wang, Simoncelli, Bovik 2003: five scales by 2x2 means, the same window at each).

use super::Image;

/// Luma (BT.601) of every pixel, as `f64`.
pub fn luma(img: &Image) -> Vec<f64> {
    if img.channels == 1 {
        return img.data.iter().map(|&v| f64::from(v)).collect();
    }
    img.data
        .chunks_exact(3)
        .map(|p| 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]))
        .collect()
}

fn psnr_of(sse: f64, count: usize) -> f64 {
    if sse == 0.0 {
        return f64::INFINITY;
    }
    10.0 * (255.0f64 * 255.0 / (sse / count as f64)).log10()
}

/// PSNR in dB over every sample of two images of the same shape (RGB PSNR for colour).
pub fn psnr(a: &Image, b: &Image) -> f64 {
    let sse: f64 = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum();
    psnr_of(sse, a.data.len())
}

/// PSNR in dB of the luma of two images.
pub fn psnr_y(a: &Image, b: &Image) -> f64 {
    let (ya, yb) = (luma(a), luma(b));
    let sse: f64 = ya.iter().zip(&yb).map(|(x, y)| (x - y).powi(2)).sum();
    psnr_of(sse, ya.len())
}

/// Separable Gaussian blur with the SSIM window (11 taps, sigma 1.5), borders clamped.
fn blur(v: &[f64], width: usize, height: usize) -> Vec<f64> {
    let kernel: Vec<f64> = {
        let k: Vec<f64> = (-5i32..=5)
            .map(|i| (-(f64::from(i * i)) / (2.0 * 1.5 * 1.5)).exp())
            .collect();
        let sum: f64 = k.iter().sum();
        k.iter().map(|x| x / sum).collect()
    };
    let clamp = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
    let mut rows = vec![0.0; v.len()];
    for y in 0..height {
        for x in 0..width {
            rows[y * width + x] = kernel
                .iter()
                .enumerate()
                .map(|(k, w)| w * v[y * width + clamp(x as isize + k as isize - 5, width)])
                .sum();
        }
    }
    let mut out = vec![0.0; v.len()];
    for y in 0..height {
        for x in 0..width {
            out[y * width + x] = kernel
                .iter()
                .enumerate()
                .map(|(k, w)| w * rows[clamp(y as isize + k as isize - 5, height) * width + x])
                .sum();
        }
    }
    out
}

/// The means over the image of SSIM's luminance term and of its contrast-structure term, for
/// two luma planes of `w` x `h`.
fn ssim_terms(x: &[f64], y: &[f64], w: usize, h: usize) -> (f64, f64, f64) {
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    let mul = |p: &[f64], q: &[f64]| p.iter().zip(q).map(|(u, v)| u * v).collect::<Vec<f64>>();
    let (mx, my) = (blur(x, w, h), blur(y, w, h));
    let (sxx, syy, sxy) = (
        blur(&mul(x, x), w, h),
        blur(&mul(y, y), w, h),
        blur(&mul(x, y), w, h),
    );
    let (mut ssim, mut luminance, mut contrast) = (0.0, 0.0, 0.0);
    for i in 0..x.len() {
        let (ux, uy) = (mx[i], my[i]);
        let (vx, vy, cxy) = (sxx[i] - ux * ux, syy[i] - uy * uy, sxy[i] - ux * uy);
        let l = (2.0 * ux * uy + c1) / (ux * ux + uy * uy + c1);
        let cs = (2.0 * cxy + c2) / (vx + vy + c2);
        ssim += l * cs;
        luminance += l;
        contrast += cs;
    }
    let n = x.len().max(1) as f64;
    (ssim / n, luminance / n, contrast / n)
}

/// Mean SSIM of the luma of two images of the same size (1 for identical images).
pub fn ssim(a: &Image, b: &Image) -> f64 {
    ssim_terms(&luma(a), &luma(b), a.width, a.height).0
}

/// MS-SSIM's weights of its five scales (Wang, Simoncelli, Bovik 2003), finest first.
pub const MS_SSIM_WEIGHTS: [f64; 5] = [0.0448, 0.2856, 0.3001, 0.2363, 0.1333];

/// Halves a plane by 2x2 means (an odd last row or column dropped).
fn halve(v: &[f64], w: usize, h: usize) -> (Vec<f64>, usize, usize) {
    let (hw, hh) = (w / 2, h / 2);
    let mut out = Vec::with_capacity(hw * hh);
    for y in 0..hh {
        for x in 0..hw {
            let at = |dx: usize, dy: usize| v[(2 * y + dy) * w + 2 * x + dx];
            out.push((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1)) / 4.0);
        }
    }
    (out, hw, hh)
}

/// Multi-scale SSIM of the luma of two images of the same size (1 for identical images): the
/// contrast-structure term at each of five scales (each half the last, by 2x2 means) and the
/// luminance term at the coarsest, weighted by [`MS_SSIM_WEIGHTS`]. An image too small for five
/// scales (a side under 176 pixels) uses the scales it has, down to a side of 11 pixels (the
/// window), with their weights renormalised; negative terms count as 0.
pub fn ms_ssim(a: &Image, b: &Image) -> f64 {
    let (mut x, mut y, mut w, mut h) = (luma(a), luma(b), a.width, a.height);
    let mut terms = Vec::new();
    for scale in 0..MS_SSIM_WEIGHTS.len() {
        let (_, luminance, contrast) = ssim_terms(&x, &y, w, h);
        terms.push((contrast.max(0.0), luminance.max(0.0)));
        if scale + 1 == MS_SSIM_WEIGHTS.len() || w / 2 < 11 || h / 2 < 11 {
            break;
        }
        (x, _, _) = halve(&x, w, h);
        (y, w, h) = halve(&y, w, h);
    }
    let weights = &MS_SSIM_WEIGHTS[..terms.len()];
    let total: f64 = weights.iter().sum();
    let last = terms.len() - 1;
    terms
        .iter()
        .zip(weights)
        .enumerate()
        .map(|(k, (&(cs, l), &wt))| {
            let term = if k == last { cs * l } else { cs };
            term.powf(wt / total)
        })
        .product()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(data: Vec<u8>, w: usize, h: usize, c: usize) -> Image {
        Image {
            width: w,
            height: h,
            channels: c,
            data,
        }
    }

    #[test]
    fn identical_and_known_error() {
        let a = image((0..48u8).collect(), 4, 4, 3);
        assert_eq!(psnr(&a, &a), f64::INFINITY);
        assert!((ssim(&a, &a) - 1.0).abs() < 1e-12);
        // Every sample off by 1: MSE 1, PSNR 48.13 dB.
        let b = image(a.data.iter().map(|v| v + 1).collect(), 4, 4, 3);
        assert!((psnr(&a, &b) - 48.1308).abs() < 1e-3);
        assert!((psnr_y(&a, &b) - 48.1308).abs() < 1e-3);
    }

    #[test]
    fn ms_ssim_is_one_for_identical_images_and_falls_with_noise() {
        let base: Vec<u8> = (0..200 * 180)
            .map(|i| (((i % 200) / 4 + (i / 200) / 3) * 5 % 256) as u8)
            .collect();
        let a = image(base.clone(), 200, 180, 1);
        assert!((ms_ssim(&a, &a) - 1.0).abs() < 1e-12);
        let noisy = |amount: usize| {
            let data = base
                .iter()
                .enumerate()
                .map(|(i, &v)| v.saturating_add(((i * 7919) % (amount + 1)) as u8))
                .collect();
            image(data, 200, 180, 1)
        };
        let (mild, strong) = (ms_ssim(&a, &noisy(4)), ms_ssim(&a, &noisy(60)));
        assert!(
            1.0 > mild && mild > strong && strong > 0.0,
            "{mild} {strong}"
        );
        // A picture too small for five scales still gets a figure.
        let small = image(base[..20 * 20].to_vec(), 20, 20, 1);
        assert!((ms_ssim(&small, &small) - 1.0).abs() < 1e-12);
        let tiny = image(vec![7; 4], 2, 2, 1);
        assert!(ms_ssim(&tiny, &tiny).is_finite());
    }

    #[test]
    fn ssim_falls_with_noise() {
        let base: Vec<u8> = (0..32 * 32).map(|i| ((i % 32) * 8) as u8).collect();
        let a = image(base.clone(), 32, 32, 1);
        let mild = image(
            base.iter()
                .enumerate()
                .map(|(i, &v)| v.saturating_add((i % 3) as u8))
                .collect(),
            32,
            32,
            1,
        );
        let strong = image(
            base.iter()
                .enumerate()
                .map(|(i, &v)| v.saturating_add(((i * 37) % 64) as u8))
                .collect(),
            32,
            32,
            1,
        );
        let (s1, s2) = (ssim(&a, &mild), ssim(&a, &strong));
        assert!(1.0 > s1 && s1 > s2, "{s1} {s2}");
    }
}
