//! A two-ended link as a state machine driven by time: frames go in, reports of their fate come
//! out.
//!
//! [`Link`] joins two modems, side A and side B, each sending through its own [`Model`]. It
//! never reads a clock: a driver offers frames at the link's current time ([`Link::offer`]),
//! moves time forward ([`Link::step`], [`Link::advance`]) and collects one [`Report`] per frame
//! ([`Link::pop_report`]) when its fate is known. The virtual-time driver steps from event to
//! event as fast as it can; the real-time driver advances to the wall clock.
//!
//! What happens to a frame sent from one side:
//!
//! 1. It enters the side's transmit FIFO, unless the FIFO's bytes would exceed `fifo_bytes`
//!    (fate `overflow`).
//! 2. It is ready for the air after the intrinsic delay plus jitter (at least zero). Frames go
//!    on air one at a time, in the order offered (or, with `reorder`, in the order they become
//!    ready), each when the previous one's air time is over.
//! 3. At the start of its air time the distance decides whether the other side can hear it
//!    (fate `range`). It reaches the other side after the propagation delay and occupies that
//!    receiver for its air time.
//! 4. Half duplex: a reception that overlaps the receiver's own transmission, or another
//!    reception, is lost, and so is every reception it overlaps (fate `collision`).
//! 5. At the end of its reception: netem loss and Gilbert-Elliott loss (fate `loss`), bit errors
//!    (fate `ber` when dropped, `corrupted` when delivered with flipped bits), netem corruption
//!    (`corrupted`), otherwise `delivered`; a delivered frame may be duplicated.
//!
//! Unless `reorder` is set, deliveries in one direction never overtake each other, even when the
//! distance shrinks. Memory holds only frames in flight.
//!
//! The machinery is the [`Medium`]'s (one event core for both): a [`Link`] is the two-node
//! medium whose nodes send with a model each and are a [`Distance`] apart; this module keeps
//! what both share (the transmitter, the receptions, the fate of an arrival) and the link's
//! view by sides.

use std::cmp::{Ordering, Reverse};
use std::collections::{BinaryHeap, VecDeque};

use serde::Serialize;

use super::distance::Distance;
use super::medium::{Medium, MediumReport};
use super::model::{ErrorMode, JitterDistribution, Model, ModelError};
use super::rng::Rng;
use super::sched::SimTime;
use rovlink_base::stats::Running;

/// One end of a link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    /// Side A (in `link-sim`, the first port; in a pipe, the input).
    A,
    /// Side B.
    B,
}

impl Side {
    /// The other end.
    pub fn other(self) -> Side {
        match self {
            Side::A => Side::B,
            Side::B => Side::A,
        }
    }

    /// 0 for A, 1 for B.
    pub fn index(self) -> usize {
        match self {
            Side::A => 0,
            Side::B => 1,
        }
    }

    /// "A" or "B".
    pub fn name(self) -> &'static str {
        match self {
            Side::A => "A",
            Side::B => "B",
        }
    }
}

/// What became of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Fate {
    /// Arrived intact.
    Delivered,
    /// Arrived with flipped bits (bit errors with `errors: corrupt`, or netem corruption).
    Corrupted,
    /// Lost to bit errors (`errors: drop`).
    Ber,
    /// Lost in a collision at the receiver (half duplex or overlapping receptions).
    Collision,
    /// Dropped: the transmit FIFO was full.
    Overflow,
    /// Not heard: the distance was outside the model's range.
    Range,
    /// Lost by netem's random or Gilbert-Elliott loss.
    Loss,
}

impl Fate {
    /// Every fate, in the order reports list them.
    pub const ALL: [Fate; 7] = [
        Fate::Delivered,
        Fate::Corrupted,
        Fate::Ber,
        Fate::Collision,
        Fate::Overflow,
        Fate::Range,
        Fate::Loss,
    ];

    /// The name used in traces.
    pub fn as_str(self) -> &'static str {
        match self {
            Fate::Delivered => "delivered",
            Fate::Corrupted => "corrupted",
            Fate::Ber => "ber",
            Fate::Collision => "collision",
            Fate::Overflow => "overflow",
            Fate::Range => "range",
            Fate::Loss => "loss",
        }
    }

    /// True when the frame's bytes reached the other side (intact or not).
    pub fn arrived(self) -> bool {
        matches!(self, Fate::Delivered | Fate::Corrupted)
    }
}

/// The fate of one frame at one receiver (or of a duplicate copy of it). `Node` names the
/// ends: a [`Side`] on a [`Link`], an index on a [`Medium`] (see [`super::MediumReport`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Report<Node = Side> {
    /// The end that sent it.
    pub from: Node,
    /// The end this report is about (on a link, the other side).
    pub to: Node,
    /// Its number among the frames offered by `from`, from 0.
    pub seq: u64,
    /// Its length, bytes.
    pub len: usize,
    /// When it was offered.
    pub t_offered: SimTime,
    /// When it went on air (none when it never did).
    pub t_tx_start: Option<SimTime>,
    /// When its last bit arrived at `to` (none when it did not arrive).
    pub t_rx: Option<SimTime>,
    /// What became of it at `to`.
    pub fate: Fate,
    /// True for the extra copy of a duplicated frame.
    pub duplicate: bool,
    /// The bytes that arrived (empty when nothing arrived).
    pub bytes: Vec<u8>,
}

