//! A simple ROV motion model for simulation: four degrees of freedom (north, east, down, yaw).
//!
//! Thrust commands in percent of full thrust become body-frame velocity targets (surge, sway,
//! heave at up to [`Vehicle::max_speed_mps`], yaw rate up to [`Vehicle::max_yaw_rate_dps`]); the
//! velocities follow their targets with a first-order lag of [`Vehicle::time_constant_s`]. A
//! go-to is a bounded proportional controller on the position error (in the vehicle's frame)
//! and on the heading error; heading hold is the same controller on yaw alone. Positions are
//! NED metres from the origin, the heading in degrees from north, clockwise.
//!
//! The model is a plain state machine: [`Vehicle::step`] advances it by a time step.
//! [`Vehicle::advance`] is the same step that also comes to rest: once the command asks for
//! less than [`REST_MPS`] (and [`REST_DPS`] in yaw) and the velocities have decayed below
//! that too, the rest of the lag's way is added in closed form and the velocities are set to
//! zero; from then on a step under such a command changes nothing ([`Vehicle::rests_under`]),
//! so a driver need not step a vehicle at rest at all. Against [`Vehicle::step`] alone (the
//! exponential tail followed forever) a track differs by at most [`REST_TOLERANCE_M`] and
//! [`REST_TOLERANCE_DEG`].

/// What the vehicle is asked to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Thrust in percent of full thrust: surge, sway, heave, yaw (-100..=100).
    Thrust {
        /// Forward.
        surge: f64,
        /// Starboard.
        sway: f64,
        /// Down.
        heave: f64,
        /// Clockwise.
        yaw: f64,
    },
    /// Go to a point (NED, m) and turn to a heading (degrees).
    GoTo {
        /// North, m.
        x: f64,
        /// East, m.
        y: f64,
        /// Down, m.
        z: f64,
        /// Heading, degrees.
        heading_deg: f64,
    },
}

/// The simulated vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct Vehicle {
    /// Position, NED metres.
    pub position_m: [f64; 3],
    /// Heading, degrees 0..360.
    pub heading_deg: f64,
    /// Body velocities: surge, sway, heave (m/s), yaw rate (degrees/s).
    pub velocity: [f64; 4],
    /// The velocities the last step's command asked for (same frame and units as `velocity`;
    /// `velocity` follows them with the lag).
    pub commanded_velocity: [f64; 4],
    /// Speed at full thrust, m/s.
    pub max_speed_mps: f64,
    /// Yaw rate at full thrust, degrees/s.
    pub max_yaw_rate_dps: f64,
    /// Time constant of the velocity response, s.
    pub time_constant_s: f64,
    /// Heading held when heading hold is on (degrees), applied to yaw thrust.
    pub heading_hold_deg: Option<f64>,
}

/// Distance within which a go-to counts as reached, m.
pub const ARRIVAL_M: f64 = 0.25;

/// Heading error within which a go-to counts as reached, degrees.
pub const ARRIVAL_DEG: f64 = 5.0;

/// Speed below which a vehicle comes to rest when its command asks for no more, m/s.
pub const REST_MPS: f64 = 1e-6;

/// Yaw rate below which a vehicle comes to rest when its command asks for no more, degrees/s.
pub const REST_DPS: f64 = 1e-6;

/// The most a track of [`Vehicle::advance`] differs from one of [`Vehicle::step`], m: what
/// the lag and the go-to controller (25 % of the error per second) would still have moved at
/// rest speeds, with a margin.
pub const REST_TOLERANCE_M: f64 = 1e-5;

/// The most a heading of [`Vehicle::advance`] differs from one of [`Vehicle::step`], degrees
/// (heading hold turns at 0.9 degrees/s per degree of error).
pub const REST_TOLERANCE_DEG: f64 = 1e-5;

/// Wraps an angle difference into -180..180 degrees.
pub fn angle_diff_deg(to: f64, from: f64) -> f64 {
    (to - from + 540.0).rem_euclid(360.0) - 180.0
}

impl Vehicle {
    /// A vehicle at rest at `position_m`, heading north, with a small ROV's figures (0.5 m/s,
    /// 30 degrees/s, 1 s lag).
    pub fn new(position_m: [f64; 3]) -> Vehicle {
        Vehicle {
            position_m,
            heading_deg: 0.0,
            velocity: [0.0; 4],
            commanded_velocity: [0.0; 4],
            max_speed_mps: 0.5,
            max_yaw_rate_dps: 30.0,
            time_constant_s: 1.0,
            heading_hold_deg: None,
        }
    }

    /// Distance to a point, m.
    pub fn distance_to(&self, point: [f64; 3]) -> f64 {
        rovlink_base::geometry::distance_m(self.position_m, point)
    }

