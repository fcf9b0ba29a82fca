//! A teleoperation session on a ROS 2 graph (`tdma-run --ros2`): what the operator sees,
//! published for the other nodes on the operator's side (RViz, Foxglove's ROS 2 bridge, a
//! logger), and, only when control is enabled, orders taken from the graph.
//!
//! Published (under the namespace, `/rov` by default; stamps are the wall clock):
//!
//! | topic | type | when |
//! |---|---|---|
//! | `NS/pose` | `geometry_msgs/msg/PoseStamped` (frame `ned`) | each pose, at most 10 per second |
//! | `/tf` | `tf2_msgs/msg/TFMessage`: `ned` -> `rov` | with each pose |
//! | `/tf_static` | `world` -> `ned` (x north, y east, z down under ENU's `world`) | once, latched |
//! | `NS/goal` | `geometry_msgs/msg/PoseStamped` | with each pose while a GoTo runs |
//! | `NS/velocity` | `geometry_msgs/msg/TwistStamped` (frame `rov`: surge, sway, heave; yaw rate) | with each pose |
//! | `NS/cmd_vel_commanded` | `geometry_msgs/msg/TwistStamped` | with each pose |
//! | `NS/image/compressed` | `sensor_msgs/msg/CompressedImage` (PNG) | each completed image, latched |
//! | `NS/status` | `std_msgs/msg/String`, one JSON object: pose, link up, frames sent, received, lost | once a second |
//! | `/rosout` | `rcl_interfaces/msg/Log` (name `tdma_run`) | each line of the session's log |
//!
//! Taken with control ([`Ros2Options::control`]; off by default, and plain DDS authenticates
//! nobody: any node on the domain can then drive): `NS/cmd_vel` (`geometry_msgs/msg/Twist`,
//! the joystick as Foxglove's Teleop panel gives it, [`twist_joystick`], held for
//! [`TWIST_HOLD`]) and `NS/goal_pose` (`geometry_msgs/msg/PoseStamped` in `ned`: a GoTo to its
//! position, heading from its yaw). Without control the node subscribes to neither: a
//! publisher there is not heard at all.
//!
//! The contract: nothing on the graph stops the session, panics, or grows memory without
//! bound: the readers keep the last 10 messages at most (a flood is cut there), a message over
//! 4 KiB or that does not decode is refused with a warning (one per kind of problem), and the
//! session's timing does not wait on the graph (writes never block).

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use crate::foxglove::{TWIST_HOLD, twist_joystick};
use crate::mcap_log::{Clock, Topic, View, wall_clock_ns};
use rovlink_link::SimTime;
use rovlink_rcp::operator::Joystick;
use rovlink_rcp::orders::{Live, OrderSource};
use rovlink_rcp::report::{FrameEvent, Observer};
use rovlink_rcp::{Event, PoseSample, Role};
use rovlink_ros2::msgs::{self, Rigid};
use rovlink_ros2::{Node, Qos, Reader, Ros2Error, Writer};

/// The least time between two poses published.
pub const POSE_EVERY: Duration = Duration::from_millis(100);
/// The time between two status messages.
pub const STATUS_EVERY: Duration = Duration::from_secs(1);
/// The largest order message read, bytes.
pub const MAX_ORDER_BYTES: usize = 4096;

/// How the session joins the graph.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Ros2Options {
    /// The domain id; `None`: `ROS_DOMAIN_ID`, else 0.
    pub domain: Option<u16>,
    /// The topics' namespace (`/rov`).
    pub namespace: String,
    /// Take `cmd_vel` and `goal_pose` from the graph.
    pub control: bool,
}

impl Default for Ros2Options {
    fn default() -> Self {
        Ros2Options {
            domain: None,
            namespace: "/rov".into(),
            control: false,
        }
    }
}

struct Writers {
    pose: Writer,
    tf: Writer,
    goal: Writer,
    velocity: Writer,
    commanded: Writer,
    image: Writer,
    status: Writer,
    log: Writer,
}

