//! Writes `octo-delta synth`'s survey in the C++ `ColorOcTree` reference's input format
//! ([`rovlink_octo::synth::reference_dump`]), for `scripts/octo-bench.sh`'s coloured anchor.
//!
//! Usage: `cargo run --release -p rovlink-octo --example reference_scans -- SCANS SEED OUT`
//! (the survey of `octo-delta synth --scans SCANS --seed SEED`).

use std::process::ExitCode;

use rovlink_octo::synth::{SurveyParams, reference_dump, survey};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scans, seed, out] = args.as_slice() else {
        eprintln!("usage: reference_scans SCANS SEED OUT");
        return ExitCode::from(2);
    };
    let (Ok(scans), Ok(seed)) = (scans.parse::<usize>(), seed.parse::<u64>()) else {
        eprintln!(
            "reference_scans: SCANS and SEED: expected whole numbers, found {scans:?} {seed:?}"
        );
        return ExitCode::from(2);
    };
    if !(1..=rovlink_octo::synth::MAX_SCANS).contains(&scans) {
        eprintln!(
            "reference_scans: SCANS: expected 1 ..= {}, found {scans}",
            rovlink_octo::synth::MAX_SCANS
        );
        return ExitCode::from(2);
    }
    let params = SurveyParams {
        seed,
        scans,
        ..SurveyParams::default()
    };
    match std::fs::write(out, reference_dump(&survey(&params))) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("reference_scans: {out}: cannot write: {e}");
            ExitCode::from(2)
        }
    }
}
