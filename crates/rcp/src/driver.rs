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
//! - [`SimAir`]: the simulated media ([`Medium`], one per medium of the scenario) in virtual
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

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::camera::Camera;
use crate::drive::Drive;
use crate::harness::{OperatorEnd, Out, RovEnd, Tally};
use crate::operator::SlotContent;
use crate::orders::OrderSource;
use crate::report::{
    Direction, FrameEvent, MediumMetrics, Metrics, NetworkMetrics, NodeMetrics, Observer, STOPPED,
    direction_of, kind_of,
};
use crate::routing::{Dropped, Router};
use crate::rov::{Rov, RovConfig};
use crate::rules;
use crate::scenario::Scenario;
use rovlink_base::stats::Running;
use rovlink_link::gll::{Endpoint, GllError, Received};
use rovlink_link::{Fate, Medium, ModelError, SimTime};
use rovlink_wire::frame::Frame;

pub use crate::report::SINGLE_MEDIUM;

/// How late an operator may send a slot's frame, ns: later than that, what arrived meanwhile is
/// read first, so that a late answer is not timed against the new slot's frame.
pub const LATE_NS: u64 = 1_000_000;

/// The longest a real-time wait lasts before the loop looks at the stop flag and live orders.
pub const WAKE_EVERY: Duration = Duration::from_millis(200);

/// The wait that reads what arrived while a loop was late for its slot.
pub const DRAIN_WAIT: Duration = Duration::from_millis(1);

/// The longest a node with two endpoints waits on one before reading the other.
pub const SLICE: Duration = Duration::from_millis(5);

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

/// One frame as a node heard it (or, in a simulation, failed to hear it).
#[derive(Debug)]
pub struct Heard {
    /// The medium (index into the scenario's media).
    pub medium: usize,
    /// The receiver's interface it came in on.
    pub interface: usize,
    /// The node that transmitted this copy, when known (a simulation).
    pub tx: Option<u8>,
    /// The node that heard it.
    pub rx: u8,
    /// Its bytes (empty when lost in a simulation).
    pub bytes: Vec<u8>,
    /// Its length.
    pub len: usize,
    /// What it is ([`kind_of`]).
    pub kind: &'static str,
    /// The medium's fate for it at `rx`.
    pub fate: &'static str,
    /// True when it arrived intact: it goes to `rx`'s router.
    pub intact: bool,
    /// When `tx` offered it, when known.
    pub t_sent: Option<SimTime>,
    /// When it arrived.
    pub t_rx: Option<SimTime>,
}

/// What the air did when the driver let time pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tick {
    /// The air had an event of its own at this time (a simulated medium): the ends wait.
    Air(SimTime),
    /// The ends' turn at this time.
    Ends(SimTime),
    /// The session's duration has passed.
    Over,
}

/// What carries the frames and keeps the time: simulated media or real endpoints.
pub trait Air {
    /// The current time.
    fn now(&self) -> SimTime;
    /// True for real time: every wake-up drains the live order sources and a late slot is
    /// possible.
    fn real_time(&self) -> bool;
    /// Lets time pass until the earliest of the air's own next event and `due` (the next
    /// thing an end has due), at most until `end`; `drain` asks for a short wait that reads
    /// what arrived (an operator late for its slot). What was heard waits in [`Air::pop`].
    fn advance(&mut self, due: SimTime, end: SimTime, drain: bool) -> Result<Tick, GllError>;
    /// The next frame heard, if any.
    fn pop(&mut self) -> Option<Heard>;
    /// Node `node` sends `bytes` on its interface `interface` at `t`; `origin` when it is the
    /// frame's origin (not a forward), for rows of frames sent.
    fn transmit(
        &mut self,
        t: SimTime,
        node: u8,
        interface: usize,
        bytes: Vec<u8>,
        origin: bool,
        observer: &mut dyn Observer,
    ) -> Result<(), GllError>;
    /// Vehicle `node` is now at `position_m`, NED m.
    fn moved(&mut self, node: u8, position_m: [f64; 3]);
    /// The name of medium `medium`.
    fn medium_name(&self, medium: usize) -> &str;
    /// What crossed each medium, by name (empty where the medium is outside).
    fn media_metrics(&self) -> BTreeMap<String, MediumMetrics>;
}

