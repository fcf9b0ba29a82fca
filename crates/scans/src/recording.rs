//! Robot logs as scans: the point clouds of a bag (MCAP, rosbag2), each posed where the robot
//! says its sensor was.
//!
//! A bag ([`bag::Bag`]) hands out CDR messages; this module picks the topics, gathers the poses
//! and turns every `sensor_msgs/msg/PointCloud2` into a [`Scan`] in the fixed frame:
//!
//! 1. **The cloud topic**: `--cloud-topic`, or the first topic of type `PointCloud2`.
//! 2. **The pose source**, in this order:
//!    - `--pose-topic TOPIC`: `geometry_msgs/msg/PoseStamped`, `TransformStamped` or
//!      `nav_msgs/msg/Odometry` messages, the cloud's pose interpolated at its
//!      `header.stamp` between the two nearest messages (by their own stamps); a topic of
//!      `tf2_msgs/msg/TFMessage` names a TF topic instead;
//!    - else the TF topics (`/tf` and `/tf_static`, or namespaced ones ending so): each cloud's
//!      `header.frame_id` is looked up in the fixed frame (`--fixed-frame`, default the root of
//!      the tree that holds the first cloud's frame) at the cloud's stamp, every dynamic link
//!      interpolated (translation linearly, rotation by slerp), static links at all times;
//!    - else the first `PoseStamped` topic, as a pose topic;
//!    - else none: an error, unless `--origin` says where the sensor was.
//! 3. **Two passes**: the poses first (they are small), then the clouds one at a time, so memory
//!    holds the poses, one decompressed chunk and one cloud, never the bag.
//!
//! A cloud whose pose cannot be had (its frame not connected to the fixed frame, its stamp
//! outside what the transforms cover) is skipped and counted; the build reports one warning per
//! reason, naming the frames. A bag whose clouds all lack a pose is an error. Never silently the
//! identity.
//!
//! Malformed TF (a cycle, a frame with two parents, NaN or non-unit quaternions) and every
//! undecodable message are errors naming the file and where ([`RecordingError`]); nothing here
//! panics on any input.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use crate::bag::{self, Bag, BagError, Location};
use crate::ros::{self, Header, Transform};
use crate::tf::{PoseTrack, TfTree, Unavailable};
use rovlink_octo::{ParseError, Pose, Scan};

/// Which topics and frames [`Recording`] reads.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RecordingOptions {
    /// The `PointCloud2` topic; `None`: the first one.
    pub cloud_topic: Option<String>,
    /// The pose topic (PoseStamped, TransformStamped, Odometry, or a TF topic); `None`: TF,
    /// else the first PoseStamped topic.
    pub pose_topic: Option<String>,
    /// The frame the map is built in; `None`: the root of the first cloud's TF tree.
    pub fixed_frame: Option<String>,
    /// Whether the caller gives the sensor origin itself (`--origin`): a bag without any pose
    /// source is then read with the identity pose (and the caller's origin).
    pub origin_given: bool,
}

/// Why a recording cannot be read: the file (one of a rosbag2 directory's files), where, what.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The container failed (bad bytes, I/O), a message does not decode, or the TF is
    /// malformed: the file and the place in it.
    #[error(transparent)]
    Bag(#[from] BagError),
    /// A choice the bag does not support (no cloud topic, no pose source, unknown frame).
    #[error("{file}: {message}")]
    Unusable {
        /// The bag (its path as given).
        file: String,
        /// What is missing, and what the bag has.
        message: String,
    },
}

/// One item of [`Recording::scans`]: a posed scan, or a cloud that had to be skipped and why.
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    /// A cloud, posed in the fixed frame.
    Scan(Scan),
    /// A cloud without a pose: the reason names the frames (the same reason for the same cause,
    /// so callers count them).
    Skipped(String),
}

/// A bag opened for reading scans: the topics chosen and the poses gathered.
pub struct Recording {
    bag: Bag,
    name: String,
    cloud_topic: usize,
    poses: Option<Poses>,
    fixed_frame: Option<String>,
    /// What a user should know (pose source used, colour fields not understood).
    pub notes: Vec<String>,
}

const TF_TYPE: &str = ros::TF_MESSAGE_SCHEMA;
pub(crate) const POSE_TYPES: [&str; 3] = [
    ros::POSE_STAMPED_SCHEMA,
    ros::TRANSFORM_STAMPED_SCHEMA,
    ros::ODOMETRY_SCHEMA,
];

