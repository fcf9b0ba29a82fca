//! Measures the resilient-layout prototype ([`rovlink_debt::resilient`]) against the plain
//! stream: PSNR with nothing lost and with 5 % of the trunks lost (8 seeded patterns).
//!
//! `cargo run --release -p rovlink-debt --example resilient_probe -- [--bytes 500,2000,8000] [--trunk 39] IMAGES`

use rovlink_base::rng::Rng;
use rovlink_debt::metrics::psnr;
use rovlink_debt::resilient::{Layout, decode_groups, encode_groups};
use rovlink_debt::{self as debt, EncodeOptions, Image, rangecoder};
use std::path::Path;

/// Seeded loss patterns per measurement.
const PATTERNS: u64 = 8;
/// Share of trunks lost.
const LOSS: f64 = 0.05;

/// `count` distinct trunk indices below `trunks`, from seed `seed`.
fn pattern(trunks: usize, count: usize, seed: u64) -> Vec<usize> {
    let mut rng = Rng::new(seed, 18);
    let mut lost = Vec::new();
    while lost.len() < count.min(trunks) {
        let t = rng.next_u32() as usize % trunks;
        if !lost.contains(&t) {
            lost.push(t);
        }
    }
    lost
}

fn grey_like(img: &Image) -> Image {
    Image {
        data: vec![128; img.data.len()],
        ..img.clone()
    }
}

/// (PSNR nothing lost, mean PSNR over the loss patterns) of the plain stream.
fn plain(img: &Image, bytes: usize, trunk: usize, levels: Option<u32>) -> (f64, f64) {
    let opts = EncodeOptions {
        bytes,
        levels,
        ..Default::default()
    };
    let data = debt::encode(img, &opts).expect("encode");
    let full = psnr(img, &debt::decode(&data).expect("decode"));
    let trunks = bytes.div_ceil(trunk);
    let count = (trunks as f64 * LOSS).round() as usize;
    let lossy: f64 = (0..PATTERNS)
        .map(|seed| {
            let ranges: Vec<_> = pattern(trunks, count, seed)
                .iter()
                .map(|&t| t * trunk..((t + 1) * trunk).min(bytes))
                .collect();
            let out = debt::decode_with_loss(&data, &ranges).unwrap_or_else(|_| grey_like(img));
            psnr(img, &out)
        })
        .sum::<f64>()
        / PATTERNS as f64;
    (full, lossy)
}

/// (PSNR nothing lost, mean PSNR over the loss patterns) of the resilient layout.
fn resilient(img: &Image, layout: &Layout) -> (f64, f64) {
    let data = encode_groups(img, layout);
    assert_eq!(data.len(), layout.bytes);
    let full = psnr(img, &decode_groups(&data, layout, &[]));
    let trunks = layout.trunks();
    let count = (trunks as f64 * LOSS).round() as usize;
    let lossy: f64 = (0..PATTERNS)
        .map(|seed| {
            psnr(
                img,
                &decode_groups(&data, layout, &pattern(trunks, count, seed)),
            )
        })
        .sum::<f64>()
        / PATTERNS as f64;
    (full, lossy)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut budgets = vec![2000usize];
    let mut trunk = 39usize;
    let mut paths = Vec::new();
    while let Some(a) = args.next() {
        match a.as_str() {
            "--bytes" => {
                budgets = args
                    .next()
                    .expect("--bytes LIST")
                    .split(',')
                    .map(|b| b.parse().expect("--bytes: a number"))
                    .collect()
            }
            "--trunk" => trunk = args.next().expect("--trunk N").parse().expect("--trunk"),
            _ => paths.push(a),
        }
    }
    let images: Vec<(String, Image)> = paths
        .iter()
        .map(|p| {
            let name = Path::new(p)
                .file_stem()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned();
            (name, debt::picture::open(Path::new(p)).expect("image"))
        })
        .collect();
    for &bytes in &budgets {
        println!(
            "## {bytes} B, {trunk}-byte trunks, {:.0} % lost ({PATTERNS} patterns)",
            LOSS * 100.0
        );
        println!(
            "variant | image | levels | groups | PSNR no loss | vs plain | PSNR lost | lost vs no loss"
        );
        let mut sums: Vec<(String, f64, f64, f64)> = Vec::new();
        for (name, img) in &images {
            let (anchor, anchor_lost) = plain(img, bytes, trunk, None);
            let base = Layout::suggested(img, bytes, trunk, 8);
            let default_levels = debt::default_levels(img.width, img.height);
            let mut rows = vec![("plain".to_string(), default_levels, 1, anchor, anchor_lost)];
            let (p, pl) = plain(img, bytes, trunk, Some(base.levels));
            rows.push((format!("plain, L={}", base.levels), base.levels, 1, p, pl));
            // What the groups' fixed costs would take from the plain stream: per group the
            // range coder's 3-byte termination margin and the 5-bit plane count.
            let fixed = base.groups * (rangecoder::MARGIN_BITS as usize + 5) / 8;
            let (p, pl) = plain(img, bytes - fixed, trunk, None);
            rows.push((format!("plain, {fixed} B less"), default_levels, 1, p, pl));
            let mut layouts = vec![("resilient".to_string(), base)];
            for dl in [-1i32, 1] {
                let levels = base.levels as i32 + dl;
                if (1..=7).contains(&levels) {
                    layouts.push((
                        format!("resilient L{dl:+}"),
                        Layout {
                            levels: levels as u32,
                            ..base
                        },
                    ));
                }
            }
            for k in [2, 4, base.groups] {
                let label = if k == base.groups {
                    "resilient G=1".to_string()
                } else {
                    format!("resilient G=N/{k}")
                };
                layouts.push((
                    label,
                    Layout {
                        groups: base.groups.div_ceil(k),
                        ..base
                    },
                ));
            }
            layouts.push((
                "contiguous (not dispersed)".to_string(),
                Layout {
                    dispersed: false,
                    ..base
                },
            ));
            for (label, layout) in layouts {
                let (q, ql) = resilient(img, &layout);
                rows.push((label, layout.levels, layout.groups, q, ql));
            }
            for (i, (label, levels, groups, q, ql)) in rows.into_iter().enumerate() {
                println!(
                    "{label} | {name} | {levels} | {groups} | {q:.2} | {:+.2} | {ql:.2} | {:+.2}",
                    q - anchor,
                    ql - q
                );
                if sums.len() <= i {
                    sums.push((label, 0.0, 0.0, 0.0));
                }
                sums[i].1 += q;
                sums[i].2 += q - anchor;
                sums[i].3 += ql;
            }
            let _ = anchor_lost;
        }
        let n = images.len() as f64;
        println!("### mean over {} images", images.len());
        println!("variant | PSNR no loss | vs plain | PSNR 5 % lost | lost vs no loss");
        for (label, q, d, ql) in sums {
            println!(
                "{label} | {:.2} | {:+.2} | {:.2} | {:+.2}",
                q / n,
                d / n,
                ql / n,
                (ql - q) / n
            );
        }
    }
}
