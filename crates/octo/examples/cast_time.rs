//! Times the casting alone (no map, no files): `octo-delta synth`'s coloured survey cast
//! scan by scan on one thread, as `octo-delta build` casts it, `PASSES` times; prints the
//! median and the fastest pass. For comparing changes to the ray walk (`docs/octo-speed.md`);
//! run it interleaved with the build it is compared with, on a quiet machine.
//!
//! Usage: `cargo run --release -p rovlink-octo --example cast_time -- [SCANS] [PASSES] [plain]`
//! (defaults 40 and 9; `plain` casts without colours).

use std::process::ExitCode;
use std::sync::atomic::AtomicBool;

use rovlink_octo::cast::ScanCaster;
use rovlink_octo::synth::{SurveyParams, survey};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let number = |i: usize, default: usize, name: &str| match args.get(i) {
        None => Ok(default),
        Some(a) => a.parse::<usize>().ok().filter(|&n| n >= 1).ok_or(format!(
            "cast_time: {name}: expected a whole number >= 1, found {a:?}"
        )),
    };
    let (scans, passes) = match (number(0, 40, "SCANS"), number(1, 9, "PASSES")) {
        (Ok(s), Ok(p)) if s <= rovlink_octo::synth::MAX_SCANS => (s, p),
        (Ok(s), Ok(_)) => {
            eprintln!(
                "cast_time: SCANS: expected 1 ..= {}, found {s}",
                rovlink_octo::synth::MAX_SCANS
            );
            return ExitCode::from(2);
        }
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let colored = match args.get(2).map(String::as_str) {
        None => true,
        Some("plain") => false,
        Some(other) => {
            eprintln!("cast_time: expected `plain` or nothing after PASSES, found {other:?}");
            return ExitCode::from(2);
        }
    };
    let scans = survey(&SurveyParams {
        scans,
        ..SurveyParams::default()
    });
    let stop = AtomicBool::new(false);
    let mut caster = ScanCaster::new(0.1, colored, 1);
    let mut times_ms = Vec::with_capacity(passes);
    let mut voxels = 0;
    for _ in 0..passes {
        let start = std::time::Instant::now();
        for scan in &scans {
            match caster.prepare(scan, None, &stop) {
                Ok(Some(p)) => voxels += p.occupied_voxels(),
                Ok(None) => {}
                Err(e) => {
                    eprintln!("cast_time: a scan over the cell budget: {e}");
                    return ExitCode::from(2);
                }
            }
        }
        times_ms.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times_ms.sort_by(f64::total_cmp);
    println!(
        "{} scans, {passes} passes: median {:.1} ms, fastest {:.1} ms ({} occupied voxels cast)",
        scans.len(),
        times_ms[passes / 2],
        times_ms[0],
        voxels / passes
    );
    ExitCode::SUCCESS
}
