//! The ROV's side of the protocol: answers each operator message in its slot, executes orders
//! exactly once, sends camera images trunk by trunk, and recovers the link by backtracking.
//!
//! [`Rov::receive`] takes an operator frame and returns the reply to send at once (the TDMA
//! slave transmits only in answer). [`Rov::poll`] advances the vehicle and the recovery timers;
//! [`Rov::poll_at`] says when it next wants to be called. Nothing here reads a clock.
//!
//! Recovery (wire.md, the paper's Algorithm 1): while heartbeats arrive the position is stacked
//! every 2 s; after 5 s without one the ROV drives back through the stacked positions, newest
//! first, until a heartbeat arrives. A GoTo in execution when the link is lost is abandoned (it
//! is what took the ROV out of range; resuming it would oscillate at the range's edge): after
//! recovery the ROV holds position under the joystick until the operator orders again.
//!
//! Holding: on a vehicle that does not stay put when idle ([`Drive::needs_hold`]: a buoyant
//! vehicle on an autopilot), what a GoTo reached, and where recovery's backtracking was going
//! when the link came back, is held (the drive is still asked to go there: an autopilot stays
//! in GUIDED at the setpoint) until the operator's next order: a Velocity order that differs from the one in
//! force when the hold began (stick input, arm, disarm, another mode), or a GoTo or
//! HoldHeading. The status says RD 1 meanwhile: no order is in execution.
//!
//! Refusals: a vehicle without a position estimate ([`DriveState::position_known`] false)
//! cannot run a GoTo nor backtrack: the GoTo is refused at once (EOID toggles, nothing is
//! executed, the vehicle keeps the sticks' mode) and the status says why (ST = 1, WHY
//! no_position, until the operator's next order); backtracking is skipped (the vehicle holds
//! its depth with neutral sticks). The drive's own reasons (an arm or a mode the autopilot
//! refused, silence) go into the same field while they last; NP says the pose is unknown.

use std::collections::VecDeque;

use crate::autopilot::DriveEvent;
use crate::autopilot::{Demand, Drive, DriveState, SimDrive};
use crate::camera::{Camera, Cycle};
use crate::trunk_cache::TrunkCache;
use crate::vehicle::Command;
use crate::{Event, ImageSettings, PoseSample, emit};
use rovlink_debt as debt;
use rovlink_link::SimTime;
use rovlink_wire::frame::{ADDR_OPERATOR, Frame};
use rovlink_wire::operator::{Order, Velocity};
use rovlink_wire::rov::{BasicStatus, Extension, Status, Why};
use rovlink_wire::{Message, MessageRepr, Nav, rov};

/// The ROV's fixed figures.
#[derive(Debug, Clone, PartialEq)]
pub struct RovConfig {
    /// Its address, 1..=14.
    pub address: u8,
    /// Silence after which the link counts as lost, s.
    pub heartbeat_timeout_s: f64,
    /// Period of the position stack while the link is up, s.
    pub stack_period_s: f64,
    /// Positions kept (oldest dropped).
    pub stack_depth: usize,
    /// Time step of the vehicle simulation, s.
    pub step_s: f64,
    /// Image settings until an ImageSettings order changes them.
    pub settings: ImageSettings,
}

impl Default for RovConfig {
    fn default() -> Self {
        RovConfig {
            address: 1,
            heartbeat_timeout_s: crate::rules::LINK_TIMEOUT_S,
            stack_period_s: 2.0,
            stack_depth: 64,
            step_s: 0.1,
            settings: ImageSettings::default(),
        }
    }
}

/// The high-level order being executed.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Executing {
    GoTo([f64; 3], f64),
}

/// A point held after a GoTo or backtracking, until the operator orders otherwise.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Hold {
    /// Where, NED m, and the heading, degrees.
    target_m: [f64; 3],
    heading_deg: f64,
    /// The Velocity order in force when the hold began: a different one ends the hold.
    order: Option<Velocity>,
}

/// An image being sent.
struct Outgoing {
    trunks: Vec<Vec<u8>>,
    /// Trunks sent once so far (the first pass goes in order).
    first_pass: usize,
}