/// The session's publisher, an [`Observer`].
pub struct Ros2View {
    _node: Node,
    /// `/tf_static`'s writer, written once: it keeps world -> ned latched for late readers.
    _tf_static: Writer,
    w: Writers,
    view: View,
    last_pose: Option<Instant>,
    last_status: Option<Instant>,
    frames: [u64; 3],
    latest: Option<PoseSample>,
    problems: Vec<String>,
}

/// The orders taken from the graph, an [`OrderSource`] (empty without control).
pub struct Ros2Orders {
    cmd_vel: Option<Reader>,
    goal: Option<Reader>,
    twist_at: Option<Instant>,
    warnings: Vec<String>,
    said: SaidOnce,
}

/// Lines said once each, at most `max` distinct ones (the rest not said again).
pub(crate) struct SaidOnce {
    said: BTreeSet<String>,
    max: usize,
}

impl SaidOnce {
    /// Nothing said yet; at most `max` distinct lines.
    pub(crate) fn new(max: usize) -> SaidOnce {
        SaidOnce {
            said: BTreeSet::new(),
            max,
        }
    }

    /// True the first time `line` comes, while fewer than `max` have.
    pub(crate) fn first(&mut self, line: &str) -> bool {
        self.said.len() < self.max && self.said.insert(line.to_string())
    }
}

/// Joins the graph: the publisher and the order source. Errors name what DDS refused.
pub fn start(options: &Ros2Options) -> Result<(Ros2View, Ros2Orders), Ros2Error> {
    let domain = rovlink_ros2::names::domain_id(options.domain)?;
    let mut node = Node::join(domain)?;
    let ns = options.namespace.trim_end_matches('/');
    let topic = |name: &str| format!("{ns}/{name}");
    let w = Writers {
        pose: node.advertise(&topic("pose"), msgs::POSE_STAMPED, Qos::DEFAULT)?,
        tf: node.advertise("/tf", msgs::TF_MESSAGE, Qos::TF)?,
        goal: node.advertise(&topic("goal"), msgs::POSE_STAMPED, Qos::LATCHED)?,
        velocity: node.advertise(&topic("velocity"), msgs::TWIST_STAMPED, Qos::DEFAULT)?,
        commanded: node.advertise(
            &topic("cmd_vel_commanded"),
            msgs::TWIST_STAMPED,
            Qos::DEFAULT,
        )?,
        image: node.advertise(
            &topic("image/compressed"),
            msgs::COMPRESSED_IMAGE,
            Qos::LATCHED,
        )?,
        status: node.advertise(&topic("status"), msgs::STRING, Qos::LATCHED)?,
        log: node.advertise("/rosout", msgs::LOG, Qos::DEFAULT)?,
    };
    let statics = node.advertise("/tf_static", msgs::TF_MESSAGE, Qos::TF_STATIC)?;
    // ENU's world to NED: a half turn about the axis (x + y) / sqrt 2.
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let ned = Rigid {
        translation_m: [0.0; 3],
        rotation_xyzw: [h, h, 0.0, 0.0],
    };
    statics.write(&msgs::tf_message(
        wall_clock_ns() as i64,
        &[("world", crate::mcap_log::NED_FRAME, ned)],
    ))?;
    let (cmd_vel, goal) = match options.control {
        true => (
            Some(node.subscribe(
                &topic("cmd_vel"),
                msgs::TWIST,
                Qos::DEFAULT,
                MAX_ORDER_BYTES,
            )?),
            Some(node.subscribe(
                &topic("goal_pose"),
                msgs::POSE_STAMPED,
                Qos::DEFAULT,
                MAX_ORDER_BYTES,
            )?),
        ),
        false => (None, None),
    };
    let mut view = View::new(Clock::Wall);
    view.want(|t| matches!(t, Topic::Events | Topic::Log));
    Ok((
        Ros2View {
            _node: node,
            _tf_static: statics,
            w,
            view,
            last_pose: None,
            last_status: None,
            frames: [0; 3],
            latest: None,
            problems: Vec::new(),
        },
        Ros2Orders {
            cmd_vel,
            goal,
            twist_at: None,
            warnings: Vec::new(),
            said: SaidOnce::new(32),
        },
    ))
}

