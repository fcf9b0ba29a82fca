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
//! [`DirectionMetrics::delay_ms`]: super::session::DirectionMetrics::delay_ms

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::operator::Operator;
use super::rov::{Rov, RovConfig};
use super::session::{
    Direction, FrameEvent, Metrics, Observer, SessionConfig, image_period_s, kind_of,
};
use super::{Event, PoseSample};
use crate::gll::{Endpoint, GllError};
use crate::link::SimTime;
use crate::stats::Running;
use crate::wire::operator::Order;

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
struct Clock {
    start: Instant,
}

impl Clock {
    fn at(&self, instant: Instant) -> SimTime {
        SimTime(
            u64::try_from(instant.saturating_duration_since(self.start).as_nanos())
                .unwrap_or(u64::MAX),
        )
    }

    fn now(&self) -> SimTime {
        self.at(Instant::now())
    }

    fn instant(&self, t: SimTime) -> Instant {
        self.start + Duration::from_nanos(t.0)
    }
}

/// Runs one end of `config`'s session over `endpoint` until its duration has passed, `stop`
/// is set, or the endpoint fails. The link model, seed and buoy of `config` are not used (the
/// link is real); the operator plays the script and waypoints, the ROV starts at
/// `config.start_m` with `config.settings` and `config.images`.
pub fn run(
    role: Role,
    config: &SessionConfig,
    endpoint: &mut dyn Endpoint,
    stop: &AtomicBool,
    observer: &mut dyn Observer,
) -> (Metrics, Ended) {
    let mut end = End {
        config,
        endpoint,
        stop,
        observer,
        clock: Clock {
            start: Instant::now(),
        },
        end: SimTime::from_secs_f64(config.duration_s),
        metrics: Metrics::default(),
        directions: [Direction::default(), Direction::default()],
    };
    let outcome = match role {
        Role::Operator => end.operator(),
        Role::Rov => end.rov(),
    };
    let End {
        clock,
        end,
        mut metrics,
        directions,
        ..
    } = end;
    let ended = match outcome {
        Ok(true) => Ended::Done,
        Ok(false) => Ended::Stopped,
        Err(error) => Ended::Failed(error),
    };
    let duration_s = clock.now().min(end).as_secs_f64();
    metrics.measured_by = match role {
        Role::Operator => "operator",
        Role::Rov => "rov",
    };
    metrics.duration_s = duration_s;
    metrics.operator_to_rov = directions[0].metrics(duration_s);
    metrics.rov_to_operator = directions[1].metrics(duration_s);
    (metrics, ended)
}

/// The event row of a frame this end sent at `t`.
fn sent_event(direction: &'static str, frame: &[u8], t: SimTime) -> FrameEvent {
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

/// One end's run: what it talks through, and what it counts.
struct End<'a> {
    config: &'a SessionConfig,
    endpoint: &'a mut dyn Endpoint,
    stop: &'a AtomicBool,
    observer: &'a mut dyn Observer,
    clock: Clock,
    end: SimTime,
    metrics: Metrics,
    /// Operator to ROV, ROV to operator.
    directions: [Direction; 2],
}