/// A frame waiting in a transmit FIFO.
pub(super) struct Waiting {
    /// Ordering key: the ready time with `reorder`, otherwise 0 (so the sequence decides).
    key: SimTime,
    /// Its number among the frames offered on its side.
    pub(super) seq: u64,
    /// When it was offered.
    pub(super) t_offered: SimTime,
    t_ready: SimTime,
    /// Its bytes.
    pub(super) bytes: Vec<u8>,
}

impl PartialEq for Waiting {
    fn eq(&self, other: &Self) -> bool {
        (self.key, self.seq) == (other.key, other.seq)
    }
}

impl Eq for Waiting {}

impl PartialOrd for Waiting {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Waiting {
    fn cmp(&self, other: &Self) -> Ordering {
        (self.key, self.seq).cmp(&(other.key, other.seq))
    }
}

/// A frame on its way to (or arriving at) a receiver (sender and receiver: a [`Link`]'s side
/// indices, or a [`super::Medium`]'s nodes).
pub(super) struct Reception {
    /// The sender.
    pub(super) from: usize,
    /// The receiver.
    pub(super) to: usize,
    /// The frame's number among its sender's.
    pub(super) seq: u64,
    /// When it was offered.
    pub(super) t_offered: SimTime,
    /// When it went on air.
    pub(super) t_tx_start: SimTime,
    /// When its last bit arrives.
    pub(super) rx_end: SimTime,
    /// Lost in a collision at the receiver.
    pub(super) collided: bool,
    /// Its bytes.
    pub(super) bytes: Vec<u8>,
}

impl Reception {
    /// The reception of `frame`, on air from `now` to `air_end`, at `to` after `propagation_s`
    /// (pushed back, unless `reorder`, so that it ends no earlier than `last_rx_end`, the
    /// latest end of the same sender's frames there, which it moves on); and when it starts.
    pub(super) fn of(
        frame: &Waiting,
        (from, to): (usize, usize),
        (now, air_end): (SimTime, SimTime),
        propagation_s: f64,
        reorder: bool,
        last_rx_end: &mut SimTime,
    ) -> (Reception, SimTime) {
        let mut rx_start = now.after_secs(propagation_s);
        let mut rx_end = air_end.after_secs(propagation_s);
        if !reorder && rx_end < *last_rx_end {
            let shift = last_rx_end.0 - rx_end.0;
            rx_start = SimTime(rx_start.0.saturating_add(shift));
            rx_end = *last_rx_end;
        }
        *last_rx_end = (*last_rx_end).max(rx_end);
        let reception = Reception {
            from,
            to,
            seq: frame.seq,
            t_offered: frame.t_offered,
            t_tx_start: now,
            rx_end,
            collided: false,
            bytes: frame.bytes.clone(),
        };
        (reception, rx_start)
    }

    /// Its fate at its end, `now` (drawn as [`arrival`] says), as one report, two when
    /// duplicated, pushed to `reports`.
    pub(super) fn end(
        mut self,
        model: &Model,
        streams: &mut Streams,
        burst_bad: &mut bool,
        now: SimTime,
        reports: &mut VecDeque<MediumReport>,
    ) {
        let (fate, duplicate) = arrival(model, streams, burst_bad, self.collided, &mut self.bytes);
        let arrived = fate.arrived();
        let report = MediumReport {
            from: self.from,
            to: self.to,
            seq: self.seq,
            len: self.bytes.len(),
            t_offered: self.t_offered,
            t_tx_start: Some(self.t_tx_start),
            t_rx: arrived.then_some(now),
            fate,
            duplicate: false,
            bytes: if arrived { self.bytes } else { Vec::new() },
        };
        if duplicate {
            let copy = MediumReport {
                duplicate: true,
                ..report.clone()
            };
            reports.push_back(report);
            reports.push_back(copy);
        } else {
            reports.push_back(report);
        }
    }
}

/// A two-node medium's report as a link's (node 0 is side A).
pub(super) fn link_report(report: MediumReport) -> Report {
    let side = |node: usize| if node == 0 { Side::A } else { Side::B };
    Report {
        from: side(report.from),
        to: side(report.to),
        seq: report.seq,
        len: report.len,
        t_offered: report.t_offered,
        t_tx_start: report.t_tx_start,
        t_rx: report.t_rx,
        fate: report.fate,
        duplicate: report.duplicate,
        bytes: report.bytes,
    }
}

/// The report of a frame that never reached `to`: out of range (on air at `t_tx_start`) or,
/// without an air time, dropped from a full FIFO.
pub(super) fn lost_report(
    (from, to): (usize, usize),
    (seq, len, t_offered): (u64, usize, SimTime),
    t_tx_start: Option<SimTime>,
) -> MediumReport {
    MediumReport {
        from,
        to,
        seq,
        len,
        t_offered,
        t_tx_start,
        t_rx: None,
        fate: if t_tx_start.is_some() {
            Fate::Range
        } else {
            Fate::Overflow
        },
        duplicate: false,
        bytes: Vec::new(),
    }
}

/// Receptions under way, in slots reused as they end: memory holds only frames in flight.
#[derive(Default)]
pub(super) struct Receptions {
    slots: Vec<Option<Reception>>,
    free: Vec<usize>,
}

impl Receptions {
    /// Stores a reception; returns its slot.
    pub(super) fn insert(&mut self, reception: Reception) -> usize {
        match self.free.pop() {
            Some(slot) => {
                if let Some(place) = self.slots.get_mut(slot) {
                    *place = Some(reception);
                }
                slot
            }
            None => {
                self.slots.push(Some(reception));
                self.slots.len() - 1
            }
        }
    }

