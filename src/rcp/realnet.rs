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
//!   vehicle their line names ([`super::orders::split_by_vehicle`]). A delivered frame goes to
//!   the end of its SRC.
//! - A vehicle ([`Role::Rov`]) runs its [`RovEnd`] at its address with a heartbeat timeout of
//!   max(5 s, 3 cycles); its answers go out on the interface towards the operator.
//!
//! Each node knows only its own half, as in [`super::realtime`]: the figures are the
//! simulation's [`NetworkMetrics`] with `measured_by` the node's role, per vehicle (the
//! operator: every vehicle it polls, with the round trip of its slots; a vehicle: itself;
//! no one-way delays) and for the node itself (what its router did; `forwarded_back` stays 0:
//! a node cannot tell which node transmitted the copy it heard). `media` is empty: the medium
//! is outside (modems, `link-sim`). `--events` rows ([`FrameRows`]) carry SRC, DST and the
//! medium of every frame the node sent or heard.
//!
//! No-panic, no-hang contract: any bytes on any endpoint are routed or dropped, never a panic;
//! every wait ends at the next slot, the next vehicle step or 0.2 s at most (so a stop is seen
//! at once), and with two endpoints each is read in turn for at most [`SLICE`] at a time.
//! Errors of the setup ([`NodeError`]) are found before anything runs.

use std::collections::BTreeMap;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use super::Role;
use super::harness::{OperatorEnd, Out, RovEnd, Tally};
use super::network::{NetObserver, NetworkMetrics, NodeMetrics, Tagged};
use super::orders::{OrderSource, Script, split_by_vehicle};
use super::realtime::{Clock, Ended, sent_event};
use super::routing::{BROADCAST, Decision, Dropped, MAX_VEHICLE, Router};
use super::rov::{Rov, RovConfig};
use super::rules;
use super::scenario::Scenario;
use super::session::{Direction, FrameEvent, Metrics, Parts, SessionConfig, kind_of};
use crate::cli::output::Dest;
use crate::cli::rows::{RowFormat, RowWriter};
use crate::gll::{Endpoint, GllError, Received};
use crate::io::IoError;
use crate::link::SimTime;
use crate::stats::Running;

/// The longest a node with two endpoints waits on one before reading the other.
pub const SLICE: Duration = Duration::from_millis(5);

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
        Router::new(
            self.address,
            self.scenario.routes.clone(),
            self.scenario.neighbours(self.address),
            rules::duplicate_window_s(self.cycle_s()),
        )
    }
}

fn list(addresses: &[u8]) -> String {
    let names: Vec<String> = addresses.iter().map(u8::to_string).collect();
    names.join(", ")
}

/// Counts what the router decided for a frame heard (`forwarded_back` needs the copy's
/// transmitter, which a node in real time does not know: it stays 0).
fn count(node: &mut NodeMetrics, decision: &Decision) {
    node.frames_heard += 1;
    node.frames_delivered += u64::from(decision.deliver);
    node.frames_forwarded += decision.forward_on.len() as u64;
    match decision.dropped {
        Some(Dropped::Own) => node.own_dropped += 1,
        Some(Dropped::Duplicate) => node.duplicates_dropped += 1,
        Some(Dropped::OffPath) => node.off_path_dropped += 1,
        Some(Dropped::Malformed) | None => {}
    }
}

/// The columns `--events` has in a network node after the single-vehicle ones
/// ([`super::outputs::EVENTS_HEADER`]): the frame's SRC and DST, and the medium (interface) it
/// went out or came in on.
pub const NODE_EVENTS_EXTRA: [&str; 3] = ["src", "dst", "medium"];

/// A network node's `--events`: one row per frame it sent or heard, with its addresses
/// ([`super::outputs::EVENTS_HEADER`], then [`NODE_EVENTS_EXTRA`]; fate `sent`, `received`, `forwarded`, or why the router dropped
/// it: `own`, `duplicate`, `off_path`, `malformed`). The first write error is kept and ends
/// the run ([`FrameRows::failed`]); [`FrameRows::finish`] returns it.
pub struct FrameRows {
    rows: RowWriter,
    error: Option<IoError>,
}

