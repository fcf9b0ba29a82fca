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
//!    holds the poses, one decompressed chunk and one cloud, never the bag. Or, with
//!    [`RecordingOptions::one_pass`], **one pass** ([`one_pass`]): clouds and poses read
//!    together, each cloud handed out once the transforms read so far settle its pose, and
//!    everything handed out checked at the end against what two passes give
//!    ([`RecordingError::OnePass`] when it differs: the caller reads the bag again in two).
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

pub mod one_pass;
use one_pass::{OnePass, PoseTopics};

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
    /// Read clouds and poses in one pass ([`one_pass`]); only for a caller that can start
    /// again in two passes on [`RecordingError::OnePass`] (nothing it made is kept yet).
    pub one_pass: bool,
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
    /// One pass ([`RecordingOptions::one_pass`]) could not pose the clouds as two passes do:
    /// read the bag again in two.
    #[error("{file}: one pass over the bag cannot pose its clouds: {why}")]
    OnePass {
        /// The bag (its path as given).
        file: String,
        /// Which cloud, and what changed its pose (or how many clouds waited).
        why: String,
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
    /// One pass: the pose topics still to read, beside the clouds.
    one_pass: Option<PoseTopics>,
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
            one_pass: None,
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
            Some(source) if options.one_pass => rec.defer_poses(source)?,
            Some(source) => {
                rec.poses = Some(rec.read_poses(&source, stop)?);
            }
        }
        Ok(rec)
    }

    /// One pass: the pose topics checked, their poses left to be read beside the clouds.
    fn defer_poses(&mut self, source: Source) -> Result<(), RecordingError> {
        let (poses, topics) = match source {
            Source::Tf(topics) => {
                for &(i, _) in &topics {
                    self.check_cdr(i, "TF")?;
                }
                let names = self.tf_names(&topics);
                self.notes.push(format!("poses from TF ({names})"));
                (Poses::Tf(TfTree::new()), PoseTopics::Tf(topics, names))
            }
            Source::Track(i) => {
                self.check_cdr(i, "pose")?;
                let topic = self.bag.topics()[i].clone();
                self.notes
                    .push(format!("poses from {} ({})", topic.name, topic.schema));
                (
                    Poses::Track(PoseTrack::new(), topic.name),
                    PoseTopics::Track(i, topic.schema),
                )
            }
        };
        self.poses = Some(poses);
        self.one_pass = Some(topics);
        Ok(())
    }

    /// The TF topics' names, for messages.
    fn tf_names(&self, topics: &[(usize, bool)]) -> String {
        let names: Vec<&str> = topics
            .iter()
            .map(|&(i, _)| self.bag.topics()[i].name.as_str())
            .collect();
        names.join(", ")
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
                    add_tf_message(&mut tree, topics, &m)?;
                    last = m.at;
                }
                tree.finish()
                    .map_err(|e| BagError::new(Location::file(&last.file), e.to_string()))?;
                let names = self.tf_names(topics);
                if let Some(fixed) = &self.fixed_frame
                    && !tree.frames().any(|f| f == fixed)
                {
                    return Err(self.unusable(unknown_fixed_frame(fixed, &tree, &names)));
                }
                self.notes.push(format!("poses from TF ({names})"));
                Ok(Poses::Tf(tree))
            }
            Source::Track(i) => {
                let i = *i;
                self.check_cdr(i, "pose")?;
                let topic = self.bag.topics()[i].clone();
                let mut track = PoseTrack::new();
                for m in self.bag.messages(&[i], stop)? {
                    add_pose_message(&mut track, &topic.schema, &m?)?;
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

    /// The second pass (or the one pass): every cloud, posed (or skipped, with the reason), in
    /// log-time order. Ends early (without an error) once `stop` is set.
    pub fn scans<'a>(
        &'a mut self,
        stop: &'a AtomicBool,
    ) -> Result<Box<dyn Iterator<Item = Result<Item, RecordingError>> + 'a>, RecordingError> {
        let Recording {
            bag,
            name,
            cloud_topic,
            poses,
            one_pass,
            fixed_frame: fixed,
            notes,
        } = self;
        let cloud = *cloud_topic;
        let poses: &Option<Poses> = match (one_pass.as_ref(), poses) {
            (Some(topics), Some(poses)) => {
                let mut read = topics.indices();
                read.push(cloud);
                return Ok(Box::new(OnePass {
                    messages: bag.messages(&read, stop)?,
                    cloud,
                    topics,
                    poses,
                    fixed_given: fixed.clone(),
                    fixed,
                    notes,
                    name,
                    stop,
                    state: Default::default(),
                }));
            }
            (_, poses) => poses,
        };
        let messages = bag.messages(&[cloud], stop)?;
        Ok(Box::new(messages.map(move |m| {
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
        })))
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

/// Adds the transforms of TF message `m` to `tree`, static if its topic is among `topics`
/// (topic, static); an error names the message's place.
fn add_tf_message(
    tree: &mut TfTree,
    topics: &[(usize, bool)],
    m: &bag::Message,
) -> Result<(), BagError> {
    let is_static = topics.iter().any(|&(i, s)| i == m.topic && s);
    let transforms = ros::decode_tf_message(&m.data, 0).map_err(|e| m.error(e))?;
    for t in &transforms {
        tree.add(t, is_static)
            .map_err(|e| BagError::new(m.at.clone(), e.to_string()))?;
    }
    Ok(())
}

/// Adds the pose of message `m` (of type `schema`) to `track`; an error names its place.
fn add_pose_message(track: &mut PoseTrack, schema: &str, m: &bag::Message) -> Result<(), BagError> {
    let (header, t) = decode_pose_message(schema, &m.data).map_err(|e| m.error(e))?;
    track
        .add(&header, &t)
        .map_err(|e| BagError::new(m.at.clone(), e.to_string()))
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

/// The message for a `--fixed-frame` the TF tree (of the topics `names`) lacks.
fn unknown_fixed_frame(fixed: &str, tree: &TfTree, names: &str) -> String {
    let mut frames: Vec<&str> = tree.frames().collect();
    frames.sort_unstable();
    frames.truncate(12);
    format!(
        "--fixed-frame {fixed:?}: expected a frame of the TF tree ({names}), found frames {}",
        if frames.is_empty() {
            "none".to_string()
        } else {
            frames.join(", ")
        }
    )
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

    /// The items of `bytes` read with `options` as they are (one or two passes), and the notes.
    fn read_as(
        bytes: Vec<u8>,
        options: &RecordingOptions,
    ) -> Result<(Vec<Item>, Vec<String>), RecordingError> {
        let stop = AtomicBool::new(false);
        let mut rec = Recording::from_mcap_bytes("t.mcap", bytes, options, &stop)?;
        let items = rec.scans(&stop)?.collect::<Result<Vec<_>, _>>()?;
        Ok((items, rec.notes))
    }

    /// Two passes and one pass over `bytes`: the same items (or the same error) and notes, or
    /// one pass refusing with [`RecordingError::OnePass`]; the two passes' items.
    fn read_both(
        bytes: Vec<u8>,
        options: &RecordingOptions,
    ) -> (Result<Vec<Item>, RecordingError>, Option<RecordingError>) {
        let two = read_as(bytes.clone(), options);
        let one_pass = RecordingOptions {
            one_pass: true,
            ..options.clone()
        };
        let one = read_as(bytes, &one_pass);
        let refused = match (&two, one) {
            (_, Err(e @ RecordingError::OnePass { .. })) => Some(e),
            (Ok(two), Ok(one)) => {
                assert_eq!(two, &one, "one pass against two");
                None
            }
            (Err(two), Err(one)) => {
                assert_eq!(two.to_string(), one.to_string(), "one pass against two");
                None
            }
            (two, one) => panic!("two passes {two:?}, one pass {one:?}"),
        };
        (two.map(|t| t.0), refused)
    }

    /// [`read_both`], one pass not refusing: the items.
    fn read(bytes: Vec<u8>, options: &RecordingOptions) -> Result<Vec<Item>, RecordingError> {
        let (two, refused) = read_both(bytes, options);
        assert!(refused.is_none(), "one pass refused: {refused:?}");
        two
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

    fn refusal(bytes: Vec<u8>, options: &RecordingOptions) -> (Vec<Item>, String) {
        let (two, refused) = read_both(bytes, options);
        let why = refused.expect("one pass should refuse").to_string();
        assert!(
            why.starts_with("t.mcap: one pass over the bag cannot pose"),
            "{why}"
        );
        (two.unwrap(), why)
    }

    #[test]
    fn one_pass_refuses_a_sample_read_after_a_cloud_it_poses() {
        // map -> lidar at 0 and 2 s, a cloud at 1 s (halfway), then a sample at 1 s itself:
        // two passes pose the cloud at it, one pass had interpolated.
        let bytes = mcap(&[
            (
                "/tf",
                TF_TYPE,
                0,
                tf_msg(&[tf(0, "map", "lidar", 0.0, 0.0)]),
            ),
            (
                "/tf",
                TF_TYPE,
                1,
                tf_msg(&[tf(2 * S, "map", "lidar", 2.0, 0.0)]),
            ),
            ("/points", ros::POINT_CLOUD2_SCHEMA, 2, cloud(S, "lidar")),
            (
                "/points",
                ros::POINT_CLOUD2_SCHEMA,
                3,
                cloud(2 * S, "lidar"),
            ),
            (
                "/tf",
                TF_TYPE,
                4,
                tf_msg(&[tf(S, "map", "lidar", 5.0, 0.0)]),
            ),
        ]);
        let (two, why) = refusal(bytes, &RecordingOptions::default());
        assert_eq!(pose(&two[0]).translation_m, [5.0, 0.0, 0.0]);
        assert!(
            why.contains("stamped 1000000000 ns in frame \"lidar\""),
            "{why}"
        );
        assert!(
            why.contains("at [1.0, 0.0, 0.0]") && why.contains("at [5.0, 0.0, 0.0]"),
            "{why}"
        );
    }

    #[test]
    fn one_pass_refuses_a_parent_frame_that_comes_after_the_first_cloud() {
        // Two passes build in "map", the root of the whole tree; one pass had chosen "odom".
        let mut messages = vec![
            (
                "/tf_static",
                TF_TYPE,
                0,
                tf_msg(&[tf(0, "odom", "lidar", 1.0, 0.0)]),
            ),
            ("/points", ros::POINT_CLOUD2_SCHEMA, 1, cloud(S, "lidar")),
            (
                "/tf_static",
                TF_TYPE,
                2,
                tf_msg(&[tf(0, "map", "odom", 10.0, 0.0)]),
            ),
        ];
        let bytes = mcap(&messages);
        messages.push(("/points", ros::POINT_CLOUD2_SCHEMA, 3, cloud(S, "lidar")));
        let (two, _) = refusal(mcap(&messages), &RecordingOptions::default());
        assert_eq!(pose(&two[0]).translation_m, [11.0, 0.0, 0.0]);
        // With the fixed frame named, one pass poses the cloud as two passes do.
        let odom = RecordingOptions {
            fixed_frame: Some("odom".into()),
            ..RecordingOptions::default()
        };
        assert_eq!(
            pose(&read(bytes, &odom).unwrap()[0]).translation_m,
            [1.0, 0.0, 0.0]
        );
    }

    #[test]
    fn one_pass_holds_clouds_until_their_transforms_and_refuses_too_many_waiting() {
        // Every cloud logged before the transform after its stamp: each waits for the next
        // message, and all come out posed, in order.
        let mut messages = vec![(
            "/tf",
            TF_TYPE,
            0,
            tf_msg(&[tf(0, "map", "lidar", 0.0, 0.0)]),
        )];
        for k in 1..=40i64 {
            messages.push((
                "/points",
                ros::POINT_CLOUD2_SCHEMA,
                2 * k,
                cloud(k * S, "lidar"),
            ));
            let x = k as f64;
            let sample = tf_msg(&[tf(k * S, "map", "lidar", x, 0.0)]);
            messages.push(("/tf", TF_TYPE, 2 * k + 1, sample));
        }
        let items = read(mcap(&messages), &RecordingOptions::default()).unwrap();
        let xs: Vec<f32> = items.iter().map(|i| pose(i).translation_m[0]).collect();
        assert_eq!(xs, (1..=40).map(|k| k as f32).collect::<Vec<_>>());
        // The transforms all at the end: more clouds wait than one pass holds.
        let (clouds, transforms): (Vec<_>, Vec<_>) =
            messages.into_iter().partition(|m| m.0 == "/points");
        let messages: Vec<_> = clouds.into_iter().chain(transforms).collect();
        let (two, why) = refusal(mcap(&messages), &RecordingOptions::default());
        assert_eq!(two.len(), 40);
        assert!(why.contains("33 clouds"), "{why}");
        // A few clouds waiting for a fixed frame that never comes: the two passes' error.
        let bytes = mcap(&[
            ("/points", ros::POINT_CLOUD2_SCHEMA, 0, cloud(S, "lidar")),
            (
                "/tf_static",
                TF_TYPE,
                1,
                tf_msg(&[tf(0, "odom", "lidar", 1.0, 0.0)]),
            ),
        ]);
        let nowhere = RecordingOptions {
            fixed_frame: Some("nowhere".into()),
            ..RecordingOptions::default()
        };
        let e = read(bytes, &nowhere).unwrap_err().to_string();
        assert!(e.starts_with("t.mcap: --fixed-frame \"nowhere\""), "{e}");
    }

    #[test]
    fn one_pass_over_a_pose_topic_is_two_passes() {
        let pose_msg = |t: i64, x: f64| {
            let h = Header {
                stamp_ns: t,
                frame_id: "map".into(),
            };
            let p = Transform {
                translation_m: [x, 0.0, 0.0],
                rotation: [1.0, 0.0, 0.0, 0.0],
            };
            ros::encode_pose_stamped(&h, &p, ByteOrder::Little)
        };
        let bytes = mcap(&[
            ("/pose", ros::POSE_STAMPED_SCHEMA, 0, pose_msg(0, 0.0)),
            ("/points", ros::POINT_CLOUD2_SCHEMA, 1, cloud(S, "lidar")),
            ("/pose", ros::POSE_STAMPED_SCHEMA, 2, pose_msg(2 * S, 4.0)),
            (
                "/points",
                ros::POINT_CLOUD2_SCHEMA,
                3,
                cloud(3 * S, "lidar"),
            ),
            ("/points", ros::POINT_CLOUD2_SCHEMA, 4, cloud(-S, "lidar")),
        ]);
        let items = read(bytes, &RecordingOptions::default()).unwrap();
        assert_eq!(pose(&items[0]).translation_m, [2.0, 0.0, 0.0]);
        assert!(
            matches!(&items[1], Item::Skipped(r) if r.contains("after")),
            "{items:?}"
        );
        assert!(
            matches!(&items[2], Item::Skipped(r) if r.contains("before")),
            "{items:?}"
        );
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

        /// Transforms and clouds in any order: one pass gives two passes' items or refuses;
        /// it never refuses when each link's samples come in stamp order and the static
        /// transform comes first.
        #[test]
        fn one_pass_is_two_passes_or_refuses(
            samples in proptest::collection::vec((0i64..20, -5.0f64..5.0), 1..12),
            clouds in proptest::collection::vec((0i64..22, 0usize..40), 0..12),
            in_order in proptest::bool::ANY,
        ) {
            let mut samples = samples;
            if in_order {
                samples.sort_by_key(|s| s.0);
                samples.dedup_by_key(|s| s.0);
            }
            // (place in the bag, message)
            let mut messages: Vec<(usize, &str, &str, Vec<u8>)> = vec![(
                0,
                "/tf_static",
                TF_TYPE,
                tf_msg(&[tf(0, "base", "lidar", 0.5, 0.0)]),
            )];
            for (k, &(t, x)) in samples.iter().enumerate() {
                let m = tf_msg(&[tf(t * S / 4, "map", "base", x, 0.25 * x)]);
                messages.push((4 * k + 1, "/tf", TF_TYPE, m));
            }
            for &(t, place) in &clouds {
                let m = cloud(t * S / 4, "lidar");
                messages.push((place + 2, "/points", ros::POINT_CLOUD2_SCHEMA, m));
            }
            messages.sort_by_key(|m| m.0);
            let bytes = mcap(
                &messages
                    .into_iter()
                    .enumerate()
                    .map(|(i, (_, topic, schema, data))| (topic, schema, i as i64, data))
                    .collect::<Vec<_>>(),
            );
            let (two, refused) = read_both(bytes, &RecordingOptions::default());
            if in_order {
                proptest::prop_assert!(refused.is_none(), "{:?}", refused);
            }
            let _ = two;
        }
    }

    #[test]
    fn one_pass_errors_are_two_passes_or_a_refusal() {
        // Found in review: errors that one pass met in another order than two passes, which
        // read every transform first. One pass now refuses them (two passes then report
        // theirs), or reports the same error.
        let mut bad_cloud = cloud(S, "lidar");
        bad_cloud.truncate(bad_cloud.len() - 3);
        let mut bad_tf = tf_msg(&[tf(0, "map", "lidar", 0.0, 0.0)]);
        bad_tf.truncate(bad_tf.len() - 3);
        let good = tf_msg(&[tf(0, "map", "lidar", 0.0, 0.0)]);
        let cycle = tf_msg(&[
            tf(0, "map", "lidar", 0.0, 0.0),
            tf(0, "x", "y", 0.0, 0.0),
            tf(0, "y", "x", 0.0, 0.0),
        ]);
        let nowhere = RecordingOptions {
            fixed_frame: Some("nowhere".into()),
            ..RecordingOptions::default()
        };
        let cases = [
            // A bad cloud before a bad transform: two passes report the transform.
            (
                vec![
                    ("/tf", TF_TYPE, 0, good.clone()),
                    ("/points", ros::POINT_CLOUD2_SCHEMA, 1, bad_cloud.clone()),
                    ("/tf", TF_TYPE, 2, bad_tf.clone()),
                ],
                RecordingOptions::default(),
                "TFMessage",
            ),
            // A fixed frame not in the tree and a bad cloud: two passes report the frame.
            (
                vec![
                    ("/tf_static", TF_TYPE, 0, good.clone()),
                    ("/points", ros::POINT_CLOUD2_SCHEMA, 1, bad_cloud.clone()),
                ],
                nowhere,
                "--fixed-frame",
            ),
            // A cycle, then a frame given a second parent: two passes report the parent.
            (
                vec![
                    ("/tf_static", TF_TYPE, 0, cycle.clone()),
                    ("/points", ros::POINT_CLOUD2_SCHEMA, 1, cloud(S, "lidar")),
                    (
                        "/tf_static",
                        TF_TYPE,
                        2,
                        tf_msg(&[tf(0, "other", "lidar", 0.0, 0.0)]),
                    ),
                ],
                RecordingOptions::default(),
                "two",
            ),
            // A cycle named by the whole tree's frames.
            (
                vec![
                    ("/tf_static", TF_TYPE, 0, cycle),
                    ("/points", ros::POINT_CLOUD2_SCHEMA, 1, cloud(S, "lidar")),
                    (
                        "/tf_static",
                        TF_TYPE,
                        2,
                        tf_msg(&[tf(0, "y", "a0", 0.0, 0.0)]),
                    ),
                ],
                RecordingOptions::default(),
                "cycle",
            ),
        ];
        for (messages, options, needle) in cases {
            let (two, _) = read_both(mcap(&messages), &options);
            let e = two.unwrap_err().to_string();
            assert!(e.contains(needle), "{e}");
        }
    }

    #[test]
    fn one_pass_refuses_samples_out_of_stamp_order_at_once() {
        // Sorting a link whole at every cloud would be quadratic: the first sort refuses.
        let bytes = mcap(&[
            (
                "/tf",
                TF_TYPE,
                0,
                tf_msg(&[tf(2 * S, "map", "lidar", 2.0, 0.0)]),
            ),
            (
                "/tf",
                TF_TYPE,
                1,
                tf_msg(&[tf(0, "map", "lidar", 0.0, 0.0)]),
            ),
            ("/points", ros::POINT_CLOUD2_SCHEMA, 2, cloud(S, "lidar")),
            ("/points", ros::POINT_CLOUD2_SCHEMA, 3, cloud(S, "lidar")),
        ]);
        let (two, why) = refusal(bytes, &RecordingOptions::default());
        assert_eq!(pose(&two[0]).translation_m, [1.0, 0.0, 0.0]);
        assert!(why.contains("out of stamp order"), "{why}");
    }
}