/// The simulated media of a scenario, in virtual time.
pub struct SimAir<'a> {
    media: Vec<Medium>,
    names: Vec<String>,
    /// Per medium, the address of each of its nodes (its index on the medium).
    members: Vec<Vec<u8>>,
    /// Per medium, each member's interface index for it.
    interfaces: Vec<Vec<usize>>,
    /// Per vehicle address, (medium, index on it) of each medium it is on.
    places: BTreeMap<u8, Vec<(usize, usize)>>,
    /// What each frame in flight on a medium is, by (medium, sender index, seq), with the
    /// receivers' reports still to come.
    kinds: HashMap<(usize, usize, u64), (&'static str, usize)>,
    metrics: Vec<MediumMetrics>,
    now: SimTime,
    /// Held to the wall clock, when paced.
    pace: Option<Pace<'a>>,
}

/// The slowest pace (virtual seconds per wall second).
pub const MIN_PACE: f64 = 0.01;
/// The fastest pace.
pub const MAX_PACE: f64 = 10_000.0;
/// How often a paced wait looks at the stop flag.
pub const PACE_POLL: Duration = Duration::from_millis(50);

/// Virtual time held back to the wall clock: virtual time `t` is reached no sooner than
/// `t / pace` seconds of wall time after the start, so a simulation (and a live view of it)
/// moves at `pace` times real time. A wait wakes every [`PACE_POLL`] to look at the stop flag.
/// Only the wall time changes: the run's results are those of the unpaced run.
pub struct Pace<'a> {
    pace: f64,
    started: Instant,
    stop: &'a AtomicBool,
}

impl<'a> Pace<'a> {
    /// A pace starting now (clamped to [`MIN_PACE`] ..= [`MAX_PACE`]; not finite is 1),
    /// giving up its waits once `stop` is set.
    pub fn new(pace: f64, stop: &'a AtomicBool) -> Pace<'a> {
        let pace = if pace.is_finite() { pace } else { 1.0 };
        Pace {
            pace: pace.clamp(MIN_PACE, MAX_PACE),
            started: Instant::now(),
            stop,
        }
    }

    /// Waits until virtual time `t` is due on the wall clock.
    pub fn wait_for(&self, t: SimTime) {
        let due = self.started + Duration::from_secs_f64((t.as_secs_f64() / self.pace).min(1e9));
        loop {
            let now = Instant::now();
            if now >= due || self.stop.load(Ordering::Relaxed) {
                return;
            }
            std::thread::sleep((due - now).min(PACE_POLL));
        }
    }
}

impl<'a> SimAir<'a> {
    /// The media of `scenario`, each at its nodes' positions, medium k seeded with the
    /// scenario's seed + k; the error names the medium.
    pub fn new(scenario: &Scenario) -> Result<SimAir<'a>, (String, ModelError)> {
        let mut air = SimAir {
            media: Vec::new(),
            names: Vec::new(),
            members: Vec::new(),
            interfaces: Vec::new(),
            places: BTreeMap::new(),
            kinds: HashMap::new(),
            metrics: vec![MediumMetrics::default(); scenario.media.len()],
            now: SimTime::ZERO,
            pace: None,
        };
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
            .map_err(|error| (spec.name.clone(), error))?;
            air.media.push(medium);
            air.names.push(spec.name.clone());
            air.members.push(spec.nodes.clone());
            air.interfaces.push(
                spec.nodes
                    .iter()
                    .map(|&a| {
                        let on = scenario.interfaces(a);
                        on.iter().position(|&m| m == k).unwrap_or(0)
                    })
                    .collect(),
            );
            for (index, &a) in spec.nodes.iter().enumerate() {
                air.places.entry(a).or_default().push((k, index));
            }
        }
        Ok(air)
    }

    /// The same media, held to the wall clock at `pace`.
    pub fn paced(mut self, pace: Pace<'a>) -> SimAir<'a> {
        self.pace = Some(pace);
        self
    }
}

