//! tdma-run as a hostile user runs it: every numeric flag at NaN, inf, 0, negative and huge;
//! empty, random and truncated inputs; outputs that are inputs, /dev/full, two outputs on
//! standard output; camera pictures larger than DEBT holds; SIGTERM and SIGINT in the middle of
//! a long simulation; `| head -1`. Exit codes 0, 1, 2 (130/143 when interrupted), never a panic
//! or a signal death, never a hang; no output file left on exit 2, no temporary file ever.

use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::common::hostile::{
    BAD_NUMBERS, SignalWhen, Stdin, assert_contract, assert_whole_csv, garbage, head_one, lines_in,
    run, run_in, signal_once, signal_when, temp_files,
};
use nix::sys::signal::Signal;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");
const LIMIT: Duration = Duration::from_secs(60);

fn tdma(args: &[&str]) -> crate::common::hostile::Run {
    run(TDMA_RUN, args, b"", LIMIT)
}

/// A PNG of `width` x `height` grey-blue pixels.
fn png(width: usize, height: usize) -> Vec<u8> {
    rovlink_debt::picture::to_png(&rovlink_debt::Image {
        width,
        height,
        channels: 3,
        data: vec![90; width * height * 3],
    })
    .unwrap()
}

/// A 1x1 PNG whose header says `width` x `height` (the pixel data does not follow).
fn png_header(width: u32, height: u32) -> Vec<u8> {
    let mut bytes = png(1, 1);
    bytes[16..20].copy_from_slice(&width.to_be_bytes());
    bytes[20..24].copy_from_slice(&height.to_be_bytes());
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&bytes[12..29]);
    bytes[29..33].copy_from_slice(&crc.to_be_bytes());
    bytes
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn every_numeric_flag_at_nan_inf_zero_negative_and_huge() {
    let flags: [(&str, &str); 13] = [
        ("--ipg", "{}"),
        ("--duration", "{}"),
        ("--seed", "{}"),
        ("--buoy", "{},0,0"),
        ("--start", "0,{},0"),
        ("--image-size", "{}"),
        ("--trunk", "{}"),
        ("--roi", "{},0,100,100"),
        ("--ber", "{}"),
        ("--loss-percent", "{}"),
        ("--bitrate-bps", "{}"),
        ("--jitter-ms", "{}"),
        ("--fifo-bytes", "{}"),
    ];
    for (flag, shape) in flags {
        for bad in BAD_NUMBERS {
            let value = shape.replace("{}", bad);
            // --flag=VALUE: clap takes `-inf` after a space as a flag, not a value.
            let arg = format!("{flag}={value}");
            let mut args = vec![arg.as_str()];
            if flag != "--duration" {
                args.extend(["--duration", "2"]);
            }
            let out = tdma(&args);
            assert_contract(&out, &[0, 2], &format!("{flag} {value}"));
            if out.code == Some(2) {
                assert!(
                    out.stderr.starts_with(&format!("tdma-run: {flag}: ")),
                    "{flag} {value}: {}",
                    out.stderr
                );
            }
        }
    }
}

#[test]
fn the_issue_s_unbounded_values_are_refused_with_units() {
    let cases: [(&[&str], &str); 6] = [
        (
            &["--ipg", "1e-9"],
            "tdma-run: --ipg: expected 1 ms ..= 10 min, found 1e-9",
        ),
        (
            &["--duration", "1e300"],
            "tdma-run: --duration: expected more than 0 s, up to 7 d, found 1e300",
        ),
        (
            &["--trunk", "243"],
            "tdma-run: --trunk: expected 1 ..= 242 bytes, found 243",
        ),
        (
            &["--trunk", "255"],
            "tdma-run: --trunk: expected 1 ..= 242 bytes",
        ),
        (
            &["--image-size", "0"],
            "tdma-run: --image-size: expected 16 ..= 65535 bytes, found 0",
        ),
        (
            &["--buoy", "1e300,0,0"],
            "tdma-run: --buoy: number 1: expected -100000 m ..= 100000 m, found 1e300",
        ),
    ];
    for (args, message) in cases {
        let out = tdma(args);
        assert_contract(&out, &[2], &args.join(" "));
        assert!(out.stderr.starts_with(message), "{args:?}: {}", out.stderr);
        assert_eq!(out.stderr.lines().count(), 1, "{}", out.stderr);
    }
    // The trunk at its maximum still runs: a 260-byte ROV frame.
    let out = tdma(&["--trunk", "242", "--duration", "5"]);
    assert_contract(&out, &[0], "--trunk 242");
}

