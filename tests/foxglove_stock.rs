//! tdma-run's live view against the stock Foxglove client: `@foxglove/ws-protocol` 0.8.0 (what
//! Foxglove Studio 1.x and Lichtblick use) over `ws`, from npm (tests/foxglove/package.json,
//! installed by `.ci/run`), run by Node. One client offers the stock name
//! `foxglove.websocket.v1`, the next the SDK's `foxglove.sdk.v1`, each after the other to an
//! operator whose ROV stands still (its joystick script is all zeros): both are accepted, get
//! the pose within 2 s of subscribing (a still vehicle's pose is republished, and a new
//! subscriber gets the latest at once), messages on every channel the session feeds, and
//! publish a GoTo that the ROV acknowledges. A client that comes once the session has started
//! gets the session's start line first on `/session/log`.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use serde_json::Value;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");

/// A new control token file in `dir`, made by `tdma-run --new-foxglove-token`; its token.
fn token_file(dir: &Path) -> (String, String) {
    let path = dir.join("foxglove.token");
    let made = Command::new(TDMA_RUN)
        .arg("--new-foxglove-token")
        .arg(&path)
        .output()
        .unwrap();
    assert!(made.status.success(), "{made:?}");
    let said = String::from_utf8_lossy(&made.stderr);
    let token = std::fs::read_to_string(&path).unwrap().trim().to_string();
    assert_eq!(token.len(), 64);
    assert!(!said.contains(&token), "the token is never said: {said}");
    (path.to_str().unwrap().to_string(), token)
}

/// A session in `dir`: a ROV standing still (its joystick script all zeros) and an operator
/// of `operator_s` seconds holding a new control token, over link-sim; the operator serves its
/// live view, and its stderr is read aside once it is up.
struct Session {
    link: crate::common::Reaped,
    rov: std::process::Child,
    operator: std::process::Child,
    said: std::thread::JoinHandle<String>,
    address: String,
    token: String,
}

fn session(dir: &Path, operator_s: u32) -> Session {
    let path = |name: &str| dir.join(name).to_str().unwrap().to_string();
    std::fs::write(dir.join("still.csv"), "t_s,vx,vy,vz,vyaw\n0,0,0,0,0\n").unwrap();
    let (token_path, token) = token_file(dir);
    let (link, a, b) = crate::common::link_sim_pty(&crate::common::TEST_S100);
    let rov = Command::new(TDMA_RUN)
        .args(["--role", "rov", "--port", &b])
        .args(["--duration", &(operator_s + 12).to_string()])
        .args(["--image-size", "400", "--metrics", &path("rov.json")])
        .args(["--track", &path("track.csv")])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let address = format!("127.0.0.1:{}", crate::common::free_port());
    let mut operator = Command::new(TDMA_RUN)
        .args(["--role", "operator", "--port", &a, "--ipg", "150"])
        .args(["--duration", &operator_s.to_string()])
        .args(["--image-size", "400", "--script", &path("still.csv")])
        .args(["--foxglove", &address, "--metrics", &path("op.json")])
        .args(["--foxglove-token-file", &token_path])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The server is up, and the session started (its start line kept for late viewers), once
    // the operator says what runs.
    let said = crate::common::said_until(&mut operator, "operator: IPG", Duration::from_secs(20));
    Session {
        link,
        rov,
        operator,
        said,
        address,
        token,
    }
}

impl Session {
    /// Waits for both ends; what the operator said.
    fn finish(mut self) -> String {
        let operator = crate::common::wait_for_exit(&mut self.operator, Duration::from_secs(30));
        let rov = crate::common::wait_for_exit(&mut self.rov, Duration::from_secs(30));
        let _ = self.link.kill();
        let said = self.said.join().unwrap();
        assert!(operator.success(), "operator: {said}");
        assert!(rov.success(), "ROV: {rov:?}");
        assert!(
            !said.contains(&self.token),
            "the token is never said: {said}"
        );
        said
    }
}

