//! A multi-vehicle network in real time: one `tdma-run` process per node, `--routes` the same
//! file for all, `link-sim` standing in for the modems (docs/tdma-network.md, "Real time: one
//! process per node").

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::thread::JoinHandle;
use std::time::Duration;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");

/// The two media of the mixed test: an "acoustic" hop from the operator to vehicle 1 (S100
/// as a stand-in, as the link-sim below runs it) and RF between the vehicles. Slots are set:
/// the link-sims run faster than the file's S100 model says.
const MIXED: &str = r#"{
  "nodes":[{"address":0,"role":"operator","position":[0,0,0]},
           {"address":1,"role":"rov","start":[0,0,200],"slot_s":0.3},
           {"address":2,"role":"rov","start":[3,0,200],"slot_s":0.5,
            "waypoints":[[2,4,0,200,90]]}],
  "media":[{"name":"acoustic","model":"s100","nodes":[0,1]},
           {"name":"rf","model":"s100","nodes":[1,2]}],
  "routes":{"0":{"2":1},"2":{"0":1}}}"#;

/// The issue's three-node network: S100 (range 5 m), the far vehicle 7 m from the operator
/// and 4 m from the relay, its GoTo at 3 s; slots automatic.
const THREE: &str = r#"{"duration_s":600,"seed":1,
  "nodes":[{"address":0,"role":"operator","position":[0,0,0]},
           {"address":1,"role":"rov","start":[3,0,1]},
           {"address":2,"role":"rov","start":[7,0,1],"waypoints":[[3,7.5,1,1,90]]}],
  "media":[{"name":"rf","model":"s100","nodes":[0,1,2]}],
  "routes":{"0":{"2":1},"2":{"0":1}}}"#;

/// Starts `link-sim --pty 3` with the three nodes' positions; its three ports.
fn shared_medium() -> (crate::common::Reaped, Vec<String>) {
    crate::common::link_sim_ptys(
        3,
        &[
            "--model",
            "s100",
            "--position",
            "0,0,0",
            "--position",
            "3,0,1",
            "--position",
            "7,0,1",
        ],
    )
}

/// Runs the three nodes of `text` over one shared medium: the operator for `duration_s`;
/// each node's metrics and events.
fn three_nodes(text: &str, duration_s: f64, extra: &[&str]) -> Vec<(serde_json::Value, String)> {
    let dir = tempfile::tempdir().unwrap();
    let routes = dir.path().join("three.json");
    std::fs::write(&routes, text).unwrap();
    let (mut link, ports) = shared_medium();
    let vehicles_s = duration_s + 2.0;
    let far = node(
        dir.path(),
        &routes,
        "rov",
        2,
        &[&ports[2]],
        vehicles_s,
        extra,
    );
    let relay = node(
        dir.path(),
        &routes,
        "rov",
        1,
        &[&ports[1]],
        vehicles_s,
        extra,
    );
    far.wait_started();
    relay.wait_started();
    let operator = node(
        dir.path(),
        &routes,
        "operator",
        0,
        &[&ports[0]],
        duration_s,
        extra,
    );
    let limit = Duration::from_secs_f64(duration_s + 10.0);
    let runs = vec![
        operator.finish(limit),
        relay.finish(limit),
        far.finish(limit),
    ];
    end(&mut link);
    runs
}