#[test]
fn a_picture_wider_than_debt_holds_is_scaled_down_and_a_huge_one_refused() {
    let dir = tempfile::tempdir().unwrap();
    let wide = write(dir.path(), "wide.png", &png(5000, 10));
    let out = tdma(&["--images", s(&wide), "--duration", "10"]);
    assert_contract(&out, &[0], "5000x10 picture");
    assert_eq!(
        out.stderr.matches("scaled down").count(),
        1,
        "{}",
        out.stderr
    );
    assert!(
        out.stderr.contains("wide.png: 5000x10 to 4096x9"),
        "{}",
        out.stderr
    );

    let huge = write(dir.path(), "huge.png", &png_header(20_000, 20_000));
    let started = std::time::Instant::now();
    let metrics = dir.path().join("m.json");
    let out = tdma(&["--images", s(&huge), "--metrics", s(&metrics)]);
    assert_contract(&out, &[2], "20000x20000 picture");
    assert!(
        out.stderr.contains("huge.png: 20000x20000 pixels"),
        "{}",
        out.stderr
    );
    assert!(started.elapsed() < Duration::from_secs(10));
    assert!(!metrics.exists());
}

#[test]
fn empty_random_and_truncated_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let kodim = std::fs::read(crate::common::testdata("kodim23-64x48.png")).unwrap();
    let inputs = [
        ("empty", Vec::new()),
        ("random", garbage(4096, 14)),
        ("truncated-png", kodim[..kodim.len() / 2].to_vec()),
        ("png-header-only", kodim[..40].to_vec()),
        (
            "truncated-csv",
            b"t_s,x_m,y_m,z_m,heading_deg\n5,2,0,1,0\n40,8,0".to_vec(),
        ),
        ("script-header-only", b"t_s,vx,vy,vz,vyaw\n".to_vec()),
    ];
    for (name, bytes) in &inputs {
        let path = write(dir.path(), name, bytes);
        for flag in ["--script", "--waypoints", "--images", "--model-file"] {
            let events = dir.path().join("events.csv");
            let out = tdma(&[flag, s(&path), "--duration", "3", "--events", s(&events)]);
            assert_contract(&out, &[0, 2], &format!("{flag} {name}"));
            if out.code == Some(2) {
                assert!(
                    out.stderr.contains(name),
                    "{flag} {name}: the error names the file: {}",
                    out.stderr
                );
                assert!(!events.exists(), "{flag} {name}: output left on exit 2");
            }
            let _ = std::fs::remove_file(&events);
        }
    }
    // A device without end as an input is read through a limit, never whole.
    for flag in ["--script", "--images"] {
        let out = tdma(&[flag, "/dev/zero", "--duration", "2"]);
        assert_contract(&out, &[2], &format!("{flag} /dev/zero"));
    }
    // A FIFO with no writer would block whoever opens it: a picture must be a regular file.
    let fifo = dir.path().join("fifo.png");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    let out = tdma(&["--images", s(&fifo), "--duration", "2"]);
    assert_contract(&out, &[2], "--images FIFO");
    assert!(temp_files(dir.path()).is_empty());
}

#[test]
fn an_output_that_is_an_input_is_refused_and_the_input_kept() {
    let dir = tempfile::tempdir().unwrap();
    let waypoints_text = b"t_s,x_m,y_m,z_m,heading_deg\n5,2,0,1,0\n";
    let waypoints = write(dir.path(), "wp.csv", waypoints_text);
    let picture = write(dir.path(), "cam.png", &png(32, 24));
    for flag in ["--events", "--track", "--metrics", "--mcap"] {
        for input in [&waypoints, &picture] {
            let out = tdma(&[
                "--waypoints",
                s(&waypoints),
                "--images",
                s(&picture),
                "--duration",
                "2",
                flag,
                s(input),
            ]);
            assert_contract(&out, &[2], &format!("{flag} = an input"));
            assert!(
                out.stderr.contains("refusing to overwrite an input"),
                "{}",
                out.stderr
            );
        }
    }
    assert_eq!(std::fs::read(&waypoints).unwrap(), waypoints_text);
    assert_eq!(std::fs::read(&picture).unwrap(), png(32, 24));
}

