//! `tdma-run --scenario FILE` as a hostile user runs it: empty, random, truncated, deep and
//! huge files, a FIFO or a directory; NaN, inf, 1e300, -0 and huge in every number of the
//! scenario; 16 nodes, 14 vehicles at one spot, duplicate media, model files missing, garbage, a
//! directory, a FIFO or the scenario itself; routes to nodes not in the scenario, unreachable
//! vehicles; outputs that are the scenario, /dev/full, `--events - | head -1`; hostile link
//! flags; SIGTERM and SIGINT mid-run. Exit 0, 1 or 2 (143/130 on signals), never a panic or a
//! hang; an error is one line naming the file and the field.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::common::hostile::{
    Run, SignalWhen, Stdin, assert_contract, garbage, head_one, run, signal_when, temp_files,
};
use nix::sys::signal::Signal;
use serde_json::{Value, json};

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");
const LIMIT: Duration = Duration::from_secs(30);

/// The three-node scenario, 60 s long.
fn base() -> Value {
    json!({"duration_s": 60, "seed": 1,
        "nodes": [{"address": 0, "role": "operator", "position": [0, 0, 0]},
                  {"address": 1, "role": "rov", "start": [3, 0, 1]},
                  {"address": 2, "role": "rov", "start": [7, 0, 1],
                   "waypoints": [[30, 7.5, 1, 1, 90]]}],
        "media": [{"name": "rf", "model": "s100", "nodes": [0, 1, 2]}],
        "routes": {"0": {"2": 1}, "2": {"0": 1}}})
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn scenario(dir: &Path, value: &Value) -> PathBuf {
    write(dir, "scenario.json", value.to_string().as_bytes())
}

fn tdma(path: &Path, extra: &[&str]) -> Run {
    let mut args = vec!["--scenario", path.to_str().unwrap()];
    args.extend_from_slice(extra);
    run(TDMA_RUN, &args, b"", LIMIT)
}

/// Exit 2 with one line that names the file and contains `wanted` (the field).
fn assert_refused(out: &Run, file: &Path, wanted: &str, what: &str) {
    assert_contract(out, &[2], what);
    let lines: Vec<&str> = out.stderr.lines().collect();
    assert_eq!(lines.len(), 1, "{what}: not one line: {}", out.stderr);
    let name = file.file_name().unwrap().to_str().unwrap();
    assert!(
        lines[0].contains(name) && lines[0].contains(wanted),
        "{what}: expected {name:?} and {wanted:?} in {:?}",
        lines[0]
    );
}

#[test]
fn files_that_are_no_scenario_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let text = base().to_string();
    let huge = format!("{{\"x\":\"{}\"}}", "a".repeat(1 << 21));
    let deep = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.json", Vec::new(), "not JSON"),
        ("random.json", garbage(4000, 17), "scenario"),
        (
            "truncated.json",
            text.as_bytes()[..text.len() / 2].to_vec(),
            "not JSON",
        ),
        ("deep.json", deep.into_bytes(), "not JSON"),
        ("huge.json", huge.into_bytes(), "larger than"),
        ("array.json", b"[]".to_vec(), "expected an object"),
        (
            "bom.json",
            format!("\u{feff}{text}").into_bytes(),
            "not JSON",
        ),
    ];
    for (name, bytes, wanted) in cases {
        let path = write(dir.path(), name, &bytes);
        assert_refused(&tdma(&path, &[]), &path, wanted, name);
    }
    let fifo = dir.path().join("fifo.json");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    assert_refused(&tdma(&fifo, &[]), &fifo, "not a regular file", "FIFO");
    let sub = dir.path().join("folder.json");
    std::fs::create_dir(&sub).unwrap();
    assert_refused(&tdma(&sub, &[]), &sub, "not a regular file", "directory");
}

/// Replaces the value at the JSON pointer `at` of the base scenario with `value`.
fn with(at: &str, value: Value) -> Value {
    let mut s = base();
    *s.pointer_mut(at).unwrap() = value;
    s
}

