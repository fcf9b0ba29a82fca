//! `tdma-run --pace X`: a simulation (single session or scenario) held to X times real time, so
//! that it can be watched live, with the same results as unpaced. Only lower bounds on the wall
//! time are checked (a loaded machine can only make a run slower, never a paced one faster).

use std::process::Command;
use std::time::{Duration, Instant};

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");
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

/// A scenario watched live: `--pace 1 --foxglove`, every vehicle under `/vehicle/N/`, and the
/// stock Foxglove client (tests/foxglove/stock_client.mjs, as in tests/foxglove_stock.rs).
#[test]
fn a_paced_scenario_can_be_watched_live_in_foxglove() {
    let address = format!("127.0.0.1:{}", crate::common::free_port());
    let mut run = Command::new(TDMA_RUN)
        .args(["--scenario", SCENARIO, "--duration", "15", "--pace", "1"])
        .args(["--foxglove", &address])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = std::io::BufReader::new(run.stderr.take().unwrap());
    let mut line = String::new();
    while !line.contains("Foxglove: ws://") {
        line.clear();
        assert!(std::io::BufRead::read_line(&mut stderr, &mut line).unwrap() > 0);
    }
    let seen =
        crate::common::stock_client(&["--url", &format!("ws://{address}"), "--seconds", "4"]);
    let status = run.wait().unwrap();
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut stderr, &mut rest).unwrap();
    assert!(status.success(), "{rest}");
    for topic in [
        "/vehicle/1/rov/pose",
        "/vehicle/2/rov/pose",
        "/vehicle/2/tf",
        "/network/frames",
    ] {
        assert!(
            seen["counts"][topic].as_u64().unwrap_or(0) > 0,
            "{topic}: {seen}"
        );
    }
    // As the MCAP log: a network's vehicles have no link of their own.
    let advertised = seen["advertised"].as_array().unwrap();
    assert!(
        !advertised.iter().any(|t| t == "/vehicle/1/link/frames"),
        "{seen}"
    );
    let first_ms = seen["first_ms"]["/vehicle/1/rov/pose"].as_f64();
    assert!(first_ms.is_some_and(|ms| ms < 2000.0), "{seen}");
}
