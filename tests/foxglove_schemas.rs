//! Every channel tdma-run logs can be read by Foxglove: its JSON Schema uses nothing
//! Foxglove's reader refuses (type arrays, `oneOf`, untyped properties), and every message
//! validates against it. Checked with the official readers (Python `mcap` and `jsonschema`,
//! tests/foxglove/check_schemas.py) on a single session's log and a network scenario's.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");
const CHECK: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/foxglove/check_schemas.py"
);
const SCENARIO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenarios/relay-rf.json");

/// The messages check_schemas.py validated, per topic.
fn checked(mcap: &Path) -> BTreeMap<String, u64> {
    let out = Command::new("python3")
        .arg(CHECK)
        .arg(mcap)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "check_schemas.py: {stderr}");
    serde_json::from_slice(&out.stdout).unwrap()
}

fn tdma(args: &[&str]) {
    let out = Command::new(TDMA_RUN).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_sessions_log_is_readable_on_every_channel() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("s.mcap");
    // A lossy link, so that frames are lost (no t_received_s) and the link log has warnings.
    tdma(&[
        "--sim",
        "--duration",
        "120",
        "--ber",
        "0.001",
        "--mcap",
        mcap.to_str().unwrap(),
    ]);
    let counts = checked(&mcap);
    for topic in ["/rov/pose", "/link/frames", "/link/log", "/camera/image"] {
        assert!(
            counts.get(topic).is_some_and(|&n| n > 0),
            "{topic}: {counts:?}"
        );
    }
}

#[test]
fn a_networks_log_is_readable_on_every_channel() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("n.mcap");
    tdma(&[
        "--scenario",
        SCENARIO,
        "--duration",
        "120",
        "--mcap",
        mcap.to_str().unwrap(),
    ]);
    let counts = checked(&mcap);
    for topic in [
        "/network/frames",
        "/vehicle/1/rov/pose",
        "/vehicle/2/rov/pose",
    ] {
        assert!(
            counts.get(topic).is_some_and(|&n| n > 0),
            "{topic}: {counts:?}"
        );
    }
}
