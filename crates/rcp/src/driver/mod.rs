//! The one session driver: every kind of session (one vehicle or a network, simulated or over
//! real modems) is the same loop over the same ends.
//!
//! A session is a network ([`Scenario`]: nodes, media, routes); a single vehicle is a
//! one-vehicle network (the operator and the vehicle on one medium, [`SINGLE_MEDIUM`]). The
//! driver holds the nodes that run here: every node in a simulation, one node per process in
//! real time. Each node is a [`Router`] in front of its engines: the operator holds one
//! [`OperatorEnd`] per vehicle, a vehicle its [`RovEnd`]. What carries the frames and keeps
//! the time is the [`Air`]:
//!
//! - [`SimAir`]: the simulated media ([`Medium`](rovlink_link::Medium), one per medium of the scenario) in virtual
//!   time; the clock jumps to the next event, or, [`Pace`]d, waits for it on the wall clock
//!   (`--pace X`: X times real time, to watch a simulation live; the same results).
//! - [`PortAir`]: the node's real endpoints (serial ports, pseudo-terminals, sockets), one
//!   per interface, with the host's monotonic clock; a wait ends at the next thing due, a
//!   frame read, or [`WAKE_EVERY`] at most (so a stop is seen at once).
//!
//! The loop ([`run`]): the air advances to the earliest of its own next event and the next
//! thing an end has due, returning what it heard; every frame heard intact goes through the
//! receiving node's router (delivered to the engine it is for, forwarded unchanged at once on
//! the interfaces the router names, or dropped), its row of `--events` shown first; then every
//! end due runs (an operator end's slot, its orders, a vehicle step), and what an origin sends
//! goes out on the interface of its next hop. In virtual time the ends run only at their own
//! instants; in real time every wake-up also drains the live order sources.
//!
//! Each rule is written once, here or in [`crate::rules`]: a frame counts as sent when its
//! origin sends it and as delivered when its destination takes it, with the delay between the
//! two when this process saw both (a simulation; in real time one-way delays need both ends'
//! clocks, so the operator times round trips instead, see [`RoundTrips`]); an operator end
//! more than [`LATE_NS`] late for its slot reads what arrived meanwhile first (never in
//! virtual time: the clock waits for it).
//!
//! No-panic, no-hang contract: any bytes heard are routed or dropped, never a panic; a run
//! ends at its duration, when `stop` is set, when the observer has failed, or when an
//! endpoint fails ([`Ended`]).
//!
//! This module holds the loop and what it keeps ([`Setup`], [`Ended`], the counters); the rest
//! is one file per part, re-exported here: `air` (the [`Air`] trait, [`Heard`], [`Tick`]),
//! `sim_air` ([`SimAir`]), `pace` ([`Pace`]), `port_air` ([`PortAir`]), `clock` ([`Clock`]),
//! `round_trips` ([`RoundTrips`]) and `ends` (the ends a node holds: [`VehicleEnds`],
//! [`operator_end`], [`rov_end`], [`router`]).

mod air;
mod clock;
mod ends;
mod pace;
mod port_air;
mod round_trips;
mod sim_air;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::harness::{OperatorEnd, Out, RovEnd, Tally};
use crate::operator::SlotContent;
use crate::report::{
    Direction, FrameEvent, NetworkMetrics, NodeMetrics, Observer, STOPPED, direction_of,
};
use crate::routing::{Dropped, Router};
use crate::scenario::Scenario;
use rovlink_link::SimTime;
use rovlink_link::gll::GllError;
use rovlink_security::{Guard, Refusal};
use rovlink_wire::frame::Frame;

pub use crate::report::SINGLE_MEDIUM;
pub use air::{Air, Heard, Tick};
pub use clock::{Clock, WAKE_EVERY};
pub use ends::{VehicleEnds, operator_end, router, rov_end};
pub use pace::{MAX_PACE, MIN_PACE, PACE_POLL, Pace};
pub use port_air::{DRAIN_WAIT, PortAir, SLICE};
pub use round_trips::RoundTrips;
pub use sim_air::SimAir;

/// How late an operator may send a slot's frame, ns: later than that, what arrived meanwhile is
/// read first, so that a late answer is not timed against the new slot's frame.
pub const LATE_NS: u64 = 1_000_000;

/// How a run ended.
#[derive(Debug)]
pub enum Ended {
    /// The session ran its whole duration.
    Done,
    /// Stopped early (`stop`, or an output failed); the figures cover the time until then.
    Stopped,
    /// An endpoint failed; the figures cover the time until then.
    Failed(GllError),
}

