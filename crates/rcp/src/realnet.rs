//! One node of a multi-vehicle network in real time: the operator polling every vehicle of a
//! routes file in turn, or one vehicle (which may relay for others), over one or two modem
//! endpoints (`tdma-run --role ... --routes FILE [--port2 DEV]`).
//!
//! Every process is given the same network ([`Network`]: a scenario file's nodes, media and
//! routes) and its own address. Interface k of a node is the k-th medium of the file it is on
//! ([`Scenario::interfaces`]); each interface is one endpoint (a serial port, a
//! pseudo-terminal of `link-sim --pty N`, a UDP socket). Every frame read on any endpoint goes
//! through the node's [`Router`]: a frame for the node is handed to its engine, a frame the
//! node lies on the routed path of is written, unchanged, at once on the interface of its
//! next hop (a relay forwards inside the slot it is in), anything else is dropped (and shown
//! in `--events` with why).
//!
//! - The operator ([`run`] with [`Role::Operator`]) runs one [`OperatorEnd`] per vehicle, each
//!   polling its vehicle once per cycle at its slot's start ([`Scenario::cycle`]), with its
//!   own order sequencing, image stream and answer timeout (max(5 s, 3 cycles)); each
//!   vehicle's waypoints from the file are its script, and the orders of `--orders` go to the
//!   vehicle their line names ([`crate::orders::split_by_vehicle`]). A delivered frame goes to
//!   the end of its SRC.
//! - A vehicle ([`Role::Rov`]) runs its [`RovEnd`] at its address with a heartbeat timeout of
//!   max(5 s, 3 cycles); its answers go out on the interface towards the operator.
//!
//! The loop is the one driver's ([`crate::driver::run`] over the node's [`PortAir`]). Each
//! node knows only its own half, as in [`crate::realtime`]: the figures are the
//! simulation's [`NetworkMetrics`] with `measured_by` the node's role, per vehicle (the
//! operator: every vehicle it polls, with the round trip of its slots; a vehicle: itself;
//! no one-way delays) and for the node itself (what its router did; `forwarded_back` stays 0:
//! a node cannot tell which node transmitted the copy it heard). `media` is empty: the medium
//! is outside (modems, `link-sim`). `--events` rows carry SRC, DST and the medium of every
//! frame the node sent (fate `sent`) or heard (fate `received`, with what its router did).
//!
//! No-panic, no-hang contract: any bytes on any endpoint are routed or dropped, never a panic;
//! every wait ends at the next slot, the next vehicle step or 0.2 s at most (so a stop is seen
//! at once), and with two endpoints each is read in turn for at most [`SLICE`] at a time.
//! Errors of the setup ([`NodeError`]) are found before anything runs.

use std::collections::BTreeMap;
use std::sync::atomic::AtomicBool;

use crate::Role;
use crate::driver::{self, Ended, PortAir, Setup, VehicleEnds};
use crate::orders::{OrderSource, Script, split_by_vehicle};
use crate::report::NetworkMetrics;
use crate::report::Observer;
use crate::routing::{MAX_VEHICLE, Router};
use crate::rules;
use crate::scenario::Scenario;
use crate::session::{Parts, SessionConfig};
use rovlink_link::gll::Endpoint;

/// The most interfaces a node has (`--port`, `--port2`).
pub const MAX_INTERFACES: usize = 2;

/// Why a node cannot run in the network it was given.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NodeError {
    /// The address is not one of the file's nodes of that role.
    #[error("--address: expected {expected} of {file}, found {found}")]
    Address {
        /// What the address must be.
        expected: String,
        /// The routes file.
        file: String,
        /// The address given.
        found: u8,
    },
    /// The node's media and the endpoints given do not match.
    #[error("{0}")]
    Interfaces(String),
}

/// The network as one node sees it: the file's nodes, media and routes, and its address.
#[derive(Debug, Clone)]
pub struct Network {
    /// The network (its duration, seed and buoy are not used in real time).
    pub scenario: Scenario,
    /// This node's address: 0 for the operator.
    pub address: u8,
}

