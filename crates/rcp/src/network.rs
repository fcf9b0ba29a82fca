//! A multi-vehicle session in virtual time: the operator, every vehicle and every medium of a
//! [`Scenario`] in one process, with routing over relays, run by the one driver
//! ([`crate::driver`]) over the simulated media ([`SimAir`]).
//!
//! Each node is a [`Router`] in front of its engines. The operator holds one [`OperatorEnd`]
//! per vehicle, each polling its vehicle once a cycle at its own slot ([`Scenario::cycle`]),
//! with its own order sequencing (OID/EOID), image stream, answers timeout and counters; each
//! vehicle is a [`RovEnd`] at its address, moved by the built-in vehicle model. Each medium is a
//! [`Medium`] over the nodes on it, whose positions follow the vehicles at every step.
//!
//! The loop takes the earliest of: a medium's next event, an operator end's next slot or order,
//! a vehicle's next step. A frame that arrives intact at a node goes through that node's router:
//! delivered to the engine it is for (the operator end of its SRC, or the vehicle), forwarded
//! unchanged at once onto the interfaces the router names (a relay forwards inside the slot it
//! is in), or dropped. The answer of a vehicle goes out on the interface of its next hop
//! towards the operator.
//!
//! Every vehicle's figures are the single-vehicle session's, end to end: a frame counts as sent
//! when its origin sends it, as delivered when its destination takes it, with the delay between
//! the two; each node's figures count what its router did. Everything is seeded from the
//! scenario's seed (medium k draws from seed + k), so a run is reproducible.

use std::collections::BTreeMap;
use std::sync::atomic::AtomicBool;

use crate::autopilot::SimDrive;
use crate::camera::Cycle;
use crate::driver::{self, Setup, SimAir, VehicleEnds};
use crate::orders::Script;
use crate::report::Observer;
use crate::rules;
use crate::scenario::Scenario;
use rovlink_debt as debt;
use rovlink_link::ModelError;

pub use crate::report::{MediumMetrics, NetworkMetrics, NodeMetrics};

/// Why a scenario could not run.
#[derive(Debug, thiserror::Error)]
pub enum NetworkError {
    /// A medium's model is invalid.
    #[error("medium {name}: {error}")]
    Model {
        /// The medium.
        name: String,
        /// Its model's error.
        error: ModelError,
    },
}

/// Runs `scenario` in virtual time; the vehicles' cameras cycle through `images` (each vehicle
/// starting at its own picture). `stop` is checked at every event: once set, the run ends
/// there with the figures so far and `interrupted` set to [`crate::report::STOPPED`]. With a
/// `pace`, virtual time is held to `pace` times real time ([`driver::Pace`]). With
/// `security`, every node seals and checks its frames ([`crate::secure`]); the caller counts
/// the overhead in `scenario.frame_overhead_bytes`.
pub fn run(
    scenario: &Scenario,
    images: &[debt::Image],
    security: Option<&crate::secure::Security>,
    observer: &mut dyn Observer,
    stop: &AtomicBool,
    pace: Option<f64>,
) -> Result<NetworkMetrics, NetworkError> {
    let mut vehicles = BTreeMap::new();
    for (k, address) in scenario.vehicles().into_iter().enumerate() {
        let Some(node) = scenario.node(address) else {
            continue;
        };
        let script = Script::new(&[], &node.waypoints);
        let mut pictures = images.to_vec();
        if !pictures.is_empty() {
            let turn = k % pictures.len();
            pictures.rotate_left(turn);
        }
        let ends = VehicleEnds {
            operator: Some(driver::operator_end(
                scenario,
                address,
                vec![Box::new(script)],
            )),
            rov: Some(driver::rov_end(
                scenario,
                address,
                Box::new(SimDrive::new(node.position_m)),
                Box::new(Cycle::new(pictures)),
            )),
        };
        vehicles.insert(address, ends);
    }
    let guards = security.map_or_else(BTreeMap::new, |s| s.simulation_guards(scenario));
    simulate(scenario, vehicles, guards, observer, stop, pace)
}

