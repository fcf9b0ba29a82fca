//! A multi-vehicle scenario's MCAP log (`tdma-run --scenario --mcap`): the single-vehicle
//! session's channels once per vehicle, and one channel of every frame at every receiver.
//!
//! | topic | schema | what |
//! |---|---|---|
//! | `/vehicle/N/rov/pose`, `/rov/goal`, `/rov/velocity/actual`, `/rov/velocity/commanded` | as in [`crate::mcap_log`] | vehicle N's pose, goal, velocities |
//! | `/vehicle/N/link/log` | `foxglove.Log` | vehicle N's link lost and recovered |
//! | `/vehicle/N/camera/image` | `foxglove.CompressedImage` | vehicle N's completed images |
//! | `/network/frames` | `rovlink.HopFrame` | one message per frame and receiver: medium, SRC, DST, transmitter, receiver, kind, bytes, fate, the receiver's action, delay |
//!
//! Each vehicle has its own [`View`], so its link state is its own. Log times are the session's
//! (the same seed gives the same file). The file is written aside and committed by
//! [`NetMcapLog::finish`]; the first write error is kept and reported there.

use std::collections::BTreeMap;

use serde_json::json;

use crate::mcap_log::{Clock, JsonMcapFile, McapLogError, Topic, View, ViewMessage, without_nulls};
use rovlink_base::output::Dest;
use rovlink_rcp::report::FrameEvent;
use rovlink_rcp::{PoseSample, Role};

/// The JSON Schema of `/network/frames`.
pub const HOP_FRAME: &str = r#"{"title":"rovlink.HopFrame","type":"object","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"medium":{"type":"string"},"src":{"type":"integer","description":"omitted when the frame had no readable header"},"dst":{"type":"integer","description":"omitted when the frame had no readable header"},"tx":{"type":"integer"},"rx":{"type":"integer"},"kind":{"type":"string"},"bytes":{"type":"integer"},"fate":{"type":"string"},"action":{"type":"string"},"t_sent_s":{"type":"number"},"t_received_s":{"type":"number","description":"omitted when not received"},"delay_ms":{"type":"number","description":"omitted when not delivered"}}}"#;

/// The topic of a network's frames.
pub const NETWORK_FRAMES_TOPIC: &str = "/network/frames";

/// A frame's fate at one receiver as a `/network/frames` message, stamped `timestamp_ns`.
pub fn hop_json(e: &FrameEvent<'_>, timestamp_ns: u64) -> String {
    let delay_ms = e.t_received_s.zip(e.t_sent_s).map(|(r, s)| (r - s) * 1e3);
    let json = json!({
        "timestamp": crate::mcap_log::timestamp_json(timestamp_ns),
        "medium": e.medium, "src": e.src, "dst": e.dst, "tx": e.tx, "rx": e.rx,
        "kind": e.kind, "bytes": e.bytes, "fate": e.fate, "action": e.action,
        "t_sent_s": e.t_sent_s, "t_received_s": e.t_received_s, "delay_ms": delay_ms,
    });
    without_nulls(&json).to_string()
}

/// The per-vehicle channels: the log's own, except the single link's frames.
fn vehicle_topics() -> impl Iterator<Item = Topic> {
    Topic::ALL
        .into_iter()
        .filter(|t| t.in_log() && *t != Topic::Frames)
}

/// The topic of `topic` for `vehicle`: `/vehicle/2/rov/pose`.
pub fn vehicle_topic(vehicle: u8, topic: Topic) -> String {
    format!("/vehicle/{vehicle}{}", topic.name())
}

/// The MCAP log of a scenario.
pub struct NetMcapLog {
    file: JsonMcapFile,
    /// Channel ids by (vehicle, topic index).
    channels: BTreeMap<(u8, usize), u16>,
    frames: u16,
    views: BTreeMap<u8, View>,
}

impl NetMcapLog {
    /// Creates the log at `dest` with the channels of `vehicles`.
    pub fn create(dest: &Dest, vehicles: &[u8]) -> Result<NetMcapLog, McapLogError> {
        let mut file = JsonMcapFile::create(dest)?;
        let mut channels = BTreeMap::new();
        for &vehicle in vehicles {
            for topic in vehicle_topics() {
                let topic_name = vehicle_topic(vehicle, topic);
                let id = file.channel(topic.schema_name(), topic.schema(), &topic_name)?;
                channels.insert((vehicle, topic.index()), id);
            }
        }
        let frames = file.channel("rovlink.HopFrame", HOP_FRAME, NETWORK_FRAMES_TOPIC)?;
        let views = vehicles
            .iter()
            .map(|&v| {
                let view = View::new(Clock::Session { base_ns: 0 });
                (v, view.with_body_frame(&format!("vehicle_{v}")))
            })
            .collect();
        Ok(NetMcapLog {
            file,
            channels,
            frames,
            views,
        })
    }

    /// True once a write failed.
    pub fn failed(&self) -> bool {
        self.file.failed()
    }

    /// Closes the file and puts it in place; reports the first error.
    pub fn finish(self) -> Result<(), McapLogError> {
        self.file.finish()
    }

    fn write(&mut self, channel_id: u16, log_time_ns: u64, json: &str) {
        self.file.write(channel_id, log_time_ns, json);
    }

    fn write_vehicle(&mut self, vehicle: u8, messages: &[ViewMessage]) {
        for m in messages {
            if let Some(&id) = self.channels.get(&(vehicle, m.topic.index())) {
                self.write(id, m.log_time_ns, &m.json);
            }
        }
    }

    /// A frame's fate at one receiver.
    pub fn hop(&mut self, e: &FrameEvent<'_>) {
        let t_s = e.t_received_s.or(e.t_sent_s).unwrap_or(0.0);
        let ns = (t_s.max(0.0) * 1e9).round() as u64;
        self.write(self.frames, ns, &hop_json(e, ns));
    }

    /// A completed image of `vehicle`.
    pub fn image(&mut self, vehicle: u8, t_s: f64, stream: &[u8]) {
        let message = self.views.get(&vehicle).and_then(|v| v.image(t_s, stream));
        if let Some(message) = message {
            self.write_vehicle(vehicle, &[message]);
        }
    }

    /// `vehicle` after a step.
    pub fn pose(&mut self, vehicle: u8, pose: &PoseSample) {
        let messages = self
            .views
            .get_mut(&vehicle)
            .map(|v| v.pose(pose))
            .unwrap_or_default();
        self.write_vehicle(vehicle, &messages);
    }

    /// An event of `vehicle`'s session that the log shows (the operator's answers lost).
    pub fn event(&mut self, vehicle: u8, end: Role, t_s: f64, event: &rovlink_rcp::Event) {
        let messages = self
            .views
            .get(&vehicle)
            .map(|v| v.event(end, t_s, event))
            .unwrap_or_default();
        self.write_vehicle(vehicle, &messages);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hop_schema_is_one_every_viewer_reads() {
        let schema: serde_json::Value = serde_json::from_str(HOP_FRAME).unwrap();
        assert!(crate::mcap_log::schema_problems(&schema, "$").is_empty());
    }
}
