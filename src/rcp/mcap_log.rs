//! A session log in MCAP that Foxglove displays: the vehicle's pose, its commanded and actual
//! velocities, the link's events, and every completed image.
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
//!
//! Log times are nanoseconds: the session's time plus a base (0 in simulation, so the same seed
//! gives the same file; the wall clock at the start in real time).

use std::collections::BTreeMap;

use base64::Engine;
use serde_json::json;

use mcap::write::NoSeek;

use super::PoseSample;
use super::session::{FrameEvent, Observer};
use crate::cli::output::Dest;
use crate::io::{IoError, Output};

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

const LOG: &str = r#"{"title":"foxglove.Log","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"level":{"type":"integer","oneOf":[{"title":"UNKNOWN","const":0},{"title":"DEBUG","const":1},{"title":"INFO","const":2},{"title":"WARNING","const":3},{"title":"ERROR","const":4},{"title":"FATAL","const":5}]},"message":{"type":"string"},"name":{"type":"string"},"file":{"type":"string"},"line":{"type":"integer","minimum":0}}}"#;

const BODY_VELOCITY: &str = r#"{"title":"rovlink.BodyVelocity","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"surge_mps":{"type":"number"},"sway_mps":{"type":"number"},"heave_mps":{"type":"number"},"yaw_rate_dps":{"type":"number"}}}"#;

const LINK_FRAME: &str = r#"{"title":"rovlink.LinkFrame","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"direction":{"type":"string"},"kind":{"type":"string"},"bytes":{"type":"integer"},"fate":{"type":"string"},"t_sent_s":{"type":["number","null"]},"t_received_s":{"type":["number","null"]},"delay_ms":{"type":["number","null"]}}}"#;

/// Foxglove's log levels.
const INFO: u8 = 2;
const WARNING: u8 = 3;

/// The channels, in the order they are added.
#[derive(Clone, Copy)]
enum Topic {
    Pose,
    Goal,
    Actual,
    Commanded,
    Frames,
    Log,
    Image,
}

const TOPICS: [(&str, &str, &str); 7] = [
    ("/rov/pose", "foxglove.PoseInFrame", POSE_IN_FRAME),
    ("/rov/goal", "foxglove.PoseInFrame", POSE_IN_FRAME),
    (
        "/rov/velocity/actual",
        "rovlink.BodyVelocity",
        BODY_VELOCITY,
    ),
    (
        "/rov/velocity/commanded",
        "rovlink.BodyVelocity",
        BODY_VELOCITY,
    ),
    ("/link/frames", "rovlink.LinkFrame", LINK_FRAME),
    ("/link/log", "foxglove.Log", LOG),
    (
        "/camera/image",
        "foxglove.CompressedImage",
        COMPRESSED_IMAGE,
    ),
];

/// An [`Observer`] that writes the session into an MCAP file, committed by [`McapLog::finish`]
/// (nothing is left at the path when the run fails before), or to standard output. The writer
/// never seeks (chunks are assembled in memory), so a pipe is as good as a file.
pub struct McapLog {
    path: String,
    writer: Option<mcap::Writer<NoSeek<Output>>>,
    channels: Vec<u16>,
    sequence: u32,
    base_ns: u64,
    link_up: Option<bool>,
    /// The first write error; later messages are dropped.
    error: Option<McapLogError>,
}

impl McapLog {
    /// Creates the log at `dest` (a file, or standard output); log times are `base_ns` plus
    /// the session's time.
    pub fn create(dest: &Dest, base_ns: u64) -> Result<McapLog, McapLogError> {
        let name = dest.name();
        let wrap = |source| McapLogError::Mcap {
            path: name.clone(),
            source,
        };
        let out = dest.open()?;
        let mut writer = crate::io::json_mcap_writer(out).map_err(wrap)?;
        let mut channels = Vec::new();
        for (topic, schema, text) in TOPICS {
            let channel =
                crate::io::json_mcap_channel(&mut writer, schema, text, topic, &BTreeMap::new());
            channels.push(channel.map_err(wrap)?);
        }
        Ok(McapLog {
            path: name,
            writer: Some(writer),
            channels,
            sequence: 0,
            base_ns,
            link_up: None,
            error: None,
        })
    }

    /// Closes the file (summary, footer) and puts it in place; reports the first error.
    pub fn finish(mut self) -> Result<(), McapLogError> {
        if let Some(error) = self.error.take() {
            return Err(error);
        }
        let Some(mut writer) = self.writer.take() else {
            return Ok(());
        };
        writer.finish().map_err(|source| McapLogError::Mcap {
            path: self.path.clone(),
            source,
        })?;
        writer.into_inner().into_inner().finish()?;
        Ok(())
    }

