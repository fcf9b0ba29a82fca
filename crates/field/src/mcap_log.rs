//! The session's view in Foxglove: one definition of its channels (topics, JSON Schemas) and of
//! its messages, which [`McapLog`] writes into an MCAP file and [`crate::foxglove`] serves
//! live: the vehicle's pose, its commanded and actual velocities, the link's events, and every
//! completed image.
//!
//! Messages are JSON with JSON-Schema schemas. Channels and schemas:
//!
//! | topic | schema | what |
//! |---|---|---|
//! | `/rov/pose` | `foxglove.PoseInFrame` | position (NED m, frame `ned`) and heading as a quaternion |
//! | `/rov/goal` | `foxglove.PoseInFrame` | the GoTo target being executed |
//! | `/rov/velocity/actual` | `rovlink.BodyVelocity` | surge, sway, heave (m/s), yaw rate (degrees/s) |
//! | `/rov/velocity/commanded` | `rovlink.BodyVelocity` | what the command in force asks for |
//! | `/link/frames` | `rovlink.LinkFrame` | one message per frame: direction, kind, bytes, fate, delay |
//! | `/link/log` | `foxglove.Log` | link lost and recovered, lost frames |
//! | `/camera/image` | `foxglove.CompressedImage` | every completed image, decoded and stored as PNG |
//! | `/camera/preview` | `foxglove.CompressedImage` | live only: the image in progress, decoded from the trunks so far |
//! | `/session/log` | `foxglove.Log` | live only: orders sent, acknowledged, executed; the vehicle's and the camera's reports |
//!
//! [`View`] turns what an [`Observer`] is told into [`ViewMessage`]s: a topic, a log time and
//! the JSON text. Log times are nanoseconds, by the view's [`Clock`]: for the MCAP file the
//! session's time plus a base (0 in simulation, so the same seed gives the same file; the wall
//! clock at the start in real time), for the live view the wall clock. Building a message
//! never fails and never panics: an image that does not decode becomes a warning on
//! `/link/log`.

use std::collections::BTreeMap;

use base64::Engine;
use serde_json::json;

use mcap::write::NoSeek;

use rovlink_base::io::{IoError, Output};
use rovlink_base::output::Dest;
use rovlink_rcp::report::FrameEvent;
use rovlink_rcp::{Event, PoseSample, Role};