impl FrameRows {
    /// Rows to `dest`, which appears with the first.
    pub fn new(dest: Dest) -> FrameRows {
        let header: Vec<&str> = (super::outputs::EVENTS_HEADER.iter())
            .chain(&NODE_EVENTS_EXTRA)
            .copied()
            .collect();
        FrameRows {
            rows: RowWriter::new(dest, RowFormat::Csv, &header),
            error: None,
        }
    }

    /// True once a row could not be written.
    pub fn failed(&self) -> bool {
        self.error.is_some()
    }

    /// Completes the output: the first write error, if any.
    pub fn finish(self) -> Result<(), IoError> {
        match self.error {
            Some(error) => Err(error),
            None => self.rows.finish(),
        }
    }

    fn row(&mut self, e: &FrameEvent, addresses: Option<(u8, u8)>, medium: &str) {
        if self.error.is_some() {
            return;
        }
        let (src, dst) = addresses.map_or((String::new(), String::new()), |(s, d)| {
            (s.to_string(), d.to_string())
        });
        let mut row = super::outputs::event_fields(e).to_vec();
        row.extend([src, dst, medium.to_string()]);
        if let Err(error) = self.rows.row(&row) {
            self.error = Some(error);
        }
    }
}

/// Where a node's outputs go: the per-vehicle outputs and its frame rows.
pub struct NodeOutputs<'a> {
    /// Images, poses, events and warnings, by vehicle.
    pub observer: &'a mut dyn NetObserver,
    /// `--events`, if asked for.
    pub frames: Option<&'a mut FrameRows>,
}

impl NodeOutputs<'_> {
    fn failed(&self) -> bool {
        self.observer.failed() || self.frames.as_ref().is_some_and(|f| f.failed())
    }

    fn frame(&mut self, e: &FrameEvent, addresses: Option<(u8, u8)>, medium: &str) {
        if let Some(frames) = self.frames.as_mut() {
            frames.row(e, addresses, medium);
        }
        self.observer.node_frame(e);
    }
}

/// Runs node `network.address` in `role` over `endpoints` (interface k on `endpoints[k]`)
/// until `config.duration_s` has passed, `stop` is set or an endpoint fails. As
/// [`super::realtime::run`], the link model, seed and buoy of `config` are not used; the
/// operator takes its orders from `config.script`, each vehicle's waypoints of the network
/// and `parts.orders` (split among the vehicles); a vehicle is moved by `parts.drive` and
/// takes pictures with `parts.camera`.
pub fn run(
    role: Role,
    config: &SessionConfig,
    network: &Network,
    parts: Parts,
    endpoints: &mut [Box<dyn Endpoint>],
    stop: &AtomicBool,
    outputs: &mut NodeOutputs<'_>,
) -> (NetworkMetrics, Ended) {
    let clock = Clock::start();
    let scenario = &network.scenario;
    let mut node = Node {
        endpoints,
        media: scenario
            .interfaces(network.address)
            .into_iter()
            .filter_map(|k| scenario.media.get(k).map(|m| m.name.clone()))
            .collect(),
        next_endpoint: 0,
        router: network.router(),
        counts: NodeMetrics::default(),
        clock: &clock,
        end: SimTime::from_secs_f64(config.duration_s),
        stop,
    };
    let mut vehicles = Vec::new();
    let outcome = match role {
        Role::Operator => {
            vehicles = operator_ends(network, parts);
            node.operator(&mut vehicles, outputs)
        }
        Role::Rov => {
            let rov_config = RovConfig {
                address: network.address,
                heartbeat_timeout_s: network.timeout_s(),
                settings: config.settings,
                ..RovConfig::default()
            };
            let rov = RovEnd::new(Rov::with(rov_config, parts.drive, parts.camera));
            vehicles.push(Polled::new(network.address, None));
            match vehicles.first_mut() {
                Some(own) => node.rov(rov, own, outputs),
                None => Ok(false),
            }
        }
    };
    let ended = match outcome {
        Ok(true) => Ended::Done,
        Ok(false) => Ended::Stopped,
        Err(error) => Ended::Failed(error),
    };
    let duration_s = clock.now().min(node.end).as_secs_f64();
    let metrics = NetworkMetrics {
        measured_by: role.name(),
        duration_s,
        interrupted: None,
        seed: scenario.seed,
        cycle_s: network.cycle_s(),
        slots_s: scenario
            .cycle()
            .iter()
            .map(|s| (s.address.to_string(), s.length_s))
            .collect(),
        vehicles: vehicles
            .into_iter()
            .map(|v| (v.address.to_string(), v.finish(role, duration_s)))
            .collect(),
        nodes: [(network.address.to_string(), node.counts)].into(),
        media: BTreeMap::new(),
    };
    (metrics, ended)
}