    fn stamp(&self, t_s: f64) -> (u64, serde_json::Value) {
        let ns = self
            .base_ns
            .saturating_add((t_s.max(0.0) * 1e9).round() as u64);
        (
            ns,
            json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000}),
        )
    }

    fn write(&mut self, topic: Topic, log_time_ns: u64, message: &serde_json::Value) {
        if self.error.is_some() {
            return;
        }
        let Some(writer) = self.writer.as_mut() else {
            return;
        };
        let header = mcap::records::MessageHeader {
            channel_id: self.channels[topic as usize],
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.sequence = self.sequence.wrapping_add(1);
        let data = message.to_string();
        if let Err(source) = writer.write_to_known_channel(&header, data.as_bytes()) {
            self.error = Some(McapLogError::Mcap {
                path: self.path.clone(),
                source,
            });
        }
    }

    fn log(&mut self, t_s: f64, level: u8, message: &str) {
        let (ns, timestamp) = self.stamp(t_s);
        self.write(
            Topic::Log,
            ns,
            &json!({"timestamp": timestamp, "level": level, "message": message,
                    "name": "tdma-run", "file": "", "line": 0}),
        );
    }
}

/// A pose message: NED position, heading as a rotation about the down axis.
fn pose_json(
    timestamp: &serde_json::Value,
    position_m: [f64; 3],
    heading_deg: f64,
) -> serde_json::Value {
    let half = heading_deg.to_radians() / 2.0;
    json!({
        "timestamp": timestamp,
        "frame_id": "ned",
        "pose": {
            "position": {"x": position_m[0], "y": position_m[1], "z": position_m[2]},
            "orientation": {"x": 0.0, "y": 0.0, "z": half.sin(), "w": half.cos()},
        }
    })
}

fn velocity_json(timestamp: &serde_json::Value, v: [f64; 4]) -> serde_json::Value {
    json!({"timestamp": timestamp, "surge_mps": v[0], "sway_mps": v[1], "heave_mps": v[2],
           "yaw_rate_dps": v[3]})
}

impl Observer for McapLog {
    /// True once a write failed: later messages are dropped, [`McapLog::finish`] reports it.
    fn failed(&self) -> bool {
        self.error.is_some()
    }

    fn frame(&mut self, e: &FrameEvent) {
        let t_s = e.t_received_s.or(e.t_sent_s).unwrap_or(0.0);
        let (ns, timestamp) = self.stamp(t_s);
        let delay_ms = e.t_sent_s.zip(e.t_received_s).map(|(s, r)| (r - s) * 1e3);
        self.write(
            Topic::Frames,
            ns,
            &json!({"timestamp": timestamp, "direction": e.direction, "kind": e.kind,
                    "bytes": e.bytes, "fate": e.fate, "t_sent_s": e.t_sent_s,
                    "t_received_s": e.t_received_s, "delay_ms": delay_ms}),
        );
        if !matches!(e.fate, "delivered" | "sent" | "received") {
            self.log(
                t_s,
                WARNING,
                &format!(
                    "{} {} frame ({} B) {}",
                    e.direction, e.kind, e.bytes, e.fate
                ),
            );
        }
    }

    fn image(&mut self, t_s: f64, stream: &[u8]) {
        let png = crate::debt::decode(stream)
            .ok()
            .and_then(|img| crate::debt::picture::to_png(&img).ok());
        let Some(png) = png else {
            self.log(t_s, WARNING, "a completed image did not decode");
            return;
        };
        let (ns, timestamp) = self.stamp(t_s);
        let data = base64::engine::general_purpose::STANDARD.encode(png);
        self.write(
            Topic::Image,
            ns,
            &json!({"timestamp": timestamp, "frame_id": "camera", "data": data, "format": "png"}),
        );
    }

    fn pose(&mut self, pose: &PoseSample) {
        let (ns, timestamp) = self.stamp(pose.t_s);
        self.write(
            Topic::Pose,
            ns,
            &pose_json(&timestamp, pose.position_m, pose.heading_deg),
        );
        if let Some(goal) = pose.goal_m {
            self.write(
                Topic::Goal,
                ns,
                &pose_json(&timestamp, goal, pose.heading_deg),
            );
        }
        self.write(Topic::Actual, ns, &velocity_json(&timestamp, pose.velocity));
        self.write(
            Topic::Commanded,
            ns,
            &velocity_json(&timestamp, pose.commanded_velocity),
        );
        if self.link_up.is_some_and(|up| up != pose.link_up) {
            let message = if pose.link_up {
                "link recovered: heartbeats again"
            } else {
                "link lost: no heartbeat for 5 s, backtracking"
            };
            self.log(pose.t_s, if pose.link_up { INFO } else { WARNING }, message);
        }
        self.link_up = Some(pose.link_up);
    }
}
