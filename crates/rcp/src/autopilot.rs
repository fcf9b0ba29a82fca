//! The vehicle's autopilot as the ROV engine sees it (the [`Drive`] trait): what moves the
//! vehicle, the engine's demand at each vehicle step, and what the vehicle reports back. (Not
//! the session driver, `driver`, the layer above that runs the engines.)
//!
//! The ROV engine decides, every [`crate::rov::RovConfig::step_s`], what the vehicle should do
//! (the joystick's thrust, a GoTo target, the backtracking target while the link is lost, the
//! arm state and navigation mode the operator asked for, heading hold) and hands it to a
//! [`Drive`] as a [`Demand`]. The drive is the built-in kinematic [`Vehicle`] in simulation, or a
//! real autopilot (`rovlink_field::mavlink`, above this crate); either way the engine reads the
//! vehicle's state back from [`Drive::state`] for the status it sends, for GoTo arrival and for
//! the position stack of the recovery algorithm. Nothing here reads a clock: the time comes with
//! each step. The built-in model comes to rest ([`Vehicle::advance`]), and says when a step
//! would not move it ([`Drive::still_under`]), so that a simulation need not wake for such
//! steps.

use crate::vehicle::{ARRIVAL_DEG, ARRIVAL_M, Command, Vehicle, angle_diff_deg};
use rovlink_link::SimTime;
use rovlink_wire::Nav;
use rovlink_wire::rov::Why;

/// What the ROV engine asks of the vehicle for the next step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Demand {
    /// Thrust (the joystick, or idle) or a GoTo target (an order, or backtracking).
    pub command: Command,
    /// Armed, as the operator last asked (a GoTo arms).
    pub arm: bool,
    /// The navigation mode the operator asked for; [`Nav::Guided`] while the command is a GoTo.
    pub nav: Nav,
    /// Heading to hold under thrust commands, degrees (HoldHeading).
    pub heading_hold_deg: Option<f64>,
    /// True while the operator's heartbeats arrive.
    pub link_up: bool,
}

/// The vehicle as last reported.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveState {
    /// Position, NED m.
    pub position_m: [f64; 3],
    /// Heading, degrees from north, 0..360.
    pub heading_deg: f64,
    /// Roll, degrees, -180..180.
    pub roll_deg: f64,
    /// Pitch, degrees, -180..180.
    pub pitch_deg: f64,
    /// Body velocities: surge, sway, heave (m/s), yaw rate (degrees/s).
    pub velocity: [f64; 4],
    /// What the command in force asks for (same frame and units).
    pub commanded_velocity: [f64; 4],
    /// Armed, as the vehicle reports it.
    pub armed: bool,
    /// The navigation mode the vehicle reports.
    pub nav: Nav,
    /// False while the vehicle (its autopilot) is silent: the status then says RD 0.
    pub responsive: bool,
    /// True while the vehicle has a position estimate (an autopilot without one, e.g. ArduSub
    /// without GPS, DVL or USBL, reports none): GoTo and backtracking need it, and without it
    /// `position_m` is not a position.
    pub position_known: bool,
    /// Why the vehicle does not do what it was asked ([`Why::Nothing`] when it does): an arm
    /// or a mode it refused, or silence.
    pub why: Why,
}

impl DriveState {
    /// A vehicle not heard yet: at the origin, heading north, still, disarmed, in manual,
    /// unresponsive, without a position, for `why`.
    pub fn unheard(why: Why) -> DriveState {
        DriveState {
            position_m: [0.0; 3],
            heading_deg: 0.0,
            roll_deg: 0.0,
            pitch_deg: 0.0,
            velocity: [0.0; 4],
            commanded_velocity: [0.0; 4],
            armed: false,
            nav: Nav::Manual,
            responsive: false,
            position_known: false,
            why,
        }
    }

    /// Distance to a point, m.
    pub fn distance_to(&self, point_m: [f64; 3]) -> f64 {
        rovlink_base::geometry::distance_m(self.position_m, point_m)
    }
}

