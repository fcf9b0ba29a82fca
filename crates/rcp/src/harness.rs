//! The two ends of a session as harnesses around the engines: what the one driver
//! (`rcp::driver`, the layer above) runs, in virtual time and in real time.
//!
//! An end is given the time by its driver (virtual or the host's monotonic clock) and the
//! frames that arrived; it returns the frames to send. Everything between the link and the
//! engines is here, once:
//!
//! - [`OperatorEnd`]: drains its [`OrderSource`]s (a script, a JSON Lines console, a Foxglove
//!   client) into the operator engine, sends each slot's frame, notices when the ROV's answers
//!   stop (the operator's side of a lost link) and shows each status as a pose;
//! - [`RovEnd`]: steps the vehicle (through its [`crate::autopilot::Drive`]), answers each frame,
//!   and numbers the orders it executes so that an order executed twice is counted;
//! - [`Tally`]: the one place events become the session's counters ([`Tally::record`]);
//! - [`Out`]: a tally and an [`Observer`], which every event, pose and image goes through.
//!
//! Nothing here reads a clock or blocks; nothing panics on any frame or order.

use std::collections::HashMap;

use crate::operator::{Operator, SlotContent};
use crate::orders::{Live, OrderSource};
use crate::report::{Metrics, Observer, image_period_s};
use crate::rov::Rov;
use crate::rules;
use crate::{Event, PoseSample, Role};
use rovlink_link::SimTime;
use rovlink_wire::frame::Frame;
use rovlink_wire::operator::Order;
use rovlink_wire::rov::BasicStatus;
use rovlink_wire::{Message, MessageRepr};

/// The session's counters, from the events of one end (real time) or both (simulation).
#[derive(Debug, Default)]
pub struct Tally {
    /// The counters so far (the direction figures are the driver's).
    pub metrics: Metrics,
    /// True when this tally sees both ends (simulation): acknowledgements are then checked
    /// against executions.
    both_ends: bool,
    /// Executions per order, by the order's number.
    executions: HashMap<u64, u64>,
    image_times_s: Vec<f64>,
    /// WHY of the last status the operator saw.
    last_why: Option<rovlink_wire::rov::Why>,
}

impl Tally {
    /// A tally of one end (`both_ends` false) or of both.
    pub fn new(both_ends: bool) -> Tally {
        Tally {
            both_ends,
            ..Tally::default()
        }
    }

    /// Counts `event` of `end` at `t_s`. `order` is the number of the order the frame that
    /// caused it carried (for an execution): the operator's own number in simulation, the
    /// ROV's numbering in real time ([`RovEnd`]).
    pub fn record(&mut self, end: Role, t_s: f64, event: &Event, order: Option<u64>) {
        let m = &mut self.metrics;
        match (end, event) {
            (Role::Rov, Event::OrderExecuted(_)) => {
                m.orders_executed += 1;
                if let Some(index) = order {
                    let count = self.executions.entry(index).or_insert(0);
                    *count += 1;
                    if *count > 1 {
                        m.orders_executed_twice += 1;
                    }
                }
            }
            (Role::Rov, Event::ImageStarted { .. }) => m.images_started += 1,
            (Role::Rov, Event::LinkLost) => m.link_losses += 1,
            (Role::Rov, Event::LinkRecovered) => m.link_recoveries += 1,
            (Role::Rov, Event::Vehicle(crate::autopilot::DriveEvent::Refused { .. })) => {
                m.refusals += 1;
            }
            (
                Role::Rov,
                Event::Vehicle(crate::autopilot::DriveEvent::MessagesRefused { reason, count }),
            ) => {
                *m.mavlink_refused.entry(*reason).or_default() += count;
            }
            (Role::Operator, Event::Status(repr)) => {
                if let rovlink_wire::Message::Rov(rovlink_wire::rov::Repr {
                    status: rovlink_wire::rov::Status::Basic(status),
                    ..
                }) = &repr.message
                {
                    let why = status.why();
                    if why != rovlink_wire::rov::Why::Nothing && Some(why) != self.last_why {
                        m.refusals += 1;
                    }
                    self.last_why = Some(why);
                    if !status.position_known() {
                        m.statuses_without_position += 1;
                    }
                }
            }
            (Role::Operator, Event::OrderSent { .. }) => m.orders_sent += 1,
            (Role::Operator, Event::OrderAcknowledged(index)) => {
                m.orders_acknowledged += 1;
                if self.both_ends && !self.executions.contains_key(index) {
                    m.orders_acknowledged_unexecuted += 1;
                }
            }
            (Role::Operator, Event::ImageCompleted(_)) => {
                m.images_completed += 1;
                self.image_times_s.push(t_s);
            }
            _ => {}
        }
    }

