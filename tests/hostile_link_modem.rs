//! link-sim and modem-bench against a hostile user: empty, random and truncated inputs, every
//! numeric flag at NaN, infinity, zero, negative and huge values, outputs that are inputs or a
//! full disk, two outputs on standard output, signals in the middle of a virtual-time run, and
//! a reader that goes away (`| head -1`). The contract (README, Exit codes): exit 0, 1 or 2
//! (130/143/129 when a simulation is interrupted), never a panic, a signal death or a hang; a
//! one-line error on exit 2 with no output file left; interrupted runs leave whole CSV rows,
//! valid JSON marked as interrupted, and no temporary file.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::hostile::{
    BAD_NUMBERS, Run, SignalWhen, Stdin, assert_contract, assert_whole_csv, garbage, head_one, run,
    run_in, signal_once, signal_when, temp_files,
};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use rovlink_wire::frame;

const LINK_SIM: &str = env!("TOOL_EXE_link-sim");
const MODEM_BENCH: &str = env!("TOOL_EXE_modem-bench");
const LIMIT: Duration = Duration::from_secs(20);

/// `count` wire.md frames of 20 bytes, all different.
fn frames(count: usize) -> Vec<u8> {
    let mut stream = Vec::with_capacity(count * 20);
    for k in 0..count {
        let payload: Vec<u8> = (0..15).map(|j| (k * 7 + j) as u8).collect();
        stream.extend(frame::build(1, 2, &payload).unwrap());
    }
    stream
}

/// The one line of an exit-2 error, with the tool's prefix.
fn error_line(run: &Run, tool: &str) -> String {
    let lines: Vec<&str> = run.stderr.lines().collect();
    assert_eq!(lines.len(), 1, "one line expected: {}", run.stderr);
    assert!(lines[0].starts_with(&format!("{tool}: ")), "{}", run.stderr);
    lines[0].to_string()
}

/// Runs `bin` with each of `flags` at every hostile value (`--flag=value`: whether `-inf` after
/// a flag is a value is clap's matter, not a range's), plus the arguments `base` gives for the
/// flag: exit 0 or 2, never a hang, and an exit-2 message naming the flag (or the model field it
/// sets, as in `range_max_m` below `range_min_m`), with nothing on standard output.
fn hostile_values(bin: &str, flags: &[&str], input: &[u8], base: impl Fn(&str) -> Vec<&str>) {
    let tool = Path::new(bin)
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    for flag in flags {
        for value in BAD_NUMBERS {
            let what = format!("{tool} {flag} {value}");
            let pair = format!("{flag}={value}");
            let mut args = base(flag);
            args.push(&pair);
            let out = run(bin, &args, input, LIMIT);
            assert_contract(&out, &[0, 2], &what);
            if out.code == Some(2) {
                let line = error_line(&out, &tool);
                let field = flag[2..].replace('-', "_");
                assert!(
                    line.contains(flag) || line.contains(&field),
                    "{what}: {line}"
                );
                assert!(out.stdout.is_empty(), "{what}: output on exit 2");
            }
        }
    }
}

fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}: {text}", path.display()))
}