/// True when a slot due at `slot_at` is more than [`LATE_NS`] behind `now`.
pub fn is_late(now: SimTime, slot_at: SimTime) -> bool {
    now.0.saturating_sub(slot_at.0) > LATE_NS
}

/// A frame's SRC and DST, when it parses.
fn addresses(bytes: &[u8]) -> Option<(u8, u8)> {
    Frame::new_checked(bytes).ok().map(|f| (f.src(), f.dst()))
}

/// One vehicle's session: the ends, its counters.
struct Vehicle {
    ends: VehicleEnds,
    tally: Tally,
    /// Operator to ROV, ROV to operator.
    directions: [Direction; 2],
    /// The operator's round trips, timed in real time.
    round_trips: Option<RoundTrips>,
}

/// A frame an origin sent, until its destination takes it.
struct Origin {
    t_sent: SimTime,
    /// The high-level order an operator frame carries.
    order: Option<u64>,
}

/// A frame's identity for matching copies to their origin: its bytes' hash.
fn frame_key(bytes: &[u8]) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    bytes.hash(&mut hasher);
    hasher.finish()
}

/// What [`run`] runs: the network, the nodes that run here, their ends.
pub struct Setup<'a> {
    /// The network.
    pub scenario: &'a Scenario,
    /// The addresses of the nodes this process runs (all of them in a simulation).
    pub nodes: Vec<u8>,
    /// Each vehicle's ends held here, by address.
    pub vehicles: BTreeMap<u8, VehicleEnds>,
    /// Whose figures: `simulation`, or the real-time node's role.
    pub measured_by: &'static str,
    /// Length of the run, s.
    pub duration_s: f64,
    /// The routers' duplicate window, s ([`crate::rules::duplicate_window_s`] of the cycle; 0 for
    /// none, where a node does not know the far end's cycle).
    pub duplicate_window_s: f64,
    /// Each secured node's guard, by address ([`crate::secure`]): it seals what the node
    /// originates and opens what the node's engines take; a frame it refuses reaches no
    /// engine. Empty: the paper's plain frames.
    pub guards: BTreeMap<u8, Guard>,
}

/// The nodes this process runs, their ends and counters.
struct Net<'a> {
    scenario: &'a Scenario,
    routers: BTreeMap<u8, Router>,
    vehicles: BTreeMap<u8, Vehicle>,
    /// Frames in flight by (vehicle, key).
    origins: HashMap<(u8, u64), Origin>,
    nodes: BTreeMap<u8, NodeMetrics>,
    cycle_s: f64,
    last_prune: SimTime,
    guards: BTreeMap<u8, Guard>,
    /// What has been said once (refusals per node and source, sealing failures).
    told: BTreeSet<String>,
}

