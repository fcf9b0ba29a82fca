//! MCAP recordings of ROS 2 messages: `sensor_msgs/msg/PointCloud2` clouds, posed by
//! `geometry_msgs/msg/PoseStamped` messages, both CDR-encoded.
//!
//! The records are walked by [`crate::octo::bag`] (chunks uncompressed, zstd or lz4) rather than
//! with the `mcap` crate's readers: those panic on some malformed records (0.26 slices an
//! Attachment body out of range when its CRC is cut off) and cannot report byte offsets. The
//! `mcap` crate writes ([`write_clouds_mcap`]).

use std::collections::BTreeMap;
use std::io::Cursor;
use std::sync::atomic::AtomicBool;

use super::{CloudBuilder, Scalar, err, shown, unpack_rgb};
use crate::octo::bag::{Bag, BagError, Message, Topic};
use crate::octo::{ParseError, Pose, Scan};

/// Schema name of the clouds read: ROS 2's `sensor_msgs/msg/PointCloud2`.
pub const POINT_CLOUD2_SCHEMA: &str = "sensor_msgs/msg/PointCloud2";
/// Schema name of the poses read: ROS 2's `geometry_msgs/msg/PoseStamped`.
pub const POSE_STAMPED_SCHEMA: &str = "geometry_msgs/msg/PoseStamped";
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

/// Reads the point clouds of an MCAP file of ROS 2 messages.
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
                listing(&topics)
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
                poses.push((m.log_time_ns, decoded(&m, decode_pose)?));
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
        let (builder, note) = decoded(&m, decode_cloud)?;
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

/// The topics, for error messages.
fn listing(topics: &[Topic]) -> String {
    if topics.is_empty() {
        return "no channels".into();
    }
    let mut list: Vec<String> = topics
        .iter()
        .take(10)
        .map(|t| {
            let schema = if t.schema.is_empty() {
                "no schema"
            } else {
                &t.schema
            };
            format!("{:?} ({schema})", t.name)
        })
        .collect();
    if topics.len() > 10 {
        list.push(format!("and {} more", topics.len() - 10));
    }
    format!("channels {}", list.join(", "))
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
                        listing(topics)
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

// ---- CDR ----------------------------------------------------------------------------------

/// Plain CDR (XCDR1) fields: primitives aligned to their size, counted from after the 4-byte
/// encapsulation header; strings and sequences as a `u32` length then the items.
struct Cdr<'a> {
    data: &'a [u8],
    pos: usize,
    big: bool,
    /// File offset of `data[0]`.
    base: usize,
    what: &'static str,
}

impl<'a> Cdr<'a> {
    fn new(message: &'a [u8], offset: usize, what: &'static str) -> Result<Self, ParseError> {
        let Some(head) = message.get(..4) else {
            return Err(err(
                offset,
                format!(
                    "{what} CDR encapsulation header: expected 4 bytes, found {}",
                    message.len()
                ),
            ));
        };
        let big = match [head[0], head[1]] {
            [0, 0] => true,
            [0, 1] => false,
            [a, b] => {
                return Err(err(
                    offset,
                    format!(
                        "{what} CDR encapsulation: expected 00 00 or 00 01 (plain CDR, big or \
                         little endian), found {a:02x} {b:02x}"
                    ),
                ));
            }
        };
        Ok(Cdr {
            data: &message[4..],
            pos: 0,
            big,
            base: offset + 4,
            what,
        })
    }

    fn offset(&self) -> usize {
        self.base + self.pos.min(self.data.len())
    }

    fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8], ParseError> {
        let left = self.data.len().saturating_sub(self.pos);
        if n > left {
            return Err(err(
                self.offset(),
                format!(
                    "{} field {field}: expected {n} bytes, found {left}",
                    self.what
                ),
            ));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, field: &str) -> Result<[u8; N], ParseError> {
        // Aligned to the size; the padding may run past the end, which `take` reports.
        self.pos = self.pos.next_multiple_of(N);
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, field)?);
        if self.big {
            a.reverse();
        }
        Ok(a)
    }

    fn u8(&mut self, field: &str) -> Result<u8, ParseError> {
        self.array::<1>(field).map(|[b]| b)
    }

    fn u32(&mut self, field: &str) -> Result<u32, ParseError> {
        self.array(field).map(u32::from_le_bytes)
    }

    fn f64(&mut self, field: &str) -> Result<f64, ParseError> {
        self.array(field).map(f64::from_le_bytes)
    }

    /// A string: `u32` length including the terminating NUL, the bytes, the NUL.
    fn string(&mut self, field: &str) -> Result<String, ParseError> {
        let n = self.u32(field)?;
        let b = self.take(n as usize, field)?;
        let b = b.strip_suffix(&[0]).unwrap_or(b);
        Ok(String::from_utf8_lossy(b).into_owned())
    }

    /// `std_msgs/Header`: stamp (`i32` sec, `u32` nanosec) and frame id.
    fn header(&mut self) -> Result<(), ParseError> {
        self.u32("header.stamp.sec")?;
        self.u32("header.stamp.nanosec")?;
        self.string("header.frame_id")?;
        Ok(())
    }
}

fn decode_pose(message: &[u8], offset: usize) -> Result<Pose, ParseError> {
    let mut c = Cdr::new(message, offset, "PoseStamped")?;
    c.header()?;
    let names = [
        "pose.position.x",
        "pose.position.y",
        "pose.position.z",
        "pose.orientation.x",
        "pose.orientation.y",
        "pose.orientation.z",
        "pose.orientation.w",
    ];
    let mut v = [0f32; 7];
    for (slot, name) in v.iter_mut().zip(names) {
        let x = c.f64(name)?;
        *slot = x as f32;
        if !slot.is_finite() {
            return Err(err(
                c.offset() - 8,
                format!("PoseStamped field {name}: expected a finite number (as f32), found {x}"),
            ));
        }
    }
    Ok(Pose {
        translation_m: [v[0], v[1], v[2]],
        rotation: [v[6], v[3], v[4], v[5]],
    })
}

struct PointField {
    name: String,
    offset: u32,
    datatype: u8,
}

fn datatype(d: u8) -> Option<Scalar> {
    Some(match d {
        1 => Scalar::I8,
        2 => Scalar::U8,
        3 => Scalar::I16,
        4 => Scalar::U16,
        5 => Scalar::I32,
        6 => Scalar::U32,
        7 => Scalar::F32,
        8 => Scalar::F64,
        _ => return None,
    })
}

enum Colour {
    /// A 4-byte `0x??RRGGBB` value at this offset in a point.
    Packed(usize, Scalar),
    /// `UINT8` r, g, b at these offsets.
    Channels([usize; 3]),
}