#[test]
fn link_sim_takes_empty_random_and_truncated_streams() {
    let good = frames(20);
    let mut truncated = good.clone();
    truncated.truncate(good.len() - 7);
    let cases: [(&str, Vec<u8>, &[i32]); 4] = [
        ("empty", Vec::new(), &[0]),
        ("random", garbage(4096, 7), &[2]),
        ("truncated", truncated, &[0]),
        (
            "frames in junk",
            [garbage(100, 3), good.clone()].concat(),
            &[0],
        ),
    ];
    for (what, input, codes) in cases {
        let out = run(LINK_SIM, &["--seed", "3"], &input, LIMIT);
        assert_contract(&out, codes, what);
        if out.code == Some(2) {
            let line = error_line(&out, "link-sim");
            assert!(
                line.contains("<stdin>: no link frame in 4096 bytes"),
                "{line}"
            );
            assert!(out.stdout.is_empty());
        }
    }
    // Files as inputs too: missing, a directory, random.
    let dir = tempfile::tempdir().unwrap();
    let random = dir.path().join("random.bin");
    std::fs::write(&random, garbage(1000, 9)).unwrap();
    for input in [
        random.to_str().unwrap(),
        "/no/such/frames.bin",
        dir.path().to_str().unwrap(),
    ] {
        let out = run_in(dir.path(), LINK_SIM, &[input, "-o", "out.bin"], b"", LIMIT);
        assert_contract(&out, &[2], input);
        error_line(&out, "link-sim");
        assert!(!dir.path().join("out.bin").exists(), "{input}: output left");
    }
}