#[test]
fn full_disks_missing_directories_and_two_outputs_on_stdout() {
    for flag in ["--events", "--track", "--metrics", "--mcap"] {
        let out = tdma(&["--duration", "5", flag, "/dev/full"]);
        assert_contract(&out, &[2], &format!("{flag} /dev/full"));
        assert!(out.stderr.contains("/dev/full"), "{}", out.stderr);
    }
    let out = tdma(&["--images-out", "/dev/full", "--duration", "2"]);
    assert_contract(&out, &[2], "--images-out /dev/full");
    assert!(
        out.stderr.contains("/dev/full is not a directory"),
        "{}",
        out.stderr
    );
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no/such/e.csv");
    let out = tdma(&["--events", s(&missing)]);
    assert_contract(&out, &[2], "missing directory");
    assert!(out.stderr.contains("does not exist"), "{}", out.stderr);
    let out = tdma(&["--events", "-", "--mcap", "-", "--duration", "2"]);
    assert_contract(&out, &[2], "two outputs on stdout");
    assert!(
        out.stderr.contains("both write to standard output"),
        "{}",
        out.stderr
    );
    assert!(out.stdout.is_empty());
}

#[test]
fn every_output_goes_to_stdout_when_asked() {
    let out = tdma(&["--duration", "20", "--mcap", "-"]);
    assert_contract(&out, &[0], "--mcap -");
    assert!(mcap::Summary::read(&out.stdout).unwrap().is_some());
    assert!(mcap::MessageStream::new(&out.stdout).unwrap().count() > 100);
    let out = tdma(&["--duration", "10", "--metrics", "-"]);
    assert_contract(&out, &[0], "--metrics -");
    let metrics: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(metrics["measured_by"], "simulation");
    for flag in ["--events", "--track"] {
        let out = tdma(&["--duration", "10", flag, "-"]);
        assert_contract(&out, &[0], flag);
        let text = String::from_utf8(out.stdout).unwrap();
        assert!(
            text.lines().count() > 5 && text.ends_with('\n'),
            "{flag}: {text}"
        );
        let out = head_one(TDMA_RUN, &["--duration", "600", flag, "-"], b"", LIMIT);
        assert_contract(&out, &[0], &format!("{flag} - | head -1"));
        assert!(out.stderr.is_empty(), "{flag} | head -1: {}", out.stderr);
    }
}