    /// Takes the reception out of `slot`, freeing it.
    pub(super) fn take(&mut self, slot: usize) -> Option<Reception> {
        let reception = self.slots.get_mut(slot)?.take()?;
        self.free.push(slot);
        Some(reception)
    }

    /// The receiver of the reception in `slot`.
    pub(super) fn receiver(&self, slot: usize) -> Option<usize> {
        Some(self.slots.get(slot)?.as_ref()?.to)
    }

    /// Receptions under way.
    pub(super) fn in_flight(&self) -> usize {
        self.slots.len() - self.free.len()
    }

    /// The most receptions ever under way at once (the slots' high-water mark).
    #[cfg(test)]
    pub(super) fn high_water(&self) -> usize {
        self.slots.len()
    }

    /// Marks every reception of `hearing` still arriving at `now` as collided (its receiver
    /// started to transmit, half duplex).
    pub(super) fn collide(&mut self, hearing: &[usize], now: SimTime) {
        for &slot in hearing {
            if let Some(Some(reception)) = self.slots.get_mut(slot)
                && reception.rx_end > now
            {
                reception.collided = true;
            }
        }
    }

    /// The reception in `slot` starts at `now` at a receiver already hearing `hearing`: when
    /// one of those is still arriving, or the receiver is `deaf` (on air, half duplex), it
    /// collides, and so does every reception it overlaps.
    pub(super) fn start(&mut self, slot: usize, hearing: &[usize], deaf: bool, now: SimTime) {
        let arriving = |slots: &[Option<Reception>], other: usize| {
            slots
                .get(other)
                .is_some_and(|r| r.as_ref().is_some_and(|r| r.rx_end > now))
        };
        let overlapping: Vec<usize> = hearing
            .iter()
            .copied()
            .filter(|&other| arriving(&self.slots, other))
            .collect();
        if deaf || !overlapping.is_empty() {
            for other in overlapping.into_iter().chain([slot]) {
                if let Some(Some(r)) = self.slots.get_mut(other) {
                    r.collided = true;
                }
            }
        }
    }
}

/// The random streams of one side's sending modem, one per random process.
pub(super) struct Streams {
    jitter: Rng,
    ber: Rng,
    loss: Rng,
    burst: Rng,
    corrupt: Rng,
    duplicate: Rng,
}

impl Streams {
    /// The streams of side (or node) `index`: streams 16 `index` + n of `seed`.
    fn new(seed: u64, index: usize) -> Streams {
        let base = 16 * index as u64;
        Streams {
            jitter: Rng::new(seed, base),
            ber: Rng::new(seed, base + 1),
            loss: Rng::new(seed, base + 2),
            burst: Rng::new(seed, base + 3),
            corrupt: Rng::new(seed, base + 4),
            duplicate: Rng::new(seed, base + 5),
        }
    }
}

/// A modem's transmit side: its random streams, its FIFO and its air (a [`Link`]'s end and a
/// [`super::Medium`]'s node both send through one).
pub(super) struct Transmitter {
    /// The sending modem's random streams.
    pub(super) streams: Streams,
    fifo: BinaryHeap<Reverse<Waiting>>,
    fifo_bytes: u64,
    next_seq: u64,
    /// End of the current (or last) transmission.
    pub(super) air_busy_until: SimTime,
    /// The pending wake-up to put the FIFO's head on air, if any.
    kick_at: Option<SimTime>,
}

/// What a transmitter does next ([`Transmitter::next_on_air`]).
pub(super) enum OnAir {
    /// Nothing now: it is on air (its end will ask again), its FIFO is empty, or a wake-up is
    /// already pending.
    Nothing,
    /// The FIFO's head is not ready yet: wake the transmitter at this time.
    WakeAt(SimTime),
    /// This frame goes on air now; its air time ends at the time given.
    Frame(Waiting, SimTime),
}

impl Transmitter {
    /// An idle transmitter with the streams of side (or node) `index`.
    pub(super) fn new(seed: u64, index: usize) -> Transmitter {
        Transmitter {
            streams: Streams::new(seed, index),
            fifo: BinaryHeap::new(),
            fifo_bytes: 0,
            next_seq: 0,
            air_busy_until: SimTime::ZERO,
            kick_at: None,
        }
    }

    /// Queues a frame offered at `now`: its sequence number, or the number as an error when
    /// it does not fit in the FIFO (the frame is then gone).
    pub(super) fn enqueue(
        &mut self,
        model: &Model,
        now: SimTime,
        bytes: Vec<u8>,
    ) -> Result<u64, u64> {
        let seq = self.next_seq;
        self.next_seq += 1;
        let len = bytes.len() as u64;
        if self.fifo_bytes + len > model.fifo_bytes {
            return Err(seq);
        }
        let delay_s = intrinsic_delay_s(model, &mut self.streams.jitter);
        let t_ready = now.after_secs(delay_s);
        let key = if model.reorder {
            t_ready
        } else {
            SimTime::ZERO
        };
        self.fifo_bytes += len;
        self.fifo.push(Reverse(Waiting {
            key,
            seq,
            t_offered: now,
            t_ready,
            bytes,
        }));
        Ok(seq)
    }

    /// A wake-up due at `now` arrived: true when it is the pending one (a stale one is ignored).
    pub(super) fn woken(&mut self, now: SimTime) -> bool {
        if self.kick_at == Some(now) {
            self.kick_at = None;
            return true;
        }
        false
    }

