//! `tdma-run --role rov --vehicle ros2`: the ROV end drives a vehicle whose own stack speaks
//! ROS 2, beside the built-in model and MAVLink. REP 103 frames on the ROS side (the odometry's
//! frame east-north-up, the body forward-left-up); the session's own are north-east-down and
//! forward-right-down, converted at this boundary.
//!
//! Out (under the namespace, `/rov` by default):
//! - `NS/cmd_vel` (`geometry_msgs/msg/Twist`): the sticks as fractions of full thrust (1 =
//!   full, as Foxglove's Teleop panel gives them), at each step while the joystick commands;
//! - `NS/goal_pose` (`geometry_msgs/msg/PoseStamped`, in the odometry's frame): a GoTo's
//!   target, once per target (a zero Twist stops the sticks);
//! - `NS/arm` (`std_msgs/msg/Bool`): armed or not, at each change.
//!
//! In: `NS/odom` (`nav_msgs/msg/Odometry`): the position, heading and body velocities the
//! status reports. Until the first odometry the position is unknown (a GoTo is refused, WHY
//! `no_position`); with none for [`SILENT_AFTER`], the vehicle is silent (WHY
//! `vehicle_silent`, said once, and again when it is heard). A message that does not decode
//! (or a NaN, a quaternion not of unit length) is refused with one line per kind.
//!
//! Plain DDS authenticates nobody: anything on the domain could publish odometry. Use a domain
//! only the vehicle's computer joins (the ROV end runs on the vehicle).

use std::time::{Duration, Instant};

use rovlink_link::SimTime;
use rovlink_rcp::autopilot::{Demand, Drive, DriveEvent, DriveState};
use rovlink_rcp::vehicle::Command;
use rovlink_ros2::msgs::{self, Rigid};
use rovlink_ros2::{Node, Qos, Reader, Ros2Error, Writer};
use rovlink_wire::rov::Why;

/// Without odometry this long, the vehicle is silent.
pub const SILENT_AFTER: Duration = Duration::from_secs(2);

/// The drive; see the [module documentation](self).
pub struct Ros2Drive {
    _node: Node,
    cmd_vel: Writer,
    goal: Writer,
    arm: Writer,
    odom: Reader,
    state: DriveState,
    odom_frame: String,
    heard: Option<Instant>,
    silent: bool,
    last_goal: Option<[f64; 4]>,
    last_arm: Option<bool>,
    events: Vec<DriveEvent>,
    refused: crate::ros2_session::SaidOnce,
}

/// Joins `domain` and advertises and subscribes under `namespace`.
pub fn ros2_drive(namespace: &str, domain: Option<u16>) -> Result<Ros2Drive, Ros2Error> {
    let domain = rovlink_ros2::names::domain_id(domain)?;
    let mut node = Node::join(domain)?;
    let ns = namespace.trim_end_matches('/');
    let topic = |name: &str| format!("{ns}/{name}");
    let cmd_vel = node.advertise(&topic("cmd_vel"), msgs::TWIST, Qos::DEFAULT)?;
    let goal = node.advertise(&topic("goal_pose"), msgs::POSE_STAMPED, Qos::LATCHED)?;
    let arm = node.advertise(&topic("arm"), msgs::BOOL, Qos::LATCHED)?;
    let odom = node.subscribe(&topic("odom"), msgs::ODOMETRY, Qos::DEFAULT, 4096)?;
    Ok(Ros2Drive {
        _node: node,
        cmd_vel,
        goal,
        arm,
        odom,
        state: DriveState::unheard(Why::VehicleSilent),
        odom_frame: "odom".into(),
        heard: None,
        silent: false,
        last_goal: None,
        last_arm: None,
        events: Vec::new(),
        refused: crate::ros2_session::SaidOnce::new(16),
    })
}

/// ENU yaw (radians, from east, counter-clockwise) as a NED heading (degrees from north,
/// clockwise, 0..360), and back.
fn heading_of_yaw(yaw_rad: f64) -> f64 {
    (90.0 - yaw_rad.to_degrees()).rem_euclid(360.0)
}

fn yaw_of_heading(heading_deg: f64) -> f64 {
    (90.0 - heading_deg).to_radians()
}

impl Ros2Drive {
    fn note_refused(&mut self, line: String) {
        if self.refused.first(&line) {
            self.events.push(DriveEvent::Note(line));
        }
    }

