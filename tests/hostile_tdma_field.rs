//! Hostile uses of tdma-run's field flags, in simulation: each ends with a contract exit code,
//! promptly, and a signal is obeyed even while the run waits on an order FIFO or a camera
//! command.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_tdma-run");

/// Waits for `child` at most `limit`; kills it and fails if it is still running then.
fn wait_within(mut child: Child, limit: Duration) -> (i32, String) {
    let started = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let err = std::io::read_to_string(child.stderr.take().unwrap()).unwrap();
            let code = status
                .code()
                .unwrap_or_else(|| panic!("killed by a signal: {status}"));
            return (code, err);
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            panic!("still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn spawn(args: &[&str], dir: &std::path::Path) -> Child {
    Command::new(BIN)
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn sigterm(child: &Child) {
    let pid = nix::unistd::Pid::from_raw(i32::try_from(child.id()).unwrap());
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
}

#[test]
fn sigterm_while_the_simulation_waits_for_an_orders_fifo_writer_ends_it_with_143_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    nix::unistd::mkfifo(&dir.path().join("orders"), nix::sys::stat::Mode::S_IRWXU).unwrap();
    let child = spawn(
        &[
            "--duration",
            "60",
            "--orders",
            "orders",
            "--metrics",
            "m.json",
        ],
        dir.path(),
    );
    std::thread::sleep(Duration::from_millis(700));
    sigterm(&child);
    let (code, err) = wait_within(child, Duration::from_secs(3));
    assert_eq!(code, 143, "{err}");
    assert!(err.contains("--orders orders"), "{err}");
    assert!(!dir.path().join("m.json").exists());
}

#[test]
fn a_camera_command_that_never_answers_costs_a_simulation_one_timeout_and_sigterm_ends_a_wait() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["--duration", "600", "--camera-cmd", "sleep 1000"];
    let started = Instant::now();
    let (code, err) = wait_within(spawn(&args, dir.path()), Duration::from_secs(20));
    assert_eq!(code, 0, "{err}");
    assert!(started.elapsed() < Duration::from_secs(15), "{err}");
    assert!(err.contains("600 s over s100"), "{err}");

    let child = spawn(&args, dir.path());
    std::thread::sleep(Duration::from_millis(700));
    sigterm(&child);
    let (code, err) = wait_within(child, Duration::from_secs(3));
    assert_eq!(code, 143, "{err}");
}

#[test]
fn bad_orders_lines_are_warnings_and_bad_field_flags_are_one_line_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut junk = b"{\"t_s\":1,\"type\":\"cancel\"}\0\n\xff\xfe\n".to_vec();
    junk.extend_from_slice(b"{\"t_s\":1e300,\"type\":\"cancel\"}\n[1]\n");
    junk.extend_from_slice(b"{\"type\":\"velocity\",\"vx\":1e300}\n");
    std::fs::write(dir.path().join("junk.jsonl"), &junk).unwrap();
    let child = spawn(&["--duration", "30", "--orders", "junk.jsonl"], dir.path());
    let (code, err) = wait_within(child, Duration::from_secs(10));
    assert_eq!(code, 0, "{err}");
    assert_eq!(err.matches("junk.jsonl: line ").count(), 5, "{err}");

    for args in [
        &["--foxglove", "host:99999"][..],
        &["--foxglove", ":0"],
        &["--telemetry", "."],
        &["--orders", "."],
        &["--camera", "/nonexistent-camera-dir"],
        &[
            "--role",
            "rov",
            "--port",
            "/dev/null",
            "--vehicle",
            "mavlink:udpin:",
        ],
        &[
            "--role",
            "rov",
            "--port",
            "/dev/null",
            "--vehicle",
            "mavlink:serial::",
        ],
        &[
            "--role",
            "rov",
            "--port",
            "/dev/null",
            "--vehicle",
            "mavlink:tcpout:h:0",
        ],
    ] {
        let mut all = vec!["--duration", "5", "--metrics", "m.json"];
        all.extend_from_slice(args);
        let (code, err) = wait_within(spawn(&all, dir.path()), Duration::from_secs(10));
        assert_eq!(code, 2, "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(!dir.path().join("m.json").exists(), "{args:?}");
    }
}
