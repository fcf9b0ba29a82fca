//! MCAP recordings of ROS 2 messages: `sensor_msgs/msg/PointCloud2` clouds, posed by
//! `geometry_msgs/msg/PoseStamped` messages, both CDR-encoded.
//!
//! The records are walked by [`crate::bag`] (chunks uncompressed, zstd or lz4) rather than
//! with the `mcap` crate's readers: those panic on some malformed records (0.26 slices an
//! Attachment body out of range when its CRC is cut off) and cannot report byte offsets. The
//! `mcap` crate writes ([`write_clouds_mcap`]).

use std::collections::BTreeMap;
use std::io::Cursor;
use std::sync::atomic::AtomicBool;

use super::err;
use crate::bag::{Bag, BagError, Message, Topic, listing};
use crate::ros::{
    self, ByteOrder, Header, POINT_CLOUD2_DEFINITION, POSE_STAMPED_DEFINITION, Transform,
    decode_point_cloud2, decode_pose_stamped_as_pose,
};
pub use crate::ros::{POINT_CLOUD2_SCHEMA, POSE_STAMPED_SCHEMA};
use rovlink_octo::{ParseError, Pose, Scan};
/// Topic of the clouds [`write_clouds_mcap`] writes.
pub const DEFAULT_CLOUD_TOPIC: &str = "/points";
/// Topic of the poses [`write_clouds_mcap`] writes.
pub const DEFAULT_POSE_TOPIC: &str = "/pose";

/// Which topics of an MCAP file [`read_mcap`] reads.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct McapOptions {
    /// Topic of the `PointCloud2` messages; `None`: the first channel (in file order) whose
    /// schema is [`POINT_CLOUD2_SCHEMA`].
    pub cloud_topic: Option<String>,
    /// Topic of the `PoseStamped` messages; `None`: the first channel whose schema is
    /// [`POSE_STAMPED_SCHEMA`], if any (without one every scan has the identity pose).
    pub pose_topic: Option<String>,
}

/// What [`read_mcap`] found: the scans, when they were logged, and from where.
#[derive(Debug, Clone, PartialEq)]
pub struct McapScans {
    /// One scan per `PointCloud2` message, in file order.
    pub scans: Vec<Scan>,
    /// Each scan's message log time, nanoseconds.
    pub log_times_ns: Vec<u64>,
    /// The topic the clouds came from.
    pub cloud_topic: String,
    /// The topic the poses came from; `None` when the file has no `PoseStamped` topic.
    pub pose_topic: Option<String>,
    /// What a user should know about how the scans were made: no poses (identity used), clouds
    /// before the first pose, points dropped, colour fields not understood.
    pub notes: Vec<String>,
}