/// Runs `setup` over `air` until its duration has passed, `stop` is set, the observer has
/// failed, or an endpoint fails; the figures cover the time reached (`interrupted` is
/// [`STOPPED`] when `stop` ended it).
pub fn run<A: Air>(
    setup: Setup<'_>,
    air: &mut A,
    stop: &AtomicBool,
    observer: &mut dyn Observer,
) -> (NetworkMetrics, Ended) {
    let scenario = setup.scenario;
    let cycle_s = scenario.cycle_s();
    let routers = setup
        .nodes
        .iter()
        .map(|&a| (a, router(scenario, a, setup.duplicate_window_s)))
        .collect();
    let real_time = air.real_time();
    let poses_every_step = observer.wants_poses();
    let vehicles = setup
        .vehicles
        .into_iter()
        .map(|(a, mut ends)| {
            if let Some(rov) = ends.rov.as_mut() {
                rov.poses_every_step = poses_every_step;
            }
            let both = ends.operator.is_some() && ends.rov.is_some();
            let round_trips = (real_time && ends.operator.is_some()).then(RoundTrips::default);
            let vehicle = Vehicle {
                ends,
                tally: Tally::new(both),
                directions: [Direction::default(), Direction::default()],
                round_trips,
            };
            (a, vehicle)
        })
        .collect();
    let mut net = Net {
        scenario,
        routers,
        vehicles,
        origins: HashMap::new(),
        nodes: setup
            .nodes
            .iter()
            .map(|&a| (a, NodeMetrics::default()))
            .collect(),
        cycle_s,
        last_prune: SimTime::ZERO,
        guards: setup.guards,
        told: BTreeSet::new(),
    };
    let end = SimTime::from_secs_f64(setup.duration_s);
    let mut drain = false;
    let ended = loop {
        if stop.load(Ordering::SeqCst) || observer.failed() {
            break Ended::Stopped;
        }
        let due = net.next_at().unwrap_or(SimTime(end.0.saturating_add(1)));
        let drained = drain;
        let tick = match air.advance(due, end, drained) {
            Ok(tick) => tick,
            Err(error) => break Ended::Failed(error),
        };
        drain = false;
        if let Err(error) = net.hear(air, observer) {
            break Ended::Failed(error);
        }
        match tick {
            Tick::Over => break Ended::Done,
            Tick::Air(t) => net.prune(t),
            Tick::Ends(t) => {
                match net.run_ends(air, t, real_time, drained, observer) {
                    Ok(behind) => drain = behind,
                    Err(error) => break Ended::Failed(error),
                }
                if let Err(error) = net.hear(air, observer) {
                    break Ended::Failed(error);
                }
                net.prune(t);
            }
        }
    };
    let duration_s = match ended {
        Ended::Done => setup.duration_s,
        _ => air.now().as_secs_f64().min(setup.duration_s),
    };
    let interrupted = stop.load(Ordering::SeqCst).then(|| STOPPED.to_string());
    let mut metrics = NetworkMetrics {
        measured_by: setup.measured_by,
        duration_s,
        interrupted: interrupted.clone(),
        seed: scenario.seed,
        cycle_s,
        slots_s: scenario
            .cycle()
            .iter()
            .map(|s| (s.address.to_string(), s.length_s))
            .collect(),
        ..NetworkMetrics::default()
    };
    for (address, v) in net.vehicles {
        let mut m = v.tally.finish(setup.measured_by, duration_s);
        m.operator_to_rov = v.directions[0].metrics(duration_s);
        m.rov_to_operator = v.directions[1].metrics(duration_s);
        if let Some(round_trips) = &v.round_trips {
            round_trips.fill(&mut m);
        }
        m.interrupted = interrupted.clone();
        metrics.vehicles.insert(address.to_string(), m);
    }
    for (address, guard) in &mut net.guards {
        if let Err(error) = guard.sync() {
            observer.warning(duration_s, &format!("node {address}: {error}"));
        }
    }
    for (&address, node) in &net.nodes {
        for (src, reasons) in &node.refused {
            let vehicle = if address == 0 {
                src.clone()
            } else {
                address.to_string()
            };
            if let Some(m) = metrics.vehicles.get_mut(&vehicle) {
                let into = m.frames_refused.entry(src.clone()).or_default();
                for (reason, n) in reasons {
                    *into.entry(reason).or_default() += n;
                }
            }
        }
    }
    metrics.nodes = net
        .nodes
        .into_iter()
        .map(|(a, m)| (a.to_string(), m))
        .collect();
    metrics.media = air.media_metrics();
    (metrics, ended)
}

