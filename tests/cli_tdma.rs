//! tdma-run as a process: the built-in session, metrics and events files, waypoints from a file,
//! bad input.

use std::io::{BufRead, Read};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use crate::common::run;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");

/// How long a process may take to show a sign (a line, a byte) or to end when it should:
/// only a hang takes this long, however loaded the machine.
const LIMIT: Duration = Duration::from_secs(30);

/// A child's output read line by line in a thread, as it comes: the test waits for the line
/// that says the child is under way, and keeps everything said for its messages.
struct Said {
    lines: Receiver<String>,
    text: String,
}

impl Said {
    fn of(stream: impl Read + Send + 'static) -> Said {
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stream).lines() {
                let Ok(line) = line else { return };
                if tx.send(line).is_err() {
                    return;
                }
            }
        });
        Said {
            lines,
            text: String::new(),
        }
    }

    /// Waits until a line holds `text`; fails if the stream ends first (the child ended) or
    /// `limit` passes.
    fn wait_for(&mut self, text: &str, limit: Duration) {
        let deadline = Instant::now() + limit;
        loop {
            match self
                .lines
                .recv_timeout(deadline.saturating_duration_since(Instant::now()))
            {
                Ok(line) => {
                    self.text.push_str(&line);
                    self.text.push('\n');
                    if line.contains(text) {
                        return;
                    }
                }
                Err(RecvTimeoutError::Timeout) => {
                    panic!("nothing said {text:?} within {limit:?}: {}", self.text)
                }
                Err(RecvTimeoutError::Disconnected) => {
                    panic!("ended before saying {text:?}: {}", self.text)
                }
            }
        }
    }

    /// Everything said, to the end of the stream (once the child has ended).
    fn rest(mut self) -> String {
        for line in self.lines.iter() {
            self.text.push_str(&line);
            self.text.push('\n');
        }
        self.text
    }
}

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
        Some("direction,kind,bytes,t_sent_s,t_received_s,fate,medium,src,dst,tx,rx,action")
    );
    let rows: Vec<&str> = lines.collect();
    // A frame counts as sent when it goes out; its row comes with its fate, so the frames
    // still in flight at the end (one slot's exchange at most) have none.
    let sent = m["rov_to_operator"]["frames_sent"].as_u64().unwrap()
        + m["operator_to_rov"]["frames_sent"].as_u64().unwrap();
    assert!(
        rows.len() as u64 <= sent && sent - rows.len() as u64 <= 2,
        "{} rows, {sent} sent",
        rows.len()
    );
    assert!(rows.iter().any(|r| r.contains(",ber")));
    assert!(
        rows.iter()
            .any(|r| r.starts_with("rov_to_operator,image_trunk,57,"))
    );
}

/// The recovery scenario's flags but the waypoints' file: the buoy at the origin, the start
/// 1 m from it.
fn recovery(waypoints: &str) -> [&str; 6] {
    [
        "--waypoints",
        waypoints,
        "--buoy",
        "0,0,0",
        "--start",
        "1,0,1",
    ]
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
    let mut args = recovery(waypoints.to_str().unwrap()).to_vec();
    args.extend(["--duration", "200", "--metrics", metrics.to_str().unwrap()]);
    let out = run(TDMA_RUN, &args, b"");
    assert_eq!(out.code, 0, "{}", out.stderr);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&metrics).unwrap()).unwrap();
    assert!(m["link_losses"].as_u64().unwrap() >= 1, "{m}");
    assert!(m["link_recoveries"].as_u64().unwrap() >= 1, "{m}");
}