#[test]
fn every_number_at_nan_inf_huge_negative_zero_and_minus_zero() {
    let dir = tempfile::tempdir().unwrap();
    // NaN and inf are no JSON numbers: the text says so.
    for bad in ["NaN", "Infinity", "-Infinity", "1e400"] {
        let text = base()
            .to_string()
            .replace("\"duration_s\":60", &format!("\"duration_s\":{bad}"));
        let path = write(dir.path(), "scenario.json", text.as_bytes());
        assert_refused(&tdma(&path, &[]), &path, "not JSON", bad);
    }
    let bad: [Value; 6] = [
        json!(1e300),
        json!(-1e300),
        json!(-0.0),
        json!(-1),
        json!(18446744073709551616.0),
        json!("x"),
    ];
    let fields: [(&str, &str); 9] = [
        ("/duration_s", "duration_s"),
        ("/seed", "seed"),
        ("/nodes/1/start/0", "nodes[1].start"),
        ("/nodes/0/position/2", "nodes[0].position"),
        ("/nodes/2/waypoints/0/0", "nodes[2].waypoints[0]"),
        ("/nodes/2/waypoints/0/1", "nodes[2].waypoints[0]"),
        ("/nodes/1/address", "nodes[1].address"),
        ("/media/0/nodes/1", "media[0].nodes[1]"),
        ("/routes/0/2", "routes"),
    ];
    for (at, field) in fields {
        for value in &bad {
            let what = format!("{at} = {value}");
            let out = tdma(&scenario(dir.path(), &with(at, value.clone())), &[]);
            // -1 and -0 are fine coordinates; -0 is not below 0 s.
            if out.code == Some(0) {
                let coordinate = at.contains("/start/")
                    || at.contains("/position/")
                    || at.ends_with("/waypoints/0/1");
                let small = value.as_f64().is_some_and(|v| v == 0.0 || v == -1.0);
                let time_zero = at.ends_with("/waypoints/0/0") && value.as_f64() == Some(0.0);
                assert!((coordinate && small) || time_zero, "{what}: accepted");
                continue;
            }
            assert_refused(&out, &dir.path().join("scenario.json"), field, &what);
        }
    }
    let mut s = base();
    s["nodes"][1]["slot_s"] = json!(1e300);
    let out = tdma(&scenario(dir.path(), &s), &[]);
    assert_refused(
        &out,
        &dir.path().join("scenario.json"),
        "nodes[1].slot_s",
        "slot 1e300",
    );
    for (value, wanted) in [
        (json!({"size_bytes": 1e300}), "image.size_bytes"),
        (json!({"size_bytes": -0.0}), "image.size_bytes"),
        (json!({"trunk_bytes": 0}), "image.trunk_bytes"),
        (json!({"trunk_bytes": 1e9}), "image.trunk_bytes"),
    ] {
        let mut s = base();
        s["image"] = value.clone();
        let out = tdma(&scenario(dir.path(), &s), &[]);
        assert_refused(
            &out,
            &dir.path().join("scenario.json"),
            wanted,
            &value.to_string(),
        );
    }
}

#[test]
fn networks_that_cannot_be_are_refused_by_field() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "garbage.model", &garbage(500, 3));
    let fifo = dir.path().join("fifo.model");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    std::fs::create_dir(dir.path().join("folder.model")).unwrap();
    let mut sixteen = base();
    sixteen["nodes"] = json!(
        (0..16)
            .map(|a| if a == 0 {
                json!({"address": 0, "role": "operator"})
            } else {
                json!({"address": a, "role": "rov"})
            })
            .collect::<Vec<_>>()
    );
    sixteen["media"][0]["nodes"] = json!((0..16).collect::<Vec<_>>());
    let mut duplicate_media = base();
    duplicate_media["media"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "rf", "model": "s100", "nodes": [1, 2]}));
    let cases: Vec<(Value, &str)> = vec![
        (sixteen, "nodes[15].address"),
        (duplicate_media, "given twice"),
        (
            with("/media/0/model", json!("missing.model")),
            "media[0].model",
        ),
        (
            with("/media/0/model", json!("garbage.model")),
            "media[0].model",
        ),
        (
            with("/media/0/model", json!("folder.model")),
            "not a regular file",
        ),
        (
            with("/media/0/model", json!("fifo.model")),
            "not a regular file",
        ),
        (
            with("/media/0/model", json!("scenario.json")),
            "media[0].model",
        ),
        (
            with("/media/0/model", json!({"range_max_m": 0})),
            "media[0].model",
        ),
        (with("/media/0/name", json!("a\nb")), "media[0].name"),
        (
            with("/media/0/name", json!("é".repeat(65))),
            "media[0].name",
        ),
        (with("/routes", json!({"0": {"9": 1}})), "routes"),
        (with("/routes", json!({"0": {"2": 9}})), "routes"),
        (
            with("/routes", json!({"0": {"2": 1}, "1": {"2": 0}})),
            "loops",
        ),
        (with("/media/0/nodes", json!([0, 1])), "nodes[2]"),
    ];
    for (value, wanted) in cases {
        let out = tdma(&scenario(dir.path(), &value), &[]);
        assert_refused(&out, &dir.path().join("scenario.json"), wanted, wanted);
    }
}

