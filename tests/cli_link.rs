//! link-sim as a process: the virtual-time pipe (reproducible bytes and traces, model files,
//! errors) and the real-time modes over pseudo-terminals (its own pair, and existing ports that
//! vanish).

use std::io::{BufRead, BufReader, Read, Write};
use std::os::fd::AsFd;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::hostile::signal_once;
use crate::common::{open_pty, run};
use nix::sys::signal::Signal;
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
use rovlink_wire::frame;

const LINK_SIM: &str = env!("TOOL_EXE_link-sim");

/// `count` frames of `len` bytes each (5 bytes of header and CRC included), all different.
fn frames(count: usize, len: usize) -> Vec<u8> {
    let mut stream = Vec::new();
    for k in 0..count {
        let payload: Vec<u8> = (0..len - 5).map(|j| (k * 7 + j) as u8).collect();
        stream.extend(frame::build(1, 2, &payload).unwrap());
    }
    stream
}

fn pipe(args: &[&str], input: &[u8]) -> (crate::common::Outcome, String) {
    let dir = tempfile::tempdir().unwrap();
    let trace = dir.path().join("trace.csv");
    let mut all = args.to_vec();
    all.extend(["--trace", trace.to_str().unwrap()]);
    let out = run(LINK_SIM, &all, input);
    let trace = std::fs::read_to_string(&trace).unwrap_or_default();
    (out, trace)
}

#[test]
fn a_clean_link_delivers_every_frame_unchanged() {
    let input = frames(50, 57);
    let (out, trace) = pipe(&["--model", "s100"], &input);
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert_eq!(out.stdout, input);
    let mut lines = trace.lines();
    assert_eq!(
        lines.next(),
        Some("seq,bytes,t_offered_s,t_tx_start_s,t_rx_s,fate")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 50);
    for (k, row) in rows.iter().enumerate() {
        assert_eq!(row[0], k.to_string());
        assert_eq!(row[1], "57");
        assert_eq!(row[5], "delivered");
        let tx: f64 = row[3].parse().unwrap();
        let rx: f64 = row[4].parse().unwrap();
        assert!(
            (rx - tx - 0.240).abs() < 1e-8,
            "air time of row {k}: {}",
            rx - tx
        );
    }
    assert!(
        out.stderr.contains("50 frames offered, 50 delivered"),
        "{}",
        out.stderr
    );
}

#[test]
fn the_same_seed_gives_the_same_bytes_and_trace() {
    let input = frames(400, 57);
    let args = [
        "--model", "s100", "--ber", "1e-3", "--errors", "corrupt", "--seed", "9",
    ];
    let (first, first_trace) = pipe(&args, &input);
    let (second, second_trace) = pipe(&args, &input);
    assert_eq!(first.code, 0, "{}", first.stderr);
    assert_eq!(first.stdout, second.stdout);
    assert_eq!(first_trace, second_trace);
    assert!(first_trace.contains(",corrupted"));
    assert_ne!(
        first.stdout, input,
        "corrupted frames are delivered changed"
    );
    let (other, other_trace) = pipe(
        &["--model", "s100", "--ber", "1e-3", "--seed", "10"],
        &input,
    );
    assert_eq!(other.code, 0);
    assert_ne!(first_trace, other_trace);
}

