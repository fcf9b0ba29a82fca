//! A multi-vehicle session in virtual time: the operator, every vehicle and every medium of a
//! [`Scenario`] in one process, with routing over relays.
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

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicBool, Ordering};

use serde::Serialize;

use super::camera::Cycle;
use super::drive::SimDrive;
use super::harness::{OperatorEnd, Out, RovEnd, Tally};
use super::operator::SlotContent;
use super::orders::Script;
use super::routing::Router;
use super::rov::{Rov, RovConfig};
use super::rules;
use super::scenario::Scenario;
use super::session::{Direction, FrameEvent, Metrics, Observer, STOPPED, kind_of};
use super::{Event, PoseSample, Role};
use crate::debt;
use crate::link::{Fate, Medium, ModelError, SimTime};
use crate::wire::frame::Frame;

/// What one node's router did.
#[derive(Debug, Clone, Default, Serialize, PartialEq, Eq)]
pub struct NodeMetrics {
    /// Frames it heard intact.
    pub frames_heard: u64,
    /// Of those, taken by its own engine.
    pub frames_delivered: u64,
    /// Frames it forwarded (each onto one interface counts once).
    pub frames_forwarded: u64,
    /// Copies dropped as duplicates (overheard again, or its own forward coming back).
    pub duplicates_dropped: u64,
    /// Frames for others, not on its routed path.
    pub off_path_dropped: u64,
    /// Its own frames relayed back to it.
    pub own_dropped: u64,
    /// Forwards towards the node the frame was heard from (must be 0).
    pub forwarded_back: u64,
}

/// What crossed one medium.
#[derive(Debug, Clone, Default, Serialize, PartialEq, Eq)]
pub struct MediumMetrics {
    /// Transmissions (origins and forwards).
    pub transmissions: u64,
    /// Receptions that arrived intact.
    pub receptions_delivered: u64,
    /// Receptions lost in a collision at their receiver.
    pub receptions_collided: u64,
    /// Receptions out of range.
    pub receptions_out_of_range: u64,
    /// Receptions lost otherwise (loss, bit errors, overflow, corruption).
    pub receptions_lost: u64,
}

/// A scenario's figures (`--metrics`).
#[derive(Debug, Clone, Default, Serialize)]
pub struct NetworkMetrics {
    /// `simulation`.
    pub measured_by: &'static str,
    /// Session length, s: the time reached when the run was interrupted.
    pub duration_s: f64,
    /// Why the run ended early; absent when it ran its whole duration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interrupted: Option<String>,
    /// The seed.
    pub seed: u64,
    /// The TDMA cycle, s.
    pub cycle_s: f64,
    /// Each vehicle's slot, s, by address.
    pub slots_s: BTreeMap<String, f64>,
    /// Each vehicle's session figures, by address (the single-vehicle session's fields, end to
    /// end over its routed path).
    pub vehicles: BTreeMap<String, Metrics>,
    /// Each node's routing figures, by address.
    pub nodes: BTreeMap<String, NodeMetrics>,
    /// Each medium's figures, by name.
    pub media: BTreeMap<String, MediumMetrics>,
}

/// One reception of one frame at one node: a row of `--events` in a scenario.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HopEvent {
    /// The medium's name.
    pub medium: String,
    /// The frame's SRC and DST (none when it does not parse).
    pub src: Option<u8>,
    /// The frame's DST.
    pub dst: Option<u8>,
    /// The node that transmitted this copy.
    pub tx: u8,
    /// The node this row is about.
    pub rx: u8,
    /// velocity, goto, ..., image_trunk, status, raw.
    pub kind: &'static str,
    /// Frame length.
    pub bytes: usize,
    /// When `tx` offered it, s.
    pub t_sent_s: f64,
    /// When it arrived at `rx`, s (none when lost).
    pub t_received_s: Option<f64>,
    /// The medium's fate for it at `rx`.
    pub fate: &'static str,
    /// What `rx` did: `delivered`, `forwarded`, `delivered+forwarded`, or why it dropped it
    /// (`duplicate`, `off_path`, `own`, `malformed`); empty when it did not arrive intact.
    pub action: &'static str,
}