/// Whether `schema` is a type a pose topic may have (PoseStamped, TransformStamped, Odometry).
pub fn is_pose_type(schema: &str) -> bool {
    POSE_TYPES.contains(&schema)
}

/// The pose topic types, as messages list them.
pub fn pose_type_names() -> String {
    format!("{}, {} or {}", POSE_TYPES[0], POSE_TYPES[1], POSE_TYPES[2])
}

pub(crate) fn is_tf_topic(name: &str) -> Option<bool> {
    // Some(true): static.
    if name == "/tf_static" || name.ends_with("/tf_static") {
        Some(true)
    } else if name == "/tf" || name.ends_with("/tf") {
        Some(false)
    } else {
        None
    }
}

impl Recording {
    /// Opens the bag at `path` (an MCAP file, a rosbag2 directory, its `metadata.yaml` or one
    /// `.db3`), picks the topics and reads every pose (the first pass).
    pub fn open(
        path: &Path,
        options: &RecordingOptions,
        stop: &AtomicBool,
    ) -> Result<Recording, RecordingError> {
        let bag = Bag::open_until(path, stop)?;
        Self::with_bag(bag, path.display().to_string(), options, stop)
    }

    /// The same for an MCAP file in memory (standard input), named `name` in errors.
    pub fn from_mcap_bytes(
        name: &str,
        bytes: Vec<u8>,
        options: &RecordingOptions,
        stop: &AtomicBool,
    ) -> Result<Recording, RecordingError> {
        let bag = Bag::from_mcap_bytes_until(name, bytes, stop)?;
        Self::with_bag(bag, name.to_string(), options, stop)
    }

    fn unusable(&self, message: String) -> RecordingError {
        RecordingError::Unusable {
            file: self.name.clone(),
            message,
        }
    }

    /// The topics, for messages: `"/points" (sensor_msgs/msg/PointCloud2), ...`.
    fn topic_list(&self) -> String {
        bag::listing(self.bag.topics(), "topics")
    }

    fn find_topic(&self, name: &str, role: &str) -> Result<usize, RecordingError> {
        self.bag
            .topics()
            .iter()
            .position(|t| t.name == name)
            .ok_or_else(|| {
                self.unusable(format!(
                    "{role} topic {name:?}: expected a topic of the bag, found {}",
                    self.topic_list()
                ))
            })
    }

    fn check_cdr(&self, index: usize, role: &str) -> Result<(), RecordingError> {
        let t = &self.bag.topics()[index];
        if t.encoding != "cdr" {
            return Err(self.unusable(format!(
                "{role} topic {:?}: expected message encoding cdr, found {:?}",
                t.name, t.encoding
            )));
        }
        Ok(())
    }

    fn with_bag(
        bag: Bag,
        name: String,
        options: &RecordingOptions,
        stop: &AtomicBool,
    ) -> Result<Recording, RecordingError> {
        let mut rec = Recording {
            bag,
            name,
            cloud_topic: 0,
            poses: None,
            fixed_frame: options.fixed_frame.clone(),
            notes: Vec::new(),
        };
        rec.cloud_topic = match &options.cloud_topic {
            Some(t) => rec.find_topic(t, "cloud")?,
            None => rec
                .bag
                .topics()
                .iter()
                .position(|t| t.schema == ros::POINT_CLOUD2_SCHEMA)
                .ok_or_else(|| {
                    rec.unusable(format!(
                        "expected a topic of type {}, found {}",
                        ros::POINT_CLOUD2_SCHEMA,
                        rec.topic_list()
                    ))
                })?,
        };
        let cloud = &rec.bag.topics()[rec.cloud_topic];
        if cloud.schema != ros::POINT_CLOUD2_SCHEMA {
            return Err(rec.unusable(format!(
                "cloud topic {:?}: expected type {}, found {}",
                cloud.name,
                ros::POINT_CLOUD2_SCHEMA,
                cloud.schema
            )));
        }
        rec.check_cdr(rec.cloud_topic, "cloud")?;

        let topics = rec.bag.topics();
        let tf_topics: Vec<(usize, bool)> = topics
            .iter()
            .enumerate()
            .filter(|(_, t)| t.schema == TF_TYPE)
            .filter_map(|(i, t)| is_tf_topic(&t.name).map(|s| (i, s)))
            .collect();
        let source = match &options.pose_topic {
            Some(t) => {
                let i = rec.find_topic(t, "pose")?;
                let schema = rec.bag.topics()[i].schema.clone();
                if schema == TF_TYPE {
                    // A named TF topic, with the static transforms beside it.
                    let mut topics = vec![(i, is_tf_topic(t) == Some(true))];
                    topics.extend(tf_topics.iter().filter(|&&(j, s)| s && j != i));
                    Some(Source::Tf(topics))
                } else if POSE_TYPES.contains(&schema.as_str()) {
                    Some(Source::Track(i))
                } else {
                    return Err(rec.unusable(format!(
                        "pose topic {t:?}: expected type {}, {}, {} or {TF_TYPE}, found {schema}",
                        POSE_TYPES[0], POSE_TYPES[1], POSE_TYPES[2]
                    )));
                }
            }
            None if !tf_topics.is_empty() => Some(Source::Tf(tf_topics)),
            None => topics
                .iter()
                .position(|t| t.schema == ros::POSE_STAMPED_SCHEMA)
                .map(Source::Track),
        };
        match source {
            None if options.origin_given => rec.notes.push(format!(
                "no pose source (no /tf, /tf_static or {} topic): every scan at --origin",
                ros::POSE_STAMPED_SCHEMA
            )),
            None => {
                return Err(rec.unusable(format!(
                    "no pose for the clouds: expected /tf and /tf_static, or a pose topic \
                     (--pose-topic: {}, {} or {}), found {}; give --origin X,Y,Z to build \
                     with the sensor there",
                    POSE_TYPES[0],
                    POSE_TYPES[1],
                    POSE_TYPES[2],
                    rec.topic_list()
                )));
            }
            Some(source) => {
                rec.poses = Some(rec.read_poses(&source, stop)?);
            }
        }
        Ok(rec)
    }