/// Metres as whole centimetres (out of wire.md's range stays out of range: refused there).
fn cm(m: f64) -> i64 {
    (m * 100.0).round().clamp(-1e9, 1e9) as i64
}

impl Ros2View {
    fn write(&mut self, which: fn(&Writers) -> &Writer, message: &[u8]) {
        if let Err(e) = which(&self.w).write(message) {
            let line = format!("ROS 2: {e}");
            if !self.problems.contains(&line) && self.problems.len() < 16 {
                self.problems.push(line);
            }
        }
    }

    /// What went wrong publishing (each problem once, at most 16): the caller says them at
    /// the end of the run.
    pub fn problems(&self) -> &[String] {
        &self.problems
    }

    fn status(&mut self, now: Instant) {
        if self
            .last_status
            .is_some_and(|t| now.duration_since(t) < STATUS_EVERY)
        {
            return;
        }
        self.last_status = Some(now);
        let pose = self.latest.as_ref().map(|p| {
            serde_json::json!({
                "t_s": p.t_s, "position_m": p.position_m, "heading_deg": p.heading_deg,
                "link_up": p.link_up, "goal_m": p.goal_m,
            })
        });
        let json = serde_json::json!({
            "pose": pose,
            "frames": {"sent": self.frames[0], "received": self.frames[1], "lost": self.frames[2]},
        });
        self.write(|w| &w.status, &msgs::string(&json.to_string()));
    }

    fn log_lines(&mut self, lines: Vec<crate::mcap_log::ViewMessage>) {
        for m in lines {
            let Ok(v) = serde_json::from_str::<serde_json::Value>(&m.json) else {
                continue;
            };
            // Foxglove's levels 1..=5 are ROS 2's 10..=50.
            let level = v["level"].as_u64().unwrap_or(2).clamp(1, 5) as u8 * 10;
            let text = v["message"].as_str().unwrap_or_default();
            let line = msgs::log(m.log_time_ns as i64, level, "tdma_run", text);
            self.write(|w| &w.log, &line);
        }
    }
}

impl Observer for Ros2View {
    fn frame(&mut self, e: &FrameEvent<'_>) {
        match e.fate {
            "sent" => self.frames[0] += 1,
            "received" | "delivered" => self.frames[1] += 1,
            _ => self.frames[2] += 1,
        }
        let lines = self.view.frame(e);
        self.log_lines(
            lines
                .into_iter()
                .filter(|m| m.topic == Topic::Log)
                .collect(),
        );
    }

    fn image(&mut self, _vehicle: u8, _t_s: f64, stream: &[u8]) {
        let png = rovlink_debt::decode(stream)
            .ok()
            .and_then(|img| rovlink_debt::picture::to_png(&img).ok());
        match png {
            Some(png) => {
                let m = msgs::compressed_image(wall_clock_ns() as i64, "camera", "png", &png);
                self.write(|w| &w.image, &m);
            }
            None => {
                let lines = self.view.warning(0.0, "a completed image did not decode");
                self.log_lines(lines);
            }
        }
    }

    fn pose(&mut self, _vehicle: u8, pose: &PoseSample) {
        let now = Instant::now();
        self.latest = Some(*pose);
        let lines = self.view.pose(pose);
        self.log_lines(lines);
        if self
            .last_pose
            .is_none_or(|t| now.duration_since(t) >= POSE_EVERY)
        {
            self.last_pose = Some(now);
            let ns = wall_clock_ns() as i64;
            let ned = crate::mcap_log::NED_FRAME;
            let body = crate::mcap_log::BODY_FRAME;
            let at = Rigid {
                translation_m: pose.position_m,
                rotation_xyzw: crate::mcap_log::heading(pose.heading_deg),
            };
            self.write(|w| &w.pose, &msgs::pose_stamped(ns, ned, &at));
            self.write(|w| &w.tf, &msgs::tf_message(ns, &[(ned, body, at)]));
            if let Some(goal) = pose.goal_m {
                let g = Rigid {
                    translation_m: goal,
                    ..at
                };
                self.write(|w| &w.goal, &msgs::pose_stamped(ns, ned, &g));
            }
            let twist = |v: [f64; 4]| {
                // Body forward-right-down to ROS's forward-left-up.
                msgs::twist_stamped(
                    ns,
                    body,
                    [v[0], -v[1], -v[2]],
                    [0.0, 0.0, -v[3].to_radians()],
                )
            };
            self.write(|w| &w.velocity, &twist(pose.velocity));
            self.write(|w| &w.commanded, &twist(pose.commanded_velocity));
        }
        self.status(now);
    }