#[test]
fn ber_drops_frames_and_stats_count_them() {
    let dir = tempfile::tempdir().unwrap();
    let stats = dir.path().join("stats.json");
    let input = frames(3000, 57);
    let out = run(
        LINK_SIM,
        &["--ber", "7e-4", "--stats", stats.to_str().unwrap()],
        &input,
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let a = &json["a_to_b"];
    let delivered = a["frames_delivered"].as_u64().unwrap();
    assert_eq!(a["frames_offered"], 3000);
    assert_eq!(a["dropped"]["ber"].as_u64().unwrap(), 3000 - delivered);
    // 72.7 % +- 4 standard errors (0.81 %).
    let ratio = delivered as f64 / 3000.0;
    assert!((ratio - 0.7272).abs() < 0.033, "{ratio}");
    assert_eq!(out.stdout.len() as u64, delivered * 57);
    assert!(json["model_a_to_b"]["ber"].as_f64().unwrap() == 7e-4);
}

#[test]
fn a_printed_model_read_back_gives_the_same_run() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("m.json");
    let printed = run(LINK_SIM, &["--print-model", "s2cr-burst"], b"");
    assert_eq!(printed.code, 0);
    std::fs::write(&model, &printed.stdout).unwrap();
    let input = frames(30, 40);
    let (preset, preset_trace) = pipe(&["--model", "s2cr-burst", "--distance", "800"], &input);
    let (file, file_trace) = pipe(
        &["--model-file", model.to_str().unwrap(), "--distance", "800"],
        &input,
    );
    assert_eq!(preset.code, 0, "{}", preset.stderr);
    assert_eq!(file.code, 0, "{}", file.stderr);
    assert_eq!(preset_trace, file_trace);
    // Flags override the file and show in --print-model.
    let overridden = run(
        LINK_SIM,
        &[
            "--model-file",
            model.to_str().unwrap(),
            "--ber",
            "0.01",
            "--print-model",
        ],
        b"",
    );
    assert!(
        overridden.stdout_text().contains("\"ber\": 0.01"),
        "{}",
        overridden.stdout_text()
    );
}

#[test]
fn a_bad_model_file_names_the_file_and_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("bad.json");
    std::fs::write(
        &model,
        r#"{"bitrate_bps": 1900, "intrinsic_delay_ms": 85, "jitter_ms": -2}"#,
    )
    .unwrap();
    let out = run(
        LINK_SIM,
        &["--model-file", model.to_str().unwrap()],
        &frames(2, 20),
    );
    assert_eq!(out.code, 2);
    assert!(out.stdout.is_empty());
    let line = out.stderr.trim();
    assert_eq!(line.lines().count(), 1, "{line}");
    assert!(
        line.contains("bad.json")
            && line.contains("field `jitter_ms`")
            && line.contains("found -2"),
        "{line}"
    );

    std::fs::write(
        &model,
        r#"{"bitrate_bps": 1900, "intrinsic_delay_ms": [1]}"#,
    )
    .unwrap();
    let out = run(
        LINK_SIM,
        &["--model-file", model.to_str().unwrap()],
        &frames(2, 20),
    );
    assert_eq!(out.code, 2);
    assert!(
        out.stderr
            .contains("field `intrinsic_delay_ms`: invalid type"),
        "{}",
        out.stderr
    );

    let out = run(LINK_SIM, &["--model", "s300"], b"");
    assert_eq!(out.code, 2);
    assert!(
        out.stderr.contains("unknown model `s300`"),
        "{}",
        out.stderr
    );
}

#[test]
fn input_that_holds_no_frame_is_refused() {
    let out = run(LINK_SIM, &[], b"this is not a frame stream\n");
    assert_eq!(out.code, 2);
    assert!(
        out.stderr.contains("<stdin>: no link frame in 27 bytes"),
        "{}",
        out.stderr
    );
    assert!(out.stdout.is_empty());
}