/// What went wrong writing the log.
#[derive(Debug, thiserror::Error)]
pub enum McapLogError {
    /// The MCAP writer failed (usually the disk).
    #[error("{path}: MCAP: {source}")]
    Mcap {
        /// The file.
        path: String,
        /// The writer's error.
        source: mcap::McapError,
    },
    /// The file could not be written or committed.
    #[error(transparent)]
    Io(#[from] IoError),
}

const POSE_IN_FRAME: &str = r#"{"title":"foxglove.PoseInFrame","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"frame_id":{"type":"string"},"pose":{"type":"object","properties":{"position":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}}}"#;

const COMPRESSED_IMAGE: &str = r#"{"title":"foxglove.CompressedImage","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"frame_id":{"type":"string"},"data":{"type":"string","contentEncoding":"base64"},"format":{"type":"string"}}}"#;

const LOG: &str = r#"{"title":"foxglove.Log","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"level":{"type":"integer","minimum":0,"maximum":5,"description":"0 UNKNOWN, 1 DEBUG, 2 INFO, 3 WARNING, 4 ERROR, 5 FATAL"},"message":{"type":"string"},"name":{"type":"string"},"file":{"type":"string"},"line":{"type":"integer","minimum":0}}}"#;

const BODY_VELOCITY: &str = r#"{"title":"rovlink.BodyVelocity","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"surge_mps":{"type":"number"},"sway_mps":{"type":"number"},"heave_mps":{"type":"number"},"yaw_rate_dps":{"type":"number"}}}"#;

const LINK_FRAME: &str = r#"{"title":"rovlink.LinkFrame","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"direction":{"type":"string"},"kind":{"type":"string"},"bytes":{"type":"integer"},"fate":{"type":"string"},"t_sent_s":{"type":"number","description":"omitted when not sent"},"t_received_s":{"type":"number","description":"omitted when not received"},"delay_ms":{"type":"number","description":"omitted when not delivered"}}}"#;

/// `value` with every `null` member of its objects left out: an optional field (a frame's
/// `t_received_s` when it was lost) is omitted, since Foxglove's JSON Schema reader refuses
/// the type arrays (`["number", "null"]`) that would describe a null.
pub fn without_nulls(value: &serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    match value {
        Value::Object(map) => Value::Object(
            map.iter()
                .filter(|(_, v)| !v.is_null())
                .map(|(k, v)| (k.clone(), without_nulls(v)))
                .collect(),
        ),
        Value::Array(items) => Value::Array(items.iter().map(without_nulls).collect()),
        other => other.clone(),
    }
}

/// What Foxglove's JSON Schema reader would refuse in `schema` (the path and why): type
/// arrays, `oneOf` / `anyOf` / `allOf`, a property without a type, an object without
/// properties, an array without items. Empty for a schema every viewer reads.
pub fn schema_problems(schema: &serde_json::Value, path: &str) -> Vec<String> {
    use serde_json::Value;
    let Value::Object(map) = schema else {
        return vec![format!("{path}: not an object")];
    };
    let mut out: Vec<String> = ["oneOf", "anyOf", "allOf"]
        .iter()
        .filter(|w| map.contains_key(**w))
        .map(|w| format!("{path}: uses {w}"))
        .collect();
    match map.get("type") {
        None => out.push(format!("{path}: has no type")),
        Some(Value::String(kind)) if kind == "object" => match map.get("properties") {
            Some(Value::Object(props)) => {
                for (name, sub) in props {
                    out.extend(schema_problems(sub, &format!("{path}.{name}")));
                }
            }
            _ => out.push(format!("{path}: an object without properties")),
        },
        Some(Value::String(kind)) if kind == "array" => match map.get("items") {
            Some(items) => out.extend(schema_problems(items, &format!("{path}[]"))),
            None => out.push(format!("{path}: an array without items")),
        },
        Some(Value::String(_)) => {}
        Some(other) => out.push(format!("{path}: type {other}, not one name")),
    }
    out
}

const FRAME_TRANSFORMS: &str = r#"{"title":"foxglove.FrameTransforms","type":"object","properties":{"transforms":{"type":"array","items":{"title":"foxglove.FrameTransform","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"parent_frame_id":{"type":"string"},"child_frame_id":{"type":"string"},"translation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},"rotation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}}}}"#;

/// The z-up world frame of the transform tree ([`Topic::Tf`]): x north, y west, z up.
pub const WORLD_FRAME: &str = "world";
/// The frame positions are given in: x north, y east, z down (depth), under [`WORLD_FRAME`].
pub const NED_FRAME: &str = "ned";
/// The vehicle's body frame, under [`NED_FRAME`], in a single session (`vehicle_N` in a
/// network).
pub const BODY_FRAME: &str = "rov";

/// JPEG quality of `/camera/preview`.
pub const PREVIEW_JPEG_QUALITY: u8 = 70;

/// Foxglove's log level DEBUG.
pub const DEBUG: u8 = 1;
/// Foxglove's log level INFO.
pub const INFO: u8 = 2;
/// Foxglove's log level WARNING.
pub const WARNING: u8 = 3;
/// Foxglove's log level ERROR.
pub const ERROR: u8 = 4;

/// A channel of the session's view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topic {
    /// `/rov/pose`.
    Pose,
    /// `/rov/goal`.
    Goal,
    /// `/rov/velocity/actual`.
    Actual,
    /// `/rov/velocity/commanded`.
    Commanded,
    /// `/link/frames`.
    Frames,
    /// `/link/log`.
    Log,
    /// `/camera/image`.
    Image,
    /// `/camera/preview` (live only).
    Preview,
    /// `/session/log` (live only).
    Events,
    /// `/tf`: the transform tree, world -> ned -> the vehicle's body.
    Tf,
}

impl Topic {
    /// Every channel, in the order a view adds them: the MCAP log's first.
    pub const ALL: [Topic; 10] = [
        Topic::Pose,
        Topic::Goal,
        Topic::Actual,
        Topic::Commanded,
        Topic::Frames,
        Topic::Log,
        Topic::Image,
        Topic::Preview,
        Topic::Events,
        Topic::Tf,
    ];

    /// The topic, e.g. `/rov/pose`.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Pose => "/rov/pose",
            Topic::Goal => "/rov/goal",
            Topic::Actual => "/rov/velocity/actual",
            Topic::Commanded => "/rov/velocity/commanded",
            Topic::Frames => "/link/frames",
            Topic::Log => "/link/log",
            Topic::Image => "/camera/image",
            Topic::Preview => "/camera/preview",
            Topic::Events => "/session/log",
            Topic::Tf => "/tf",
        }
    }

    /// The schema's name, e.g. `foxglove.PoseInFrame`.
    pub fn schema_name(self) -> &'static str {
        match self {
            Topic::Pose | Topic::Goal => "foxglove.PoseInFrame",
            Topic::Actual | Topic::Commanded => "rovlink.BodyVelocity",
            Topic::Frames => "rovlink.LinkFrame",
            Topic::Log | Topic::Events => "foxglove.Log",
            Topic::Image | Topic::Preview => "foxglove.CompressedImage",
            Topic::Tf => "foxglove.FrameTransforms",
        }
    }

    /// The JSON Schema of its messages.
    pub fn schema(self) -> &'static str {
        match self {
            Topic::Pose | Topic::Goal => POSE_IN_FRAME,
            Topic::Actual | Topic::Commanded => BODY_VELOCITY,
            Topic::Frames => LINK_FRAME,
            Topic::Log | Topic::Events => LOG,
            Topic::Image | Topic::Preview => COMPRESSED_IMAGE,
            Topic::Tf => FRAME_TRANSFORMS,
        }
    }

    /// True for the channels of the MCAP log; false for the live view's own (the image in
    /// progress, the session's events).
    pub fn in_log(self) -> bool {
        !matches!(self, Topic::Preview | Topic::Events)
    }

    /// Its place in [`Topic::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

