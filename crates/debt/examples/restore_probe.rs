//! Measures decoder-side restoration ([`rovlink_debt::restore`]) before it is in the stream:
//! at each budget B, the plain stream of B bytes against the stream of B - T bytes (T: the
//! filter's bytes plus the version 3 header's 3) filtered with the taps fitted on its own decode.
//! Prints, per set (a directory) and budget, the mean PSNR of both and the mean gain, dB.
//!
//! With `--cross`, a second variant: each colour channel's filter also takes the 12 differences
//! of the decoded luma (24 taps a channel, 72 B), fitted and quantised the same way. With
//! `--ycc`, a third: the filter works in YCbCr (BT.601), luma with its 12 taps, each chroma with
//! its own 12 and the luma's 12 (60 B).
//!
//! `cargo run --release -p rovlink-debt --example restore_probe -- [--bytes 300,...] [--row-step 1] [--cross] [--ycc] DIR...`

use rovlink_debt::metrics::psnr;
use rovlink_debt::restore::{Filter, OFFSETS, TAP_SCALE, apply, fit, ridge_solve};
use rovlink_debt::{self as debt, EncodeOptions, Image, picture};
use std::path::PathBuf;
use std::time::Instant;

fn main() {
    let mut budgets = vec![300, 500, 1000, 2000, 4000, 8000, 16000];
    let mut row_step = 1;
    let mut cross = false;
    let mut ycc = false;
    let mut dirs = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--bytes" => {
                budgets = args
                    .next()
                    .unwrap_or_default()
                    .split(',')
                    .filter_map(|b| b.parse().ok())
                    .collect()
            }
            "--row-step" => row_step = args.next().and_then(|s| s.parse().ok()).unwrap_or(1),
            "--cross" => cross = true,
            "--ycc" => ycc = true,
            _ => dirs.push(PathBuf::from(arg)),
        }
    }
    println!(
        "| set | bytes | plain dB | restored dB | gain dB | fit+apply ms | cross gain dB | YCbCr gain dB |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for dir in &dirs {
        let images = match picture::load(dir) {
            Ok(images) => images,
            Err(e) => {
                eprintln!("{}: {e}", dir.display());
                std::process::exit(2);
            }
        };
        for &bytes in &budgets {
            let (mut plain_db, mut restored_db, mut ms, mut cross_db) = (0.0, 0.0, 0.0, 0.0);
            let mut ycc_db = 0.0;
            for (_, img) in &images {
                let trailer = Filter::len_for(img.channels) + 3;
                let at = |bytes: usize| {
                    let opts = EncodeOptions {
                        bytes,
                        ..EncodeOptions::default()
                    };
                    debt::decode(&debt::encode(img, &opts).unwrap()).unwrap()
                };
                plain_db += psnr(&at(bytes), img);
                let short = at(bytes.saturating_sub(trailer).max(8));
                let started = Instant::now();
                let filter = fit(&short, img, row_step);
                let restored = apply(&short, &filter);
                ms += started.elapsed().as_secs_f64() * 1e3;
                restored_db += psnr(&restored, img);
                if cross && img.channels == 3 {
                    let short = at(bytes.saturating_sub(72 + 3).max(8));
                    cross_db += psnr(&cross_filtered(&short, img), img);
                }
                if ycc && img.channels == 3 {
                    let short = at(bytes.saturating_sub(60 + 3).max(8));
                    ycc_db += psnr(&ycc_filtered(&short, img), img);
                }
            }
            let n = images.len() as f64;
            let cross_gain = if cross {
                format!("{:+.3}", (cross_db - plain_db) / n)
            } else {
                "-".into()
            };
            let ycc_gain = if ycc {
                format!("{:+.3}", (ycc_db - plain_db) / n)
            } else {
                "-".into()
            };
            println!(
                "| {} | {bytes} | {:.2} | {:.2} | {:+.3} | {:.1} | {cross_gain} | {ycc_gain} |",
                dir.display(),
                plain_db / n,
                restored_db / n,
                (restored_db - plain_db) / n,
                ms / n
            );
        }
    }
}

/// The 12 mirrored-pair differences of `plane` (w x h) at (x, y), borders repeated.
fn differences(plane: &[f64], w: usize, h: usize, x: usize, y: usize) -> [f64; 12] {
    let at = |dx: i32, dy: i32| {
        let xx = (x as i64 + i64::from(dx)).clamp(0, w as i64 - 1) as usize;
        let yy = (y as i64 + i64::from(dy)).clamp(0, h as i64 - 1) as usize;
        plane[yy * w + xx]
    };
    let centre = at(0, 0);
    std::array::from_fn(|k| {
        let (dx, dy) = OFFSETS[k];
        at(dx, dy) + at(-dx, -dy) - 2.0 * centre
    })
}