#[test]
fn three_nodes_on_one_medium_reach_the_far_vehicle_only_through_the_relay() {
    let direct = THREE.replace(r#""routes":{"0":{"2":1},"2":{"0":1}}"#, r#""routes":{}"#);
    let m = three_nodes(&direct, 4.0, &[]);
    let (o, r, f) = (&m[0].0, &m[1].0, &m[2].0);
    assert_eq!(
        count(&f["vehicles"]["2"]["operator_to_rov"]["frames_delivered"]),
        0,
        "{f:#}"
    );
    assert_eq!(
        count(&o["vehicles"]["2"]["rov_to_operator"]["frames_delivered"]),
        0,
        "{o:#}"
    );
    assert_eq!(count(&r["nodes"]["1"]["frames_forwarded"]), 0, "{r:#}");
    assert!(count(&r["nodes"]["1"]["off_path_dropped"]) > 0, "{r:#}");
    assert!(
        count(&o["vehicles"]["1"]["rov_to_operator"]["frames_delivered"]) > 0,
        "{o:#}"
    );

    let m = three_nodes(THREE, 16.0, &[]);
    let ((o, o_events), (r, _), (f, f_events)) = (&m[0], &m[1], &m[2]);
    for v in ["1", "2"] {
        let heard = count(&o["vehicles"][v]["rov_to_operator"]["frames_delivered"]);
        assert!(heard >= 5, "vehicle {v}: {heard} answers: {o:#}");
        let trunks = o_events
            .lines()
            .filter(|l| {
                l.starts_with("rov_to_operator,image_trunk,")
                    && l.contains(&format!(",received,rf,{v},0,"))
            })
            .count();
        assert!(trunks >= 5, "vehicle {v}: {trunks} trunks");
    }
    // The relay forwarded both ways; the far vehicle heard the operator only through it
    // (7 m is out of range) and ran its GoTo once.
    assert!(count(&r["nodes"]["1"]["frames_forwarded"]) >= 10, "{r:#}");
    assert!(
        count(&f["vehicles"]["2"]["operator_to_rov"]["frames_delivered"]) >= 5,
        "{f:#}"
    );
    assert_eq!(f["vehicles"]["2"]["orders_executed"], 1, "{f:#}");
    assert_eq!(f["vehicles"]["2"]["orders_executed_twice"], 0, "{f:#}");
    // Copies the far vehicle overhears of its own answers, relayed, are dropped as its own.
    assert!(count(&f["nodes"]["2"]["own_dropped"]) >= 5, "{f:#}");
    assert!(
        f_events
            .lines()
            .any(|l| l.ends_with(",received,rf,0,2,,2,delivered")),
        "{f_events}"
    );
    let rtt = |v: &str| o["vehicles"][v]["round_trip_ms"].as_f64().unwrap();
    assert!(rtt("2") > rtt("1") + 100.0, "{} vs {}", rtt("2"), rtt("1"));
}

/// One node's process: `tdma-run --role ROLE --routes FILE ...`, its outputs in `dir`.
struct NodeRun {
    child: Child,
    metrics: PathBuf,
    events: PathBuf,
    /// Told once the node says it runs (its line "...: cycle ... ms (slots: ...) on PORT").
    started: Receiver<()>,
    /// Its standard error, read aside as it comes.
    said: JoinHandle<String>,
}

fn node(
    dir: &Path,
    routes: &Path,
    role: &str,
    address: u8,
    ports: &[&str],
    duration_s: f64,
    extra: &[&str],
) -> NodeRun {
    let name = |what: &str| dir.join(format!("node{address}-{what}"));
    let (metrics, events) = (name("metrics.json"), name("events.csv"));
    let mut command = Command::new(TDMA_RUN);
    command
        .args(["--role", role, "--routes"])
        .arg(routes)
        .args(["--duration", &duration_s.to_string(), "--image-size", "200"])
        .arg("--metrics")
        .arg(&metrics)
        .arg("--events")
        .arg(&events);
    if role == "rov" {
        command.args(["--address", &address.to_string()]);
    } else {
        command.arg("--images-out").arg(dir.join("images"));
    }
    for (k, port) in ports.iter().enumerate() {
        command
            .arg(if k == 0 { "--port" } else { "--port2" })
            .arg(port);
    }
    command.args(extra);
    let mut child = command
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("tdma-run starts");
    let mut stderr = std::io::BufReader::new(child.stderr.take().expect("stderr"));
    let (tx, started) = std::sync::mpsc::channel();
    let said = std::thread::spawn(move || {
        use std::io::BufRead;
        let (mut said, mut line) = (String::new(), String::new());
        while stderr.read_line(&mut line).is_ok_and(|n| n > 0) {
            if line.contains(": cycle ") {
                let _ = tx.send(());
            }
            said.push_str(&line);
            line.clear();
        }
        said
    });
    NodeRun {
        child,
        metrics,
        events,
        started,
        said,
    }
}

impl NodeRun {
    /// Waits until the node says it runs (its ports open, its session under way): the nodes
    /// that must listen first do, whatever the machine's speed. Fails if it ends first or
    /// says nothing within 30 s.
    fn wait_started(&self) {
        assert!(
            self.started.recv_timeout(Duration::from_secs(30)).is_ok(),
            "the node did not start"
        );
    }

    /// Waits for the node to end (well within `limit`) and returns its metrics.
    fn finish(mut self, limit: Duration) -> (serde_json::Value, String) {
        let status = crate::common::wait_for_exit(&mut self.child, limit);
        let stderr = self.said.join().unwrap_or_default();
        assert!(status.success(), "{status:?}: {stderr}");
        let text = std::fs::read_to_string(&self.metrics).expect("metrics written");
        let events = std::fs::read_to_string(&self.events).expect("events written");
        (
            serde_json::from_str(&text).expect("metrics are JSON"),
            events,
        )
    }
}

fn count(v: &serde_json::Value) -> u64 {
    v.as_u64().unwrap_or_else(|| panic!("a count, found {v}"))
}

/// Ends a link-sim the test started.
fn end(link: &mut Child) {
    let _ = link.kill();
    let _ = link.wait();
}

#[test]
fn with_keys_the_relay_forwards_the_far_vehicles_secured_frames_unchanged() {
    // Every node reads the same file of per-vehicle keys; the relay forwards the far
    // vehicle's frames without opening them (a simulation gives it only its own key:
    // rcp::network's tests).
    let dir = tempfile::tempdir().unwrap();
    let keys = crate::common::private_file(
        dir.path(),
        "keys",
        "1 000102030405060708090a0b0c0d0e0f\n2 f0e0d0c0b0a090807060504030201000\n",
    );
    let m = three_nodes(THREE, 16.0, &["--key-file", keys.to_str().unwrap()]);
    let ((o, _), (r, _), (f, f_events)) = (&m[0], &m[1], &m[2]);
    assert_eq!(f["vehicles"]["2"]["orders_executed"], 1, "{f:#}");
    assert_eq!(o["vehicles"]["2"]["orders_acknowledged"], 1, "{o:#}");
    assert!(count(&r["nodes"]["1"]["frames_forwarded"]) >= 5, "{r:#}");
    for n in [o, r, f] {
        assert!(
            n["nodes"]
                .as_object()
                .unwrap()
                .values()
                .all(|m| m.get("refused").is_none()),
            "{n:#}"
        );
    }
    // The far vehicle's frames are 6 bytes longer than the plain ones: 22-byte polls.
    assert!(
        f_events
            .lines()
            .any(|l| l.contains(",22,") && l.ends_with(",2,delivered")),
        "{f_events}"
    );
}

#[test]
fn a_relay_on_two_media_carries_the_far_vehicle_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let routes = dir.path().join("mixed.json");
    std::fs::write(&routes, MIXED).unwrap();
    let (mut acoustic, op_port, relay_down) =
        crate::common::link_sim_pty(&crate::common::TEST_S100);
    let (mut rf, relay_up, far_port) = crate::common::link_sim_pty(&crate::common::TEST_S100);
    let far = node(dir.path(), &routes, "rov", 2, &[&far_port], 14.0, &[]);
    let relay = node(
        dir.path(),
        &routes,
        "rov",
        1,
        &[&relay_down, &relay_up],
        14.0,
        &[],
    );
    far.wait_started();
    relay.wait_started();
    // The operator's live view, watched by the stock Foxglove client while the session runs.
    let live = format!("127.0.0.1:{}", crate::common::free_port());
    let operator = node(
        dir.path(),
        &routes,
        "operator",
        0,
        &[&op_port],
        12.0,
        &["--foxglove", &live],
    );
    operator.wait_started();
    let seen = crate::common::stock_client(&["--url", &format!("ws://{live}"), "--seconds", "6"]);
    let (o, o_events) = operator.finish(Duration::from_secs(25));
    let (r, _) = relay.finish(Duration::from_secs(10));
    let (f, f_events) = far.finish(Duration::from_secs(10));
    end(&mut acoustic);
    end(&mut rf);

    assert_eq!(o["measured_by"], "operator");
    for v in ["1", "2"] {
        let heard = count(&o["vehicles"][v]["rov_to_operator"]["frames_delivered"]);
        assert!(heard >= 8, "vehicle {v}: {heard} answers: {o:#}");
        assert!(count(&o["vehicles"][v]["images_completed"]) >= 1, "{o:#}");
    }
    // The relay forwarded both ways, from one medium to the other.
    let relay_node = &r["nodes"]["1"];
    assert!(count(&relay_node["frames_forwarded"]) >= 16, "{r:#}");
    // Every frame the far vehicle heard came from the operator through the relay; its GoTo
    // ran once, and the operator saw it acknowledged.
    assert_eq!(f["vehicles"]["2"]["orders_executed"], 1, "{f:#}");
    assert_eq!(f["vehicles"]["2"]["orders_executed_twice"], 0, "{f:#}");
    assert_eq!(o["vehicles"]["2"]["orders_acknowledged"], 1, "{o:#}");
    // Two hops each way take longer than one.
    let rtt = |v: &str| o["vehicles"][v]["round_trip_ms"].as_f64().unwrap();
    assert!(rtt("2") > rtt("1") + 50.0, "{} vs {}", rtt("2"), rtt("1"));
    // The events name each frame's addresses and medium.
    assert!(
        o_events.starts_with(
            "direction,kind,bytes,t_sent_s,t_received_s,fate,medium,src,dst,tx,rx,action\n"
        ),
        "{o_events}"
    );
    assert!(
        o_events
            .lines()
            .any(|l| l.ends_with(",received,acoustic,2,0,,0,delivered")),
        "{o_events}"
    );
    assert!(
        f_events
            .lines()
            .any(|l| l.ends_with(",received,rf,0,2,,2,delivered")),
        "{f_events}"
    );
    let images = dir.path().join("images");
    for v in ["vehicle-1", "vehicle-2"] {
        assert!(images.join(v).join("image-0001.png").is_file(), "{v}");
    }

    // The live view: both vehicles under /vehicle/N/ (as the MCAP log has them, without a
    // per-vehicle link), and the operator node's own frames on /link/frames.
    assert_eq!(seen["subprotocol"], "foxglove.websocket.v1", "{seen}");
    for topic in [
        "/vehicle/1/rov/pose",
        "/vehicle/2/rov/pose",
        "/vehicle/2/tf",
        "/link/frames",
    ] {
        let n = seen["counts"][topic].as_u64().unwrap_or(0);
        assert!(n > 0, "{topic}: {seen}");
    }
    assert_eq!(
        seen["schemas"]["/link/frames"], "rovlink.LinkFrame",
        "{seen}"
    );
    let advertised = seen["advertised"].as_array().unwrap();
    assert!(
        !advertised
            .iter()
            .any(|t| t == "/vehicle/1/link/frames" || t == "/network/frames" || t == "/rov/pose"),
        "{seen}"
    );
}