/// How a view stamps its messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clock {
    /// `base_ns` plus the session's time (the MCAP log).
    Session {
        /// Nanoseconds at the session's time 0.
        base_ns: u64,
    },
    /// The wall clock when the message is built, ns since the Unix epoch (a live view).
    Wall,
}

/// Nanoseconds since the Unix epoch now (0 for a clock set before 1970).
pub fn wall_clock_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// One message of the view.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewMessage {
    /// Its channel.
    pub topic: Topic,
    /// Its log time, ns.
    pub log_time_ns: u64,
    /// The message, JSON text following the channel's schema.
    pub json: String,
}

/// Builds the view's messages from what an [`Observer`] is told: every channel's, or only
/// those of the channels [`View::want`]s (a live view builds nothing nobody subscribes to).
#[derive(Debug, Clone)]
pub struct View {
    clock: Clock,
    link_up: Option<bool>,
    /// WHY and NP of the last status told (a change is a line on the log).
    status_reason: std::cell::Cell<Option<(rovlink_wire::rov::Why, bool)>>,
    wanted: [bool; Topic::ALL.len()],
    /// The body frame's name on `/tf`.
    body_frame: String,
}

impl View {
    /// A view stamping its messages by `clock`, for every channel.
    pub fn new(clock: Clock) -> View {
        View {
            clock,
            link_up: None,
            status_reason: std::cell::Cell::new(None),
            wanted: [true; Topic::ALL.len()],
            body_frame: BODY_FRAME.to_string(),
        }
    }

    /// The vehicle's body frame on `/tf` is `name` (a network's `vehicle_2`).
    pub fn with_body_frame(mut self, name: &str) -> View {
        self.body_frame = name.to_string();
        self
    }

    /// From now on, builds the messages of the channels `wanted` says yes to only.
    pub fn want(&mut self, wanted: impl Fn(Topic) -> bool) {
        for topic in Topic::ALL {
            self.wanted[topic.index()] = wanted(topic);
        }
    }

    fn wants(&self, topic: Topic) -> bool {
        self.wanted[topic.index()]
    }

    fn stamp(&self, t_s: f64) -> (u64, serde_json::Value) {
        let ns = match self.clock {
            Clock::Session { base_ns } => {
                base_ns.saturating_add((t_s.max(0.0) * 1e9).round() as u64)
            }
            Clock::Wall => wall_clock_ns(),
        };
        (ns, timestamp_json(ns))
    }

    fn message(topic: Topic, log_time_ns: u64, json: &serde_json::Value) -> ViewMessage {
        ViewMessage {
            topic,
            log_time_ns,
            json: without_nulls(json).to_string(),
        }
    }

    fn log(
        &self,
        topic: Topic,
        t_s: f64,
        level: u8,
        name: &str,
        message: &str,
    ) -> Option<ViewMessage> {
        if !self.wants(topic) {
            return None;
        }
        let (ns, timestamp) = self.stamp(t_s);
        Some(View::message(
            topic,
            ns,
            &log_json(&timestamp, level, name, message),
        ))
    }

    /// A frame's fate: its `/link/frames` message, and a warning on `/link/log` when it was
    /// not delivered.
    pub fn frame(&self, e: &FrameEvent) -> Vec<ViewMessage> {
        let t_s = e.t_received_s.or(e.t_sent_s).unwrap_or(0.0);
        let mut out = Vec::new();
        if self.wants(Topic::Frames) {
            let (ns, timestamp) = self.stamp(t_s);
            let delay_ms = e.t_sent_s.zip(e.t_received_s).map(|(s, r)| (r - s) * 1e3);
            out.push(View::message(
                Topic::Frames,
                ns,
                &json!({"timestamp": timestamp, "direction": e.direction, "kind": e.kind,
                        "bytes": e.bytes, "fate": e.fate, "t_sent_s": e.t_sent_s,
                        "t_received_s": e.t_received_s, "delay_ms": delay_ms}),
            ));
        }
        if !matches!(e.fate, "delivered" | "sent" | "received") {
            out.extend(self.log(
                Topic::Log,
                t_s,
                WARNING,
                TOOL,
                &format!(
                    "{} {} frame ({} B) {}",
                    e.direction, e.kind, e.bytes, e.fate
                ),
            ));
        }
        out
    }