#[test]
fn a_distance_track_cuts_the_link_and_restores_it() {
    let dir = tempfile::tempdir().unwrap();
    let track = dir.path().join("track.csv");
    std::fs::write(&track, "t_s,distance_m\n0,1\n10,9\n20,1\n").unwrap();
    let (out, trace) = pipe(
        &[
            "--distance-file",
            track.to_str().unwrap(),
            "--interval",
            "500",
            "--jitter-ms",
            "0",
        ],
        &frames(40, 16),
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    let fates: Vec<(f64, String)> = trace
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[3].parse().unwrap(), f[5].to_string())
        })
        .collect();
    assert_eq!(fates.len(), 40);
    for (t, fate) in &fates {
        // 1 + 0.8 t metres out to 9 m and back: beyond 5 m from t = 5 s to t = 15 s.
        let expected = if (5.0..=15.0).contains(t) {
            "range"
        } else {
            "delivered"
        };
        assert_eq!(fate, expected, "on air at {t} s");
    }

    std::fs::write(&track, "t_s,distance_m\n0,1\n3,far\n").unwrap();
    let out = run(
        LINK_SIM,
        &["--distance-file", track.to_str().unwrap()],
        &frames(1, 16),
    );
    assert_eq!(out.code, 2);
    assert!(
        out.stderr.contains("track.csv: line 3: field `distance_m`"),
        "{}",
        out.stderr
    );
}