fn metrics(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn images(m: &Value, vehicle: &str) -> u64 {
    m["vehicles"][vehicle]["images_completed"]
        .as_u64()
        .unwrap_or(0)
}

#[test]
fn odd_but_valid_networks_run() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("m.json");
    let m_arg = out_path.to_str().unwrap().to_string();
    // Fourteen vehicles and the operator at one spot, no routes.
    let mut crowd = base();
    crowd["nodes"] = json!(
        (0..15)
            .map(|a| if a == 0 {
                json!({"address": 0, "role": "operator", "position": [1, 1, 1]})
            } else {
                json!({"address": a, "role": "rov", "start": [1, 1, 1]})
            })
            .collect::<Vec<_>>()
    );
    crowd["media"][0]["nodes"] = json!((0..15).collect::<Vec<_>>());
    crowd.as_object_mut().unwrap().remove("routes");
    let out = tdma(&scenario(dir.path(), &crowd), &["--metrics", &m_arg]);
    assert_contract(&out, &[0], "14 vehicles at one spot");
    assert_eq!(
        metrics(&out_path)["vehicles"].as_object().unwrap().len(),
        14
    );
    // Vehicle 2 only on a second medium with vehicle 1, no routes: unreachable, not an error.
    let mut apart = base();
    apart["media"] = json!([{"name": "a", "model": "s100", "nodes": [0, 1]},
                            {"name": "b", "model": "s100", "nodes": [1, 2]}]);
    apart.as_object_mut().unwrap().remove("routes");
    let out = tdma(&scenario(dir.path(), &apart), &["--metrics", &m_arg]);
    assert_contract(&out, &[0], "unreachable vehicle");
    let m = metrics(&out_path);
    assert!(images(&m, "1") > 0, "{m}");
    assert_eq!(images(&m, "2"), 0, "{m}");
    // A vehicle on two media with no route, slots at their bounds, a waypoint at the end.
    let mut two = base();
    two["media"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "b", "model": "s100", "nodes": [1, 2]}));
    two.as_object_mut().unwrap().remove("routes");
    two["nodes"][1]["slot_s"] = json!(0.001);
    two["nodes"][2]["slot_s"] = json!(600);
    two["nodes"][2]["waypoints"] = json!([[604800, 1, 1, 1, -0.0]]);
    let out = tdma(&scenario(dir.path(), &two), &["--metrics", &m_arg]);
    assert_contract(&out, &[0], "two media, slots at bounds");
    // Hostile link flags and seeds on the scenario.
    let path = scenario(dir.path(), &base());
    for flags in [
        &["--loss-percent", "100"][..],
        &["--ber", "0.5"],
        &["--bitrate-bps", "1"],
        &["--seed", "18446744073709551615"],
        &["--duration", "3600", "--bitrate-bps", "1"],
    ] {
        let mut args = flags.to_vec();
        args.extend(["--metrics", &m_arg]);
        let started = Instant::now();
        let out = tdma(&path, &args);
        assert_contract(&out, &[0], &format!("{flags:?}"));
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "{flags:?} slow"
        );
        metrics(&out_path);
    }
    for flags in [
        &["--seed", "18446744073709551616"][..],
        &["--model", "s100"],
    ] {
        assert_contract(&tdma(&path, flags), &[2], &format!("{flags:?}"));
    }
}

#[test]
fn outputs_that_are_the_scenario_full_or_closed() {
    let dir = tempfile::tempdir().unwrap();
    let path = scenario(dir.path(), &base());
    let before = std::fs::read(&path).unwrap();
    let p = path.to_str().unwrap();
    for flag in ["--metrics", "--events", "--track", "--telemetry", "--mcap"] {
        let out = tdma(&path, &[flag, p]);
        assert_contract(&out, &[2], flag);
        assert!(out.stderr.contains(flag), "{flag}: {}", out.stderr);
        assert_eq!(
            std::fs::read(&path).unwrap(),
            before,
            "{flag} wrote the scenario"
        );
    }
    for flag in ["--metrics", "--events", "--mcap"] {
        let out = tdma(&path, &[flag, "/dev/full"]);
        assert_contract(&out, &[1, 2], flag);
        assert!(out.stderr.contains("/dev/full"), "{flag}: {}", out.stderr);
    }
    let out = head_one(TDMA_RUN, &["--scenario", p, "--events", "-"], b"", LIMIT);
    assert_contract(&out, &[0, 1], "--events - | head -1");
    assert!(temp_files(dir.path()).is_empty());
}

#[test]
fn signals_mid_run_leave_whole_outputs_marked_interrupted() {
    for (signal, code) in [(Signal::SIGTERM, 143), (Signal::SIGINT, 130)] {
        let dir = tempfile::tempdir().unwrap();
        let path = scenario(dir.path(), &base());
        let args = [
            "--scenario",
            path.to_str().unwrap(),
            "--duration",
            "604800",
            "--metrics",
            "m.json",
            "--events",
            "e.csv",
            "--mcap",
            "r.mcap",
        ];
        // A week does not end in a test's time: signalled once events are written.
        let out = signal_when(
            dir.path(),
            TDMA_RUN,
            &args,
            Stdin::Bytes(b""),
            SignalWhen {
                signal,
                ready: &|seen| seen.lines_in("e.csv") > 20,
            },
            LIMIT,
        );
        assert_contract(&out, &[code], &format!("{signal:?}"));
        let m = metrics(&dir.path().join("m.json"));
        let name = format!("{signal:?}");
        assert_eq!(m["interrupted"], json!(name), "{m}");
        assert_eq!(m["vehicles"]["2"]["interrupted"], json!(name), "{m}");
        let events = std::fs::read_to_string(dir.path().join("e.csv")).unwrap();
        assert!(events.ends_with('\n'), "events cut mid-line");
        let mcap = std::fs::read(dir.path().join("r.mcap")).unwrap();
        assert!(
            mcap.ends_with(b"\x89MCAP0\r\n"),
            "MCAP without its footer magic"
        );
        assert!(temp_files(dir.path()).is_empty());
    }
}