    /// The first pass: every pose message of the source.
    fn read_poses(&mut self, source: &Source, stop: &AtomicBool) -> Result<Poses, RecordingError> {
        match source {
            Source::Tf(topics) => {
                for &(i, _) in topics {
                    self.check_cdr(i, "TF")?;
                }
                let indices: Vec<usize> = topics.iter().map(|t| t.0).collect();
                let mut tree = TfTree::new();
                let mut last = Location::file(&self.name);
                for m in self.bag.messages(&indices, stop)? {
                    let m = m?;
                    let is_static = topics.iter().any(|&(i, s)| i == m.topic && s);
                    let transforms = ros::decode_tf_message(&m.data, 0).map_err(|e| m.error(e))?;
                    for t in &transforms {
                        tree.add(t, is_static)
                            .map_err(|e| BagError::new(m.at.clone(), e.to_string()))?;
                    }
                    last = m.at;
                }
                tree.finish()
                    .map_err(|e| BagError::new(Location::file(&last.file), e.to_string()))?;
                let names: Vec<&str> = topics
                    .iter()
                    .map(|&(i, _)| self.bag.topics()[i].name.as_str())
                    .collect();
                if let Some(fixed) = &self.fixed_frame
                    && !tree.frames().any(|f| f == fixed)
                {
                    let mut frames: Vec<&str> = tree.frames().collect();
                    frames.sort_unstable();
                    frames.truncate(12);
                    return Err(self.unusable(format!(
                        "--fixed-frame {fixed:?}: expected a frame of the TF tree ({}), found \
                         frames {}",
                        names.join(", "),
                        if frames.is_empty() {
                            "none".to_string()
                        } else {
                            frames.join(", ")
                        }
                    )));
                }
                self.notes
                    .push(format!("poses from TF ({})", names.join(", ")));
                Ok(Poses::Tf(tree))
            }
            Source::Track(i) => {
                let i = *i;
                self.check_cdr(i, "pose")?;
                let topic = self.bag.topics()[i].clone();
                let mut track = PoseTrack::new();
                for m in self.bag.messages(&[i], stop)? {
                    let m = m?;
                    let (header, t) =
                        decode_pose_message(&topic.schema, &m.data).map_err(|e| m.error(e))?;
                    track
                        .add(&header, &t)
                        .map_err(|e| BagError::new(m.at.clone(), e.to_string()))?;
                }
                track.finish();
                self.notes
                    .push(format!("poses from {} ({})", topic.name, topic.schema));
                Ok(Poses::Track(track, topic.name))
            }
        }
    }

    /// Whether the clouds are posed by the bag (TF or a pose topic); `false`: the caller's
    /// `--origin` (only possible when [`RecordingOptions::origin_given`]).
    pub fn has_poses(&self) -> bool {
        self.poses.is_some()
    }