#[test]
fn a_fifo_too_small_for_the_offered_rate_overflows() {
    let (out, trace) = pipe(
        &["--interval", "100", "--fifo-bytes", "120"],
        &frames(20, 57),
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(trace.contains(",overflow"), "{trace}");
    assert!(out.stderr.contains("overflow"), "{}", out.stderr);
}

/// Puts a terminal in raw mode, so bytes pass unchanged.
fn raw(fd: impl AsFd) {
    let mut termios = tcgetattr(&fd).unwrap();
    cfmakeraw(&mut termios);
    tcsetattr(&fd, SetArg::TCSANOW, &termios).unwrap();
}

fn open_rw(path: &str) -> std::fs::File {
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .unwrap();
    raw(&file);
    file
}

/// link-sim with `args`, started: the child, its stderr, and the first line it said there.
fn start(
    args: &[&str],
) -> (
    std::process::Child,
    BufReader<std::process::ChildStderr>,
    String,
) {
    let mut child = Command::new(LINK_SIM)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut first = String::new();
    stderr.read_line(&mut first).unwrap();
    (child, stderr, first)
}

/// How long a read waits for bytes the link delivers in well under a second: only a hang
/// takes this long, however loaded the machine.
const READ_LIMIT: Duration = Duration::from_secs(10);

/// The most a signalled or unplugged link-sim takes to end: only a hang takes this long.
const EXIT_LIMIT: Duration = Duration::from_secs(30);

/// Reads exactly `n` bytes or gives up after `limit`.
fn read_exactly(file: &mut std::fs::File, n: usize, limit: Duration) -> Vec<u8> {
    let (tx, rx) = std::sync::mpsc::channel();
    let mut reader = file.try_clone().unwrap();
    std::thread::spawn(move || {
        let mut got = vec![0u8; n];
        let ok = reader.read_exact(&mut got).is_ok();
        let _ = tx.send(if ok { got } else { Vec::new() });
    });
    rx.recv_timeout(limit).unwrap_or_default()
}

/// Ends a real-time link-sim with SIGTERM (once it catches it): it must exit 0; returns what it
/// said on stderr.
fn terminate(child: &mut std::process::Child) -> String {
    signal_once(child, Signal::SIGTERM, &|| true, EXIT_LIMIT);
    let status = crate::common::wait_for_exit(child, EXIT_LIMIT);
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    assert_eq!(status.code(), Some(0), "{stderr}");
    stderr
}

/// Starts link-sim in --pty mode with `args` and opens both sides raw: (child, A, B).
fn start_pty(args: &[&str]) -> (crate::common::Reaped, std::fs::File, std::fs::File) {
    let (child, a_path, b_path) = crate::common::link_sim_pty(args);
    (child, open_rw(&a_path), open_rw(&b_path))
}

#[test]
fn pty_mode_forwards_frames_in_real_time_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let stats = dir.path().join("stats.json");
    let stats_path = stats.to_str().unwrap();
    let (mut child, mut a, mut b) = start_pty(&[
        "--model",
        "s100",
        "--jitter-distribution",
        "none",
        "--stats",
        stats_path,
    ]);

    let frame_a = frame::build(1, 2, &[0xAA; 52]).unwrap();
    let sent = Instant::now();
    a.write_all(&frame_a).unwrap();
    let got = read_exactly(&mut b, 57, READ_LIMIT);
    let delay = sent.elapsed();
    assert_eq!(got, frame_a);
    // 85 ms + 240 ms of air time, and no earlier. Above, only a bound on a hang: a loaded
    // machine may deliver late (the real-time accuracy is measured by scripts/pty-latency.py,
    // and the model's delay exactly, in virtual time, by the stats below).
    assert!(delay >= Duration::from_millis(324), "{delay:?}");
    assert!(delay < READ_LIMIT, "{delay:?}");

    let frame_b = frame::build(2, 1, &[0xBB; 11]).unwrap();
    b.write_all(&frame_b).unwrap();
    assert_eq!(read_exactly(&mut a, 16, READ_LIMIT), frame_b);

    let stderr = terminate(&mut child);
    assert!(
        stderr.contains("A->B: 1 frames offered, 1 delivered"),
        "{stderr}"
    );
    assert!(
        stderr.contains("B->A: 1 frames offered, 1 delivered"),
        "{stderr}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert_eq!(json["a_to_b"]["delay_ms_mean"], 325.0);
    assert_eq!(json["b_to_a"]["frames_delivered"], 1);
}

#[test]
fn serial_ports_that_vanish_end_the_run_naming_the_side() {
    let (mut master_a, path_a) = open_pty();
    let (master_b, path_b) = open_pty();
    let args = [
        "--jitter-ms",
        "0",
        "--a",
        &path_a,
        "--b",
        &path_b,
        "--baud",
        "115200",
    ];
    let (mut child, mut stderr, first) = start(&args);
    assert!(first.contains("forwarding A"), "{first}");

    let frame_a = frame::build(1, 2, &[7; 20]).unwrap();
    master_a.write_all(&frame_a).unwrap();
    let mut b = std::fs::File::from(std::os::fd::OwnedFd::from(master_b));
    assert_eq!(read_exactly(&mut b, frame_a.len(), READ_LIMIT), frame_a);

    drop(master_a); // the modem on side A is unplugged
    let status = crate::common::wait_for_exit(&mut child, EXIT_LIMIT);
    let mut rest = String::new();
    stderr.read_to_string(&mut rest).unwrap();
    assert_eq!(status.code(), Some(1), "{rest}");
    assert!(
        rest.contains(&format!("side A ({path_a}) closed")),
        "{rest}"
    );
    assert!(
        rest.contains("A->B: 1 frames offered, 1 delivered"),
        "{rest}"
    );
}

#[test]
fn udp_mode_carries_datagrams_as_frames() {
    let client_a = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let client_b = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    client_b.set_read_timeout(Some(READ_LIMIT)).unwrap();
    // Ports for link-sim's two sockets: bind, note, release (a race only with other tests).
    let free = || {
        std::net::UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
    };
    let (side_a, side_b) = (free(), free());
    let (a, b) = (side_a.to_string(), side_b.to_string());
    let peer = client_b.local_addr().unwrap().to_string();
    let args = [
        "--model",
        "satellite-up",
        "--udp-a",
        &a,
        "--udp-b",
        &b,
        "--udp-b-peer",
        &peer,
    ];
    let (mut child, _stderr, first) = start(&args);
    assert!(first.contains("forwarding A"), "{first}");

    let datagram = b"any bytes: a datagram is a packet".to_vec();
    let sent = Instant::now();
    client_a.send_to(&datagram, side_a).unwrap();
    let mut buf = [0u8; 512];
    let (n, from) = client_b.recv_from(&mut buf).unwrap();
    assert_eq!(&buf[..n], &datagram[..]);
    assert_eq!(from, side_b);
    assert!(
        sent.elapsed() >= Duration::from_millis(310),
        "{:?}",
        sent.elapsed()
    );

    // B answers; A's address was learned from its datagram.
    client_b.send_to(b"reply", side_b).unwrap();
    client_a.set_read_timeout(Some(READ_LIMIT)).unwrap();
    let (n, _) = client_a.recv_from(&mut buf).unwrap();
    assert_eq!(&buf[..n], b"reply");

    signal_once(&mut child, Signal::SIGINT, &|| true, EXIT_LIMIT);
    assert_eq!(
        crate::common::wait_for_exit(&mut child, EXIT_LIMIT).code(),
        Some(0)
    );
}

/// Sides named in the one device grammar: a new pseudo-terminal on A (its path alone on
/// stdout), a UDP socket with a fixed peer on B (`udp:BIND=PEER`), frames both ways.
#[test]
fn sides_given_as_devices_mix_a_pty_and_udp() {
    let client_b = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    client_b.set_read_timeout(Some(READ_LIMIT)).unwrap();
    let side_b = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let b = format!("udp:{side_b}={}", client_b.local_addr().unwrap());
    let (mut child, _stderr, first) = start(&["--jitter-ms", "0", "--a", "pty", "--b", &b]);
    let mut path_a = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut path_a)
        .unwrap();
    let path_a = path_a.trim_end().to_string();
    assert!(path_a.starts_with("/dev/"), "{path_a}");
    assert!(
        first.contains(&format!("forwarding A ({path_a}) <-> B ({side_b})")),
        "{first}"
    );
    let mut a = open_rw(&path_a);

    let frame_a = frame::build(1, 2, &[7; 20]).unwrap();
    a.write_all(&frame_a).unwrap();
    let mut buf = [0u8; 512];
    let (n, from) = client_b.recv_from(&mut buf).unwrap();
    assert_eq!(&buf[..n], &frame_a[..]);
    assert_eq!(from, side_b);

    let frame_b = frame::build(2, 1, &[9; 12]).unwrap();
    client_b.send_to(&frame_b, side_b).unwrap();
    assert_eq!(read_exactly(&mut a, frame_b.len(), READ_LIMIT), frame_b);

    signal_once(&mut child, Signal::SIGINT, &|| true, EXIT_LIMIT);
    assert_eq!(
        crate::common::wait_for_exit(&mut child, EXIT_LIMIT).code(),
        Some(0)
    );
}

