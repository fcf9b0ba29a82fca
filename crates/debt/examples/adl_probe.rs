//! Measures adaptive directional lifting ([`rovlink_debt::adl`]) before it is in the stream:
//! at each budget B, the plain stream of B bytes against the directional one whose bit-planes
//! take B less the direction map's coded bytes (the map goes to the decoder out of band, its
//! bytes counted). Pictures are grouped into sets by name (`uieb-*` underwater, `*-gray` grey,
//! `kodim*` Kodak, the rest "other"); per set and budget it prints the plain mean PSNR (RGB) and,
//! per variant, the mean gain (dB) and map bytes, then the mean encode and decode times. A
//! picture whose map does not fit the budget counts as the plain stream ("off": the encoder
//! would switch directions off), its map as 0 B.
//!
//! A variant is `levels:block:margin[:chroma]` (directional levels, block side in samples of
//! the level, the margin a direction must beat direction 0 by, and `chroma` to lift the chroma
//! planes along the luma's directions too).
//!
//! `cargo run --release -p rovlink-debt --example adl_probe -- [--bytes 300,...] [--variant 2:32:0.1 ...] DIR...`

use rovlink_debt::adl::Params;
use rovlink_debt::metrics::psnr;
use rovlink_debt::{self as debt, EncodeOptions, Image, picture};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The set a picture belongs to, by its file name.
fn set_of(path: &Path) -> &'static str {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if name.starts_with("uieb-") {
        "underwater"
    } else if name.contains("-gray") {
        "grey"
    } else if name.starts_with("kodim") {
        "Kodak"
    } else {
        "other"
    }
}

/// Parses `levels:block:margin[:chroma]`.
fn variant(text: &str) -> Option<Params> {
    let mut parts = text.split(':');
    Some(Params {
        levels: parts.next()?.parse().ok()?,
        block: parts.next()?.parse().ok()?,
        margin: parts.next()?.parse().ok()?,
        chroma: parts.next() == Some("chroma"),
    })
}

/// Per variant and set-budget cell: summed PSNR, map bytes, encode and decode seconds.
#[derive(Default, Clone, Copy)]
struct Sums {
    db: f64,
    map: f64,
    encode: f64,
    decode: f64,
    /// Pictures whose map did not fit the budget (counted as the plain stream).
    fallbacks: usize,
}

fn main() {
    let mut budgets = vec![300, 500, 1000, 2000, 4000, 8000, 16000];
    let mut variants = Vec::new();
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
            "--variant" => match args.next().as_deref().and_then(variant) {
                Some(v) => variants.push(v),
                None => {
                    eprintln!("--variant levels:block:margin[:chroma]");
                    std::process::exit(2);
                }
            },
            _ => dirs.push(PathBuf::from(arg)),
        }
    }
    if variants.is_empty() {
        variants.push(Params::default());
    }
    let mut images: Vec<(&'static str, Image)> = Vec::new();
    for dir in &dirs {
        match picture::load(dir) {
            Ok(loaded) => images.extend(loaded.into_iter().map(|(p, img)| (set_of(&p), img))),
            Err(e) => {
                eprintln!("{}: {e}", dir.display());
                std::process::exit(2);
            }
        }
    }
    let mut sets: Vec<&str> = images.iter().map(|(s, _)| *s).collect();
    sets.dedup();
    sets.sort_unstable();
    sets.dedup();
    let names: Vec<String> = variants
        .iter()
        .map(|v| {
            let chroma = if v.chroma { ":chroma" } else { "" };
            format!("{}:{}:{}{chroma}", v.levels, v.block, v.margin)
        })
        .collect();
    print!("| set | bytes | plain dB |");
    for name in &names {
        print!(" {name} dB | map B |");
    }
    println!();
    println!("|---|---|---|{}", "---|---|".repeat(names.len()));
    // Plain, then each variant.
    let mut totals = vec![Sums::default(); variants.len() + 1];
    let mut runs = 0;
    for set in &sets {
        for &bytes in &budgets {
            let mut cell = vec![Sums::default(); variants.len() + 1];
            let members: Vec<&Image> = images
                .iter()
                .filter(|(s, _)| s == set)
                .map(|(_, i)| i)
                .collect();
            for img in &members {
                let opts = EncodeOptions {
                    bytes,
                    ..EncodeOptions::default()
                };
                let started = Instant::now();
                let stream = debt::encode(img, &opts).expect("encode");
                let encoded = Instant::now();
                let plain = debt::decode(&stream).expect("decode");
                cell[0].encode += (encoded - started).as_secs_f64();
                cell[0].decode += encoded.elapsed().as_secs_f64();
                cell[0].db += psnr(&plain, img);
                for (sums, params) in cell[1..].iter_mut().zip(&variants) {
                    let started = Instant::now();
                    let (stream, map) =
                        debt::encode_with_directions(img, &opts, params).expect("encode");
                    let encoded = Instant::now();
                    let decoded = debt::decode_with_directions(&stream, &map).expect("decode");
                    sums.encode += (encoded - started).as_secs_f64();
                    sums.decode += encoded.elapsed().as_secs_f64();
                    let map_bytes = map.to_bytes().len();
                    if stream.len() + map_bytes > bytes {
                        // The map alone overruns the budget: the encoder would switch
                        // directions off for this stream.
                        sums.db += psnr(&plain, img);
                        sums.fallbacks += 1;
                    } else {
                        sums.db += psnr(&decoded, img);
                        sums.map += map_bytes as f64;
                    }
                }
            }
            let n = members.len() as f64;
            print!("| {set} | {bytes} | {:.2} |", cell[0].db / n);
            for sums in &cell[1..] {
                let off = if sums.fallbacks > 0 {
                    format!(" ({} off)", sums.fallbacks)
                } else {
                    String::new()
                };
                print!(
                    " {:+.3} | {:.0}{off} |",
                    (sums.db - cell[0].db) / n,
                    sums.map / n
                );
            }
            println!();
            for (total, sums) in totals.iter_mut().zip(&cell) {
                total.encode += sums.encode;
                total.decode += sums.decode;
            }
            runs += members.len();
        }
    }
    println!();
    println!("| variant | encode ms | decode ms |");
    println!("|---|---|---|");
    for (name, total) in std::iter::once(&"plain".to_string())
        .chain(&names)
        .zip(&totals)
    {
        println!(
            "| {name} | {:.1} | {:.1} |",
            total.encode * 1e3 / runs as f64,
            total.decode * 1e3 / runs as f64
        );
    }
}