    /// The name of the cloud topic read.
    pub fn cloud_topic(&self) -> &str {
        self.bag
            .topics()
            .get(self.cloud_topic)
            .map_or("", |t| t.name.as_str())
    }

    /// How many clouds the bag says it holds, when it says.
    pub fn cloud_count(&self) -> Option<u64> {
        self.bag.topics()[self.cloud_topic].messages
    }

    /// The second pass: every cloud, posed (or skipped, with the reason), in log-time order.
    /// Ends early (without an error) once `stop` is set.
    pub fn scans<'a>(
        &'a mut self,
        stop: &'a AtomicBool,
    ) -> Result<impl Iterator<Item = Result<Item, RecordingError>> + 'a, RecordingError> {
        let cloud = self.cloud_topic;
        let poses = &self.poses;
        let fixed = &mut self.fixed_frame;
        let notes = &mut self.notes;
        let messages = self.bag.messages(&[cloud], stop)?;
        Ok(messages.map(move |m| {
            let m = m?;
            let (header, builder, note) =
                ros::decode_point_cloud2(&m.data, 0).map_err(|e| m.error(e))?;
            if let Some(note) = note
                && !notes.contains(&note)
            {
                notes.push(note);
            }
            let pose = match poses {
                None => Pose::IDENTITY,
                Some(poses) => match pose_of(poses, fixed, &header.frame_id, header.stamp_ns) {
                    Ok(p) => p,
                    Err(reason) => return Ok(Item::Skipped(reason)),
                },
            };
            Ok(Item::Scan(builder.finish(pose)))
        }))
    }
}

/// Where the pose comes from, before it is read.
enum Source {
    /// TF topics, with whether each is static.
    Tf(Vec<(usize, bool)>),
    /// One pose topic.
    Track(usize),
}

/// The poses read in the first pass (or gathered live).
pub(crate) enum Poses {
    /// The TF buffer.
    Tf(TfTree),
    /// A pose topic's track, and the topic.
    Track(PoseTrack, String),
}

/// The header and transform of a PoseStamped, TransformStamped or Odometry message.
pub(crate) fn decode_pose_message(
    schema: &str,
    data: &[u8],
) -> Result<(Header, Transform), ParseError> {
    match schema {
        ros::POSE_STAMPED_SCHEMA => ros::decode_pose_stamped(data, 0),
        ros::TRANSFORM_STAMPED_SCHEMA => {
            ros::decode_transform_stamped(data, 0).map(|t| (t.header, t.transform))
        }
        _ => ros::decode_odometry(data, 0).map(|t| (t.header, t.transform)),
    }
}

/// Why a cloud was skipped, the same text for the same cause whatever the stamp.
fn reason(frame: &str, fixed: &str, why: &Unavailable) -> String {
    let why = match why {
        Unavailable::Before { link, .. } => format!("stamped before the first sample of {link}"),
        Unavailable::After { link, .. } => format!("stamped after the last sample of {link}"),
        other => other.to_string(),
    };
    format!("no pose for cloud frame {frame:?} in {fixed}: {why}")
}

/// Why a cloud has no pose (yet).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NoPose {
    /// The same text for the same cause whatever the stamp.
    pub reason: String,
    /// Whether transforms still to come could pose it (a stamp after the last sample, a frame
    /// not yet in the tree or not yet connected): a live reader waits for them.
    pub may_come: bool,
}

/// The pose of a cloud in `frame` at `stamp_ns`, or why there is none.
fn pose_of(
    poses: &Poses,
    fixed: &mut Option<String>,
    frame: &str,
    stamp_ns: i64,
) -> Result<Pose, String> {
    pose_at(poses, fixed, frame, stamp_ns, false).map_err(|w| w.reason)
}