impl Network {
    /// Node `address` (0 for the operator, a vehicle of the file for the ROV) of `scenario`,
    /// read from `file` (named in errors), with `ports` endpoints: one per medium the node is
    /// on, at most [`MAX_INTERFACES`].
    pub fn new(
        scenario: Scenario,
        file: &str,
        role: Role,
        address: u8,
        ports: usize,
    ) -> Result<Network, NodeError> {
        let vehicles = scenario.vehicles();
        let known = match role {
            Role::Operator => address == 0 && scenario.node(0).is_some(),
            Role::Rov => vehicles.contains(&address),
        };
        if !known {
            let expected = match role {
                Role::Operator if scenario.node(0).is_none() => "an operator (node 0)".to_string(),
                Role::Operator => "0, the operator's address,".to_string(),
                Role::Rov => format!(
                    "a vehicle address ({}) in 1..={MAX_VEHICLE}",
                    list(&vehicles)
                ),
            };
            return Err(NodeError::Address {
                expected,
                file: file.to_string(),
                found: address,
            });
        }
        let media: Vec<&str> = scenario
            .interfaces(address)
            .into_iter()
            .filter_map(|k| scenario.media.get(k).map(|m| m.name.as_str()))
            .collect();
        let node = format!("node {address} of {file}");
        let problem = match (media.len(), ports) {
            (n, _) if n > MAX_INTERFACES => Some(format!(
                "{node} is on {n} media ({}): at most {MAX_INTERFACES} (--port, --port2)",
                media.join(", ")
            )),
            (2, 1) => Some(format!(
                "{node} is on two media ({}): give --port2 for {}",
                media.join(", "),
                media[1]
            )),
            (1, 2) => Some(format!(
                "--port2: {node} is on one medium ({}): it has no second interface",
                media[0]
            )),
            _ => None,
        };
        if let Some(text) = problem {
            return Err(NodeError::Interfaces(text));
        }
        Ok(Network { scenario, address })
    }

    /// The operator's cycle, s.
    pub fn cycle_s(&self) -> f64 {
        self.scenario.cycle_s()
    }

    /// The heartbeat timeout of every vehicle and the operator's answers timeout
    /// ([`rules::link_timeout_s`] of the cycle).
    pub fn timeout_s(&self) -> f64 {
        rules::link_timeout_s(self.cycle_s())
    }

    /// This node's router: the file's routes, its neighbours per interface, the duplicate
    /// window of the cycle ([`rules::duplicate_window_s`]).
    pub fn router(&self) -> Router {
        driver::router(
            &self.scenario,
            self.address,
            rules::duplicate_window_s(self.cycle_s()),
        )
    }
}

fn list(addresses: &[u8]) -> String {
    let names: Vec<String> = addresses.iter().map(u8::to_string).collect();
    names.join(", ")
}

/// Runs node `network.address` in `role` over `endpoints` (interface k on `endpoints[k]`)
/// until `config.duration_s` has passed, `stop` is set or an endpoint fails. As
/// [`crate::realtime::run`], the link model, seed and buoy of `config` are not used (its image
/// settings are); the operator takes its orders from each vehicle's waypoints of the network
/// and `parts.orders` (split among the vehicles); a vehicle is moved by `parts.drive` and
/// takes pictures with `parts.camera`.
pub fn run(
    role: Role,
    config: &SessionConfig,
    network: &Network,
    mut parts: Parts,
    endpoints: &mut [Box<dyn Endpoint>],
    stop: &AtomicBool,
    observer: &mut dyn Observer,
) -> (NetworkMetrics, Ended) {
    let mut scenario = network.scenario.clone();
    scenario.settings = config.settings;
    let guards = std::mem::take(&mut parts.guards);
    if !guards.is_empty() {
        scenario.frame_overhead_bytes = crate::secure::OVERHEAD_BYTES;
    }
    let address = network.address;
    let vehicles = match role {
        Role::Operator => operator_ends(&scenario, parts),
        Role::Rov => BTreeMap::from([(
            address,
            VehicleEnds {
                operator: None,
                rov: Some(driver::rov_end(
                    &scenario,
                    address,
                    parts.drive,
                    parts.camera,
                )),
            },
        )]),
    };
    let endpoints = endpoints
        .iter_mut()
        .map(|e| &mut **e as &mut dyn Endpoint)
        .collect();
    let mut air = PortAir::new(&scenario, address, endpoints);
    let setup = Setup {
        scenario: &scenario,
        nodes: vec![address],
        vehicles,
        measured_by: role.name(),
        duration_s: config.duration_s,
        duplicate_window_s: rules::duplicate_window_s(scenario.cycle_s()),
        guards,
    };
    driver::run(setup, &mut air, stop, observer)
}

