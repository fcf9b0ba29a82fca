//! tdma-run as a process: the built-in session, metrics and events files, waypoints from a file,
//! bad input.

mod common;

use common::run;

const TDMA_RUN: &str = env!("CARGO_BIN_EXE_tdma-run");

#[test]
fn a_session_writes_metrics_and_one_event_per_frame() {
    let dir = tempfile::tempdir().unwrap();
    let (metrics, events) = (dir.path().join("m.json"), dir.path().join("e.csv"));
    let out = run(
        TDMA_RUN,
        &[
            "--ipg",
            "640",
            "--duration",
            "120",
            "--ber",
            "7e-4",
            "--metrics",
            metrics.to_str().unwrap(),
            "--events",
            events.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(out.stderr.contains("throughput kbit/s"), "{}", out.stderr);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&metrics).unwrap()).unwrap();
    for direction in ["rov_to_operator", "operator_to_rov"] {
        for field in [
            "throughput_kbps",
            "delay_ms",
            "jitter_ms",
            "iat_ms",
            "iat_sigma_ms",
            "frames_sent",
            "frames_delivered",
        ] {
            assert!(m[direction][field].is_number(), "{direction}.{field}");
        }
    }
    assert_eq!(m["orders_executed_twice"], 0);
    let csv = std::fs::read_to_string(&events).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("direction,kind,bytes,t_sent_s,t_received_s,fate")
    );
    let rows: Vec<&str> = lines.collect();
    let sent = m["rov_to_operator"]["frames_sent"].as_u64().unwrap()
        + m["operator_to_rov"]["frames_sent"].as_u64().unwrap();
    assert_eq!(rows.len() as u64, sent);
    assert!(rows.iter().any(|r| r.contains(",ber")));
    assert!(
        rows.iter()
            .any(|r| r.starts_with("rov_to_operator,image_trunk,57,"))
    );
}

#[test]
fn waypoints_past_the_range_lose_and_regain_the_link() {
    let dir = tempfile::tempdir().unwrap();
    let (waypoints, metrics) = (dir.path().join("wp.csv"), dir.path().join("m.json"));
    std::fs::write(
        &waypoints,
        "t_s,x_m,y_m,z_m,heading_deg\n5,2,0,1,0\n40,8,0,1,0\n",
    )
    .unwrap();
    let out = run(
        TDMA_RUN,
        &[
            "--waypoints",
            waypoints.to_str().unwrap(),
            "--buoy",
            "0,0,0",
            "--start",
            "1,0,1",
            "--duration",
            "200",
            "--metrics",
            metrics.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&metrics).unwrap()).unwrap();
    assert!(m["link_losses"].as_u64().unwrap() >= 1, "{m}");
    assert!(m["link_recoveries"].as_u64().unwrap() >= 1, "{m}");
}

#[test]
fn bad_input_names_the_file_line_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let waypoints = dir.path().join("wp.csv");
    std::fs::write(&waypoints, "t_s,x_m,y_m,z_m,heading_deg\n5,2,0,north,0\n").unwrap();
    let out = run(TDMA_RUN, &["--waypoints", waypoints.to_str().unwrap()], b"");
    assert_eq!(out.code, 2);
    assert!(
        out.stderr
            .contains("wp.csv: line 2: field `z_m`: expected a number, found `north`"),
        "{}",
        out.stderr
    );
    let out = run(TDMA_RUN, &["--ipg", "fast"], b"");
    assert_eq!(out.code, 2);
    assert!(out.stderr.contains("--ipg"), "{}", out.stderr);
    let out = run(TDMA_RUN, &["--buoy", "1,2"], b"");
    assert_eq!(out.code, 2);
}