impl Air for SimAir<'_> {
    fn now(&self) -> SimTime {
        self.now
    }

    fn real_time(&self) -> bool {
        false
    }

    fn advance(&mut self, due: SimTime, end: SimTime, _drain: bool) -> Result<Tick, GllError> {
        let medium_next = self.media.iter().filter_map(Medium::next_event_time).min();
        let t = medium_next.map_or(due, |m| m.min(due));
        if t > end {
            return Ok(Tick::Over);
        }
        if let Some(pace) = &self.pace {
            pace.wait_for(t);
        }
        self.now = t;
        if medium_next == Some(t) {
            for medium in &mut self.media {
                if medium.next_event_time() == Some(t) {
                    medium.step();
                }
            }
            return Ok(Tick::Air(t));
        }
        Ok(Tick::Ends(t))
    }

    fn pop(&mut self) -> Option<Heard> {
        let (medium, report) =
            (0..self.media.len()).find_map(|k| self.media[k].pop_report().map(|r| (k, r)))?;
        let key = (medium, report.from, report.seq);
        let kind = match self.kinds.get_mut(&key) {
            Some((kind, left)) => {
                let kind = *kind;
                if !report.duplicate {
                    *left = left.saturating_sub(1);
                    if *left == 0 {
                        self.kinds.remove(&key);
                    }
                }
                kind
            }
            None => "raw",
        };
        let metrics = &mut self.metrics[medium];
        match report.fate {
            Fate::Delivered => metrics.receptions_delivered += 1,
            Fate::Collision => metrics.receptions_collided += 1,
            Fate::Range => metrics.receptions_out_of_range += 1,
            _ => metrics.receptions_lost += 1,
        }
        let members = &self.members[medium];
        Some(Heard {
            medium,
            interface: self.interfaces[medium].get(report.to).copied().unwrap_or(0),
            tx: Some(members.get(report.from).copied().unwrap_or(0)),
            rx: members.get(report.to).copied().unwrap_or(0),
            len: report.len,
            kind,
            fate: report.fate.as_str(),
            intact: report.fate == Fate::Delivered && report.t_rx.is_some(),
            t_sent: Some(report.t_offered),
            t_rx: report.t_rx,
            bytes: report.bytes,
        })
    }

    fn transmit(
        &mut self,
        t: SimTime,
        node: u8,
        interface: usize,
        bytes: Vec<u8>,
        _origin: bool,
        _observer: &mut dyn Observer,
    ) -> Result<(), GllError> {
        let Some(&(medium, index)) = self.places.get(&node).and_then(|p| {
            p.iter()
                .find(|&&(m, i)| self.interfaces[m].get(i) == Some(&interface))
        }) else {
            return Ok(());
        };
        let kind = kind_of(&bytes);
        let link = &mut self.media[medium];
        link.advance(t);
        let receivers = link.nodes().saturating_sub(1);
        let seq = link.offer(index, bytes);
        self.kinds.insert((medium, index, seq), (kind, receivers));
        self.metrics[medium].transmissions += 1;
        Ok(())
    }

    fn moved(&mut self, node: u8, position_m: [f64; 3]) {
        if let Some(places) = self.places.get(&node) {
            for &(medium, index) in places {
                self.media[medium].set_position(index, position_m);
            }
        }
    }

    fn medium_name(&self, medium: usize) -> &str {
        self.names.get(medium).map_or("", String::as_str)
    }

    fn media_metrics(&self) -> BTreeMap<String, MediumMetrics> {
        self.names
            .iter()
            .cloned()
            .zip(self.metrics.iter().cloned())
            .collect()
    }
}

/// The host's monotonic clock: time since the start, as the engines count it.
pub struct Clock {
    start: Instant,
}

impl Clock {
    /// A clock whose time zero is now.
    pub fn start() -> Clock {
        Clock {
            start: Instant::now(),
        }
    }

    /// The time of `instant`.
    pub fn at(&self, instant: Instant) -> SimTime {
        SimTime(
            u64::try_from(instant.saturating_duration_since(self.start).as_nanos())
                .unwrap_or(u64::MAX),
        )
    }

    /// The time now.
    pub fn now(&self) -> SimTime {
        self.at(Instant::now())
    }

    /// The instant of `t`.
    pub fn instant(&self, t: SimTime) -> Instant {
        self.start + Duration::from_nanos(t.0)
    }

    /// When a wait for `at` wakes: then, or [`WAKE_EVERY`] from now if that is sooner.
    pub fn wake_at(&self, at: SimTime) -> Instant {
        self.instant(at).min(Instant::now() + WAKE_EVERY)
    }
}

/// True when a slot due at `slot_at` is more than [`LATE_NS`] behind `now`.
pub fn is_late(now: SimTime, slot_at: SimTime) -> bool {
    now.0.saturating_sub(slot_at.0) > LATE_NS
}

/// One node's real endpoints (interface k on endpoint k), with the host's clock.
pub struct PortAir<'a> {
    clock: Clock,
    endpoints: Vec<&'a mut dyn Endpoint>,
    /// The node's address.
    node: u8,
    /// Per interface, the medium (index into the scenario's media).
    media: Vec<usize>,
    names: Vec<String>,
    /// The endpoint read first next time (two endpoints are read in turn).
    next_endpoint: usize,
    heard: Option<Heard>,
    /// The latest time handed out: frames are stamped no earlier.
    last: SimTime,
}