    /// A DEBT stream (or prefix) decoded, as PNG, or as JPEG at `jpeg_quality`.
    fn picture(
        &self,
        topic: Topic,
        t_s: f64,
        stream: &[u8],
        jpeg_quality: Option<u8>,
    ) -> Option<ViewMessage> {
        if !self.wants(topic) {
            return None;
        }
        let img = rovlink_debt::decode(stream).ok()?;
        let (bytes, format) = match jpeg_quality {
            Some(q) => (rovlink_debt::picture::to_jpeg(&img, q).ok()?, "jpeg"),
            None => (rovlink_debt::picture::to_png(&img).ok()?, "png"),
        };
        let (ns, timestamp) = self.stamp(t_s);
        let data = base64::engine::general_purpose::STANDARD.encode(bytes);
        Some(View::message(
            topic,
            ns,
            &json!({"timestamp": timestamp, "frame_id": "camera", "data": data, "format": format}),
        ))
    }

    /// A completed image (its DEBT stream) as PNG on `/camera/image`, or a warning on
    /// `/link/log` when it does not decode.
    pub fn image(&self, t_s: f64, stream: &[u8]) -> Option<ViewMessage> {
        if !self.wants(Topic::Image) {
            return None;
        }
        self.picture(Topic::Image, t_s, stream, None).or_else(|| {
            self.log(
                Topic::Log,
                t_s,
                WARNING,
                TOOL,
                "a completed image did not decode",
            )
        })
    }

    /// The image in progress (a DEBT prefix) as JPEG on `/camera/preview` (a picture still
    /// arriving is blurry: JPEG at [`PREVIEW_JPEG_QUALITY`] is a fraction of its PNG); nothing
    /// when the prefix does not decode yet.
    pub fn preview(&self, t_s: f64, prefix: &[u8]) -> Option<ViewMessage> {
        self.picture(Topic::Preview, t_s, prefix, Some(PREVIEW_JPEG_QUALITY))
    }

    /// The vehicle's pose, goal and velocities; a line on `/link/log` when the link was lost
    /// or recovered since the last pose.
    pub fn pose(&mut self, pose: &PoseSample) -> Vec<ViewMessage> {
        let mut out = Vec::new();
        let pose_topics = [
            Topic::Pose,
            Topic::Goal,
            Topic::Actual,
            Topic::Commanded,
            Topic::Tf,
        ];
        if pose_topics.iter().any(|&t| self.wants(t)) {
            let (ns, timestamp) = self.stamp(pose.t_s);
            let goal = pose
                .goal_m
                .map(|goal| pose_json(&timestamp, NED_FRAME, goal, heading(pose.heading_deg)));
            let messages = [
                (
                    Topic::Pose,
                    Some(pose_json(
                        &timestamp,
                        NED_FRAME,
                        pose.position_m,
                        heading(pose.heading_deg),
                    )),
                ),
                (Topic::Goal, goal),
                (
                    Topic::Actual,
                    Some(velocity_json(&timestamp, pose.velocity)),
                ),
                (
                    Topic::Commanded,
                    Some(velocity_json(&timestamp, pose.commanded_velocity)),
                ),
                (
                    Topic::Tf,
                    Some(tf_json(
                        &timestamp,
                        &self.body_frame,
                        pose.position_m,
                        pose.heading_deg,
                    )),
                ),
            ];
            for (topic, json) in messages {
                if let Some(json) = json.filter(|_| self.wants(topic)) {
                    out.push(View::message(topic, ns, &json));
                }
            }
        }
        if self.link_up.is_some_and(|up| up != pose.link_up) {
            let message = if pose.link_up {
                "link recovered: heartbeats again"
            } else {
                "link lost: no heartbeat for 5 s, backtracking"
            };
            let level = if pose.link_up { INFO } else { WARNING };
            out.extend(self.log(Topic::Log, pose.t_s, level, TOOL, message));
        }
        self.link_up = Some(pose.link_up);
        out
    }

    /// A line when the WHY or NP of the statuses changes (ST = 1, wire.md's status version 1):
    /// a WARNING for a reason or a missing position, INFO when they clear.
    fn status_reason_line(
        &self,
        repr: &rovlink_wire::MessageRepr,
        events: &dyn Fn(u8, &str) -> Vec<ViewMessage>,
    ) -> Vec<ViewMessage> {
        let rovlink_wire::Message::Rov(rovlink_wire::rov::Repr {
            status: rovlink_wire::rov::Status::Basic(status),
            ..
        }) = &repr.message
        else {
            return Vec::new();
        };
        let now = (status.why(), status.position_known());
        let before = self.status_reason.replace(Some(now));
        if before == Some(now)
            || (before.is_none() && now == (rovlink_wire::rov::Why::Nothing, true))
        {
            return Vec::new();
        }
        match now {
            (rovlink_wire::rov::Why::Nothing, true) => events(
                INFO,
                "ROV status: nothing stands in the way, position known",
            ),
            (why, known) => events(
                WARNING,
                &format!(
                    "ROV status: why {why}{}",
                    if known { "" } else { "; no position estimate" }
                ),
            ),
        }
    }