    /// Takes the FIFO's head for the air if the transmitter is free and the head is ready;
    /// otherwise says when to wake it (once per wake-up time).
    pub(super) fn next_on_air(&mut self, model: &Model, now: SimTime) -> OnAir {
        if self.air_busy_until > now {
            return OnAir::Nothing;
        }
        let Some(Reverse(head)) = self.fifo.peek() else {
            return OnAir::Nothing;
        };
        if head.t_ready > now {
            let due = head.t_ready;
            if self.kick_at.is_none_or(|pending| due < pending) {
                self.kick_at = Some(due);
                return OnAir::WakeAt(due);
            }
            return OnAir::Nothing;
        }
        let Some(Reverse(frame)) = self.fifo.pop() else {
            return OnAir::Nothing;
        };
        self.fifo_bytes -= frame.bytes.len() as u64;
        let air_end = now.after_secs(model.air_time_s(frame.bytes.len()));
        self.air_busy_until = air_end;
        OnAir::Frame(frame, air_end)
    }

    /// True when nothing waits and nothing is on air at `now`.
    pub(super) fn idle(&self, now: SimTime) -> bool {
        self.fifo.is_empty() && self.air_busy_until <= now
    }

    /// Frames in the FIFO.
    pub(super) fn queued(&self) -> usize {
        self.fifo.len()
    }
}

/// Two modems and the channel between them, driven by time: the two-node [`Medium`] whose
/// nodes send with a model each (A's frames follow `a_to_b`, B's `b_to_a`) and are a
/// [`Distance`] apart, seen by sides.
pub struct Link {
    medium: Medium,
}

impl Link {
    /// A link whose frames from A follow `a_to_b` and from B follow `b_to_a`, with every random
    /// stream seeded from `seed`.
    pub fn new(
        a_to_b: Model,
        b_to_a: Model,
        seed: u64,
        distance: Distance,
    ) -> Result<Link, ModelError> {
        Ok(Link {
            medium: Medium::pair(a_to_b, b_to_a, seed, distance)?,
        })
    }

    /// A link with the same model both ways.
    pub fn symmetric(model: Model, seed: u64, distance: Distance) -> Result<Link, ModelError> {
        Link::new(model.clone(), model, seed, distance)
    }

    /// The model of frames sent from `side`.
    pub fn model(&self, side: Side) -> &Model {
        self.medium.model_of(side.index())
    }

    /// The link's current time.
    pub fn now(&self) -> SimTime {
        self.medium.now()
    }

    /// When the next event is due (none when nothing is in flight).
    pub fn next_event_time(&self) -> Option<SimTime> {
        self.medium.next_event_time()
    }

    /// Events scheduled since the start (each is handled once): the simulation's work.
    pub fn events_scheduled(&self) -> u64 {
        self.medium.events_scheduled()
    }

    /// Frames offered but not yet reported.
    pub fn in_flight(&self) -> usize {
        self.medium.in_flight()
    }

    /// True when `side` has nothing waiting and is not transmitting: a frame offered now goes
    /// straight to its intrinsic delay.
    pub fn tx_idle(&self, side: Side) -> bool {
        self.medium.tx_idle(side.index())
    }

    /// Sets the distance from now on (a vehicle simulation drives this).
    pub fn set_distance(&mut self, distance_m: f64) {
        self.medium.set_track(Distance::Fixed(distance_m));
    }

    /// The distance now, m.
    pub fn distance_m(&mut self) -> f64 {
        self.medium.pair_distance_m()
    }

    /// The next report, in the order fates were decided.
    pub fn pop_report(&mut self) -> Option<Report> {
        self.medium.pop_report().map(link_report)
    }

    /// Offers a frame from `side` at the current time; returns its sequence number. A frame
    /// that does not fit in the FIFO is reported at once as `overflow`.
    pub fn offer(&mut self, side: Side, bytes: Vec<u8>) -> u64 {
        self.medium.offer(side.index(), bytes)
    }

    /// Processes the next event, moving time to it; false when nothing is pending.
    pub fn step(&mut self) -> bool {
        self.medium.step()
    }

