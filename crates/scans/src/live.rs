//! Clouds posed as they arrive: a live topic's `PointCloud2` messages matched with the
//! transforms (`/tf`, `/tf_static`) or poses that come beside them, by the rules and the code
//! that pose a bag's clouds ([`recording`](crate::recording)), so the same messages give the
//! same scans.
//!
//! tf2's rules, live:
//!
//! - static transforms hold at all times (a late `/tf_static` is latched by its publisher);
//! - a dynamic link is interpolated at the cloud's stamp between its samples around it, so a
//!   cloud waits until a sample at or after its stamp has come on every dynamic link of its
//!   chain (or its frame has joined the tree), at most [`LiveOptions::wait_ns`] after it
//!   arrived; then it is skipped, with the reason (one warning per reason is the caller's);
//! - clouds are handed out in the order they came: a waiting cloud holds back those after it;
//! - memory is bounded: at most [`LiveOptions::max_pending`] clouds wait (the oldest is
//!   skipped past that), and samples older than [`LiveOptions::keep_ns`] before the newest
//!   transform are dropped (tf2 keeps 10 s).
//!
//! A malformed message (CDR that does not decode, a NaN pose, a quaternion not of unit length,
//! a frame given a second parent, a transform that would close a cycle) is refused with a
//! problem line and changes nothing; the others go on. Nothing here panics on any input.

use std::collections::VecDeque;

use crate::recording::{Item, NoPose, Poses, decode_pose_message, pose_at};
use crate::ros;
use crate::tf::{PoseTrack, TfTree};
use rovlink_octo::Pose;

/// Where live clouds get their pose.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LivePoseSource {
    /// `/tf` and `/tf_static`.
    Tf,
    /// A pose topic (its name, for messages) of `schema` (PoseStamped, TransformStamped or
    /// Odometry).
    Track {
        /// The topic's name.
        topic: String,
        /// Its message type.
        schema: String,
    },
    /// None: every cloud at the identity (the caller's `--origin`).
    Fixed,
}

/// How [`LivePoser`] waits and what it keeps.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LiveOptions {
    /// The pose source.
    pub source: LivePoseSource,
    /// The frame the map is built in; `None`: the root of the first posed cloud's tree.
    pub fixed_frame: Option<String>,
    /// How long a cloud waits for its transforms after it arrived, nanoseconds.
    pub wait_ns: i64,
    /// How much transform history is kept before the newest sample, nanoseconds.
    pub keep_ns: i64,
    /// The most clouds waiting at once.
    pub max_pending: usize,
}

impl Default for LiveOptions {
    fn default() -> Self {
        LiveOptions {
            source: LivePoseSource::Tf,
            fixed_frame: None,
            wait_ns: 1_000_000_000,
            keep_ns: 10_000_000_000,
            max_pending: 16,
        }
    }
}

struct Pending {
    header: ros::Header,
    builder: crate::cloud::CloudBuilder,
    arrived_ns: i64,
}

/// Live clouds and their poses; see the [module documentation](self).
pub struct LivePoser {
    options: LiveOptions,
    poses: Option<Poses>,
    fixed: Option<String>,
    pending: VecDeque<Pending>,
    newest_ns: i64,
    /// Notes for the user (colour fields not understood), each once.
    pub notes: Vec<String>,
}

impl LivePoser {
    /// An empty poser.
    pub fn new(options: LiveOptions) -> LivePoser {
        let poses = match &options.source {
            LivePoseSource::Tf => Some(Poses::Tf(TfTree::new())),
            LivePoseSource::Track { topic, .. } => {
                Some(Poses::Track(PoseTrack::new(), topic.clone()))
            }
            LivePoseSource::Fixed => None,
        };
        LivePoser {
            fixed: options.fixed_frame.clone(),
            options,
            poses,
            pending: VecDeque::new(),
            newest_ns: i64::MIN,
            notes: Vec::new(),
        }
    }

    /// The fixed frame, once known.
    pub fn fixed_frame(&self) -> Option<&str> {
        self.fixed.as_deref()
    }