    /// A warning for the user (a refused frame's source, an order source's bad line): a
    /// WARNING line on `/session/log`.
    pub fn warning(&self, t_s: f64, text: &str) -> Vec<ViewMessage> {
        self.log(Topic::Events, t_s, WARNING, TOOL, text)
            .into_iter()
            .collect()
    }

    /// The session's start line (what runs, where, for how long): an INFO line on
    /// `/session/log`.
    pub fn started(&self, t_s: f64, text: &str) -> Vec<ViewMessage> {
        self.log(Topic::Events, t_s, INFO, TOOL, text)
            .into_iter()
            .collect()
    }

    /// What happened at `end`: a line on `/session/log` (the operator's lost and recovered
    /// answers on `/link/log`), the image in progress on `/camera/preview`. Statuses,
    /// completed images and the ROV's link changes are told through [`View::pose`] and
    /// [`View::image`], so they give nothing here.
    pub fn event(&self, end: Role, t_s: f64, event: &Event) -> Vec<ViewMessage> {
        let name = match end {
            Role::Operator => "tdma-run operator",
            Role::Rov => "tdma-run rov",
        };
        let line = |topic, level, text: &str| {
            self.log(topic, t_s, level, name, text)
                .into_iter()
                .collect()
        };
        let events = |level, text: &str| line(Topic::Events, level, text);
        match event {
            Event::OrderSent { index, order } => {
                events(INFO, &format!("order {index} sent: {order:?}"))
            }
            Event::OrderAcknowledged(index) => events(INFO, &format!("order {index} acknowledged")),
            Event::CancelConfirmed => events(
                INFO,
                "cancel confirmed: the order in execution was cancelled",
            ),
            Event::OrderExecuted(order) => events(INFO, &format!("executing {order:?}")),
            Event::OrderCancelled => events(INFO, "the order in execution was cancelled"),
            Event::ImageStarted { trunks, bytes } => {
                events(DEBUG, &format!("image started: {trunks} trunks, {bytes} B"))
            }
            Event::ImageCancelled => events(INFO, "the image in flight was cancelled"),
            Event::Vehicle(drive) => match drive {
                rovlink_rcp::autopilot::DriveEvent::Silent { silent_s } => {
                    events(WARNING, &format!("autopilot silent for {silent_s:.1} s"))
                }
                rovlink_rcp::autopilot::DriveEvent::Heard => events(INFO, "autopilot heard again"),
                rovlink_rcp::autopilot::DriveEvent::CommandAck {
                    command,
                    result,
                    accepted,
                } => events(
                    if *accepted { INFO } else { WARNING },
                    &format!("autopilot answered {command}: {result}"),
                ),
                rovlink_rcp::autopilot::DriveEvent::Refused { why, reason } => {
                    events(WARNING, &format!("vehicle refused ({why}): {reason}"))
                }
                rovlink_rcp::autopilot::DriveEvent::Note(note) => {
                    events(INFO, &format!("vehicle: {note}"))
                }
                // Counted in the metrics; the drive's note said it once per source.
                rovlink_rcp::autopilot::DriveEvent::MessagesRefused { .. } => Vec::new(),
            },
            Event::CameraFailed(why) => events(WARNING, &format!("camera: {why}")),
            Event::AnswersLost => line(Topic::Log, WARNING, "answers lost: no ROV frame for 5 s"),
            Event::AnswersBack => line(Topic::Log, INFO, "answers back: ROV frames again"),
            Event::ImageProgress { prefix, .. } => self.preview(t_s, prefix).into_iter().collect(),
            Event::Status(repr) => self.status_reason_line(repr, &events),
            Event::ImageCompleted(_) | Event::LinkLost | Event::LinkRecovered => Vec::new(),
        }
    }
}

/// The name the log's lines carry.
const TOOL: &str = "tdma-run";

/// An MCAP file of JSON channels being written: the writer, its message sequence and the first
/// write error (later messages are dropped; [`JsonMcapFile::finish`] reports it). Both session
/// logs ([`McapLog`] and [`crate::net_mcap::NetMcapLog`]) write through one.
pub struct JsonMcapFile {
    path: String,
    writer: mcap::Writer<NoSeek<Output>>,
    sequence: u32,
    error: Option<McapLogError>,
}