    /// True when a go-to target is reached (position and heading).
    pub fn reached(&self, target: [f64; 3], heading_deg: f64) -> bool {
        self.distance_to(target) <= ARRIVAL_M
            && angle_diff_deg(heading_deg, self.heading_deg).abs() <= ARRIVAL_DEG
    }

    /// The thrust (percent) a command asks for now.
    pub fn thrust_for(&self, command: Command) -> [f64; 4] {
        let mut thrust = match command {
            Command::Thrust {
                surge,
                sway,
                heave,
                yaw,
            } => [surge, sway, heave, yaw],
            Command::GoTo {
                x,
                y,
                z,
                heading_deg,
            } => {
                // Position error in the body frame, proportional gain: full thrust 2 m away.
                let (dn, de, dd) = (
                    x - self.position_m[0],
                    y - self.position_m[1],
                    z - self.position_m[2],
                );
                let psi = self.heading_deg.to_radians();
                let surge = dn * psi.cos() + de * psi.sin();
                let sway = -dn * psi.sin() + de * psi.cos();
                let gain = 50.0; // percent per metre
                let mut t = [surge * gain, sway * gain, dd * gain];
                let largest = t.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                if largest > 100.0 {
                    t.iter_mut().for_each(|v| *v *= 100.0 / largest);
                }
                let yaw =
                    (angle_diff_deg(heading_deg, self.heading_deg) * 3.0).clamp(-100.0, 100.0);
                [t[0], t[1], t[2], yaw]
            }
        };
        if let (Some(hold), Command::Thrust { .. }) = (self.heading_hold_deg, command) {
            thrust[3] = (angle_diff_deg(hold, self.heading_deg) * 3.0).clamp(-100.0, 100.0);
        }
        thrust.map(|t| t.clamp(-100.0, 100.0))
    }

    /// The body velocities `command` asks for now (the frame and units of `velocity`).
    pub fn target_velocity(&self, command: Command) -> [f64; 4] {
        let thrust = self.thrust_for(command);
        let limits = [
            self.max_speed_mps,
            self.max_speed_mps,
            self.max_speed_mps,
            self.max_yaw_rate_dps,
        ];
        std::array::from_fn(|k| thrust[k] / 100.0 * limits[k])
    }

    /// Advances the vehicle by `dt_s` under `command` (first-order lag, then Euler).
    pub fn step(&mut self, dt_s: f64, command: Command) {
        let target = self.target_velocity(command);
        let alpha = (dt_s / self.time_constant_s).min(1.0);
        for (k, &target) in target.iter().enumerate() {
            self.commanded_velocity[k] = target;
            self.velocity[k] += (target - self.velocity[k]) * alpha;
        }
        self.integrate(dt_s);
    }

    /// True when the vehicle is at rest (every velocity zero) and `command` asks for no more
    /// than the rest speeds: [`Vehicle::advance`] would leave it as it is.
    pub fn rests_under(&self, command: Command) -> bool {
        self.velocity == [0.0; 4] && at_rest_speeds(self.target_velocity(command))
    }

    /// [`Vehicle::step`], coming to rest: a vehicle that [`Vehicle::rests_under`] `command`
    /// stays as it is; one whose command and velocities fall below the rest speeds after the
    /// step moves on by what the lag's geometric decay would still add (its closed-form sum)
    /// and stops there.
    pub fn advance(&mut self, dt_s: f64, command: Command) {
        if self.rests_under(command) {
            self.commanded_velocity = [0.0; 4];
            return;
        }
        self.step(dt_s, command);
        if at_rest_speeds(self.commanded_velocity) && at_rest_speeds(self.velocity) {
            let alpha = (dt_s / self.time_constant_s).min(1.0);
            if alpha > 0.0 {
                // Each later step keeps (1 - alpha) of the velocity: sum over k >= 1.
                self.integrate(dt_s * (1.0 - alpha) / alpha);
            }
            self.velocity = [0.0; 4];
            self.commanded_velocity = [0.0; 4];
        }
    }

    /// Moves at the current velocities for `duration_s`, the heading held over it.
    fn integrate(&mut self, duration_s: f64) {
        let psi = self.heading_deg.to_radians();
        let [u, v, w, r] = self.velocity;
        self.position_m[0] += (u * psi.cos() - v * psi.sin()) * duration_s;
        self.position_m[1] += (u * psi.sin() + v * psi.cos()) * duration_s;
        self.position_m[2] += w * duration_s;
        self.heading_deg = (self.heading_deg + r * duration_s).rem_euclid(360.0);
    }
}