    /// How many clouds wait for their pose.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    fn seen(&mut self, stamp_ns: i64) {
        if stamp_ns > self.newest_ns {
            self.newest_ns = stamp_ns;
            let keep_from = stamp_ns.saturating_sub(self.options.keep_ns);
            // The oldest waiting cloud still needs its samples.
            let keep_from = self
                .pending
                .front()
                .map_or(keep_from, |p| keep_from.min(p.header.stamp_ns));
            match &mut self.poses {
                Some(Poses::Tf(tree)) => tree.forget_before(keep_from),
                Some(Poses::Track(track, _)) => track.forget_before(keep_from),
                None => {}
            }
        }
    }

    /// A `tf2_msgs/msg/TFMessage` from `/tf` (or `/tf_static` when `is_static`). Each transform
    /// is taken or refused on its own; the problems are returned, one line each.
    pub fn tf(&mut self, message: &[u8], is_static: bool) -> Vec<String> {
        let transforms = match ros::decode_tf_message(message, 0) {
            Ok(t) => t,
            Err(e) => return vec![format!("TF message: {e}")],
        };
        let Some(Poses::Tf(tree)) = &mut self.poses else {
            return Vec::new();
        };
        let mut problems = Vec::new();
        let mut newest = i64::MIN;
        for t in &transforms {
            match tree.add_live(t, is_static) {
                Ok(()) => newest = newest.max(t.header.stamp_ns),
                Err(e) => problems.push(format!("TF refused: {e}")),
            }
        }
        if !is_static && newest > i64::MIN {
            self.seen(newest);
        }
        problems
    }

    /// A message of the pose topic; a problem line if it is refused.
    pub fn pose(&mut self, message: &[u8]) -> Option<String> {
        let LivePoseSource::Track { schema, topic } = &self.options.source else {
            return None;
        };
        let (header, t) = match decode_pose_message(schema, message) {
            Ok(x) => x,
            Err(e) => return Some(format!("pose topic {topic}: {e}")),
        };
        let Some(Poses::Track(track, _)) = &mut self.poses else {
            return None;
        };
        if let Err(e) = track.add(&header, &t) {
            return Some(format!("pose topic {topic}: refused: {e}"));
        }
        track.finish();
        self.seen(header.stamp_ns);
        None
    }

    /// A `sensor_msgs/msg/PointCloud2` that arrived at `now_ns` (any monotonic clock, the same
    /// as [`LivePoser::ready`]'s); an error line if it does not decode. Past
    /// [`LiveOptions::max_pending`] the oldest waiting cloud is skipped, returned here.
    pub fn cloud(&mut self, message: &[u8], now_ns: i64) -> Result<Option<Item>, String> {
        let (header, builder, note) =
            ros::decode_point_cloud2(message, 0).map_err(|e| format!("cloud: {e}"))?;
        if let Some(note) = note
            && !self.notes.contains(&note)
        {
            self.notes.push(note);
        }
        self.pending.push_back(Pending {
            header,
            builder,
            arrived_ns: now_ns,
        });
        if self.pending.len() > self.options.max_pending.max(1) {
            let p = self.pending.pop_front();
            return Ok(p.map(|p| {
                Item::Skipped(format!(
                    "cloud in frame {:?} dropped: {} clouds were waiting for their pose",
                    p.header.frame_id, self.options.max_pending
                ))
            }));
        }
        Ok(None)
    }

    /// The clouds that can be handed out at `now_ns`, in order: posed, or skipped because
    /// their pose cannot come (or did not within the wait).
    pub fn ready(&mut self, now_ns: i64) -> Vec<Item> {
        let mut out = Vec::new();
        while let Some(front) = self.pending.front() {
            let pose = match &self.poses {
                None => Ok(Pose::IDENTITY),
                Some(poses) => pose_at(
                    poses,
                    &mut self.fixed,
                    &front.header.frame_id,
                    front.header.stamp_ns,
                    true,
                ),
            };
            let waited = now_ns.saturating_sub(front.arrived_ns);
            match pose {
                Err(NoPose { may_come: true, .. }) if waited < self.options.wait_ns => break,
                Err(NoPose { reason, .. }) => {
                    self.pending.pop_front();
                    out.push(Item::Skipped(reason));
                }
                Ok(pose) => {
                    if let Some(p) = self.pending.pop_front() {
                        out.push(Item::Scan(p.builder.finish(pose)));
                    }
                }
            }
        }
        out
    }

    /// Every waiting cloud, posed if it can be now or skipped (at the end of the input).
    pub fn flush(&mut self) -> Vec<Item> {
        self.ready(i64::MAX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::tests::tf as transform;
    use crate::ros::{ByteOrder, Header, TransformStamped};
    use rovlink_octo::Scan;

    const S: i64 = 1_000_000_000;

    fn tf(links: &[TransformStamped]) -> Vec<u8> {
        ros::encode_tf_message(links, ByteOrder::Little)
    }

    fn cloud(stamp_ns: i64, frame: &str) -> Vec<u8> {
        let scan = Scan {
            points: vec![[1.0, 2.0, 3.0]],
            colors: None,
            pose: Pose::IDENTITY,
        };
        let header = Header {
            stamp_ns,
            frame_id: frame.into(),
        };
        ros::encode_point_cloud2(&header, &scan, ByteOrder::Little)
    }

    fn scans(items: &[Item]) -> Vec<&Scan> {
        items
            .iter()
            .filter_map(|i| match i {
                Item::Scan(s) => Some(s),
                Item::Skipped(_) => None,
            })
            .collect()
    }

    #[test]
    fn a_cloud_waits_for_the_transform_at_its_stamp_then_is_posed_by_interpolation() {
        let mut p = LivePoser::new(LiveOptions::default());
        assert!(
            p.tf(&tf(&[transform(0, "map", "odom", 0.0, 0.0)]), true)
                .is_empty()
        );
        assert!(
            p.tf(&tf(&[transform(S, "odom", "base", 1.0, 0.0)]), false)
                .is_empty()
        );
        assert_eq!(p.cloud(&cloud(2 * S, "base"), 0).unwrap(), None);
        // Its stamp is after the last sample: it waits.
        assert!(p.ready(10).is_empty());
        assert_eq!(p.pending(), 1);
        p.tf(&tf(&[transform(3 * S, "odom", "base", 3.0, 0.0)]), false);
        let out = p.ready(20);
        let posed = scans(&out);
        assert_eq!(posed.len(), 1, "{out:?}");
        // Halfway between x = 1 and x = 3.
        assert_eq!(posed[0].pose.translation_m, [2.0, 0.0, 0.0]);
        assert_eq!(p.fixed_frame(), Some("map"));
    }

    #[test]
    fn a_cloud_whose_transform_does_not_come_is_skipped_after_the_wait_with_the_reason() {
        let mut p = LivePoser::new(LiveOptions {
            wait_ns: 100,
            ..LiveOptions::default()
        });
        p.tf(&tf(&[transform(S, "odom", "base", 1.0, 0.0)]), false);
        p.cloud(&cloud(2 * S, "base"), 0).unwrap();
        p.cloud(&cloud(2 * S, "base"), 1).unwrap();
        assert!(p.ready(50).is_empty());
        let out = p.ready(100);
        assert_eq!(out.len(), 1, "the second has not waited its time: {out:?}");
        match &out[0] {
            Item::Skipped(why) => assert!(why.contains("after the last sample"), "{why}"),
            other => panic!("{other:?}"),
        }
        // A cloud in a frame nobody publishes is skipped the same way, in order.
        p.cloud(&cloud(S, "camera"), 2).unwrap();
        let out = p.flush();
        assert_eq!(out.len(), 2, "{out:?}");
    }

    #[test]
    fn a_cycle_or_a_nan_arriving_live_is_refused_and_the_rest_goes_on() {
        let mut p = LivePoser::new(LiveOptions::default());
        p.tf(
            &tf(&[
                transform(0, "map", "odom", 0.0, 0.0),
                transform(0, "odom", "base", 0.0, 0.0),
            ]),
            true,
        );
        let problems = p.tf(&tf(&[transform(0, "base", "map", 0.0, 0.0)]), true);
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(problems[0].contains("cycle"), "{problems:?}");
        let mut nan = transform(S, "base", "sensor", 0.0, 0.0);
        nan.transform.translation_m[1] = f64::NAN;
        // A message with a number that is not finite is refused whole (its decoder names the
        // field); the next one is taken.
        let problems = p.tf(&tf(&[nan, transform(S, "base", "sonar", 0.0, 0.0)]), false);
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(
            p.tf(&tf(&[transform(S, "base", "sonar", 0.5, 0.0)]), true)
                .is_empty()
        );
        p.cloud(&cloud(S, "sonar"), 0).unwrap();
        let out = p.ready(0);
        assert_eq!(scans(&out)[0].pose.translation_m, [0.5, 0.0, 0.0]);
        // Bytes that are no TF message are one problem, nothing more.
        assert_eq!(p.tf(&[0, 1, 0, 0, 9], false).len(), 1);
        assert!(p.cloud(&[0, 1, 0, 0], 0).is_err());
    }

    #[test]
    fn memory_is_bounded_however_long_transforms_and_clouds_come() {
        let mut p = LivePoser::new(LiveOptions {
            max_pending: 4,
            ..LiveOptions::default()
        });
        p.tf(&tf(&[transform(0, "map", "odom", 0.0, 0.0)]), true);
        for k in 0..5_000 {
            p.tf(
                &tf(&[transform(k * S / 10, "odom", "base", 0.0, 0.0)]),
                false,
            );
        }
        let Some(Poses::Tf(tree)) = &p.poses else {
            panic!("a TF source")
        };
        // 10 s of samples at 10 per second, plus the static link.
        assert!(tree.sample_count() <= 103, "{}", tree.sample_count());
        // Clouds that cannot be posed yet are dropped past the bound, the oldest first.
        let mut dropped = 0;
        for k in 0..10 {
            if let Some(Item::Skipped(why)) = p.cloud(&cloud(10_000 * S + k, "base"), 0).unwrap() {
                assert!(why.contains("waiting"), "{why}");
                dropped += 1;
            }
        }
        assert_eq!((dropped, p.pending()), (6, 4));
    }

    #[test]
    fn a_pose_topic_poses_live_clouds_too() {
        let mut p = LivePoser::new(LiveOptions {
            source: LivePoseSource::Track {
                topic: "/pose".into(),
                schema: ros::POSE_STAMPED_SCHEMA.into(),
            },
            ..LiveOptions::default()
        });
        let pose = |ns, x| {
            let t = transform(ns, "map", "", x, 0.0);
            ros::encode_pose_stamped(&t.header, &t.transform, ByteOrder::Little)
        };
        assert_eq!(p.pose(&pose(0, 0.0)), None);
        p.cloud(&cloud(S / 2, "sensor"), 0).unwrap();
        assert!(p.ready(0).is_empty());
        assert_eq!(p.pose(&pose(S, 4.0)), None);
        assert_eq!(scans(&p.ready(0))[0].pose.translation_m, [2.0, 0.0, 0.0]);
        assert!(p.pose(&[1, 2, 3]).is_some());
    }
}