#[test]
fn link_sim_refuses_hostile_model_and_distance_files() {
    let dir = tempfile::tempdir().unwrap();
    let files = [
        ("empty.json", b"".to_vec()),
        ("random.json", garbage(300, 5)),
        ("truncated.json", br#"{"bitrate_bps": 1900, "intrinsic_de"#.to_vec()),
        ("slow.json", br#"{"bitrate_bps": 1e-300, "intrinsic_delay_ms": 85}"#.to_vec()),
        ("jitter.json", br#"{"bitrate_bps": 1900, "intrinsic_delay_ms": 85, "jitter_ms": 1e300}"#.to_vec()),
        ("fifo.json", br#"{"bitrate_bps": 1900, "intrinsic_delay_ms": 85, "fifo_bytes": 18446744073709551615}"#.to_vec()),
    ];
    for (name, text) in &files {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let out = run_in(
            dir.path(),
            LINK_SIM,
            &["--model-file", name, "-o", "o.bin"],
            &frames(3),
            LIMIT,
        );
        assert_contract(&out, &[2], name);
        assert!(
            error_line(&out, "link-sim").contains(name),
            "{}",
            out.stderr
        );
        assert!(!dir.path().join("o.bin").exists());
    }
    let out = run_in(
        dir.path(),
        LINK_SIM,
        &["--model-file", "slow.json"],
        b"",
        LIMIT,
    );
    assert!(
        out.stderr
            .contains("expected 1 bit/s ..= 10 Gbit/s (1e10), found 1e-300"),
        "{}",
        out.stderr
    );
    for (name, text) in [
        ("d-empty.csv", &b""[..]),
        ("d-random.csv", &garbage(200, 11)[..]),
        ("d-far.csv", &b"t_s,distance_m\n0,1\n5,1e300\n"[..]),
        ("d-cut.csv", &b"t_s,distance_m\n0,1\n5,"[..]),
    ] {
        std::fs::write(dir.path().join(name), text).unwrap();
        let out = run_in(
            dir.path(),
            LINK_SIM,
            &["--distance-file", name],
            &frames(3),
            LIMIT,
        );
        assert_contract(&out, &[2], name);
        assert!(
            error_line(&out, "link-sim").contains(name),
            "{}",
            out.stderr
        );
    }
}

/// Every numeric flag of link-sim's pipe and of the model, at every hostile value: exit 0 or 2,
/// never a hang (no value lets virtual time run away), a one-line message naming the flag.
#[test]
fn link_sim_numeric_flags_at_hostile_values() {
    let input = frames(5);
    let flags = [
        "--interval",
        "--distance",
        "--seed",
        "--baud",
        "--idle-ms",
        "--bitrate-bps",
        "--intrinsic-delay-ms",
        "--jitter-ms",
        "--propagation-min-ms",
        "--propagation-ms-per-m",
        "--range-min-m",
        "--range-max-m",
        "--ber",
        "--fifo-bytes",
        "--loss-percent",
        "--corrupt-percent",
        "--duplicate-percent",
        "--rate-limit-bps",
        "--gilbert-elliott",
    ];
    // --baud and --idle-ms belong to real time: alone they leave the pipe running.
    hostile_values(LINK_SIM, &flags, &input, |flag| match flag {
        "--idle-ms" => vec!["--raw"],
        _ => vec![],
    });
    // The issue's cases: each refused before anything runs, with the range and its unit.
    for (flag, value, expected) in [
        (
            "--interval",
            "1e300",
            "--interval: expected 0.001 ms ..= 1 h, found 1e300",
        ),
        ("--bitrate-bps", "1e-300", "--bitrate-bps: expected 1 bit/s"),
        ("--jitter-ms", "1e300", "--jitter-ms: expected 0 s ..= "),
    ] {
        let out = run(LINK_SIM, &[flag, value], &input, LIMIT);
        assert_contract(&out, &[2], flag);
        assert!(
            error_line(&out, "link-sim").contains(expected),
            "{}",
            out.stderr
        );
        assert!(out.stdout.is_empty());
    }
}

#[test]
fn link_sim_outputs_never_overwrite_inputs_and_say_when_the_disk_is_full() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.bin");
    let stream = frames(30);
    std::fs::write(&input, &stream).unwrap();
    let model = dir.path().join("m.json");
    std::fs::write(&model, s100_json()).unwrap();
    let inp = input.to_str().unwrap();
    let m = model.to_str().unwrap();
    for args in [
        vec![inp, "-o", inp],
        vec![inp, "--trace", inp],
        vec![inp, "--stats", inp],
        vec![inp, "--model-file", m, "--stats", m],
    ] {
        let out = run(LINK_SIM, &args, b"", LIMIT);
        assert_contract(&out, &[2], &format!("{args:?}"));
        assert!(error_line(&out, "link-sim").contains("refusing to overwrite an input"));
        assert_eq!(std::fs::read(&input).unwrap(), stream, "input changed");
    }
    for args in [
        vec![inp, "-o", "/dev/full"],
        vec![inp, "--trace", "/dev/full", "-o", "/dev/null"],
        vec![inp, "--stats", "/dev/full", "-o", "/dev/null"],
    ] {
        let flag = args[1];
        let out = run(LINK_SIM, &args, b"", LIMIT);
        assert_contract(&out, &[2], flag);
        assert!(
            error_line(&out, "link-sim").contains("/dev/full: write failed"),
            "{}",
            out.stderr
        );
    }
    // `-` is standard output for every output, and only one may take it.
    let out = run(LINK_SIM, &[inp, "--stats", "-"], b"", LIMIT);
    assert_contract(&out, &[2], "--stats - with the frames on stdout");
    assert!(out.stderr.contains("both write to standard output"));
    let out = run(
        LINK_SIM,
        &[inp, "-o", "/dev/null", "--stats", "-"],
        b"",
        LIMIT,
    );
    assert_contract(&out, &[0], "--stats -");
    let stats: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(stats["a_to_b"]["frames_offered"], 30);
    assert!(!Path::new("-").exists());
    let out = head_one(
        LINK_SIM,
        &[inp, "-o", "/dev/null", "--trace", "-"],
        b"",
        LIMIT,
    );
    assert_contract(&out, &[0], "--trace - | head -1");
    assert_eq!(
        out.stdout,
        b"seq,bytes,t_offered_s,t_tx_start_s,t_rx_s,fate\n"
    );
}

/// A model file to start from, as `--print-model` writes it.
fn s100_json() -> Vec<u8> {
    let out = run(LINK_SIM, &["--print-model", "s100"], b"", LIMIT);
    assert_contract(&out, &[0], "--print-model");
    out.stdout
}

#[test]
fn link_sim_pipe_stops_at_a_signal_with_complete_outputs() {
    let dir = tempfile::tempdir().unwrap();
    // Frames without end on standard input: the run ends only by the signal, which comes once
    // the trace holds rows.
    let input = frames(1000);
    for (signal, code) in [(Signal::SIGTERM, 143), (Signal::SIGINT, 130)] {
        // The sign is rows in this run's trace, not the last run's.
        let _ = std::fs::remove_file(dir.path().join("t.csv"));
        let args = [
            "-", "-o", "out.bin", "--trace", "t.csv", "--stats", "s.json",
        ];
        let out = signal_when(
            dir.path(),
            LINK_SIM,
            &args,
            Stdin::Forever(&input),
            SignalWhen {
                signal,
                ready: &|seen| seen.lines_in("t.csv") > 100,
            },
            LIMIT,
        );
        assert_contract(&out, &[code], &format!("{signal:?}"));
        assert!(out.stderr.contains("interrupted by SIG"), "{}", out.stderr);
        assert!(
            temp_files(dir.path()).is_empty(),
            "{:?}",
            temp_files(dir.path())
        );
        assert_whole_csv(&dir.path().join("t.csv"));
        let stats = json(&dir.path().join("s.json"));
        assert_eq!(stats["interrupted"], format!("interrupted by {signal:?}"));
        let delivered = stats["a_to_b"]["frames_delivered"].as_u64().unwrap();
        assert!(delivered >= 100, "{delivered}");
        // The frames that arrived are all there, whole.
        let output = std::fs::read(dir.path().join("out.bin")).unwrap();
        assert_eq!(output.len() as u64, delivered * 20);
    }
}

#[test]
fn link_sim_pipe_stops_at_a_signal_while_its_input_is_silent() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(LINK_SIM)
        .args(["--stats", "s.json", "--trace", "t.csv"])
        .current_dir(dir.path())
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(&frames(3)).unwrap();
    // Signalled once the three frames are traced (a header and three rows), the input silent.
    let trace = dir.path().join("t.csv");
    signal_once(
        &mut child,
        Signal::SIGTERM,
        &|| crate::common::hostile::lines_in(&trace) == 4,
        LIMIT,
    );
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        assert!(
            started.elapsed() < Duration::from_secs(5),
            "hung on a silent input"
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    drop(stdin);
    assert_eq!(status.code(), Some(143));
    let stats = json(&dir.path().join("s.json"));
    assert_eq!(stats["a_to_b"]["frames_offered"], 3);
    assert_eq!(stats["interrupted"], "interrupted by SIGTERM");
}

#[test]
fn link_sim_pipe_stops_at_a_signal_while_waiting_for_a_named_pipe_writer() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("frames.fifo");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    let args = ["frames.fifo", "-o", "out.bin", "--stats", "s.json"];
    // Without a writer the open never returns: the signal comes once the handler is in place.
    let out = signal_when(
        dir.path(),
        LINK_SIM,
        &args,
        Stdin::Bytes(b""),
        SignalWhen {
            signal: Signal::SIGTERM,
            ready: &|_| true,
        },
        LIMIT,
    );
    assert_contract(&out, &[143], "a named pipe without a writer");
    assert_eq!(
        json(&dir.path().join("s.json"))["a_to_b"]["frames_offered"],
        0
    );
    assert!(temp_files(dir.path()).is_empty());
}

#[test]
fn link_sim_real_time_keeps_exit_0_on_a_signal() {
    let mut child = Command::new(LINK_SIM)
        .args(["--pty"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut paths = String::new();
    let mut stdout = std::io::BufReader::new(child.stdout.take().unwrap());
    for _ in 0..2 {
        std::io::BufRead::read_line(&mut stdout, &mut paths).unwrap();
    }
    assert_eq!(paths.lines().count(), 2, "{paths}");
    kill(Pid::from_raw(child.id() as i32), Signal::SIGTERM).unwrap();
    let out = child.wait_with_output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Every numeric flag of modem-bench at every hostile value.
#[test]
fn modem_bench_numeric_flags_at_hostile_values() {
    let flags = [
        "--count",
        "--size",
        "--sizes",
        "--interval",
        "--timeout",
        "--distance",
        "--seed",
        "--bitrate-bps",
        "--intrinsic-delay-ms",
        "--jitter-ms",
        "--ber",
        "--fifo-bytes",
        "--loss-percent",
    ];
    hostile_values(MODEM_BENCH, &flags, b"", |flag| match flag {
        "--count" => vec!["--sim", "s100", "-q"],
        _ => vec!["--sim", "s100", "-q", "--count", "5"],
    });
    // Counts up to 10^9 are accepted; campaigns longer than virtual time holds are refused.
    for args in [
        &[
            "--sim",
            "s100",
            "--count",
            "1000000000",
            "--sizes",
            "16,17,18,19,20",
        ][..],
        &[
            "--sim",
            "s100",
            "--count",
            "1000000000",
            "--interval",
            "3600000",
        ],
        &["--sim", "s100", "--count", "1000000001"],
    ] {
        let out = run(MODEM_BENCH, args, b"", LIMIT);
        assert_contract(&out, &[2], &format!("{args:?}"));
        error_line(&out, "modem-bench");
    }
}

#[test]
fn modem_bench_leaves_no_file_on_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("ber.json"),
        br#"{"bitrate_bps": 1900, "intrinsic_delay_ms": 85, "ber": 2}"#,
    )
    .unwrap();
    std::fs::write(dir.path().join("cut.json"), br#"{"bitrate_bps": 19"#).unwrap();
    std::fs::write(dir.path().join("random.json"), garbage(100, 2)).unwrap();
    for args in [
        // Issue 14: this one left a header-only p.csv.
        &[
            "--sim",
            "s100",
            "--ber",
            "2",
            "-o",
            "p.csv",
            "--summary",
            "s.json",
            "--fit",
            "f.json",
        ][..],
        &[
            "--model-file",
            "ber.json",
            "-o",
            "p.csv",
            "--summary",
            "s.json",
        ],
        &["--model-file", "cut.json", "-o", "p.csv"],
        &["--model-file", "random.json", "-o", "p.csv"],
        &["--model-file", "missing.json", "-o", "p.csv"],
        &["--sim", "s100", "--dialect", "evologics", "-o", "p.csv"],
        &[
            "--sim",
            "s100",
            "-o",
            "p.csv",
            "--summary",
            "-",
            "--fit",
            "-",
        ],
        &["--model-file", "ber.json", "--summary", "ber.json"],
    ] {
        let out = run_in(dir.path(), MODEM_BENCH, args, b"", LIMIT);
        assert_contract(&out, &[2], &format!("{args:?}"));
        error_line(&out, "modem-bench");
        for name in ["p.csv", "s.json", "f.json", "-"] {
            assert!(!dir.path().join(name).exists(), "{args:?} left {name}");
        }
    }
    let text = std::fs::read_to_string(dir.path().join("ber.json")).unwrap();
    assert!(text.contains("\"ber\": 2"), "the input was overwritten");
    let out = run_in(
        dir.path(),
        MODEM_BENCH,
        &["--sim", "s100", "-o", "/dev/full"],
        b"",
        LIMIT,
    );
    assert_contract(&out, &[2], "-o /dev/full");
    assert!(error_line(&out, "modem-bench").contains("/dev/full: write failed"));
}

#[test]
fn modem_bench_outputs_on_stdout_and_a_closed_pipe() {
    let out = run(
        MODEM_BENCH,
        &[
            "--sim",
            "s100",
            "--count",
            "20",
            "-o",
            "/dev/null",
            "--summary",
            "-",
            "-q",
        ],
        b"",
        LIMIT,
    );
    assert_contract(&out, &[0], "--summary -");
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["count"], 20);
    assert!(summary["interrupted"].is_null());
    let out = run(
        MODEM_BENCH,
        &[
            "--sim",
            "s100",
            "--sizes",
            "16,57",
            "--count",
            "50",
            "-o",
            "/dev/null",
            "--fit",
            "-",
            "-q",
        ],
        b"",
        LIMIT,
    );
    assert_contract(&out, &[0], "--fit -");
    let model: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(model["bitrate_bps"].is_number());
    let out = head_one(
        MODEM_BENCH,
        &["--sim", "s100", "--count", "100000"],
        b"",
        LIMIT,
    );
    assert_contract(&out, &[0], "| head -1");
    assert_eq!(
        out.stdout,
        b"seq,size_bytes,t_tx_s,t_rx_s,delay_ms,delivered,corrupted\n"
    );
}

#[test]
fn modem_bench_sim_stops_at_a_signal_with_summary_and_fit() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "--sim",
        "s100",
        "--sizes",
        "16,57",
        "--count",
        "100000000",
        "-o",
        "p.csv",
        "--summary",
        "s.json",
        "--fit",
        "fit.json",
    ];
    for (signal, code) in [
        (Signal::SIGTERM, 143),
        (Signal::SIGINT, 130),
        (Signal::SIGHUP, 129),
    ] {
        // The sign is rows in this run's file, not the last run's.
        let _ = std::fs::remove_file(dir.path().join("p.csv"));
        // 10^8 packets do not end in a test's time: signalled once rows are written.
        let out = signal_when(
            dir.path(),
            MODEM_BENCH,
            &args,
            Stdin::Bytes(b""),
            SignalWhen {
                signal,
                ready: &|seen| seen.lines_in("p.csv") > 10,
            },
            LIMIT,
        );
        assert_contract(&out, &[code], &format!("{signal:?}"));
        assert!(
            temp_files(dir.path()).is_empty(),
            "{:?}",
            temp_files(dir.path())
        );
        let rows = dir.path().join("p.csv");
        assert_whole_csv(&rows);
        let lines = std::fs::read_to_string(&rows).unwrap().lines().count() as u64;
        let summary = json(&dir.path().join("s.json"));
        assert_eq!(summary["interrupted"], format!("interrupted by {signal:?}"));
        assert_eq!(
            summary["count"].as_u64().unwrap(),
            lines - 1,
            "a row per packet counted"
        );
        assert!(json(&dir.path().join("fit.json"))["bitrate_bps"].is_number());
    }
}

/// Issue 14: `modem-bench --sim` kept every row for its summary (4.5 MB/s in a release build).
#[test]
fn modem_bench_sim_memory_does_not_grow_with_the_count() {
    let mut child = Command::new(MODEM_BENCH)
        .args([
            "--sim",
            "s100",
            "--count",
            "1000000000",
            "-o",
            "/dev/null",
            "-q",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let rss_kb = |pid: u32| -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
        let line = status.lines().find(|l| l.starts_with("VmRSS:")).unwrap();
        line.split_whitespace().nth(1).unwrap().parse().unwrap()
    };
    // Measured by work done, not by time: the bytes of rows written so far (`wchar`).
    let written = |pid: u32| -> u64 {
        let io = std::fs::read_to_string(format!("/proc/{pid}/io")).unwrap_or_default();
        io.lines()
            .find_map(|l| l.strip_prefix("wchar:"))
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or(0)
    };
    let wait_for = |bytes: u64| {
        let started = Instant::now();
        while written(child.id()) < bytes {
            assert!(started.elapsed() < LIMIT, "no progress to {bytes} bytes");
            std::thread::sleep(Duration::from_millis(10));
        }
    };
    // Early: after 1 MB of rows (tens of thousands of packets); late: after 10 MB more.
    wait_for(1 << 20);
    let early = rss_kb(child.id());
    wait_for(11 << 20);
    let late = rss_kb(child.id());
    signal_once(&mut child, Signal::SIGTERM, &|| true, LIMIT);
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(143));
    assert!(
        late < early + 1024,
        "resident memory grew from {early} kB to {late} kB"
    );
}

/// A stats file that cannot be created (in /proc no temporary file can go, even for root) is
/// an error before the pipe runs: the frames were not written to -o and the trace not begun,
/// so exit 2 leaves no file.
#[test]
fn link_sim_an_uncreatable_stats_file_fails_before_the_run_and_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("in.bin"), frames(50)).unwrap();
    let args = [
        "in.bin",
        "-o",
        "out.bin",
        "--trace",
        "t.csv",
        "--stats",
        "/proc/version",
    ];
    let out = run_in(dir.path(), LINK_SIM, &args, b"", LIMIT);
    assert_contract(&out, &[2], "--stats /proc/version");
    assert!(error_line(&out, "link-sim").contains("/proc/version"));
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, ["in.bin"]);
}

