//! What carries the frames and keeps the time for the loop ([`super::run`]): the [`Air`]
//! trait, what it hands back when time passes ([`Tick`]) and each frame a node heard
//! ([`Heard`]). Its two implementations: [`super::SimAir`] (simulated media, virtual time) and
//! [`super::PortAir`] (a node's real endpoints, the host's clock).

use std::collections::BTreeMap;

use crate::report::{MediumMetrics, Observer};
use rovlink_link::SimTime;
use rovlink_link::gll::GllError;

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
    /// What it is (`report::kind_of`).
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