/// The operator's ends, one per vehicle of the network, each at its slot of the cycle.
fn operator_ends(network: &Network, parts: Parts) -> Vec<Polled> {
    let scenario = &network.scenario;
    let vehicles = scenario.vehicles();
    let shared = split_by_vehicle(parts.orders, &vehicles);
    let cycle_s = network.cycle_s().max(super::session::MIN_IPG_S);
    let slots = scenario.cycle();
    vehicles
        .iter()
        .zip(shared)
        .map(|(&address, tap)| {
            let waypoints = scenario
                .node(address)
                .map_or(&[][..], |n| n.waypoints.as_slice());
            let sources: Vec<Box<dyn OrderSource>> =
                vec![Box::new(Script::new(&[], waypoints)), tap];
            let start_s = slots
                .iter()
                .find(|s| s.address == address)
                .map_or(0.0, |s| s.start_s);
            let mut end = OperatorEnd::new(address, cycle_s, sources)
                .first_slot_at(SimTime::from_secs_f64(start_s));
            end.answers_timeout_s = network.timeout_s();
            end.status_poses = true;
            Polled::new(address, Some(end))
        })
        .collect()
}

/// One vehicle as this node sees it: its operator end (at the operator), its counters.
struct Polled {
    address: u8,
    end: Option<OperatorEnd>,
    tally: Tally,
    /// Operator to ROV, ROV to operator.
    directions: [Direction; 2],
    round_trip_ms: Running,
    /// The last slot's send time, until its answer arrives.
    awaiting: Option<SimTime>,
    /// A slot went out while the one before was unanswered: the next answer is not timed.
    ambiguous: bool,
}

impl Polled {
    fn new(address: u8, end: Option<OperatorEnd>) -> Polled {
        Polled {
            address,
            end,
            tally: Tally::new(false),
            directions: [Direction::default(), Direction::default()],
            round_trip_ms: Running::new(),
            awaiting: None,
            ambiguous: false,
        }
    }

    fn finish(self, role: Role, duration_s: f64) -> Metrics {
        let mut metrics = self.tally.finish(role.name(), duration_s);
        metrics.operator_to_rov = self.directions[0].metrics(duration_s);
        metrics.rov_to_operator = self.directions[1].metrics(duration_s);
        if self.round_trip_ms.count() > 0 {
            metrics.round_trip_ms = Some(self.round_trip_ms.mean());
            metrics.round_trip_jitter_ms = Some(self.round_trip_ms.std());
        }
        metrics
    }
}

/// Runs `f` with an [`Out`] counting into `tally` and showing on `outputs` as `vehicle`'s.
fn with_out<R>(
    vehicle: u8,
    tally: &mut Tally,
    outputs: &mut NodeOutputs<'_>,
    f: impl FnOnce(&mut Out<'_>) -> R,
) -> R {
    let mut tagged = Tagged {
        vehicle,
        inner: &mut *outputs.observer,
    };
    f(&mut Out {
        tally,
        observer: &mut tagged,
    })
}

/// The direction of a frame from `src` to `dst`: towards the operator or away from it.
fn direction_of(src: u8, dst: u8) -> &'static str {
    if dst == 0 && src != 0 {
        "rov_to_operator"
    } else {
        "operator_to_rov"
    }
}

/// The event row of a frame heard at `t` and what the router made of it.
fn heard_event(bytes: &[u8], t: SimTime, decision: &Decision) -> FrameEvent {
    let (src, dst) = decision.addresses.unwrap_or((BROADCAST, BROADCAST));
    let fate = match (
        decision.deliver,
        decision.forward_on.is_empty(),
        decision.dropped,
    ) {
        (true, _, _) => "received",
        (false, false, _) => "forwarded",
        (false, true, Some(dropped)) => dropped.as_str(),
        (false, true, None) => "dropped",
    };
    FrameEvent {
        direction: direction_of(src, dst),
        kind: kind_of(bytes),
        bytes: bytes.len(),
        t_sent_s: None,
        t_received_s: Some(t.as_secs_f64()),
        fate,
    }
}

