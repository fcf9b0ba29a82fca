//! Helpers shared by the process-level tests: run a built binary with stdin bytes, capture
//! everything, compare against golden files.
#![allow(dead_code)]

pub mod ardusub;
pub mod hostile;
pub mod watched;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use nix::fcntl::OFlag;
use nix::pty::{PtyMaster, grantpt, posix_openpt, ptsname_r, unlockpt};

/// What a finished process left behind.
pub struct Outcome {
    pub code: i32,
    pub stdout: Vec<u8>,
    pub stderr: String,
}

impl Outcome {
    pub fn stdout_text(&self) -> String {
        String::from_utf8(self.stdout.clone()).expect("stdout is UTF-8")
    }
}

/// Path of a file in the project's testdata/.
pub fn testdata(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("testdata")
        .join(name)
}

/// Runs `bin` (a path from `env!("TOOL_EXE_...")`) with arguments and standard input.
pub fn run(bin: &str, args: &[&str], stdin: &[u8]) -> Outcome {
    let mut child = Command::new(bin)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("binary starts");
    let mut input = child.stdin.take().expect("stdin");
    let data = stdin.to_vec();
    let writer = std::thread::spawn(move || {
        let _ = input.write_all(&data);
    });
    let out = child.wait_with_output().expect("binary finishes");
    writer.join().expect("stdin writer");
    Outcome {
        code: out.status.code().expect("exit code, not a signal"),
        stdout: out.stdout,
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// Compares `actual` with testdata/golden/`name`; with UPDATE_GOLDEN=1 in the environment,
/// rewrites the golden file instead.
pub fn golden(name: &str, actual: &str) {
    let path = testdata("golden").join(name);
    if std::env::var_os("UPDATE_GOLDEN").is_some() {
        std::fs::write(&path, actual).expect("write golden file");
        return;
    }
    let expected = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (run with UPDATE_GOLDEN=1 to create it)",
            path.display()
        )
    });
    assert_eq!(actual, expected, "output differs from {}", path.display());
}