/// The points of a `PointCloud2` message, and a note when a colour field was not understood.
fn decode_cloud(
    message: &[u8],
    offset: usize,
) -> Result<(CloudBuilder, Option<String>), ParseError> {
    let mut c = Cdr::new(message, offset, "PointCloud2")?;
    c.header()?;
    let height = c.u32("height")? as usize;
    let width = c.u32("width")? as usize;
    let fields_at = c.offset();
    let n = c.u32("fields")?;
    let mut fields = Vec::new();
    for _ in 0..n {
        fields.push(PointField {
            name: c.string("fields[].name")?,
            offset: c.u32("fields[].offset")?,
            datatype: c.u8("fields[].datatype")?,
        });
        c.u32("fields[].count")?;
    }
    let big = c.u8("is_bigendian")? != 0;
    let step_at = c.offset();
    let point_step = c.u32("point_step")? as usize;
    let row_step_at = c.offset();
    let row_step = c.u32("row_step")? as usize;
    let data_at = c.offset();
    let len = c.u32("data")?;
    let data = c.take(len as usize, "data")?;
    c.u8("is_dense")?;

    let find = |name: &str| fields.iter().find(|f| f.name == name);
    // A field's (offset, type) if it has a known datatype and fits in a point.
    let usable = |f: &PointField| {
        let s = datatype(f.datatype)?;
        (f.offset as usize + s.size() <= point_step).then_some((f.offset as usize, s))
    };
    let mut xyz = [(0usize, Scalar::F32); 3];
    for (slot, name) in xyz.iter_mut().zip(["x", "y", "z"]) {
        let Some(f) = find(name) else {
            return Err(err(
                fields_at,
                format!(
                    "PointCloud2 fields: expected x, y and z, found {}",
                    shown(
                        fields
                            .iter()
                            .map(|f| f.name.as_str())
                            .collect::<Vec<_>>()
                            .join(" ")
                            .as_bytes()
                    )
                ),
            ));
        };
        *slot = usable(f).ok_or_else(|| {
            err(
                fields_at,
                format!(
                    "PointCloud2 field {name}: expected a datatype 1..8 within point_step \
                     {point_step} (at step offset {step_at}), found datatype {} at offset {}",
                    f.datatype, f.offset
                ),
            )
        })?;
    }
    let mut note = None;
    let colour = if let Some(f) = find("rgb").or_else(|| find("rgba")) {
        match usable(f).filter(|(_, s)| s.size() == 4) {
            Some((o, s)) => Some(Colour::Packed(o, s)),
            None => {
                note = Some(format!(
                    "PointCloud2 field {} (datatype {}) is not a 4-byte packed colour within the \
                     point: colours ignored",
                    f.name, f.datatype
                ));
                None
            }
        }
    } else {
        let channel = |name| {
            find(name)
                .and_then(usable)
                .filter(|(_, s)| *s == Scalar::U8)
                .map(|(o, _)| o)
        };
        match (channel("r"), channel("g"), channel("b")) {
            (Some(r), Some(g), Some(b)) => Some(Colour::Channels([r, g, b])),
            _ => None,
        }
    };

    let points = if width == 0 || height == 0 {
        0
    } else {
        let row = width.checked_mul(point_step);
        let Some(row) = row.filter(|&r| r <= row_step) else {
            return Err(err(
                row_step_at,
                format!(
                    "PointCloud2 row_step: expected at least width x point_step = {width} x \
                     {point_step}, found {row_step}"
                ),
            ));
        };
        let need = (height - 1)
            .checked_mul(row_step)
            .and_then(|v| v.checked_add(row));
        if need.is_none_or(|need| need > data.len()) {
            return Err(err(
                data_at,
                format!(
                    "PointCloud2 data: expected {} bytes (height {height} rows of row_step \
                     {row_step}, the last one width {width} x point_step {point_step}), found {}",
                    need.map_or("too many".into(), |v| v.to_string()),
                    data.len()
                ),
            ));
        }
        // Within `data`, so bounded by the input.
        width * height
    };
    let mut builder = CloudBuilder::new(points, colour.is_some());
    let short = || {
        err(
            data_at,
            "PointCloud2 data: a point lies outside the data (internal size check failed)",
        )
    };
    if points > 0 {
        for r in 0..height {
            for k in 0..width {
                let base = r * row_step + k * point_step;
                let point = data.get(base..).ok_or_else(short)?;
                let mut p = [0f32; 3];
                for (slot, (o, s)) in p.iter_mut().zip(xyz) {
                    *slot = point
                        .get(o..)
                        .and_then(|b| s.read_f32(b, big))
                        .ok_or_else(short)?;
                }
                let rgb = match &colour {
                    None => [0; 3],
                    Some(Colour::Packed(o, s)) => point
                        .get(*o..)
                        .and_then(|b| s.read_bits32(b, big))
                        .map(unpack_rgb)
                        .ok_or_else(short)?,
                    Some(Colour::Channels(o)) => {
                        let mut rgb = [0u8; 3];
                        for (slot, &o) in rgb.iter_mut().zip(o) {
                            *slot = *point.get(o).ok_or_else(short)?;
                        }
                        rgb
                    }
                };
                builder.push(p, rgb);
            }
        }
    }
    Ok((builder, note))
}

/// Writes plain little-endian CDR.
struct CdrWriter {
    buf: Vec<u8>,
}

