//! Times the parity repair ([`rovlink_debt::fec::repair`]) alone, without decoding the picture:
//! the layout search when the header's trunk is lost, then every block's rebuilding (issue 48).
//! Prints the fastest of RUNS repairs in milliseconds, the layout found and the bytes still
//! lost. ERASE is a comma list of trunks and inclusive ranges (`0-21999,30000`).
//!
//! `cargo run --release -p rovlink-debt --example fec_repair_time -- STREAM TRUNK_BYTES ERASE [RUNS]`

use std::process::ExitCode;
use std::time::Instant;

use rovlink_debt::fec;

/// The trunks of an ERASE argument.
fn trunks(list: &str) -> Option<Vec<usize>> {
    let mut out = Vec::new();
    for part in list.split(',') {
        match part.split_once('-') {
            Some((first, last)) => out.extend(first.parse::<usize>().ok()?..=last.parse().ok()?),
            None => out.push(part.parse().ok()?),
        }
    }
    Some(out)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(path), Some(Ok(trunk_bytes)), Some(Some(lost))) = (
        args.first(),
        args.get(1).map(|t| t.parse::<usize>()),
        args.get(2).map(|e| trunks(e)),
    ) else {
        eprintln!("usage: fec_repair_time STREAM TRUNK_BYTES ERASE [RUNS]");
        return ExitCode::from(2);
    };
    let runs: usize = args.get(3).and_then(|r| r.parse().ok()).unwrap_or(5);
    let stream = match std::fs::read(path) {
        Ok(stream) => stream,
        Err(e) => {
            eprintln!("{path}: {e}");
            return ExitCode::from(2);
        }
    };
    let mut fastest_ms = f64::INFINITY;
    let mut repaired = None;
    for _ in 0..runs.max(1) {
        let start = Instant::now();
        let r = fec::repair(&stream, trunk_bytes, &lost);
        fastest_ms = fastest_ms.min(start.elapsed().as_secs_f64() * 1e3);
        repaired = Some(r);
    }
    let Some(repaired) = repaired else {
        return ExitCode::from(2);
    };
    let still_lost: usize = repaired.lost.iter().map(|r| r.len()).sum();
    let mut distinct = lost.clone();
    distinct.sort_unstable();
    distinct.dedup();
    println!(
        "{path}: {} bytes, {} trunks erased ({} listed), repair {fastest_ms:.1} ms (fastest of \
         {runs}); layout {:?}; {still_lost} bytes still lost",
        stream.len(),
        distinct.len(),
        lost.len(),
        repaired.fec,
    );
    ExitCode::SUCCESS
}
