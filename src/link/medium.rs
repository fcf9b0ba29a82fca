//! A shared medium: one model for N modems with positions, driven by time.
//!
//! [`Medium`] generalises [`super::Link`] from two modems to N on one channel (an RF or
//! acoustic band every node on it hears): a transmission from one node reaches every other node
//! within the model's range, each after its own propagation delay, and occupies that receiver
//! for its air time. At each receiver separately, a reception that overlaps another reception,
//! or (half duplex) the receiver's own transmission, is lost with every reception it overlaps
//! (fate `collision`), exactly as in the two-node model; loss, bit errors, corruption and
//! duplication are then drawn per reception. The two-node medium is the [`super::Link`] with
//! the same model both ways, frame for frame and fate for fate, under the same seed.
//!
//! Like [`super::Link`] it never reads a clock: a driver offers frames at the medium's time
//! ([`Medium::offer`]), moves time forward ([`Medium::step`], [`Medium::advance`]) and collects
//! one [`MediumReport`] per frame and receiver ([`Medium::pop_report`]): a frame offered by one
//! of N nodes gives N - 1 reports (`range` for the receivers out of range, `overflow` to every
//! receiver when it never left its FIFO). Positions change at any time
//! ([`Medium::set_position`]); the range and the propagation delay of a transmission are decided
//! by the distances at the start of its air time.
//!
//! Random streams: node k's sending modem draws from the streams a [`super::Link`]'s side k
//! would (seed, stream 16 k + n), in the order its receptions end, so adding a node never
//! changes what the others draw from. Nothing here panics on any input: an out-of-range node
//! index is ignored (offer returns its sequence number and reports nothing).

use super::Fate;
use super::model::{Model, ModelError};
use super::sched::SimTime;

/// The fate of one frame at one receiver (or of a duplicate copy of it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MediumReport {
    /// The node that sent it (its index on the medium).
    pub from: usize,
    /// The node this report is about.
    pub to: usize,
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

/// N modems on one channel, driven by time.
pub struct Medium {
    _private: (),
}

impl Medium {
    /// A medium of `positions_m.len()` nodes (at least one) at those NED positions, every node
    /// sending through `model`, every random stream seeded from `seed`.
    pub fn new(model: Model, seed: u64, positions_m: Vec<[f64; 3]>) -> Result<Medium, ModelError> {
        let _ = (model, seed, positions_m);
        todo!("helper A")
    }

    /// The number of nodes.
    pub fn nodes(&self) -> usize {
        todo!("helper A")
    }

    /// The model every node sends with.
    pub fn model(&self) -> &Model {
        todo!("helper A")
    }

    /// Moves `node` to `position_m` from now on.
    pub fn set_position(&mut self, node: usize, position_m: [f64; 3]) {
        let _ = (node, position_m);
        todo!("helper A")
    }

    /// Where `node` is, m (the origin for an unknown node).
    pub fn position_m(&self, node: usize) -> [f64; 3] {
        let _ = node;
        todo!("helper A")
    }

    /// The medium's current time.
    pub fn now(&self) -> SimTime {
        todo!("helper A")
    }

    /// When the next event is due (none when nothing is in flight).
    pub fn next_event_time(&self) -> Option<SimTime> {
        todo!("helper A")
    }

    /// Offers a frame from `node` at the current time; returns its sequence number (per node).
    pub fn offer(&mut self, node: usize, bytes: Vec<u8>) -> u64 {
        let _ = (node, bytes);
        todo!("helper A")
    }

    /// Processes the next event, moving time to it; false when nothing is pending.
    pub fn step(&mut self) -> bool {
        todo!("helper A")
    }

    /// Processes every event due up to `t`, then moves time to `t` (never backwards).
    pub fn advance(&mut self, t: SimTime) {
        let _ = t;
        todo!("helper A")
    }

    /// The next report, in the order fates were decided.
    pub fn pop_report(&mut self) -> Option<MediumReport> {
        todo!("helper A")
    }
}
