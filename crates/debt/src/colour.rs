//! From pixels to the component planes the wavelet transforms, and back: the box-filter
//! downscale by 2^scale (and the bilinear upscale that undoes it), and the colour transforms,
//! JPEG's YCbCr for lossy coding and the reversible RCT (integers held in `f32`) for lossless.

use std::borrow::Cow;

use super::Image;

/// Squared-error weight of Y, Cb, Cr errors in RGB (columns of the inverse ICT, averaged).
pub(super) const COMPONENT_MSE_WEIGHTS: [f32; 3] = [1.0, 1.086, 0.825];

/// Box-filter downscale by 2^scale (scale 0: the image itself, not a copy).
pub(super) fn downscale(img: &Image, scale: u32) -> Cow<'_, Image> {
    if scale == 0 {
        return Cow::Borrowed(img);
    }
    let f = 1usize << scale;
    let (w, h) = (img.width.div_ceil(f), img.height.div_ceil(f));
    let c = img.channels;
    let mut data = vec![0u8; w * h * c];
    for y in 0..h {
        for x in 0..w {
            for ch in 0..c {
                let (mut sum, mut n) = (0u32, 0u32);
                for yy in y * f..((y + 1) * f).min(img.height) {
                    for xx in x * f..((x + 1) * f).min(img.width) {
                        sum += u32::from(img.data[(yy * img.width + xx) * c + ch]);
                        n += 1;
                    }
                }
                data[(y * w + x) * c + ch] = ((sum + n / 2) / n) as u8;
            }
        }
    }
    Cow::Owned(Image {
        width: w,
        height: h,
        channels: c,
        data,
    })
}

/// Bilinear upscale to `width` x `height` (an image of that size is returned as it is).
pub(super) fn upscale(img: Image, width: usize, height: usize) -> Image {
    if img.width == width && img.height == height {
        return img;
    }
    let c = img.channels;
    let (sx, sy) = (
        img.width as f32 / width as f32,
        img.height as f32 / height as f32,
    );
    let mut data = vec![0u8; width * height * c];
    for y in 0..height {
        let fy = ((y as f32 + 0.5) * sy - 0.5).clamp(0.0, (img.height - 1) as f32);
        let (y0, ty) = (fy.floor() as usize, fy - fy.floor());
        let y1 = (y0 + 1).min(img.height - 1);
        for x in 0..width {
            let fx = ((x as f32 + 0.5) * sx - 0.5).clamp(0.0, (img.width - 1) as f32);
            let (x0, tx) = (fx.floor() as usize, fx - fx.floor());
            let x1 = (x0 + 1).min(img.width - 1);
            for ch in 0..c {
                let p = |xx: usize, yy: usize| f32::from(img.data[(yy * img.width + xx) * c + ch]);
                let top = p(x0, y0) * (1.0 - tx) + p(x1, y0) * tx;
                let bottom = p(x0, y1) * (1.0 - tx) + p(x1, y1) * tx;
                data[(y * width + x) * c + ch] =
                    (top * (1.0 - ty) + bottom * ty).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    Image {
        width,
        height,
        channels: c,
        data,
    }
}

/// Component planes of an image, as `f32` (lossy: level-shifted YCbCr) or exact integers held
/// in `f32` (lossless: RCT).
pub(super) fn to_components(img: &Image, gray: bool, lossless: bool) -> Vec<Vec<f32>> {
    let n = img.width * img.height;
    let px = |i: usize| -> (f32, f32, f32) {
        if img.channels == 1 {
            let v = f32::from(img.data[i]);
            (v, v, v)
        } else {
            let p = &img.data[i * 3..i * 3 + 3];
            (f32::from(p[0]), f32::from(p[1]), f32::from(p[2]))
        }
    };
    if gray {
        let y = (0..n)
            .map(|i| {
                let (r, g, b) = px(i);
                if img.channels == 1 {
                    r - 128.0
                } else if lossless {
                    ((r + 2.0 * g + b) / 4.0).floor() - 128.0
                } else {
                    0.299 * r + 0.587 * g + 0.114 * b - 128.0
                }
            })
            .collect();
        return vec![y];
    }
    // One pass over the pixels per plane, as chunks collected (exact length, no bounds checks
    // or capacity checks in the loop).
    let plane = |f: fn(f32, f32, f32) -> f32| -> Vec<f32> {
        if img.channels == 1 {
            img.data[..n]
                .iter()
                .map(|&v| f(f32::from(v), f32::from(v), f32::from(v)))
                .collect()
        } else {
            img.data[..n * 3]
                .chunks_exact(3)
                .map(|p| f(f32::from(p[0]), f32::from(p[1]), f32::from(p[2])))
                .collect()
        }
    };
    if lossless {
        vec![
            plane(|r, g, b| ((r + 2.0 * g + b) / 4.0).floor() - 128.0),
            plane(|_, g, b| b - g),
            plane(|r, g, _| r - g),
        ]
    } else {
        vec![
            plane(|r, g, b| 0.299 * r + 0.587 * g + 0.114 * b - 128.0),
            plane(|r, g, b| -0.168_736 * r - 0.331_264 * g + 0.5 * b),
            plane(|r, g, b| 0.5 * r - 0.418_688 * g - 0.081_312 * b),
        ]
    }
}

/// YCbCr -> RGB (JPEG's, full range): row `c` holds the weights of Y, Cb and Cr in channel `c`.
pub(super) const YCBCR_TO_RGB: [[f32; 3]; 3] = [
    [1.0, 0.0, 1.402],
    [1.0, -0.344_136, -0.714_136],
    [1.0, 1.772, 0.0],
];

/// A sample from a reconstructed value: clamped first, so adding one half and truncating
/// rounds to nearest.
pub(super) fn to_sample(v: f32) -> u8 {
    (v.clamp(0.0, 255.0) + 0.5) as u8
}

/// The picture of component planes (`to_components`' inverse): grey from one plane, RGB from
/// three.
pub(super) fn from_components(
    planes: &[Vec<f32>],
    width: usize,
    height: usize,
    lossless: bool,
) -> Image {
    let n = width * height;
    if planes.len() == 1 {
        let data = planes[0].iter().map(|&y| to_sample(y + 128.0)).collect();
        return Image {
            width,
            height,
            channels: 1,
            data,
        };
    }
    // Appended into the exact capacity (never zeroed, never regrown); iterating the planes
    // together lets the compiler drop the bounds checks.
    let mut data = Vec::with_capacity(n * 3);
    let pixels = planes[0][..n]
        .iter()
        .zip(&planes[1][..n])
        .zip(&planes[2][..n]);
    for ((&y, &cb), &cr) in pixels {
        let y = y + 128.0;
        let (r, g, b) = if lossless {
            let g = y - ((cb + cr) / 4.0).floor();
            (cr + g, g, cb + g)
        } else {
            let [r, g, b] = YCBCR_TO_RGB;
            (y + r[2] * cr, y + g[1] * cb + g[2] * cr, y + b[1] * cb)
        };
        data.extend_from_slice(&[to_sample(r), to_sample(g), to_sample(b)]);
    }
    Image {
        width,
        height,
        channels: 3,
        data,
    }
}