/// The operator's ends, one per vehicle of the network, each at its slot of the cycle, each
/// showing its vehicle's statuses as poses.
fn operator_ends(scenario: &Scenario, parts: Parts) -> BTreeMap<u8, VehicleEnds> {
    let vehicles = scenario.vehicles();
    let shared = split_by_vehicle(parts.orders, &vehicles);
    vehicles
        .iter()
        .zip(shared)
        .map(|(&address, tap)| {
            let waypoints = scenario
                .node(address)
                .map_or(&[][..], |n| n.waypoints.as_slice());
            let sources: Vec<Box<dyn OrderSource>> =
                vec![Box::new(Script::new(&[], waypoints)), tap];
            let mut end = driver::operator_end(scenario, address, sources);
            end.status_poses = true;
            let ends = VehicleEnds {
                operator: Some(end),
                rov: None,
            };
            (address, ends)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use std::path::Path;
    use std::sync::mpsc::{Receiver, Sender, channel};

    use super::*;
    use crate::report::Quiet;
    use crate::session::Waypoint;
    use rovlink_link::SimTime;
    use rovlink_link::gll::{GllError, Received};
    use std::time::Instant;

    /// The issue's three-node network, with short slots (the in-memory bus has no delay).
    const THREE: &str = r#"{"nodes":[{"address":0,"role":"operator","position":[0,0,0]},
               {"address":1,"role":"rov","start":[3,0,1],"slot_s":0.15},
               {"address":2,"role":"rov","start":[7,0,1],"slot_s":0.15,
                "waypoints":[[0.5,7.5,1,1,90]]}],
      "media":[{"name":"rf","model":"s100","nodes":[0,1,2]}],
      "routes":{"0":{"2":1},"2":{"0":1}}}"#;

    fn scenario(text: &str) -> Scenario {
        Scenario::parse(text, Path::new(".")).unwrap()
    }

    #[test]
    fn a_node_must_be_in_the_file_with_one_endpoint_per_medium() {
        let three = scenario(THREE);
        let error = |role, address, ports| {
            Network::new(three.clone(), "f.json", role, address, ports)
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            error(Role::Rov, 15, 1),
            "--address: expected a vehicle address (1, 2) in 1..=14 of f.json, found 15"
        );
        assert!(error(Role::Rov, 3, 1).ends_with("found 3"));
        assert!(error(Role::Rov, 0, 1).ends_with("found 0"));
        assert_eq!(
            error(Role::Operator, 1, 1),
            "--address: expected 0, the operator's address, of f.json, found 1"
        );
        assert_eq!(
            error(Role::Rov, 1, 2),
            "--port2: node 1 of f.json is on one medium (rf): it has no second interface"
        );
        let mixed = scenario(
            r#"{"nodes":[{"address":0,"role":"operator","position":[0,0,0]},
                 {"address":1,"role":"rov","start":[0,0,200]},
                 {"address":2,"role":"rov","start":[3,0,200]}],
                "media":[{"name":"acoustic","model":"s2cr-burst","nodes":[0,1]},
                         {"name":"rf","model":"s100","nodes":[1,2]}],
                "routes":{"0":{"2":1},"2":{"0":1}}}"#,
        );
        let relay = Network::new(mixed.clone(), "m.json", Role::Rov, 1, 1).unwrap_err();
        assert_eq!(
            relay.to_string(),
            "node 1 of m.json is on two media (acoustic, rf): give --port2 for rf"
        );
        let relay = Network::new(mixed, "m.json", Role::Rov, 1, 2).unwrap();
        assert_eq!(relay.router().interface_to(0), 0);
        assert_eq!(relay.router().interface_to(2), 1);
        let far = Network::new(three, "f.json", Role::Rov, 2, 1).unwrap();
        assert_eq!(far.timeout_s(), (3.0 * far.cycle_s()).max(5.0));
    }

    /// One node's end of an in-memory medium: what it sends reaches the nodes in its range at
    /// once, in order.
    struct Bus {
        rx: Receiver<Vec<u8>>,
        peers: Vec<Sender<Vec<u8>>>,
    }

    impl Endpoint for Bus {
        fn name(&self) -> &str {
            "bus"
        }

        fn send(&mut self, packet: &[u8]) -> Result<(), GllError> {
            for peer in &self.peers {
                let _ = peer.send(packet.to_vec());
            }
            Ok(())
        }

        fn receive(&mut self, deadline: Instant) -> Result<Option<Received>, GllError> {
            let wait = deadline.saturating_duration_since(Instant::now());
            Ok(self.rx.recv_timeout(wait).ok().map(|bytes| Received {
                at: Instant::now(),
                bytes,
                damaged: false,
            }))
        }
    }

    /// Runs the three nodes of `text` for `duration_s` over a medium where 0 hears 1, 1 hears
    /// 0 and 2, 2 hears 1 (7 m from the operator, out of range); each node's figures.
    fn three_nodes(text: &str, duration_s: f64) -> Vec<NetworkMetrics> {
        let reach: [&[usize]; 3] = [&[1], &[0, 2], &[1]];
        let (senders, receivers): (Vec<_>, Vec<_>) = (0..3).map(|_| channel()).unzip();
        let stop = std::sync::Arc::new(AtomicBool::new(false));
        let threads: Vec<_> = receivers
            .into_iter()
            .enumerate()
            .map(|(address, rx)| {
                let peers = reach[address].iter().map(|&k| senders[k].clone()).collect();
                let text = text.to_string();
                let stop = stop.clone();
                std::thread::spawn(move || {
                    let scenario = scenario(&text);
                    let role = if address == 0 {
                        Role::Operator
                    } else {
                        Role::Rov
                    };
                    let address = address as u8;
                    let network = Network::new(scenario, "t", role, address, 1).unwrap();
                    let start_m = network.scenario.node(address).unwrap().position_m;
                    let config = SessionConfig {
                        model: network.scenario.media[0].model.clone(),
                        seed: 1,
                        ipg_s: network.cycle_s(),
                        duration_s,
                        buoy_m: [0.0; 3],
                        start_m,
                        script: Vec::new(),
                        waypoints: Vec::<Waypoint>::new(),
                        settings: network.scenario.settings,
                        images: vec![crate::camera::builtin_picture(64, 48, 1)],
                    };
                    let mut parts = Parts::from_config(&config);
                    // A console line naming vehicle 1: a HoldHeading order for it alone.
                    let hold = rovlink_wire::operator::Order::HoldHeading {
                        heading_deg: 90,
                        enable: true,
                    };
                    let console = Script::addressed(vec![(
                        SimTime::from_secs_f64(0.2),
                        Some(1),
                        crate::orders::Live::Order(hold),
                    )]);
                    parts.orders.push(Box::new(console));
                    let mut endpoints: Vec<Box<dyn Endpoint>> = vec![Box::new(Bus { rx, peers })];
                    let (metrics, ended) = run(
                        role,
                        &config,
                        &network,
                        parts,
                        &mut endpoints,
                        &stop,
                        &mut Quiet,
                    );
                    assert!(matches!(ended, Ended::Done), "{ended:?}");
                    metrics
                })
            })
            .collect();
        drop(senders);
        threads.into_iter().map(|t| t.join().unwrap()).collect()
    }

    #[test]
    fn the_far_vehicle_answers_through_the_relay_and_not_without_routes() {
        let cycle_s = scenario(THREE).cycle_s();
        let m = three_nodes(THREE, 6.0 * cycle_s + 0.5);
        let (operator, relay, far) = (&m[0], &m[1], &m[2]);
        let heard = |n: &NetworkMetrics, v: &str| n.vehicles[v].rov_to_operator.frames_delivered;
        assert!(heard(operator, "1") >= 3, "{operator:#?}");
        assert!(heard(operator, "2") >= 3, "{operator:#?}");
        assert!(
            far.vehicles["2"].operator_to_rov.frames_delivered >= 3,
            "{far:#?}"
        );
        // The far vehicle's GoTo (due at 0.5 s) was executed, once.
        assert_eq!(far.vehicles["2"].orders_executed, 1, "{far:#?}");
        assert_eq!(operator.vehicles["2"].orders_acknowledged, 1);
        // The order naming vehicle 1 went to vehicle 1 only.
        assert_eq!(relay.vehicles["1"].orders_executed, 1, "{relay:#?}");
        assert_eq!(operator.vehicles["1"].orders_sent, 1);
        assert_eq!(operator.vehicles["2"].orders_sent, 1);
        let node1 = &relay.nodes["1"];
        assert!(node1.frames_forwarded >= 6, "{node1:?}");
        // Nobody relays the relay's own answers back to it.
        assert_eq!(node1.own_dropped, 0);
        assert!(relay.nodes["1"].frames_delivered >= 3);
        // The bus has no delay: each round trip is the far end's own time to answer.
        assert!(operator.vehicles["2"].round_trip_ms.is_some());

        let direct = THREE.replace(r#""routes":{"0":{"2":1},"2":{"0":1}}"#, r#""routes":{}"#);
        let m = three_nodes(&direct, 4.0 * cycle_s);
        assert_eq!(m[2].vehicles["2"].operator_to_rov.frames_delivered, 0);
        assert_eq!(m[0].vehicles["2"].rov_to_operator.frames_delivered, 0);
        assert_eq!(m[1].nodes["1"].frames_forwarded, 0);
        assert!(m[1].nodes["1"].off_path_dropped > 0);
        assert!(m[0].vehicles["1"].rov_to_operator.frames_delivered > 0);
    }
}