    /// Processes every event due up to `t`, then moves time to `t` (never backwards).
    pub fn advance(&mut self, t: SimTime) {
        self.medium.advance(t);
    }
}

/// What became of a reception at its end, and whether it is duplicated: a collision, else
/// the sender's losses, bit errors (flipped in `bytes`), corruption and duplication, drawn from
/// the sender's `streams` (`burst_bad`: the Gilbert-Elliott state of this sender's channel into
/// this receiver).
pub(super) fn arrival(
    model: &Model,
    streams: &mut Streams,
    burst_bad: &mut bool,
    collided: bool,
    bytes: &mut [u8],
) -> (Fate, bool) {
    let fate = if collided {
        Fate::Collision
    } else if lost(model, streams, burst_bad) {
        Fate::Loss
    } else if flip_bit_errors(model.ber, bytes, &mut streams.ber) {
        match model.errors {
            ErrorMode::Drop => Fate::Ber,
            ErrorMode::Corrupt => Fate::Corrupted,
        }
    } else if model.corrupt_percent > 0.0
        && streams.corrupt.bernoulli(model.corrupt_percent / 100.0)
        && !bytes.is_empty()
    {
        let bit = (streams.corrupt.uniform() * (bytes.len() * 8) as f64) as usize;
        if let Some(byte) = bytes.get_mut(bit / 8) {
            *byte ^= 0x80 >> (bit % 8);
        }
        Fate::Corrupted
    } else {
        Fate::Delivered
    };
    let duplicate = fate.arrived()
        && model.duplicate_percent > 0.0
        && streams.duplicate.bernoulli(model.duplicate_percent / 100.0);
    (fate, duplicate)
}

/// The intrinsic delay of one frame, with its jitter, never negative, seconds.
fn intrinsic_delay_s(model: &Model, rng: &mut Rng) -> f64 {
    let jitter = if model.jitter_ms == 0.0 {
        0.0
    } else {
        match model.jitter_distribution {
            JitterDistribution::None => 0.0,
            JitterDistribution::Uniform => rng.standard_uniform(),
            JitterDistribution::Normal => rng.standard_normal(),
            JitterDistribution::Laplace => rng.standard_laplace(),
        }
    };
    ((model.intrinsic_delay_ms + model.jitter_ms * jitter) * 1e-3).max(0.0)
}

/// netem's random loss, then Gilbert-Elliott's (which moves its state on every frame).
fn lost(model: &Model, streams: &mut Streams, burst_bad: &mut bool) -> bool {
    let mut lost = model.loss_percent > 0.0 && streams.loss.bernoulli(model.loss_percent / 100.0);
    if let Some(ge) = &model.gilbert_elliott {
        let loss = if *burst_bad {
            ge.loss_bad_percent
        } else {
            ge.loss_good_percent
        };
        lost |= streams.burst.bernoulli(loss / 100.0);
        let switch = if *burst_bad {
            ge.r_percent
        } else {
            ge.p_percent
        };
        if streams.burst.bernoulli(switch / 100.0) {
            *burst_bad = !*burst_bad;
        }
    }
    lost
}

/// Flips each bit of `bytes` with probability `ber`, drawing the gaps between errors
/// (geometric), so the cost is per error, not per bit. True when any bit was flipped.
fn flip_bit_errors(ber: f64, bytes: &mut [u8], rng: &mut Rng) -> bool {
    if ber <= 0.0 {
        return false;
    }
    let bits = bytes.len() as f64 * 8.0;
    let log_keep = (-ber).ln_1p();
    let mut position = 0.0f64;
    let mut hit = false;
    loop {
        // Bits before the next error: floor(ln U / ln(1 - ber)), U in (0, 1].
        let gap = ((1.0 - rng.uniform()).ln() / log_keep).floor();
        position += gap;
        if position >= bits {
            return hit;
        }
        let bit = position as usize;
        bytes[bit / 8] ^= 0x80 >> (bit % 8);
        hit = true;
        position += 1.0;
    }
}

/// Counters of one direction of a link, for summaries and `--stats`.
#[derive(Debug, Clone, Default)]
pub struct DirectionStats {
    /// Frames offered.
    pub frames_offered: u64,
    /// Frames that arrived (intact or corrupted), duplicates not counted.
    pub frames_delivered: u64,
    /// Of those, frames that arrived corrupted.
    pub frames_corrupted: u64,
    /// Extra copies delivered by duplication.
    pub frames_duplicated: u64,
    /// Frames lost, by fate: ber, collision, overflow, range, loss.
    pub dropped: [u64; 5],
    /// Bytes offered.
    pub bytes_offered: u64,
    /// Bytes that arrived (duplicates not counted).
    pub bytes_delivered: u64,
    /// Delay from offer to the last bit's arrival of arrived frames, ms.
    pub delay_ms: Running,
    /// Time of the last arrival, for the throughput.
    pub last_rx: Option<SimTime>,
}

/// Which of [`DirectionStats::dropped`] counts a fate (none for arrivals).
fn drop_index(fate: Fate) -> Option<usize> {
    match fate {
        Fate::Delivered | Fate::Corrupted => None,
        Fate::Ber => Some(0),
        Fate::Collision => Some(1),
        Fate::Overflow => Some(2),
        Fate::Range => Some(3),
        Fate::Loss => Some(4),
    }
}

/// The names of [`DirectionStats::dropped`]'s entries.
pub const DROP_CAUSES: [&str; 5] = ["ber", "collision", "overflow", "range", "loss"];

impl DirectionStats {
    /// Counts a report.
    pub fn record(&mut self, report: &Report) {
        self.count(
            report.duplicate,
            report.len,
            report.fate,
            report.t_offered,
            report.t_rx,
        );
    }

    /// Counts a shared medium's report (the direction is its (from, to) pair).
    pub fn record_medium(&mut self, report: &super::MediumReport) {
        self.count(
            report.duplicate,
            report.len,
            report.fate,
            report.t_offered,
            report.t_rx,
        );
    }

    fn count(
        &mut self,
        duplicate: bool,
        len: usize,
        fate: Fate,
        t_offered: SimTime,
        t_rx: Option<SimTime>,
    ) {
        if duplicate {
            self.frames_duplicated += 1;
            return;
        }
        self.frames_offered += 1;
        self.bytes_offered += len as u64;
        if let Some(index) = drop_index(fate) {
            self.dropped[index] += 1;
            return;
        }
        self.frames_delivered += 1;
        self.bytes_delivered += len as u64;
        if fate == Fate::Corrupted {
            self.frames_corrupted += 1;
        }
        if let Some(t_rx) = t_rx {
            self.delay_ms
                .push((t_rx.0.saturating_sub(t_offered.0)) as f64 * 1e-6);
            self.last_rx = Some(self.last_rx.map_or(t_rx, |last| last.max(t_rx)));
        }
    }

    /// Frames lost for any reason.
    pub fn frames_dropped(&self) -> u64 {
        self.dropped.iter().sum()
    }