    /// The counters, with the image period, for a run that lasted `duration_s`.
    pub fn finish(mut self, measured_by: &'static str, duration_s: f64) -> Metrics {
        self.metrics.image_period_s = image_period_s(&self.image_times_s);
        self.metrics.measured_by = measured_by;
        self.metrics.duration_s = duration_s;
        self.metrics
    }
}

/// Where an end's events go: counted, then shown as `vehicle`'s.
pub struct Out<'a> {
    /// The counters.
    pub tally: &'a mut Tally,
    /// The outputs.
    pub observer: &'a mut dyn Observer,
    /// The vehicle whose session this is.
    pub vehicle: u8,
}

impl Out<'_> {
    /// Counts and shows `event` of `end` at `t`; a completed image also goes to
    /// [`Observer::image`].
    pub fn record(&mut self, end: Role, t: SimTime, event: &Event, order: Option<u64>) {
        let t_s = t.as_secs_f64();
        self.tally.record(end, t_s, event, order);
        self.observer.event(self.vehicle, end, t_s, event);
        if let Event::ImageCompleted(stream) = event {
            self.observer.image(self.vehicle, t_s, stream);
        }
    }

    /// Shows the vehicle's pose.
    pub fn pose(&mut self, pose: &PoseSample) {
        self.observer.pose(self.vehicle, pose);
    }
}

/// The operator's end: its engine and where its orders come from.
pub struct OperatorEnd {
    engine: Operator,
    sources: Vec<Box<dyn OrderSource>>,
    last_answer: SimTime,
    answers_up: bool,
    last_status: Option<BasicStatus>,
    /// True when each new status is shown as the pose (when the operator is the only end the
    /// observer sees: in simulation the ROV's own steps are the poses).
    pub status_poses: bool,
    /// Silence after which the ROV's answers count as lost, s ([`rules::LINK_TIMEOUT_S`] until
    /// the driver sets [`rules::link_timeout_s`] of its cycle).
    pub answers_timeout_s: f64,
}

impl OperatorEnd {
    /// The operator polling the ROV at `rov_address` every `ipg_s`, its orders from `sources`
    /// (drained in turn at every instant).
    pub fn new(rov_address: u8, ipg_s: f64, sources: Vec<Box<dyn OrderSource>>) -> OperatorEnd {
        OperatorEnd {
            engine: Operator::new(rov_address, (ipg_s * 1e9).round().max(1.0) as u64),
            sources,
            last_answer: SimTime::ZERO,
            answers_up: true,
            last_status: None,
            status_poses: false,
            answers_timeout_s: rules::LINK_TIMEOUT_S,
        }
    }

    /// The same end expecting images with parity ([`Operator::with_parity`]).
    pub fn with_parity(mut self, parity: bool) -> OperatorEnd {
        self.engine = self.engine.with_parity(parity);
        self
    }

    /// The same end with its first slot at `first` (its vehicle's place in a multi-vehicle
    /// cycle; `ipg_s` is then the cycle's length).
    pub fn first_slot_at(mut self, first: SimTime) -> OperatorEnd {
        self.engine = self.engine.first_slot_at(first);
        self
    }

    /// When the end wants to run next: its next slot, or the next scripted order.
    pub fn next_at(&self) -> SimTime {
        self.sources
            .iter()
            .filter_map(|s| s.next_at())
            .chain([self.engine.poll_at()])
            .min()
            .unwrap_or(self.engine.poll_at())
    }

    /// When the next slot is due.
    pub fn slot_at(&self) -> SimTime {
        self.engine.poll_at()
    }

    /// Takes the orders due at `now`; returns the slot's frame when the slot is due
    /// (`now >= slot_at()`), with what it carries.
    pub fn poll(&mut self, now: SimTime, out: &mut Out<'_>) -> Option<(Vec<u8>, SlotContent)> {
        self.take_orders(now, out);
        if self.answers_up
            && now.0.saturating_sub(self.last_answer.0) as f64 * 1e-9 > self.answers_timeout_s
        {
            self.answers_up = false;
            out.record(Role::Operator, now, &Event::AnswersLost, None);
        }
        if self.engine.poll_at() > now {
            return None;
        }
        let slot = self.engine.poll(now);
        self.flush(now, out);
        Some(slot)
    }