/// Runs one of OctoMap's tools (Debian's octomap-tools): its standard output and error. Fails
/// the test with a clear message when the tool is not installed or fails.
pub fn octomap_tool(name: &str, args: &[&str]) -> String {
    let out = Command::new(name).args(args).output().unwrap_or_else(|e| {
        panic!("{name} not runnable ({e}): install Debian's octomap-tools (apt-get install octomap-tools)")
    });
    assert!(
        out.status.success(),
        "{name} {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr)
}

/// OctoMap's `compare_octrees` finds the two `.ot` maps equal: it says `KLD: 0`.
pub fn assert_kld_zero(ours: &Path, theirs: &Path, what: &str) {
    let path = |p: &Path| p.to_str().expect("UTF-8 path").to_string();
    let cmp = octomap_tool("compare_octrees", &[&path(ours), &path(theirs)]);
    let kld = cmp.lines().find_map(|l| l.split("KLD: ").nth(1));
    assert_eq!(kld.map(str::trim), Some("0"), "{what}: {cmp}");
}

/// The frames of testdata/wire-vectors.hex, as bytes.
pub fn vector_frames() -> Vec<Vec<u8>> {
    std::fs::read_to_string(testdata("wire-vectors.hex"))
        .expect("vectors")
        .lines()
        .map(|l| rovlink_wire::json::decode_hex(l.trim()).expect("hex"))
        .collect()
}

/// Opens a pseudo-terminal master (close-on-exec, so the child does not inherit it and closing
/// it here really hangs up the line) and returns it with the path of its slave side.
pub fn open_pty() -> (PtyMaster, String) {
    let master =
        posix_openpt(OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_CLOEXEC).expect("posix_openpt");
    grantpt(&master).expect("grantpt");
    unlockpt(&master).expect("unlockpt");
    let path = ptsname_r(&master).expect("ptsname");
    (master, path)
}

/// Waits for `child` to exit on its own, failing the test if it has not within `limit`.
pub fn wait_for_exit(
    child: &mut std::process::Child,
    limit: std::time::Duration,
) -> std::process::ExitStatus {
    let started = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            return status;
        }
        assert!(
            started.elapsed() < limit,
            "the process did not exit within {limit:?}"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// The link the real-time tests run two `tdma-run` ends over: S100 at 9600 bit/s, 20 ms delay,
/// 2 ms jitter, full duplex (a debug build's ROV can answer late enough to collide with the
/// next slot).
pub const TEST_S100: [&str; 10] = [
    "--model",
    "s100",
    "--bitrate-bps",
    "9600",
    "--intrinsic-delay-ms",
    "20",
    "--jitter-ms",
    "2",
    "--half-duplex",
    "false",
];

/// Starts `link-sim --pty` with `args`; returns it and the paths of its sides A and B.
pub fn link_sim_pty(args: &[&str]) -> (Reaped, String, String) {
    let mut child = Command::new(env!("TOOL_EXE_link-sim"))
        .arg("--pty")
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("link-sim starts");
    let mut ports = pty_paths(&mut child, 2).into_iter();
    let (a, b) = (ports.next().unwrap(), ports.next().unwrap());
    (Reaped(child), a, b)
}

/// Starts `link-sim --pty COUNT` (one shared medium) with `args` (the model, `--position`s);
/// returns it and the paths of its COUNT pseudo-terminals, in port order.
pub fn link_sim_ptys(count: usize, args: &[&str]) -> (Reaped, Vec<String>) {
    let mut child = Command::new(env!("TOOL_EXE_link-sim"))
        .args(args)
        .args(["--pty", &count.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("link-sim starts");
    let ports = pty_paths(&mut child, count);
    (Reaped(child), ports)
}

/// The first `count` lines of a `link-sim --pty`'s standard output: its ports' paths.
fn pty_paths(child: &mut std::process::Child, count: usize) -> Vec<String> {
    use std::io::BufRead;
    let mut stdout = std::io::BufReader::new(child.stdout.take().expect("stdout"));
    (0..count)
        .map(|_| {
            let mut line = String::new();
            stdout.read_line(&mut line).expect("a port's path");
            line.trim().to_string()
        })
        .collect()
}

/// Writes `text` to a new file `name` in `dir`, created with mode 0600 (as key and token files
/// must be: never readable by others); its path.
pub fn private_file(dir: &Path, name: &str, text: &str) -> PathBuf {
    use std::os::unix::fs::OpenOptionsExt;
    let path = dir.join(name);
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(&path)
        .unwrap();
    file.write_all(text.as_bytes()).unwrap();
    path
}

/// A child process killed and reaped when dropped, so that a test that fails (panics) leaves
/// no process of its own running; otherwise a [`std::process::Child`] (by deref).
pub struct Reaped(pub std::process::Child);

impl std::ops::Deref for Reaped {
    type Target = std::process::Child;
    fn deref(&self) -> &std::process::Child {
        &self.0
    }
}

impl std::ops::DerefMut for Reaped {
    fn deref_mut(&mut self) -> &mut std::process::Child {
        &mut self.0
    }
}

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Every file below `dir` (links not followed) and its bytes.
pub fn tree(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut files = Vec::new();
    let mut folders = vec![dir.to_path_buf()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if std::fs::symlink_metadata(&path).unwrap().is_dir() {
                folders.push(path);
            } else {
                files.push((path.clone(), std::fs::read(&path).unwrap_or_default()));
            }
        }
    }
    files.sort();
    files
}

/// A TCP port on 127.0.0.1 that refuses every connection while this value lives: a socket is
/// bound to it and never listens, so no other program can listen there (a test that took port 1
/// to be closed failed while another program had it), and the kernel never picks it as the
/// local port of an outgoing connection either.
pub struct ClosedPort {
    _held: socket2::Socket,
    /// The port.
    pub port: u16,
}

impl ClosedPort {
    /// A port the kernel chose, held closed.
    pub fn hold() -> ClosedPort {
        use socket2::{Domain, Socket, Type};
        let held = Socket::new(Domain::IPV4, Type::STREAM, None).expect("a TCP socket");
        let any = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
        held.bind(&any.into()).expect("bind 127.0.0.1:0");
        let port = held
            .local_addr()
            .ok()
            .and_then(|a| a.as_socket())
            .expect("the bound address")
            .port();
        ClosedPort { _held: held, port }
    }
}

/// A free port on 127.0.0.1 (bound and released: another process could take it first, which
/// fails a test loudly rather than passing it wrongly).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Runs the stock Foxglove client (tests/foxglove/stock_client.mjs: `@foxglove/ws-protocol`
/// from npm, on Node) with `args` (`--url`, `--seconds`, ...) and `--out` in a file of its
/// own; what it saw (its JSON). Fails if it cannot connect.
pub fn stock_client(args: &[&str]) -> serde_json::Value {
    const CLIENT: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/foxglove/stock_client.mjs"
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seen.json");
    let run = Command::new("node")
        .arg(CLIENT)
        .args(args)
        .arg("--out")
        .arg(&out)
        .stdin(Stdio::null())
        .output()
        .expect("node runs (apt-get install nodejs npm; npm ci --prefix tests/foxglove)");
    assert!(
        run.status.success(),
        "stock client {args:?}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap()
}

/// Reads `child`'s standard error until a line holds `text` (failing, and killing the child,
/// if it ends first or says nothing of the kind within `limit`); the rest is read aside and
/// comes with the handle.
pub fn said_until(
    child: &mut std::process::Child,
    text: &str,
    limit: std::time::Duration,
) -> std::thread::JoinHandle<String> {
    use std::io::BufRead;
    let mut stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    let (tx, rx) = std::sync::mpsc::channel();
    let wanted = text.to_string();
    let reader = std::thread::spawn(move || {
        let mut said = String::new();
        let mut line = String::new();
        let mut told = false;
        while stderr.read_line(&mut line).is_ok_and(|n| n > 0) {
            said.push_str(&line);
            if !told && line.contains(&wanted) {
                told = tx.send(()).is_ok();
            }
            line.clear();
        }
        said
    });
    if rx.recv_timeout(limit).is_err() {
        let _ = child.kill();
        panic!("nothing said {text:?}: {}", reader.join().unwrap());
    }
    reader
}

/// Opens the FIFO at `path` for writing once `reader` has opened it for reading (without
/// blocking: a reader that ended first, or did not open it within `limit`, fails the test
/// instead of hanging it).
pub fn fifo_writer(
    path: impl AsRef<Path>,
    reader: &mut std::process::Child,
    limit: std::time::Duration,
) -> std::fs::File {
    use std::os::unix::fs::OpenOptionsExt;
    let path = path.as_ref();
    let started = std::time::Instant::now();
    loop {
        match std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(OFlag::O_NONBLOCK.bits())
            .open(path)
        {
            Ok(file) => return file,
            Err(e) if e.raw_os_error() == Some(nix::libc::ENXIO) => {}
            Err(e) => panic!("{}: {e}", path.display()),
        }
        if let Some(status) = reader.try_wait().unwrap() {
            panic!("ended ({status}) before opening {}", path.display());
        }
        assert!(
            started.elapsed() < limit,
            "{} was not opened",
            path.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// The lines of `stream` (a child's stderr), read in a thread as they come.
pub fn lines_of(stream: impl std::io::Read + Send + 'static) -> std::sync::mpsc::Receiver<String> {
    use std::io::BufRead;
    let (tx, lines) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stream)
            .lines()
            .map_while(Result::ok)
        {
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    lines
}