/// What a scenario's outputs see.
pub trait NetObserver {
    /// A frame's fate at one receiver is known.
    fn hop(&mut self, _event: &HopEvent) {}
    /// The operator completed an image of `vehicle` at `t_s`.
    fn image(&mut self, _vehicle: u8, _t_s: f64, _stream: &[u8]) {}
    /// `vehicle` after a step.
    fn pose(&mut self, _vehicle: u8, _pose: &PoseSample) {}
    /// Something happened at `end` of `vehicle`'s session.
    fn event(&mut self, _vehicle: u8, _end: Role, _t_s: f64, _event: &Event) {}
    /// Something to tell the user.
    fn warning(&mut self, _t_s: f64, _text: &str) {}
    /// A frame this node sent or received (a real-time node of a network, which sees its own
    /// frames, not the network's hops).
    fn node_frame(&mut self, _event: &FrameEvent) {}
    /// True once the observer can record nothing more: the run ends at the next event.
    fn failed(&self) -> bool {
        false
    }
}

/// Several network observers, each seeing everything in turn (failed once any has).
pub struct NetTee<'a>(pub Vec<&'a mut dyn NetObserver>);

impl NetObserver for NetTee<'_> {
    fn hop(&mut self, event: &HopEvent) {
        self.0.iter_mut().for_each(|o| o.hop(event));
    }

    fn image(&mut self, vehicle: u8, t_s: f64, stream: &[u8]) {
        self.0
            .iter_mut()
            .for_each(|o| o.image(vehicle, t_s, stream));
    }

    fn pose(&mut self, vehicle: u8, pose: &PoseSample) {
        self.0.iter_mut().for_each(|o| o.pose(vehicle, pose));
    }

    fn event(&mut self, vehicle: u8, end: Role, t_s: f64, event: &Event) {
        self.0
            .iter_mut()
            .for_each(|o| o.event(vehicle, end, t_s, event));
    }

    fn warning(&mut self, t_s: f64, text: &str) {
        self.0.iter_mut().for_each(|o| o.warning(t_s, text));
    }

    fn node_frame(&mut self, event: &FrameEvent) {
        self.0.iter_mut().for_each(|o| o.node_frame(event));
    }

    fn failed(&self) -> bool {
        self.0.iter().any(|o| o.failed())
    }
}

/// A network observer that observes nothing.
pub struct QuietNet;

impl NetObserver for QuietNet {}

/// One vehicle's session as a single-vehicle [`Observer`] sees it.
pub(crate) struct Tagged<'a> {
    pub(crate) vehicle: u8,
    pub(crate) inner: &'a mut dyn NetObserver,
}

impl Observer for Tagged<'_> {
    fn image(&mut self, t_s: f64, stream: &[u8]) {
        self.inner.image(self.vehicle, t_s, stream);
    }

    fn pose(&mut self, pose: &PoseSample) {
        self.inner.pose(self.vehicle, pose);
    }

    fn event(&mut self, end: Role, t_s: f64, event: &Event) {
        self.inner.event(self.vehicle, end, t_s, event);
    }

    fn warning(&mut self, t_s: f64, text: &str) {
        self.inner.warning(t_s, text);
    }

    fn failed(&self) -> bool {
        self.inner.failed()
    }
}

/// A frame an origin sent, until its destination takes it.
struct Origin {
    t_sent: SimTime,
    /// The high-level order an operator frame carries.
    order: Option<u64>,
}

/// One vehicle's session: both ends, its counters.
struct Vehicle {
    operator: OperatorEnd,
    rov: RovEnd,
    tally: Tally,
    /// Operator to ROV, ROV to operator.
    directions: [Direction; 2],
}

/// A frame's identity for matching copies to their origin: its bytes' hash.
fn frame_key(bytes: &[u8]) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    bytes.hash(&mut hasher);
    hasher.finish()
}