impl CdrWriter {
    fn new() -> Self {
        CdrWriter {
            buf: vec![0, 1, 0, 0],
        }
    }

    fn align(&mut self, n: usize) {
        while !(self.buf.len() - 4).is_multiple_of(n) {
            self.buf.push(0);
        }
    }

    fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    fn header(&mut self, stamp_ns: u64, frame_id: &str) {
        self.u32((stamp_ns / 1_000_000_000) as u32);
        self.u32((stamp_ns % 1_000_000_000) as u32);
        self.string(frame_id);
    }
}

fn encode_cloud(scan: &Scan, stamp_ns: u64) -> Vec<u8> {
    let colors = scan.colors.as_deref();
    if let Some(c) = colors {
        assert_eq!(c.len(), scan.points.len(), "one colour per point");
    }
    let width = u32::try_from(scan.points.len()).expect("PointCloud2 width: over 2^32 points");
    let step: u32 = if colors.is_some() { 16 } else { 12 };
    let mut w = CdrWriter::new();
    w.header(stamp_ns, "sensor");
    w.u32(1);
    w.u32(width);
    let names: &[&str] = if colors.is_some() {
        &["x", "y", "z", "rgb"]
    } else {
        &["x", "y", "z"]
    };
    w.u32(names.len() as u32);
    for (i, name) in names.iter().enumerate() {
        w.string(name);
        w.u32(4 * i as u32);
        w.u8(7); // FLOAT32
        w.u32(1);
    }
    w.u8(0); // little endian
    w.u32(step);
    w.u32(step * width);
    w.u32(step * width);
    for (i, p) in scan.points.iter().enumerate() {
        for v in p {
            w.buf.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(c) = colors {
            let [r, g, b] = c[i];
            w.buf
                .extend_from_slice(&u32::from_be_bytes([0, r, g, b]).to_le_bytes());
        }
    }
    let dense = scan.points.iter().flatten().all(|v| v.is_finite());
    w.u8(u8::from(dense));
    w.buf
}

fn encode_pose(pose: &Pose, stamp_ns: u64) -> Vec<u8> {
    let mut w = CdrWriter::new();
    w.header(stamp_ns, "map");
    let [x, y, z] = pose.translation_m;
    let [qw, qx, qy, qz] = pose.rotation;
    for v in [x, y, z, qx, qy, qz, qw] {
        w.f64(f64::from(v));
    }
    w.buf
}

/// `sensor_msgs/msg/PointCloud2`'s definition, as rosbag2 stores it (`ros2msg`).
const POINT_CLOUD2_DEFINITION: &str = "\
std_msgs/Header header
uint32 height
uint32 width
PointField[] fields
bool is_bigendian
uint32 point_step
uint32 row_step
uint8[] data
bool is_dense
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: sensor_msgs/PointField
uint8 INT8    = 1
uint8 UINT8   = 2
uint8 INT16   = 3
uint8 UINT16  = 4
uint8 INT32   = 5
uint8 UINT32  = 6
uint8 FLOAT32 = 7
uint8 FLOAT64 = 8
string name
uint32 offset
uint8  datatype
uint32 count
";

/// `geometry_msgs/msg/PoseStamped`'s definition, as rosbag2 stores it (`ros2msg`).
const POSE_STAMPED_DEFINITION: &str = "\
std_msgs/Header header
Pose pose
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Pose
Point position
Quaternion orientation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
";

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
        // The little-endian cloud of encode_cloud, turned big endian by hand: every u32 and
        // float swapped, the encapsulation 00 00 and is_bigendian 1.
        let s = scan(&[[1.0, -2.0, 3.5]], Some(&[[10, 20, 30]]), Pose::IDENTITY);
        let le = encode_cloud(&s, 5);
        let mut be = CdrWriter::new();
        be.buf[1] = 0;
        let put = |b: &mut CdrWriter, v: u32| {
            b.align(4);
            b.buf.extend_from_slice(&v.to_be_bytes());
        };
        put(&mut be, 0);
        put(&mut be, 5);
        put(&mut be, 7);
        be.buf.extend_from_slice(b"sensor\0");
        put(&mut be, 1);
        put(&mut be, 1);
        put(&mut be, 4);
        for (i, name) in ["x", "y", "z", "rgb"].iter().enumerate() {
            put(&mut be, name.len() as u32 + 1);
            be.buf.extend_from_slice(name.as_bytes());
            be.buf.push(0);
            put(&mut be, 4 * i as u32);
            be.u8(7);
            put(&mut be, 1);
        }
        be.u8(1);
        put(&mut be, 16);
        put(&mut be, 16);
        put(&mut be, 16);
        for v in [1.0f32, -2.0, 3.5] {
            be.buf.extend_from_slice(&v.to_be_bytes());
        }
        be.buf.extend_from_slice(&0x000a141eu32.to_be_bytes());
        be.u8(1);
        assert_eq!(be.buf.len(), le.len());
        for (data, t) in [(&le, 10), (&be.buf, 20)] {
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
    fn hand_built_cdr_both_byte_orders() {
        // PointCloud2, little endian, laid out by hand: header {sec 1, nanosec 2, "map"},
        // height 1, width 2, fields x (F32 @0), y (F64 @4), z (I16 @12), r g b (U8 @14..16),
        // point_step 17, row_step 34.
        let le = [
            &[0u8, 1, 0, 0][..],
            &1u32.to_le_bytes(),
            &2u32.to_le_bytes(),
            &4u32.to_le_bytes(),
            b"map\0",
            &1u32.to_le_bytes(),
            &2u32.to_le_bytes(),
            &6u32.to_le_bytes(), // 6 fields; pos 24
            // "x": len at 28, "x\0" 32..34, pad to 36, offset, datatype at 40, pad, count at 44
            &2u32.to_le_bytes(),
            b"x\0\0\0",
            &0u32.to_le_bytes(),
            &[7, 0, 0, 0],
            &1u32.to_le_bytes(),
            &2u32.to_le_bytes(),
            b"y\0\0\0",
            &4u32.to_le_bytes(),
            &[8, 0, 0, 0],
            &1u32.to_le_bytes(),
            &2u32.to_le_bytes(),
            b"z\0\0\0",
            &12u32.to_le_bytes(),
            &[3, 0, 0, 0],
            &1u32.to_le_bytes(),
            &2u32.to_le_bytes(),
            b"r\0\0\0",
            &14u32.to_le_bytes(),
            &[2, 0, 0, 0],
            &1u32.to_le_bytes(),
            &2u32.to_le_bytes(),
            b"g\0\0\0",
            &15u32.to_le_bytes(),
            &[2, 0, 0, 0],
            &1u32.to_le_bytes(),
            &2u32.to_le_bytes(),
            b"b\0\0\0",
            &16u32.to_le_bytes(),
            &[2, 0, 0, 0],
            &1u32.to_le_bytes(),
            &[0, 0, 0, 0], // is_bigendian false, padded
            &17u32.to_le_bytes(),
            &34u32.to_le_bytes(),
            &34u32.to_le_bytes(),
        ]
        .concat();
        let mut le = le;
        for (x, y, z, rgb) in [
            (1.5f32, -2.25f64, -7i16, [1u8, 2, 3]),
            (0.0, 1e10, 300, [9, 8, 7]),
        ] {
            le.extend_from_slice(&x.to_le_bytes());
            le.extend_from_slice(&y.to_le_bytes());
            le.extend_from_slice(&z.to_le_bytes());
            le.extend_from_slice(&rgb);
        }
        le.push(1); // is_dense
        let (b, note) = decode_cloud(&le, 0).unwrap();
        assert_eq!(note, None);
        let s = b.finish(Pose::IDENTITY);
        assert_eq!(s.points, vec![[1.5, -2.25, -7.0], [0.0, 1e10, 300.0]]);
        assert_eq!(s.colors, Some(vec![[1, 2, 3], [9, 8, 7]]));
        // Cut before is_dense: the error names the field and its offset.
        let e = decode_cloud(&le[..le.len() - 1], 100).unwrap_err();
        assert_eq!(e.offset, 100 + le.len() as u64 - 1);
        assert!(
            e.message
                .contains("PointCloud2 field is_dense: expected 1 bytes, found 0"),
            "{}",
            e.message
        );

        // PoseStamped, big endian: header {0, 0, ""}, pad to 8 (pos 16), then 7 doubles.
        let mut be = vec![0u8, 0, 0, 0];
        be.extend_from_slice(&0u32.to_be_bytes());
        be.extend_from_slice(&0u32.to_be_bytes());
        be.extend_from_slice(&1u32.to_be_bytes());
        be.push(0);
        be.extend_from_slice(&[0; 3]);
        for v in [1.0f64, 2.0, 3.0, 0.0, 0.0, 0.5, 0.25] {
            be.extend_from_slice(&v.to_be_bytes());
        }
        assert_eq!(be.len(), 4 + 16 + 56);
        let p = decode_pose(&be, 0).unwrap();
        assert_eq!(p.translation_m, [1.0, 2.0, 3.0]);
        assert_eq!(p.rotation, [0.25, 0.0, 0.0, 0.5]);
        let e = decode_pose(&be[..be.len() - 3], 10).unwrap_err();
        assert_eq!(e.offset, 10 + 4 + 16 + 48);
        assert!(
            e.message
                .contains("pose.orientation.w: expected 8 bytes, found 5"),
            "{}",
            e.message
        );
        let mut xcdr2 = be.clone();
        xcdr2[1] = 7;
        let e = decode_pose(&xcdr2, 10).unwrap_err();
        assert_eq!(e.offset, 10);
        assert!(e.message.contains("found 00 07"), "{}", e.message);
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
    fn cloud_errors_carry_offsets() {
        let cloud = encode_cloud(
            &scan(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], None, Pose::IDENTITY),
            0,
        );
        // Find the data length field: it is followed by 24 bytes of data and is_dense.
        let len_at = cloud.len() - 1 - 24 - 4;
        assert_eq!(&cloud[len_at..len_at + 4], &24u32.to_le_bytes());
        let mut bad = cloud.clone();
        bad[len_at - 4..len_at].copy_from_slice(&10u32.to_le_bytes()); // row_step 10 < 24
        let e = decode_cloud(&bad, 1000).unwrap_err();
        assert_eq!(e.offset, 1000 + len_at as u64 - 4);
        assert!(
            e.message
                .contains("row_step: expected at least width x point_step = 2 x 12, found 10"),
            "{}",
            e.message
        );
        // After the header {sec, nsec, length, "sensor\0"} and padding: height, width.
        let height_at: usize = (4 + 4 + 4 + 4 + 7usize).next_multiple_of(4);
        assert_eq!(&cloud[height_at..height_at + 4], &1u32.to_le_bytes());
        assert_eq!(&cloud[height_at + 4..height_at + 8], &2u32.to_le_bytes());
        let mut bad = cloud.clone();
        bad[height_at + 4..height_at + 8].copy_from_slice(&3u32.to_le_bytes());
        let e = decode_cloud(&bad, 0).unwrap_err();
        assert_eq!(e.offset, len_at as u64 - 4);
        assert!(e.message.contains("= 3 x 12, found 24"), "{}", e.message);
        // Claiming 4 billion rows of a 24-byte data array errors without allocating.
        let mut bad = cloud.clone();
        bad[height_at..height_at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        let e = decode_cloud(&bad, 0).unwrap_err();
        assert_eq!(e.offset, len_at as u64);
        assert!(
            e.message.contains("PointCloud2 data: expected"),
            "{}",
            e.message
        );
        // No z field.
        let mut bad = cloud.clone();
        let z = bad.windows(2).rposition(|w| w == b"z\0").unwrap();
        bad[z] = b'w';
        let e = decode_cloud(&bad, 0).unwrap_err();
        assert!(
            e.message.contains("expected x, y and z, found \"x y w\""),
            "{}",
            e.message
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
