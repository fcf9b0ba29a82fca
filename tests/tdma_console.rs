//! The live console of `tdma-run` as a user runs it: `--orders` (a file with times, standard
//! input, a FIFO written while the session runs), `--telemetry`, `--preview`, and the field
//! cameras `--camera DIR` and `--camera-cmd CMD`.

use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use crate::common::run;
use serde_json::Value;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");

/// Telemetry lines, each a JSON object with its type, time and end.
fn telemetry(text: &str) -> Vec<Value> {
    text.lines()
        .map(|line| {
            let value: Value = serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}"));
            assert!(value["type"].is_string(), "{line}");
            assert!(value["t_s"].as_f64().is_some_and(|t| t >= 0.0), "{line}");
            assert!(
                value["end"] == "operator" || value["end"] == "rov",
                "{line}"
            );
            value
        })
        .collect()
}

fn read_telemetry(path: &Path) -> Vec<Value> {
    telemetry(&std::fs::read_to_string(path).unwrap())
}

/// The lines of `kind` (and `state`, if given).
fn of<'a>(lines: &'a [Value], kind: &str, state: Option<&str>) -> Vec<&'a Value> {
    lines
        .iter()
        .filter(|l| l["type"] == kind && state.is_none_or(|s| l["state"] == s))
        .collect()
}

fn json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// A small RGB picture as PNG, `width` x `height`.
fn png(width: usize, height: usize) -> Vec<u8> {
    let data = (0..width * height * 3)
        .map(|k| (k * 7 % 256) as u8)
        .collect();
    rovlink_debt::picture::to_png(&rovlink_debt::Image {
        width,
        height,
        channels: 3,
        data,
    })
    .unwrap()
}

const GOTO: &str = r#"{"type":"goto","x_cm":300,"y_cm":0,"z_cm":50,"heading_deg":90"#;