impl<'a> PortAir<'a> {
    /// Node `node` of `scenario` over `endpoints`, one per medium it is on; time zero is now.
    pub fn new(scenario: &Scenario, node: u8, endpoints: Vec<&'a mut dyn Endpoint>) -> Self {
        PortAir {
            clock: Clock::start(),
            endpoints,
            node,
            media: scenario.interfaces(node),
            names: scenario.media.iter().map(|m| m.name.clone()).collect(),
            next_endpoint: 0,
            heard: None,
            last: SimTime::ZERO,
        }
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

    fn stamp(&mut self, t: SimTime) -> SimTime {
        self.last = self.last.max(t);
        self.last
    }
}

impl Air for PortAir<'_> {
    fn now(&self) -> SimTime {
        self.clock.now().max(self.last)
    }

    fn real_time(&self) -> bool {
        true
    }

    fn advance(&mut self, due: SimTime, end: SimTime, drain: bool) -> Result<Tick, GllError> {
        let now = self.now();
        if now >= end {
            return Ok(Tick::Over);
        }
        let deadline = if drain {
            Instant::now() + DRAIN_WAIT
        } else {
            self.clock.wake_at(due.min(end))
        };
        if let Some((k, received)) = self.receive(deadline)? {
            let t = self.stamp(self.clock.at(received.at));
            self.heard = Some(Heard {
                medium: self.media.get(k).copied().unwrap_or(0),
                interface: k,
                tx: None,
                rx: self.node,
                len: received.bytes.len(),
                kind: kind_of(&received.bytes),
                fate: if received.damaged {
                    "damaged"
                } else {
                    "received"
                },
                intact: !received.damaged,
                t_sent: None,
                t_rx: Some(t),
                bytes: received.bytes,
            });
        }
        let now = self.now();
        Ok(Tick::Ends(self.stamp(now)))
    }

    fn pop(&mut self) -> Option<Heard> {
        self.heard.take()
    }

    fn transmit(
        &mut self,
        t: SimTime,
        node: u8,
        interface: usize,
        bytes: Vec<u8>,
        origin: bool,
        observer: &mut dyn Observer,
    ) -> Result<(), GllError> {
        if let Some(endpoint) = self.endpoints.get_mut(interface) {
            endpoint.send(&bytes)?;
        }
        if origin {
            let sent_at = self.stamp(self.clock.now().max(t));
            let medium = self.media.get(interface).copied().unwrap_or(0);
            let addresses = addresses(&bytes);
            observer.frame(&FrameEvent {
                direction: addresses.map_or("operator_to_rov", |(s, d)| direction_of(s, d)),
                kind: kind_of(&bytes),
                bytes: bytes.len(),
                t_sent_s: Some(sent_at.as_secs_f64()),
                t_received_s: None,
                fate: "sent",
                medium: self.medium_name(medium),
                src: addresses.map(|a| a.0),
                dst: addresses.map(|a| a.1),
                tx: Some(node),
                rx: None,
                action: "",
            });
        }
        Ok(())
    }

    fn moved(&mut self, _node: u8, _position_m: [f64; 3]) {}

    fn medium_name(&self, medium: usize) -> &str {
        self.names.get(medium).map_or("", String::as_str)
    }

    fn media_metrics(&self) -> BTreeMap<String, MediumMetrics> {
        BTreeMap::new()
    }
}

/// A frame's SRC and DST, when it parses.
fn addresses(bytes: &[u8]) -> Option<(u8, u8)> {
    Frame::new_checked(bytes).ok().map(|f| (f.src(), f.dst()))
}

/// An operator's round trips in real time: from a slot's frame to the next answer heard. When a
/// slot goes out while the one before is unanswered, the next answer may be that late one, so
/// it is not timed (it would give a round trip shorter than the link allows).
#[derive(Debug, Default)]
pub struct RoundTrips {
    /// The last slot's send time, until its answer arrives.
    awaiting: Option<SimTime>,
    /// A slot went out while the one before was unanswered: the next answer is not timed.
    ambiguous: bool,
    /// The round trips timed, ms.
    ms: Running,
}

impl RoundTrips {
    /// A slot's frame went out at `t`.
    pub fn sent(&mut self, t: SimTime) {
        self.ambiguous = self.awaiting.is_some();
        self.awaiting = Some(t);
    }

    /// An answer arrived at `t`.
    pub fn answered(&mut self, t: SimTime) {
        if let Some(sent) = self.awaiting.take() {
            if self.ambiguous {
                self.ambiguous = false;
            } else {
                self.ms.push(t.0.saturating_sub(sent.0) as f64 * 1e-6);
            }
        }
    }

    /// The figures' round trip and its jitter, once one was timed.
    pub fn fill(&self, metrics: &mut Metrics) {
        if self.ms.count() > 0 {
            metrics.round_trip_ms = Some(self.ms.mean());
            metrics.round_trip_jitter_ms = Some(self.ms.std());
        }
    }
}