/// The whole network and its clock.
struct Net<'a> {
    scenario: &'a Scenario,
    media: Vec<Medium>,
    /// Per medium, the address of each of its nodes (its index on the medium).
    members: Vec<Vec<u8>>,
    routers: BTreeMap<u8, Router>,
    vehicles: BTreeMap<u8, Vehicle>,
    /// Frames in flight by (vehicle, key).
    origins: HashMap<(u8, u64), Origin>,
    /// What each frame in flight on a medium is, by (medium, sender index, seq), with the
    /// receivers' reports still to come.
    kinds: HashMap<(usize, usize, u64), (&'static str, usize)>,
    node_metrics: BTreeMap<u8, NodeMetrics>,
    medium_metrics: Vec<MediumMetrics>,
    cycle_s: f64,
    last_prune: SimTime,
}

impl Net<'_> {
    /// The interfaces (media indices) of `address`.
    fn medium_of(&self, address: u8, interface: usize) -> Option<usize> {
        self.scenario.interfaces(address).get(interface).copied()
    }

    fn index_on(&self, medium: usize, address: u8) -> Option<usize> {
        self.members[medium].iter().position(|&a| a == address)
    }

    /// `address` transmits `bytes` on its interface `interface` at `t`.
    fn transmit(&mut self, t: SimTime, address: u8, interface: usize, bytes: Vec<u8>) {
        let Some(medium) = self.medium_of(address, interface) else {
            return;
        };
        let Some(index) = self.index_on(medium, address) else {
            return;
        };
        let kind = kind_of(&bytes);
        let link = &mut self.media[medium];
        link.advance(t);
        let receivers = link.nodes().saturating_sub(1);
        let seq = link.offer(index, bytes);
        self.kinds.insert((medium, index, seq), (kind, receivers));
        self.medium_metrics[medium].transmissions += 1;
    }

    /// `address` originates `bytes` (for `dst`) at `t`.
    fn originate(&mut self, t: SimTime, address: u8, bytes: Vec<u8>, order: Option<u64>) {
        let Some(router) = self.routers.get_mut(&address) else {
            return;
        };
        router.sent(t, &bytes);
        let Ok(frame) = Frame::new_checked(&bytes[..]) else {
            return;
        };
        let (src, dst) = (frame.src(), frame.dst());
        let interface = router.interface_to(dst);
        let vehicle = if src == 0 { dst } else { src };
        if let Some(v) = self.vehicles.get_mut(&vehicle) {
            v.directions[usize::from(src != 0)].sent();
        }
        self.origins
            .insert((vehicle, frame_key(&bytes)), Origin { t_sent: t, order });
        self.transmit(t, address, interface, bytes);
    }

    /// Forgets origins older than four cycles (frames that never arrived).
    fn prune(&mut self, now: SimTime) {
        let horizon_ns = (4.0 * self.cycle_s * 1e9) as u64;
        if now.0.saturating_sub(self.last_prune.0) < horizon_ns {
            return;
        }
        self.last_prune = now;
        self.origins
            .retain(|_, o| now.0.saturating_sub(o.t_sent.0) < horizon_ns);
    }
}

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
/// there with the figures so far and `interrupted` set to [`STOPPED`].
pub fn run(
    scenario: &Scenario,
    images: &[debt::Image],
    observer: &mut dyn NetObserver,
    stop: &AtomicBool,
) -> Result<NetworkMetrics, NetworkError> {
    let cycle = scenario.cycle();
    let cycle_s = scenario.cycle_s();
    let duplicate_window_s = rules::duplicate_window_s(cycle_s);
    let timeout_s = rules::link_timeout_s(cycle_s);
    let mut media = Vec::new();
    let mut members = Vec::new();
    for (k, spec) in scenario.media.iter().enumerate() {
        let positions = spec
            .nodes
            .iter()
            .map(|&a| scenario.node(a).map_or([0.0; 3], |n| n.position_m))
            .collect();
        let medium = Medium::new(
            spec.model.clone(),
            scenario.seed.wrapping_add(k as u64),
            positions,
        )
        .map_err(|error| NetworkError::Model {
            name: spec.name.clone(),
            error,
        })?;
        media.push(medium);
        members.push(spec.nodes.clone());
    }
    let routers = scenario
        .nodes
        .iter()
        .map(|n| {
            let router = Router::new(
                n.address,
                scenario.routes.clone(),
                scenario.neighbours(n.address),
                duplicate_window_s,
            );
            (n.address, router)
        })
        .collect();
    let mut vehicles = BTreeMap::new();
    for (k, slot) in cycle.iter().enumerate() {
        let Some(node) = scenario.node(slot.address) else {
            continue;
        };
        let script = Script::new(&[], &node.waypoints);
        let mut operator = OperatorEnd::new(slot.address, cycle_s, vec![Box::new(script)])
            .first_slot_at(SimTime::from_secs_f64(slot.start_s));
        operator.answers_timeout_s = timeout_s;
        let rov_config = RovConfig {
            address: slot.address,
            heartbeat_timeout_s: timeout_s,
            settings: scenario.settings,
            ..RovConfig::default()
        };
        let mut pictures = images.to_vec();
        if !pictures.is_empty() {
            let turn = k % pictures.len();
            pictures.rotate_left(turn);
        }
        let rov = RovEnd::new(Rov::with(
            rov_config,
            Box::new(SimDrive::new(node.position_m)),
            Box::new(Cycle::new(pictures)),
        ));
        vehicles.insert(
            slot.address,
            Vehicle {
                operator,
                rov,
                tally: Tally::new(true),
                directions: [Direction::default(), Direction::default()],
            },
        );
    }
    let mut net = Net {
        scenario,
        medium_metrics: vec![MediumMetrics::default(); media.len()],
        media,
        members,
        routers,
        vehicles,
        origins: HashMap::new(),
        kinds: HashMap::new(),
        node_metrics: scenario
            .nodes
            .iter()
            .map(|n| (n.address, NodeMetrics::default()))
            .collect(),
        cycle_s,
        last_prune: SimTime::ZERO,
    };
    let end = SimTime::from_secs_f64(scenario.duration_s);
    let mut stopped_at = None;
    loop {
        let medium_next = net.media.iter().filter_map(Medium::next_event_time).min();
        let ends_next = net
            .vehicles
            .values()
            .flat_map(|v| [v.operator.next_at(), v.rov.next_at()])
            .min();
        let Some(t) = [medium_next, ends_next].into_iter().flatten().min() else {
            break;
        };
        if t > end {
            break;
        }
        if stop.load(Ordering::Relaxed) || observer.failed() {
            stopped_at = Some((t, stop.load(Ordering::Relaxed)));
            break;
        }
        if medium_next == Some(t) {
            for k in 0..net.media.len() {
                if net.media[k].next_event_time() == Some(t) {
                    net.media[k].step();
                }
            }
        } else {
            let addresses: Vec<u8> = net.vehicles.keys().copied().collect();
            for v in addresses {
                step_vehicle(&mut net, v, t, observer);
            }
        }
        drain_reports(&mut net, observer);
        net.prune(t);
    }
    let (duration_s, interrupted) = match stopped_at {
        Some((t, by_stop)) => (
            t.as_secs_f64().min(scenario.duration_s),
            by_stop.then(|| STOPPED.to_string()),
        ),
        None => (scenario.duration_s, None),
    };
    let mut metrics = NetworkMetrics {
        measured_by: "simulation",
        duration_s,
        interrupted,
        seed: scenario.seed,
        cycle_s,
        slots_s: cycle
            .iter()
            .map(|s| (s.address.to_string(), s.length_s))
            .collect(),
        ..NetworkMetrics::default()
    };
    for (address, v) in net.vehicles {
        let mut m = v.tally.finish("simulation", duration_s);
        m.operator_to_rov = v.directions[0].metrics(duration_s);
        m.rov_to_operator = v.directions[1].metrics(duration_s);
        m.interrupted = metrics.interrupted.clone();
        metrics.vehicles.insert(address.to_string(), m);
    }
    metrics.nodes = net
        .node_metrics
        .into_iter()
        .map(|(a, m)| (a.to_string(), m))
        .collect();
    metrics.media = scenario
        .media
        .iter()
        .zip(net.medium_metrics)
        .map(|(spec, m)| (spec.name.clone(), m))
        .collect();
    Ok(metrics)
}