/// Something the vehicle did that the events and the operator's telemetry report.
#[derive(Debug, Clone, PartialEq)]
pub enum DriveEvent {
    /// The autopilot has been silent for `silent_s` seconds.
    Silent {
        /// How long, s.
        silent_s: f64,
    },
    /// The autopilot is heard again.
    Heard,
    /// The autopilot answered a command (COMMAND_ACK).
    CommandAck {
        /// The command, by its MAVLink name (e.g. `MAV_CMD_COMPONENT_ARM_DISARM`).
        command: String,
        /// The result, by its MAVLink name (e.g. `MAV_RESULT_ACCEPTED`).
        result: String,
        /// True for MAV_RESULT_ACCEPTED (and IN_PROGRESS).
        accepted: bool,
    },
    /// Something asked cannot be done: an arm or a mode the vehicle refused, a GoTo or
    /// backtracking without a position estimate. Reported once per refusal, and in the status
    /// (WHY) while it lasts.
    Refused {
        /// The status's reason.
        why: Why,
        /// The whole story, e.g. the autopilot's own words.
        reason: String,
    },
    /// Anything else worth a line (e.g. a mode the autopilot has no number for).
    Note(String),
    /// Messages from the link that were not used since the last step, `count` of them for
    /// `reason` (a MAVLink autopilot's: `unsigned`, `bad_signature`, `replayed`,
    /// `other_address`, `other_system`): summed in the metrics, said once per source as a
    /// [`DriveEvent::Note`] by the drive.
    MessagesRefused {
        /// Why, as the metrics name it.
        reason: &'static str,
        /// How many.
        count: u64,
    },
}

/// A vehicle the ROV engine drives, stepped every vehicle step.
pub trait Drive: Send {
    /// Acts on `demand` for the step of `dt_s` seconds that starts at `now`.
    fn step(&mut self, now: SimTime, dt_s: f64, demand: &Demand);
    /// The vehicle's state as last known.
    fn state(&self) -> DriveState;
    /// Position within which a GoTo counts as reached, m.
    fn arrival_m(&self) -> f64 {
        ARRIVAL_M
    }
    /// Heading error within which a GoTo counts as reached, degrees.
    fn arrival_deg(&self) -> f64 {
        ARRIVAL_DEG
    }
    /// The events since the last call.
    fn take_events(&mut self) -> Vec<DriveEvent> {
        Vec::new()
    }
    /// True when the vehicle does not stay where idle thrust leaves it (a positively buoyant
    /// vehicle on an autopilot): the ROV engine then holds what a GoTo or recovery's
    /// backtracking reached by asking for it until the operator's next order. The built-in
    /// model stays put by itself (false).
    fn needs_hold(&self) -> bool {
        false
    }
    /// True when a step under `demand` would not move the vehicle (nor turn it): a driver
    /// may then leave it unstepped until something changes. The built-in model says so at
    /// rest ([`Vehicle::rests_under`]); an autopilot, never (false).
    fn still_under(&self, _demand: &Demand) -> bool {
        false
    }
    /// True when the GoTo to `target_m`, `heading_deg` is reached.
    fn reached(&self, target_m: [f64; 3], heading_deg: f64) -> bool {
        let state = self.state();
        state.distance_to(target_m) <= self.arrival_m()
            && angle_diff_deg(heading_deg, state.heading_deg).abs() <= self.arrival_deg()
    }
}

/// The built-in kinematic model: it is armed and in the mode it is asked for, at once.
pub struct SimDrive {
    /// The model.
    pub vehicle: Vehicle,
    armed: bool,
    nav: Nav,
}

impl SimDrive {
    /// A vehicle at rest at `start_m`, heading north, disarmed, in manual.
    pub fn new(start_m: [f64; 3]) -> SimDrive {
        SimDrive {
            vehicle: Vehicle::new(start_m),
            armed: false,
            nav: Nav::Manual,
        }
    }
}

impl Drive for SimDrive {
    fn step(&mut self, _now: SimTime, dt_s: f64, demand: &Demand) {
        self.armed = demand.arm;
        self.nav = demand.nav;
        self.vehicle.heading_hold_deg = demand.heading_hold_deg;
        self.vehicle.advance(dt_s, demand.command);
    }

    fn still_under(&self, demand: &Demand) -> bool {
        let mut vehicle = self.vehicle.clone();
        vehicle.heading_hold_deg = demand.heading_hold_deg;
        vehicle.rests_under(demand.command)
    }

    fn state(&self) -> DriveState {
        let v = &self.vehicle;
        DriveState {
            position_m: v.position_m,
            heading_deg: v.heading_deg,
            roll_deg: 0.0,
            pitch_deg: 0.0,
            velocity: v.velocity,
            commanded_velocity: v.commanded_velocity,
            armed: self.armed,
            nav: self.nav,
            responsive: true,
            position_known: true,
            why: Why::Nothing,
        }
    }

    fn reached(&self, target_m: [f64; 3], heading_deg: f64) -> bool {
        self.vehicle.reached(target_m, heading_deg)
    }
}
