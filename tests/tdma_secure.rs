//! Issue 45's attacks on the medium, each tried against two real-time ends with `--key-file`
//! over `link-sim --pty 3` (one shared medium: the operator, the ROV, and a third node that
//! hears every frame and may transmit any), with the legitimate path shown to work in the
//! same run: injected and forged frames, spoofed statuses, a recorded frame replayed in the
//! same session and in a later one, neutral frames sent after the operator stopped. And the
//! simulation with keys: the same session, each frame 6 bytes longer.
//!
//! Every wait is for a sign (a line the process says, a frame heard), never a delay.

use std::io::{BufRead, Read, Write};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use crate::common::Reaped;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");
const KEY: &str = "2b7e151628aed2a6abf7158809cf4f3c";
const LIMIT: Duration = Duration::from_secs(30);

/// A private key file holding `KEY` for every vehicle.
fn key_file(dir: &Path) -> PathBuf {
    crate::common::private_file(dir, "keys", &format!("* {KEY}\n"))
}

/// `link-sim --pty 3`: the test link (9600 bit/s, full duplex) with three nodes in range of
/// each other; its ports: operator, ROV, intruder.
fn medium() -> (Reaped, Vec<String>) {
    let positions = [
        "--position",
        "0,0,0",
        "--position",
        "1,0,0",
        "--position",
        "2,0,0",
    ];
    crate::common::link_sim_ptys(3, &[&crate::common::TEST_S100[..], &positions].concat())
}

/// One `tdma-run` end: the lines it writes (stdout and stderr) as they come.
struct End {
    child: Reaped,
    lines: Receiver<String>,
    said: String,
    metrics: PathBuf,
}

/// Starts a `tdma-run` end and waits until it says it is under way.
fn start(role: &str, port: &str, dir: &Path, name: &str, args: &[&str]) -> End {
    let metrics = dir.join(format!("{name}.json"));
    let mut child = Command::new(TDMA_RUN)
        .args(["--role", role, "--port", port, "--metrics"])
        .arg(&metrics)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("tdma-run starts");
    let (tx, lines) = std::sync::mpsc::channel();
    let stdout = std::io::BufReader::new(child.stdout.take().unwrap());
    let stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    for reader in [
        Box::new(stdout) as Box<dyn BufRead + Send>,
        Box::new(stderr),
    ] {
        let tx = tx.clone();
        std::thread::spawn(move || {
            for line in reader.lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
    }
    let mut end = End {
        child: Reaped(child),
        lines,
        said: String::new(),
        metrics,
    };
    // Under way: the ROV listens, the operator sends its slots.
    end.wait_for(if role == "rov" {
        "ROV: answering"
    } else {
        "operator: IPG"
    });
    end
}

/// A waypoints file in `dir` with one GoTo, at 1 s, to (2, 0, 1) m.
fn one_goto(dir: &Path) -> PathBuf {
    let path = dir.join("wp.csv");
    std::fs::write(&path, "t_s,x_m,y_m,z_m,heading_deg\n1,2,0,1,90\n").unwrap();
    path
}

impl End {
    /// True once the end has said a line holding `text` (reading what it said so far, waiting
    /// at most `wait`).
    fn has_said(&mut self, text: &str, wait: Duration) -> bool {
        if self.said.contains(text) {
            return true;
        }
        let until = Instant::now() + wait;
        loop {
            let left = until.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    self.said.push_str(&line);
                    self.said.push('\n');
                    if line.contains(text) {
                        return true;
                    }
                }
                Err(RecvTimeoutError::Timeout) => return false,
                Err(RecvTimeoutError::Disconnected) => return false,
            }
        }
    }

    /// Waits for `text`, failing the test after [`LIMIT`].
    fn wait_for(&mut self, text: &str) {
        assert!(
            self.has_said(text, LIMIT),
            "nothing said {text:?}: {}",
            self.said
        );
    }

    /// Waits for the end to exit on its own; its metrics and everything it said.
    fn finish(mut self) -> (serde_json::Value, String) {
        let status = crate::common::wait_for_exit(&mut self.child.0, LIMIT);
        while let Ok(line) = self.lines.recv_timeout(Duration::from_secs(5)) {
            self.said.push_str(&line);
            self.said.push('\n');
        }
        assert!(status.success(), "{status:?}: {}", self.said);
        let text = std::fs::read_to_string(&self.metrics).expect("metrics written");
        (
            serde_json::from_str(&text).expect("metrics JSON"),
            self.said,
        )
    }
}

