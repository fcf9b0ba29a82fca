//! Helpers for the hostile-input suites (`tests/hostile_*.rs`): run a tool the way a hostile
//! user would and check the README's contract: exit 0, 1 or 2 (130/143 when interrupted),
//! never 101 or a signal, never a hang; errors in one line; no temporary file left behind.
#![allow(dead_code)]

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// What a finished (or killed) process left behind.
#[derive(Debug)]
pub struct Run {
    /// The exit code; `None` if a signal ended it.
    pub code: Option<i32>,
    /// The signal that ended it, if one did.
    pub signal: Option<i32>,
    pub stdout: Vec<u8>,
    pub stderr: String,
    /// True if it had to be killed because it did not end in time.
    pub hung: bool,
}

/// The values every numeric flag is tried with.
pub const BAD_NUMBERS: [&str; 10] = [
    "NaN",
    "nan",
    "inf",
    "-inf",
    "0",
    "-1",
    "-0.5",
    "1e300",
    "-1e300",
    "18446744073709551616",
];

/// Random bytes from a fixed seed (xorshift), for garbage inputs.
pub fn garbage(len: usize, seed: u64) -> Vec<u8> {
    let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

fn spawn(bin: &str, args: &[&str], dir: Option<&Path>) -> Child {
    let mut cmd = Command::new(bin);
    cmd.args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if let Some(dir) = dir {
        cmd.current_dir(dir);
    }
    cmd.spawn().expect("binary starts")
}

fn collect(
    mut child: Child,
    stdin: &[u8],
    limit: Duration,
    signal_after: Option<(Duration, Signal)>,
) -> Run {
    let input = child.stdin.take();
    let data = stdin.to_vec();
    let writer = std::thread::spawn(move || {
        if let Some(mut input) = input {
            let _ = input.write_all(&data);
        }
    });
    let out = child.stdout.take();
    let mut err = child.stderr.take().expect("stderr");
    let out_reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        if let Some(mut out) = out {
            let _ = out.read_to_end(&mut buf);
        }
        buf
    });
    let err_reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = err.read_to_end(&mut buf);
        buf
    });
    let started = Instant::now();
    let mut signalled = false;
    let mut hung = false;
    let status = loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            break status;
        }
        if let Some((after, signal)) = signal_after
            && !signalled
            && started.elapsed() >= after
        {
            let _ = kill(Pid::from_raw(child.id() as i32), signal);
            signalled = true;
        }
        if started.elapsed() > limit {
            hung = true;
            let _ = child.kill();
            break child.wait().expect("wait");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let _ = writer.join();
    use std::os::unix::process::ExitStatusExt;
    Run {
        code: status.code(),
        signal: status.signal(),
        stdout: out_reader.join().unwrap_or_default(),
        stderr: String::from_utf8_lossy(&err_reader.join().unwrap_or_default()).into_owned(),
        hung,
    }
}

/// Runs `bin` with `args` and `stdin`, killing it after `limit`.
pub fn run(bin: &str, args: &[&str], stdin: &[u8], limit: Duration) -> Run {
    collect(spawn(bin, args, None), stdin, limit, None)
}

/// Runs `bin` in `dir` (for tests that look for stray files there).
pub fn run_in(dir: &Path, bin: &str, args: &[&str], stdin: &[u8], limit: Duration) -> Run {
    collect(spawn(bin, args, Some(dir)), stdin, limit, None)
}

/// Runs `bin` in `dir` and sends it `signal` after `after`; killed after `limit`.
pub fn run_signalled(
    dir: &Path,
    bin: &str,
    args: &[&str],
    after: Duration,
    signal: Signal,
    limit: Duration,
) -> Run {
    collect(
        spawn(bin, args, Some(dir)),
        b"",
        limit,
        Some((after, signal)),
    )
}