impl End<'_> {
    /// The operator's loop; `Ok(true)` when the duration ran out, `Ok(false)` when stopped.
    fn operator(&mut self) -> Result<bool, GllError> {
        let End {
            config,
            endpoint,
            stop,
            observer,
            clock,
            end,
            metrics,
            directions,
        } = self;
        let (config, stop, end) = (*config, *stop, *end);
        let mut operator = Operator::new(1, (config.ipg_s * 1e9).round().max(1.0) as u64);
        let mut script = config.script.iter().peekable();
        let mut waypoints = config.waypoints.iter().peekable();
        let mut image_times = Vec::new();
        let mut round_trip_ms = Running::new();
        // The last slot's send time, until its answer arrives.
        let mut awaiting: Option<SimTime> = None;
        // Set when a slot went out while the previous one was still unanswered: the next
        // answer may be that late one, so it is not timed against the new slot's frame (it
        // would give a round trip shorter than the link allows).
        let mut ambiguous = false;
        let mut last_status: Option<crate::wire::rov::BasicStatus> = None;
        let mut drained = false;
        loop {
            if stop.load(Ordering::SeqCst) || observer.failed() {
                return Ok(false);
            }
            let now = clock.now();
            if now >= end {
                break;
            }
            while let Some(change) = script.next_if(|c| SimTime::from_secs_f64(c.t_s) <= now) {
                operator.set_joystick(change.joystick);
            }
            while let Some(w) = waypoints.next_if(|w| SimTime::from_secs_f64(w.t_s) <= now) {
                operator.push_order(goto_order(w.position_m, w.heading_deg));
                metrics.orders_sent += 1;
            }
            let late = now.0.saturating_sub(operator.poll_at().0) > 1_000_000;
            if operator.poll_at() <= now && (drained || !late) {
                let (frame, _) = operator.poll(now);
                endpoint.send(&frame)?;
                directions[0].sent();
                observer.frame(&sent_event("operator_to_rov", &frame, now));
                ambiguous = awaiting.is_some();
                awaiting = Some(now);
                drained = false;
            }
            let wake = [
                Some(operator.poll_at()),
                script.peek().map(|c| SimTime::from_secs_f64(c.t_s)),
                waypoints.peek().map(|w| SimTime::from_secs_f64(w.t_s)),
                Some(end),
            ]
            .into_iter()
            .flatten()
            .min()
            .unwrap_or(end);
            // Wake at least every 0.2 s to notice Ctrl-C.
            let mut deadline = clock
                .instant(wake)
                .min(Instant::now() + Duration::from_millis(200));
            if operator.poll_at() <= now {
                // Late for the slot (busy with an image): what arrived meanwhile is read
                // first, so a late answer is not timed against the new slot's frame.
                drained = true;
                deadline = Instant::now() + Duration::from_millis(1);
            }
            let Some(received) = endpoint.receive(deadline)? else {
                continue;
            };
            let t = clock.at(received.at);
            if received.damaged {
                continue;
            }
            directions[1].delivered(t, received.bytes.len(), None);
            observer.frame(&received_event("rov_to_operator", &received.bytes, t));
            if let Some(sent) = awaiting.take() {
                if ambiguous {
                    ambiguous = false;
                } else {
                    round_trip_ms.push(t.0.saturating_sub(sent.0) as f64 * 1e-6);
                }
            }
            operator.receive(t, &received.bytes);
            for event in operator.take_events() {
                match event {
                    Event::OrderAcknowledged(_) => metrics.orders_acknowledged += 1,
                    Event::ImageCompleted(stream) => {
                        metrics.images_completed += 1;
                        image_times.push(t.as_secs_f64());
                        observer.image(t.as_secs_f64(), &stream);
                    }
                    _ => {}
                }
            }
            if operator.last_status != last_status {
                last_status = operator.last_status;
                if let Some(status) = last_status {
                    observer.pose(&status_pose(t, &status));
                }
            }
        }
        metrics.image_period_s = image_period_s(&image_times);
        if round_trip_ms.count() > 0 {
            metrics.round_trip_ms = Some(round_trip_ms.mean());
            metrics.round_trip_jitter_ms = Some(round_trip_ms.std());
        }
        Ok(true)
    }

    /// The ROV's loop; `Ok(true)` when the duration ran out, `Ok(false)` when stopped.
    fn rov(&mut self) -> Result<bool, GllError> {
        let End {
            config,
            endpoint,
            stop,
            observer,
            clock,
            end,
            metrics,
            directions,
        } = self;
        let (config, stop, end) = (*config, *stop, *end);
        let rov_config = RovConfig {
            settings: config.settings,
            ..RovConfig::default()
        };
        let mut rov = Rov::new(rov_config, config.start_m, config.images.clone());
        let tally = |rov: &mut Rov, metrics: &mut Metrics| {
            for event in rov.take_events() {
                match event {
                    Event::OrderExecuted(_) => metrics.orders_executed += 1,
                    Event::ImageStarted { .. } => metrics.images_started += 1,
                    Event::LinkLost => metrics.link_losses += 1,
                    Event::LinkRecovered => metrics.link_recoveries += 1,
                    _ => {}
                }
            }
        };
        let mut last = SimTime::ZERO;
        loop {
            if stop.load(Ordering::SeqCst) || observer.failed() {
                return Ok(false);
            }
            let now = clock.now().max(last);
            if now >= end {
                return Ok(true);
            }
            while rov.poll_at() <= now {
                let step = rov.poll_at();
                rov.poll(step);
                observer.pose(&rov.pose(step.as_secs_f64()));
            }
            tally(&mut rov, metrics);
            last = now;
            let deadline = clock
                .instant(rov.poll_at().min(end))
                .min(Instant::now() + Duration::from_millis(200));
            let Some(received) = endpoint.receive(deadline)? else {
                continue;
            };
            if received.damaged {
                continue;
            }
            let t = clock.at(received.at).max(last);
            directions[0].delivered(t, received.bytes.len(), None);
            observer.frame(&received_event("operator_to_rov", &received.bytes, t));
            if let Some(reply) = rov.receive(t, &received.bytes) {
                endpoint.send(&reply)?;
                directions[1].sent();
                observer.frame(&sent_event("rov_to_operator", &reply, clock.now().max(t)));
            }
            tally(&mut rov, metrics);
        }
    }
}

/// A GoTo order for a waypoint (centimetres and whole degrees on the wire).
pub(crate) fn goto_order(position_m: [f64; 3], heading_deg: f64) -> Order {
    let cm = |m: f64| (m * 100.0).round().clamp(-32768.0, 32767.0) as i16;
    Order::GoTo {
        x_cm: cm(position_m[0]),
        y_cm: cm(position_m[1]),
        z_cm: cm(position_m[2]),
        heading_deg: (heading_deg.rem_euclid(360.0).round() as u16) % 360,
    }
}

/// What the operator knows of the vehicle: the position and heading of its last status.
fn status_pose(t: SimTime, status: &crate::wire::rov::BasicStatus) -> PoseSample {
    PoseSample {
        t_s: t.as_secs_f64(),
        position_m: [
            f64::from(status.x_cm) / 100.0,
            f64::from(status.y_cm) / 100.0,
            f64::from(status.z_cm) / 100.0,
        ],
        heading_deg: f64::from(status.yaw_deg),
        velocity: [0.0; 4],
        commanded_velocity: [0.0; 4],
        goal_m: None,
        backtrack_m: None,
        link_up: true,
    }
}
