//! Golden outputs of a fixed set of simulated sessions (issue 30): today's drivers, recorded
//! before they are rebuilt as one, so that the rebuilt driver is held to the same bytes.
//!
//! Each session runs with `--metrics`, `--events`, `--track` and `--mcap` (and `--images-out`
//! where it completes images); testdata/golden/sessions.txt holds, per session, its metrics
//! (JSON, the tool's version blanked: it is not the driver's) and the length and SHA-256 of every
//! other output file, so any changed byte shows and the shell can check a file with
//! `sha256sum`. A change that is meant must be recorded (`UPDATE_GOLDEN=1 scripts/test --
//! golden_sessions`) and said in the commit that makes it.

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

use sha2::{Digest, Sha256};

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");
const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// The paper's recovery scenario (scripts/recovery.sh): a GoTo out of the S100's range.
const RECOVERY_WAYPOINTS: &str = "t_s,x_m,y_m,z_m,heading_deg\n5,2,0,1,0\n40,8,0,1,0\n";

/// The sessions: a name and tdma-run's arguments (`{dir}` is the session's folder).
fn sessions() -> Vec<(&'static str, Vec<String>)> {
    let args = |text: &str| -> Vec<String> { text.split_whitespace().map(String::from).collect() };
    vec![
        ("default", args("--sim --duration 120")),
        ("ber-7e-4", args("--sim --ber 7e-4 --duration 120")),
        (
            "recovery",
            args(
                "--sim --model s100 --ber 7e-4 --buoy 0,0,0 --start 1,0,1 --duration 100 \
                 --waypoints {dir}/waypoints.csv",
            ),
        ),
        (
            "images",
            args(&format!(
                "--sim --duration 90 --seed 7 --image-size 1200 --images {ROOT}/testdata/kodim23-64x48.png \
                 --images-out {{dir}}/images"
            )),
        ),
        (
            "relay-rf",
            args(&format!(
                "--scenario {ROOT}/scenarios/relay-rf.json --duration 60"
            )),
        ),
        (
            "acoustic-rf",
            args(&format!(
                "--scenario {ROOT}/scenarios/acoustic-rf.json --duration 60"
            )),
        ),
    ]
}

/// `path`'s length and SHA-256, as `sha256sum` prints it.
fn digest(path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    format!("{} {:x}", bytes.len(), Sha256::digest(&bytes))
}

/// Runs one session in `dir`; its lines of the golden file.
fn record(name: &str, args: &[String], dir: &Path) -> String {
    std::fs::write(dir.join("waypoints.csv"), RECOVERY_WAYPOINTS).unwrap();
    let dir_text = dir.to_str().unwrap();
    let args: Vec<String> = args.iter().map(|a| a.replace("{dir}", dir_text)).collect();
    let out = Command::new(TDMA_RUN)
        .args(&args)
        .arg("--metrics")
        .arg(dir.join("metrics.json"))
        .arg("--events")
        .arg(dir.join("events.csv"))
        .arg("--track")
        .arg(dir.join("track.csv"))
        .arg("--mcap")
        .arg(dir.join("session.mcap"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(dir.join("metrics.json")).unwrap();
    let mut metrics: serde_json::Value = serde_json::from_str(&text).unwrap();
    metrics["version"] = "".into();
    // The recorded parameters hold the session's own folder: blanked to the placeholder.
    let metrics = metrics
        .to_string()
        .replace(dir_text, "{dir}")
        .replace(ROOT, "{root}");
    let mut lines = format!("== {name}\nmetrics {metrics}\n");
    let mut files: Vec<_> = walk(dir);
    files.sort();
    for path in files {
        let rel = path
            .strip_prefix(dir)
            .unwrap()
            .to_str()
            .unwrap()
            .to_string();
        if rel == "metrics.json" || rel == "waypoints.csv" {
            continue;
        }
        writeln!(lines, "{rel} {}", digest(&path)).unwrap();
    }
    lines
}

/// Every file under `dir`.
fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(walk(&path));
        } else {
            out.push(path);
        }
    }
    out
}

#[test]
fn simulated_sessions_give_their_recorded_bytes() {
    let mut report = String::new();
    for (name, args) in sessions() {
        let dir = tempfile::tempdir().unwrap();
        report.push_str(&record(name, &args, dir.path()));
    }
    crate::common::golden("sessions.txt", &report);
}

/// A one-vehicle network read from a scenario file: the single session of the same settings.
const ONE_VEHICLE: &str = r#"{"duration_s":120,"seed":3,
 "nodes":[{"address":0,"role":"operator","position":[0,0,0]},
          {"address":1,"role":"rov","start":[1,0,0],"waypoints":[[20,2,1,1,90]]}],
 "media":[{"name":"link","model":"s100","nodes":[0,1]}]}"#;

/// Runs tdma-run with `args` and `--events`, `--track`, `--metrics` into `dir` as `tag`-*;
/// the three files' text.
fn outputs(args: &[&str], dir: &Path, tag: &str) -> [String; 3] {
    let path = |what: &str| dir.join(format!("{tag}-{what}"));
    let out = Command::new(TDMA_RUN)
        .args(args)
        .arg("--events")
        .arg(path("events.csv"))
        .arg("--track")
        .arg(path("track.csv"))
        .arg("--metrics")
        .arg(path("metrics.json"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    ["events.csv", "track.csv", "metrics.json"].map(|f| std::fs::read_to_string(path(f)).unwrap())
}

#[test]
fn a_one_vehicle_network_is_the_single_session_event_for_event() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("one.json");
    std::fs::write(&scenario, ONE_VEHICLE).unwrap();
    let waypoints = dir.path().join("waypoints.csv");
    std::fs::write(&waypoints, "t_s,x_m,y_m,z_m,heading_deg\n20,2,1,1,90\n").unwrap();
    for link in [&[][..], &["--ber", "7e-4"][..]] {
        let mut network = vec!["--scenario", scenario.to_str().unwrap()];
        network.extend(link);
        let mut single = vec![
            "--sim",
            "--model",
            "s100",
            "--buoy",
            "0,0,0",
            "--start",
            "1,0,0",
            "--duration",
            "120",
            "--seed",
            "3",
            "--waypoints",
            waypoints.to_str().unwrap(),
        ];
        single.extend(link);
        let [n_events, n_track, n_metrics] = outputs(&network, dir.path(), "network");
        let [s_events, s_track, s_metrics] = outputs(&single, dir.path(), "single");
        assert!(n_events.lines().count() > 300, "{link:?}");
        assert_eq!(n_events, s_events, "{link:?}: --events differ");
        // The network's track is the single one's position and heading, after the address.
        let columns = |text: &str, skip: usize| -> Vec<String> {
            text.lines()
                .skip(1)
                .map(|l| {
                    l.split(',')
                        .skip(skip)
                        .take(5)
                        .collect::<Vec<_>>()
                        .join(",")
                })
                .collect()
        };
        assert_eq!(columns(&n_track, 1), columns(&s_track, 0), "{link:?}");
        let n: serde_json::Value = serde_json::from_str(&n_metrics).unwrap();
        let s: serde_json::Value = serde_json::from_str(&s_metrics).unwrap();
        let vehicle = n["vehicles"]["1"].as_object().unwrap();
        for (key, value) in vehicle {
            assert_eq!(Some(value), s.get(key), "{link:?}: {key}");
        }
        assert!(vehicle["images_completed"].as_u64().unwrap() >= 1);
        assert_eq!(vehicle["orders_executed"], 1, "{link:?}");
    }
}