/// Reads the point clouds of an MCAP file of ROS 2 messages, whole, posed by log time.
///
/// This is the simple in-memory reader behind [`super::read`] (fuzzing, tests, and the
/// round trip of [`write_clouds_mcap`]). `octo-delta build` does not use it: it reads every bag
/// through [`crate::recording`], which poses clouds by their stamps from TF or a pose
/// topic, streams them, and refuses a bag without poses.
///
/// Each `PointCloud2` message on the cloud topic (see [`McapOptions`]) becomes one scan: its
/// points from the `x`, `y`, `z` fields (any numeric datatype), colours from an `rgb` field
/// (packed `0x00RRGGBB`, `FLOAT32` or 4-byte integer), an `rgba` field (`0xAARRGGBB`), or
/// `UINT8` fields `r`, `g`, `b`. Its pose is the latest `PoseStamped` on the pose topic with a
/// log time at or before the cloud's, or the first pose if none is earlier, or the identity when
/// there are no poses (said in [`McapScans::notes`]).
///
/// Messages must be CDR (plain XCDR1, either byte order). Chunks may be uncompressed, zstd or
/// lz4; an error inside a compressed chunk is at the chunk's offset, its message giving the
/// offset in the decompressed records. Never panics.
pub fn read_mcap(bytes: &[u8], options: &McapOptions) -> Result<McapScans, ParseError> {
    let end = bytes.len();
    let mut bag = Bag::from_mcap_bytes("", bytes.to_vec()).map_err(parse_error)?;
    let topics = bag.topics().to_vec();
    let Some((cloud_topic, cloud_ids)) = pick(
        &topics,
        options.cloud_topic.as_deref(),
        POINT_CLOUD2_SCHEMA,
        "cloud",
        end,
    )?
    else {
        return Err(err(
            end,
            format!(
                "MCAP: expected a channel with schema {POINT_CLOUD2_SCHEMA}, found {}",
                listing(&topics, "channels")
            ),
        ));
    };
    let pose = pick(
        &topics,
        options.pose_topic.as_deref(),
        POSE_STAMPED_SCHEMA,
        "pose",
        end,
    )?;
    let stop = AtomicBool::new(false);
    let mut notes = Vec::new();
    let mut poses: Vec<(u64, Pose)> = Vec::new();
    match &pose {
        None => notes.push(format!(
            "no {POSE_STAMPED_SCHEMA} topic: every scan has the identity pose"
        )),
        Some((topic, ids)) => {
            for m in bag.messages(ids, &stop).map_err(parse_error)? {
                let m = m.map_err(parse_error)?;
                poses.push((m.log_time_ns, decoded(&m, decode_pose_stamped_as_pose)?.1));
            }
            // Stable: of poses logged at the same time, the last in the file counts.
            poses.sort_by_key(|p| p.0);
            if poses.is_empty() {
                notes.push(format!(
                    "pose topic {topic} has no messages: every scan has the identity pose"
                ));
            }
        }
    }
    let mut scans = Vec::new();
    let mut log_times_ns = Vec::new();
    let mut before_first_pose = 0usize;
    let mut dropped = 0usize;
    let mut colour_notes: Vec<String> = Vec::new();
    for m in bag.messages(&cloud_ids, &stop).map_err(parse_error)? {
        let m = m.map_err(parse_error)?;
        let (_, builder, note) = decoded(&m, decode_point_cloud2)?;
        if let Some(note) = note
            && !colour_notes.contains(&note)
        {
            colour_notes.push(note);
        }
        let pose = match poses.partition_point(|p| p.0 <= m.log_time_ns) {
            _ if poses.is_empty() => Pose::IDENTITY,
            0 => {
                before_first_pose += 1;
                poses[0].1
            }
            k => poses[k - 1].1,
        };
        dropped += builder.dropped;
        scans.push(builder.finish(pose));
        log_times_ns.push(m.log_time_ns);
    }
    if before_first_pose > 0 {
        notes.push(format!(
            "{before_first_pose} scan(s) logged before the first pose use the first pose"
        ));
    }
    if dropped > 0 {
        notes.push(format!(
            "{dropped} point(s) with a non-finite coordinate dropped"
        ));
    }
    notes.extend(colour_notes);
    Ok(McapScans {
        scans,
        log_times_ns,
        cloud_topic,
        pose_topic: pose.map(|(topic, _)| topic),
        notes,
    })
}

// ---- Topics -------------------------------------------------------------------------------

/// A [`BagError`] of an in-memory file as a [`ParseError`]: inside a compressed chunk, the
/// chunk's offset, with the offset in its decompressed records said in the message.
fn parse_error(e: BagError) -> ParseError {
    let offset = e.at.offset.unwrap_or(0);
    match e.at.inner {
        Some(inner) => err(
            offset as usize,
            format!("MCAP chunk's decompressed offset {inner}: {}", e.message),
        ),
        None => ParseError::new(offset, e.message),
    }
}

/// `decode` run on a message's payload, with errors at the payload's place in the file.
fn decoded<T>(
    m: &Message,
    decode: impl FnOnce(&[u8], usize) -> Result<T, ParseError>,
) -> Result<T, ParseError> {
    if m.at.inner.is_some() {
        decode(&m.data, 0).map_err(|e| parse_error(m.error(e)))
    } else {
        decode(&m.data, m.at.offset.unwrap_or(0) as usize)
    }
}

