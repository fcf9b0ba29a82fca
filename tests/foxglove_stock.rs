//! tdma-run's live view against the stock Foxglove client: `@foxglove/ws-protocol` 0.8.0 (what
//! Foxglove Studio 1.x and Lichtblick use) over `ws`, from npm (tests/foxglove/package.json,
//! installed by `.ci/run`), run by Node. One client offers the stock name
//! `foxglove.websocket.v1`, the next the SDK's `foxglove.sdk.v1`, each after the other to an
//! operator whose ROV stands still (its joystick script is all zeros): both are accepted, get
//! the pose within 2 s of subscribing (a still vehicle's pose is republished, and a new
//! subscriber gets the latest at once), messages on every channel the session feeds, and
//! publish a GoTo that the ROV acknowledges.

use std::process::{Command, Stdio};
use std::time::Duration;

use serde_json::Value;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");
#[test]
fn stock_and_sdk_clients_see_a_still_vehicle_at_once_and_drive_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    std::fs::write(
        dir.path().join("still.csv"),
        "t_s,vx,vy,vz,vyaw\n0,0,0,0,0\n",
    )
    .unwrap();
    let (mut link, a, b) = crate::common::link_sim_pty(&crate::common::TEST_S100);
    let mut rov = Command::new(TDMA_RUN)
        .args(["--role", "rov", "--port", &b, "--duration", "30"])
        .args(["--image-size", "400", "--metrics", &path("rov.json")])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let address = format!("127.0.0.1:{}", crate::common::free_port());
    let mut operator = Command::new(TDMA_RUN)
        .args(["--role", "operator", "--port", &a, "--ipg", "150"])
        .args(["--duration", "18", "--image-size", "400", "--script"])
        .arg(path("still.csv"))
        .args(["--foxglove", &address, "--metrics", &path("op.json")])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The server is up once the operator says where.
    let mut stderr = std::io::BufReader::new(operator.stderr.take().unwrap());
    let mut line = String::new();
    std::io::BufRead::read_line(&mut stderr, &mut line).unwrap();
    assert!(line.contains("Foxglove: ws://"), "{line}");
    let url = format!("ws://{address}");
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
    let operator_status = crate::common::wait_for_exit(&mut operator, Duration::from_secs(30));
    let rov_status = crate::common::wait_for_exit(&mut rov, Duration::from_secs(30));
    let _ = link.kill();
    let _ = link.wait();
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut stderr, &mut rest).unwrap();
    assert!(operator_status.success(), "operator: {rest}");
    assert!(rov_status.success(), "ROV: {rov_status:?}");
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
