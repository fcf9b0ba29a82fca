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
        crate::geometry::distance_m(self.position_m, point)
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

    /// Advances the vehicle by `dt_s` under `command`.
    pub fn step(&mut self, dt_s: f64, command: Command) {
        let thrust = self.thrust_for(command);
        let limits = [
            self.max_speed_mps,
            self.max_speed_mps,
            self.max_speed_mps,
            self.max_yaw_rate_dps,
        ];
        let alpha = (dt_s / self.time_constant_s).min(1.0);
        for k in 0..4 {
            let target = thrust[k] / 100.0 * limits[k];
            self.commanded_velocity[k] = target;
            self.velocity[k] += (target - self.velocity[k]) * alpha;
        }
        let psi = self.heading_deg.to_radians();
        let [u, v, w, r] = self.velocity;
        self.position_m[0] += (u * psi.cos() - v * psi.sin()) * dt_s;
        self.position_m[1] += (u * psi.sin() + v * psi.cos()) * dt_s;
        self.position_m[2] += w * dt_s;
        self.heading_deg = (self.heading_deg + r * dt_s).rem_euclid(360.0);
    }
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
}