/// The topic to read `schema` messages from and its indices in `topics`: `wanted`, or the
/// first topic with that schema (`None` if there is none).
fn pick(
    topics: &[Topic],
    wanted: Option<&str>,
    schema: &str,
    role: &str,
    end: usize,
) -> Result<Option<(String, Vec<usize>)>, ParseError> {
    let topic = match wanted {
        Some(t) => {
            if !topics.iter().any(|c| c.name == t) {
                return Err(err(
                    end,
                    format!(
                        "MCAP {role} topic {t:?}: expected a channel with that topic, found {}",
                        listing(topics, "channels")
                    ),
                ));
            }
            t
        }
        None => match topics.iter().find(|c| c.schema == schema) {
            Some(c) => &c.name,
            None => return Ok(None),
        },
    };
    let mut ids = Vec::new();
    for (i, c) in topics.iter().enumerate().filter(|(_, c)| c.name == topic) {
        if c.schema != schema {
            return Err(err(
                end,
                format!(
                    "MCAP {role} channel {topic:?}: expected schema {schema}, found {}",
                    if c.schema.is_empty() {
                        "no schema"
                    } else {
                        &c.schema
                    }
                ),
            ));
        }
        if c.encoding != "cdr" {
            return Err(err(
                end,
                format!(
                    "MCAP {role} channel {topic:?}: expected message encoding cdr, found {:?}",
                    c.encoding
                ),
            ));
        }
        ids.push(i);
    }
    Ok(Some((topic.to_string(), ids)))
}

/// `scan` as a little-endian `PointCloud2` in frame `sensor`, stamped `stamp_ns`.
fn encode_cloud(scan: &Scan, stamp_ns: u64) -> Vec<u8> {
    let header = Header {
        stamp_ns: i64::try_from(stamp_ns).unwrap_or(i64::MAX),
        frame_id: "sensor".into(),
    };
    ros::encode_point_cloud2(&header, scan, ByteOrder::Little)
}

/// `pose` as a little-endian `PoseStamped` in frame `map`, stamped `stamp_ns`.
fn encode_pose(pose: &Pose, stamp_ns: u64) -> Vec<u8> {
    let header = Header {
        stamp_ns: i64::try_from(stamp_ns).unwrap_or(i64::MAX),
        frame_id: "map".into(),
    };
    ros::encode_pose_stamped(&header, &Transform::from_pose(pose), ByteOrder::Little)
}