/// The ROV engine.
pub struct Rov {
    cfg: RovConfig,
    drive: Box<dyn Drive>,
    camera: Box<dyn Camera>,
    /// The trunks of the pictures last encoded (a cycling camera repeats its pictures).
    encoded: TrunkCache,
    /// The reason of the last failed capture, to report a failing camera once per reason.
    camera_failure: Option<String>,
    heading_hold_deg: Option<f64>,
    settings: ImageSettings,
    eoid: bool,
    loc: bool,
    executing: Option<Executing>,
    hold: Option<Hold>,
    /// The last Velocity order received.
    velocity: Option<Velocity>,
    /// A refusal of the engine's own (a GoTo without position), reported until the next order.
    refused: Option<Why>,
    /// True while backtracking is skipped for want of a position (reported once per loss).
    backtrack_refused: bool,
    arm: bool,
    nav: Nav,
    joystick: [f64; 4],
    isn: bool,
    ci: bool,
    image: Option<Outgoing>,
    last_heartbeat: SimTime,
    link_up: bool,
    stack: VecDeque<[f64; 3]>,
    next_push: SimTime,
    next_step: SimTime,
    events: Vec<Event>,
}

impl Rov {
    /// A simulated ROV at `start` (NED, m) whose camera yields `images`, cycled.
    pub fn new(cfg: RovConfig, start: [f64; 3], images: Vec<debt::Image>) -> Rov {
        Rov::with(
            cfg,
            Box::new(SimDrive::new(start)),
            Box::new(Cycle::new(images)),
        )
    }

    /// A ROV moved by `drive` (the built-in model or an autopilot) with `camera`.
    pub fn with(cfg: RovConfig, drive: Box<dyn Drive>, camera: Box<dyn Camera>) -> Rov {
        Rov {
            settings: cfg.settings,
            drive,
            camera,
            encoded: TrunkCache::default(),
            camera_failure: None,
            heading_hold_deg: None,
            eoid: false,
            loc: false,
            executing: None,
            hold: None,
            velocity: None,
            refused: None,
            backtrack_refused: false,
            arm: false,
            nav: Nav::Manual,
            joystick: [0.0; 4],
            isn: false,
            ci: false,
            image: None,
            last_heartbeat: SimTime::ZERO,
            link_up: true,
            stack: VecDeque::new(),
            next_push: SimTime::ZERO,
            next_step: SimTime::ZERO,
            events: Vec::new(),
            cfg,
        }
    }

    /// Takes the events since the last call.
    pub fn take_events(&mut self) -> Vec<Event> {
        std::mem::take(&mut self.events)
    }

    /// True while heartbeats arrive.
    pub fn link_up(&self) -> bool {
        self.link_up
    }

    /// The vehicle as last known.
    pub fn state(&self) -> DriveState {
        self.drive.state()
    }

    /// The vehicle's state at `t_s` for logs and plots.
    pub fn pose(&self, t_s: f64) -> PoseSample {
        let state = self.drive.state();
        PoseSample {
            t_s,
            position_m: state.position_m,
            heading_deg: state.heading_deg,
            velocity: state.velocity,
            commanded_velocity: state.commanded_velocity,
            goal_m: self.executing.map(|Executing::GoTo(target, _)| target),
            backtrack_m: if self.link_up {
                None
            } else {
                self.stack.back().copied()
            },
            link_up: self.link_up,
        }
    }

    /// When [`Rov::poll`] wants to run next: the next vehicle step, or, while the link is up,
    /// nothing is executed or held and the vehicle stays still under the sticks
    /// ([`Drive::still_under`]), a step before the heartbeat timeout (nothing else changes
    /// by itself until then; a frame received meanwhile catches the steps up first).
    pub fn poll_at(&self) -> SimTime {
        if self.still() {
            return self.last_still_step().max(self.next_step);
        }
        self.next_step
    }

    /// True while nothing changes by itself but the position stack and, at its time, the
    /// link's state: the link is up, nothing is executed or held, and the vehicle stays still
    /// under the sticks ([`Drive::still_under`]).
    fn still(&self) -> bool {
        self.link_up
            && self.executing.is_none()
            && self.hold.is_none()
            && self.drive.state().position_known
            && self.drive.still_under(&self.demand(self.sticks()))
    }

    /// A step before the heartbeat timeout: the last that a still ROV may leave unrun.
    fn last_still_step(&self) -> SimTime {
        let timeout_s = self.cfg.heartbeat_timeout_s - self.cfg.step_s;
        self.last_heartbeat.after_secs(timeout_s)
    }