#[test]
fn sleeping_through_a_still_vehicles_steps_changes_no_result() {
    // Without --track or --mcap the ROV end sleeps while the vehicle is still (issue 32); with
    // --track it runs every 0.1 s step. Moves, rests, a link loss and its recovery: the same
    // metrics and the same frames either way.
    let dir = tempfile::tempdir().unwrap();
    let waypoints = dir.path().join("wp.csv");
    std::fs::write(
        &waypoints,
        "t_s,x_m,y_m,z_m,heading_deg\n5,2,0,1,0\n40,8,0,1,0\n150,1,1,1,90\n",
    )
    .unwrap();
    let session = |name: &str, track: bool| {
        let (metrics, events) = (
            dir.path().join(format!("{name}.json")),
            dir.path().join(format!("{name}.csv")),
        );
        let track_path = dir.path().join(format!("{name}-track.csv"));
        let mut args = recovery(waypoints.to_str().unwrap()).to_vec();
        args.extend([
            "--ber",
            "1e-4",
            "--duration",
            "300",
            "--metrics",
            metrics.to_str().unwrap(),
            "--events",
            events.to_str().unwrap(),
        ]);
        if track {
            args.extend(["--track", track_path.to_str().unwrap()]);
        }
        let out = run(TDMA_RUN, &args, b"");
        assert_eq!(out.code, 0, "{}", out.stderr);
        let mut metrics = json(&metrics);
        // The flags given differ (the outputs' names, --track): not a result.
        metrics["params"] = serde_json::Value::Null;
        (metrics, std::fs::read_to_string(&events).unwrap())
    };
    let (stepped, stepped_events) = session("stepped", true);
    let (slept, slept_events) = session("slept", false);
    assert!(stepped["link_losses"].as_u64().unwrap() >= 1, "{stepped}");
    assert_eq!(stepped, slept);
    assert_eq!(stepped_events, slept_events);
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

fn json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Topic names and message counts of an MCAP file, read with the mcap crate.
fn mcap_topics(path: &std::path::Path) -> std::collections::BTreeMap<String, usize> {
    let bytes = std::fs::read(path).unwrap();
    let mut topics = std::collections::BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let value: serde_json::Value = serde_json::from_slice(&message.data).unwrap();
        assert!(value.is_object(), "{}", message.channel.topic);
        *topics.entry(message.channel.topic.clone()).or_insert(0) += 1;
    }
    topics
}