    fn event(&mut self, _vehicle: u8, end: Role, t_s: f64, event: &Event) {
        let lines = self.view.event(end, t_s, event);
        self.log_lines(lines);
    }

    fn warning(&mut self, t_s: f64, text: &str) {
        let lines = self.view.warning(t_s, text);
        self.log_lines(lines);
    }
}

impl Ros2Orders {
    fn warn(&mut self, line: String) {
        if self.said.first(&line) {
            self.warnings.push(line);
        }
    }

    /// Whether orders are taken from the graph.
    pub fn control(&self) -> bool {
        self.cmd_vel.is_some()
    }
}

impl OrderSource for Ros2Orders {
    fn poll(&mut self, _now: SimTime) -> Vec<Live> {
        let mut out = Vec::new();
        let now = Instant::now();
        let mut twists = Vec::new();
        let mut problems = Vec::new();
        if let Some(r) = self.cmd_vel.as_mut() {
            loop {
                match r.take() {
                    Ok(Some(m)) => twists.push(m.message),
                    Ok(None) => break,
                    Err(e) => {
                        problems.push(format!("ROS 2 cmd_vel: {e}"));
                        break;
                    }
                }
            }
            if r.too_big() > 0 {
                problems.push(format!(
                    "ROS 2 cmd_vel: messages over {MAX_ORDER_BYTES} bytes refused"
                ));
            }
        }
        // Only the newest Twist matters: a flood is one joystick per poll.
        if let Some(m) = twists.last() {
            match msgs::decode_twist(m) {
                Ok((linear, angular)) => {
                    let json = serde_json::json!({
                        "linear": {"x": linear[0], "y": linear[1], "z": linear[2]},
                        "angular": {"x": angular[0], "y": angular[1], "z": angular[2]},
                    });
                    if let Some(map) = json.as_object()
                        && let Ok(live) = twist_joystick(map)
                    {
                        out.push(live);
                        self.twist_at = Some(now);
                    }
                }
                Err(e) => problems.push(format!("ROS 2 cmd_vel refused: {e}")),
            }
        } else if self
            .twist_at
            .is_some_and(|at| now.saturating_duration_since(at) > TWIST_HOLD)
        {
            self.twist_at = None;
            out.push(Live::scripted_joystick(Joystick::default()));
        }
        if let Some(r) = self.goal.as_mut() {
            while let Ok(Some(m)) = r.take() {
                match msgs::decode_pose_stamped(&m.message) {
                    Ok((_, frame, pose))
                        if frame == crate::mcap_log::NED_FRAME || frame.is_empty() =>
                    {
                        let [x, y, z] = pose.translation_m;
                        let yaw = pose.yaw_rad();
                        let order = serde_json::json!({
                            "type": "goto",
                            "x_cm": cm(x), "y_cm": cm(y), "z_cm": cm(z),
                            "heading_deg": yaw.to_degrees().rem_euclid(360.0).round() as i64 % 360,
                        });
                        match order.as_object().map(Live::from_object) {
                            Some(Ok(live)) => out.push(live),
                            Some(Err(e)) => problems.push(format!("ROS 2 goal_pose refused: {e}")),
                            None => {}
                        }
                    }
                    Ok((_, frame, _)) => problems.push(format!(
                        "ROS 2 goal_pose refused: expected frame \"ned\", found {frame:?}"
                    )),
                    Err(e) => problems.push(format!("ROS 2 goal_pose refused: {e}")),
                }
            }
        }
        for p in problems {
            self.warn(p);
        }
        out
    }

    fn take_warnings(&mut self) -> Vec<String> {
        std::mem::take(&mut self.warnings)
    }
}