    fn take_orders(&mut self, now: SimTime, out: &mut Out<'_>) {
        for source in &mut self.sources {
            for warning in source.take_warnings() {
                out.observer.warning(now.as_secs_f64(), &warning);
            }
            for live in source.poll(now) {
                match live {
                    Live::Joystick {
                        joystick,
                        arm,
                        disarm,
                        nav,
                    } => {
                        self.engine.set_joystick(joystick);
                        self.engine.set_modes(arm, disarm, nav);
                    }
                    Live::Order(order) => {
                        self.engine.push_order(order);
                    }
                    Live::Cancel => self.engine.cancel(),
                }
            }
        }
    }

    /// Takes a ROV frame received at `t`.
    pub fn receive(&mut self, t: SimTime, bytes: &[u8], out: &mut Out<'_>) {
        self.last_answer = t;
        if !self.answers_up {
            self.answers_up = true;
            out.record(Role::Operator, t, &Event::AnswersBack, None);
        }
        self.engine.receive(t, bytes);
        self.flush(t, out);
        if self.engine.last_status != self.last_status {
            self.last_status = self.engine.last_status;
            if let (Some(status), true) = (&self.last_status, self.status_poses) {
                out.pose(&status_pose(t, status));
            }
        }
    }

    fn flush(&mut self, t: SimTime, out: &mut Out<'_>) {
        for event in self.engine.take_events() {
            out.record(Role::Operator, t, &event, None);
        }
    }
}

/// What the operator knows of the vehicle: the position and heading of its last status.
pub fn status_pose(t: SimTime, status: &BasicStatus) -> PoseSample {
    PoseSample {
        t_s: t.as_secs_f64(),
        position_m: [status.x_cm, status.y_cm, status.z_cm].map(|cm| f64::from(cm) / 100.0),
        heading_deg: f64::from(status.yaw_deg),
        velocity: [0.0; 4],
        commanded_velocity: [0.0; 4],
        goal_m: None,
        backtrack_m: None,
        link_up: true,
    }
}

/// The ROV's end: its engine, and the numbering of the orders it executes.
pub struct RovEnd {
    /// The engine (read its state for distances and poses).
    pub engine: Rov,
    /// The high-level order of the last operator frame received, with its number.
    last_order: Option<(Order, bool, u64)>,
    next_number: u64,
    /// True when every vehicle step's pose is wanted as it happens (a track, a log, a live
    /// view): the end then runs at every step. Otherwise it sleeps while the vehicle is still
    /// ([`Rov::poll_at`]): the steps slept through run when it next runs or when a frame
    /// arrives (the same steps, the same results), and not every one's pose is shown.
    pub poses_every_step: bool,
}

impl RovEnd {
    /// The end around `engine`.
    pub fn new(engine: Rov) -> RovEnd {
        RovEnd {
            engine,
            last_order: None,
            next_number: 0,
            poses_every_step: true,
        }
    }

    /// When the end wants to run next: the next vehicle step, or with
    /// [`RovEnd::poses_every_step`] off, [`Rov::poll_at`].
    pub fn next_at(&self) -> SimTime {
        if self.poses_every_step {
            self.engine.next_step_at()
        } else {
            self.engine.poll_at()
        }
    }

    /// Runs every vehicle step due by `now`; each step's pose goes to the observer.
    pub fn poll(&mut self, now: SimTime, out: &mut Out<'_>) {
        while self.engine.next_step_at() <= now {
            let step = self.engine.next_step_at();
            self.engine.poll(step);
            self.flush(step, None, out);
            out.pose(&self.engine.pose(step.as_secs_f64()));
        }
    }

    /// Takes an operator frame received at `t`; returns the answer to send at once. `order`
    /// is the number of the order the frame carries when the driver knows it (simulation: the
    /// operator's own); otherwise the ROV numbers orders itself: a frame carrying the same
    /// high-level order with the same OID as the frame before it is the same order resent, any
    /// other is a new one (so an order executed again after its acknowledgement counts twice).
    pub fn receive(
        &mut self,
        t: SimTime,
        bytes: &[u8],
        order: Option<u64>,
        out: &mut Out<'_>,
    ) -> Option<Vec<u8>> {
        let number = order.or_else(|| self.number(bytes));
        let reply = self.engine.receive(t, bytes);
        self.flush(t, number, out);
        reply
    }