/// True when body velocities are within [`REST_MPS`] (and [`REST_DPS`] in yaw) of zero.
fn at_rest_speeds(velocity: [f64; 4]) -> bool {
    velocity[..3].iter().all(|v| v.abs() <= REST_MPS) && velocity[3].abs() <= REST_DPS
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_surge_reaches_the_speed_limit_with_a_lag() {
        let mut v = Vehicle::new([0.0; 3]);
        let full = Command::Thrust {
            surge: 100.0,
            sway: 0.0,
            heave: 0.0,
            yaw: 0.0,
        };
        for _ in 0..10 {
            v.step(0.1, full);
        }
        // After one time constant, about 1 - 1/e of the target.
        assert!(
            (v.velocity[0] / 0.5 - 0.65).abs() < 0.05,
            "{}",
            v.velocity[0]
        );
        for _ in 0..100 {
            v.step(0.1, full);
        }
        assert!((v.velocity[0] - 0.5).abs() < 1e-3);
        assert!(v.position_m[0] > 4.0 && v.position_m[1].abs() < 1e-9);
    }

    #[test]
    fn go_to_arrives_and_stays() {
        let mut v = Vehicle::new([1.0, 0.0, 1.0]);
        let target = Command::GoTo {
            x: 5.0,
            y: 2.0,
            z: 0.0,
            heading_deg: 90.0,
        };
        let mut t = 0.0;
        while !v.reached([5.0, 2.0, 0.0], 90.0) {
            v.step(0.1, target);
            t += 0.1;
            assert!(t < 60.0, "not there after a minute: {v:?}");
        }
        assert!(t > 5.0, "faster than the speed limit allows: {t}");
    }

    #[test]
    fn heading_hold_turns_to_the_held_heading() {
        let mut v = Vehicle::new([0.0; 3]);
        v.heading_hold_deg = Some(270.0);
        let idle = Command::Thrust {
            surge: 0.0,
            sway: 0.0,
            heave: 0.0,
            yaw: 0.0,
        };
        for _ in 0..200 {
            v.step(0.1, idle);
        }
        assert!(
            angle_diff_deg(270.0, v.heading_deg).abs() < 1.0,
            "{}",
            v.heading_deg
        );
        assert_eq!(angle_diff_deg(10.0, 350.0), 20.0);
    }

    /// A session's worth of commands: sticks, idle, a go-to, heading hold, idle again.
    fn script() -> Vec<(usize, Option<f64>, Command)> {
        let thrust = |surge, sway, heave, yaw| Command::Thrust {
            surge,
            sway,
            heave,
            yaw,
        };
        vec![
            (300, None, thrust(0.0, 0.0, 0.0, 0.0)),
            (150, None, thrust(80.0, -30.0, 20.0, 40.0)),
            (600, None, thrust(0.0, 0.0, 0.0, 0.0)),
            (
                900,
                None,
                Command::GoTo {
                    x: -3.0,
                    y: 4.0,
                    z: 2.0,
                    heading_deg: 200.0,
                },
            ),
            (700, Some(45.0), thrust(0.0, 0.0, 0.0, 0.0)),
            (100, Some(45.0), thrust(50.0, 0.0, 0.0, 0.0)),
            (1200, None, thrust(0.0, 0.0, 0.0, 0.0)),
        ]
    }

    #[test]
    fn coming_to_rest_keeps_the_track_of_plain_steps_within_the_tolerance() {
        // Today's model (0.1 s steps, the lag's tail followed forever) against advance.
        let (mut reference, mut resting) = (Vehicle::new([1.0, 2.0, 3.0]), None::<Vehicle>);
        let mut vehicle = Vehicle::new([1.0, 2.0, 3.0]);
        let (mut steps, mut skipped) = (0, 0);
        for (count, hold, command) in script() {
            reference.heading_hold_deg = hold;
            vehicle.heading_hold_deg = hold;
            for _ in 0..count {
                reference.step(0.1, command);
                if vehicle.rests_under(command) {
                    skipped += 1;
                    // At rest, nothing changes.
                    let before = resting.get_or_insert_with(|| vehicle.clone()).clone();
                    vehicle.advance(0.1, command);
                    assert_eq!(vehicle, before);
                } else {
                    resting = None;
                    vehicle.advance(0.1, command);
                }
                steps += 1;
                let gap_m =
                    rovlink_base::geometry::distance_m(vehicle.position_m, reference.position_m);
                let gap_deg = angle_diff_deg(vehicle.heading_deg, reference.heading_deg).abs();
                assert!(
                    gap_m <= REST_TOLERANCE_M && gap_deg <= REST_TOLERANCE_DEG,
                    "step {steps}: {gap_m} m, {gap_deg} degrees apart"
                );
            }
        }
        // Most of the idle time is spent at rest (the lag decays below 1e-6 m/s in ~13 s).
        assert!(skipped > steps / 2, "{skipped} of {steps} steps at rest");
    }
}