/// Writes `scans` as an MCAP file of ROS 2 messages that [`read_mcap`] reads back to the same
/// scans (non-finite points are written but dropped on reading).
///
/// Scan `i` becomes a `geometry_msgs/msg/PoseStamped` on [`DEFAULT_POSE_TOPIC`] (frame `map`)
/// and then a `sensor_msgs/msg/PointCloud2` on [`DEFAULT_CLOUD_TOPIC`] (frame `sensor`; one row;
/// `FLOAT32` fields `x y z` and, with colours, `rgb`), both logged and stamped at
/// `(i + 1) x 100 ms`. Messages are little-endian CDR with `ros2msg` schemas, in one or more
/// uncompressed chunks, with the usual summary section (profile `ros2`).
///
/// # Panics
///
/// If a scan's `colors` is `Some` with a length other than its `points`', or a scan has more
/// than `u32::MAX / 16` points.
pub fn write_clouds_mcap(scans: &[Scan]) -> Vec<u8> {
    const MEMORY: &str = "writing MCAP to memory cannot fail";
    let mut w = ::mcap::WriteOptions::new()
        .profile("ros2")
        .library(concat!("rovlink ", env!("CARGO_PKG_VERSION")))
        .compression(None)
        .create(Cursor::new(Vec::new()))
        .expect(MEMORY);
    let no_metadata = BTreeMap::new();
    let cloud_schema = w
        .add_schema(
            POINT_CLOUD2_SCHEMA,
            "ros2msg",
            POINT_CLOUD2_DEFINITION.as_bytes(),
        )
        .expect(MEMORY);
    let pose_schema = w
        .add_schema(
            POSE_STAMPED_SCHEMA,
            "ros2msg",
            POSE_STAMPED_DEFINITION.as_bytes(),
        )
        .expect(MEMORY);
    let clouds = w
        .add_channel(cloud_schema, DEFAULT_CLOUD_TOPIC, "cdr", &no_metadata)
        .expect(MEMORY);
    let poses = w
        .add_channel(pose_schema, DEFAULT_POSE_TOPIC, "cdr", &no_metadata)
        .expect(MEMORY);
    for (i, scan) in scans.iter().enumerate() {
        let t = (i as u64 + 1) * 100_000_000;
        let header = |channel_id| ::mcap::records::MessageHeader {
            channel_id,
            sequence: i as u32,
            log_time: t,
            publish_time: t,
        };
        w.write_to_known_channel(&header(poses), &encode_pose(&scan.pose, t))
            .expect(MEMORY);
        w.write_to_known_channel(&header(clouds), &encode_cloud(scan, t))
            .expect(MEMORY);
    }
    w.finish().expect(MEMORY);
    w.into_inner().into_inner()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ::mcap::records::op;

    fn scan(points: &[[f32; 3]], colors: Option<&[[u8; 3]]>, pose: Pose) -> Scan {
        Scan {
            points: points.to_vec(),
            colors: colors.map(<[_]>::to_vec),
            pose,
        }
    }

    fn pose(k: f32) -> Pose {
        Pose {
            translation_m: [k, -2.0 * k, 0.5],
            rotation: [0.5, 0.5, -0.5, k],
        }
    }

    fn options(cloud: Option<&str>, pose: Option<&str>) -> McapOptions {
        McapOptions {
            cloud_topic: cloud.map(str::to_string),
            pose_topic: pose.map(str::to_string),
        }
    }

    /// A hand-assembled MCAP file: magic, Header, the given records, Footer, magic.
    fn file(records: &[(u8, Vec<u8>)]) -> Vec<u8> {
        let mut out = ::mcap::MAGIC.to_vec();
        let mut rec = |op: u8, body: &[u8]| {
            out.push(op);
            out.extend_from_slice(&(body.len() as u64).to_le_bytes());
            out.extend_from_slice(body);
        };
        rec(op::HEADER, &[0; 8]);
        for (op, body) in records {
            rec(*op, body);
        }
        rec(op::FOOTER, &[0; 20]);
        out.extend_from_slice(::mcap::MAGIC);
        out
    }

    fn string(s: &str) -> Vec<u8> {
        let mut v = (s.len() as u32).to_le_bytes().to_vec();
        v.extend_from_slice(s.as_bytes());
        v
    }

    fn schema(id: u16, name: &str) -> (u8, Vec<u8>) {
        let mut b = id.to_le_bytes().to_vec();
        b.extend(string(name));
        b.extend(string("ros2msg"));
        b.extend(string(""));
        (op::SCHEMA, b)
    }

    fn channel(id: u16, schema: u16, topic: &str, encoding: &str) -> (u8, Vec<u8>) {
        let mut b = id.to_le_bytes().to_vec();
        b.extend(schema.to_le_bytes());
        b.extend(string(topic));
        b.extend(string(encoding));
        b.extend(0u32.to_le_bytes());
        (op::CHANNEL, b)
    }

    fn message(channel: u16, log_time: u64, data: &[u8]) -> (u8, Vec<u8>) {
        let mut b = channel.to_le_bytes().to_vec();
        b.extend(0u32.to_le_bytes());
        b.extend(log_time.to_le_bytes());
        b.extend(log_time.to_le_bytes());
        b.extend_from_slice(data);
        (op::MESSAGE, b)
    }

    fn chunk(records: &[(u8, Vec<u8>)], compression: &str, crc: bool) -> (u8, Vec<u8>) {
        let mut inner = Vec::new();
        for (op, body) in records {
            inner.push(*op);
            inner.extend((body.len() as u64).to_le_bytes());
            inner.extend_from_slice(body);
        }
        let mut b = Vec::new();
        b.extend(0u64.to_le_bytes());
        b.extend(0u64.to_le_bytes());
        b.extend((inner.len() as u64).to_le_bytes());
        let sum = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&inner);
        b.extend(if crc { sum } else { 0 }.to_le_bytes());
        b.extend(string(compression));
        b.extend((inner.len() as u64).to_le_bytes());
        b.extend(inner);
        (op::CHUNK, b)
    }

    fn error(r: Result<McapScans, ParseError>) -> (u64, String) {
        let e = r.unwrap_err();
        (e.offset, e.message)
    }

    #[test]
    fn round_trips_through_the_mcap_writer() {
        let scans = vec![
            scan(
                &[[1.0, 2.0, 3.0], [-4.5, 0.0, 1e-9]],
                Some(&[[255, 0, 1], [2, 3, 4]]),
                pose(1.0),
            ),
            scan(&[[7.0, 8.0, 9.0]], None, pose(2.0)),
            scan(&[], None, Pose::IDENTITY),
        ];
        let bytes = write_clouds_mcap(&scans);
        let read = read_mcap(&bytes, &McapOptions::default()).unwrap();
        assert_eq!(read.scans, scans);
        assert_eq!(
            read.log_times_ns,
            vec![100_000_000, 200_000_000, 300_000_000]
        );
        assert_eq!(read.cloud_topic, DEFAULT_CLOUD_TOPIC);
        assert_eq!(read.pose_topic.as_deref(), Some(DEFAULT_POSE_TOPIC));
        assert!(read.notes.is_empty(), "{:?}", read.notes);
        // Named topics give the same.
        let named = read_mcap(&bytes, &options(Some("/points"), Some("/pose"))).unwrap();
        assert_eq!(named, read);
        // The mcap crate's own reader agrees on the messages.
        let count = ::mcap::MessageStream::new(&bytes).unwrap().count();
        assert_eq!(count, 6);
        let empty = read_mcap(&write_clouds_mcap(&[]), &McapOptions::default()).unwrap();
        assert!(empty.scans.is_empty());
    }

    #[test]
    fn reads_unchunked_files_with_attachments_metadata_and_big_endian_clouds() {
        let mut w = ::mcap::WriteOptions::new()
            .use_chunks(false)
            .compression(None)
            .create(Cursor::new(Vec::new()))
            .unwrap();
        let cs = w
            .add_schema(
                POINT_CLOUD2_SCHEMA,
                "ros2msg",
                POINT_CLOUD2_DEFINITION.as_bytes(),
            )
            .unwrap();
        let mut metadata = BTreeMap::new();
        metadata.insert(
            "offered_qos_profiles".to_string(),
            "- history: 3".to_string(),
        );
        let c = w.add_channel(cs, "/lidar", "cdr", &metadata).unwrap();
        w.attach(&::mcap::Attachment {
            log_time: 1,
            create_time: 1,
            name: "calibration.yaml".into(),
            media_type: "text/yaml".into(),
            data: std::borrow::Cow::Borrowed(b"k: 1"),
        })
        .unwrap();
        w.write_metadata(&::mcap::records::Metadata {
            name: "info".into(),
            metadata: metadata.clone(),
        })
        .unwrap();
        // The same cloud little and big endian.
        let s = scan(&[[1.0, -2.0, 3.5]], Some(&[[10, 20, 30]]), Pose::IDENTITY);
        let le = encode_cloud(&s, 5);
        let header = Header {
            stamp_ns: 5,
            frame_id: "sensor".into(),
        };
        let be = ros::encode_point_cloud2(&header, &s, ByteOrder::Big);
        assert_eq!(be.len(), le.len());
        for (data, t) in [(&le, 10), (&be, 20)] {
            let header = ::mcap::records::MessageHeader {
                channel_id: c,
                sequence: 0,
                log_time: t,
                publish_time: t,
            };
            w.write_to_known_channel(&header, data).unwrap();
        }
        w.finish().unwrap();
        let bytes = w.into_inner().into_inner();
        let read = read_mcap(&bytes, &McapOptions::default()).unwrap();
        assert_eq!(read.scans, vec![s.clone(), s]);
        assert_eq!(read.cloud_topic, "/lidar");
        assert_eq!(read.log_times_ns, vec![10, 20]);
    }

    #[test]
    fn pose_is_the_latest_at_or_before_each_cloud() {
        let cloud = encode_cloud(&scan(&[[1.0, 1.0, 1.0]], None, Pose::IDENTITY), 0);
        let p = |k| encode_pose(&pose(k), 0);
        let records = vec![
            schema(1, POINT_CLOUD2_SCHEMA),
            schema(2, POSE_STAMPED_SCHEMA),
            channel(1, 1, "/c", "cdr"),
            channel(2, 2, "/p", "cdr"),
            message(1, 5, &cloud),   // before any pose: the first pose
            message(2, 30, &p(3.0)), // out of log-time order in the file
            message(2, 10, &p(1.0)),
            message(1, 10, &cloud), // same time as a pose: that pose
            message(1, 29, &cloud),
            message(2, 30, &p(4.0)), // same time as an earlier one: the later in the file counts
            message(1, 99, &cloud),
        ];
        let bytes = file(&records);
        let read = read_mcap(&bytes, &McapOptions::default()).unwrap();
        let got: Vec<Pose> = read.scans.iter().map(|s| s.pose).collect();
        assert_eq!(got, vec![pose(1.0), pose(1.0), pose(1.0), pose(4.0)]);
        assert_eq!(read.log_times_ns, vec![5, 10, 29, 99]);
        assert_eq!(
            read.notes,
            vec!["1 scan(s) logged before the first pose use the first pose".to_string()]
        );
        // The same inside a chunk (with its CRC checked).
        let (head, rest) = records.split_at(2);
        let mut chunked = head.to_vec();
        chunked.push(chunk(rest, "", true));
        assert_eq!(
            read_mcap(&file(&chunked), &McapOptions::default()).unwrap(),
            read
        );
    }

    #[test]
    fn no_pose_topic_means_identity_with_a_note() {
        let cloud = encode_cloud(
            &scan(&[[1.0, f32::NAN, 1.0], [2.0, 2.0, 2.0]], None, pose(1.0)),
            0,
        );
        let bytes = file(&[
            schema(1, POINT_CLOUD2_SCHEMA),
            channel(3, 1, "/c", "cdr"),
            message(3, 1, &cloud),
        ]);
        let read = read_mcap(&bytes, &McapOptions::default()).unwrap();
        assert_eq!(
            read.scans,
            vec![scan(&[[2.0, 2.0, 2.0]], None, Pose::IDENTITY)]
        );
        assert_eq!(read.pose_topic, None);
        assert_eq!(
            read.notes,
            vec![
                format!("no {POSE_STAMPED_SCHEMA} topic: every scan has the identity pose"),
                "1 point(s) with a non-finite coordinate dropped".to_string(),
            ]
        );
        // A pose topic without messages.
        let bytes = file(&[
            schema(1, POINT_CLOUD2_SCHEMA),
            schema(2, POSE_STAMPED_SCHEMA),
            channel(3, 1, "/c", "cdr"),
            channel(4, 2, "/p", "cdr"),
            message(3, 1, &cloud),
        ]);
        let read = read_mcap(&bytes, &McapOptions::default()).unwrap();
        assert_eq!(read.pose_topic.as_deref(), Some("/p"));
        assert!(read.notes[0].contains("pose topic /p has no messages"));
    }

    #[test]
    fn topic_choice_and_its_errors() {
        let cloud = encode_cloud(&scan(&[[1.0, 2.0, 3.0]], None, Pose::IDENTITY), 0);
        let other = encode_cloud(&scan(&[[4.0, 5.0, 6.0]], None, Pose::IDENTITY), 0);
        let records = [
            schema(1, POINT_CLOUD2_SCHEMA),
            schema(2, "std_msgs/msg/String"),
            channel(1, 2, "/text", "cdr"),
            channel(2, 1, "/first", "cdr"),
            channel(3, 1, "/second", "cdr"),
            channel(4, 1, "/json", "json"),
            message(3, 1, &other),
            message(2, 2, &cloud),
        ];
        let bytes = file(&records);
        let read = |c: Option<&str>, p: Option<&str>| read_mcap(&bytes, &options(c, p));
        let first = read(None, None).unwrap();
        assert_eq!(first.cloud_topic, "/first");
        assert_eq!(first.scans[0].points, vec![[1.0, 2.0, 3.0]]);
        let second = read(Some("/second"), None).unwrap();
        assert_eq!(second.scans[0].points, vec![[4.0, 5.0, 6.0]]);
        let (at, msg) = error(read(Some("/nope"), None));
        assert_eq!(at, bytes.len() as u64);
        assert!(
            msg.contains("MCAP cloud topic \"/nope\": expected a channel with that topic"),
            "{msg}"
        );
        assert!(msg.contains("\"/text\" (std_msgs/msg/String)"), "{msg}");
        let (_, msg) = error(read(Some("/text"), None));
        assert!(
            msg.contains("expected schema sensor_msgs/msg/PointCloud2, found std_msgs/msg/String"),
            "{msg}"
        );
        let (_, msg) = error(read(Some("/json"), None));
        assert!(
            msg.contains("expected message encoding cdr, found \"json\""),
            "{msg}"
        );
        let (_, msg) = error(read(None, Some("/first")));
        assert!(
            msg.contains(
                "MCAP pose channel \"/first\": expected schema geometry_msgs/msg/PoseStamped"
            ),
            "{msg}"
        );
        // No cloud schema at all.
        let bytes = file(&[
            schema(2, "std_msgs/msg/String"),
            channel(1, 2, "/text", "cdr"),
        ]);
        let (at, msg) = error(read_mcap(&bytes, &McapOptions::default()));
        assert_eq!(at, bytes.len() as u64);
        assert!(msg.contains("expected a channel with schema sensor_msgs/msg/PointCloud2, found channels \"/text\""), "{msg}");
    }

    #[test]
    fn record_errors_carry_offsets() {
        let good = file(&[]);
        // Magic.
        let (at, msg) = error(read_mcap(b"\x89MCAX", &McapOptions::default()));
        assert_eq!(at, 0);
        assert!(
            msg.contains("expected 89 4d 43 41 50 30 0d 0a, found 89 4d 43 41 58"),
            "{msg}"
        );
        // Truncated anywhere: an error, never a panic; the offset is within the input.
        for cut in 0..good.len() {
            let (at, _) = error(read_mcap(&good[..cut], &McapOptions::default()));
            assert!(at <= cut as u64);
        }
        // A record length beyond the input.
        let mut bad = good.clone();
        bad[9..17].copy_from_slice(&u64::MAX.to_le_bytes());
        let (at, msg) = error(read_mcap(&bad, &McapOptions::default()));
        assert_eq!(at, 9);
        assert!(
            msg.contains("MCAP record 0x01 length: expected at most the"),
            "{msg}"
        );
        // Bytes after the closing magic.
        let mut bad = good.clone();
        bad.push(0);
        let (at, msg) = error(read_mcap(&bad, &McapOptions::default()));
        assert_eq!(at, good.len() as u64 - 8);
        assert!(msg.contains("MCAP closing magic"), "{msg}");
        // Not starting with a Header.
        let mut bad = good.clone();
        bad[8] = op::DATA_END;
        let (at, msg) = error(read_mcap(&bad, &McapOptions::default()));
        assert_eq!(at, 8);
        assert!(
            msg.contains("expected a Header record (opcode 0x01) first, found opcode 0x0f"),
            "{msg}"
        );
        // Field errors inside records: offset of the field.
        let header_end = 8 + 9 + 8;
        let bytes = file(&[(op::SCHEMA, vec![1, 0, 200, 0, 0, 0])]);
        let (at, msg) = error(read_mcap(&bytes, &McapOptions::default()));
        assert_eq!(at, header_end as u64 + 9 + 2);
        assert!(
            msg.contains("MCAP Schema record field name: expected 200 bytes, found 0"),
            "{msg}"
        );
        let bytes = file(&[channel(1, 5, "/c", "cdr")]);
        let (at, msg) = error(read_mcap(&bytes, &McapOptions::default()));
        assert_eq!(at, header_end as u64 + 9 + 2);
        assert!(
            msg.contains("schema_id: expected a schema defined earlier (or 0), found 5"),
            "{msg}"
        );
        let bytes = file(&[message(1, 0, b"")]);
        let (_, msg) = error(read_mcap(&bytes, &McapOptions::default()));
        assert!(
            msg.contains("channel_id: expected a channel defined earlier, found 1"),
            "{msg}"
        );
        let bytes = file(&[schema(0, "x")]);
        let (_, msg) = error(read_mcap(&bytes, &McapOptions::default()));
        assert!(msg.contains("id: expected 1..65535, found 0"), "{msg}");
        let bytes = file(&[schema(1, "x"), schema(1, "y")]);
        let (_, msg) = error(read_mcap(&bytes, &McapOptions::default()));
        assert!(
            msg.contains("MCAP Schema record 1: expected the content of its earlier"),
            "{msg}"
        );
    }

    #[test]
    fn compressed_and_corrupt_chunks() {
        let records = [schema(1, POINT_CLOUD2_SCHEMA)];
        let bytes = file(&[chunk(&records, "zstd", false)]);
        let (at, msg) = error(read_mcap(&bytes, &McapOptions::default()));
        let chunk_body = 8 + 9 + 8 + 9;
        assert_eq!(at, chunk_body as u64 + 28 + 8 + 8);
        assert!(
            msg.contains("zstd-compressed records at offset") && msg.contains("zstd: "),
            "{msg}"
        );
        let bytes = file(&[chunk(&records, "brotli", false)]);
        let (at, msg) = error(read_mcap(&bytes, &McapOptions::default()));
        assert_eq!(at, chunk_body as u64 + 28);
        assert!(
            msg.contains("compression: expected \"\", \"zstd\" or \"lz4\", found \"brotli\""),
            "{msg}"
        );
        let mut bytes = file(&[chunk(&records, "", true)]);
        bytes[chunk_body + 40] ^= 1; // inside the records
        let (at, msg) = error(read_mcap(&bytes, &McapOptions::default()));
        assert_eq!(at, chunk_body as u64 + 24);
        assert!(msg.contains("uncompressed_crc"), "{msg}");
        // An unknown opcode inside a chunk and outside is skipped.
        let bytes = file(&[
            (0x80, vec![1, 2, 3]),
            chunk(
                &[
                    (0x81, vec![]),
                    schema(1, POINT_CLOUD2_SCHEMA),
                    channel(1, 1, "/c", "cdr"),
                ],
                "",
                false,
            ),
        ]);
        assert!(
            read_mcap(&bytes, &McapOptions::default())
                .unwrap()
                .scans
                .is_empty()
        );
    }

    #[test]
    fn every_prefix_and_byte_flip_of_a_valid_file_is_handled() {
        let bytes = write_clouds_mcap(&[scan(&[[1.0, 2.0, 3.0]], Some(&[[1, 2, 3]]), pose(1.0))]);
        for cut in 0..bytes.len() {
            assert!(read_mcap(&bytes[..cut], &McapOptions::default()).is_err());
        }
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0xff;
            let _ = read_mcap(&b, &McapOptions::default());
        }
    }

    #[test]
    fn the_crates_attachment_panic_does_not_reach_us() {
        // An Attachment record whose CRC is cut off (mcap 0.26's reader slices out of range).
        let mut body = Vec::new();
        body.extend(0u64.to_le_bytes());
        body.extend(0u64.to_le_bytes());
        body.extend(string(""));
        body.extend(string(""));
        body.extend(0u64.to_le_bytes());
        let bytes = file(&[
            (op::ATTACHMENT, body),
            schema(1, POINT_CLOUD2_SCHEMA),
            channel(1, 1, "/c", "cdr"),
        ]);
        assert!(
            read_mcap(&bytes, &McapOptions::default())
                .unwrap()
                .scans
                .is_empty()
        );
    }
}
