//! Image quality figures for compression trials: PSNR over all channels, PSNR of luma, and
//! SSIM of luma (Wang et al. 2004: 11x11 Gaussian window, sigma 1.5, K1 0.01, K2 0.03).

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

/// Mean SSIM of the luma of two images of the same size (1 for identical images).
pub fn ssim(a: &Image, b: &Image) -> f64 {
    let (w, h) = (a.width, a.height);
    let (x, y) = (luma(a), luma(b));
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    let mul = |p: &[f64], q: &[f64]| p.iter().zip(q).map(|(u, v)| u * v).collect::<Vec<f64>>();
    let (mx, my) = (blur(&x, w, h), blur(&y, w, h));
    let (sxx, syy, sxy) = (
        blur(&mul(&x, &x), w, h),
        blur(&mul(&y, &y), w, h),
        blur(&mul(&x, &y), w, h),
    );
    let total: f64 = (0..x.len())
        .map(|i| {
            let (ux, uy) = (mx[i], my[i]);
            let (vx, vy, cxy) = (sxx[i] - ux * ux, syy[i] - uy * uy, sxy[i] - ux * uy);
            ((2.0 * ux * uy + c1) * (2.0 * cxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
        })
        .sum();
    total / x.len() as f64
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