/// Asserts the contract for a run: it ended by itself, with one of `codes`, no panic, and for
/// exit 2 a one-line error prefixed with the tool's name.
pub fn assert_contract(run: &Run, codes: &[i32], what: &str) {
    assert!(
        !run.hung,
        "{what}: hung (killed after the limit); stderr: {}",
        run.stderr
    );
    assert!(
        run.signal.is_none(),
        "{what}: ended by signal {:?}; stderr: {}",
        run.signal,
        run.stderr
    );
    let code = run.code.unwrap_or(-1);
    assert!(
        !run.stderr.contains("panicked"),
        "{what}: panicked: {}",
        run.stderr
    );
    assert!(
        codes.contains(&code),
        "{what}: exit {code}, expected one of {codes:?}; stderr: {}",
        run.stderr
    );
    if code == 2 {
        let lines: Vec<&str> = run
            .stderr
            .lines()
            .filter(|l| !l.trim().is_empty())
            .collect();
        assert!(!lines.is_empty(), "{what}: exit 2 without a message");
    }
}

/// The temporary files (`.NAME.tmp-PID-N`, as the atomic writer names them) under `dir`.
pub fn temp_files(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if entry.file_name().to_string_lossy().contains(".tmp-") {
                found.push(path);
            }
        }
    }
    found
}

/// Asserts that a CSV file ends with a whole line and every line has the header's field count
/// (fields are not quoted with commas in the tools' numeric CSVs).
pub fn assert_whole_csv(path: &Path) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        text.is_empty() || text.ends_with('\n'),
        "{}: ends mid-line",
        path.display()
    );
    let mut lines = text.lines();
    if let Some(header) = lines.next() {
        let fields = header.split(',').count();
        for (i, line) in lines.enumerate() {
            assert_eq!(
                line.split(',').count(),
                fields,
                "{}: line {} has another field count than the header",
                path.display(),
                i + 2
            );
        }
    }
}

/// Runs `bin` with stdout into a reader that takes one line and closes the pipe, as
/// `bin ... | head -1` does; returns the run (the contract: exit 0, no message).
pub fn head_one(bin: &str, args: &[&str], stdin: &[u8], limit: Duration) -> Run {
    let mut child = spawn(bin, args, None);
    let mut input = child.stdin.take().expect("stdin");
    let data = stdin.to_vec();
    let writer = std::thread::spawn(move || {
        let _ = input.write_all(&data);
    });
    let mut out = child.stdout.take().expect("stdout");
    let mut first = Vec::new();
    let mut byte = [0u8; 1];
    while out.read(&mut byte).map(|n| n == 1).unwrap_or(false) {
        first.push(byte[0]);
        if byte[0] == b'\n' {
            break;
        }
    }
    drop(out);
    let mut run = collect(child, b"", limit, None);
    let _ = writer.join();
    run.stdout = first;
    run
}

/// Runs `bin` with `args` in `dir`, reading the named pipe `dir/fifo` (created here) whose
/// writer sends `bytes` and then stays open and silent, as a live producer does; sends `signal`
/// after `wait` and fails the test if the tool has not ended within `limit` of it. Returns the
/// exit status and standard error.
#[allow(clippy::too_many_arguments)]
pub fn signalled_on_a_silent_pipe(
    dir: &Path,
    fifo: &str,
    bin: &str,
    args: &[&str],
    bytes: &[u8],
    signal: Signal,
    wait: Duration,
    limit: Duration,
) -> (std::process::ExitStatus, String) {
    let fifo = dir.join(fifo);
    let _ = std::fs::remove_file(&fifo);
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).expect("mkfifo");
    let mut child = Command::new(bin)
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("binary starts");
    // Read and write: opening does not wait for the reader, and the pipe never ends.
    let mut writer = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&fifo)
        .expect("the pipe opens");
    writer.write_all(bytes).expect("the pipe takes the bytes");
    std::thread::sleep(wait);
    let _ = kill(Pid::from_raw(child.id() as i32), signal);
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            break status;
        }
        assert!(
            started.elapsed() < limit,
            "{args:?}: did not stop on {signal}"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut err = String::new();
    let _ = child
        .stderr
        .take()
        .expect("stderr")
        .read_to_string(&mut err);
    drop(writer);
    (status, err)
}