/// The third node on the medium: every frame it hears, and a way to transmit.
struct Intruder {
    port: std::fs::File,
    heard: Receiver<Vec<u8>>,
}

fn intruder(path: &str) -> Intruder {
    use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
    let port = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .expect("the intruder's port");
    let mut raw = tcgetattr(&port).expect("tcgetattr");
    cfmakeraw(&mut raw);
    tcsetattr(&port, SetArg::TCSANOW, &raw).expect("raw mode");
    let mut reader = port.try_clone().unwrap();
    let (tx, heard) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut deframer = rovlink_wire::Deframer::new();
        let mut buf = [0u8; 512];
        while let Ok(n) = reader.read(&mut buf) {
            if n == 0 {
                break;
            }
            deframer.push(&buf[..n]);
            while let Some(event) = deframer.next_event() {
                if let rovlink_wire::DeframeEvent::Frame { frame, .. } = event
                    && tx.send(frame.into_inner().to_vec()).is_err()
                {
                    return;
                }
            }
        }
    });
    Intruder { port, heard }
}

impl Intruder {
    fn send(&mut self, frame: &[u8]) {
        self.port.write_all(frame).expect("the intruder transmits");
    }

    /// The next frame heard that `wanted` picks, failing after [`LIMIT`].
    fn record(&self, wanted: impl Fn(&[u8]) -> bool) -> Vec<u8> {
        let until = Instant::now() + LIMIT;
        loop {
            let left = until.saturating_duration_since(Instant::now());
            let frame = self.heard.recv_timeout(left).expect("a frame heard");
            if wanted(&frame) {
                return frame;
            }
        }
    }
}

/// A plain frame of wire.md from its JSON line.
fn pack(line: &str) -> Vec<u8> {
    let repr = rovlink_wire::json::parse_line(line).expect("a message");
    rovlink_wire::pack::frame(&repr, false).expect("a frame")
}

/// The same frame sealed under another key (a forger without ours).
fn forged(plain: &[u8], counter: u64) -> Vec<u8> {
    let key = rovlink_security::Key::from_bytes(&[0x5a; 16]).unwrap();
    let suite = rovlink_security::suite::Suite::new(&key);
    rovlink_security::sealed::seal(&suite, plain, counter, false).unwrap()
}

const GOTO_TO_1: [&str; 2] = [
    r#"{"type":"operator","src":0,"dst":1,"oid":0,"clo":false,"eisn":0,"ic":false,"rit":0,"order":{"type":"goto","x_cm":790,"y_cm":-490,"z_cm":300,"heading_deg":90}}"#,
    r#"{"type":"operator","src":0,"dst":1,"oid":1,"clo":false,"eisn":0,"ic":false,"rit":0,"order":{"type":"goto","x_cm":790,"y_cm":-490,"z_cm":300,"heading_deg":90}}"#,
];

const FAKE_STATUS: &str = r#"{"type":"rov","src":1,"dst":0,"ft":false,"lt":false,"st":0,"isn":0,"ci":false,"itsn":0,"rd":true,"eoid":0,"loc":false,"hh":false,"arm":true,"nav":"guided","x_cm":7777,"y_cm":7777,"z_cm":0,"roll_deg":0,"pitch_deg":0,"yaw_deg":0,"trunk":""}"#;

/// Sends `frames` in turn until `end` says `sign` (each refusal is said once per source).
fn inject_until(intruder: &mut Intruder, frames: &[Vec<u8>], end: &mut End, sign: &str) {
    let until = Instant::now() + LIMIT;
    for frame in frames.iter().cycle() {
        intruder.send(frame);
        if end.has_said(sign, Duration::from_millis(100)) {
            return;
        }
        assert!(Instant::now() < until, "{sign:?} never said: {}", end.said);
    }
}

fn refused(m: &serde_json::Value, src: &str, reason: &str) -> u64 {
    m["frames_refused"][src][reason].as_u64().unwrap_or(0)
}