/// Runs what vehicle `v`'s two ends have due at `t`.
fn step_vehicle(net: &mut Net<'_>, v: u8, t: SimTime, observer: &mut dyn NetObserver) {
    let Some(vehicle) = net.vehicles.get_mut(&v) else {
        return;
    };
    let mut tagged = Tagged {
        vehicle: v,
        inner: observer,
    };
    let mut out = Out {
        tally: &mut vehicle.tally,
        observer: &mut tagged,
    };
    let mut slot = None;
    if vehicle.operator.next_at() == t {
        slot = vehicle.operator.poll(t, &mut out);
    }
    let moved = vehicle.rov.next_at() == t;
    if moved {
        vehicle.rov.poll(t, &mut out);
    }
    let position_m = vehicle.rov.engine.state().position_m;
    if let Some((frame, content)) = slot {
        let order = match content {
            SlotContent::Order(index) => Some(index),
            SlotContent::Velocity => None,
        };
        net.originate(t, 0, frame, order);
    }
    if moved {
        for medium in net.scenario.interfaces(v) {
            if let Some(index) = net.index_on(medium, v) {
                net.media[medium].set_position(index, position_m);
            }
        }
    }
}

/// Handles every report the media have: counts it, shows it, and gives what arrived intact to
/// its receiver's router.
fn drain_reports(net: &mut Net<'_>, observer: &mut dyn NetObserver) {
    loop {
        let Some((medium, report)) =
            (0..net.media.len()).find_map(|k| net.media[k].pop_report().map(|r| (k, r)))
        else {
            return;
        };
        let key = (medium, report.from, report.seq);
        let kind = match net.kinds.get_mut(&key) {
            Some((kind, left)) => {
                let kind = *kind;
                if !report.duplicate {
                    *left = left.saturating_sub(1);
                    if *left == 0 {
                        net.kinds.remove(&key);
                    }
                }
                kind
            }
            None => "raw",
        };
        let tx = net.members[medium].get(report.from).copied().unwrap_or(0);
        let rx = net.members[medium].get(report.to).copied().unwrap_or(0);
        let metrics = &mut net.medium_metrics[medium];
        match report.fate {
            Fate::Delivered => metrics.receptions_delivered += 1,
            Fate::Collision => metrics.receptions_collided += 1,
            Fate::Range => metrics.receptions_out_of_range += 1,
            _ => metrics.receptions_lost += 1,
        }
        let parsed = Frame::new_checked(&report.bytes[..])
            .ok()
            .map(|f| (f.src(), f.dst()));
        let mut event = HopEvent {
            medium: net.scenario.media[medium].name.clone(),
            src: parsed.map(|p| p.0),
            dst: parsed.map(|p| p.1),
            tx,
            rx,
            kind,
            bytes: report.len,
            t_sent_s: report.t_offered.as_secs_f64(),
            t_received_s: report.t_rx.map(SimTime::as_secs_f64),
            fate: report.fate.as_str(),
            action: "",
        };
        if report.fate == Fate::Delivered
            && let Some(t) = report.t_rx
        {
            event.action = receive(net, medium, tx, rx, t, report.bytes, observer);
        }
        observer.hop(&event);
    }
}