    /// The counters as JSON, with the field names `--stats` documents.
    pub fn to_json(&self) -> serde_json::Value {
        let dropped: serde_json::Map<String, serde_json::Value> = DROP_CAUSES
            .iter()
            .zip(self.dropped)
            .map(|(name, count)| (name.to_string(), count.into()))
            .collect();
        serde_json::json!({
            "frames_offered": self.frames_offered,
            "frames_delivered": self.frames_delivered,
            "frames_corrupted": self.frames_corrupted,
            "frames_duplicated": self.frames_duplicated,
            "frames_dropped": self.frames_dropped(),
            "dropped": dropped,
            "bytes_offered": self.bytes_offered,
            "bytes_delivered": self.bytes_delivered,
            "delivered_ratio": if self.frames_offered == 0 { 0.0 } else { self.frames_delivered as f64 / self.frames_offered as f64 },
            "delay_ms_mean": self.delay_ms.mean(),
            "delay_ms_std": self.delay_ms.std(),
            "delay_ms_min": self.delay_ms.min(),
            "delay_ms_max": self.delay_ms.max(),
        })
    }

    /// One line for a summary on stderr.
    pub fn summary_line(&self, direction: &str) -> String {
        let mut line = format!(
            "{direction}: {} frames offered, {} delivered ({:.1} %)",
            self.frames_offered,
            self.frames_delivered,
            if self.frames_offered == 0 {
                0.0
            } else {
                100.0 * self.frames_delivered as f64 / self.frames_offered as f64
            }
        );
        if self.frames_corrupted > 0 {
            line += &format!(", {} of them corrupted", self.frames_corrupted);
        }
        if self.frames_duplicated > 0 {
            line += &format!(", {} duplicates", self.frames_duplicated);
        }
        let drops: Vec<String> = DROP_CAUSES
            .iter()
            .zip(self.dropped)
            .filter(|(_, count)| *count > 0)
            .map(|(name, count)| format!("{count} {name}"))
            .collect();
        if !drops.is_empty() {
            line += &format!("; dropped: {}", drops.join(", "));
        }
        if self.delay_ms.count() > 0 {
            line += &format!(
                "; delay {:.2} ms mean, {:.2} ms std",
                self.delay_ms.mean(),
                self.delay_ms.std()
            );
        }
        line
    }
}

/// Serialises a fate as its trace name.
impl Serialize for Fate {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::pipe::{self, Pace};

    /// The S100 preset.
    pub(crate) fn s100() -> Model {
        Model::preset("s100").unwrap()
    }

    /// `model` without jitter.
    pub(crate) fn quiet(mut model: Model) -> Model {
        model.jitter_distribution = JitterDistribution::None;
        model
    }

    /// Runs `count` frames of `len` bytes from A and returns every report.
    fn run(model: Model, seed: u64, count: usize, len: usize, pace: Pace) -> Vec<Report> {
        let mut link = Link::symmetric(model, seed, Distance::Fixed(1.0)).unwrap();
        let mut sent = 0usize;
        let mut reports = Vec::new();
        pipe::run::<()>(
            &mut link,
            pace,
            &std::sync::atomic::AtomicBool::new(false),
            |_| {
                sent += 1;
                Ok((sent <= count).then(|| {
                    let mut frame = vec![0u8; len];
                    frame[..8.min(len)].copy_from_slice(&(sent as u64).to_le_bytes()[..8.min(len)]);
                    frame
                }))
            },
            |report| {
                reports.push(report);
                Ok(())
            },
        )
        .unwrap();
        reports
    }

    fn stats(reports: &[Report]) -> DirectionStats {
        let mut stats = DirectionStats::default();
        reports.iter().for_each(|r| stats.record(r));
        stats
    }

    #[test]
    fn air_time_is_exactly_size_times_8_over_bit_rate() {
        for len in [1usize, 16, 57, 255] {
            let reports = run(quiet(s100()), 1, 3, len, Pace::BackToBack);
            let air_ns = (len as f64 * 8.0 / 1900.0 * 1e9).round() as u64;
            for r in &reports {
                let tx = r.t_tx_start.unwrap();
                assert_eq!(tx.0 - r.t_offered.0, 85_000_000, "intrinsic delay");
                assert_eq!(r.t_rx.unwrap().0 - tx.0, air_ns, "air time of {len} bytes");
                assert_eq!(r.fate, Fate::Delivered);
            }
            // Back to back: the next frame is offered when the previous one's air time ends.
            assert_eq!(reports[1].t_offered.0, reports[0].t_rx.unwrap().0);
        }
    }

    #[test]
    fn s100_delay_and_jitter_converge_to_the_model() {
        let n = 20_000;
        let s = stats(&run(s100(), 7, n, 57, Pace::BackToBack));
        assert_eq!(s.frames_delivered, n as u64);
        // Mean 85 + 240 ms; standard error 13.2 / sqrt(n) = 0.093 ms: within 4 of them.
        assert!(
            (s.delay_ms.mean() - 325.0).abs() < 4.0 * 13.2 / (n as f64).sqrt(),
            "{}",
            s.delay_ms.mean()
        );
        // Standard deviation of the sample std of a normal: sigma / sqrt(2n) = 0.066 ms.
        assert!(
            (s.delay_ms.std() - 13.2).abs() < 4.0 * 13.2 / (2.0 * n as f64).sqrt(),
            "{}",
            s.delay_ms.std()
        );
    }

