//! Property tests of whole simulated networks under heavy loss: the issue's three-node scenario
//! (the far vehicle reached only through the relay) with 20 % of receptions lost on every hop,
//! sometimes duplicates and bit errors too, for any seed and any GoTo orders to either
//! vehicle: no order is executed twice on any vehicle, no acknowledged order went unexecuted,
//! and no node ever forwards a frame back towards the node it heard it from.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use proptest::prelude::*;
use rovlink_rcp::camera::builtin_picture;
use rovlink_rcp::network;
use rovlink_rcp::report::Quiet;
use rovlink_rcp::scenario::Scenario;

const THREE: &str = r#"{"duration_s":150,
  "nodes":[{"address":0,"role":"operator","position":[0,0,0]},
           {"address":1,"role":"rov","start":[3,0,1]},
           {"address":2,"role":"rov","start":[7,0,1]}],
  "media":[{"name":"rf","model":"s100","nodes":[0,1,2]}],
  "routes":{"0":{"2":1},"2":{"0":1}},
  "image":{"size_bytes":600,"trunk_bytes":39}}"#;

/// A GoTo order near a vehicle's start (so the relay stays in range of both ends).
fn waypoints(around: [f64; 3]) -> impl Strategy<Value = Vec<[f64; 5]>> {
    let one = (0.0..140.0f64, -1.0..1.0f64, -1.0..1.0f64, 0.0..360.0f64)
        .prop_map(move |(t, dx, dy, h)| [t, around[0] + dx, around[1] + dy, around[2], h]);
    prop::collection::vec(one, 1..12).prop_map(|mut v| {
        v.sort_by(|a, b| a[0].total_cmp(&b[0]));
        v
    })
}

fn scenario(
    seed: u64,
    near: &[[f64; 5]],
    far: &[[f64; 5]],
    duplicate_percent: f64,
    ber: f64,
) -> Scenario {
    let mut value: serde_json::Value = serde_json::from_str(THREE).unwrap();
    value["seed"] = seed.into();
    value["nodes"][1]["waypoints"] = serde_json::json!(near);
    value["nodes"][2]["waypoints"] = serde_json::json!(far);
    let mut scenario = Scenario::parse(&value.to_string(), Path::new(".")).unwrap();
    for medium in &mut scenario.media {
        medium.model.loss_percent = 20.0;
        medium.model.duplicate_percent = duplicate_percent;
        medium.model.ber = ber;
    }
    scenario
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn no_order_twice_and_nothing_forwarded_back(
        seed in any::<u64>(),
        near in waypoints([3.0, 0.0, 1.0]),
        far in waypoints([7.0, 0.0, 1.0]),
        duplicate_percent in prop_oneof![Just(0.0), 0.0..10.0f64],
        ber in prop_oneof![Just(0.0), 1e-4..5e-4f64],
    ) {
        let s = scenario(seed, &near, &far, duplicate_percent, ber);
        let images = [builtin_picture(96, 64, seed)];
        let m = network::run(&s, &images, None, &mut Quiet, &AtomicBool::new(false), None).unwrap();
        for (address, v) in &m.vehicles {
            prop_assert_eq!(v.orders_executed_twice, 0, "vehicle {}: {:?}", address, v);
            prop_assert_eq!(v.orders_acknowledged_unexecuted, 0, "vehicle {}: {:?}", address, v);
            prop_assert!(v.orders_executed >= v.orders_acknowledged);
        }
        for (address, n) in &m.nodes {
            prop_assert_eq!(n.forwarded_back, 0, "node {}: {:?}", address, n);
        }
        // The relay did relay: the far vehicle heard the operator through it.
        prop_assert!(m.nodes["1"].frames_forwarded > 0);
        prop_assert!(m.vehicles["2"].operator_to_rov.frames_delivered > 0);
    }
}
