//! A multi-vehicle network in real time: one `tdma-run` process per node, `--routes` the same
//! file for all, `link-sim` standing in for the modems (docs/tdma-network.md, "Real time: one
//! process per node").

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

const TDMA_RUN: &str = env!("CARGO_BIN_EXE_tdma-run");

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

/// One node's process: `tdma-run --role ROLE --routes FILE ...`, its outputs in `dir`.
struct NodeRun {
    child: Child,
    metrics: PathBuf,
    events: PathBuf,
}

fn node(
    dir: &Path,
    routes: &Path,
    role: &str,
    address: u8,
    ports: &[&str],
    duration_s: f64,
) -> NodeRun {
    let name = |what: &str| dir.join(format!("node{address}-{what}"));
    let (metrics, events) = (name("metrics.json"), name("events.csv"));
    let mut command = Command::new(TDMA_RUN);
    command
        .args(["--role", role, "--routes"])
        .arg(routes)
        .args(["--duration", &duration_s.to_string(), "--image-size", "400"])
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
    let child = command
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("tdma-run starts");
    NodeRun {
        child,
        metrics,
        events,
    }
}

impl NodeRun {
    /// Waits for the node to end (well within `limit`) and returns its metrics.
    fn finish(mut self, limit: Duration) -> (serde_json::Value, String) {
        let status = common::wait_for_exit(&mut self.child, limit);
        let stderr =
            std::io::read_to_string(self.child.stderr.take().expect("stderr")).unwrap_or_default();
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
fn end(mut link: Child) {
    let _ = link.kill();
    let _ = link.wait();
}

#[test]
fn a_relay_on_two_media_carries_the_far_vehicle_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let routes = dir.path().join("mixed.json");
    std::fs::write(&routes, MIXED).unwrap();
    let (acoustic, op_port, relay_down) = common::link_sim_pty(&common::TEST_S100);
    let (rf, relay_up, far_port) = common::link_sim_pty(&common::TEST_S100);
    let far = node(dir.path(), &routes, "rov", 2, &[&far_port], 14.0);
    let relay = node(
        dir.path(),
        &routes,
        "rov",
        1,
        &[&relay_down, &relay_up],
        14.0,
    );
    std::thread::sleep(Duration::from_millis(300));
    let operator = node(dir.path(), &routes, "operator", 0, &[&op_port], 12.0);
    let (o, o_events) = operator.finish(Duration::from_secs(25));
    let (r, _) = relay.finish(Duration::from_secs(10));
    let (f, f_events) = far.finish(Duration::from_secs(10));
    end(acoustic);
    end(rf);

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
        o_events.starts_with("direction,kind,bytes,t_sent_s,t_received_s,fate,src,dst,medium\n"),
        "{o_events}"
    );
    assert!(
        o_events
            .lines()
            .any(|l| l.ends_with(",received,2,0,acoustic")),
        "{o_events}"
    );
    assert!(
        f_events.lines().any(|l| l.ends_with(",received,0,2,rf")),
        "{f_events}"
    );
    let images = dir.path().join("images");
    for v in ["vehicle-1", "vehicle-2"] {
        assert!(images.join(v).join("image-0001.png").is_file(), "{v}");
    }
}