    #[test]
    fn every_jitter_shape_has_the_model_standard_deviation() {
        for shape in [JitterDistribution::Uniform, JitterDistribution::Laplace] {
            let mut model = s100();
            model.jitter_distribution = shape;
            let n = 20_000;
            let s = stats(&run(model, 3, n, 57, Pace::BackToBack));
            assert!(
                (s.delay_ms.mean() - 325.0).abs() < 0.5,
                "{shape:?} {}",
                s.delay_ms.mean()
            );
            // Laplace's sample std varies more (kurtosis 6): a 3 % band is > 4 standard errors.
            assert!(
                (s.delay_ms.std() / 13.2 - 1.0).abs() < 0.03,
                "{shape:?} {}",
                s.delay_ms.std()
            );
        }
    }

    #[test]
    fn ber_losses_stay_in_the_binomial_confidence_interval() {
        let mut model = s100();
        model.ber = 7e-4;
        let n = 20_000;
        let s = stats(&run(model.clone(), 11, n, 57, Pace::BackToBack));
        let p = 1.0 - model.packet_error_rate(57); // 0.7272...
        let ratio = s.frames_delivered as f64 / n as f64;
        let sigma = (p * (1.0 - p) / n as f64).sqrt();
        assert!(
            (ratio - p).abs() < 4.0 * sigma,
            "delivered {ratio}, expected {p}"
        );
        assert!((p - 0.727).abs() < 0.001);
        assert_eq!(s.dropped[0], n as u64 - s.frames_delivered);
    }

    #[test]
    fn corrupt_mode_hits_the_same_frames_and_flips_bits() {
        let mut model = s100();
        model.ber = 2e-3;
        let dropped = run(model.clone(), 5, 2000, 57, Pace::BackToBack);
        model.errors = ErrorMode::Corrupt;
        let corrupted = run(model, 5, 2000, 57, Pace::BackToBack);
        let mut hits = 0;
        for (d, c) in dropped.iter().zip(&corrupted) {
            assert_eq!(d.seq, c.seq);
            assert_eq!(d.fate == Fate::Ber, c.fate == Fate::Corrupted);
            if c.fate == Fate::Corrupted {
                hits += 1;
                let mut clean = vec![0u8; 57];
                clean[..8].copy_from_slice(&(c.seq + 1).to_le_bytes());
                assert_ne!(c.bytes, clean);
            }
        }
        assert!(hits > 100, "{hits}");
    }

    /// A sends at 0, B sends `b_offset_ns` later; S100 without jitter at 1 m.
    fn duel(b_offset_ns: u64) -> Vec<Report> {
        let mut link = Link::symmetric(quiet(s100()), 1, Distance::Fixed(1.0)).unwrap();
        link.offer(Side::A, vec![1; 57]);
        link.advance(SimTime(b_offset_ns));
        link.offer(Side::B, vec![2; 57]);
        while link.step() {}
        std::iter::from_fn(|| link.pop_report()).collect()
    }

    #[test]
    fn collisions_happen_exactly_when_transmissions_overlap() {
        // A is on air [85, 325] ms; B's frame offered at t is on air [t + 85, t + 325] ms.
        let overlapping = duel(240_000_000 - 1);
        assert_eq!(overlapping.len(), 2);
        assert!(
            overlapping.iter().all(|r| r.fate == Fate::Collision),
            "{overlapping:?}"
        );
        let touching = duel(240_000_000);
        assert!(
            touching.iter().all(|r| r.fate == Fate::Delivered),
            "{touching:?}"
        );
        let mut full_duplex = quiet(s100());
        full_duplex.half_duplex = false;
        let mut link = Link::symmetric(full_duplex, 1, Distance::Fixed(1.0)).unwrap();
        link.offer(Side::A, vec![1; 57]);
        link.offer(Side::B, vec![2; 57]);
        while link.step() {}
        assert!(std::iter::from_fn(|| link.pop_report()).all(|r| r.fate == Fate::Delivered));
    }

    #[test]
    fn two_receptions_that_overlap_both_collide() {
        // Duplicated frames never collide (the copy is made at delivery), but two senders do:
        // make B deaf-free (full duplex) and let two frames from A overlap at B by reordering.
        let mut model = quiet(s100());
        model.half_duplex = false;
        model.reorder = true;
        model.propagation_ms_per_m = 1.0; // 1 ms per metre.
        model.range_max_m = None;
        let mut link =
            Link::symmetric(model, 1, Distance::Track(vec![(0.0, 100.0), (0.2, 1.0)])).unwrap();
        // Frame 0 goes on air at 85 ms at ~58 m (58 ms of propagation); frame 1 goes on air when
        // frame 0's air time ends (325 ms) at 1 m: it arrives while frame 0 is still arriving.
        link.offer(Side::A, vec![1; 57]);
        link.offer(Side::A, vec![2; 57]);
        while link.step() {}
        let fates: Vec<Fate> = std::iter::from_fn(|| link.pop_report())
            .map(|r| r.fate)
            .collect();
        assert_eq!(fates, vec![Fate::Collision, Fate::Collision]);
    }

    #[test]
    fn range_cuts_the_link_and_it_comes_back() {
        let mut link = Link::symmetric(
            quiet(s100()),
            1,
            Distance::Track(vec![(0.0, 1.0), (10.0, 9.0), (20.0, 1.0)]),
        )
        .unwrap();
        let mut fates = Vec::new();
        for k in 0..40u64 {
            link.advance(SimTime(k * 500_000_000));
            link.offer(Side::A, vec![0; 16]);
            while let Some(r) = link.pop_report() {
                fates.push((r.t_tx_start.unwrap().as_secs_f64(), r.fate));
            }
        }
        while link.step() {}
        fates.extend(
            std::iter::from_fn(|| link.pop_report())
                .map(|r| (r.t_tx_start.unwrap().as_secs_f64(), r.fate)),
        );
        for (t, fate) in fates {
            // Distance 1 + 0.8 t up to 10 s, then back down: 5 m at t = 5 s and t = 15 s.
            let in_range = !(5.0..=15.0).contains(&t);
            let near_edge = (t - 5.0).abs() < 0.01 || (t - 15.0).abs() < 0.01;
            if !near_edge {
                assert_eq!(fate == Fate::Delivered, in_range, "t = {t}: {fate:?}");
            }
        }
    }