#[test]
fn injected_forged_and_spoofed_frames_move_nothing_and_fool_no_one() {
    let dir = tempfile::tempdir().unwrap();
    let keys = key_file(dir.path());
    let keys = keys.to_str().unwrap();
    let waypoints = one_goto(dir.path());
    let telemetry = dir.path().join("op.jsonl");
    let (_link, ports) = medium();
    let mut rov = start(
        "rov",
        &ports[1],
        dir.path(),
        "rov",
        &["--key-file", keys, "--duration", "14"],
    );
    let mut op = start(
        "operator",
        &ports[0],
        dir.path(),
        "op",
        &[
            "--key-file",
            keys,
            "--duration",
            "12",
            "--waypoints",
            waypoints.to_str().unwrap(),
            "--telemetry",
            telemetry.to_str().unwrap(),
        ],
    );
    let mut intruder = intruder(&ports[2]);
    let gotos: Vec<Vec<u8>> = GOTO_TO_1.iter().map(|l| pack(l)).collect();
    let mut attack = gotos.clone();
    attack.extend(gotos.iter().map(|g| forged(g, 1)));
    inject_until(&mut intruder, &attack, &mut rov, "claiming to come from 0");
    let fake = pack(FAKE_STATUS);
    inject_until(
        &mut intruder,
        &[fake.clone(), forged(&fake, 1)],
        &mut op,
        "claiming to come from 1",
    );
    let (o, o_said) = op.finish();
    let (r, _) = rov.finish();
    let rov_refused = refused(&r, "0", "unsecured") + refused(&r, "0", "bad_tag");
    assert!(rov_refused >= 1, "{r:#}");
    let op_refused = refused(&o, "1", "unsecured") + refused(&o, "1", "bad_tag");
    assert!(op_refused >= 1, "{o:#}");
    // The operator's GoTo ran, once; none of the intruder's did.
    assert_eq!(r["orders_executed"], 1, "{r:#}");
    assert_eq!(o["orders_acknowledged"], 1, "{o:#}");
    // The operator showed none of the fake positions.
    let shown = std::fs::read_to_string(&telemetry).unwrap();
    assert!(shown.contains(r#""type":"rov""#), "{shown}");
    assert!(!shown.contains(r#""x_cm":7777"#), "{shown}");
    assert!(o_said.contains("frames authenticated"), "{o_said}");
    assert!(
        r["operator_to_rov"]["frames_delivered"].as_u64().unwrap() >= 5,
        "the operator's own frames still arrive: {r:#}"
    );
}

/// An operator frame to vehicle 1 carrying order type `ot`, sealed but not encrypted (the
/// intruder can see the type: the test keys do not encrypt).
fn is_order(frame: &[u8], ot: u8) -> bool {
    frame.len() > 6 && frame[1] == 0x01 && frame[3] & 0x20 != 0 && (frame[5] >> 2) & 0x0f == ot
}

#[test]
fn a_recorded_frame_replayed_is_refused_in_the_same_session_and_the_next() {
    let dir = tempfile::tempdir().unwrap();
    let keys = key_file(dir.path());
    let keys = keys.to_str().unwrap();
    let waypoints = one_goto(dir.path());
    let wp = waypoints.to_str().unwrap();
    let (_link, ports) = medium();
    let mut intruder = intruder(&ports[2]);
    let events = dir.path().join("rov1-events.csv");
    let mut rov = start(
        "rov",
        &ports[1],
        dir.path(),
        "rov1",
        &[
            "--key-file",
            keys,
            "--duration",
            "12",
            "--events",
            events.to_str().unwrap(),
        ],
    );
    let op = start(
        "operator",
        &ports[0],
        dir.path(),
        "op1",
        &["--key-file", keys, "--duration", "8", "--waypoints", wp],
    );
    let goto = intruder.record(|f| is_order(f, 1));
    inject_until(
        &mut intruder,
        std::slice::from_ref(&goto),
        &mut rov,
        "claiming to come from 0 (replay)",
    );
    let (o, _) = op.finish();
    let (r, _) = rov.finish();
    assert_eq!(r["orders_executed"], 1, "{r:#}");
    assert_eq!(o["orders_acknowledged"], 1, "{o:#}");
    assert!(refused(&r, "0", "replay") >= 1, "{r:#}");
    // --events shows each refused copy with its fate.
    let rows = std::fs::read_to_string(&events).unwrap();
    assert!(
        rows.lines().any(|l| l.ends_with(",refused:replay")),
        "{rows}"
    );

    // A later session with the same keys and counter files: the old GoTo is still a replay,
    // and the operator's new frames (counters above everything it sent before) are taken.
    let mut rov = start(
        "rov",
        &ports[1],
        dir.path(),
        "rov2",
        &["--key-file", keys, "--duration", "8"],
    );
    inject_until(
        &mut intruder,
        &[goto],
        &mut rov,
        "claiming to come from 0 (replay)",
    );
    let op = start(
        "operator",
        &ports[0],
        dir.path(),
        "op2",
        &["--key-file", keys, "--duration", "4"],
    );
    let (o, _) = op.finish();
    let (r, _) = rov.finish();
    assert_eq!(r["orders_executed"], 0, "{r:#}");
    assert!(refused(&r, "0", "replay") >= 1, "{r:#}");
    assert!(
        r["operator_to_rov"]["frames_delivered"].as_u64().unwrap() >= 3,
        "the operator's new frames are taken: {r:#}"
    );
    assert!(
        o["rov_to_operator"]["frames_delivered"].as_u64().unwrap() >= 3,
        "{o:#}"
    );
}

#[test]
fn frames_sent_after_the_operator_stopped_do_not_hold_the_link_up() {
    let dir = tempfile::tempdir().unwrap();
    let keys = key_file(dir.path());
    let keys = keys.to_str().unwrap();
    let (_link, ports) = medium();
    let mut intruder = intruder(&ports[2]);
    let mut rov = start(
        "rov",
        &ports[1],
        dir.path(),
        "rov",
        &["--key-file", keys, "--duration", "25", "--telemetry", "-"],
    );
    let op = start(
        "operator",
        &ports[0],
        dir.path(),
        "op",
        &["--key-file", keys, "--duration", "3"],
    );
    let neutral = intruder.record(|f| is_order(f, 0));
    let (o, _) = op.finish();
    assert!(
        o["operator_to_rov"]["frames_sent"].as_u64().unwrap() >= 3,
        "{o:#}"
    );
    // The operator is gone: a recorded heartbeat and plain neutral sticks, sent again and
    // again, must not keep the vehicle from counting the link as lost.
    let plain = pack(
        r#"{"type":"operator","src":0,"dst":1,"oid":0,"clo":false,"eisn":0,"ic":false,"rit":0,"order":{"type":"velocity","vx":0,"vy":0,"vz":0,"vyaw":0,"arm":false,"disarm":false,"nav":"manual"}}"#,
    );
    inject_until(
        &mut intruder,
        &[neutral, plain],
        &mut rov,
        r#""state":"lost""#,
    );
    let (r, _) = rov.finish();
    assert!(r["link_losses"].as_u64().unwrap() >= 1, "{r:#}");
    let refusals = refused(&r, "0", "replay") + refused(&r, "0", "unsecured");
    assert!(refusals >= 1, "{r:#}");
}

#[test]
fn a_secured_simulation_runs_the_same_session_with_longer_frames() {
    let dir = tempfile::tempdir().unwrap();
    let keys = key_file(dir.path());
    let run = |extra: &[&str]| {
        let metrics = dir.path().join("m.json");
        let events = dir.path().join("e.csv");
        let mut args = vec!["--sim", "--duration", "120", "--metrics"];
        args.push(metrics.to_str().unwrap());
        args.extend(["--events", events.to_str().unwrap()]);
        args.extend(extra);
        let out = crate::common::run(TDMA_RUN, &args, b"");
        assert_eq!(out.code, 0, "{}", out.stderr);
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&metrics).unwrap()).unwrap();
        (m, std::fs::read_to_string(&events).unwrap(), out.stderr)
    };
    let (plain, plain_events, _) = run(&[]);
    for extra in [
        &["--key-file", keys.to_str().unwrap()][..],
        &["--key-file", keys.to_str().unwrap(), "--encrypt"],
    ] {
        let (m, events, said) = run(extra);
        assert!(said.contains("frames authenticated"), "{said}");
        assert_eq!(m["orders_executed"], plain["orders_executed"], "{m:#}");
        assert!(m.get("frames_refused").is_none(), "{m:#}");
        assert!(m["images_completed"].as_u64().unwrap() >= 2, "{m:#}");
        // Every operator frame is 16 + 6 bytes; the plain session's are 16.
        assert!(events.contains(",22,"), "{events}");
        assert!(!events.contains("operator_to_rov,velocity,16,"));
        assert!(plain_events.contains("operator_to_rov,velocity,16,"));
        // The IPG counts the 12 bytes of a slot: fewer slots in the same time.
        let sent = |m: &serde_json::Value| m["operator_to_rov"]["frames_sent"].as_u64().unwrap();
        assert!(sent(&m) < sent(&plain), "{m:#} {plain:#}");
    }
}

#[test]
fn hostile_key_files_are_refused_with_one_line_and_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let private = |name: &str, text: &str| crate::common::private_file(dir.path(), name, text);
    let empty = private("empty", "");
    let short = private("short", &format!("* {}\n", &KEY[..30]));
    let comments = private("comments", "# no key\n");
    let open = private("open", &format!("* {KEY}\n"));
    std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o644)).unwrap();
    let foreign = private("foreign", &format!("* {KEY}\n"));
    let am_root = nix::unistd::geteuid().is_root();
    if am_root {
        nix::unistd::chown(&foreign, Some(nix::unistd::Uid::from_raw(65534)), None).unwrap();
    }
    let mut cases = vec![
        (empty, "0 bytes"),
        (short, "found 30 characters"),
        (comments, "no key in the file"),
        (open, "permissions 0644 are too open"),
        (dir.path().to_path_buf(), "found a directory"),
        (PathBuf::from("/dev/zero"), "found a device"),
        (dir.path().join("missing"), "cannot read"),
    ];
    if am_root {
        cases.push((foreign, "owned by uid 65534"));
    } else {
        eprintln!("not root: the file owned by another user is not tried");
    }
    let metrics = dir.path().join("m.json");
    for (path, expected) in cases {
        let out = crate::common::run(
            TDMA_RUN,
            &[
                "--sim",
                "--key-file",
                path.to_str().unwrap(),
                "--metrics",
                metrics.to_str().unwrap(),
            ],
            b"",
        );
        assert_eq!(out.code, 2, "{path:?}: {}", out.stderr);
        assert_eq!(out.stderr.lines().count(), 1, "{}", out.stderr);
        assert!(out.stderr.contains(expected), "{path:?}: {}", out.stderr);
        assert!(!out.stderr.contains(&KEY[..16]), "the key is never shown");
        assert!(!metrics.exists(), "nothing written");
    }
}