    /// When the next vehicle step is due ([`Rov::poll`] runs every step due by its time).
    pub fn next_step_at(&self) -> SimTime {
        self.next_step
    }

    /// Advances the vehicle to `now` and runs the recovery algorithm.
    ///
    /// While the ROV is still (after one step under the demand in force, so the drive has
    /// it), the steps due are not run one by one: all they would do is stack the same position
    /// every [`RovConfig::stack_period_s`], which is done at those steps' times alone.
    pub fn poll(&mut self, now: SimTime) {
        while self.next_step <= now {
            let t = self.next_step;
            self.step(t);
            self.next_step = t.after_secs(self.cfg.step_s);
            if self.next_step <= now && self.still() {
                self.rest_until(now.min(self.last_still_step()));
            }
        }
    }

    /// Runs the still steps due by `last` at once: the position stacked at each step a push
    /// is due, as the steps would.
    fn rest_until(&mut self, last: SimTime) {
        let step_ns = SimTime::ZERO.after_secs(self.cfg.step_s).0;
        if step_ns == 0 || last < self.next_step {
            return;
        }
        let first = self.next_step;
        let end = SimTime(first.0 + (last.0 - first.0) / step_ns * step_ns);
        let position_m = self.drive.state().position_m;
        while self.next_push <= end {
            // The first of the skipped steps at or after the push's time.
            let after_ns = self.next_push.0.saturating_sub(first.0);
            let at = SimTime(first.0 + after_ns.div_ceil(step_ns) * step_ns);
            self.push(position_m);
            self.next_push = at.after_secs(self.cfg.stack_period_s);
        }
        self.next_step = end.after_secs(self.cfg.step_s);
    }

    /// Stacks `position_m`, dropping the oldest when the stack is full.
    fn push(&mut self, position_m: [f64; 3]) {
        if self.stack.len() == self.cfg.stack_depth {
            self.stack.pop_front();
        }
        self.stack.push_back(position_m);
    }

    fn step(&mut self, now: SimTime) {
        let since = now.0.saturating_sub(self.last_heartbeat.0) as f64 * 1e-9;
        if self.link_up && since > self.cfg.heartbeat_timeout_s {
            self.link_up = false;
            // The order in execution led out of range: it is abandoned, so that once the link
            // is back the ROV holds where it regained it instead of driving out again.
            self.executing = None;
            self.hold = None;
            self.events.push(Event::LinkLost);
        }
        let position_known = self.drive.state().position_known;
        if !position_known {
            if let Some(Executing::GoTo(..)) = self.executing.take() {
                self.refuse(
                    Why::NoPosition,
                    "the GoTo in execution was abandoned: the vehicle lost its position estimate"
                        .to_string(),
                );
            }
            self.hold = None;
        }
        if self.link_up && now >= self.next_push {
            self.push(self.drive.state().position_m);
            self.next_push = now.after_secs(self.cfg.stack_period_s);
        }
        let command = if !self.link_up && !position_known {
            // No position: nothing to backtrack to; neutral sticks (a depth-holding mode).
            if !self.backtrack_refused {
                self.backtrack_refused = true;
                self.events.push(Event::Vehicle(DriveEvent::Refused {
                    why: Why::NoPosition,
                    reason: "link lost: no backtracking, the vehicle has no position estimate; it holds its depth with neutral sticks".to_string(),
                }));
            }
            idle()
        } else if !self.link_up {
            // Backtracking: drive to the newest stacked position, pop it when reached.
            while let Some(&back) = self.stack.back() {
                if self.drive.state().distance_to(back) > self.drive.arrival_m()
                    || self.stack.len() == 1
                {
                    break;
                }
                self.stack.pop_back();
            }
            match self.stack.back() {
                Some(&[x, y, z]) => Command::GoTo {
                    x,
                    y,
                    z,
                    heading_deg: self.drive.state().heading_deg,
                },
                None => idle(),
            }
        } else {
            match self.executing {
                Some(Executing::GoTo([x, y, z], heading_deg)) => {
                    if self.drive.reached([x, y, z], heading_deg) {
                        // Done: held there until the operator's next order (by the drive
                        // itself where it stays put when idle).
                        self.executing = None;
                        self.hold = self.drive.needs_hold().then_some(Hold {
                            target_m: [x, y, z],
                            heading_deg,
                            order: self.velocity,
                        });
                        match self.hold {
                            Some(_) => Command::GoTo {
                                x,
                                y,
                                z,
                                heading_deg,
                            },
                            None => self.sticks(),
                        }
                    } else {
                        Command::GoTo {
                            x,
                            y,
                            z,
                            heading_deg,
                        }
                    }
                }
                None => match self.hold {
                    Some(hold) => {
                        let [x, y, z] = hold.target_m;
                        Command::GoTo {
                            x,
                            y,
                            z,
                            heading_deg: hold.heading_deg,
                        }
                    }
                    None => self.sticks(),
                },
            }
        };
        let demand = self.demand(command);
        self.drive.step(now, self.cfg.step_s, &demand);
        self.events
            .extend(self.drive.take_events().into_iter().map(Event::Vehicle));
    }