/// `decoded` with each channel filtered by 24 quantised taps fitted against `original`: its
/// own 12 differences and the decoded luma's 12.
fn cross_filtered(decoded: &Image, original: &Image) -> Image {
    let (w, h, n) = (decoded.width, decoded.height, decoded.channels);
    let channel = |img: &Image, c: usize| -> Vec<f64> {
        img.data
            .iter()
            .skip(c)
            .step_by(n)
            .map(|&v| f64::from(v))
            .collect()
    };
    let luma: Vec<f64> = picture::to_gray(decoded)
        .data
        .iter()
        .map(|&v| f64::from(v))
        .collect();
    let mut out = decoded.clone();
    for c in 0..n {
        let plane = channel(decoded, c);
        let features = |i: usize| -> [f64; 24] {
            let (own, by_luma) = (
                differences(&plane, w, h, i % w, i / w),
                differences(&luma, w, h, i % w, i / w),
            );
            std::array::from_fn(|k| if k < 12 { own[k] } else { by_luma[k - 12] })
        };
        let filtered = filtered(&features, &plane, &channel(original, c));
        for (sample, v) in out.data.iter_mut().skip(c).step_by(n).zip(filtered) {
            *sample = v.round().clamp(0.0, 255.0) as u8;
        }
    }
    out
}

/// The BT.601 components (Y, Cb, Cr) of a colour picture, as planes.
fn ycc_planes(img: &Image) -> [Vec<f64>; 3] {
    let px = |i: usize| {
        let p = &img.data[i * 3..i * 3 + 3];
        (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
    };
    let count = img.width * img.height;
    [
        (0..count)
            .map(|i| {
                let (r, g, b) = px(i);
                0.299 * r + 0.587 * g + 0.114 * b
            })
            .collect(),
        (0..count)
            .map(|i| {
                let (r, g, b) = px(i);
                -0.168736 * r - 0.331264 * g + 0.5 * b
            })
            .collect(),
        (0..count)
            .map(|i| {
                let (r, g, b) = px(i);
                0.5 * r - 0.418688 * g - 0.081312 * b
            })
            .collect(),
    ]
}

/// `plane` plus `features . taps`, the taps fitted by least squares (the library's
/// [`ridge_solve`]) to bring it closest to `target` and quantised as the stream's are.
fn filtered<const N: usize>(
    features: &dyn Fn(usize) -> [f64; N],
    plane: &[f64],
    target: &[f64],
) -> Vec<f64> {
    let mut a = [[0.0; N]; N];
    let mut b = [0.0; N];
    for (i, (&p, &t)) in plane.iter().zip(target).enumerate() {
        let f = features(i);
        for j in 0..N {
            b[j] += f[j] * (t - p);
            for k in 0..N {
                a[j][k] += f[j] * f[k];
            }
        }
    }
    let scale = f64::from(TAP_SCALE);
    let taps = ridge_solve(&a, &b)
        .unwrap_or([0.0; N])
        .map(|t| (t * scale).round().clamp(-127.0, 127.0) / scale);
    plane
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            p + features(i)
                .iter()
                .zip(&taps)
                .map(|(f, t)| f * t)
                .sum::<f64>()
        })
        .collect()
}

/// `decoded` filtered in YCbCr: luma by its own 12 taps, each chroma by its own 12 and the
/// decoded luma's 12, fitted against `original`.
fn ycc_filtered(decoded: &Image, original: &Image) -> Image {
    let (w, h) = (decoded.width, decoded.height);
    let got = ycc_planes(decoded);
    let want = ycc_planes(original);
    let got = &got;
    let own = |c: usize| move |i: usize| differences(&got[c], w, h, i % w, i / w);
    let with_luma = |c: usize| {
        move |i: usize| -> [f64; 24] {
            let (mine, luma) = (own(c)(i), own(0)(i));
            std::array::from_fn(|k| if k < 12 { mine[k] } else { luma[k - 12] })
        }
    };
    let out_planes = [
        filtered(&own(0), &got[0], &want[0]),
        filtered(&with_luma(1), &got[1], &want[1]),
        filtered(&with_luma(2), &got[2], &want[2]),
    ];
    let mut out = decoded.clone();
    let [ys, cbs, crs] = &out_planes;
    let components = ys.iter().zip(cbs).zip(crs);
    for (pixel, ((&y, &cb), &cr)) in out.data.chunks_exact_mut(3).zip(components) {
        let rgb = [
            y + 1.402 * cr,
            y - 0.344136 * cb - 0.714136 * cr,
            y + 1.772 * cb,
        ];
        for (sample, v) in pixel.iter_mut().zip(rgb) {
            *sample = v.round().clamp(0.0, 255.0) as u8;
        }
    }
    out
}
