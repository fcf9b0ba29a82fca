//! rcp-dump on a real serial device: a pseudo-terminal pair stands in for a modem's port.
//! The test writes frames (with garbage between them) into the master side, in small chunks with
//! pauses as a modem would deliver them, then closes it; rcp-dump must print every frame and end
//! on its own when the port closes, with exit code 1 (the README's "a port it was using
//! closed"); Ctrl-C is the normal end of a capture, exit 0.

use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Child, ChildStderr, Command, Stdio};
use std::time::Duration;

use crate::common::open_pty;

const DUMP: &str = env!("TOOL_EXE_rcp-dump");

/// Starts `rcp-dump --port PATH --format FORMAT` and waits until it says it is reading.
fn start_dump(path: &str, format: &str) -> (Child, BufReader<ChildStderr>) {
    let mut child = Command::new(DUMP)
        .args(["--port", path, "--baud", "9600", "--format", format])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("rcp-dump starts");
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut first = String::new();
    stderr.read_line(&mut first).unwrap();
    assert!(
        first.contains(&format!("reading {path} at 9600 baud")),
        "{first}"
    );
    (child, stderr)
}

#[test]
fn dump_reads_frames_from_a_pseudo_terminal() {
    let (mut master, path) = open_pty();
    let (mut child, mut stderr) = start_dump(&path, "ndjson");

    let frames = crate::common::vector_frames();
    let mut stream = vec![0x00, 0x13, 0x02, 0xff];
    for f in &frames {
        stream.extend(f);
        stream.extend([0x0d, 0x0a]); // the S100 driver's CR LF between frames: garbage here
    }
    for chunk in stream.chunks(45) {
        master.write_all(chunk).unwrap();
        master.flush().unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    // Wait until every frame was printed (rcp-dump flushes per read on a port), then hang up.
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut out = String::new();
    for _ in 0..frames.len() {
        stdout.read_line(&mut out).unwrap();
    }
    drop(master);
    stdout.read_to_string(&mut out).unwrap();
    let mut rest = String::new();
    stderr.read_to_string(&mut rest).unwrap();
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(1), "{rest}");
    assert!(
        rest.contains(&format!("rcp-dump: {path}: port closed")),
        "{rest}"
    );

    let lines: Vec<serde_json::Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), frames.len(), "{out}\n{rest}");
    for line in &lines {
        assert!(line["t_s"].as_f64().unwrap() >= 0.0);
    }
    let types: Vec<&str> = lines.iter().map(|l| l["type"].as_str().unwrap()).collect();
    assert_eq!(
        types,
        ["rov", "operator", "operator", "operator", "operator"]
    );
    assert!(rest.contains("5 frames ok (0 invalid messages)"), "{rest}");
}

#[test]
fn false_preamble_is_given_up_when_the_line_goes_idle() {
    let (mut master, path) = open_pty();
    let (mut child, mut stderr) = start_dump(&path, "ndjson");
    // 0x55 0x02 0xff announces a 255-byte payload; the real frame behind it is only 16 bytes.
    let frame = &crate::common::vector_frames()[1];
    // Timed from before the bytes are written: rcp-dump cannot have read them (and started
    // its idle time) earlier, however late this thread runs after the writes.
    let started = std::time::Instant::now();
    master.write_all(&[0x55, 0x02, 0xff]).unwrap();
    master.write_all(frame).unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    stdout.read_line(&mut line).unwrap();
    // The frame comes out once the line has been idle for --idle-ms (1000 ms by default).
    assert!(
        started.elapsed() >= Duration::from_millis(900),
        "{:?}",
        started.elapsed()
    );
    let v: serde_json::Value = serde_json::from_str(&line).unwrap();
    assert_eq!(v["offset"], 3);
    assert_eq!(v["type"], "operator");
    drop(master);
    let mut rest = String::new();
    stderr.read_to_string(&mut rest).unwrap();
    assert_eq!(child.wait().unwrap().code(), Some(1), "{rest}");
    assert!(rest.contains("offset 0: incomplete frame given up after the line went idle (needs 260 bytes, 19 there)"), "{rest}");
}

#[test]
fn dump_stops_cleanly_on_ctrl_c_with_its_summary() {
    use crate::common::hostile::signal_once;
    use nix::sys::signal::Signal;

    let (mut master, path) = open_pty();
    let (mut child, mut stderr) = start_dump(&path, "csv");
    master
        .write_all(&crate::common::vector_frames()[1])
        .unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut out = String::new();
    stdout.read_line(&mut out).unwrap();
    stdout.read_line(&mut out).unwrap();
    // Ctrl-C once rcp-dump catches it (it has printed the frame: it is well under way).
    signal_once(
        &mut child,
        Signal::SIGINT,
        &|| true,
        std::time::Duration::from_secs(30),
    );
    stdout.read_to_string(&mut out).unwrap();
    let mut rest = String::new();
    stderr.read_to_string(&mut rest).unwrap();
    assert_eq!(child.wait().unwrap().code(), Some(0), "{rest}");
    // The CSV is complete: header plus the one frame, and the summary was printed.
    assert_eq!(out.lines().count(), 2, "{out}");
    assert!(
        out.lines().nth(1).unwrap().contains(",operator,0,1,"),
        "{out}"
    );
    assert!(rest.contains("1 frames ok"), "{rest}");
    drop(master);
}

#[test]
fn pack_refuses_binary_to_a_terminal() {
    let (_master, path) = open_pty();
    let tty = std::fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .expect("open the terminal side");
    let out = Command::new(env!("TOOL_EXE_rcp-pack"))
        .arg(crate::common::testdata("wire-vectors.jsonl"))
        .stdout(tty)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("refusing to write binary data to a terminal"),
        "{stderr}"
    );
    // Hex is text: allowed on a terminal.
    let tty = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    let status = Command::new(env!("TOOL_EXE_rcp-pack"))
        .args([
            "--hex",
            crate::common::testdata("wire-vectors.jsonl")
                .to_str()
                .unwrap(),
        ])
        .stdout(tty)
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(0));
}