/// Node `rx` heard `bytes` intact on `medium` from `tx` at `t`; what it did.
fn receive(
    net: &mut Net<'_>,
    medium: usize,
    tx: u8,
    rx: u8,
    t: SimTime,
    bytes: Vec<u8>,
    observer: &mut dyn NetObserver,
) -> &'static str {
    let interface = net
        .scenario
        .interfaces(rx)
        .iter()
        .position(|&m| m == medium)
        .unwrap_or(0);
    let Some(router) = net.routers.get_mut(&rx) else {
        return "";
    };
    let decision = router.decide(t, &bytes, interface);
    let node = net.node_metrics.entry(rx).or_default();
    node.frames_heard += 1;
    if let Some(dropped) = decision.dropped {
        match dropped {
            super::routing::Dropped::Duplicate => node.duplicates_dropped += 1,
            super::routing::Dropped::OffPath => node.off_path_dropped += 1,
            super::routing::Dropped::Own => node.own_dropped += 1,
            super::routing::Dropped::Malformed => {}
        }
        return dropped.as_str();
    }
    let Some((src, dst)) = decision.addresses else {
        return "";
    };
    let forwarded_back = decision
        .forward_on
        .iter()
        .filter(|&&k| {
            net.scenario.routes.next_hop(rx, dst) == tx
                && net
                    .scenario
                    .neighbours(rx)
                    .get(k)
                    .is_some_and(|reach| reach.contains(&tx))
        })
        .count() as u64;
    node.frames_forwarded += decision.forward_on.len() as u64;
    node.forwarded_back += forwarded_back;
    for &k in &decision.forward_on {
        net.transmit(t, rx, k, bytes.clone());
    }
    if decision.deliver {
        net.node_metrics.entry(rx).or_default().frames_delivered += 1;
        deliver(net, rx, src, t, bytes, observer);
    }
    match (decision.deliver, decision.forward_on.is_empty()) {
        (true, true) => "delivered",
        (true, false) => "delivered+forwarded",
        (false, false) => "forwarded",
        (false, true) => "",
    }
}

