//! `tdma-run --pace X`: a simulation (single session or scenario) held to X times real time, so
//! that it can be watched live, with the same results as unpaced. Only lower bounds on the wall
//! time are checked (a loaded machine can only make a run slower, never a paced one faster).

use std::process::Command;
use std::time::{Duration, Instant};

const TDMA_RUN: &str = env!("CARGO_BIN_EXE_tdma-run");
const SCENARIO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenarios/relay-rf.json");

/// Runs tdma-run with `args` and `--metrics -`: the figures (without the wall time and the
/// recorded parameters, which differ) and the wall time the run took.
fn figures(args: &[&str]) -> (serde_json::Value, Duration) {
    let started = Instant::now();
    let out = Command::new(TDMA_RUN)
        .args(args)
        .args(["--metrics", "-"])
        .output()
        .unwrap();
    let took = started.elapsed();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut m: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let map = m.as_object_mut().unwrap();
    for key in ["params", "wall_s", "wall_time_s"] {
        map.remove(key);
    }
    (m, took)
}

#[test]
fn a_paced_session_takes_its_time_and_gives_the_same_figures() {
    let (plain, _) = figures(&["--sim", "--duration", "3"]);
    let (paced, took) = figures(&["--sim", "--duration", "3", "--pace", "2"]);
    assert!(took >= Duration::from_millis(1400), "3 s at 2x in {took:?}");
    assert_eq!(plain, paced);
}

#[test]
fn a_paced_scenario_takes_its_time_and_gives_the_same_figures() {
    let args = ["--scenario", SCENARIO, "--duration", "20"];
    let (plain, _) = figures(&args);
    let (paced, took) = figures(&[&args[..], &["--pace", "20"]].concat());
    assert!(
        took >= Duration::from_millis(950),
        "20 s at 20x in {took:?}"
    );
    assert_eq!(plain, paced);
}
