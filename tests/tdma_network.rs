//! tdma-run --scenario as a process: the example scenarios of `scenarios/`, their outputs per
//! vehicle and per hop, overrides, and bad scenarios (one line naming the file and the field,
//! exit 2, no output left).

use std::path::{Path, PathBuf};

use crate::common::run;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");

fn scenario(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenarios")
        .join(name)
}

fn metrics(args: &[&str]) -> serde_json::Value {
    let out = run(TDMA_RUN, args, b"");
    assert_eq!(out.code, 0, "{}", out.stderr);
    serde_json::from_slice(&out.stdout).expect("metrics JSON on stdout")
}

#[test]
fn the_relay_scenario_reaches_the_far_vehicle_and_writes_per_vehicle_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let (events, track, images, log) = (
        dir.path().join("e.csv"),
        dir.path().join("t.csv"),
        dir.path().join("rx"),
        dir.path().join("s.mcap"),
    );
    let file = scenario("relay-rf.json");
    let m = metrics(&[
        "--scenario",
        file.to_str().unwrap(),
        "--duration",
        "120",
        "--metrics",
        "-",
        "--events",
        events.to_str().unwrap(),
        "--track",
        track.to_str().unwrap(),
        "--images-out",
        images.to_str().unwrap(),
        "--mcap",
        log.to_str().unwrap(),
    ]);
    assert_eq!(m["duration_s"], 120.0);
    for v in ["1", "2"] {
        assert!(
            m["vehicles"][v]["images_completed"].as_u64().unwrap() >= 1,
            "{m:#}"
        );
        assert_eq!(m["vehicles"][v]["orders_executed_twice"], 0);
        assert!(
            images
                .join(format!("vehicle-{v}"))
                .join("image-0001.png")
                .is_file()
        );
    }
    assert_eq!(m["vehicles"]["2"]["orders_executed"], 1, "{m:#}");
    assert!(m["nodes"]["1"]["frames_forwarded"].as_u64().unwrap() > 100);
    let events = std::fs::read_to_string(&events).unwrap();
    let mut lines = events.lines();
    assert_eq!(
        lines.next(),
        Some("direction,kind,bytes,t_sent_s,t_received_s,fate,medium,src,dst,tx,rx,action")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // The relay forwards the operator's polls of vehicle 2, which takes them from the relay.
    assert!(
        rows.iter()
            .any(|r| r[7..11] == ["0", "2", "0", "1"] && r[11] == "forwarded")
    );
    assert!(
        rows.iter()
            .any(|r| r[7..11] == ["0", "2", "1", "2"] && r[11] == "delivered")
    );
    // The operator never hears vehicle 2 itself.
    assert!(
        rows.iter()
            .filter(|r| r[9] == "2" && r[10] == "0")
            .all(|r| r[5] == "range")
    );
    let track = std::fs::read_to_string(&track).unwrap();
    assert!(track.starts_with("vehicle,t_s,x_m,y_m,z_m,heading_deg,link_up\n"));
    assert!(track.lines().any(|l| l.starts_with("2,")));
    // The official MCAP reader sees each vehicle's channels and every hop.
    let topics = mcap_topics(&log);
    for v in [1, 2] {
        assert!(
            topics[&format!("/vehicle/{v}/rov/pose")] > 1000,
            "{topics:?}"
        );
        assert!(
            topics[&format!("/vehicle/{v}/camera/image")] >= 1,
            "{topics:?}"
        );
    }
    assert_eq!(topics["/network/frames"], rows.len(), "{topics:?}");
}