    /// Takes an operator frame received at `now`; returns the reply frame.
    pub fn receive(&mut self, now: SimTime, bytes: &[u8]) -> Option<Vec<u8>> {
        let frame = Frame::new_checked(bytes).ok()?;
        let repr = MessageRepr::parse(&frame).ok()?;
        if repr.src != ADDR_OPERATOR || (repr.dst != self.cfg.address && repr.dst != 15) {
            return None;
        }
        let Message::Operator(msg) = repr.message else {
            return None;
        };
        self.poll(now);
        self.last_heartbeat = now;
        if !self.link_up {
            self.link_up = true;
            self.backtrack_refused = false;
            // Where backtracking was going is held until the operator orders otherwise.
            let state = self.drive.state();
            let hold = state.position_known && self.drive.needs_hold();
            if let (Some(&target_m), true) = (self.stack.back(), hold) {
                self.hold = Some(Hold {
                    target_m,
                    heading_deg: state.heading_deg,
                    order: self.velocity,
                });
            }
            self.events.push(Event::LinkRecovered);
        }

        if msg.clo && self.executing.is_some() && msg.oid == self.eoid {
            self.executing = None;
            self.loc = true;
            self.events.push(Event::OrderCancelled);
        }
        match msg.order {
            Order::Velocity(order) => {
                if self.velocity != Some(order) {
                    // The operator's next order: a hold or a refusal of the last ends here.
                    if self.hold.is_some_and(|h| h.order != Some(order)) {
                        self.hold = None;
                    }
                    if self.velocity.is_some() {
                        self.refused = None;
                    }
                    self.velocity = Some(order);
                }
                self.joystick = order.axes().map(crate::operator::thrust_percent);
                if order.arm {
                    self.arm = true;
                }
                if order.disarm {
                    self.arm = false;
                }
                self.nav = order.nav;
            }
            order @ (Order::GoTo { .. } | Order::ImageSettings(_) | Order::HoldHeading { .. }) => {
                if msg.oid == self.eoid {
                    self.eoid = !self.eoid;
                    self.loc = false;
                    self.refused = None;
                    if matches!(order, Order::GoTo { .. }) && !self.drive.state().position_known {
                        // Refused at once, and said so: the order is taken (EOID toggles)
                        // but nothing runs.
                        self.refuse(
                            Why::NoPosition,
                            format!("{order:?} refused: the vehicle has no position estimate"),
                        );
                    } else {
                        self.execute(order);
                        self.events.push(Event::OrderExecuted(order));
                    }
                }
            }
            Order::Unknown { .. } => {}
        }

        // Images: IC ends a cancellation; EISN != ISN acknowledges the image.
        if self.ci {
            if msg.ic {
                self.ci = false;
                self.capture();
            }
        } else if self.image.is_none() {
            self.capture();
        } else if msg.eisn != self.isn {
            self.isn = !self.isn;
            self.capture();
        }
        Some(self.reply(msg.rit))
    }

    /// What the drive is asked for under `command`.
    fn demand(&self, command: Command) -> Demand {
        Demand {
            command,
            arm: self.arm,
            nav: match command {
                Command::GoTo { .. } => Nav::Guided,
                Command::Thrust { .. } => self.nav,
            },
            heading_hold_deg: self.heading_hold_deg,
            link_up: self.link_up,
        }
    }

    /// The joystick's thrust while armed, idle otherwise.
    fn sticks(&self) -> Command {
        if self.arm {
            Command::Thrust {
                surge: self.joystick[0],
                sway: self.joystick[1],
                heave: self.joystick[2],
                yaw: self.joystick[3],
            }
        } else {
            idle()
        }
    }

