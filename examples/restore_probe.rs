//! Measures decoder-side restoration ([`rovlink::debt::restore`]) before it is in the stream:
//! at each budget B, the plain stream of B bytes against the stream of B - T bytes (T: the
//! filter's bytes plus the version 3 header's 3) filtered with the taps fitted on its own decode.
//! Prints, per set (a directory) and budget, the mean PSNR of both and the mean gain, dB.
//!
//! `cargo run --release --example restore_probe -- [--bytes 300,...] [--row-step 1] DIR...`

use rovlink::debt::metrics::psnr;
use rovlink::debt::restore::{Filter, apply, fit};
use rovlink::debt::{self, EncodeOptions, picture};
use std::path::PathBuf;
use std::time::Instant;

fn main() {
    let mut budgets = vec![300, 500, 1000, 2000, 4000, 8000, 16000];
    let mut row_step = 1;
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
            _ => dirs.push(PathBuf::from(arg)),
        }
    }
    println!("| set | bytes | plain dB | restored dB | gain dB | fit+apply ms |");
    println!("|---|---|---|---|---|---|");
    for dir in &dirs {
        let images = match picture::load(dir) {
            Ok(images) => images,
            Err(e) => {
                eprintln!("{}: {e}", dir.display());
                std::process::exit(2);
            }
        };
        for &bytes in &budgets {
            let (mut plain_db, mut restored_db, mut ms) = (0.0, 0.0, 0.0);
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
            }
            let n = images.len() as f64;
            println!(
                "| {} | {bytes} | {:.2} | {:.2} | {:+.3} | {:.1} |",
                dir.display(),
                plain_db / n,
                restored_db / n,
                (restored_db - plain_db) / n,
                ms / n
            );
        }
    }
}