/// One vehicle's session as this process runs it: the ends it holds (both in a simulation,
/// the operator's or the vehicle's in real time).
pub struct VehicleEnds {
    /// The operator's end for this vehicle, when the operator runs here.
    pub operator: Option<OperatorEnd>,
    /// The vehicle's end, when the vehicle runs here.
    pub rov: Option<RovEnd>,
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
    /// The routers' duplicate window, s ([`rules::duplicate_window_s`] of the cycle; 0 for
    /// none, where a node does not know the far end's cycle).
    pub duplicate_window_s: f64,
}

/// The operator's end for `vehicle` of `scenario`: polling it once a cycle at its slot
/// ([`Scenario::cycle`]), its answers timeout [`rules::link_timeout_s`] of the cycle, its
/// orders from `sources`.
pub fn operator_end(
    scenario: &Scenario,
    vehicle: u8,
    sources: Vec<Box<dyn OrderSource>>,
) -> OperatorEnd {
    let cycle_s = scenario.cycle_s();
    let start_s = scenario
        .cycle()
        .iter()
        .find(|s| s.address == vehicle)
        .map_or(0.0, |s| s.start_s);
    let mut end = OperatorEnd::new(vehicle, cycle_s, sources)
        .first_slot_at(SimTime::from_secs_f64(start_s))
        .with_parity(scenario.settings.fec_percent > 0);
    end.answers_timeout_s = rules::link_timeout_s(cycle_s);
    end
}

/// `vehicle`'s end: at its address, with the scenario's image settings, a heartbeat timeout of
/// [`rules::link_timeout_s`] of the cycle, moved by `drive`, taking pictures with `camera`.
pub fn rov_end(
    scenario: &Scenario,
    vehicle: u8,
    drive: Box<dyn Drive>,
    camera: Box<dyn Camera>,
) -> RovEnd {
    let config = RovConfig {
        address: vehicle,
        heartbeat_timeout_s: rules::link_timeout_s(scenario.cycle_s()),
        settings: scenario.settings,
        ..RovConfig::default()
    };
    RovEnd::new(Rov::with(config, drive, camera))
}

/// Node `address`'s router in `scenario`: the scenario's routes, the node's neighbours per
/// interface, a duplicate window of `duplicate_window_s`.
pub fn router(scenario: &Scenario, address: u8, duplicate_window_s: f64) -> Router {
    Router::new(
        address,
        scenario.routes.clone(),
        scenario.neighbours(address),
        duplicate_window_s,
    )
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
        let mut action = "";
        if let Some((_, decision)) = &decision {
            let node = self.nodes.entry(heard.rx).or_default();
            node.frames_heard += 1;
            node.frames_delivered += u64::from(decision.deliver);
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
        for &k in &decision.forward_on {
            air.transmit(t, heard.rx, k, heard.bytes.clone(), false, observer)?;
        }
        match (decision.deliver, decision.addresses) {
            (true, Some((src, _))) => self.deliver(air, heard.rx, src, t, heard.bytes, observer),
            _ => Ok(()),
        }
    }

    /// Node `rx`'s engine takes a frame from `src` at `t`.
    fn deliver<A: Air>(
        &mut self,
        air: &mut A,
        rx: u8,
        src: u8,
        t: SimTime,
        bytes: Vec<u8>,
        observer: &mut dyn Observer,
    ) -> Result<(), GllError> {
        let vehicle_address = if rx == 0 { src } else { rx };
        let origin = self.origins.remove(&(vehicle_address, frame_key(&bytes)));
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pace_waits_for_virtual_time_and_gives_up_on_a_stop() {
        let never = AtomicBool::new(false);
        let pace = Pace::new(10.0, &never);
        // 1 s of virtual time at 10x: 0.1 s of wall time after the start.
        pace.wait_for(SimTime::from_secs_f64(1.0));
        assert!(pace.started.elapsed() >= Duration::from_millis(100));
        // A time already past does not wait.
        let waited = Instant::now();
        pace.wait_for(SimTime::from_secs_f64(0.5));
        assert!(waited.elapsed() < Duration::from_millis(50));
        let stopped = AtomicBool::new(true);
        let waited = Instant::now();
        Pace::new(MIN_PACE, &stopped).wait_for(SimTime::from_secs_f64(1e6));
        assert!(waited.elapsed() < PACE_POLL);
        assert_eq!(Pace::new(f64::NAN, &never).pace, 1.0);
        assert_eq!(Pace::new(1e9, &never).pace, MAX_PACE);
        assert_eq!(Pace::new(0.0, &never).pace, MIN_PACE);
    }
}