/// `--print-model` writes to -o when given (it was ignored: the JSON went to standard output)
/// and refuses what it would ignore (an input, a trace, ports).
#[test]
fn link_sim_print_model_honours_o_and_refuses_what_it_would_ignore() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["--print-model", "s100", "--ber", "0.001", "-o", "m.json"];
    let out = run_in(dir.path(), LINK_SIM, &args, b"", LIMIT);
    assert_contract(&out, &[0], "--print-model -o");
    assert!(out.stdout.is_empty());
    let model = json(&dir.path().join("m.json"));
    assert_eq!(
        (model["name"].as_str(), model["ber"].as_f64()),
        (Some("s100"), Some(0.001))
    );
    let args = ["--print-model", "--model-file", "m.json", "-o", "m.json"];
    let out = run_in(dir.path(), LINK_SIM, &args, b"", LIMIT);
    assert_contract(&out, &[2], "--print-model -o = --model-file");
    assert!(error_line(&out, "link-sim").contains("refusing to overwrite an input"));
    for extra in [
        &["in.bin"][..],
        &["--trace", "t.csv"],
        &["--stats", "-"],
        &["--pty"],
    ] {
        let mut args = vec!["--print-model", "s100"];
        args.extend(extra);
        let out = run_in(dir.path(), LINK_SIM, &args, b"", LIMIT);
        assert_contract(&out, &[2], &format!("--print-model {extra:?}"));
        assert!(error_line(&out, "link-sim").contains("cannot be used with"));
        assert!(out.stdout.is_empty());
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

/// A summary or fit file that cannot be created (in /proc) is an error before the campaign:
/// no packets.csv and no other document left behind, however long --count asked it to run.
#[test]
fn modem_bench_an_uncreatable_summary_or_fit_fails_before_the_run_and_leaves_nothing() {
    for (flag, other) in [("--summary", "--fit"), ("--fit", "--summary")] {
        let dir = tempfile::tempdir().unwrap();
        let args = [
            "--sim",
            "s100",
            "--count",
            "1000000000",
            "-o",
            "p.csv",
            other,
            "other.json",
            flag,
            "/proc/version",
        ];
        let started = Instant::now();
        let out = run_in(dir.path(), MODEM_BENCH, &args, b"", LIMIT);
        assert_contract(&out, &[2], &format!("{flag} /proc/version"));
        assert!(error_line(&out, "modem-bench").contains("/proc/version"));
        assert!(started.elapsed() < Duration::from_secs(10), "ran first");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "{flag}");
    }
}

/// A side that is not a serial port is named as such (it said `cannot open: Not a
/// typewriter`).
#[test]
fn link_sim_a_side_that_is_not_a_terminal_is_named_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("frames.bin");
    std::fs::write(&file, frames(2)).unwrap();
    let out = run(
        LINK_SIM,
        &["--a", file.to_str().unwrap(), "--b", "/dev/null"],
        b"",
        LIMIT,
    );
    assert_contract(&out, &[2], "--a FILE");
    let line = error_line(&out, "link-sim");
    assert!(line.contains("a regular file, not a serial port"), "{line}");
}