    #[test]
    fn a_full_fifo_drops_what_does_not_fit() {
        let mut model = quiet(s100());
        model.fifo_bytes = 100;
        let mut link = Link::symmetric(model, 1, Distance::Fixed(1.0)).unwrap();
        for _ in 0..3 {
            link.offer(Side::A, vec![0; 57]);
        }
        let first = link.pop_report().unwrap();
        assert_eq!((first.seq, first.fate), (1, Fate::Overflow));
        let second = link.pop_report().unwrap();
        assert_eq!((second.seq, second.fate), (2, Fate::Overflow));
        while link.step() {}
        assert_eq!(link.pop_report().unwrap().fate, Fate::Delivered);
    }

    #[test]
    fn jitter_reorders_only_when_asked() {
        let mut model = Model::preset("s2cr-burst").unwrap();
        model.range_max_m = None;
        let order = |model: Model| -> Vec<u64> {
            run(model, 9, 300, 16, Pace::IntervalNs(50_000_000))
                .into_iter()
                .filter(|r| r.fate == Fate::Delivered)
                .map(|r| r.seq)
                .collect()
        };
        let in_order = order(model.clone());
        assert!(in_order.windows(2).all(|w| w[0] < w[1]));
        model.reorder = true;
        model.half_duplex = false;
        let reordered = order(model);
        assert!(
            reordered.windows(2).any(|w| w[0] > w[1]),
            "no reordering seen"
        );
    }

    #[test]
    fn the_same_seed_gives_the_same_run_and_another_seed_another() {
        let mut model = s100();
        model.ber = 1e-3;
        model.errors = ErrorMode::Corrupt;
        model.duplicate_percent = 5.0;
        model.loss_percent = 3.0;
        let a = run(model.clone(), 42, 2000, 57, Pace::BackToBack);
        let b = run(model.clone(), 42, 2000, 57, Pace::BackToBack);
        let c = run(model, 43, 2000, 57, Pace::BackToBack);
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn netem_losses_match_their_rates() {
        let n = 40_000u64;
        let mut model = quiet(s100());
        model.loss_percent = 10.0;
        let s = stats(&run(model, 2, n as usize, 16, Pace::BackToBack));
        let sigma = (0.1 * 0.9 / n as f64).sqrt();
        assert!((s.dropped[4] as f64 / n as f64 - 0.1).abs() < 4.0 * sigma);

        let mut model = quiet(s100());
        model.gilbert_elliott = Some(super::super::model::GilbertElliott {
            p_percent: 2.0,
            r_percent: 18.0,
            loss_bad_percent: 100.0,
            loss_good_percent: 0.0,
        });
        let reports = run(model, 2, n as usize, 16, Pace::BackToBack);
        let lost = reports.iter().filter(|r| r.fate == Fate::Loss).count() as f64;
        // Long-run loss p / (p + r) = 10 %; bursts make the spread larger than binomial.
        assert!((lost / n as f64 - 0.1).abs() < 0.01, "{}", lost / n as f64);
        // Mean burst length 1 / r = 5.6 frames.
        let bursts = reports
            .windows(2)
            .filter(|w| w[0].fate != Fate::Loss && w[1].fate == Fate::Loss)
            .count() as f64;
        assert!(
            (lost / bursts - 1.0 / 0.18).abs() < 0.6,
            "{}",
            lost / bursts
        );

        let mut model = quiet(s100());
        model.duplicate_percent = 20.0;
        model.corrupt_percent = 10.0;
        let s = stats(&run(model, 2, n as usize, 16, Pace::BackToBack));
        let sigma = (0.2 * 0.8 / n as f64).sqrt();
        assert!((s.frames_duplicated as f64 / n as f64 - 0.2).abs() < 4.0 * sigma);
        assert!((s.frames_corrupted as f64 / n as f64 - 0.1).abs() < 0.01);
    }

    #[test]
    fn memory_holds_only_frames_in_flight() {
        let mut link = Link::symmetric(s100(), 1, Distance::Fixed(1.0)).unwrap();
        let mut sent = 0;
        pipe::run::<()>(
            &mut link,
            Pace::IntervalNs(100_000_000),
            &std::sync::atomic::AtomicBool::new(false),
            |_| {
                sent += 1;
                Ok((sent <= 50_000).then(|| vec![0; 57]))
            },
            |_| Ok(()),
        )
        .unwrap();
        // Offered faster than the link (every 100 ms, 240 ms of air each): the FIFO (2048 B)
        // bounds the backlog, and the reception slab's high-water mark stays tiny.
        assert_eq!(link.in_flight(), 0);
        assert!(
            link.medium.slab_high_water() <= 4,
            "slab grew to {}",
            link.medium.slab_high_water()
        );
        assert_eq!(link.next_event_time(), None);
    }

    #[test]
    fn rate_limit_slows_the_air() {
        let mut model = quiet(s100());
        model.rate_limit_bps = Some(950.0);
        let r = &run(model, 1, 1, 57, Pace::BackToBack)[0];
        assert_eq!(r.t_rx.unwrap().0 - r.t_tx_start.unwrap().0, 480_000_000);
    }
}