/// `udp:BIND=PEER` takes only PEER's datagrams: valid frames from another socket on the same
/// host are dropped (their source named once on stderr, counted in `--stats`), PEER's are
/// still carried.
#[test]
fn a_udp_side_drops_frames_from_anyone_but_its_peer() {
    let dir = tempfile::tempdir().unwrap();
    let stats = dir.path().join("stats.json");
    let client_b = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let side_b = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let peer = client_b.local_addr().unwrap();
    let b = format!("udp:{side_b}={peer}");
    let stats_path = stats.to_str().unwrap();
    let args = [
        "--jitter-ms",
        "0",
        "--a",
        "pty",
        "--b",
        &b,
        "--stats",
        stats_path,
    ];
    let (child, stderr, first) = start(&args);
    let mut child = crate::common::Reaped(child);
    assert!(first.contains("forwarding A"), "{first}");
    let mut path_a = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut path_a)
        .unwrap();
    let mut a = open_rw(path_a.trim_end());
    let lines = crate::common::lines_of(stderr);

    // Someone else on the host sends well-formed frames to B's port, twice.
    let foreign = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let forged = frame::build(2, 1, &[0x66; 12]).unwrap();
    foreign.send_to(&forged, side_b).unwrap();
    foreign.send_to(&forged, side_b).unwrap();
    let said = format!(
        "dropped datagrams from {}, not the peer {peer}",
        foreign.local_addr().unwrap()
    );
    let mut seen = Vec::new();
    while !seen
        .last()
        .is_some_and(|l: &String| l.contains("dropped datagrams"))
    {
        match lines.recv_timeout(READ_LIMIT) {
            Ok(line) => seen.push(line),
            Err(e) => panic!("no line naming the foreign source ({e}): {seen:#?}"),
        }
    }
    let line = seen.last().unwrap();
    assert!(
        line.contains(&format!("udp:{side_b}={peer}: {said}")),
        "{line}"
    );

    // The peer's frame, sent after both forged ones, is the first A hears.
    let frame_b = frame::build(2, 1, &[0x99; 12]).unwrap();
    client_b.send_to(&frame_b, side_b).unwrap();
    assert_eq!(read_exactly(&mut a, frame_b.len(), READ_LIMIT), frame_b);

    signal_once(&mut child, Signal::SIGINT, &|| true, EXIT_LIMIT);
    let status = crate::common::wait_for_exit(&mut child, EXIT_LIMIT);
    let rest: Vec<String> = lines.iter().collect();
    assert_eq!(status.code(), Some(0), "{rest:#?}");
    assert!(
        !rest.iter().any(|l| l.contains(&said)),
        "a source is named once: {rest:#?}"
    );
    assert!(
        rest.iter()
            .any(|l| l.contains("B->A: 1 frames offered, 1 delivered")),
        "{rest:#?}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let dropped = &json["real_time"]["foreign_datagrams_dropped"];
    assert_eq!(
        (dropped["a"].as_u64(), dropped["b"].as_u64()),
        (Some(0), Some(2))
    );
}

