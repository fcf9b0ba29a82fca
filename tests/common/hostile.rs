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

/// What a running tool has shown so far, for the sign a signal test waits for.
pub struct Seen<'a> {
    /// The folder it runs in.
    pub dir: &'a Path,
    /// Its standard output so far.
    pub stdout: &'a [u8],
    /// Its standard error so far.
    pub stderr: &'a [u8],
}

impl Seen<'_> {
    /// The number of lines (ends of line) in `dir/name`: 0 while it does not exist.
    pub fn lines_in(&self, name: &str) -> usize {
        lines_in(&self.dir.join(name))
    }

    /// True if standard error holds `text`.
    pub fn said(&self, text: &str) -> bool {
        String::from_utf8_lossy(self.stderr).contains(text)
    }
}

/// The number of lines (ends of line) in a file: 0 while it does not exist.
pub fn lines_in(path: &Path) -> usize {
    std::fs::read(path).map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count())
}

/// True once process `pid` catches `signal` (its handler is installed), read from the
/// `SigCgt` mask of `/proc/PID/status`: a signal sent earlier would end it by the default
/// action, which is not what a signal test means to try.
pub fn catches(pid: u32, signal: Signal) -> bool {
    let Ok(status) = std::fs::read_to_string(format!("/proc/{pid}/status")) else {
        return false;
    };
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigCgt:"))
        .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        .is_some_and(|mask| mask & (1u64 << (signal as i32 - 1)) != 0)
}

/// Waits until `child` catches `signal` (its handler is installed; see [`catches`]) and then
/// until `ready()` holds, polling every 5 ms, and sends the signal. Panics (the test fails) if
/// the child ends first or `limit` passes: a signal test never sends on a timer.
pub fn signal_once(child: &mut Child, signal: Signal, ready: &dyn Fn() -> bool, limit: Duration) {
    let started = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            panic!("ended ({status}) before the sign the test waited for, {signal} unsent");
        }
        if catches(child.id(), signal) && ready() {
            kill(Pid::from_raw(child.id() as i32), signal).expect("kill");
            return;
        }
        assert!(
            started.elapsed() < limit,
            "no sign within {limit:?}, {signal} unsent"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// True if process `pid` has `path` open and every one of its threads is asleep (state `S`):
/// it has read what a pipe held and waits for more. (A thread at work is `R`; one waiting on
/// the disk `D`.)
pub fn idle_reading(pid: u32, path: &Path) -> bool {
    let open = std::fs::read_dir(format!("/proc/{pid}/fd")).is_ok_and(|fds| {
        fds.flatten()
            .any(|fd| std::fs::read_link(fd.path()).is_ok_and(|target| target == path))
    });
    let asleep = std::fs::read_dir(format!("/proc/{pid}/task")).is_ok_and(|tasks| {
        tasks.flatten().all(|task| {
            std::fs::read_to_string(task.path().join("stat")).is_ok_and(|stat| {
                // The state follows the command name's closing parenthesis.
                stat.rsplit_once(')')
                    .is_some_and(|(_, rest)| rest.trim_start().starts_with('S'))
            })
        })
    });
    open && asleep
}

/// When a signal test sends its signal: once the tool catches it and `ready` holds.
pub struct SignalWhen<'a> {
    /// The signal.
    pub signal: Signal,
    /// The sign that the work is under way.
    pub ready: &'a dyn Fn(&Seen) -> bool,
}