#[test]
fn stock_and_sdk_clients_see_a_still_vehicle_at_once_and_drive_it() {
    let dir = tempfile::tempdir().unwrap();
    let session = session(dir.path(), 18);
    let url = format!("ws://{}/?token={}", session.address, session.token);
    let goto = |x_cm: i32| {
        format!(r#"{{"type":"goto","x_cm":{x_cm},"y_cm":-20,"z_cm":50,"heading_deg":90}}"#)
    };
    let seen = [
        ("foxglove.websocket.v1", goto(300)),
        ("foxglove.sdk.v1", goto(-300)),
    ]
    .map(|(subprotocol, order)| {
        let args = [
            "--url",
            &url,
            "--subprotocol",
            subprotocol,
            "--seconds",
            "6",
        ];
        let seen = crate::common::stock_client(&[&args[..], &["--publish-order", &order]].concat());
        (subprotocol, seen)
    });
    let rest = session.finish();
    assert!(!rest.contains("refused"), "{rest}");
    for (subprotocol, seen) in &seen {
        eprintln!("{subprotocol}: {seen}");
        assert_eq!(seen["subprotocol"], *subprotocol, "{seen}");
        let first_ms = seen["first_ms"]["/rov/pose"]
            .as_f64()
            .unwrap_or(f64::INFINITY);
        assert!(first_ms < 2000.0, "{subprotocol}: pose after {first_ms} ms");
        for topic in [
            "/rov/pose",
            "/tf",
            "/rov/velocity/actual",
            "/rov/velocity/commanded",
            "/link/frames",
            "/camera/preview",
            "/session/log",
        ] {
            assert!(
                seen["counts"][topic].as_u64().unwrap_or(0) > 0,
                "{subprotocol}: nothing on {topic}: {seen}"
            );
        }
        assert_eq!(seen["published"], 1);
    }
    // The second client came after images completed: it has the latest at once.
    let later = &seen[1].1;
    let image_ms = later["first_ms"]["/camera/image"].as_f64();
    assert!(image_ms.is_some_and(|ms| ms < 500.0), "{later}");
    let json = |name: &str| -> Value {
        serde_json::from_slice(&std::fs::read(dir.path().join(name)).unwrap()).unwrap()
    };
    let op = json("op.json");
    assert_eq!(op["orders_sent"], 2, "{op}");
    assert_eq!(op["orders_acknowledged"], 2, "{op}");
}

/// The loopback ports process `pid` listens on (`/proc/net/tcp`, `/proc/PID/fd`).
fn listening_ports(pid: u32) -> Vec<u16> {
    let inodes: Vec<String> = std::fs::read_dir(format!("/proc/{pid}/fd"))
        .unwrap()
        .filter_map(|fd| std::fs::read_link(fd.ok()?.path()).ok())
        .filter_map(|link| {
            let link = link.to_string_lossy().into_owned();
            Some(
                link.strip_prefix("socket:[")?
                    .strip_suffix(']')?
                    .to_string(),
            )
        })
        .collect();
    let table = std::fs::read_to_string("/proc/net/tcp").unwrap();
    table
        .lines()
        .skip(1)
        .filter_map(|line| {
            let fields: Vec<&str> = line.split_whitespace().collect();
            let (local, state, inode) = (fields.get(1)?, fields.get(3)?, fields.get(9)?);
            let (ip, port) = local.split_once(':')?;
            (*state == "0A" && ip == "0100007F" && inodes.iter().any(|i| i == inode))
                .then(|| u16::from_str_radix(port, 16).ok())
                .flatten()
        })
        .collect()
}

/// Runs the stock client expecting it to fail to connect; what it said.
fn stock_client_refused(args: &[&str]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let run = Command::new("node")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/foxglove/stock_client.mjs"
        ))
        .args(args)
        .arg("--out")
        .arg(dir.path().join("seen.json"))
        .stdin(Stdio::null())
        .output()
        .expect("node runs");
    assert_eq!(run.status.code(), Some(1), "{run:?}");
    String::from_utf8_lossy(&run.stderr).into_owned()
}