#[test]
fn raw_mode_cuts_packets_at_silence() {
    let dir = tempfile::tempdir().unwrap();
    let trace = dir.path().join("trace.csv");
    let trace_path = trace.to_str().unwrap();
    // A silence of a second cuts a packet: two writes 5 ms apart stay one packet even on a
    // loaded machine that runs the test a few hundred milliseconds late.
    let (mut child, mut a, mut b) = start_pty(&[
        "--jitter-ms",
        "0",
        "--raw",
        "--idle-ms",
        "1000",
        "--trace",
        trace_path,
    ]);
    a.write_all(b"hel").unwrap();
    std::thread::sleep(Duration::from_millis(5));
    a.write_all(b"lo").unwrap(); // 5 ms later: the same packet
    // Side B hears it once the silence has cut it (and the link carried it); only then comes
    // the next write, after at least --idle-ms of silence whatever the machine's speed.
    assert_eq!(read_exactly(&mut b, 5, READ_LIMIT), b"hello");
    a.write_all(b"world!").unwrap(); // after the silence: a new packet
    assert_eq!(read_exactly(&mut b, 6, READ_LIMIT), b"world!");
    signal_once(&mut child, Signal::SIGTERM, &|| true, EXIT_LIMIT);
    assert_eq!(
        crate::common::wait_for_exit(&mut child, EXIT_LIMIT).code(),
        Some(0)
    );
    let trace = std::fs::read_to_string(&trace).unwrap();
    let sizes: Vec<&str> = trace
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap())
        .collect();
    assert_eq!(sizes, ["5", "6"], "{trace}");
}

/// Starts `link-sim --pty N` with `args`; returns it and its N ports, opened raw.
fn start_medium(ports: usize, args: &[&str]) -> (std::process::Child, Vec<std::fs::File>) {
    let mut child = Command::new(LINK_SIM)
        .args(["--pty", &ports.to_string()])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("link-sim starts");
    let mut stdout = BufReader::new(child.stdout.take().expect("stdout"));
    let files = (0..ports)
        .map(|_| {
            let mut path = String::new();
            stdout.read_line(&mut path).expect("a port's path");
            open_rw(path.trim())
        })
        .collect();
    (child, files)
}