impl JsonMcapFile {
    /// Opens `dest` (a file written aside, or standard output) and starts the MCAP stream.
    pub fn create(dest: &Dest) -> Result<JsonMcapFile, McapLogError> {
        let path = dest.name();
        let writer = rovlink_base::io::json_mcap_writer(dest.open()?).map_err(|source| {
            McapLogError::Mcap {
                path: path.clone(),
                source,
            }
        })?;
        Ok(JsonMcapFile {
            path,
            writer,
            sequence: 0,
            error: None,
        })
    }

    /// Adds a channel of JSON messages on `topic` with a JSON Schema; returns its id.
    pub fn channel(
        &mut self,
        schema_name: &str,
        schema: &str,
        topic: &str,
    ) -> Result<u16, McapLogError> {
        rovlink_base::io::json_mcap_channel(
            &mut self.writer,
            schema_name,
            schema,
            topic,
            &BTreeMap::new(),
        )
        .map_err(|source| McapLogError::Mcap {
            path: self.path.clone(),
            source,
        })
    }

    /// True once a write failed.
    pub fn failed(&self) -> bool {
        self.error.is_some()
    }

    /// Writes one message on `channel_id` at `log_time_ns` (nothing once a write failed).
    pub fn write(&mut self, channel_id: u16, log_time_ns: u64, json: &str) {
        if self.error.is_some() {
            return;
        }
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.sequence = self.sequence.wrapping_add(1);
        if let Err(source) = self.writer.write_to_known_channel(&header, json.as_bytes()) {
            self.error = Some(McapLogError::Mcap {
                path: self.path.clone(),
                source,
            });
        }
    }

    /// Closes the file (summary, footer) and puts it in place; reports the first error.
    pub fn finish(self) -> Result<(), McapLogError> {
        let JsonMcapFile {
            path,
            mut writer,
            error,
            ..
        } = self;
        if let Some(error) = error {
            return Err(error);
        }
        writer
            .finish()
            .map_err(|source| McapLogError::Mcap { path, source })?;
        writer.into_inner().into_inner().finish()?;
        Ok(())
    }
}

/// An [`Observer`] that writes the session into an MCAP file, committed by [`McapLog::finish`]
/// (nothing is left at the path when the run fails before), or to standard output. The writer
/// never seeks (chunks are assembled in memory), so a pipe is as good as a file. It has the
/// channels whose [`Topic::in_log`] is true.
pub struct McapLog {
    file: JsonMcapFile,
    /// The MCAP channel id of each [`Topic`] the log has, by [`Topic::index`].
    channels: Vec<Option<u16>>,
    view: View,
}

impl McapLog {
    /// Creates the log at `dest` (a file, or standard output); log times are `base_ns` plus
    /// the session's time.
    pub fn create(dest: &Dest, base_ns: u64) -> Result<McapLog, McapLogError> {
        let mut file = JsonMcapFile::create(dest)?;
        let mut channels = vec![None; Topic::ALL.len()];
        for topic in Topic::ALL.into_iter().filter(|t| t.in_log()) {
            let channel = file.channel(topic.schema_name(), topic.schema(), topic.name())?;
            channels[topic.index()] = Some(channel);
        }
        Ok(McapLog {
            file,
            channels,
            view: View::new(Clock::Session { base_ns }),
        })
    }

    /// Closes the file (summary, footer) and puts it in place; reports the first error.
    pub fn finish(self) -> Result<(), McapLogError> {
        self.file.finish()
    }

    fn write(&mut self, message: &ViewMessage) {
        if let Some(&Some(channel_id)) = self.channels.get(message.topic.index()) {
            self.file
                .write(channel_id, message.log_time_ns, &message.json);
        }
    }

    fn write_all(&mut self, messages: &[ViewMessage]) {
        for message in messages {
            self.write(message);
        }
    }
}

/// `/tf` at a pose: world -> ned (a half turn about north: z down becomes z up) and ned ->
/// `body` (the position, and the heading as a turn about ned's z).
fn tf_json(
    timestamp: &serde_json::Value,
    body: &str,
    position_m: [f64; 3],
    heading_deg: f64,
) -> serde_json::Value {
    let [qx, qy, qz, qw] = heading(heading_deg);
    json!({"transforms": [
        {"timestamp": timestamp, "parent_frame_id": WORLD_FRAME, "child_frame_id": NED_FRAME,
         "translation": {"x": 0.0, "y": 0.0, "z": 0.0},
         "rotation": {"x": 1.0, "y": 0.0, "z": 0.0, "w": 0.0}},
        {"timestamp": timestamp, "parent_frame_id": NED_FRAME, "child_frame_id": body,
         "translation": {"x": position_m[0], "y": position_m[1], "z": position_m[2]},
         "rotation": {"x": qx, "y": qy, "z": qz, "w": qw}},
    ]})
}

/// A heading as a rotation about the down axis (x, y, z, w).
pub(crate) fn heading(heading_deg: f64) -> [f64; 4] {
    rovlink_ros2::msgs::yaw_quaternion(heading_deg.to_radians())
}