fn orders_file(dir: &Path) -> PathBuf {
    let path = dir.join("orders.jsonl");
    let text = [
        r#"{"type":"velocity","vx":64,"vy":0,"vz":0,"vyaw":0,"arm":true,"disarm":false,"nav":"manual","t_s":1}"#.to_string(),
        r#"{"type":"velocity","vx":0,"vy":0,"vz":0,"vyaw":0,"arm":true,"disarm":false,"nav":"manual","t_s":4}"#.to_string(),
        format!("{GOTO},\"t_s\":10}}"),
        "this is not json".to_string(),
        r#"{"type":"hold_heading","heading_deg":45,"enable":true,"t_s":40}"#.to_string(),
    ]
    .join("\n");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_simulated_session_plays_an_orders_file_and_telemetry_shows_it() {
    let dir = tempfile::tempdir().unwrap();
    let orders = orders_file(dir.path());
    let (t, metrics) = (dir.path().join("t.jsonl"), dir.path().join("m.json"));
    let out = run(
        TDMA_RUN,
        &[
            "--orders",
            orders.to_str().unwrap(),
            "--telemetry",
            t.to_str().unwrap(),
            "--metrics",
            metrics.to_str().unwrap(),
            "--duration",
            "60",
            "--ber",
            "0",
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    // The bad line is reported on stderr, with its number, and skipped.
    assert!(
        out.stderr.contains("orders.jsonl: line 4: not valid JSON"),
        "{}",
        out.stderr
    );
    let lines = read_telemetry(&t);
    let times: Vec<f64> = lines.iter().map(|l| l["t_s"].as_f64().unwrap()).collect();
    assert!(
        times.windows(2).all(|w| w[0] <= w[1]),
        "lines out of time order"
    );
    assert_eq!(of(&lines, "warning", None).len(), 1);

    // Both high-level orders went out at their times and came back acknowledged, in order.
    let sent = of(&lines, "order", Some("sent"));
    let acked = of(&lines, "order", Some("acknowledged"));
    assert_eq!(sent.len(), 2, "{sent:?}");
    assert_eq!(acked.len(), 2, "{acked:?}");
    assert_eq!(sent[0]["order"]["type"], "goto");
    assert_eq!(sent[0]["order"]["x_cm"], 300);
    assert!(sent[0]["t_s"].as_f64().unwrap() >= 10.0);
    assert_eq!(sent[1]["order"]["type"], "hold_heading");
    assert!(sent[1]["t_s"].as_f64().unwrap() >= 40.0);
    for (s, a) in sent.iter().zip(&acked) {
        assert_eq!(s["index"], a["index"]);
        assert!(a["t_s"].as_f64() >= s["t_s"].as_f64());
    }
    let m = json(&metrics);
    assert_eq!(m["orders_sent"], 2, "{m}");
    assert_eq!(m["orders_acknowledged"], 2, "{m}");
    assert_eq!(m["orders_executed_twice"], 0, "{m}");

    // Statuses: wire.md's rov JSON without the trunk. Before the orders the vehicle was at
    // rest, disarmed; half a stick forward for 3 s moved it north, the GoTo took it to 3 m
    // north, 0.5 m deep, facing east (within the 0.25 m it counts as arrived), and HoldHeading
    // turned it to 45 degrees.
    let statuses = of(&lines, "rov", None);
    assert!(statuses.len() > 50, "{}", statuses.len());
    assert!(
        statuses
            .iter()
            .all(|s| s.get("trunk").is_none() && s["x_cm"].is_i64())
    );
    let first = statuses[0];
    assert_eq!(first["arm"], false, "{first}");
    let moved = statuses
        .iter()
        .find(|s| s["t_s"].as_f64() < Some(10.0) && s["x_cm"].as_i64() > Some(20));
    assert!(moved.is_some(), "the joystick did not move the vehicle");
    let last = statuses.last().unwrap();
    for (field, want) in [("x_cm", 300), ("y_cm", 0), ("z_cm", 50)] {
        assert!(
            (last[field].as_i64().unwrap() - want).abs() <= 25,
            "{field}: {last}"
        );
    }
    assert!(
        (last["yaw_deg"].as_i64().unwrap() - 45).abs() <= 5,
        "{last}"
    );
    let at_goal = statuses
        .iter()
        .find(|s| s["t_s"].as_f64() > Some(30.0))
        .unwrap();
    assert!(
        (at_goal["yaw_deg"].as_i64().unwrap() - 90).abs() <= 5,
        "{at_goal}"
    );
    assert_eq!(last["arm"], true, "{last}");
    assert_eq!(last["hh"], true, "{last}");

    // Images: progress trunk by trunk, then complete, as many as the metrics say.
    let progress = of(&lines, "image", Some("progress"));
    let complete = of(&lines, "image", Some("complete"));
    assert!(progress.len() > 20, "{}", progress.len());
    assert_eq!(
        complete.len() as u64,
        m["images_completed"].as_u64().unwrap()
    );
    assert!(!complete.is_empty());
    assert!(
        complete
            .iter()
            .all(|c| c["file"].is_null() && c["of"].as_u64() > Some(0))
    );
    assert!(progress.iter().all(|p| p["file"].is_null()));
}

#[test]
fn orders_come_from_standard_input_and_telemetry_goes_to_standard_output() {
    let text = format!(
        "{GOTO},\"t_s\":2}}\n\n{{\"type\":\"cancel\",\"t_s\":3}}\n[1]\n{{\"type\":\"goto\"}}\n"
    );
    let out = run(
        TDMA_RUN,
        &[
            "--orders",
            "-",
            "--telemetry",
            "-",
            "--duration",
            "20",
            "--ber",
            "0",
        ],
        text.as_bytes(),
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(
        out.stderr
            .contains("<stdin>: line 4: field (line): expected a JSON object, found [1]"),
        "{}",
        out.stderr
    );
    assert!(
        out.stderr.contains("<stdin>: line 5: field x_cm: missing"),
        "{}",
        out.stderr
    );
    let lines = telemetry(&out.stdout_text());
    assert_eq!(of(&lines, "order", Some("acknowledged")).len(), 1);
    // The ROV executed the GoTo, then cancelled it on the operator's request (LOC).
    assert_eq!(of(&lines, "order", Some("executed")).len(), 1);
    let cancelled = of(&lines, "order", Some("cancelled"));
    assert!(
        cancelled.iter().any(|c| c["end"] == "operator"),
        "{cancelled:?}"
    );
    assert!(cancelled.iter().any(|c| c["end"] == "rov"), "{cancelled:?}");
}

#[test]
fn a_missing_orders_file_or_camera_directory_is_an_error_before_the_session() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("none");
    let m = missing.to_str().unwrap();
    for args in [["--orders", m], ["--camera", m]] {
        let out = run(TDMA_RUN, &args, b"");
        assert_eq!(out.code, 2, "{args:?}: {}", out.stderr);
        assert_eq!(out.stderr.lines().count(), 1, "{}", out.stderr);
        assert!(out.stderr.contains(m), "{}", out.stderr);
    }
    let out = run(TDMA_RUN, &["--camera-cmd", " "], b"");
    assert_eq!(out.code, 2, "{}", out.stderr);
    assert!(
        out.stderr.contains("camera command: empty"),
        "{}",
        out.stderr
    );
}

#[test]
fn preview_leaves_partial_then_whole_pictures() {
    let dir = tempfile::tempdir().unwrap();
    let picture = dir.path().join("cam.png");
    std::fs::write(&picture, png(96, 64)).unwrap();
    let session = |name: &str, preview: bool| {
        let (rx, t) = (
            dir.path().join(name),
            dir.path().join(format!("{name}.jsonl")),
        );
        let mut args = vec![
            "--images".to_string(),
            picture.display().to_string(),
            "--image-size".into(),
            "400".into(),
            "--duration".into(),
            "25".into(),
            "--ber".into(),
            "0".into(),
            "--images-out".into(),
            rx.display().to_string(),
            "--telemetry".into(),
            t.display().to_string(),
        ];
        if preview {
            args.push("--preview".into());
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = run(TDMA_RUN, &args, b"");
        assert_eq!(out.code, 0, "{}", out.stderr);
        (rx, read_telemetry(&t))
    };
    let (plain, _) = session("plain", false);
    let (rx, lines) = session("preview", true);
    let complete = of(&lines, "image", Some("complete"));
    assert!(complete.len() >= 2, "{}", complete.len());
    // Each image was previewed before it completed, into the file it completed as.
    for c in &complete {
        let file = c["file"].as_str().unwrap();
        let before: Vec<_> = lines
            .iter()
            .filter(|l| l["state"] == "progress" && l["file"] == file)
            .collect();
        assert!(before.len() >= 5, "{file}: {} previews", before.len());
        assert!(
            before
                .iter()
                .all(|p| p["t_s"].as_f64() <= c["t_s"].as_f64())
        );
    }
    // The completed pictures are exactly those of a session without previews.
    for c in &complete {
        let file = PathBuf::from(c["file"].as_str().unwrap());
        let name = file.file_name().unwrap();
        assert_eq!(
            std::fs::read(&file).unwrap(),
            std::fs::read(plain.join(name)).unwrap(),
            "{name:?}"
        );
    }
    // The image in flight when the session ended stays as its last preview.
    let files = std::fs::read_dir(&rx).unwrap().count();
    let last = lines
        .iter()
        .rev()
        .find(|l| l["type"] == "image" && l["end"] == "operator")
        .unwrap();
    if last["state"] == "progress" {
        assert_eq!(files, complete.len() + 1);
        let partial =
            rovlink_debt::picture::open(Path::new(last["file"].as_str().unwrap())).unwrap();
        assert_eq!((partial.width, partial.height), (96, 64));
    } else {
        assert_eq!(files, complete.len());
    }
}

#[test]
fn the_simulated_rov_takes_its_pictures_from_a_directory_or_a_command() {
    let dir = tempfile::tempdir().unwrap();
    let cam = dir.path().join("cam");
    std::fs::create_dir(&cam).unwrap();
    std::fs::write(cam.join("frame-1.png"), png(40, 30)).unwrap();
    let cmd_picture = dir.path().join("shot.png");
    std::fs::write(&cmd_picture, png(56, 42)).unwrap();
    let cmd = format!("cat '{}'", cmd_picture.display());
    for (flag, value, size) in [
        ("--camera", cam.display().to_string(), (40, 30)),
        ("--camera-cmd", cmd, (56, 42)),
    ] {
        let rx = dir.path().join(format!("rx{}", &flag[2..]));
        let t = dir.path().join(format!("{}.jsonl", &flag[2..]));
        let out = run(
            TDMA_RUN,
            &[
                flag,
                &value,
                "--image-size",
                "400",
                "--duration",
                "20",
                "--ber",
                "0",
                "--images-out",
                rx.to_str().unwrap(),
                "--telemetry",
                t.to_str().unwrap(),
            ],
            b"",
        );
        assert_eq!(out.code, 0, "{flag}: {}", out.stderr);
        let lines = read_telemetry(&t);
        let complete = of(&lines, "image", Some("complete"));
        assert!(!complete.is_empty(), "{flag}: no image");
        for c in complete {
            let image =
                rovlink_debt::picture::open(Path::new(c["file"].as_str().unwrap())).unwrap();
            assert_eq!((image.width, image.height), size, "{flag}");
        }
        // In simulation the capture waits for the camera: it never fails.
        let failures = of(&lines, "camera", Some("failed"));
        assert!(failures.is_empty(), "{flag}: {failures:?}");
    }
}

/// How long a process may take to show the sign a test waits for, or to end when it should:
/// only a hang takes this long, however loaded the machine.
const LIMIT: Duration = Duration::from_secs(30);

/// A stream's lines, read in a thread as they come, each with the instant it came.
fn lines_as_they_come(
    stream: impl std::io::Read + Send + 'static,
) -> (Receiver<(Instant, String)>, std::thread::JoinHandle<()>) {
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        for line in std::io::BufReader::new(stream).lines() {
            let Ok(line) = line else { return };
            if tx.send((Instant::now(), line)).is_err() {
                return;
            }
        }
    });
    (rx, reader)
}

/// Takes lines from `lines` into `taken` until `sign` holds for one (`what` it shows); fails if
/// the stream ends first (the process ended) or LIMIT passes.
fn wait_for_line(
    lines: &Receiver<(Instant, String)>,
    taken: &mut Vec<(Instant, String)>,
    what: &str,
    sign: impl Fn(&str) -> bool,
) {
    let deadline = Instant::now() + LIMIT;
    loop {
        match lines.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
            Ok((at, line)) => {
                let found = sign(&line);
                taken.push((at, line));
                if found {
                    return;
                }
            }
            Err(e) => {
                let said: Vec<&str> = taken.iter().map(|(_, l)| l.as_str()).collect();
                let why = match e {
                    RecvTimeoutError::Timeout => "not within the limit",
                    RecvTimeoutError::Disconnected => "the stream ended",
                };
                panic!("no {what}: {why}: {said:#?}");
            }
        }
    }
}

/// True if `line` is a JSON object that `holds` says yes to.
fn json_line(line: &str, holds: impl Fn(&Value) -> bool) -> bool {
    serde_json::from_str::<Value>(line).is_ok_and(|v| holds(&v))
}

#[test]
fn real_time_orders_written_into_a_fifo_while_the_operator_runs_are_acknowledged() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let fifo = dir.path().join("orders");
    // As the docs make it: mkfifo -m 600 (the user's own; nobody else may write orders).
    let private = nix::sys::stat::Mode::S_IRUSR | nix::sys::stat::Mode::S_IWUSR;
    nix::unistd::mkfifo(&fifo, private).unwrap();
    let shot = dir.path().join("shot.png");
    std::fs::write(&shot, png(48, 36)).unwrap();
    let (mut link, a, b) = crate::common::link_sim_pty(&crate::common::TEST_S100);
    let cmd = format!("cat '{}'", shot.display());
    let mut rov = Command::new(TDMA_RUN)
        .args(["--role", "rov", "--port", &b, "--duration", "14"])
        .args(["--image-size", "400", "--camera-cmd", &cmd])
        .args([
            "--metrics",
            &path("rov.json"),
            "--telemetry",
            &path("rov.jsonl"),
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The operator starts once the ROV listens on its port (it says so), not after a guess.
    let (rov_stderr, rov_reader) = lines_as_they_come(rov.stderr.take().unwrap());
    let mut rov_said = Vec::new();
    wait_for_line(&rov_stderr, &mut rov_said, "ROV start line", |l| {
        l.contains("ROV: answering every slot")
    });
    let mut op = Command::new(TDMA_RUN)
        .args([
            "--role",
            "operator",
            "--port",
            &a,
            "--ipg",
            "150",
            "--duration",
            "10",
        ])
        .args(["--image-size", "400", "--orders", fifo.to_str().unwrap()])
        .args(["--telemetry", "-", "--images-out", &path("rx"), "--preview"])
        .args(["--metrics", &path("op.json")])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The operator's telemetry, read live from its pipe.
    let (telemetry_lines, reader) = lines_as_they_come(op.stdout.take().unwrap());
    let mut timed = Vec::new();
    // Orders while it runs: once the first status of the (disarmed) vehicle is in, two
    // writers one after the other; once the GoTo is acknowledged and the vehicle on its way,
    // one more, held open. Each waits for its sign, not for a guessed time.
    wait_for_line(&telemetry_lines, &mut timed, "status", |l| {
        json_line(l, |v| v["type"] == "rov")
    });
    for line in [
        r#"{"type":"velocity","vx":64,"vy":0,"vz":0,"vyaw":0,"arm":true,"disarm":false,"nav":"manual"}"#.to_string(),
        format!("{GOTO}}}"),
    ] {
        let mut w = std::fs::OpenOptions::new().write(true).open(&fifo).unwrap();
        writeln!(w, "{line}").unwrap();
    }
    // Telemetry comes as it happens: the GoTo's acknowledgement is read while the operator
    // runs (the order written next is acknowledged by it too), not when it ends.
    wait_for_line(&telemetry_lines, &mut timed, "GoTo acknowledgement", |l| {
        json_line(l, |v| {
            v["type"] == "order" && v["state"] == "acknowledged" && v["order"]["type"] == "goto"
        })
    });
    wait_for_line(&telemetry_lines, &mut timed, "vehicle on its way", |l| {
        json_line(l, |v| v["type"] == "rov" && v["x_cm"].as_i64() > Some(50))
    });
    let mut w = std::fs::OpenOptions::new().write(true).open(&fifo).unwrap();
    writeln!(w, "not an order").unwrap();
    writeln!(
        w,
        r#"{{"type":"hold_heading","heading_deg":45,"enable":true}}"#
    )
    .unwrap();
    let status = crate::common::wait_for_exit(&mut op, LIMIT);
    drop(w);
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut op.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(status.success(), "operator: {stderr}");
    let rov_status = crate::common::wait_for_exit(&mut rov, LIMIT);
    let _ = link.kill();
    let _ = link.wait();
    rov_reader.join().unwrap();
    rov_said.extend(rov_stderr.iter());
    let rov_text: Vec<&str> = rov_said.iter().map(|(_, l)| l.as_str()).collect();
    assert!(
        rov_status.success(),
        "ROV end: {rov_status:?}: {rov_text:#?}"
    );
    assert!(stderr.contains(": line 3: not valid JSON"), "{stderr}");

    reader.join().unwrap();
    timed.extend(telemetry_lines.iter());
    let text: String = timed.iter().map(|(_, l)| format!("{l}\n")).collect();
    let lines = telemetry(&text);
    let acked = of(&lines, "order", Some("acknowledged"));
    let kinds: Vec<&str> = acked
        .iter()
        .map(|a| a["order"]["type"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["goto", "hold_heading"], "{text}");
    // (Lines arrived as they happened: the HoldHeading was written only once the GoTo's
    // acknowledgement had been read, and the operator acknowledged it before it ended.)
    // The vehicle armed and moved on the orders (the operator's statuses say so).
    let statuses = of(&lines, "rov", None);
    assert_eq!(statuses.first().unwrap()["arm"], false);
    let last = statuses.last().unwrap();
    assert_eq!(last["arm"], true, "{last}");
    assert!(last["x_cm"].as_i64().unwrap() > 50, "{last}");
    // Pictures from the ROV's camera command, whole and previewed.
    let complete = of(&lines, "image", Some("complete"));
    assert!(!complete.is_empty(), "{text}");
    let image =
        rovlink_debt::picture::open(Path::new(complete[0]["file"].as_str().unwrap())).unwrap();
    assert_eq!((image.width, image.height), (48, 36));
    assert!(
        of(&lines, "image", Some("progress"))
            .iter()
            .any(|p| p["file"].is_string())
    );
    let r = json(&dir.path().join("rov.json"));
    assert_eq!(r["orders_executed"], 2, "{r}");
    assert_eq!(r["orders_executed_twice"], 0, "{r}");
    let rov_lines = read_telemetry(&dir.path().join("rov.jsonl"));
    assert_eq!(of(&rov_lines, "order", Some("executed")).len(), 2);
    assert!(rov_lines.iter().all(|l| l["end"] == "rov"));
}

/// Someone else's orders FIFO (issue 45): one that any user may write (0666), or one owned by
/// another user, with a GoTo already written into it by that user. `tdma-run` refuses it with
/// one line and exit 2, in simulation and as the real-time operator, before a byte is read: no
/// session runs (no metrics), so no vehicle moves, and the GoTo is still in the FIFO.
#[test]
fn someone_elses_orders_fifo_is_refused_and_its_goto_never_read() {
    use std::io::Read;
    use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("orders");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    // The other user's GoTo, waiting in the FIFO (held open for reading and writing, so it
    // stays there and the FIFO never ends).
    let mut held = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(nix::fcntl::OFlag::O_NONBLOCK.bits())
        .open(&fifo)
        .unwrap();
    let goto = format!("{GOTO}}}\n");
    held.write_all(goto.as_bytes()).unwrap();
    let (_master, port) = crate::common::open_pty();
    let fifo_path = fifo.to_str().unwrap();
    let metrics = dir.path().join("m.json");
    let metrics_path = metrics.to_str().unwrap();
    let sim = ["--duration", "20", "--ber", "0"];
    let real_time = ["--role", "operator", "--port", &port, "--duration", "20"];
    let mut cases = vec![(0o666, None, "permissions 0666 are too open")];
    if nix::unistd::geteuid().is_root() {
        cases.push((0o600, Some(65534), "owned by uid 65534, not by this user"));
    } else {
        eprintln!("skipped the FIFO owned by another user: making one needs root");
    }
    for (mode, owner, said) in cases {
        std::fs::set_permissions(&fifo, std::fs::Permissions::from_mode(mode)).unwrap();
        std::os::unix::fs::chown(&fifo, owner, owner).unwrap();
        for session in [&sim[..], &real_time[..]] {
            let mut child = crate::common::Reaped(
                Command::new(TDMA_RUN)
                    .args(session)
                    .args(["--orders", fifo_path, "--metrics", metrics_path])
                    .stdin(Stdio::null())
                    .stdout(Stdio::null())
                    .stderr(Stdio::piped())
                    .spawn()
                    .unwrap(),
            );
            let status = crate::common::wait_for_exit(&mut child, LIMIT);
            let stderr = std::io::read_to_string(child.stderr.take().unwrap()).unwrap();
            assert_eq!(status.code(), Some(2), "{session:?}: {stderr}");
            assert_eq!(stderr.lines().count(), 1, "{session:?}: {stderr}");
            assert!(
                stderr.contains(fifo_path) && stderr.contains(said),
                "{session:?}: {stderr}"
            );
            assert!(!metrics.exists(), "{session:?}: a session ran");
        }
    }
    // Not a byte was read: the GoTo is still in the FIFO, whole.
    let mut left = vec![0u8; 4096];
    let n = held.read(&mut left).unwrap();
    assert_eq!(&left[..n], goto.as_bytes());
}