/// Runs a simulation of a week with every output and sends `signal` after `after`.
fn interrupted(signal: Signal, code: i32) {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "--duration",
        "604800",
        "--mcap",
        "s.mcap",
        "--events",
        "e.csv",
        "--track",
        "t.csv",
        "--metrics",
        "m.json",
        "--images-out",
        "received",
    ];
    // A week does not end in a test's time: signalled once the track has rows.
    let out = signal_when(
        dir.path(),
        TDMA_RUN,
        &args,
        Stdin::Bytes(b""),
        SignalWhen {
            signal,
            ready: &|seen| seen.lines_in("t.csv") > 50,
        },
        LIMIT,
    );
    assert_contract(&out, &[code], &format!("{signal:?} mid-run"));
    assert!(
        temp_files(dir.path()).is_empty(),
        "{:?}",
        temp_files(dir.path())
    );
    let name = format!("{signal:?}");
    assert!(
        out.stderr.contains(&format!("interrupted by {name}")),
        "{}",
        out.stderr
    );
    assert!(out.stderr.contains("throughput kbit/s"), "{}", out.stderr);
    for csv in ["e.csv", "t.csv"] {
        assert_whole_csv(&dir.path().join(csv));
    }
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("m.json")).unwrap()).unwrap();
    assert_eq!(metrics["interrupted"], name.as_str());
    let duration_s = metrics["duration_s"].as_f64().unwrap();
    assert!(duration_s > 0.0 && duration_s < 604_800.0, "{metrics}");
    let events = std::fs::read_to_string(dir.path().join("e.csv")).unwrap();
    let sent = metrics["rov_to_operator"]["frames_sent"].as_u64().unwrap()
        + metrics["operator_to_rov"]["frames_sent"].as_u64().unwrap();
    // One row per frame whose fate is known: the header, and every frame sent but those
    // still in flight when the signal came (one slot's exchange at most).
    let rows = events.lines().count() as u64 - 1;
    assert!(
        rows <= sent && sent - rows <= 2,
        "{rows} rows for {sent} frames sent"
    );
    let mcap = std::fs::read(dir.path().join("s.mcap")).unwrap();
    let summary = mcap::Summary::read(&mcap)
        .unwrap()
        .expect("a summary section");
    assert!(summary.stats.is_some_and(|s| s.message_count > 0));
    for message in mcap::MessageStream::new(&mcap).unwrap() {
        message.unwrap();
    }
    if let Ok(entries) = std::fs::read_dir(dir.path().join("received")) {
        for entry in entries {
            let bytes = std::fs::read(entry.unwrap().path()).unwrap();
            rovlink_debt::picture::from_bytes("received", &bytes).unwrap();
        }
    }
}

#[test]
fn sigterm_mid_run_leaves_complete_outputs_and_exit_143() {
    interrupted(Signal::SIGTERM, 143);
}

#[test]
fn sigint_mid_run_exits_130() {
    interrupted(Signal::SIGINT, 130);
}

#[test]
fn bad_usage_leaves_no_file_at_all() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_in(
        dir.path(),
        TDMA_RUN,
        &[
            "--events",
            "e.csv",
            "--track",
            "t.csv",
            "--mcap",
            "s.mcap",
            "--metrics",
            "m.json",
            "--waypoints",
            "missing.csv",
        ],
        b"",
        LIMIT,
    );
    assert_contract(&out, &[2], "missing waypoints");
    assert!(out.stderr.contains("missing.csv"), "{}", out.stderr);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// Resident memory of a process, kB.