/// A `foxglove.Timestamp` of `ns` nanoseconds.
pub fn timestamp_json(ns: u64) -> serde_json::Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

/// A `foxglove.PoseInFrame` message: `position_m` and the rotation `orientation` (x, y, z, w)
/// in `frame_id`.
pub fn pose_json(
    timestamp: &serde_json::Value,
    frame_id: &str,
    position_m: [f64; 3],
    orientation: [f64; 4],
) -> serde_json::Value {
    let [x, y, z, w] = orientation;
    json!({
        "timestamp": timestamp,
        "frame_id": frame_id,
        "pose": {
            "position": {"x": position_m[0], "y": position_m[1], "z": position_m[2]},
            "orientation": {"x": x, "y": y, "z": z, "w": w},
        }
    })
}

/// A `foxglove.Log` message of `level` ([`INFO`], [`WARNING`], ...) from `name`.
pub fn log_json(
    timestamp: &serde_json::Value,
    level: u8,
    name: &str,
    message: &str,
) -> serde_json::Value {
    json!({"timestamp": timestamp, "level": level, "message": message,
           "name": name, "file": "", "line": 0})
}

fn velocity_json(timestamp: &serde_json::Value, v: [f64; 4]) -> serde_json::Value {
    json!({"timestamp": timestamp, "surge_mps": v[0], "sway_mps": v[1], "heave_mps": v[2],
           "yaw_rate_dps": v[3]})
}

/// What the session's outputs hand the log (a single session's: one vehicle).
impl McapLog {
    /// True once a write failed: later messages are dropped, [`McapLog::finish`] reports it.
    pub fn failed(&self) -> bool {
        self.file.failed()
    }

    /// A frame's fate.
    pub fn frame(&mut self, e: &FrameEvent<'_>) {
        let messages = self.view.frame(e);
        self.write_all(&messages);
    }

    /// A completed image.
    pub fn image(&mut self, t_s: f64, stream: &[u8]) {
        if let Some(message) = self.view.image(t_s, stream) {
            self.write(&message);
        }
    }

