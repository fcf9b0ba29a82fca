//! The real-time driver: one end of a session, the operator or the ROV, over a modem endpoint
//! (a serial port, a pseudo-terminal such as `link-sim --pty`'s, a TCP modem console or UDP),
//! with the host's monotonic clock.
//!
//! The engines are the ones [`super::session`] runs in virtual time; only the clock and the
//! transport change. Time zero is when [`run`] starts; the engines see the time elapsed since,
//! and a received frame is stamped when its last byte was read. The operator sends its slot's
//! frame when the slot is due and listens until the next slot (or script event); the ROV steps
//! its vehicle every 0.1 s and answers a frame the moment it arrives.
//!
//! Each end knows only its half of the figures: what it sent, and when what it received
//! arrived. One-way delays need both ends' clocks, so they are left out
//! ([`DirectionMetrics::delay_ms`] is `None`); the operator measures the round trip from a
//! slot's frame to the ROV's answer instead.
//!
//! [`DirectionMetrics::delay_ms`]: super::report::DirectionMetrics::delay_ms

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::harness::{OperatorEnd, Out, RovEnd, Tally};
use super::report::{Direction, FrameEvent, Metrics, Observer, kind_of};
use super::session::{Parts, SessionConfig};
use crate::gll::{Endpoint, GllError};
use crate::link::SimTime;
use crate::stats::Running;

pub use super::Role;

/// How a real-time run ended.
#[derive(Debug)]
pub enum Ended {
    /// The session ran its whole duration.
    Done,
    /// Stopped early (Ctrl-C); the figures cover the time until then.
    Stopped,
    /// The endpoint failed; the figures cover the time until then.
    Failed(GllError),
}

/// The clock: time since the start, as the engines count it.
pub(super) struct Clock {
    start: Instant,
}

impl Clock {
    /// A clock whose time zero is now.
    pub(super) fn start() -> Clock {
        Clock {
            start: Instant::now(),
        }
    }

    pub(super) fn at(&self, instant: Instant) -> SimTime {
        SimTime(
            u64::try_from(instant.saturating_duration_since(self.start).as_nanos())
                .unwrap_or(u64::MAX),
        )
    }

    pub(super) fn now(&self) -> SimTime {
        self.at(Instant::now())
    }

    pub(super) fn instant(&self, t: SimTime) -> Instant {
        self.start + Duration::from_nanos(t.0)
    }
}

/// Runs one end of `config`'s session over `endpoint` until its duration has passed, `stop`
/// is set, or the endpoint fails. The link model, seed and buoy of `config` are not used (the
/// link is real); the operator takes its orders from `parts.orders`, the ROV is moved by
/// `parts.drive` and takes pictures with `parts.camera` (the other end's parts are unused).
pub fn run(
    role: Role,
    config: &SessionConfig,
    parts: Parts,
    endpoint: &mut dyn Endpoint,
    stop: &AtomicBool,
    observer: &mut dyn Observer,
) -> (Metrics, Ended) {
    let clock = Clock::start();
    let end = SimTime::from_secs_f64(config.duration_s);
    let (mut operator, rov) = parts.ends(config);
    operator.status_poses = true;
    let mut tally = Tally::new(false);
    let mut directions = [Direction::default(), Direction::default()];
    let mut out = Out {
        tally: &mut tally,
        observer,
    };
    let mut io = Io {
        endpoint,
        stop,
        clock: &clock,
        end,
        directions: &mut directions,
    };
    let mut round_trips = RoundTrips::default();
    let outcome = match role {
        Role::Operator => io.operator(operator, &mut out, &mut round_trips),
        Role::Rov => io.rov(rov, &mut out),
    };
    let ended = match outcome {
        Ok(true) => Ended::Done,
        Ok(false) => Ended::Stopped,
        Err(error) => Ended::Failed(error),
    };
    let duration_s = clock.now().min(end).as_secs_f64();
    let mut metrics = tally.finish(role.name(), duration_s);
    metrics.operator_to_rov = directions[0].metrics(duration_s);
    metrics.rov_to_operator = directions[1].metrics(duration_s);
    round_trips.fill(&mut metrics);
    (metrics, ended)
}

/// How late an operator may send a slot's frame, ns: later than that, what arrived meanwhile is
/// read first, so that a late answer is not timed against the new slot's frame.
pub(super) const LATE_NS: u64 = 1_000_000;

/// The longest a real-time loop waits before it looks at the stop flag and live orders again.
pub(super) const WAKE_EVERY: Duration = Duration::from_millis(200);

/// The wait that reads what arrived while a loop was late for its slot.
pub(super) const DRAIN_WAIT: Duration = Duration::from_millis(1);

/// True when a slot due at `slot_at` is more than [`LATE_NS`] behind `now`.
pub(super) fn is_late(now: SimTime, slot_at: SimTime) -> bool {
    now.0.saturating_sub(slot_at.0) > LATE_NS
}

/// When a loop waiting for `at` wakes: then, or [`WAKE_EVERY`] from now if that is sooner.
pub(super) fn wake_at(clock: &Clock, at: SimTime) -> Instant {
    clock.instant(at).min(Instant::now() + WAKE_EVERY)
}