/// One node's endpoints, router and clock.
struct Node<'a> {
    endpoints: &'a mut [Box<dyn Endpoint>],
    /// The medium of each interface, by name.
    media: Vec<String>,
    /// The endpoint read first next time (two endpoints are read in turn).
    next_endpoint: usize,
    router: Router,
    counts: NodeMetrics,
    clock: &'a Clock,
    end: SimTime,
    stop: &'a AtomicBool,
}

impl Node<'_> {
    fn stopped(&self, outputs: &NodeOutputs<'_>) -> bool {
        self.stop.load(std::sync::atomic::Ordering::SeqCst) || outputs.failed()
    }

    fn medium(&self, k: usize) -> &str {
        self.media.get(k).map_or("", String::as_str)
    }

    /// Sends a frame this node originates for `dst` at `t`, and shows it.
    fn originate(
        &mut self,
        t: SimTime,
        dst: u8,
        frame: &[u8],
        direction: &'static str,
        outputs: &mut NodeOutputs<'_>,
    ) -> Result<(), GllError> {
        let k = self.router.interface_to(dst);
        if let Some(endpoint) = self.endpoints.get_mut(k) {
            endpoint.send(frame)?;
        }
        self.router.sent(t, frame);
        let addresses = Some((self.router.address(), dst));
        outputs.frame(&sent_event(direction, frame, t), addresses, self.medium(k));
        Ok(())
    }

    /// The next frame on any endpoint until `deadline`, with the interface it came on.
    fn receive(&mut self, deadline: Instant) -> Result<Option<(usize, Received)>, GllError> {
        let n = self.endpoints.len();
        if n <= 1 {
            return match self.endpoints.first_mut() {
                Some(endpoint) => Ok(endpoint.receive(deadline)?.map(|r| (0, r))),
                None => {
                    std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
                    Ok(None)
                }
            };
        }
        loop {
            for _ in 0..n {
                let k = self.next_endpoint % n;
                self.next_endpoint = (k + 1) % n;
                let slice = deadline.min(Instant::now() + SLICE);
                if let Some(endpoint) = self.endpoints.get_mut(k)
                    && let Some(received) = endpoint.receive(slice)?
                {
                    // The same endpoint first next time: what it still holds comes at once.
                    self.next_endpoint = k;
                    return Ok(Some((k, received)));
                }
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    /// Routes a frame heard at `t` on interface `k`: forwards it at once where the router
    /// says, shows it, and returns the decision.
    fn route(
        &mut self,
        t: SimTime,
        k: usize,
        bytes: &[u8],
        outputs: &mut NodeOutputs<'_>,
    ) -> Result<Decision, GllError> {
        let decision = self.router.decide(t, bytes, k);
        count(&mut self.counts, &decision);
        for &out in &decision.forward_on {
            if let Some(endpoint) = self.endpoints.get_mut(out) {
                endpoint.send(bytes)?;
            }
        }
        let event = heard_event(bytes, t, &decision);
        outputs.frame(&event, decision.addresses, self.medium(k));
        Ok(decision)
    }

    /// The operator's loop over every vehicle's end; `Ok(true)` when the duration ran out,
    /// `Ok(false)` when stopped.
    fn operator(
        &mut self,
        vehicles: &mut [Polled],
        outputs: &mut NodeOutputs<'_>,
    ) -> Result<bool, GllError> {
        let clock = self.clock;
        let mut drained = false;
        loop {
            if self.stopped(outputs) {
                return Ok(false);
            }
            let now = clock.now();
            if now >= self.end {
                return Ok(true);
            }
            let mut behind = false;
            for vehicle in vehicles.iter_mut() {
                let Some(end) = vehicle.end.as_mut() else {
                    continue;
                };
                let late = now.0.saturating_sub(end.slot_at().0) > 1_000_000;
                if end.slot_at() <= now && late && !drained {
                    // Late for the slot: what arrived meanwhile is read first, so a late
                    // answer is not timed against the new slot's frame.
                    behind = true;
                    continue;
                }
                let polled = with_out(vehicle.address, &mut vehicle.tally, outputs, |out| {
                    end.poll(now, out)
                });
                if let Some((frame, _)) = polled {
                    let direction = "operator_to_rov";
                    self.originate(now, vehicle.address, &frame, direction, outputs)?;
                    vehicle.directions[0].sent();
                    vehicle.ambiguous = vehicle.awaiting.is_some();
                    vehicle.awaiting = Some(now);
                }
            }
            drained = false;
            let wake = vehicles
                .iter()
                .filter_map(|v| v.end.as_ref().map(OperatorEnd::next_at))
                .min()
                .unwrap_or(self.end)
                .min(self.end);
            // Wake at least every 0.2 s to notice Ctrl-C and live orders.
            let mut deadline = clock
                .instant(wake)
                .min(Instant::now() + Duration::from_millis(200));
            if behind {
                drained = true;
                deadline = Instant::now() + Duration::from_millis(1);
            }
            let Some((k, received)) = self.receive(deadline)? else {
                continue;
            };
            if received.damaged {
                continue;
            }
            let t = clock.at(received.at);
            let decision = self.route(t, k, &received.bytes, outputs)?;
            let Some((src, _)) = decision.addresses.filter(|_| decision.deliver) else {
                continue;
            };
            let Some(vehicle) = vehicles.iter_mut().find(|v| v.address == src) else {
                continue;
            };
            vehicle.directions[1].delivered(t, received.bytes.len(), None);
            if let Some(sent) = vehicle.awaiting.take() {
                if vehicle.ambiguous {
                    vehicle.ambiguous = false;
                } else {
                    vehicle
                        .round_trip_ms
                        .push(t.0.saturating_sub(sent.0) as f64 * 1e-6);
                }
            }
            if let Some(end) = vehicle.end.as_mut() {
                with_out(vehicle.address, &mut vehicle.tally, outputs, |out| {
                    end.receive(t, &received.bytes, out);
                });
            }
        }
    }

    /// A vehicle's loop; `Ok(true)` when the duration ran out, `Ok(false)` when stopped.
    fn rov(
        &mut self,
        mut rov: RovEnd,
        own: &mut Polled,
        outputs: &mut NodeOutputs<'_>,
    ) -> Result<bool, GllError> {
        let clock = self.clock;
        let mut last = SimTime::ZERO;
        loop {
            if self.stopped(outputs) {
                return Ok(false);
            }
            let now = clock.now().max(last);
            if now >= self.end {
                return Ok(true);
            }
            with_out(own.address, &mut own.tally, outputs, |out| {
                rov.poll(now, out)
            });
            last = now;
            let deadline = clock
                .instant(rov.next_at().min(self.end))
                .min(Instant::now() + Duration::from_millis(200));
            let Some((k, received)) = self.receive(deadline)? else {
                continue;
            };
            if received.damaged {
                continue;
            }
            let t = clock.at(received.at).max(last);
            let decision = self.route(t, k, &received.bytes, outputs)?;
            if !decision.deliver {
                continue;
            }
            own.directions[0].delivered(t, received.bytes.len(), None);
            let reply = with_out(own.address, &mut own.tally, outputs, |out| {
                rov.receive(t, &received.bytes, None, out)
            });
            if let Some(reply) = reply {
                let sent_at = clock.now().max(t);
                self.originate(sent_at, 0, &reply, "rov_to_operator", outputs)?;
                own.directions[1].sent();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;
    use std::sync::mpsc::{Receiver, Sender, channel};

    use super::*;
    use crate::rcp::network::QuietNet;
    use crate::rcp::session::Waypoint;

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
                        images: vec![crate::rcp::test_image(64, 48, 1)],
                    };
                    let mut parts = Parts::from_config(&config);
                    // A console line naming vehicle 1: a HoldHeading order for it alone.
                    let hold = crate::wire::operator::Order::HoldHeading {
                        heading_deg: 90,
                        enable: true,
                    };
                    let console = Script::addressed(vec![(
                        SimTime::from_secs_f64(0.2),
                        Some(1),
                        crate::rcp::orders::Live::Order(hold),
                    )]);
                    parts.orders.push(Box::new(console));
                    let mut endpoints: Vec<Box<dyn Endpoint>> = vec![Box::new(Bus { rx, peers })];
                    let mut outputs = NodeOutputs {
                        observer: &mut QuietNet,
                        frames: None,
                    };
                    let (metrics, ended) = run(
                        role,
                        &config,
                        &network,
                        parts,
                        &mut endpoints,
                        &stop,
                        &mut outputs,
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