impl Net<'_> {
    /// When the next end wants to run.
    fn next_at(&self) -> Option<SimTime> {
        self.vehicles
            .values()
            .flat_map(|v| {
                [
                    v.ends.operator.as_ref().map(OperatorEnd::next_at),
                    v.ends.rov.as_ref().map(RovEnd::next_at),
                ]
            })
            .flatten()
            .min()
    }

    /// Runs what every vehicle's ends have due at `t` (in real time, every operator end's
    /// order sources too); true when an operator end was late for its slot and waits for
    /// what arrived meanwhile (unless `drained`: the air has just read it).
    fn run_ends<A: Air>(
        &mut self,
        air: &mut A,
        t: SimTime,
        real_time: bool,
        drained: bool,
        observer: &mut dyn Observer,
    ) -> Result<bool, GllError> {
        let mut behind = false;
        let addresses: Vec<u8> = self.vehicles.keys().copied().collect();
        for v in addresses {
            let Some(vehicle) = self.vehicles.get_mut(&v) else {
                continue;
            };
            let mut out = Out {
                tally: &mut vehicle.tally,
                observer: &mut *observer,
                vehicle: v,
            };
            let mut slot = None;
            if let Some(operator) = vehicle.ends.operator.as_mut()
                && (real_time || operator.next_at() <= t)
            {
                let slot_at = operator.slot_at();
                if slot_at <= t && is_late(t, slot_at) && !drained {
                    behind = true;
                } else {
                    slot = operator.poll(t, &mut out);
                }
            }
            let mut moved = None;
            if let Some(rov) = vehicle.ends.rov.as_mut()
                && rov.next_at() <= t
            {
                rov.poll(t, &mut out);
                moved = Some(rov.engine.state().position_m);
            }
            if let Some((frame, content)) = slot {
                let order = match content {
                    SlotContent::Order(index) => Some(index),
                    SlotContent::Velocity => None,
                };
                if let Some(round_trips) = vehicle.round_trips.as_mut() {
                    round_trips.sent(t);
                }
                self.originate(air, t, 0, frame, order, observer)?;
            }
            if let Some(position_m) = moved {
                air.moved(v, position_m);
            }
        }
        Ok(behind)
    }

    /// Node `address` originates `bytes` at `t`.
    fn originate<A: Air>(
        &mut self,
        air: &mut A,
        t: SimTime,
        address: u8,
        bytes: Vec<u8>,
        order: Option<u64>,
        observer: &mut dyn Observer,
    ) -> Result<(), GllError> {
        let bytes = match self.guards.get_mut(&address).map(|g| g.seal(&bytes)) {
            None => bytes,
            Some(Ok(sealed)) => sealed,
            Some(Err(error)) => {
                let text = format!("node {address}: a frame not sent: {error}");
                self.tell(observer, t, text.clone(), text);
                return Ok(());
            }
        };
        let Some(router) = self.routers.get_mut(&address) else {
            return Ok(());
        };
        router.sent(t, &bytes);
        let Some((src, dst)) = addresses(&bytes) else {
            return Ok(());
        };
        let interface = router.interface_to(dst);
        let vehicle = if src == 0 { dst } else { src };
        if let Some(v) = self.vehicles.get_mut(&vehicle) {
            v.directions[usize::from(src != 0)].sent();
        }
        self.origins
            .insert((vehicle, frame_key(&bytes)), Origin { t_sent: t, order });
        air.transmit(t, address, interface, bytes, true, observer)
    }

    /// Shows `text` once per `topic` (a warning on stderr and in the live log).
    fn tell(&mut self, observer: &mut dyn Observer, t: SimTime, topic: String, text: String) {
        if self.told.insert(topic) {
            observer.warning(t.as_secs_f64(), &text);
        }
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

    /// Handles everything the air heard: shows each row, routes what arrived intact.
    fn hear<A: Air>(&mut self, air: &mut A, observer: &mut dyn Observer) -> Result<(), GllError> {
        while let Some(heard) = air.pop() {
            self.heard(air, heard, observer)?;
        }
        Ok(())
    }

    /// One frame heard: its row, then what its receiver's router does with it.
    fn heard<A: Air>(
        &mut self,
        air: &mut A,
        heard: Heard,
        observer: &mut dyn Observer,
    ) -> Result<(), GllError> {
        let parsed = addresses(&heard.bytes);
        let mut decision = None;
        if let (true, Some(t), Some(router)) =
            (heard.intact, heard.t_rx, self.routers.get_mut(&heard.rx))
        {
            decision = Some((t, router.decide(t, &heard.bytes, heard.interface)));
        }
        let mut refused = None;
        let mut opened = None;
        let mut store_error = None;
        if let Some((_, decision)) = &decision
            && decision.deliver
            && let Some(guard) = self.guards.get_mut(&heard.rx)
        {
            match guard.open(&heard.bytes) {
                Ok((o, stored)) => {
                    opened = Some(o.frame);
                    store_error = stored;
                }
                Err(reason) => refused = Some(reason),
            }
        }
        let mut action = "";
        if let Some((_, decision)) = &decision {
            let node = self.nodes.entry(heard.rx).or_default();
            node.frames_heard += 1;
            node.frames_delivered += u64::from(decision.deliver && refused.is_none());
            if let (Some(reason), Some((src, _))) = (refused, decision.addresses) {
                *node
                    .refused
                    .entry(src.to_string())
                    .or_default()
                    .entry(reason.as_str())
                    .or_default() += 1;
            }
            node.frames_forwarded += decision.forward_on.len() as u64;
            match decision.dropped {
                Some(Dropped::Duplicate) => node.duplicates_dropped += 1,
                Some(Dropped::OffPath) => node.off_path_dropped += 1,
                Some(Dropped::Own) => node.own_dropped += 1,
                Some(Dropped::Malformed) | None => {}
            }
            if let (Some(tx), Some((_, dst)), Some(router)) =
                (heard.tx, decision.addresses, self.routers.get(&heard.rx))
                && self.scenario.routes.next_hop(heard.rx, dst) == tx
            {
                let reaches = router.interfaces();
                node.forwarded_back += decision
                    .forward_on
                    .iter()
                    .filter(|&&k| reaches.get(k).is_some_and(|r| r.contains(&tx)))
                    .count() as u64;
            }
            action = match (decision.deliver, decision.forward_on.is_empty()) {
                _ if let Some(reason) = refused => {
                    crate::secure::refused_action(reason, !decision.forward_on.is_empty())
                }
                (true, true) => "delivered",
                (true, false) => "delivered+forwarded",
                (false, false) => "forwarded",
                (false, true) => decision.dropped.map_or("", Dropped::as_str),
            };
        }
        // A frame lost has no bytes: its direction is the hop's.
        let ends = parsed.or(heard.tx.map(|tx| (tx, heard.rx)));
        observer.frame(&FrameEvent {
            direction: ends.map_or("operator_to_rov", |(s, d)| direction_of(s, d)),
            kind: heard.kind,
            bytes: heard.len,
            t_sent_s: heard.t_sent.map(SimTime::as_secs_f64),
            t_received_s: heard.t_rx.map(SimTime::as_secs_f64),
            fate: heard.fate,
            medium: air.medium_name(heard.medium),
            src: parsed.map(|p| p.0),
            dst: parsed.map(|p| p.1),
            tx: heard.tx,
            rx: Some(heard.rx),
            action,
        });
        let Some((t, decision)) = decision else {
            return Ok(());
        };
        if let Some(error) = store_error {
            let text = format!("node {}: {error}", heard.rx);
            self.tell(observer, t, format!("store {}", heard.rx), text);
        }
        if let (Some(reason), Some((src, _))) = (refused, decision.addresses) {
            self.told_refusal(observer, t, heard.rx, src, reason);
        }
        for &k in &decision.forward_on {
            air.transmit(t, heard.rx, k, heard.bytes.clone(), false, observer)?;
        }
        match (decision.deliver && refused.is_none(), decision.addresses) {
            (true, Some((src, _))) => {
                let key = frame_key(&heard.bytes);
                let bytes = opened.unwrap_or(heard.bytes);
                self.deliver(air, heard.rx, src, t, bytes, key, observer)
            }
            _ => Ok(()),
        }
    }

    /// Says once per receiving node and claimed source that its frames are refused.
    fn told_refusal(
        &mut self,
        observer: &mut dyn Observer,
        t: SimTime,
        rx: u8,
        src: u8,
        reason: Refusal,
    ) {
        let text = format!(
            "node {rx}: refused a frame claiming to come from {src} ({}): it moves nothing and \
             is no heartbeat; refusals are counted per source and reason in --metrics (said \
             once per source)",
            reason.as_str()
        );
        self.tell(observer, t, format!("refused {rx} {src}"), text);
    }

    /// Node `rx`'s engine takes a frame from `src` at `t` (`key`: the frame's identity as it
    /// was on the air, [`frame_key`]; `bytes`: the plain frame).
    #[allow(clippy::too_many_arguments)]
    fn deliver<A: Air>(
        &mut self,
        air: &mut A,
        rx: u8,
        src: u8,
        t: SimTime,
        bytes: Vec<u8>,
        key: u64,
        observer: &mut dyn Observer,
    ) -> Result<(), GllError> {
        let vehicle_address = if rx == 0 { src } else { rx };
        let origin = self.origins.remove(&(vehicle_address, key));
        let Some(vehicle) = self.vehicles.get_mut(&vehicle_address) else {
            return Ok(());
        };
        let delay_ms = origin
            .as_ref()
            .map(|o| t.0.saturating_sub(o.t_sent.0) as f64 * 1e-6);
        vehicle.directions[usize::from(rx == 0)].delivered(t, bytes.len(), delay_ms);
        let mut out = Out {
            tally: &mut vehicle.tally,
            observer: &mut *observer,
            vehicle: vehicle_address,
        };
        if rx == 0 {
            if let Some(round_trips) = vehicle.round_trips.as_mut() {
                round_trips.answered(t);
            }
            if let Some(operator) = vehicle.ends.operator.as_mut() {
                operator.receive(t, &bytes, &mut out);
            }
            return Ok(());
        }
        let order = origin.and_then(|o| o.order);
        let reply = match vehicle.ends.rov.as_mut() {
            Some(rov) => rov.receive(t, &bytes, order, &mut out),
            None => None,
        };
        match reply {
            Some(reply) => self.originate(air, t, rx, reply, None, observer),
            None => Ok(()),
        }
    }
}