/// An operator's round trips in real time: from a slot's frame to the next answer heard. When a
/// slot goes out while the one before is unanswered, the next answer may be that late one, so
/// it is not timed (it would give a round trip shorter than the link allows).
#[derive(Debug, Default)]
pub(super) struct RoundTrips {
    /// The last slot's send time, until its answer arrives.
    awaiting: Option<SimTime>,
    /// A slot went out while the one before was unanswered: the next answer is not timed.
    ambiguous: bool,
    /// The round trips timed, ms.
    ms: Running,
}

impl RoundTrips {
    /// A slot's frame went out at `t`.
    pub(super) fn sent(&mut self, t: SimTime) {
        self.ambiguous = self.awaiting.is_some();
        self.awaiting = Some(t);
    }

    /// An answer arrived at `t`.
    pub(super) fn answered(&mut self, t: SimTime) {
        if let Some(sent) = self.awaiting.take() {
            if self.ambiguous {
                self.ambiguous = false;
            } else {
                self.ms.push(t.0.saturating_sub(sent.0) as f64 * 1e-6);
            }
        }
    }

    /// The figures' round trip and its jitter, once one was timed.
    pub(super) fn fill(&self, metrics: &mut Metrics) {
        if self.ms.count() > 0 {
            metrics.round_trip_ms = Some(self.ms.mean());
            metrics.round_trip_jitter_ms = Some(self.ms.std());
        }
    }
}

/// The event row of a frame this end sent at `t`.
pub(super) fn sent_event(direction: &'static str, frame: &[u8], t: SimTime) -> FrameEvent {
    FrameEvent {
        direction,
        kind: kind_of(frame),
        bytes: frame.len(),
        t_sent_s: Some(t.as_secs_f64()),
        t_received_s: None,
        fate: "sent",
    }
}

/// The event row of a frame this end received at `t`.
fn received_event(direction: &'static str, frame: &[u8], t: SimTime) -> FrameEvent {
    FrameEvent {
        direction,
        kind: kind_of(frame),
        bytes: frame.len(),
        t_sent_s: None,
        t_received_s: Some(t.as_secs_f64()),
        fate: "received",
    }
}

/// One end's link to the world: the port, the clock, and the frame counts.
struct Io<'a> {
    endpoint: &'a mut dyn Endpoint,
    stop: &'a AtomicBool,
    clock: &'a Clock,
    end: SimTime,
    /// Operator to ROV, ROV to operator.
    directions: &'a mut [Direction; 2],
}

impl Io<'_> {
    fn stopped(&self, out: &Out<'_>) -> bool {
        self.stop.load(Ordering::SeqCst) || out.observer.failed()
    }

    /// The operator's loop; `Ok(true)` when the duration ran out, `Ok(false)` when stopped.
    fn operator(
        &mut self,
        mut operator: OperatorEnd,
        out: &mut Out<'_>,
        round_trips: &mut RoundTrips,
    ) -> Result<bool, GllError> {
        let clock = self.clock;
        let mut drained = false;
        loop {
            if self.stopped(out) {
                return Ok(false);
            }
            let now = clock.now();
            if now >= self.end {
                return Ok(true);
            }
            let late = is_late(now, operator.slot_at());
            if (operator.slot_at() > now || drained || !late)
                && let Some((frame, _)) = operator.poll(now, out)
            {
                self.endpoint.send(&frame)?;
                self.directions[0].sent();
                out.observer
                    .frame(&sent_event("operator_to_rov", &frame, now));
                round_trips.sent(now);
                drained = false;
            }
            let mut deadline = wake_at(clock, operator.next_at().min(self.end));
            if operator.slot_at() <= now {
                // Late for the slot (busy with an image): what arrived meanwhile is read
                // first, so a late answer is not timed against the new slot's frame.
                drained = true;
                deadline = Instant::now() + DRAIN_WAIT;
            }
            let Some(received) = self.endpoint.receive(deadline)? else {
                continue;
            };
            let t = clock.at(received.at);
            if received.damaged {
                continue;
            }
            self.directions[1].delivered(t, received.bytes.len(), None);
            out.observer
                .frame(&received_event("rov_to_operator", &received.bytes, t));
            round_trips.answered(t);
            operator.receive(t, &received.bytes, out);
        }
    }

    /// The ROV's loop; `Ok(true)` when the duration ran out, `Ok(false)` when stopped.
    fn rov(&mut self, mut rov: RovEnd, out: &mut Out<'_>) -> Result<bool, GllError> {
        let clock = self.clock;
        let mut last = SimTime::ZERO;
        loop {
            if self.stopped(out) {
                return Ok(false);
            }
            let now = clock.now().max(last);
            if now >= self.end {
                return Ok(true);
            }
            rov.poll(now, out);
            last = now;
            let deadline = wake_at(clock, rov.next_at().min(self.end));
            let Some(received) = self.endpoint.receive(deadline)? else {
                continue;
            };
            if received.damaged {
                continue;
            }
            let t = clock.at(received.at).max(last);
            self.directions[0].delivered(t, received.bytes.len(), None);
            out.observer
                .frame(&received_event("operator_to_rov", &received.bytes, t));
            if let Some(reply) = rov.receive(t, &received.bytes, None, out) {
                self.endpoint.send(&reply)?;
                self.directions[1].sent();
                let sent_at = clock.now().max(t);
                out.observer
                    .frame(&sent_event("rov_to_operator", &reply, sent_at));
            }
        }
    }
}