    fn number(&mut self, bytes: &[u8]) -> Option<u64> {
        let repr = Frame::new_checked(bytes)
            .ok()
            .and_then(|f| MessageRepr::parse(&f).ok())?;
        let Message::Operator(msg) = repr.message else {
            return None;
        };
        if matches!(msg.order, Order::Velocity(_) | Order::Unknown { .. }) {
            self.last_order = None;
            return None;
        }
        let number = match self.last_order {
            Some((order, oid, number)) if order == msg.order && oid == msg.oid => number,
            _ => {
                self.next_number += 1;
                self.next_number
            }
        };
        self.last_order = Some((msg.order, msg.oid, number));
        Some(number)
    }

    fn flush(&mut self, t: SimTime, order: Option<u64>, out: &mut Out<'_>) {
        for event in self.engine.take_events() {
            out.record(Role::Rov, t, &event, order);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::Quiet;
    use rovlink_wire::frame::ADDR_OPERATOR;
    use rovlink_wire::{Nav, operator};

    fn frame(oid: bool, order: Order) -> Vec<u8> {
        crate::emit(
            ADDR_OPERATOR,
            1,
            Message::Operator(operator::Repr {
                oid,
                clo: false,
                eisn: false,
                ic: false,
                rit: 0,
                order,
            }),
        )
    }

    const GOTO: Order = Order::GoTo {
        x_cm: 150,
        y_cm: 0,
        z_cm: 0,
        heading_deg: 0,
    };

    #[test]
    fn the_tally_counts_a_second_execution_of_one_order() {
        let mut tally = Tally::new(false);
        let executed = Event::OrderExecuted(GOTO);
        tally.record(Role::Rov, 1.0, &executed, Some(7));
        tally.record(Role::Rov, 2.0, &executed, Some(8));
        assert_eq!(tally.metrics.orders_executed_twice, 0);
        tally.record(Role::Rov, 3.0, &executed, Some(7));
        assert_eq!(tally.metrics.orders_executed_twice, 1);
        // One end alone cannot tell an acknowledged order from an unexecuted one.
        tally.record(Role::Operator, 3.0, &Event::OrderAcknowledged(99), None);
        let metrics = tally.finish("rov", 3.0);
        assert_eq!(metrics.orders_acknowledged_unexecuted, 0);
        assert_eq!(metrics.orders_executed, 3);
    }

    #[test]
    fn the_rov_numbers_a_resent_order_as_the_same_and_the_next_as_new() {
        let mut rov = RovEnd::new(Rov::new(Default::default(), [0.0; 3], Vec::new()));
        let velocity = Order::Velocity(operator::Velocity {
            vx: 0,
            vy: 0,
            vz: 0,
            vyaw: 0,
            arm: true,
            disarm: false,
            nav: Nav::Manual,
        });
        assert_eq!(rov.number(&frame(false, GOTO)), Some(1));
        assert_eq!(rov.number(&frame(false, GOTO)), Some(1));
        // The next order (same content, the toggled OID) is another order.
        assert_eq!(rov.number(&frame(true, GOTO)), Some(2));
        assert_eq!(rov.number(&frame(true, velocity)), None);
        assert_eq!(rov.number(&frame(true, GOTO)), Some(3));
        assert_eq!(rov.number(b"garbage"), None);
    }

    #[test]
    fn the_operator_notices_silence_and_answers_again() {
        let mut operator = OperatorEnd::new(1, 0.5, Vec::new());
        let mut tally = Tally::new(false);
        let mut observer = Quiet;
        let mut out = Out {
            tally: &mut tally,
            observer: &mut observer,
            vehicle: 1,
        };
        let mut events = Vec::new();
        struct Seen<'a>(&'a mut Vec<Event>);
        impl Observer for Seen<'_> {
            fn event(&mut self, _vehicle: u8, _end: Role, _t_s: f64, event: &Event) {
                self.0.push(event.clone());
            }
        }
        let mut seen = Seen(&mut events);
        out.observer = &mut seen;
        let mut t = SimTime::ZERO;
        let mut frames = 0;
        while t < SimTime::from_secs_f64(6.0) {
            frames += usize::from(operator.poll(t, &mut out).is_some());
            t = operator.next_at();
        }
        assert_eq!(frames, 12);
        let mut rov = Rov::new(Default::default(), [0.0; 3], Vec::new());
        let (slot, _) = operator.poll(t, &mut out).unwrap();
        let reply = rov.receive(t, &slot).unwrap();
        operator.receive(t, &reply, &mut out);
        assert_eq!(
            events
                .iter()
                .filter(|e| matches!(e, Event::AnswersLost | Event::AnswersBack))
                .collect::<Vec<_>>(),
            [&Event::AnswersLost, &Event::AnswersBack]
        );
        assert!(events.iter().any(|e| matches!(e, Event::Status(_))));
    }
}