#[test]
fn the_two_ends_run_in_real_time_through_link_sim() {
    use std::process::{Command, Stdio};
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let (mut link, a, b) = crate::common::link_sim_pty(&crate::common::TEST_S100);
    let waypoints = path("wp.csv");
    std::fs::write(
        &waypoints,
        "t_s,x_m,y_m,z_m,heading_deg\n1,1.5,0,0,90\n4,1,0.5,0,0\n",
    )
    .unwrap();
    let mut rov = Command::new(TDMA_RUN)
        .args([
            "--role",
            "rov",
            "--port",
            &b,
            "--duration",
            "12",
            "--image-size",
            "400",
        ])
        .args([
            "--metrics",
            &path("rov.json"),
            "--track",
            &path("track.csv"),
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The operator starts once the ROV listens on its port (it says so), not after a guess.
    let mut rov_said = Said::of(rov.stderr.take().unwrap());
    rov_said.wait_for("ROV: answering every slot", LIMIT);
    let op = run(
        TDMA_RUN,
        &[
            "--role",
            "operator",
            "--port",
            &a,
            "--ipg",
            "150",
            "--duration",
            "9",
            "--image-size",
            "400",
            "--waypoints",
            &waypoints,
            "--metrics",
            &path("op.json"),
            "--events",
            &path("op.csv"),
            "--mcap",
            &path("op.mcap"),
            "--images-out",
            &path("images"),
        ],
        b"",
    );
    assert_eq!(op.code, 0, "{}", op.stderr);
    let status = crate::common::wait_for_exit(&mut rov, LIMIT);
    let _ = link.kill();
    let _ = link.wait();
    assert!(status.success(), "ROV end: {status:?}: {}", rov_said.rest());

    let (o, r) = (
        json(&dir.path().join("op.json")),
        json(&dir.path().join("rov.json")),
    );
    assert_eq!(o["measured_by"], "operator");
    assert_eq!(r["measured_by"], "rov");
    // 400 bytes are 11 trunks of 39: one image every 11 slots of 150 ms when nothing is lost.
    // (A debug build on a busy machine misses some slots: the bounds are loose.)
    let images = o["images_completed"].as_u64().unwrap();
    assert!(images >= 2, "{o}");
    assert_eq!(o["orders_sent"], 2, "{o}");
    assert_eq!(o["orders_acknowledged"], 2, "{o}");
    assert_eq!(r["orders_executed"], 2, "{r}");
    // One harness for both drivers: every end reports the simulation's fields.
    for key in [
        "measured_by",
        "rov_to_operator",
        "operator_to_rov",
        "images_started",
        "images_completed",
        "image_period_s",
        "orders_sent",
        "orders_acknowledged",
        "orders_executed",
        "orders_executed_twice",
        "orders_acknowledged_unexecuted",
        "link_losses",
        "link_recoveries",
        "duration_s",
    ] {
        assert!(
            o.get(key).is_some() && r.get(key).is_some(),
            "{key}: {o} {r}"
        );
    }
    assert_eq!(r["orders_executed_twice"], 0, "{r}");
    let sent = o["operator_to_rov"]["frames_sent"].as_u64().unwrap();
    let heard = r["operator_to_rov"]["frames_delivered"].as_u64().unwrap();
    assert!(
        sent >= 30 && heard == sent,
        "sent {sent}, ROV heard {heard}"
    );
    let rtt = o["round_trip_ms"].as_f64().unwrap();
    // 16 + 57 bytes at 9600 bit/s and 2 x 20 ms: about 101 ms.
    assert!((90.0..400.0).contains(&rtt), "{o}");
    assert_eq!(
        std::fs::read_dir(dir.path().join("images"))
            .unwrap()
            .count() as u64,
        images
    );
    let topics = mcap_topics(&dir.path().join("op.mcap"));
    assert_eq!(
        topics.get("/camera/image").copied(),
        Some(images as usize),
        "{topics:?}"
    );
    assert!(
        topics.get("/rov/pose").copied().unwrap_or(0) > 10,
        "{topics:?}"
    );
    // The ROV's track: a row per 0.1 s step, the first GoTo's goal in it.
    let track = std::fs::read_to_string(dir.path().join("track.csv")).unwrap();
    assert!(track.lines().count() > 100, "{track}");
    assert!(
        track.lines().any(|l| l.contains(",1.5000,0.0000,0.0000,")),
        "{track}"
    );
}

#[test]
fn a_simulated_session_logs_to_mcap_and_track() {
    let dir = tempfile::tempdir().unwrap();
    let (mcap, track) = (dir.path().join("s.mcap"), dir.path().join("t.csv"));
    let out = run(
        TDMA_RUN,
        &[
            "--sim",
            "--duration",
            "100",
            "--mcap",
            mcap.to_str().unwrap(),
            "--track",
            track.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    let topics = mcap_topics(&mcap);
    assert_eq!(topics.get("/rov/pose").copied(), Some(1001), "{topics:?}");
    for topic in [
        "/rov/velocity/actual",
        "/rov/velocity/commanded",
        "/link/frames",
        "/camera/image",
    ] {
        assert!(
            topics.get(topic).copied().unwrap_or(0) > 0,
            "{topic}: {topics:?}"
        );
    }
    let text = std::fs::read_to_string(&track).unwrap();
    assert_eq!(text.lines().count(), 1002);
    // Virtual time: the same seed gives the same file.
    let again = dir.path().join("again.mcap");
    let out = run(
        TDMA_RUN,
        &["--duration", "100", "--mcap", again.to_str().unwrap()],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert_eq!(
        std::fs::read(&mcap).unwrap(),
        std::fs::read(&again).unwrap()
    );
}

#[test]
fn a_port_that_closes_ends_the_run_with_exit_1_and_keeps_the_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let metrics = dir.path().join("m.json");
    let (mut link, a, b) = crate::common::link_sim_pty(&["--model", "s100"]);
    let mut op = std::process::Command::new(TDMA_RUN)
        .args(["--role", "operator", "--port", &a, "--duration", "60"])
        .args(["--metrics", metrics.to_str().unwrap()])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let said = Said::of(op.stderr.take().unwrap());
    // The link goes once the operator's first frame has crossed it: a byte at side B (which
    // link-sim keeps raw), not a guess at how long the operator takes to start.
    let far_end = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&b)
        .unwrap();
    let mut reader = far_end.try_clone().unwrap();
    let (tx, heard) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut byte = [0u8; 1];
        let _ = tx.send(reader.read(&mut byte).is_ok_and(|n| n == 1));
    });
    assert_eq!(
        heard.recv_timeout(LIMIT),
        Ok(true),
        "no frame from the operator"
    );
    let _ = link.kill();
    let _ = link.wait();
    let status = crate::common::wait_for_exit(&mut op, LIMIT);
    drop(far_end);
    assert_eq!(status.code(), Some(1), "{}", said.rest());
    let m = json(&metrics);
    assert!(
        m["operator_to_rov"]["frames_sent"].as_u64().unwrap() >= 1,
        "{m}"
    );
}

#[test]
fn real_time_flags_are_checked() {
    let out = run(TDMA_RUN, &["--role", "rov"], b"");
    assert_eq!(out.code, 2, "{}", out.stderr);
    let out = run(TDMA_RUN, &["--dialect", "evologics"], b"");
    assert_eq!(out.code, 2, "{}", out.stderr);
    assert!(out.stderr.contains("--role"), "{}", out.stderr);
    let out = run(
        TDMA_RUN,
        &["--role", "rov", "--port", "/nonexistent/tty"],
        b"",
    );
    assert_eq!(out.code, 2, "{}", out.stderr);
    assert!(out.stderr.contains("/nonexistent/tty"), "{}", out.stderr);
}