/// Runs `scenario` in virtual time with the vehicles' `ends`, every node in this process.
pub fn simulate(
    scenario: &Scenario,
    ends: BTreeMap<u8, VehicleEnds>,
    guards: BTreeMap<u8, rovlink_security::Guard>,
    observer: &mut dyn Observer,
    stop: &AtomicBool,
    pace: Option<f64>,
) -> Result<NetworkMetrics, NetworkError> {
    let mut air =
        SimAir::new(scenario).map_err(|(name, error)| NetworkError::Model { name, error })?;
    if let Some(pace) = pace {
        air = air.paced(driver::Pace::new(pace, stop));
    }
    let setup = Setup {
        scenario,
        nodes: scenario.nodes.iter().map(|n| n.address).collect(),
        vehicles: ends,
        measured_by: "simulation",
        duration_s: scenario.duration_s,
        duplicate_window_s: rules::duplicate_window_s(scenario.cycle_s()),
        guards,
    };
    let (metrics, _) = driver::run(setup, &mut air, stop, observer);
    Ok(metrics)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::{Metrics, Quiet, STOPPED};
    use std::path::Path;

    use crate::scenario::tests::THREE;

    fn scenario(text: &str) -> Scenario {
        Scenario::parse(text, Path::new(".")).unwrap()
    }

    fn images() -> Vec<debt::Image> {
        vec![crate::camera::builtin_picture(160, 120, 1)]
    }

    fn run_quiet(s: &Scenario) -> NetworkMetrics {
        run(
            s,
            &images(),
            None,
            &mut Quiet,
            &AtomicBool::new(false),
            None,
        )
        .unwrap()
    }

    #[test]
    fn the_far_vehicle_is_reached_through_the_relay() {
        let m = run_quiet(&scenario(THREE));
        let (near, far) = (&m.vehicles["1"], &m.vehicles["2"]);
        for v in [near, far] {
            assert!(v.images_completed >= 3, "{m:#?}");
            assert_eq!(v.orders_executed_twice, 0, "{m:#?}");
            assert_eq!(v.orders_acknowledged_unexecuted, 0, "{m:#?}");
        }
        assert_eq!(far.orders_sent, 1, "{m:#?}");
        assert_eq!(far.orders_executed, 1, "{m:#?}");
        assert_eq!(far.orders_acknowledged, 1, "{m:#?}");
        let delay = |v: &Metrics| v.operator_to_rov.delay_ms.unwrap();
        assert!(delay(far) > 1.5 * delay(near), "{m:#?}");
        let back = |v: &Metrics| v.rov_to_operator.delay_ms.unwrap();
        assert!(back(far) > back(near), "{m:#?}");
        let relay = &m.nodes["1"];
        // Every poll of the far vehicle and every answer went through the relay, once.
        let far_frames =
            far.operator_to_rov.frames_delivered + far.rov_to_operator.frames_delivered;
        assert!(far_frames > 700, "{m:#?}");
        assert!(relay.frames_forwarded >= far_frames, "{m:#?}");
        assert!(
            relay.frames_forwarded
                <= far.operator_to_rov.frames_sent + far.rov_to_operator.frames_sent
        );
        assert!(m.nodes.values().all(|n| n.forwarded_back == 0), "{m:#?}");
        // The operator never hears the far vehicle itself: 7 m is out of the S100's 5 m.
        assert_eq!(m.nodes["0"].frames_forwarded, 0);
        assert!(m.media["rf"].receptions_out_of_range > 0);
    }

    #[test]
    fn secured_frames_cross_the_relay_unchanged_and_cost_their_bytes() {
        use rovlink_security::KeyRing;
        let plain_scenario = scenario(THREE);
        let mut secured = plain_scenario.clone();
        secured.frame_overhead_bytes = crate::secure::OVERHEAD_BYTES;
        let ring = KeyRing::parse(
            "1 000102030405060708090a0b0c0d0e0f\n2 0f0e0d0c0b0a09080706050403020100\n",
        )
        .unwrap();
        for encrypt in [false, true] {
            let security = crate::secure::Security {
                ring: ring.clone(),
                encrypt,
                key_file: "keys".into(),
            };
            let m = run(
                &secured,
                &images(),
                Some(&security),
                &mut Quiet,
                &AtomicBool::new(false),
                None,
            )
            .unwrap();
            let far = &m.vehicles["2"];
            assert_eq!(far.orders_executed, 1, "{m:#?}");
            assert!(far.images_completed >= 3, "{m:#?}");
            assert!(far.frames_refused.is_empty(), "{m:#?}");
            assert!(m.nodes.values().all(|n| n.refused.is_empty()), "{m:#?}");
            assert!(m.nodes["1"].frames_forwarded > 700, "{m:#?}");
            assert!(m.cycle_s > plain_scenario.cycle_s(), "{m:#?}");
        }
    }

    #[test]
    fn a_chain_of_relays_suppresses_the_copies_it_overhears() {
        // 0 - 1 - 2 - 3 along x, 3 m apart, on one S100 medium (range 5 m): each node hears only
        // its neighbours, so relay 1 hears relay 2 forward what 1 itself forwarded.
        let text = r#"{"duration_s":400,"seed":2,
          "nodes":[{"address":0,"role":"operator","position":[0,0,0]},
                   {"address":1,"role":"rov","start":[3,0,0]},
                   {"address":2,"role":"rov","start":[6,0,0]},
                   {"address":3,"role":"rov","start":[9,0,0],"waypoints":[[20,9.5,0,0,0]]}],
          "media":[{"name":"rf","model":"s100","nodes":[0,1,2,3]}],
          "routes":{"0":{"2":1,"3":1},"1":{"3":2},"2":{"0":1},"3":{"0":2,"1":2}}}"#;
        let m = run_quiet(&scenario(text));
        let far = &m.vehicles["3"];
        assert!(far.images_completed >= 1, "{m:#?}");
        assert_eq!(
            (far.orders_executed, far.orders_executed_twice),
            (1, 0),
            "{m:#?}"
        );
        assert!(m.nodes["1"].duplicates_dropped > 100, "{m:#?}");
        assert!(m.nodes["2"].duplicates_dropped > 100, "{m:#?}");
        assert!(m.nodes.values().all(|n| n.forwarded_back == 0), "{m:#?}");
        // Three hops out and three back: the far vehicle's delay is about three times the
        // near one's.
        let delay = |v: &str| m.vehicles[v].operator_to_rov.delay_ms.unwrap();
        assert!(delay("3") > 2.5 * delay("1"), "{m:#?}");
    }

    #[test]
    fn without_routes_the_far_vehicle_gets_nothing() {
        let text = THREE.replace(r#""routes":{"0":{"2":1},"2":{"0":1}}"#, r#""routes":{}"#);
        let m = run_quiet(&scenario(&text));
        let far = &m.vehicles["2"];
        assert_eq!(far.operator_to_rov.frames_delivered, 0, "{m:#?}");
        assert_eq!(far.rov_to_operator.frames_delivered, 0, "{m:#?}");
        assert_eq!(far.images_completed, 0);
        assert_eq!(far.orders_executed, 0);
        assert_eq!(m.nodes["1"].frames_forwarded, 0);
        assert!(m.vehicles["1"].images_completed >= 3, "{m:#?}");
    }

    #[test]
    fn a_seed_gives_the_same_run() {
        let s = scenario(&THREE.replace(r#""duration_s":600"#, r#""duration_s":120"#));
        let a = serde_json::to_string(&run_quiet(&s)).unwrap();
        let b = serde_json::to_string(&run_quiet(&s)).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn acoustic_to_the_surface_and_rf_between_vehicles_both_deliver_images() {
        let text = r#"{"duration_s":1800,"seed":3,
          "nodes":[{"address":0,"role":"operator","position":[0,0,0]},
                   {"address":1,"role":"rov","start":[0,0,200]},
                   {"address":2,"role":"rov","start":[3,0,200]}],
          "media":[{"name":"acoustic","model":"s2cr-burst","nodes":[0,1]},
                   {"name":"rf","model":"s100","nodes":[1,2]}],
          "routes":{"0":{"2":1},"2":{"0":1}}}"#;
        let s = scenario(text);
        // The relay's two interfaces: acoustic up, RF across.
        assert_eq!(s.interfaces(1), [0, 1]);
        let m = run_quiet(&s);
        for v in m.vehicles.values() {
            assert!(v.images_completed >= 1, "{m:#?}");
            assert_eq!(v.orders_executed_twice, 0);
        }
        assert!(m.nodes["1"].frames_forwarded > 0);
        assert!(m.media["rf"].transmissions > 0 && m.media["acoustic"].transmissions > 0);
    }

    #[test]
    fn a_stop_ends_the_run_with_the_figures_so_far() {
        let stop = AtomicBool::new(true);
        let m = run(&scenario(THREE), &images(), None, &mut Quiet, &stop, None).unwrap();
        assert_eq!(m.interrupted.as_deref(), Some(STOPPED));
        assert!(m.duration_s < 1.0);
    }
}