#[test]
fn with_encrypt_an_eavesdropper_reads_neither_positions_nor_images() {
    let dir = tempfile::tempdir().unwrap();
    let keys = key_file(dir.path());
    let keys = keys.to_str().unwrap();
    let (_link, ports) = medium();
    let intruder = intruder(&ports[2]);
    let secured = ["--key-file", keys, "--encrypt"];
    let rov = start(
        "rov",
        &ports[1],
        dir.path(),
        "rov",
        &[&secured[..], &["--duration", "8"]].concat(),
    );
    let op = start(
        "operator",
        &ports[0],
        dir.path(),
        "op",
        &[&secured[..], &["--duration", "5"]].concat(),
    );
    // Every frame the vehicle sends, as the eavesdropper hears it: encrypted, so no status and
    // no trunk parses, while the operator decodes them all.
    let mut heard = Vec::new();
    for _ in 0..5 {
        heard.push(intruder.record(|f| f.len() > 5 && f[1] == 0x10));
    }
    let (o, _) = op.finish();
    let (_, _) = rov.finish();
    for frame in &heard {
        assert_eq!(frame[3] & 0xa0, 0xa0, "secured and encrypted: {frame:02x?}");
        // The message inside the 6 bytes, read as a plain ROV message: the vehicle sits at
        // its start, (1, 0, 0) m, which a readable status would say.
        let inner = &frame[5..frame.len() - 6];
        let read = rovlink_wire::frame::build(1, 0, inner)
            .ok()
            .and_then(|plain| {
                let f = rovlink_wire::frame::Frame::new_checked(plain).ok()?;
                rovlink_wire::MessageRepr::parse(&f).ok()
            })
            .map(|r| rovlink_wire::json::to_line(&r))
            .unwrap_or_default();
        assert!(
            !read.contains(r#""x_cm":100,"y_cm":0,"z_cm":0"#),
            "a position read off the air: {read}"
        );
    }
    assert!(
        o["rov_to_operator"]["frames_delivered"].as_u64().unwrap() >= 5,
        "{o:#}"
    );
    // rcp-dump without the key sees only that they are secured; with it, the statuses.
    let capture = dir.path().join("heard.bin");
    std::fs::write(&capture, heard.concat()).unwrap();
    let blind = crate::common::run(env!("TOOL_EXE_rcp-dump"), &[capture.to_str().unwrap()], b"");
    assert!(
        blind.stdout_text().contains("unverified"),
        "{}",
        blind.stdout_text()
    );
    assert!(
        !blind.stdout_text().contains("ned="),
        "{}",
        blind.stdout_text()
    );
    let keyed = crate::common::run(
        env!("TOOL_EXE_rcp-dump"),
        &["--key-file", keys, capture.to_str().unwrap()],
        b"",
    );
    assert_eq!(keyed.code, 0, "{}", keyed.stderr);
    assert_eq!(
        keyed.stdout_text().matches(": ok]").count(),
        5,
        "{}",
        keyed.stdout_text()
    );
}
