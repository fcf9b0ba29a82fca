//! Hostile uses of tdma-run's field flags, in simulation: each ends with a contract exit code,
//! promptly, and a signal is obeyed even while the run waits on an order FIFO or a camera
//! command.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::hostile::signal_once;
use nix::sys::signal::Signal;
use rovlink_rcp::camera::COMMAND_TIMEOUT_S;

const BIN: &str = env!("TOOL_EXE_tdma-run");

/// How long a run may take to show the sign a test waits for, or to end when it has nothing
/// left to wait for: only a hang takes this long, however loaded the machine.
const LIMIT: Duration = Duration::from_secs(30);

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

/// True if process `pid` has a thread named `name` (its `comm` in /proc).
fn has_thread(pid: u32, name: &str) -> bool {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return false;
    };
    tasks.flatten().any(|task| {
        std::fs::read_to_string(task.path().join("comm")).is_ok_and(|comm| comm.trim() == name)
    })
}

/// True if process `pid` has a child process (some /proc/N/stat names it as the parent).
fn has_child(pid: u32) -> bool {
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return false;
    };
    entries.flatten().any(|entry| {
        let stat = std::fs::read_to_string(entry.path().join("stat")).unwrap_or_default();
        // After the command name in parentheses: the state, then the parent's id.
        stat.rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().nth(1))
            .is_some_and(|ppid| ppid == pid.to_string())
    })
}

#[test]
fn sigterm_while_the_simulation_waits_for_an_orders_fifo_writer_ends_it_with_143_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    nix::unistd::mkfifo(&dir.path().join("orders"), nix::sys::stat::Mode::S_IRWXU).unwrap();
    let mut child = spawn(
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
    // The signal goes once the run waits for the FIFO's writer: its thread that opens the
    // FIFO (and blocks there) is running.
    let pid = child.id();
    let waiting = || has_thread(pid, "orders-open");
    signal_once(&mut child, Signal::SIGTERM, &waiting, LIMIT);
    let (code, err) = wait_within(child, LIMIT);
    assert_eq!(code, 143, "{err}");
    assert!(err.contains("--orders orders"), "{err}");
    assert!(!dir.path().join("m.json").exists());
}

#[test]
fn a_camera_command_that_never_answers_costs_a_simulation_one_timeout_and_sigterm_ends_a_wait() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["--duration", "600", "--camera-cmd", "sleep 1000"];
    let timeout = Duration::from_secs_f64(COMMAND_TIMEOUT_S);
    let started = Instant::now();
    let (code, err) = wait_within(spawn(&args, dir.path()), 2 * timeout + LIMIT);
    assert_eq!(code, 0, "{err}");
    // One timeout, not two: the simulation itself takes a fraction of a second, and the
    // second timeout would make it twice as long, whatever the machine's speed.
    let took = started.elapsed();
    assert!(took >= timeout && took < 2 * timeout, "{took:?}: {err}");
    assert!(err.contains("600 s over s100"), "{err}");

    // The signal goes once the capture waits: the camera command runs (a child process).
    let mut child = spawn(&args, dir.path());
    let pid = child.id();
    let waiting = || has_child(pid);
    signal_once(&mut child, Signal::SIGTERM, &waiting, LIMIT);
    let signalled = Instant::now();
    let (code, err) = wait_within(child, LIMIT);
    assert_eq!(code, 143, "{err}");
    // The wait ended on the signal, not at the command's timeout (a run that ignored the
    // signal would end there, with 143 too).
    let took = signalled.elapsed();
    assert!(took < timeout / 2, "{took:?}: {err}");
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