fn rss_kb(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let line = status.lines().find(|l| l.starts_with("VmRSS:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

#[test]
fn memory_stays_flat_at_the_shortest_ipg() {
    // At 1 ms slots the S100 drops most frames; each lost slot carrying an order used to stay
    // in a map for the whole session (about 3 MB/s).
    let dir = tempfile::tempdir().unwrap();
    let track = dir.path().join("t.csv");
    let mut child = std::process::Command::new(TDMA_RUN)
        .args(["--ipg", "1", "--duration", "604800", "--track"])
        .arg(&track)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Measured by session time simulated (track rows, one per 0.1 s of the session), not
    // by wall time: early after 2000 rows, late after 3000 more.
    let wait_for = |rows: usize| {
        let started = std::time::Instant::now();
        while lines_in(&track) < rows {
            assert!(
                started.elapsed() < LIMIT,
                "no progress to {rows} track rows"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    };
    wait_for(2000);
    let early = rss_kb(child.id());
    wait_for(5000);
    let late = rss_kb(child.id());
    signal_once(&mut child, Signal::SIGTERM, &|| true, LIMIT);
    let status = crate::common::wait_for_exit(&mut child, LIMIT);
    assert_eq!(status.code(), Some(143));
    assert!(late < early + 2048, "{early} kB, 3 s later {late} kB");
}

#[test]
fn ctrl_c_ends_a_real_time_run_with_exit_0_and_its_summary() {
    let (_master, slave) = crate::common::open_pty();
    let dir = tempfile::tempdir().unwrap();
    // Real time on a silent port: signalled once the handler is in place.
    let out = signal_when(
        dir.path(),
        TDMA_RUN,
        &[
            "--role",
            "rov",
            "--port",
            &slave,
            "--duration",
            "600",
            "--metrics",
            "m.json",
            "--events",
            "e.csv",
        ],
        Stdin::Bytes(b""),
        SignalWhen {
            signal: Signal::SIGINT,
            ready: &|_| true,
        },
        LIMIT,
    );
    assert_contract(&out, &[0], "SIGINT on a real-time ROV");
    assert!(out.stderr.contains("stopped after"), "{}", out.stderr);
    assert!(out.stderr.contains("images started"), "{}", out.stderr);
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("m.json")).unwrap()).unwrap();
    assert_eq!(metrics["measured_by"], "rov");
    assert_eq!(metrics["interrupted"], "SIGINT");
    assert_whole_csv(&dir.path().join("e.csv"));
    assert!(temp_files(dir.path()).is_empty());
}

/// A metrics file that cannot be created (here in /proc, where no temporary file can go, even
/// for root) is an error before the session: a week of virtual time is not run first, and the
/// other outputs are not left behind.
#[test]
fn an_uncreatable_metrics_file_fails_before_the_run_and_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "--duration",
        "604800",
        "--metrics",
        "/proc/version",
        "--mcap",
        "s.mcap",
        "--events",
        "e.csv",
        "--track",
        "t.csv",
    ];
    let started = std::time::Instant::now();
    let out = run_in(dir.path(), TDMA_RUN, &args, b"", LIMIT);
    assert_contract(&out, &[2], "--metrics /proc/version");
    assert!(out.stderr.contains("/proc/version"), "{}", out.stderr);
    assert!(
        started.elapsed() < Duration::from_secs(20),
        "ran the session first"
    );
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// NED positions west, north or above the origin are negative: `--buoy -5,0,0` is a value,
/// not an unknown flag `-5`; `--seed` says its range like every other number.
#[test]
fn negative_positions_are_values_and_the_seed_has_a_range() {
    let out = tdma(&[
        "--duration",
        "2",
        "--buoy",
        "-5,0,0",
        "--start",
        "-4,-0.5,1",
    ]);
    assert_contract(&out, &[0], "--buoy -5,0,0");
    let out = tdma(&["--duration", "2", "--buoy", "-1e300,0,0"]);
    assert_contract(&out, &[2], "--buoy -1e300,0,0");
    assert!(out.stderr.contains("--buoy: "), "{}", out.stderr);
    for seed in ["-1", "18446744073709551616", "1.5"] {
        let out = tdma(&["--duration", "2", "--seed", seed]);
        assert_contract(&out, &[2], &format!("--seed {seed}"));
        assert!(
            out.stderr
                .contains("--seed: expected a whole number 0 ..= 18446744073709551615"),
            "{}",
            out.stderr
        );
    }
}

/// `--script -` (or `--waypoints -`) reads standard input; not both at once.
#[test]
fn a_script_from_standard_input() {
    let script = b"t_s,vx,vy,vz,vyaw\n0,10,0,0,0\n";
    let out = run(
        TDMA_RUN,
        &["--duration", "2", "--script", "-"],
        script,
        LIMIT,
    );
    assert_contract(&out, &[0], "--script -");
    let bad = b"t_s,vx,vy,vz,vyaw\n0,1e300,0,0,0\n";
    let out = run(TDMA_RUN, &["--duration", "2", "--script", "-"], bad, LIMIT);
    assert_contract(&out, &[2], "--script - with a bad row");
    assert!(out.stderr.contains("line 2"), "{}", out.stderr);
    let args = ["--duration", "2", "--script", "-", "--waypoints", "-"];
    let out = run(TDMA_RUN, &args, script, LIMIT);
    assert_contract(&out, &[2], "both from stdin");
    assert!(
        out.stderr.contains("both read standard input"),
        "{}",
        out.stderr
    );
}

/// `--images-out` into the directory the camera's pictures come from: a picture named like
/// the received ones (`image-0001.png`, or a link to it) is an input, so the run is refused
/// before it starts and the picture kept (it was overwritten by the first received image).
#[test]
fn images_out_never_overwrites_a_camera_picture() {
    let dir = tempfile::tempdir().unwrap();
    let pictures = dir.path().join("pictures");
    std::fs::create_dir(&pictures).unwrap();
    let picture = write(&pictures, "image-0001.png", &png(64, 48));
    let link = dir.path().join("link.png");
    std::os::unix::fs::symlink(&picture, &link).unwrap();
    let before = std::fs::read(&picture).unwrap();
    for images in [&pictures, &picture, &link] {
        let args = [
            "--duration",
            "60",
            "--images",
            s(images),
            "--images-out",
            s(&pictures),
        ];
        let out = tdma(&args);
        assert_contract(&out, &[2], &format!("--images {}", images.display()));
        assert!(
            out.stderr.contains("--images-out: ") && out.stderr.contains("refusing to overwrite"),
            "{}",
            out.stderr
        );
        assert_eq!(std::fs::read(&picture).unwrap(), before);
        assert_eq!(std::fs::read_dir(&pictures).unwrap().count(), 1);
    }
    let received = dir.path().join("received");
    let args = [
        "--duration",
        "60",
        "--images",
        s(&pictures),
        "--images-out",
        s(&received),
    ];
    assert_contract(&tdma(&args), &[0], "another directory");
    assert!(received.join("image-0001.png").exists());
}

#[test]
fn field_flags_on_the_wrong_end_or_malformed_are_one_line_and_exit_2() {
    let cases: [(&[&str], &str); 6] = [
        (&["--vehicle", "bogus"], "--vehicle"),
        (
            &["--vehicle", "mavlink:"],
            "expected sim, ros2 or mavlink:ENDPOINT",
        ),
        (
            &["--vehicle", "mavlink:udpin:127.0.0.1:14550"],
            "needs --role rov",
        ),
        (
            &["--role", "operator", "--port", "/dev/null", "--camera", "."],
            "--camera only applies to the ROV end",
        ),
        (
            &["--role", "rov", "--port", "/dev/null", "--orders", "-"],
            "--orders only applies to the operator end",
        ),
        (&["--preview"], "--images-out"),
    ];
    for (args, message) in cases {
        let out = tdma(args);
        assert_contract(&out, &[2], message);
        assert!(out.stderr.contains(message), "{args:?}: {}", out.stderr);
        assert_eq!(out.stderr.trim().lines().count(), 1, "{}", out.stderr);
    }
}

/// A real-time end on `udp:BIND=PEER` takes frames only from PEER: datagrams from another
/// socket on the host are dropped, their source named once on stderr and counted in
/// `--metrics` (`foreign_datagrams_dropped`); the peer's are tested through link-sim
/// (`cli_link`), the endpoint's receiving loop in `rovlink-link`'s unit tests.
#[test]
fn a_real_time_end_on_udp_drops_datagrams_from_anyone_but_its_peer() {
    let dir = tempfile::tempdir().unwrap();
    let metrics = dir.path().join("m.json");
    let peer = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let at = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let port = format!("udp:{at}={}", peer.local_addr().unwrap());
    let mut child = crate::common::Reaped(
        std::process::Command::new(TDMA_RUN)
            .args(["--role", "rov", "--port", &port, "--duration", "60"])
            .args(["--metrics", metrics.to_str().unwrap()])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let lines = crate::common::lines_of(child.stderr.take().unwrap());
    let mut said = Vec::new();
    let mut wait_for = |sign: &str| {
        while !said.last().is_some_and(|l: &String| l.contains(sign)) {
            match lines.recv_timeout(LIMIT) {
                Ok(line) => said.push(line),
                Err(e) => panic!("no {sign:?} ({e}): {said:#?}"),
            }
        }
    };
    wait_for("ROV: answering every slot");
    let foreign = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let forged = rovlink_wire::frame::build(0, 1, &[0x66; 11]).unwrap();
    foreign.send_to(&forged, at).unwrap();
    wait_for(&format!(
        "{port}: dropped datagrams from {}, not the peer",
        foreign.local_addr().unwrap()
    ));
    signal_once(&mut child, Signal::SIGINT, &|| true, LIMIT);
    let status = crate::common::wait_for_exit(&mut child, LIMIT);
    assert_eq!(status.code(), Some(0), "{said:#?}");
    let m: serde_json::Value = serde_json::from_slice(&std::fs::read(&metrics).unwrap()).unwrap();
    assert_eq!(m["foreign_datagrams_dropped"], 1, "{m}");
}
