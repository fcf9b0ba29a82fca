//! modem-bench as a process: simulated campaigns and their model files, real-time campaigns
//! through link-sim's pseudo-terminals (transparent and EvoLogics dialects), an echoing far end,
//! and a port that vanishes mid-run.

use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::hostile::{lines_in, signal_once};
use crate::common::{open_pty, run};
use nix::sys::signal::Signal;

const MODEM_BENCH: &str = env!("TOOL_EXE_modem-bench");
const LINK_SIM: &str = env!("TOOL_EXE_link-sim");

fn rows(csv: &str) -> Vec<Vec<String>> {
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("seq,size_bytes,t_tx_s,t_rx_s,delay_ms,delivered,corrupted")
    );
    lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

#[test]
fn a_simulated_sweep_fits_the_model_it_ran_on() {
    let dir = tempfile::tempdir().unwrap();
    let summary = dir.path().join("s.json");
    let fitted = dir.path().join("fitted.json");
    let out = run(
        MODEM_BENCH,
        &[
            "--sim",
            "s100",
            "--sizes",
            "16,57,100",
            "--count",
            "500",
            "--summary",
            summary.to_str().unwrap(),
            "--fit",
            fitted.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    let rows = rows(&out.stdout_text());
    assert_eq!(rows.len(), 1500);
    assert_eq!(rows[1][1], "57");
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    for field in [
        "count",
        "delivered",
        "loss_ratio",
        "delay_ms_mean",
        "delay_ms_p50",
        "delay_ms_p99",
        "jitter_ms",
        "jitter_rfc3550_ms",
        "iat_ms_mean",
        "iat_ms_std",
        "throughput_bps",
        "fit_bitrate_bps",
        "fit_intrinsic_delay_ms",
    ] {
        assert!(s[field].is_number(), "{field}: {}", s[field]);
    }
    let rate = s["fit_bitrate_bps"].as_f64().unwrap();
    assert!((rate / 1900.0 - 1.0).abs() < 0.03, "{rate}");
    let intrinsic = s["fit_intrinsic_delay_ms"].as_f64().unwrap();
    assert!((intrinsic - 85.0).abs() < 3.0, "{intrinsic}");
    let jitter = s["fit_jitter_ms"].as_f64().unwrap();
    assert!((jitter / 13.2 - 1.0).abs() < 0.1, "{jitter}");

    // The fitted model is a model file the other tools take.
    let again = run(
        MODEM_BENCH,
        &[
            "--model-file",
            fitted.to_str().unwrap(),
            "--count",
            "300",
            "-q",
        ],
        b"",
    );
    assert_eq!(again.code, 0, "{}", again.stderr);
    let printed = run(
        LINK_SIM,
        &["--model-file", fitted.to_str().unwrap(), "--print-model"],
        b"",
    );
    assert_eq!(printed.code, 0, "{}", printed.stderr);
}

#[test]
fn the_same_seed_gives_the_same_rows() {
    let args = ["--sim", "s100", "--ber", "1e-3", "--count", "300", "-q"];
    let first = run(MODEM_BENCH, &args, b"");
    let second = run(MODEM_BENCH, &args, b"");
    assert_eq!(first.code, 0, "{}", first.stderr);
    assert_eq!(first.stdout, second.stdout);
    let lost = rows(&first.stdout_text())
        .iter()
        .filter(|r| r[5] == "false")
        .count();
    assert!(
        (50..120).contains(&lost),
        "{lost} of 300 lost at a 37 % frame error rate"
    );
}

#[test]
fn bad_arguments_are_refused() {
    let out = run(MODEM_BENCH, &["--sim", "s100", "--size", "10"], b"");
    assert_eq!(out.code, 2);
    assert!(
        out.stderr
            .contains("--size: expected 15 ..= 260 bytes, found 10"),
        "{}",
        out.stderr
    );
    let out = run(MODEM_BENCH, &["--sim", "nope"], b"");
    assert_eq!(out.code, 2);
    assert!(
        out.stderr.contains("unknown model `nope`"),
        "{}",
        out.stderr
    );
    let out = run(
        MODEM_BENCH,
        &["--sim", "s100", "--dialect", "evologics"],
        b"",
    );
    assert_eq!(out.code, 2);
    assert!(out.stdout.is_empty());
}

/// modem-bench's `--timeout` in the real-time tests: a probe later than this counts as lost.
/// Only a hang takes so long; it lengthens no run (a campaign ends when every probe is in).
const PROBE_TIMEOUT: &str = "10";

/// The most a signalled or unplugged tool takes to end: only a hang takes this long.
const EXIT_LIMIT: Duration = Duration::from_secs(30);

/// Ends a link-sim with SIGTERM, once it catches it.
fn stop(child: &mut Child) {
    signal_once(child, Signal::SIGTERM, &|| true, EXIT_LIMIT);
    crate::common::wait_for_exit(child, EXIT_LIMIT);
}

#[test]
fn real_time_through_link_sim_measures_its_model() {
    let (mut sim, a, b) = crate::common::link_sim_pty(&["--model", "s100", "--jitter-ms", "0"]);
    let out = run(
        MODEM_BENCH,
        &[
            "--tx",
            &a,
            "--rx",
            &b,
            "--sizes",
            "16,57",
            "--count",
            "3",
            "--interval",
            "150",
            "--timeout",
            PROBE_TIMEOUT,
        ],
        b"",
    );
    stop(&mut sim);
    assert_eq!(out.code, 0, "{}", out.stderr);
    let rows = rows(&out.stdout_text());
    assert_eq!(rows.len(), 6);
    for row in &rows {
        assert_eq!(row[5], "true", "{row:?}");
        let size: f64 = row[1].parse().unwrap();
        let delay: f64 = row[4].parse().unwrap();
        let expected = 85.0 + size * 8.0 / 1900.0 * 1e3;
        // Frames queue behind each other at 150 ms intervals (up to about 200 ms): never
        // earlier than the model. Above, only a bound on a hang: a loaded machine delivers
        // late (the model's exact delays are checked in virtual time, tests/cli_link.rs).
        assert!(delay >= expected - 1.0, "{row:?} vs {expected}");
        assert!(delay < expected + 5000.0, "{row:?} vs {expected}");
    }
}

#[test]
fn the_evologics_dialect_works_end_to_end() {
    let (mut sim, a, b) = crate::common::link_sim_pty(&[
        "--model",
        "s2cr-burst",
        "--jitter-ms",
        "0",
        "--dialect",
        "evologics",
    ]);
    let out = run(
        MODEM_BENCH,
        &[
            "--tx",
            &a,
            "--rx",
            &b,
            "--dialect",
            "evologics",
            "--sizes",
            "16,57",
            "--count",
            "2",
            "--interval",
            "400",
            "--timeout",
            PROBE_TIMEOUT,
        ],
        b"",
    );
    stop(&mut sim);
    assert_eq!(out.code, 0, "{}", out.stderr);
    let rows = rows(&out.stdout_text());
    assert_eq!(rows.len(), 4);
    assert!(rows.iter().all(|r| r[5] == "true"), "{rows:?}");
    let first: f64 = rows.iter().find(|r| r[0] == "0").unwrap()[4]
        .parse()
        .unwrap();
    // 443 ms + 16 bytes at 1620 bit/s (79 ms) + 0.67 ms of propagation; late only by a
    // loaded machine (the bound above is one on a hang).
    assert!((522.0..6000.0).contains(&first), "{first}");
}

#[test]
fn an_echoing_far_end_gives_round_trips() {
    let (mut master, path) = open_pty();
    let (done, finished) = std::sync::mpsc::channel::<()>();
    let echo = std::thread::spawn(move || {
        let mut buf = [0u8; 256];
        let mut echoed = 0;
        while echoed < 3 * 20 {
            match master.read(&mut buf) {
                Ok(n) if n > 0 => {
                    std::thread::sleep(Duration::from_millis(30));
                    master.write_all(&buf[..n]).unwrap();
                    echoed += n;
                }
                _ => break,
            }
        }
        // Keep the line open until modem-bench has read the last echo: until it has ended.
        let _ = finished.recv_timeout(Duration::from_secs(120));
    });
    let out = run(
        MODEM_BENCH,
        &[
            "--port",
            &path,
            "--echo",
            "--size",
            "20",
            "--count",
            "3",
            "--interval",
            "100",
            "--timeout",
            PROBE_TIMEOUT,
        ],
        b"",
    );
    done.send(()).unwrap();
    echo.join().unwrap();
    assert_eq!(out.code, 0, "{}", out.stderr);
    let rows = rows(&out.stdout_text());
    assert_eq!(rows.len(), 3);
    for row in rows {
        let delay: f64 = row[4].parse().unwrap();
        // The far end answers 30 ms late; above, a bound on a hang only.
        assert!((29.0..5000.0).contains(&delay), "{row:?}");
    }
}

#[test]
fn a_port_that_vanishes_keeps_the_rows_and_exits_1() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("packets.csv");
    let (mut tx_master, tx_path) = open_pty();
    let (mut rx_master, rx_path) = open_pty();
    let mut child = Command::new(MODEM_BENCH)
        .args([
            "--tx", &tx_path, "--rx", &rx_path, "--size", "20", "--count", "50",
        ])
        .args(["--interval", "100", "--timeout", PROBE_TIMEOUT, "-o"])
        .arg(&csv)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Forward the first two probes by hand, then unplug the receiving modem.
    let mut forwarded = 0;
    let mut buf = [0u8; 64];
    while forwarded < 40 {
        let n = tx_master.read(&mut buf).unwrap();
        rx_master.write_all(&buf[..n]).unwrap();
        forwarded += n;
    }
    // Unplug once modem-bench has recorded both (the header and two rows), not after a guess.
    let started = Instant::now();
    while lines_in(&csv) < 3 {
        assert!(
            child.try_wait().unwrap().is_none(),
            "modem-bench ended before recording the forwarded probes"
        );
        assert!(
            started.elapsed() < EXIT_LIMIT,
            "the forwarded probes were not recorded"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    drop(rx_master);
    let status = crate::common::wait_for_exit(&mut child, EXIT_LIMIT);
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert!(stderr.contains(&rx_path), "{stderr}");
    let kept = rows(&std::fs::read_to_string(&csv).unwrap());
    assert!(kept.len() >= 2, "{kept:?}");
    assert!(kept.iter().take(2).all(|r| r[5] == "true"), "{kept:?}");
    drop(tx_master);
}

#[test]
fn udp_endpoints_through_link_sim() {
    let free = || {
        std::net::UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .to_string()
    };
    let (sim_a, sim_b, tx, rx) = (free(), free(), free(), free());
    let mut sim = Command::new(LINK_SIM)
        .args(["--jitter-ms", "0", "--udp-a", &sim_a, "--udp-b", &sim_b])
        .args(["--udp-b-peer", &rx])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(sim.stderr.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    let out = run(
        MODEM_BENCH,
        &[
            "--tx",
            &format!("udp:{tx}={sim_a}"),
            "--rx",
            &format!("udp:{rx}={sim_b}"),
            "--size",
            "30",
            "--count",
            "3",
            "--interval",
            "300",
            "--timeout",
            PROBE_TIMEOUT,
        ],
        b"",
    );
    stop(&mut sim);
    assert_eq!(out.code, 0, "{}", out.stderr);
    let rows = rows(&out.stdout_text());
    assert_eq!(rows.len(), 3);
    for row in rows {
        let delay: f64 = row[4].parse().unwrap();
        // 85 ms + 30 bytes at 1900 bit/s; above, a bound on a hang only.
        assert!((211.0..5000.0).contains(&delay), "{row:?}");
    }
}

#[test]
fn ctrl_c_keeps_the_rows_and_writes_the_summary() {
    let dir = tempfile::tempdir().unwrap();
    let (csv, summary) = (dir.path().join("p.csv"), dir.path().join("s.json"));
    let (mut sim, a, b) = crate::common::link_sim_pty(&["--model", "s100", "--jitter-ms", "0"]);
    let mut child = Command::new(MODEM_BENCH)
        .args(["--tx", &a, "--rx", &b, "--size", "20", "--count", "1000"])
        .args(["--interval", "100", "-o"])
        .arg(&csv)
        .arg("--summary")
        .arg(&summary)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Ctrl-C once five rows are in the file (it runs for 100 s otherwise).
    let rows_in = || lines_in(&csv) >= 6;
    signal_once(
        &mut child,
        Signal::SIGINT,
        &rows_in,
        Duration::from_secs(60),
    );
    let status = crate::common::wait_for_exit(&mut child, EXIT_LIMIT);
    stop(&mut sim);
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    assert_eq!(status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("stopped:"), "{stderr}");
    let kept = rows(&std::fs::read_to_string(&csv).unwrap());
    assert!(kept.len() >= 5, "{} rows", kept.len());
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert_eq!(s["count"].as_u64().unwrap(), kept.len() as u64);
}