/// Node `rx`'s engine takes a frame from `src` at `t`.
fn deliver(
    net: &mut Net<'_>,
    rx: u8,
    src: u8,
    t: SimTime,
    bytes: Vec<u8>,
    observer: &mut dyn NetObserver,
) {
    let vehicle_address = if rx == 0 { src } else { rx };
    let origin = net.origins.remove(&(vehicle_address, frame_key(&bytes)));
    let Some(vehicle) = net.vehicles.get_mut(&vehicle_address) else {
        return;
    };
    let delay_ms = origin
        .as_ref()
        .map(|o| t.0.saturating_sub(o.t_sent.0) as f64 * 1e-6);
    vehicle.directions[usize::from(rx == 0)].delivered(t, bytes.len(), delay_ms);
    let mut tagged = Tagged {
        vehicle: vehicle_address,
        inner: observer,
    };
    let mut out = Out {
        tally: &mut vehicle.tally,
        observer: &mut tagged,
    };
    if rx == 0 {
        vehicle.operator.receive(t, &bytes, &mut out);
        return;
    }
    let order = origin.and_then(|o| o.order);
    if let Some(reply) = vehicle.rov.receive(t, &bytes, order, &mut out) {
        net.originate(t, rx, reply, None);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// The issue's scenario.
    pub(crate) const THREE: &str = r#"{"duration_s":600,"seed":1,
      "nodes":[{"address":0,"role":"operator","position":[0,0,0]},
               {"address":1,"role":"rov","start":[3,0,1]},
               {"address":2,"role":"rov","start":[7,0,1],"waypoints":[[30,7.5,1,1,90]]}],
      "media":[{"name":"rf","model":"s100","nodes":[0,1,2]}],
      "routes":{"0":{"2":1},"2":{"0":1}}}"#;

    fn scenario(text: &str) -> Scenario {
        Scenario::parse(text, Path::new(".")).unwrap()
    }

    fn images() -> Vec<debt::Image> {
        vec![super::super::test_image(160, 120, 1)]
    }

    fn run_quiet(s: &Scenario) -> NetworkMetrics {
        run(s, &images(), &mut QuietNet, &AtomicBool::new(false)).unwrap()
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
        let m = run(&scenario(THREE), &images(), &mut QuietNet, &stop).unwrap();
        assert_eq!(m.interrupted.as_deref(), Some(STOPPED));
        assert!(m.duration_s < 1.0);
    }
}