    /// Reports a refusal of the engine's own: an event now, WHY in the status until the next
    /// order.
    fn refuse(&mut self, why: Why, reason: String) {
        self.refused = Some(why);
        self.events
            .push(Event::Vehicle(DriveEvent::Refused { why, reason }));
    }

    fn execute(&mut self, order: Order) {
        if !matches!(order, Order::ImageSettings(_)) {
            self.hold = None;
        }
        match order {
            Order::GoTo {
                x_cm,
                y_cm,
                z_cm,
                heading_deg,
            } => {
                let target = [x_cm, y_cm, z_cm].map(|c| f64::from(c) / 100.0);
                self.executing = Some(Executing::GoTo(target, f64::from(heading_deg)));
                self.arm = true;
                self.nav = Nav::Guided;
            }
            Order::HoldHeading {
                heading_deg,
                enable,
            } => {
                self.heading_hold_deg = enable.then_some(f64::from(heading_deg));
            }
            Order::ImageSettings(image) => {
                // Parity is the session's, not the order's.
                self.settings = ImageSettings {
                    fec_percent: self.settings.fec_percent,
                    ..ImageSettings::from(image)
                };
                if self.image.is_some() {
                    self.ci = true;
                    self.image = None;
                    self.events.push(Event::ImageCancelled);
                }
            }
            Order::Velocity(_) | Order::Unknown { .. } => {}
        }
    }

    /// Encodes the next camera image with the current settings.
    fn capture(&mut self) {
        let picture = match self.camera.capture() {
            Ok(picture) => {
                self.camera_failure = None;
                picture
            }
            Err(reason) => {
                self.image = None;
                if self.camera_failure.as_ref() != Some(&reason) {
                    self.camera_failure = Some(reason.clone());
                    self.events.push(Event::CameraFailed(reason));
                }
                return;
            }
        };
        let trunks = self.encoded.trunks(&picture, &self.settings);
        if trunks.is_empty() {
            // A picture the codec refuses (e.g. larger than DEBT holds): nothing to send.
            self.image = None;
            return;
        }
        self.events.push(Event::ImageStarted {
            trunks: trunks.len(),
            bytes: trunks.iter().map(Vec::len).sum(),
        });
        self.image = Some(Outgoing {
            trunks,
            first_pass: 0,
        });
    }

    fn reply(&mut self, rit: u8) -> Vec<u8> {
        let state = self.drive.state();
        let [x_cm, y_cm, z_cm] = state
            .position_m
            .map(|m| (m * 100.0).round().clamp(-32768.0, 32767.0) as i16);
        // Whole degrees 0..=359 (NaN, never given by a drive, would be 0).
        let degrees = |a: f64| (a.rem_euclid(360.0).round() as u16) % 360;
        let status = BasicStatus {
            // Not ready while executing an order, or while the vehicle does not answer.
            rd: self.executing.is_none() && state.responsive,
            eoid: self.eoid,
            loc: self.loc,
            hh: self.heading_hold_deg.is_some(),
            arm: state.armed,
            nav: state.nav,
            x_cm,
            y_cm,
            z_cm,
            roll_deg: degrees(state.roll_deg),
            pitch_deg: degrees(state.pitch_deg),
            yaw_deg: degrees(state.heading_deg),
            extension: None,
        };
        let why = self.refused.unwrap_or(state.why);
        let status = if !state.position_known || why != Why::Nothing {
            BasicStatus {
                // Without a position, X, Y, Z are not one: 0 rather than a stale value.
                x_cm: if state.position_known { x_cm } else { 0 },
                y_cm: if state.position_known { y_cm } else { 0 },
                z_cm: if state.position_known { z_cm } else { 0 },
                extension: Some(Extension {
                    no_position: !state.position_known,
                    why,
                }),
                ..status
            }
        } else {
            status
        };
        let (mut ft, mut lt, mut itsn, mut trunk) = (false, false, 0u8, Vec::new());
        if let (false, Some(image)) = (
            self.ci,
            self.image.as_mut().filter(|image| !image.trunks.is_empty()),
        ) {
            let n = image.trunks.len();
            let k = if image.first_pass < n {
                image.first_pass += 1;
                image.first_pass - 1
            } else if usize::from(rit) < n {
                usize::from(rit)
            } else {
                n - 1
            };
            ft = k == 0;
            lt = k + 1 == n;
            itsn = k as u8;
            trunk = image.trunks[k].clone();
        }
        // A trunk of the largest size leaves no room for the extension byte: that frame goes
        // as ST = 0 (the next one without such a trunk says it again).
        let status = if trunk.len() > rov::MAX_EXTENDED_TRUNK_BYTES {
            BasicStatus {
                extension: None,
                ..status
            }
        } else {
            status
        };
        let message = Message::Rov(rov::Repr {
            ft,
            lt,
            isn: self.isn,
            ci: self.ci,
            itsn,
            status: Status::Basic(status),
            trunk,
        });
        emit(self.cfg.address, ADDR_OPERATOR, message)
    }
}