#[test]
fn pty_3_is_one_medium_the_middle_hears_both_ends_and_the_ends_never_each_other() {
    let dir = tempfile::tempdir().unwrap();
    let stats = dir.path().join("stats.json");
    let (mut child, mut ports) = start_medium(
        3,
        &[
            "--model",
            "s100",
            "--jitter-distribution",
            "none",
            "--position",
            "0,0,0",
            "--position",
            "3,0,1",
            "--position",
            "7,0,1",
            "--stats",
            stats.to_str().unwrap(),
        ],
    );
    let from_middle = frame::build(2, 15, &[0x22; 52]).unwrap();
    let sent = Instant::now();
    ports[1].write_all(&from_middle).unwrap();
    let at_1 = read_exactly(&mut ports[0], 57, READ_LIMIT);
    let delay = sent.elapsed();
    let at_3 = read_exactly(&mut ports[2], 57, READ_LIMIT);
    assert_eq!(at_1, from_middle);
    assert_eq!(at_3, from_middle);
    assert!(delay >= Duration::from_millis(324), "{delay:?}");

    // Port 1's frame reaches the middle, never port 3 (7.07 m away, range 5 m).
    let from_end = frame::build(0, 2, &[0x11; 11]).unwrap();
    ports[0].write_all(&from_end).unwrap();
    assert_eq!(read_exactly(&mut ports[1], 16, READ_LIMIT), from_end);
    // Nothing at port 3 meanwhile (a check that can only miss a late byte, never fail
    // wrongly; the stats below count the frame as dropped for range, whatever the timing).
    assert!(read_exactly(&mut ports[2], 1, Duration::from_millis(700)).is_empty());

    let stderr = terminate(&mut child);
    for line in [
        "2->1: 1 frames offered, 1 delivered",
        "2->3: 1 frames offered, 1 delivered",
        "1->2: 1 frames offered, 1 delivered",
        "1->3: 1 frames offered, 0 delivered (0.0 %); dropped: 1 range",
    ] {
        assert!(stderr.contains(line), "{line} in {stderr}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert_eq!(json["ports"], 3);
    assert_eq!(json["pairs"]["2->3"]["delay_ms_mean"], 325.0);
    assert_eq!(json["pairs"]["1->3"]["dropped"]["range"], 1);
    assert_eq!(json["pairs"]["3->1"]["frames_offered"], 0);
    assert_eq!(json["positions_m"][2], serde_json::json!([7.0, 0.0, 1.0]));
}

#[test]
fn pty_n_and_positions_are_checked_in_one_line() {
    let three = "--pty 3 --position 0,0,0 --position 1,0,0 --position";
    for (args, expected) in [
        ("--pty 1", "--pty: expected 2 ..= 16 ports, found 1"),
        ("--pty 17", "--pty: expected 2 ..= 16 ports, found 17"),
        (
            "--pty 3 --position 0,0,0",
            "--position: expected one per port (3), found 1",
        ),
        (
            &format!("{three} nan,0,0"),
            "--position: number 1: expected",
        ),
        (
            &format!("{three} inf,0,0"),
            "--position: number 1: expected",
        ),
        (
            "--pty 3 --distance 2",
            "--distance applies to two ports, not to --pty 3",
        ),
        ("--pty 4 --trace t.csv", "--trace applies to two ports"),
        (
            "--pty 3 --reverse-model s100",
            "--reverse-model applies to two ports",
        ),
        ("--position 0,0,0", "--pty"),
    ] {
        let args: Vec<&str> = ["--model", "s100"]
            .into_iter()
            .chain(args.split(' '))
            .collect();
        let out = run(LINK_SIM, &args, b"");
        assert_eq!(out.code, 2, "{args:?}: {}", out.stderr);
        assert!(out.stdout.is_empty(), "{args:?}");
        let line = out.stderr.trim();
        assert_eq!(line.lines().count(), 1, "{args:?}: {line}");
        assert!(line.contains(expected), "{args:?}: {line}");
    }
}