/// Topic names and message counts of an MCAP file, read with Python's `mcap` package.
fn mcap_topics(path: &Path) -> std::collections::BTreeMap<String, usize> {
    let script = r#"
import json, sys, collections
from mcap.reader import make_reader
counts = collections.Counter()
with open(sys.argv[1], 'rb') as f:
    for schema, channel, message in make_reader(f).iter_messages():
        json.loads(message.data)
        counts[channel.topic] += 1
print(json.dumps(counts))
"#;
    let out = std::process::Command::new("python3")
        .args(["-c", script, path.to_str().unwrap()])
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn seed_and_duration_override_the_file_and_link_flags_change_every_medium() {
    let file = scenario("relay-rf.json");
    let base = ["--scenario", file.to_str().unwrap(), "--metrics", "-"];
    let short = |extra: &[&str]| {
        let mut args = base.to_vec();
        args.extend(["--duration", "60"]);
        args.extend(extra);
        metrics(&args)
    };
    let (a, b, c) = (short(&[]), short(&["--seed", "7"]), short(&[]));
    assert_eq!(a.to_string(), c.to_string(), "same seed, same run");
    assert_eq!(b["seed"], 7);
    assert_ne!(a["vehicles"].to_string(), b["vehicles"].to_string());
    let lossy = short(&["--loss-percent", "30"]);
    let lost = |m: &serde_json::Value| m["media"]["rf"]["receptions_lost"].as_u64().unwrap();
    assert_eq!(lost(&a), 0);
    assert!(lost(&lossy) > 50, "{lossy:#}");
}

#[test]
fn bad_scenarios_are_one_line_and_exit_2_with_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let metrics_path = dir.path().join("m.json");
    let bad = dir.path().join("bad.json");
    let cases: Vec<(String, Vec<&str>, &str)> = vec![
        (
            r#"{"nodes":[{"address":0,"role":"operator"},{"address":1,"role":"rov"}],
                "media":[{"model":"s100","nodes":[0,1]}],"routes":{"0":{"1":3}}}"#
                .into(),
            vec![],
            "routes",
        ),
        (
            r#"{"nodes":[{"address":0,"role":"operator"},{"address":1,"role":"rov"},
                {"address":2,"role":"rov"},{"address":3,"role":"rov"}],
                "media":[{"model":"s100","nodes":[0,1,2,3]}],
                "routes":{"1":{"3":2},"2":{"3":1}}}"#
                .into(),
            vec![],
            "loops: 1 -> 2 -> 1",
        ),
        (
            r#"{"nodes":[{"address":0,"role":"operator"},{"address":1,"role":"rov"},
                {"address":2,"role":"rov"}],
                "media":[{"model":"s100","nodes":[0,1]},{"model":"s100","nodes":[1,2]}],
                "routes":{"0":{"2":2}}}"#
                .into(),
            vec![],
            "share no interface",
        ),
        ("{\"nodes\": [".into(), vec![], "not JSON"),
        (
            String::from_utf8_lossy(&[0xff, 0xfe, 0]).into_owned(),
            vec![],
            "bad.json",
        ),
        (
            std::fs::read_to_string(scenario("relay-rf.json")).unwrap(),
            vec!["--model", "s2cr-burst"],
            "--model",
        ),
        (
            std::fs::read_to_string(scenario("relay-rf.json")).unwrap(),
            vec!["--duration", "nan"],
            "--duration",
        ),
    ];
    for (text, extra, needle) in cases {
        std::fs::write(&bad, text).unwrap();
        let mut args = vec![
            "--scenario",
            bad.to_str().unwrap(),
            "--metrics",
            metrics_path.to_str().unwrap(),
        ];
        args.extend(extra);
        let out = run(TDMA_RUN, &args, b"");
        assert_eq!(out.code, 2, "{needle}: {}", out.stderr);
        assert_eq!(out.stderr.trim_end().lines().count(), 1, "{}", out.stderr);
        assert!(out.stderr.contains(needle), "{needle}: {}", out.stderr);
        assert!(!metrics_path.exists());
    }
    let missing = run(TDMA_RUN, &["--scenario", "/nonexistent/s.json"], b"");
    assert_eq!(missing.code, 2);
    assert!(
        missing.stderr.contains("/nonexistent/s.json"),
        "{}",
        missing.stderr
    );
    let file = scenario("relay-rf.json");
    let with_role = run(
        TDMA_RUN,
        &[
            "--scenario",
            file.to_str().unwrap(),
            "--role",
            "rov",
            "--port",
            "x",
        ],
        b"",
    );
    assert_eq!(with_role.code, 2, "{}", with_role.stderr);
    let same = run(
        TDMA_RUN,
        &[
            "--scenario",
            file.to_str().unwrap(),
            "--metrics",
            file.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(same.code, 2, "{}", same.stderr);
}
