//! A shared medium: N modems with positions, driven by time (one model for all; a
//! [`super::Link`], the two-node medium, has one per side).
//!
//! [`Medium`] generalises [`super::Link`] from two modems to N on one channel (an RF or
//! acoustic band every node on it hears): a transmission from one node reaches every other node
//! within the model's range, each after its own propagation delay, and occupies that receiver
//! for its air time. At each receiver separately, a reception that overlaps another reception,
//! or (half duplex) the receiver's own transmission, is lost with every reception it overlaps
//! (fate `collision`), exactly as in the two-node model; loss, bit errors, corruption and
//! duplication are then drawn per reception. A [`super::Link`] is the two-node medium, a model
//! for each side and a distance (fixed or a track) in place of positions.
//!
//! Like [`super::Link`] it never reads a clock: a driver offers frames at the medium's time
//! ([`Medium::offer`]), moves time forward ([`Medium::step`], [`Medium::advance`]) and collects
//! one [`MediumReport`] per frame and receiver ([`Medium::pop_report`]): a frame offered by one
//! of N nodes gives N - 1 reports (`range` for the receivers out of range, `overflow` to every
//! receiver when it never left its FIFO). Positions change at any time
//! ([`Medium::set_position`]); the range and the propagation delay of a transmission are decided
//! by the distances at the start of its air time.
//!
//! Per receiver, as at a [`super::Link`]'s end: its own list of receptions it is hearing (for
//! collisions); per (sender, receiver) pair: the latest reception end (unless `reorder`, the
//! frames of one sender never overtake each other at one receiver) and the Gilbert-Elliott
//! state of that channel.
//!
//! Random streams: node k's sending modem draws from the streams a [`super::Link`]'s side k
//! would (seed, stream 16 k + n), in the order its receptions end, so adding a node never
//! changes what the others draw from. Memory holds only the frames in flight (one reception
//! per receiver in range) and one small state per pair of nodes that have exchanged a frame.
//!
//! Nothing here panics or loops forever on any input: an unknown node index is ignored
//! ([`Medium::offer`] returns 0 and reports nothing; [`Medium::set_position`] does nothing),
//! a non-finite position is refused by [`Medium::new`] and ignored by
//! [`Medium::set_position`].

use std::collections::{HashMap, VecDeque};

use super::Distance;
use super::channel::{OnAir, Reception, Receptions, Transmitter, lost_report};
use super::model::{Model, ModelError};
use super::sched::{Scheduler, SimTime};
use rovlink_base::geometry::distance_m;

/// The fate of one frame at one receiver of a medium (or of a duplicate copy of it): nodes
/// are indices on the medium.
pub type MediumReport = super::Report<usize>;

/// One modem on the medium.
struct Node {
    tx: Transmitter,
    position_m: [f64; 3],
    /// Receptions arriving at this node now (indices into the reception slab).
    hearing: Vec<usize>,
}

/// The channel from one node into another.
#[derive(Default)]
struct Pair {
    /// Latest reception end of this sender's frames at this receiver (no overtaking).
    last_rx_end: SimTime,
    /// Gilbert-Elliott state: true when bad.
    burst_bad: bool,
}

#[derive(Debug, Clone, Copy)]
enum Event {
    /// Try to put the node's FIFO head on air.
    Kick(usize),
    /// The node's transmission ends.
    TxEnd(usize),
    /// A reception starts (slab index).
    RxStart(usize),
    /// A reception ends (slab index).
    RxEnd(usize),
}

/// N modems on one channel, driven by time.
pub struct Medium {
    /// The model each node sends with, by node.
    models: Vec<Model>,
    nodes: Vec<Node>,
    /// A two-node medium's distance over time, with its lookup cursor, in place of the
    /// positions (the [`super::Link`] this medium is).
    track: Option<(Distance, usize)>,
    /// Keyed by (sender, receiver); created by the first frame between them.
    pairs: HashMap<(usize, usize), Pair>,
    sched: Scheduler<Event>,
    receptions: Receptions,
    reports: VecDeque<MediumReport>,
}