fn idle() -> Command {
    Command::Thrust {
        surge: 0.0,
        sway: 0.0,
        heave: 0.0,
        yaw: 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::operator::Operator;

    #[test]
    fn a_picture_the_codec_refuses_sends_status_without_panicking() {
        // Wider than DEBT holds: trunks_of yields nothing (src/rcp/rov.rs used to index trunk
        // n - 1 of none).
        let picture = crate::camera::builtin_picture(4097, 2, 0);
        let mut rov = Rov::new(RovConfig::default(), [1.0, 0.0, 0.0], vec![picture]);
        let mut operator = Operator::new(1, 640_000_000);
        for slot in 0..3u64 {
            let t = SimTime(slot * 640_000_000);
            let (frame, _) = operator.poll(t);
            let reply = rov.receive(t, &frame).expect("a reply to every slot");
            operator.receive(t, &reply);
        }
        assert!(
            !rov.take_events()
                .iter()
                .any(|e| matches!(e, Event::ImageStarted { .. }))
        );
    }

    /// Runs `slots` operator slots of 0.64 s between `operator` and `rov`; returns the ROV's
    /// last status and its events.
    fn slots(
        operator: &mut Operator,
        rov: &mut Rov,
        from: u64,
        slots: u64,
    ) -> (BasicStatus, Vec<Event>) {
        let mut events = Vec::new();
        let mut last = None;
        for slot in from..from + slots {
            let t = SimTime(slot * 640_000_000);
            rov.poll(t);
            let (frame, _) = operator.poll(t);
            let reply = rov.receive(t, &frame).expect("a reply to every slot");
            operator.receive(t, &reply);
            events.extend(rov.take_events());
            last = operator.last_status;
        }
        (last.expect("a status"), events)
    }

    #[test]
    fn a_still_rov_run_late_is_the_rov_run_every_step() {
        // One ROV polled at every 0.1 s step, one only when a frame comes (and at the end):
        // heartbeats for 20 s, then none, so the link times out and backtracking starts.
        let start = [1.0, 2.0, 3.0];
        let mut stepped = Rov::new(RovConfig::default(), start, Vec::new());
        let mut late = Rov::new(RovConfig::default(), start, Vec::new());
        let mut operator = Operator::new(1, 640_000_000);
        let step_ns = 100_000_000;
        let mut t = SimTime::ZERO;
        while t <= SimTime(40_000_000_000) {
            stepped.poll(t);
            if t.0.is_multiple_of(640_000_000) && t.0 < 20_000_000_000 {
                let (frame, _) = operator.poll(t);
                let reply = stepped.receive(t, &frame).expect("a reply to every slot");
                assert_eq!(late.receive(t, &frame), Some(reply.clone()));
                operator.receive(t, &reply);
            }
            t = SimTime(t.0 + step_ns);
        }
        late.poll(SimTime(t.0 - step_ns));
        assert_eq!(late.take_events(), stepped.take_events());
        assert!(!late.link_up());
        assert_eq!(late.stack, stepped.stack);
        assert_eq!(
            (late.next_push, late.next_step),
            (stepped.next_push, stepped.next_step)
        );
        assert_eq!(late.pose(40.0), stepped.pose(40.0));
    }

    const GOTO: Order = Order::GoTo {
        x_cm: 100,
        y_cm: 0,
        z_cm: 0,
        heading_deg: 0,
    };

    /// The built-in model, as a vehicle that needs an explicit hold.
    struct Drifting(SimDrive);

    impl Drive for Drifting {
        fn step(&mut self, now: SimTime, dt_s: f64, demand: &Demand) {
            self.0.step(now, dt_s, demand);
        }
        fn state(&self) -> DriveState {
            self.0.state()
        }
        fn needs_hold(&self) -> bool {
            true
        }
    }

    #[test]
    fn what_a_goto_reached_is_held_until_the_next_order() {
        let mut rov = Rov::with(
            RovConfig::default(),
            Box::new(Drifting(SimDrive::new([0.0; 3]))),
            Box::new(Cycle::new(Vec::new())),
        );
        let mut operator = Operator::new(1, 640_000_000);
        operator.set_modes(true, false, Nav::Stabilize);
        slots(&mut operator, &mut rov, 0, 2);
        operator.push_order(GOTO);
        let (status, events) = slots(&mut operator, &mut rov, 2, 30);
        assert!(events.contains(&Event::OrderExecuted(GOTO)), "{events:?}");
        // Reached and held: RD 1 (nothing in execution), still guided at the target.
        assert!(status.rd && status.nav == Nav::Guided, "{status:?}");
        assert_eq!(status.extension, None);
        assert!((rov.state().position_m[0] - 1.0).abs() < 0.1);
        let (status, _) = slots(&mut operator, &mut rov, 32, 5);
        assert_eq!(
            status.nav,
            Nav::Guided,
            "the same Velocity order keeps the hold"
        );
        // Stick input ends it: back to the operator's mode, the sticks drive.
        operator.set_joystick(crate::operator::Joystick {
            vx: 50.0,
            ..Default::default()
        });
        let (status, _) = slots(&mut operator, &mut rov, 37, 5);
        assert_eq!(status.nav, Nav::Stabilize, "{status:?}");
        assert!(rov.state().position_m[0] > 1.2);
        // The built-in model stays put by itself: no hold, the operator's mode at once.
        let mut sim = Rov::new(RovConfig::default(), [0.0; 3], Vec::new());
        let mut operator = Operator::new(1, 640_000_000);
        operator.set_modes(true, false, Nav::Stabilize);
        slots(&mut operator, &mut sim, 0, 2);
        operator.push_order(GOTO);
        let (status, _) = slots(&mut operator, &mut sim, 2, 30);
        assert!(status.rd && status.nav == Nav::Stabilize, "{status:?}");
        let at = sim.state().position_m;
        assert!((at[0] - 1.0).abs() <= crate::vehicle::ARRIVAL_M, "{at:?}");
    }

    /// The built-in model without a position estimate.
    struct Blind(SimDrive);

    impl Drive for Blind {
        fn step(&mut self, now: SimTime, dt_s: f64, demand: &Demand) {
            self.0.step(now, dt_s, demand);
        }
        fn state(&self) -> DriveState {
            DriveState {
                position_known: false,
                ..self.0.state()
            }
        }
    }

    #[test]
    fn without_a_position_a_goto_is_refused_at_once_and_said_until_the_next_order() {
        let mut rov = Rov::with(
            RovConfig::default(),
            Box::new(Blind(SimDrive::new([2.0, 3.0, 4.0]))),
            Box::new(Cycle::new(Vec::new())),
        );
        let mut operator = Operator::new(1, 640_000_000);
        operator.set_modes(true, false, Nav::Stabilize);
        let (status, _) = slots(&mut operator, &mut rov, 0, 2);
        // No position: NP, and X, Y, Z are not the model's stale 2, 3, 4.
        assert_eq!(
            status.extension,
            Some(Extension {
                no_position: true,
                why: Why::Nothing
            })
        );
        assert_eq!([status.x_cm, status.y_cm, status.z_cm], [0; 3]);
        let index = operator.push_order(GOTO);
        let (status, events) = slots(&mut operator, &mut rov, 2, 4);
        assert!(!events.contains(&Event::OrderExecuted(GOTO)), "{events:?}");
        assert!(
            events.iter().any(|e| matches!(e, Event::Vehicle(DriveEvent::Refused { why: Why::NoPosition, reason }) if reason.contains("no position estimate"))),
            "{events:?}"
        );
        assert_eq!(status.why(), Why::NoPosition);
        assert!(status.rd, "nothing left pending");
        assert_eq!(status.nav, Nav::Stabilize);
        assert!(
            operator
                .take_events()
                .contains(&Event::OrderAcknowledged(index))
        );
        // The next order clears the reason.
        operator.set_modes(true, false, Nav::DepthHold);
        let (status, _) = slots(&mut operator, &mut rov, 6, 3);
        assert_eq!(status.why(), Why::Nothing);
        assert!(!status.position_known());
    }
}