/// What a test writes to a tool's standard input.
pub enum Stdin<'a> {
    /// These bytes, then end of file.
    Bytes(&'a [u8]),
    /// These bytes over and over until the tool closes its end: input that never ends.
    Forever(&'a [u8]),
}

fn shared_reader(
    source: Option<impl Read + Send + 'static>,
) -> (
    std::sync::Arc<std::sync::Mutex<Vec<u8>>>,
    std::thread::JoinHandle<()>,
) {
    let buf = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let into = buf.clone();
    let handle = std::thread::spawn(move || {
        let Some(mut source) = source else { return };
        let mut chunk = [0u8; 1 << 14];
        while let Ok(n) = source.read(&mut chunk) {
            if n == 0 {
                break;
            }
            into.lock().unwrap().extend_from_slice(&chunk[..n]);
        }
    });
    (buf, handle)
}

fn collect(
    dir: Option<&Path>,
    mut child: Child,
    stdin: Stdin,
    limit: Duration,
    when: Option<SignalWhen>,
) -> Run {
    let input = child.stdin.take();
    let (data, forever) = match stdin {
        Stdin::Bytes(b) => (b.to_vec(), false),
        Stdin::Forever(b) => (b.to_vec(), true),
    };
    let writer = std::thread::spawn(move || {
        if let Some(mut input) = input {
            while input.write_all(&data).is_ok() && forever && !data.is_empty() {}
        }
    });
    let (out, out_reader) = shared_reader(child.stdout.take());
    let (err, err_reader) = shared_reader(child.stderr.take());
    let started = Instant::now();
    let mut signalled = when.is_none();
    let mut hung = false;
    let here = PathBuf::from(".");
    let dir = dir.unwrap_or(&here);
    let status = loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            break status;
        }
        if let Some(when) = &when
            && !signalled
            && catches(child.id(), when.signal)
        {
            let ready = {
                let stdout = out.lock().unwrap();
                let stderr = err.lock().unwrap();
                (when.ready)(&Seen {
                    dir,
                    stdout: &stdout,
                    stderr: &stderr,
                })
            };
            if ready {
                let _ = kill(Pid::from_raw(child.id() as i32), when.signal);
                signalled = true;
            }
        }
        if started.elapsed() > limit {
            hung = true;
            let _ = child.kill();
            break child.wait().expect("wait");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let _ = writer.join();
    let _ = out_reader.join();
    let _ = err_reader.join();
    use std::os::unix::process::ExitStatusExt;
    let take =
        |b: std::sync::Arc<std::sync::Mutex<Vec<u8>>>| std::mem::take(&mut *b.lock().unwrap());
    let stderr = String::from_utf8_lossy(&take(err)).into_owned();
    Run {
        code: status.code(),
        signal: status.signal(),
        stdout: take(out),
        stderr: if signalled {
            stderr
        } else {
            format!("(ended before the sign the test waited for) {stderr}")
        },
        hung,
    }
}

/// Runs `bin` with `args` and `stdin`, killing it after `limit`.
pub fn run(bin: &str, args: &[&str], stdin: &[u8], limit: Duration) -> Run {
    collect(
        None,
        spawn(bin, args, None),
        Stdin::Bytes(stdin),
        limit,
        None,
    )
}

/// Runs `bin` in `dir` (for tests that look for stray files there).
pub fn run_in(dir: &Path, bin: &str, args: &[&str], stdin: &[u8], limit: Duration) -> Run {
    collect(
        Some(dir),
        spawn(bin, args, Some(dir)),
        Stdin::Bytes(stdin),
        limit,
        None,
    )
}

/// Runs `bin` in `dir` with `stdin` and sends it a signal once it catches it and `when`'s sign
/// shows that the work is under way (a file with rows, a line on stderr); killed after `limit`.
/// No timing: a tool that ends before the sign fails the test with a note saying so.
pub fn signal_when(
    dir: &Path,
    bin: &str,
    args: &[&str],
    stdin: Stdin,
    when: SignalWhen,
    limit: Duration,
) -> Run {
    collect(
        Some(dir),
        spawn(bin, args, Some(dir)),
        stdin,
        limit,
        Some(when),
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
    let mut run = collect(None, child, Stdin::Bytes(b""), limit, None);
    let _ = writer.join();
    run.stdout = first;
    run
}

/// Runs `bin` with `args` in `dir`, reading the named pipe `dir/fifo` (created here) whose
/// writer sends `bytes` and then stays open and silent, as a live producer does; sends `signal`
/// once the tool has read them and waits for more (it has the pipe open and all its threads
/// have looked asleep over `wait`: see [`idle_reading`]) and fails the test if the tool has not
/// ended within `limit` of it. Returns the exit status and standard error.
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
    // Signalled once the tool has taken everything and waits on the pipe for more: the sign is
    // its state, not a time (`wait` is only how long it must look idle).
    // (Some of these tools do not catch the signal at all: it is sent without waiting for a
    // handler, which a tool at its read has installed if it has one.)
    let pid = child.id();
    let started = Instant::now();
    while !(0..3).all(|_| {
        std::thread::sleep(wait / 3);
        idle_reading(pid, &fifo)
    }) {
        assert!(
            child.try_wait().expect("try_wait").is_none(),
            "{args:?}: ended before it waited on the pipe"
        );
        assert!(
            started.elapsed() < limit,
            "{args:?}: never waited on the pipe"
        );
    }
    let _ = kill(Pid::from_raw(pid as i32), signal);
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