impl Medium {
    /// A medium of `positions_m.len()` nodes at those NED positions, every node sending
    /// through `model`, every random stream seeded from `seed`. An invalid model, or a
    /// position that is not finite, is an error.
    pub fn new(model: Model, seed: u64, positions_m: Vec<[f64; 3]>) -> Result<Medium, ModelError> {
        model.validate()?;
        if let Some(k) = positions_m
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite()))
        {
            return Err(ModelError::Field {
                field: format!("positions_m[{k}]"),
                problem: format!("expected finite coordinates, found {:?}", positions_m[k]),
            });
        }
        let models = vec![model; positions_m.len()];
        Ok(Medium::of(models, seed, positions_m, None))
    }

    /// Two modems, node 0 sending with `a_to_b` and node 1 with `b_to_a`, `distance` apart
    /// (a [`Distance::Track`] moves them in time): the [`super::Link`]. Invalid models are an
    /// error.
    pub(super) fn pair(
        a_to_b: Model,
        b_to_a: Model,
        seed: u64,
        distance: Distance,
    ) -> Result<Medium, ModelError> {
        a_to_b.validate()?;
        b_to_a.validate()?;
        let positions_m = vec![[0.0; 3]; 2];
        Ok(Medium::of(
            vec![a_to_b, b_to_a],
            seed,
            positions_m,
            Some((distance, 0)),
        ))
    }

    fn of(
        models: Vec<Model>,
        seed: u64,
        positions_m: Vec<[f64; 3]>,
        track: Option<(Distance, usize)>,
    ) -> Medium {
        let nodes = positions_m
            .into_iter()
            .enumerate()
            .map(|(k, position_m)| Node {
                tx: Transmitter::new(seed, k),
                position_m,
                hearing: Vec::new(),
            })
            .collect();
        Medium {
            models,
            nodes,
            track,
            pairs: HashMap::new(),
            sched: Scheduler::new(),
            receptions: Receptions::default(),
            reports: VecDeque::new(),
        }
    }

    /// The number of nodes.
    pub fn nodes(&self) -> usize {
        self.nodes.len()
    }

    /// The model every node sends with (node 0's, where a pair's differ).
    pub fn model(&self) -> &Model {
        &self.models[0]
    }

    /// The model `node` sends with (node 0's for an unknown node).
    pub fn model_of(&self, node: usize) -> &Model {
        self.models.get(node).unwrap_or(&self.models[0])
    }

    /// The most receptions in flight at once so far (the reception slab's size).
    #[cfg(test)]
    pub(super) fn slab_high_water(&self) -> usize {
        self.receptions.high_water()
    }

    /// Sets a pair's distance from now on (nothing on a medium of positions).
    pub(super) fn set_track(&mut self, distance: Distance) {
        if let Some(track) = self.track.as_mut() {
            *track = (distance, 0);
        }
    }

    /// A pair's distance now, m (between nodes 0 and 1 on a medium of positions).
    pub(super) fn pair_distance_m(&mut self) -> f64 {
        let now_s = self.now().as_secs_f64();
        match self.track.as_mut() {
            Some((distance, cursor)) => distance.at(now_s, cursor),
            None => self.distance_m(0, 1),
        }
    }

    /// Moves `node` to `position_m` from now on (a position that is not finite is ignored).
    pub fn set_position(&mut self, node: usize, position_m: [f64; 3]) {
        if let Some(n) = self.nodes.get_mut(node)
            && position_m.iter().all(|c| c.is_finite())
        {
            n.position_m = position_m;
        }
    }

    /// Where `node` is, m (the origin for an unknown node).
    pub fn position_m(&self, node: usize) -> [f64; 3] {
        self.nodes.get(node).map_or([0.0; 3], |n| n.position_m)
    }

    /// The distance between nodes `a` and `b` now, m (an unknown node is at the origin).
    pub fn distance_m(&self, a: usize, b: usize) -> f64 {
        distance_m(self.position_m(a), self.position_m(b))
    }

    /// The medium's current time.
    pub fn now(&self) -> SimTime {
        self.sched.now()
    }

    /// When the next event is due (none when nothing is in flight).
    pub fn next_event_time(&self) -> Option<SimTime> {
        self.sched.next_due()
    }

    /// Events scheduled since the start (each is handled once): the simulation's work.
    pub fn events_scheduled(&self) -> u64 {
        self.sched.scheduled()
    }

    /// Frames waiting in a FIFO plus receptions under way (one per frame and receiver).
    pub fn in_flight(&self) -> usize {
        self.nodes.iter().map(|n| n.tx.queued()).sum::<usize>() + self.receptions.in_flight()
    }

    /// True when `node` has nothing waiting and is not transmitting (false for an unknown node).
    pub fn tx_idle(&self, node: usize) -> bool {
        self.nodes.get(node).is_some_and(|n| n.tx.idle(self.now()))
    }

    /// Offers a frame from `node` at the current time; returns its sequence number (per node).
    /// A frame that does not fit in the node's FIFO is reported at once as `overflow`, to
    /// every other node. An unknown node: 0, and nothing happens.
    pub fn offer(&mut self, node: usize, bytes: Vec<u8>) -> u64 {
        let now = self.now();
        let Some(sender) = self.nodes.get_mut(node) else {
            return 0;
        };
        let len = bytes.len();
        match sender.tx.enqueue(&self.models[node], now, bytes) {
            Ok(seq) => {
                self.try_transmit(node);
                seq
            }
            Err(seq) => {
                for to in (0..self.nodes.len()).filter(|&to| to != node) {
                    let lost = lost_report((node, to), (seq, len, now), None);
                    self.reports.push_back(lost);
                }
                seq
            }
        }
    }

    /// Processes the next event, moving time to it; false when nothing is pending.
    pub fn step(&mut self) -> bool {
        match self.sched.pop() {
            Some((_, event)) => {
                self.handle(event);
                true
            }
            None => false,
        }
    }

    /// Processes every event due up to `t`, then moves time to `t` (never backwards).
    pub fn advance(&mut self, t: SimTime) {
        while let Some((_, event)) = self.sched.pop_until(t) {
            self.handle(event);
        }
    }

    /// The next report, in the order fates were decided.
    pub fn pop_report(&mut self) -> Option<MediumReport> {
        self.reports.pop_front()
    }

    fn handle(&mut self, event: Event) {
        match event {
            Event::Kick(node) => {
                let now = self.now();
                if self.nodes.get_mut(node).is_some_and(|n| n.tx.woken(now)) {
                    self.try_transmit(node);
                }
            }
            Event::TxEnd(node) => self.try_transmit(node),
            Event::RxStart(slot) => self.reception_starts(slot),
            Event::RxEnd(slot) => self.reception_ends(slot),
        }
    }

    /// Puts the node's FIFO head on air if it can go now (else schedules the wake-up), and
    /// sends it towards every other node: out of range (`range`, reported now) or a reception
    /// after that receiver's propagation delay.
    fn try_transmit(&mut self, node: usize) {
        let now = self.now();
        let Some(sender) = self.nodes.get_mut(node) else {
            return;
        };
        let model = &self.models[node];
        let (frame, air_end) = match sender.tx.next_on_air(model, now) {
            OnAir::Nothing => return,
            OnAir::WakeAt(due) => {
                self.sched.schedule(due, Event::Kick(node));
                return;
            }
            OnAir::Frame(frame, air_end) => (frame, air_end),
        };
        let from = sender.position_m;
        self.sched.schedule(air_end, Event::TxEnd(node));
        if model.half_duplex {
            self.receptions.collide(&sender.hearing, now);
        }
        let now_s = now.as_secs_f64();
        for to in (0..self.nodes.len()).filter(|&to| to != node) {
            let Some(receiver) = self.nodes.get(to) else {
                continue;
            };
            let distance = match self.track.as_mut() {
                Some((track, cursor)) => track.at(now_s, cursor),
                None => distance_m(from, receiver.position_m),
            };
            if !model.in_range(distance) {
                let lost = (frame.seq, frame.bytes.len(), frame.t_offered);
                let range = lost_report((node, to), lost, Some(now));
                self.reports.push_back(range);
                continue;
            }
            let propagation_s = model.propagation_s(distance);
            let last_rx_end = &mut self.pairs.entry((node, to)).or_default().last_rx_end;
            let times = (now, air_end);
            let reorder = model.reorder;
            let (reception, rx_start) = Reception::of(
                &frame,
                (node, to),
                times,
                propagation_s,
                reorder,
                last_rx_end,
            );
            let rx_end = reception.rx_end;
            let slot = self.receptions.insert(reception);
            self.sched.schedule(rx_start, Event::RxStart(slot));
            self.sched.schedule(rx_end, Event::RxEnd(slot));
        }
    }

    /// A reception starts at its receiver: it collides, with everything it overlaps there, when
    /// the receiver is hearing another frame or (half duplex) is on air itself.
    fn reception_starts(&mut self, slot: usize) {
        let now = self.now();
        let Some(to) = self.receptions.receiver(slot) else {
            return;
        };
        let Some(receiver) = self.nodes.get_mut(to) else {
            return;
        };
        let deaf = self.models[to].half_duplex && receiver.tx.air_busy_until > now;
        self.receptions.start(slot, &receiver.hearing, deaf, now);
        receiver.hearing.push(slot);
    }

    /// A reception ends: its fate at that receiver, drawn from the sender's streams.
    fn reception_ends(&mut self, slot: usize) {
        let now = self.now();
        let Some(reception) = self.receptions.take(slot) else {
            return;
        };
        let (from, to) = (reception.from, reception.to);
        if let Some(receiver) = self.nodes.get_mut(to) {
            receiver.hearing.retain(|&s| s != slot);
        }
        let Some(sender) = self.nodes.get_mut(from) else {
            return;
        };
        let burst_bad = &mut self.pairs.entry((from, to)).or_default().burst_bad;
        let streams = &mut sender.tx.streams;
        reception.end(
            &self.models[from],
            streams,
            burst_bad,
            now,
            &mut self.reports,
        );
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;
    use crate::channel::link_report;
    use crate::channel::tests::{quiet, s100};
    use crate::model::{ErrorMode, GilbertElliott, JitterDistribution};
    use crate::{Distance, Fate, Link, Report, Side};

    fn drain(medium: &mut Medium) -> Vec<MediumReport> {
        while medium.step() {}
        std::iter::from_fn(|| medium.pop_report()).collect()
    }

    /// The report of `from`'s frame `seq` at `to` (not a duplicate).
    fn at(reports: &[MediumReport], from: usize, seq: u64, to: usize) -> &MediumReport {
        reports
            .iter()
            .find(|r| (r.from, r.seq, r.to, r.duplicate) == (from, seq, to, false))
            .unwrap_or_else(|| panic!("no report of {from}#{seq} at {to} in {reports:?}"))
    }

    /// A two-node medium's report as the link's, checking that it is about the other node.
    fn as_link(report: MediumReport) -> Report {
        assert_eq!(report.to, 1 - report.from, "{report:?}");
        link_report(report)
    }

    /// A model drawn around a preset, with every random process and constraint of the model
    /// reachable: jitter shapes, losses, bursts, bit errors, corruption, duplicates, reorder,
    /// half or full duplex, a FIFO small enough to overflow, a range the distance may leave.
    fn any_model() -> impl Strategy<Value = Model> {
        let base = prop_oneof![Just("s100"), Just("s2cr-burst"), Just("satellite-up")];
        let shape = prop_oneof![
            Just(JitterDistribution::None),
            Just(JitterDistribution::Uniform),
            Just(JitterDistribution::Normal),
            Just(JitterDistribution::Laplace),
        ];
        let ge = proptest::option::of((0.0..30.0f64, 5.0..60.0f64, 50.0..100.0f64, 0.0..5.0f64));
        (
            (base, shape, 0.0..400.0f64, 0.0..20.0f64, ge),
            (0.0..2e-3f64, any::<bool>(), any::<bool>(), 60u64..3000),
            (any::<bool>(), 0.0..10.0f64, 0.0..20.0f64, 0.0..2.0f64),
        )
            .prop_map(
                |(
                    (base, shape, jitter_ms, loss, ge),
                    (ber, corrupt, half_duplex, fifo_bytes),
                    (reorder, corrupt_percent, duplicate_percent, propagation),
                )| {
                    let mut model = Model::preset(base).unwrap();
                    model.jitter_distribution = shape;
                    model.jitter_ms = jitter_ms;
                    model.loss_percent = loss;
                    model.gilbert_elliott = ge.map(|(p, r, bad, good)| GilbertElliott {
                        p_percent: p,
                        r_percent: r,
                        loss_bad_percent: bad,
                        loss_good_percent: good,
                    });
                    model.ber = ber;
                    model.errors = if corrupt {
                        ErrorMode::Corrupt
                    } else {
                        ErrorMode::Drop
                    };
                    model.half_duplex = half_duplex;
                    model.fifo_bytes = fifo_bytes;
                    model.reorder = reorder;
                    model.corrupt_percent = corrupt_percent;
                    model.duplicate_percent = duplicate_percent;
                    model.propagation_ms_per_m = propagation;
                    model
                },
            )
    }

    /// Offers: (wait before it, ns; from B rather than A; length).
    fn any_offers() -> impl Strategy<Value = Vec<(u64, bool, usize)>> {
        proptest::collection::vec((0u64..700_000_000, any::<bool>(), 1usize..200), 1..60)
    }

    /// Runs the same offers (wait before it, ns; from B rather than A; length) through the
    /// symmetric link and the two-node medium: their reports, as (link's, medium's).
    fn both(
        model: Model,
        seed: u64,
        distance: f64,
        offers: &[(u64, bool, usize)],
    ) -> (Vec<Report>, Vec<Report>) {
        let mut link = Link::symmetric(model.clone(), seed, Distance::Fixed(distance)).unwrap();
        let positions = vec![[distance, 0.0, 0.0], [0.0, 0.0, 0.0]];
        let mut medium = Medium::new(model, seed, positions).unwrap();
        let (mut t, mut expected, mut got) = (SimTime::ZERO, Vec::new(), Vec::new());
        for (k, &(wait_ns, from_b, len)) in offers.iter().enumerate() {
            t = SimTime(t.0 + wait_ns);
            link.advance(t);
            medium.advance(t);
            let bytes: Vec<u8> = (0..len).map(|i| (i * 31 + k) as u8).collect();
            let side = if from_b { Side::B } else { Side::A };
            assert_eq!(
                link.offer(side, bytes.clone()),
                medium.offer(side.index(), bytes)
            );
            assert_eq!(link.tx_idle(side), medium.tx_idle(side.index()));
            expected.extend(std::iter::from_fn(|| link.pop_report()));
            got.extend(std::iter::from_fn(|| medium.pop_report()).map(as_link));
        }
        while link.step() {}
        expected.extend(std::iter::from_fn(|| link.pop_report()));
        got.extend(drain(&mut medium).into_iter().map(as_link));
        assert_eq!(link.now(), medium.now());
        assert_eq!(link.events_scheduled(), medium.events_scheduled());
        assert_eq!(medium.in_flight(), 0);
        (expected, got)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        #[test]
        fn two_nodes_are_the_symmetric_link_report_for_report(
            model in any_model(),
            seed in any::<u64>(),
            distance in 0.0..8.0f64,
            offers in any_offers(),
        ) {
            let (expected, got) = both(model, seed, distance, &offers);
            prop_assert_eq!(expected, got);
        }
    }

    #[test]
    fn the_equivalence_holds_through_every_fate() {
        // A lossy, bursty, noisy S100 with a small FIFO, mostly A sending faster than the air
        // (overflow), B now and then over it (collision), in and out of range: all seven fates.
        let mut model = s100();
        model.loss_percent = 10.0;
        model.ber = 1e-3;
        model.corrupt_percent = 5.0;
        model.duplicate_percent = 10.0;
        model.fifo_bytes = 300;
        model.gilbert_elliott = Some(GilbertElliott {
            p_percent: 5.0,
            r_percent: 30.0,
            loss_bad_percent: 90.0,
            loss_good_percent: 1.0,
        });
        let offers: Vec<(u64, bool, usize)> =
            (0..600).map(|k| (150_000_000, k % 10 == 9, 57)).collect();
        let mut fates = std::collections::BTreeSet::new();
        let mut duplicates = 0;
        for (distance, errors) in [
            (4.0, ErrorMode::Drop),
            (4.0, ErrorMode::Corrupt),
            (6.0, ErrorMode::Drop),
        ] {
            model.errors = errors;
            let (expected, got) = both(model.clone(), 3, distance, &offers);
            assert_eq!(expected, got);
            fates.extend(got.iter().map(|r| r.fate));
            duplicates += got.iter().filter(|r| r.duplicate).count();
        }
        assert_eq!(fates.len(), Fate::ALL.len(), "{fates:?}");
        assert!(duplicates > 10, "{duplicates}");
    }

    /// The three nodes: operator at the origin, relay at 3,0,1, far vehicle at 7,0,1.
    fn three() -> Medium {
        let positions = vec![[0.0, 0.0, 0.0], [3.0, 0.0, 1.0], [7.0, 0.0, 1.0]];
        Medium::new(quiet(s100()), 1, positions).unwrap()
    }

    #[test]
    fn a_frame_from_the_middle_reaches_both_ends() {
        let mut medium = three();
        medium.offer(1, vec![5; 57]);
        let reports = drain(&mut medium);
        assert_eq!(reports.len(), 2, "{reports:?}");
        for to in [0, 2] {
            let r = at(&reports, 1, 0, to);
            assert_eq!(
                (r.fate, r.bytes.as_slice()),
                (Fate::Delivered, &[5u8; 57][..])
            );
        }
    }

    #[test]
    fn the_far_ends_seven_metres_apart_never_hear_each_other() {
        let mut medium = three();
        assert!((medium.distance_m(0, 2) - 50f64.sqrt()).abs() < 1e-12);
        for k in 0..20u64 {
            medium.advance(SimTime(k * 1_000_000_000));
            medium.offer(if k % 2 == 0 { 0 } else { 2 }, vec![1; 30]);
        }
        let reports = drain(&mut medium);
        assert_eq!(reports.len(), 40);
        for r in &reports {
            let relay = r.from == 1 || r.to == 1;
            let expected = if relay { Fate::Delivered } else { Fate::Range };
            assert_eq!(r.fate, expected, "{r:?}");
            assert!(r.t_tx_start.is_some());
        }
    }

    #[test]
    fn two_senders_collide_at_a_receiver_hearing_both_and_not_at_one_hearing_one() {
        // 0 and 2 are 7 m apart; 1 (middle) hears both; 3 hears only 0.
        let positions = vec![[0.0; 3], [3.5, 0.0, 0.0], [7.0, 0.0, 0.0], [-3.0, 0.0, 0.0]];
        let mut medium = Medium::new(quiet(s100()), 1, positions).unwrap();
        medium.offer(0, vec![1; 57]);
        medium.advance(SimTime(100_000_000));
        medium.offer(2, vec![2; 57]);
        let reports = drain(&mut medium);
        assert_eq!(reports.len(), 6, "{reports:?}");
        assert_eq!(at(&reports, 0, 0, 1).fate, Fate::Collision);
        assert_eq!(at(&reports, 2, 0, 1).fate, Fate::Collision);
        assert_eq!(at(&reports, 0, 0, 3).fate, Fate::Delivered);
        assert_eq!(at(&reports, 0, 0, 2).fate, Fate::Range);
        assert_eq!(at(&reports, 2, 0, 0).fate, Fate::Range);
        assert_eq!(at(&reports, 2, 0, 3).fate, Fate::Range);

        // One after the other (air times touching), the middle node hears both.
        let positions = vec![[0.0; 3], [3.5, 0.0, 0.0], [7.0, 0.0, 0.0]];
        let mut medium = Medium::new(quiet(s100()), 1, positions).unwrap();
        medium.offer(0, vec![1; 57]);
        medium.advance(SimTime(240_000_000));
        medium.offer(2, vec![2; 57]);
        let reports = drain(&mut medium);
        assert_eq!(at(&reports, 0, 0, 1).fate, Fate::Delivered);
        assert_eq!(at(&reports, 2, 0, 1).fate, Fate::Delivered);
    }

    #[test]
    fn a_half_duplex_node_on_air_loses_what_it_hears_but_others_do_not() {
        // 1 transmits while 0's frame arrives at it: lost at 1, delivered at 2 (which hears 0
        // and is not on air); 1's own frame collides at 0 (on air? no: 0 finished) -> check.
        let positions = vec![[0.0; 3], [2.0, 0.0, 0.0], [4.0, 0.0, 0.0]];
        let mut medium = Medium::new(quiet(s100()), 1, positions).unwrap();
        medium.offer(0, vec![1; 57]); // on air [85, 325] ms
        medium.advance(SimTime(200_000_000));
        medium.offer(1, vec![2; 16]); // on air [285, 352] ms
        let reports = drain(&mut medium);
        assert_eq!(at(&reports, 0, 0, 1).fate, Fate::Collision);
        // At 2, the two receptions overlap: both collide there too.
        assert_eq!(at(&reports, 0, 0, 2).fate, Fate::Collision);
        assert_eq!(at(&reports, 1, 0, 2).fate, Fate::Collision);
        // 0 is on air when 1's frame starts arriving (half duplex): lost at 0.
        assert_eq!(at(&reports, 1, 0, 0).fate, Fate::Collision);

        // Full duplex with 2 out of 1's range: 0's frame still reaches 2 intact.
        let mut model = quiet(s100());
        model.half_duplex = false;
        let positions = vec![[0.0; 3], [-2.0, 0.0, 0.0], [4.0, 0.0, 0.0]];
        let mut medium = Medium::new(model, 1, positions).unwrap();
        medium.offer(0, vec![1; 57]);
        medium.advance(SimTime(200_000_000));
        medium.offer(1, vec![2; 16]);
        let reports = drain(&mut medium);
        assert_eq!(at(&reports, 0, 0, 2).fate, Fate::Delivered);
        assert_eq!(at(&reports, 1, 0, 2).fate, Fate::Range);
        // 1 hears 0's frame while itself on air, full duplex: delivered.
        assert_eq!(at(&reports, 0, 0, 1).fate, Fate::Delivered);
    }

    #[test]
    fn propagation_is_per_receiver() {
        let mut model = quiet(s100());
        model.propagation_ms_per_m = 1.0;
        model.range_max_m = None;
        let positions = vec![[0.0; 3], [0.0, 10.0, 0.0], [0.0, 0.0, 100.0]];
        let mut medium = Medium::new(model, 1, positions).unwrap();
        medium.offer(0, vec![0; 57]);
        let reports = drain(&mut medium);
        let air_end_ns = 85_000_000 + 240_000_000;
        assert_eq!(
            at(&reports, 0, 0, 1).t_rx,
            Some(SimTime(air_end_ns + 10_000_000))
        );
        assert_eq!(
            at(&reports, 0, 0, 2).t_rx,
            Some(SimTime(air_end_ns + 100_000_000))
        );
        // Reports come in the order fates are decided: the nearer receiver first.
        assert_eq!(reports.iter().map(|r| r.to).collect::<Vec<_>>(), vec![1, 2]);
    }

    #[test]
    fn positions_move_and_range_follows_at_the_air_start() {
        let mut medium = three();
        medium.offer(0, vec![0; 16]); // goes on air at 85 ms
        medium.advance(SimTime(50_000_000));
        medium.set_position(2, [4.0, 0.0, 0.0]);
        medium.set_position(2, [f64::NAN, 0.0, 0.0]); // ignored
        assert_eq!(medium.position_m(2), [4.0, 0.0, 0.0]);
        let reports = drain(&mut medium);
        assert_eq!(at(&reports, 0, 0, 2).fate, Fate::Delivered);
        medium.offer(0, vec![0; 16]);
        medium.advance(medium.now().after_secs(0.2)); // on air now
        medium.set_position(2, [9.0, 0.0, 0.0]); // too late for this frame
        let reports = drain(&mut medium);
        assert_eq!(at(&reports, 0, 1, 2).fate, Fate::Delivered);
        medium.offer(0, vec![0; 16]);
        let reports = drain(&mut medium);
        assert_eq!(at(&reports, 0, 2, 2).fate, Fate::Range);
    }

    #[test]
    fn a_full_fifo_reports_overflow_to_every_other_node() {
        let mut model = quiet(s100());
        model.fifo_bytes = 100;
        let mut medium = three();
        medium.models = vec![model; 3];
        medium.offer(1, vec![0; 57]);
        medium.offer(1, vec![0; 57]);
        let overflow: Vec<_> = std::iter::from_fn(|| medium.pop_report()).collect();
        assert_eq!(overflow.len(), 2);
        assert!(
            overflow
                .iter()
                .all(|r| (r.seq, r.fate, r.t_tx_start) == (1, Fate::Overflow, None))
        );
        assert_eq!(
            overflow.iter().map(|r| r.to).collect::<Vec<_>>(),
            vec![0, 2]
        );
        assert!(
            drain(&mut medium)
                .iter()
                .all(|r| r.seq == 0 && r.fate == Fate::Delivered)
        );
    }

    #[test]
    fn bad_input_is_refused_or_ignored_never_a_panic() {
        let error = Medium::new(s100(), 1, vec![[0.0; 3], [1.0, f64::INFINITY, 0.0]])
            .err()
            .unwrap();
        assert_eq!(
            error.to_string(),
            "field `positions_m[1]`: expected finite coordinates, found [1.0, inf, 0.0]"
        );
        let mut broken = s100();
        broken.bitrate_bps = -1.0;
        assert!(Medium::new(broken, 1, vec![[0.0; 3]]).is_err());

        let mut medium = three();
        assert_eq!(medium.offer(3, vec![1; 10]), 0);
        medium.set_position(99, [1.0; 3]);
        assert_eq!(medium.position_m(99), [0.0; 3]);
        assert!(!medium.tx_idle(99));
        assert!(drain(&mut medium).is_empty());

        // Nobody to hear: a single node's frame goes on air and reports nothing.
        let mut alone = Medium::new(s100(), 1, vec![[0.0; 3]]).unwrap();
        alone.offer(0, vec![1; 10]);
        assert!(alone.next_event_time().is_some());
        assert!(drain(&mut alone).is_empty());
        assert!(alone.tx_idle(0));
        let mut empty = Medium::new(s100(), 1, Vec::new()).unwrap();
        assert_eq!((empty.nodes(), empty.offer(0, vec![1])), (0, 0));
        assert!(!empty.step());
    }

    #[test]
    fn memory_holds_only_frames_in_flight() {
        let mut medium = three();
        for k in 0..20_000u64 {
            medium.advance(SimTime(k * 100_000_000));
            medium.offer((k % 3) as usize, vec![0; 57]);
            while medium.pop_report().is_some() {}
        }
        while medium.step() {}
        assert_eq!(medium.in_flight(), 0);
        assert!(
            medium.receptions.high_water() <= 8,
            "slab grew to {}",
            medium.receptions.high_water()
        );
        assert!(medium.pairs.len() <= 6);
        assert!(medium.sched.is_empty());
    }

    /// An hour of three S100 nodes (the positions) offering 57-byte frames, `senders`
    /// of them in each 0.64 s slot (in turn); the fates counted, and the wall time.
    fn an_hour(senders: usize) -> (std::collections::BTreeMap<&'static str, u64>, f64) {
        let start = std::time::Instant::now();
        let positions = vec![[0.0; 3], [3.0, 0.0, 1.0], [7.0, 0.0, 1.0]];
        let mut medium = Medium::new(s100(), 1, positions).unwrap();
        let mut counts = std::collections::BTreeMap::new();
        let period_ns = 640_000_000u64;
        let mut k = 0u64;
        while k * period_ns < 3_600_000_000_000 {
            for j in 0..senders as u64 {
                medium.advance(SimTime(k * period_ns + j * period_ns / senders as u64));
                medium.offer(((k + j) % 3) as usize, vec![k as u8; 57]);
            }
            for r in std::iter::from_fn(|| medium.pop_report()) {
                *counts.entry(r.fate.as_str()).or_insert(0u64) += 1;
            }
            k += 1;
        }
        for r in drain(&mut medium) {
            *counts.entry(r.fate.as_str()).or_insert(0u64) += 1;
        }
        (counts, start.elapsed().as_secs_f64())
    }

    /// The benchmark of the brief: an hour of three S100 nodes exchanging frames every 0.64 s,
    /// one node per slot in turn, and all three in every slot (saturated: they collide)
    /// (`cargo test --release --lib link::medium -- --ignored --nocapture`).
    #[test]
    #[ignore]
    fn an_hour_of_three_s100_nodes() {
        for senders in [1, 3] {
            let (counts, wall_s) = an_hour(senders);
            println!(
                "one simulated hour, 3 S100 nodes, {senders} frame(s) per 0.64 s: {:.1} ms {counts:?}",
                wall_s * 1e3
            );
            assert!(wall_s < 1.0);
        }
        // In turn: every frame reaches the relay and the relay's reach both ends.
        let (counts, _) = an_hour(1);
        assert_eq!(counts.get("delivered"), Some(&(5625 / 3 * 4)));
        assert_eq!(counts.get("range"), Some(&(5625 / 3 * 2)));
    }
}