    fn write(&mut self, which: fn(&Ros2Drive) -> &Writer, message: &[u8]) {
        if let Err(e) = which(self).write(message) {
            self.note_refused(format!("ROS 2: {e}"));
        }
    }

    fn take_odometry(&mut self) {
        loop {
            let m = match self.odom.take() {
                Ok(Some(m)) => m,
                Ok(None) => break,
                Err(e) => {
                    self.note_refused(format!("odometry: {e}"));
                    break;
                }
            };
            match msgs::decode_odometry(&m.message) {
                Ok(o) => {
                    let [e, n, u] = o.pose.translation_m;
                    let yaw = o.pose.yaw_rad();
                    self.state.position_m = [n, e, -u];
                    self.state.heading_deg = heading_of_yaw(yaw);
                    self.state.velocity = [
                        o.linear[0],
                        -o.linear[1],
                        -o.linear[2],
                        -o.angular[2].to_degrees(),
                    ];
                    self.state.position_known = true;
                    self.odom_frame = o.frame_id;
                    self.heard = Some(Instant::now());
                }
                Err(e) => self.note_refused(format!("odometry refused: {e}")),
            }
        }
        if self.odom.too_big() > 0 {
            self.note_refused("odometry over 4096 bytes refused".into());
        }
    }
}

impl Drive for Ros2Drive {
    fn step(&mut self, _now: SimTime, _dt_s: f64, demand: &Demand) {
        self.take_odometry();
        let fresh = self.heard.is_some_and(|t| t.elapsed() < SILENT_AFTER);
        match (fresh, self.silent, self.heard.is_some()) {
            (false, false, true) => {
                self.silent = true;
                self.events.push(DriveEvent::Silent {
                    silent_s: self.heard.map_or(0.0, |t| t.elapsed().as_secs_f64()),
                });
            }
            (true, true, _) => {
                self.silent = false;
                self.events.push(DriveEvent::Heard);
            }
            _ => {}
        }
        self.state.responsive = fresh;
        if self.last_arm != Some(demand.arm) {
            self.last_arm = Some(demand.arm);
            self.write(|d| &d.arm, &msgs::boolean(demand.arm));
        }
        self.state.armed = demand.arm;
        self.state.nav = demand.nav;
        self.state.why = match (fresh, &demand.command) {
            (false, _) => Why::VehicleSilent,
            (true, Command::GoTo { .. }) if !self.state.position_known => Why::NoPosition,
            _ => Why::Nothing,
        };
        match demand.command {
            Command::Thrust {
                surge,
                sway,
                heave,
                yaw,
            } => {
                self.last_goal = None;
                let f = |v: f64| (v / 100.0).clamp(-1.0, 1.0);
                self.state.commanded_velocity = [surge, sway, heave, yaw];
                let twist = msgs::twist([f(surge), -f(sway), -f(heave)], [0.0, 0.0, -f(yaw)]);
                self.write(|d| &d.cmd_vel, &twist);
            }
            Command::GoTo {
                x,
                y,
                z,
                heading_deg,
            } => {
                let target = [x, y, z, heading_deg];
                if self.last_goal != Some(target) && self.state.position_known {
                    self.last_goal = Some(target);
                    self.write(|d| &d.cmd_vel, &msgs::twist([0.0; 3], [0.0; 3]));
                    let pose = Rigid {
                        translation_m: [y, x, -z],
                        rotation_xyzw: msgs::yaw_quaternion(yaw_of_heading(heading_deg)),
                    };
                    let stamp = crate::mcap_log::wall_clock_ns() as i64;
                    let frame = self.odom_frame.clone();
                    self.write(|d| &d.goal, &msgs::pose_stamped(stamp, &frame, &pose));
                }
                self.state.commanded_velocity = [0.0; 4];
            }
        }
    }

    fn state(&self) -> DriveState {
        self.state
    }

    fn take_events(&mut self) -> Vec<DriveEvent> {
        std::mem::take(&mut self.events)
    }

    fn needs_hold(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headings_and_yaws_are_each_others_inverse() {
        for h in [0.0, 45.0, 90.0, 180.0, 270.0, 359.0] {
            let back = heading_of_yaw(yaw_of_heading(h));
            assert!((back - h).abs() < 1e-9, "{h} -> {back}");
        }
        // East is yaw 0, heading 90.
        assert!((heading_of_yaw(0.0) - 90.0).abs() < 1e-12);
    }
}