#[test]
fn without_the_token_a_client_views_but_cannot_move_the_vehicle() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let session = session(dir.path(), 15);
    let (address, token) = (session.address.clone(), session.token.clone());
    let url = format!("ws://{address}");
    let goto = r#"{"type":"goto","x_cm":700,"y_cm":-500,"z_cm":300,"heading_deg":90}"#;
    // A second client without the token: it views, and its GoTo is refused.
    let stranger =
        crate::common::stock_client(&["--url", &url, "--seconds", "3", "--publish-order", goto]);
    // Teleop Twists without the token, from the Python client.
    let twists = dir.path().join("twists.json");
    let python = Command::new("python3")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/foxglove/client.py"
        ))
        .args(["--url", &url, "--seconds", "3", "--publish-twist"])
        .arg("--out")
        .arg(&twists)
        .status()
        .unwrap();
    assert!(python.success());
    // It came after the session started: the start line was the first it had of the log.
    let seen: Value = serde_json::from_slice(&std::fs::read(&twists).unwrap()).unwrap();
    let start_line = seen["first"]["/session/log"]["message"].to_string();
    assert!(
        start_line.starts_with("\"operator: IPG 150.0 ms on "),
        "{seen:.500}"
    );
    // A page of another site, with the token even: refused at the handshake.
    let foreign = stock_client_refused(&[
        "--url",
        &format!("{url}/?token={token}"),
        "--origin",
        "https://evil.example",
        "--publish-order",
        goto,
    ]);
    assert!(foreign.contains("403"), "{foreign}");
    // A wrong token: refused.
    let first = if token.starts_with('0') { '1' } else { '0' };
    let wrong = stock_client_refused(&["--url", &format!("{url}/?token={first}{}", &token[1..])]);
    assert!(wrong.contains("403"), "{wrong}");
    // Round the gate: the SDK's own port gives nothing and takes nothing.
    let gate_port: u16 = address.rsplit_once(':').unwrap().1.parse().unwrap();
    let inner: Vec<u16> = listening_ports(session.operator.id())
        .into_iter()
        .filter(|&p| p != gate_port)
        .collect();
    assert_eq!(inner.len(), 1, "one port besides the gate's: {inner:?}");
    let direct = crate::common::stock_client(&[
        "--url",
        &format!("ws://127.0.0.1:{}/?token={token}", inner[0]),
        "--subprotocol",
        "foxglove.sdk.v1",
        "--seconds",
        "3",
        "--publish-order",
        goto,
    ]);
    let rest = session.finish();
    eprintln!("stranger: {stranger}\ndirect: {direct}\noperator said:\n{rest}");
    // The stranger viewed: the pose came.
    assert!(
        stranger["counts"]["/rov/pose"].as_u64().unwrap_or(0) > 0,
        "{stranger}"
    );
    let told = stranger["statuses"].to_string();
    assert!(told.contains("publishing refused"), "{stranger}");
    // The direct client was advertised the channels but got no message at all.
    assert!(
        !direct["advertised"].as_array().unwrap().is_empty(),
        "{direct}"
    );
    let got: u64 = (direct["counts"].as_object().unwrap().values())
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert_eq!(got, 0, "{direct}");
    // Said once per refused client; the foreign Origin and the wrong token once each.
    assert_eq!(rest.matches("publishing refused").count(), 3, "{rest}");
    assert!(
        rest.contains(r#"Origin "https://evil.example" is not allowed"#),
        "{rest}"
    );
    assert!(rest.contains("not the control token"), "{rest}");
    // No order went out, and the vehicle never moved.
    let op: Value = serde_json::from_slice(&std::fs::read(path("op.json")).unwrap()).unwrap();
    assert_eq!(op["orders_sent"], 0, "{op}");
    let track = std::fs::read_to_string(path("track.csv")).unwrap();
    let positions: Vec<Vec<&str>> = track
        .lines()
        .skip(1)
        .map(|row| row.split(',').skip(1).take(3).collect())
        .collect();
    assert!(positions.len() > 10, "{track}");
    assert!(
        positions.iter().all(|p| *p == positions[0]),
        "the vehicle moved: {track}"
    );
}