/// [`pose_of`], saying whether the pose may still come. The default fixed frame (the root of
/// the first cloud's tree) is kept at once, or with `settle` only once a cloud is posed in it
/// (live, the tree may still be growing above the cloud's frame).
pub(crate) fn pose_at(
    poses: &Poses,
    fixed: &mut Option<String>,
    frame: &str,
    stamp_ns: i64,
    settle: bool,
) -> Result<Pose, NoPose> {
    let may_come = |why: &Unavailable| {
        matches!(
            why,
            Unavailable::After { .. }
                | Unavailable::UnknownFrame { .. }
                | Unavailable::NotConnected { .. }
                | Unavailable::NoSamples { .. }
        )
    };
    let no = |to: &str, why: &Unavailable| NoPose {
        reason: reason(frame, to, why),
        may_come: may_come(why),
    };
    let (t, to) = match poses {
        Poses::Track(track, topic) => {
            let to = format!("pose topic {topic}");
            let t = track.lookup_named(stamp_ns, || to.clone());
            (t.map_err(|e| no(&to, &e))?, to)
        }
        Poses::Tf(tree) => {
            // The default fixed frame: the root of the first posable cloud's tree.
            let chosen: String = match fixed {
                Some(f) => f.clone(),
                None => tree
                    .default_fixed_frame(frame)
                    .map_err(|e| no("the TF tree", &e))?
                    .to_string(),
            };
            if !settle && fixed.is_none() {
                *fixed = Some(chosen.clone());
            }
            let to = format!("fixed frame {chosen:?}");
            let t = tree.lookup(&chosen, frame, stamp_ns);
            let t = t.map_err(|e| no(&to, &e))?;
            if fixed.is_none() {
                *fixed = Some(chosen);
            }
            (t, to)
        }
    };
    t.to_pose().ok_or_else(|| NoPose {
        reason: format!("no pose for cloud frame {frame:?} in {to}: not finite as f32"),
        may_come: false,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use std::collections::BTreeMap;
    use std::io::Cursor;

    use super::*;
    use crate::ros::{ByteOrder, TransformStamped};

    const S: i64 = 1_000_000_000;

    /// A transform from `parent` to `child` at `stamp_ns`: `x` m along x, `yaw_rad` about z.
    pub(crate) fn tf(
        stamp_ns: i64,
        parent: &str,
        child: &str,
        x: f64,
        yaw_rad: f64,
    ) -> TransformStamped {
        TransformStamped {
            header: Header {
                stamp_ns,
                frame_id: parent.into(),
            },
            child_frame_id: child.into(),
            transform: Transform {
                translation_m: [x, 0.0, 0.0],
                rotation: [(yaw_rad / 2.0).cos(), 0.0, 0.0, (yaw_rad / 2.0).sin()],
            },
        }
    }

    /// An MCAP of `(topic, schema, log time, payload)` messages.
    fn mcap(messages: &[(&str, &str, i64, Vec<u8>)]) -> Vec<u8> {
        let mut w = ::mcap::WriteOptions::new()
            .compression(None)
            .create(Cursor::new(Vec::new()))
            .unwrap();
        let mut channels = BTreeMap::new();
        for (topic, schema, t, data) in messages {
            let id = match channels.get(topic) {
                Some(&id) => id,
                None => {
                    let s = w.add_schema(schema, "ros2msg", b"").unwrap();
                    let id = w.add_channel(s, topic, "cdr", &BTreeMap::new()).unwrap();
                    channels.insert(*topic, id);
                    id
                }
            };
            let header = ::mcap::records::MessageHeader {
                channel_id: id,
                sequence: 0,
                log_time: *t as u64,
                publish_time: *t as u64,
            };
            w.write_to_known_channel(&header, data).unwrap();
        }
        w.finish().unwrap();
        w.into_inner().into_inner()
    }

    fn cloud(stamp_ns: i64, frame: &str) -> Vec<u8> {
        let scan = Scan {
            points: vec![[1.0, 0.0, 0.0]],
            ..Scan::default()
        };
        let header = Header {
            stamp_ns,
            frame_id: frame.into(),
        };
        ros::encode_point_cloud2(&header, &scan, ByteOrder::Little)
    }

    fn tf_msg(transforms: &[TransformStamped]) -> Vec<u8> {
        ros::encode_tf_message(transforms, ByteOrder::Little)
    }

    fn read(bytes: Vec<u8>, options: &RecordingOptions) -> Result<Vec<Item>, RecordingError> {
        let stop = AtomicBool::new(false);
        let mut rec = Recording::from_mcap_bytes("t.mcap", bytes, options, &stop)?;
        let items = rec.scans(&stop)?.collect::<Result<Vec<_>, _>>()?;
        Ok(items)
    }

    fn pose(item: &Item) -> Pose {
        match item {
            Item::Scan(s) => s.pose,
            Item::Skipped(r) => panic!("skipped: {r}"),
        }
    }

    #[test]
    fn a_cloud_between_two_transforms_is_posed_between_them_through_the_chain() {
        let quarter = std::f64::consts::FRAC_PI_2;
        let bytes = mcap(&[
            (
                "/tf_static",
                TF_TYPE,
                0,
                tf_msg(&[tf(0, "base", "lidar", 0.5, 0.0)]),
            ),
            ("/tf", TF_TYPE, 0, tf_msg(&[tf(0, "map", "base", 0.0, 0.0)])),
            (
                "/tf",
                TF_TYPE,
                2 * S,
                tf_msg(&[tf(2 * S, "map", "base", 2.0, quarter)]),
            ),
            ("/points", ros::POINT_CLOUD2_SCHEMA, S, cloud(S, "lidar")),
            (
                "/points",
                ros::POINT_CLOUD2_SCHEMA,
                2 * S,
                cloud(2 * S, "lidar"),
            ),
            (
                "/points",
                ros::POINT_CLOUD2_SCHEMA,
                3 * S,
                cloud(3 * S, "lidar"),
            ),
        ]);
        let items = read(bytes, &RecordingOptions::default()).unwrap();
        assert_eq!(items.len(), 3);
        // Halfway: base at x = 1 turned 45 degrees; the lidar 0.5 m ahead of it.
        let p = pose(&items[0]);
        let h = std::f64::consts::FRAC_1_SQRT_2 * 0.5;
        let expect = [1.0 + h, h, 0.0];
        for (got, want) in p.translation_m.iter().zip(expect) {
            assert!((f64::from(*got) - want).abs() < 1e-6, "{p:?}");
        }
        let yaw = 2.0 * f64::from(p.rotation[3]).atan2(f64::from(p.rotation[0]));
        assert!((yaw - quarter / 2.0).abs() < 1e-6, "{p:?}");
        // At the last sample: exactly it (x = 2 + lidar offset turned 90 degrees).
        let p = pose(&items[1]);
        assert!((p.translation_m[0] - 2.0).abs() < 1e-6 && (p.translation_m[1] - 0.5).abs() < 1e-6);
        // After it: skipped, naming the frames.
        match &items[2] {
            Item::Skipped(r) => assert!(
                r.contains("\"lidar\"") && r.contains("\"map\"") && r.contains("after"),
                "{r}"
            ),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_named_fixed_frame_is_used_and_an_unknown_one_refused() {
        let bytes = || {
            mcap(&[
                (
                    "/tf_static",
                    TF_TYPE,
                    0,
                    tf_msg(&[
                        tf(0, "map", "odom", 10.0, 0.0),
                        tf(0, "odom", "lidar", 1.0, 0.0),
                    ]),
                ),
                ("/points", ros::POINT_CLOUD2_SCHEMA, S, cloud(S, "lidar")),
            ])
        };
        let odom = RecordingOptions {
            fixed_frame: Some("odom".into()),
            ..RecordingOptions::default()
        };
        assert_eq!(
            pose(&read(bytes(), &odom).unwrap()[0]).translation_m,
            [1.0, 0.0, 0.0]
        );
        assert_eq!(
            pose(&read(bytes(), &RecordingOptions::default()).unwrap()[0]).translation_m,
            [11.0, 0.0, 0.0]
        );
        let nowhere = RecordingOptions {
            fixed_frame: Some("nowhere".into()),
            ..RecordingOptions::default()
        };
        let e = read(bytes(), &nowhere).err().unwrap().to_string();
        assert!(e.starts_with("t.mcap: --fixed-frame \"nowhere\""), "{e}");
    }

    #[test]
    fn no_pose_source_is_an_error_unless_the_origin_is_given() {
        let bytes = || mcap(&[("/points", ros::POINT_CLOUD2_SCHEMA, S, cloud(S, "lidar"))]);
        let e = read(bytes(), &RecordingOptions::default()).err().unwrap();
        assert!(e.to_string().contains("--origin"), "{e}");
        let given = RecordingOptions {
            origin_given: true,
            ..RecordingOptions::default()
        };
        assert_eq!(pose(&read(bytes(), &given).unwrap()[0]), Pose::IDENTITY);
    }

    #[test]
    fn a_bad_message_names_the_file_and_its_offset() {
        let mut bad = tf_msg(&[tf(0, "map", "lidar", 0.0, 0.0)]);
        bad.truncate(bad.len() - 3);
        let bytes = mcap(&[
            ("/tf", TF_TYPE, 0, bad),
            ("/points", ros::POINT_CLOUD2_SCHEMA, S, cloud(S, "lidar")),
        ]);
        let e = read(bytes, &RecordingOptions::default())
            .err()
            .unwrap()
            .to_string();
        assert!(e.starts_with("t.mcap: offset "), "{e}");
        assert!(e.contains("TFMessage"), "{e}");
    }
}