    /// The vehicle after a step.
    pub fn pose(&mut self, pose: &PoseSample) {
        let messages = self.view.pose(pose);
        self.write_all(&messages);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rovlink_wire::operator::Order;

    #[test]
    fn every_schema_is_one_every_viewer_reads() {
        for topic in Topic::ALL {
            let schema: serde_json::Value = serde_json::from_str(topic.schema()).unwrap();
            assert_eq!(
                schema_problems(&schema, "$"),
                Vec::<String>::new(),
                "{}",
                topic.name()
            );
        }
        // The checker finds what Foxglove refused.
        let bad = serde_json::json!({"type": "object", "properties": {
            "t": {"type": ["number", "null"]}, "u": {}, "v": {"type": "integer", "oneOf": []},
            "w": {"type": "array"}}});
        assert_eq!(
            schema_problems(&bad, "$"),
            [
                "$.t: type [\"number\",\"null\"], not one name",
                "$.u: has no type",
                "$.v: uses oneOf",
                "$.w: an array without items"
            ]
        );
    }

    #[test]
    fn optional_fields_are_left_out_not_null() {
        let v = serde_json::json!({"a": null, "b": {"c": null, "d": 1}, "e": [null, {"f": null}]});
        assert_eq!(
            without_nulls(&v),
            serde_json::json!({"b": {"d": 1}, "e": [null, {}]})
        );
    }

    fn pose(t_s: f64, link_up: bool, goal: bool) -> PoseSample {
        PoseSample {
            t_s,
            position_m: [1.0, 2.0, 3.0],
            heading_deg: 180.0,
            velocity: [0.0; 4],
            commanded_velocity: [0.0; 4],
            goal_m: goal.then_some([4.0, 5.0, 6.0]),
            backtrack_m: None,
            link_up,
        }
    }

    fn topics(messages: &[ViewMessage]) -> Vec<Topic> {
        messages.iter().map(|m| m.topic).collect()
    }

    #[test]
    fn a_pose_gives_its_channels_and_the_links_changes() {
        let mut view = View::new(Clock::Session { base_ns: 1_000 });
        let first = view.pose(&pose(2.5, true, true));
        use Topic::*;
        assert_eq!(topics(&first), [Pose, Goal, Actual, Commanded, Tf]);
        assert!(first.iter().all(|m| m.log_time_ns == 2_500_001_000));
        let json: serde_json::Value = serde_json::from_str(&first[0].json).unwrap();
        assert_eq!(json["timestamp"]["sec"], 2);
        assert_eq!(json["timestamp"]["nsec"], 500_001_000);
        assert!((json["pose"]["orientation"]["z"].as_f64().unwrap() - 1.0).abs() < 1e-12);
        // The transform tree: world -> ned (a half turn about north), ned -> rov at the pose.
        let tf: serde_json::Value = serde_json::from_str(&first[4].json).unwrap();
        let t = &tf["transforms"];
        assert_eq!(
            (
                t[0]["parent_frame_id"].as_str(),
                t[0]["child_frame_id"].as_str()
            ),
            (Some("world"), Some("ned"))
        );
        assert_eq!(t[0]["rotation"]["x"], 1.0);
        assert_eq!(
            (
                t[1]["parent_frame_id"].as_str(),
                t[1]["child_frame_id"].as_str()
            ),
            (Some("ned"), Some("rov"))
        );
        assert_eq!(t[1]["translation"], json["pose"]["position"]);
        assert_eq!(t[1]["rotation"], json["pose"]["orientation"]);
        let lost = view.pose(&pose(3.0, false, false));
        assert_eq!(topics(&lost), [Pose, Actual, Commanded, Tf, Log]);
        assert!(lost[4].json.contains("link lost"), "{}", lost[4].json);
        // Only the link log wanted: nothing else is built, the link is still followed.
        view.want(|t| t == Log);
        assert!(view.pose(&pose(3.5, false, false)).is_empty());
        let back = view.pose(&pose(4.0, true, false));
        assert_eq!(topics(&back), [Log]);
        assert!(back[0].json.contains("link recovered"));
        assert_eq!(view.image(4.0, b"not DEBT"), None, "images not wanted");
    }

    #[test]
    fn events_become_session_lines_and_images_that_fail_a_warning() {
        let view = View::new(Clock::Wall);
        let order = Order::HoldHeading {
            heading_deg: 90,
            enable: true,
        };
        let sent = view.event(Role::Operator, 1.0, &Event::OrderSent { index: 3, order });
        assert_eq!(topics(&sent), [Topic::Events]);
        let json: serde_json::Value = serde_json::from_str(&sent[0].json).unwrap();
        assert_eq!(json["name"], "tdma-run operator");
        assert_eq!(json["level"], INFO);
        assert!(
            json["message"]
                .as_str()
                .unwrap()
                .starts_with("order 3 sent: HoldHeading")
        );
        let lost = view.event(Role::Operator, 1.0, &Event::AnswersLost);
        assert_eq!(topics(&lost), [Topic::Log]);
        assert!(view.event(Role::Rov, 1.0, &Event::LinkLost).is_empty());
        let wall_ns = wall_clock_ns();
        assert!(sent[0].log_time_ns <= wall_ns && wall_ns - sent[0].log_time_ns < 10_000_000_000);
        let bad = view.image(1.0, b"not DEBT").unwrap();
        assert_eq!(bad.topic, Topic::Log);
        assert!(bad.json.contains("did not decode"));
        assert!(view.preview(1.0, b"").is_none());
    }

    #[test]
    fn a_warning_is_a_warning_line_on_the_session_log() {
        let view = View::new(Clock::Wall);
        let said = view.warning(
            2.0,
            "node 1: refused a frame claiming to come from 0 (bad_tag)",
        );
        assert_eq!(topics(&said), [Topic::Events]);
        let json: serde_json::Value = serde_json::from_str(&said[0].json).unwrap();
        assert_eq!(json["level"], WARNING);
        assert!(json["message"].as_str().unwrap().contains("(bad_tag)"));
    }

    #[test]
    fn a_status_reason_is_a_line_when_it_changes() {
        use rovlink_wire::rov::{BasicStatus, Extension, Repr, Status, Why};
        let view = View::new(Clock::Wall);
        let status = |extension| {
            Event::Status(rovlink_wire::MessageRepr {
                src: 1,
                dst: 0,
                message: rovlink_wire::Message::Rov(Repr {
                    ft: false,
                    lt: false,
                    isn: false,
                    ci: false,
                    itsn: 0,
                    status: Status::Basic(BasicStatus {
                        extension,
                        ..BasicStatus::default()
                    }),
                    trunk: Vec::new(),
                }),
            })
        };
        let refused = Some(Extension {
            no_position: true,
            why: Why::NoPosition,
        });
        assert!(view.event(Role::Operator, 1.0, &status(None)).is_empty());
        let said = view.event(Role::Operator, 2.0, &status(refused));
        assert_eq!(topics(&said), [Topic::Events]);
        let json: serde_json::Value = serde_json::from_str(&said[0].json).unwrap();
        assert_eq!(json["level"], WARNING);
        assert_eq!(
            json["message"],
            "ROV status: why no_position; no position estimate"
        );
        assert!(view.event(Role::Operator, 3.0, &status(refused)).is_empty());
        let cleared = view.event(Role::Operator, 4.0, &status(None));
        let json: serde_json::Value = serde_json::from_str(&cleared[0].json).unwrap();
        assert_eq!(json["level"], INFO);
    }
}
