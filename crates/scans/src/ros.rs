//! ROS 2 messages as bags store them: CDR decoders and encoders, and rigid transforms.
//!
//! A ROS 2 bag (MCAP or rosbag2's sqlite3 storage) holds each message as plain CDR (XCDR1): a
//! 4-byte encapsulation header (`00 01` little endian, `00 00` big endian, then two option
//! bytes), then the fields in order, each primitive aligned to its own size counted from after
//! the header, strings as a `u32` length (with the terminating NUL) and the bytes, sequences as a
//! `u32` count and the items, fixed arrays as the items alone. This module reads and writes the
//! messages octo-delta uses:
//!
//! - `std_msgs/Header` as [`Header`] (the stamp in nanoseconds);
//! - `sensor_msgs/msg/PointCloud2` ([`decode_point_cloud2`], [`encode_point_cloud2`]);
//! - `geometry_msgs/msg/PoseStamped` ([`decode_pose_stamped`], [`encode_pose_stamped`]);
//! - `geometry_msgs/msg/TransformStamped` ([`decode_transform_stamped`],
//!   [`encode_transform_stamped`]);
//! - `tf2_msgs/msg/TFMessage`, what `/tf` and `/tf_static` carry ([`decode_tf_message`],
//!   [`encode_tf_message`]);
//! - `nav_msgs/msg/Odometry`, its `pose.pose` ([`decode_odometry`], [`encode_odometry`]).
//!
//! The schema names (`*_SCHEMA`) and the `ros2msg` definition texts (`*_DEFINITION`, as rosbag2
//! and MCAP store them) go with them, for writing bags.
//!
//! A [`Transform`] is a rigid motion in `f64`, translation and unit quaternion, as ROS holds
//! it. A transform read from a message is kept exactly as stored (not renormalised): the same
//! `f64` values converted to `f32` ([`Transform::to_pose`]) are what OctoMap's tools read from
//! the same numbers, and so the same maps. A transform whose numbers are not finite, or whose
//! quaternion is far from unit length (tf2's rule: `|norm² - 1| > 0.01`), is an error naming
//! the field and its offset.
//!
//! # The no-panic contract
//!
//! The decoders never panic, on any input: a failure is a [`ParseError`] whose offset is the
//! byte offset where the message stopped making sense (the `offset` argument is the message's
//! own offset in its file, so errors point into the file), naming the field and what was
//! expected and found. Allocations are bounded by the input: a count that claims more items than
//! the remaining bytes could hold is an error before anything is allocated. The decoders are
//! fuzzed (`fuzz/fuzz_targets/octo_ros.rs`) and property-tested (`tests/proptest_octo_tf.rs`).

use crate::cloud::{CloudBuilder, Scalar, err, shown_names, unpack_rgb};
use rovlink_octo::{ParseError, Pose, Scan};

/// Schema name of point clouds: ROS 2's `sensor_msgs/msg/PointCloud2`.
pub const POINT_CLOUD2_SCHEMA: &str = "sensor_msgs/msg/PointCloud2";
/// Schema name of stamped poses: ROS 2's `geometry_msgs/msg/PoseStamped`.
pub const POSE_STAMPED_SCHEMA: &str = "geometry_msgs/msg/PoseStamped";
/// Schema name of stamped transforms: ROS 2's `geometry_msgs/msg/TransformStamped`.
pub const TRANSFORM_STAMPED_SCHEMA: &str = "geometry_msgs/msg/TransformStamped";
/// Schema name of the `/tf` and `/tf_static` messages: ROS 2's `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE_SCHEMA: &str = "tf2_msgs/msg/TFMessage";
/// Schema name of odometry: ROS 2's `nav_msgs/msg/Odometry`.
pub const ODOMETRY_SCHEMA: &str = "nav_msgs/msg/Odometry";

/// `std_msgs/Header`: when and in which frame a message's data was taken.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct Header {
    /// The stamp (`builtin_interfaces/Time`: `i32` seconds and `u32` nanoseconds) in
    /// nanoseconds since the epoch; negative before it.
    pub stamp_ns: i64,
    /// The coordinate frame the data is in (for a transform: the parent frame).
    pub frame_id: String,
}

/// A rigid transform: a point `p` in the child frame is `rotation * p + translation_m` in the
/// parent frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// Translation x, y, z in metres.
    pub translation_m: [f64; 3],
    /// Rotation quaternion (w, x, y, z), of unit length (within tf2's tolerance).
    pub rotation: [f64; 4],
}

/// `geometry_msgs/msg/TransformStamped`: the transform from `child_frame_id` to
/// `header.frame_id` at `header.stamp_ns`. Also what an `Odometry` message says (its pose of
/// `child_frame_id` in `header.frame_id`).
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The frame the transform takes points from.
    pub child_frame_id: String,
    /// Child to parent.
    pub transform: Transform,
}

/// The byte order an encoder writes (the decoders read both).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum ByteOrder {
    /// Little endian (encapsulation `00 01`), what ROS 2 writes on every common machine.
    #[default]
    Little,
    /// Big endian (encapsulation `00 00`).
    Big,
}

/// What is wrong with a transform's numbers, for error messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TransformProblem {
    /// A value is NaN or infinite: which (as in the message: translation x, y, z, then rotation
    /// x, y, z, w) and the value.
    NotFinite {
        /// `translation.x` ... `rotation.w`.
        field: &'static str,
        /// The value found.
        value: f64,
    },
    /// The quaternion's squared norm is more than 0.01 from 1 (tf2's rule).
    NotUnit {
        /// The squared norm found.
        norm2: f64,
    },
}

impl std::fmt::Display for TransformProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TransformProblem::NotFinite { field, value } => {
                write!(f, "{field}: expected a finite number, found {value:?}")
            }
            TransformProblem::NotUnit { norm2 } => write!(
                f,
                "rotation: expected a unit quaternion (squared norm within 0.01 of 1), found \
                 squared norm {norm2}"
            ),
        }
    }
}

/// Field names of a transform's seven numbers, in message order.
const TRANSFORM_FIELDS: [&str; 7] = [
    "translation.x",
    "translation.y",
    "translation.z",
    "rotation.x",
    "rotation.y",
    "rotation.z",
    "rotation.w",
];

/// The squared norm of `q` if it is out of tf2's tolerance.
fn not_unit(q: [f64; 4]) -> Option<f64> {
    let norm2 = q.iter().map(|v| v * v).sum::<f64>();
    ((norm2 - 1.0).abs() > 0.01).then_some(norm2)
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a ⊗ b`, Hamilton's product of quaternions (w, x, y, z).
fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

impl Transform {
    /// No motion: zero translation, rotation (1, 0, 0, 0).
    pub const IDENTITY: Transform = Transform {
        translation_m: [0.0; 3],
        rotation: [1.0, 0.0, 0.0, 0.0],
    };

    /// The transform of an OctoMap pose (`f32` widened exactly to `f64`).
    pub fn from_pose(pose: &Pose) -> Transform {
        Transform {
            translation_m: pose.translation_m.map(f64::from),
            rotation: pose.rotation.map(f64::from),
        }
    }

    /// The pose OctoMap would read from these numbers: each rounded to `f32`, the quaternion not
    /// renormalised. `None` when a value is not finite as `f32` (NaN, infinite, or beyond
    /// `f32`'s range).
    pub fn to_pose(&self) -> Option<Pose> {
        let f = |v: f64| Some(v as f32).filter(|x| x.is_finite());
        let [x, y, z] = self.translation_m;
        let [qw, qx, qy, qz] = self.rotation;
        Some(Pose {
            translation_m: [f(x)?, f(y)?, f(z)?],
            rotation: [f(qw)?, f(qx)?, f(qy)?, f(qz)?],
        })
    }

    /// Whether every number is finite and the quaternion is of unit length within tf2's
    /// tolerance (`|norm² - 1| <= 0.01`).
    pub fn check(&self) -> Result<(), TransformProblem> {
        let [qw, qx, qy, qz] = self.rotation;
        let values = [
            self.translation_m[0],
            self.translation_m[1],
            self.translation_m[2],
            qx,
            qy,
            qz,
            qw,
        ];
        for (value, field) in values.into_iter().zip(TRANSFORM_FIELDS) {
            if !value.is_finite() {
                return Err(TransformProblem::NotFinite { field, value });
            }
        }
        match not_unit(self.rotation) {
            Some(norm2) => Err(TransformProblem::NotUnit { norm2 }),
            None => Ok(()),
        }
    }

    /// `p` rotated by the quaternion (taken as unit) and translated.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let [w, x, y, z] = self.rotation;
        let u = [x, y, z];
        let c = cross(u, p);
        let t = [2.0 * c[0], 2.0 * c[1], 2.0 * c[2]];
        let ut = cross(u, t);
        let mut out = [0.0; 3];
        for (i, o) in out.iter_mut().enumerate() {
            *o = p[i] + w * t[i] + ut[i] + self.translation_m[i];
        }
        out
    }

    /// `self * other`: the transform that takes a point `p` in `other`'s child frame to
    /// `self.apply(other.apply(p))` (for `other` from frame A to B and `self` from B to C, the
    /// transform from A to C). Composing with an exact [`Transform::IDENTITY`] on either side
    /// gives the other transform bit for bit.
    pub fn compose(&self, other: &Transform) -> Transform {
        if *self == Transform::IDENTITY {
            return *other;
        }
        if *other == Transform::IDENTITY {
            return *self;
        }
        Transform {
            translation_m: self.apply(other.translation_m),
            rotation: quat_mul(self.rotation, other.rotation),
        }
    }

    /// The inverse motion (the quaternion conjugated, as tf2 does for unit quaternions).
    pub fn inverse(&self) -> Transform {
        let [w, x, y, z] = self.rotation;
        let rotation = [w, -x, -y, -z];
        let back = Transform {
            translation_m: [0.0; 3],
            rotation,
        }
        .apply(self.translation_m);
        Transform {
            translation_m: back.map(|v| -v),
            rotation,
        }
    }

    /// The transform a fraction `t` of the way from `self` to `other`: translation linear,
    /// rotation by spherical linear interpolation along the shortest arc (`q` and `-q` are the
    /// same rotation). `t = 0` gives `self` and `t = 1` gives `other`, bit for bit.
    pub fn interpolate(&self, other: &Transform, t: f64) -> Transform {
        if t == 0.0 {
            return *self;
        }
        if t == 1.0 {
            return *other;
        }
        let mut translation_m = [0.0; 3];
        for (i, v) in translation_m.iter_mut().enumerate() {
            let (a, b) = (self.translation_m[i], other.translation_m[i]);
            *v = a + (b - a) * t;
        }
        Transform {
            translation_m,
            rotation: slerp(self.rotation, other.rotation, t),
        }
    }
}

/// Spherical linear interpolation from `a` to `b` (or `-b`, whichever is nearer), fraction `t`.
fn slerp(a: [f64; 4], b: [f64; 4], t: f64) -> [f64; 4] {
    let mut dot: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
    let mut b = b;
    if dot < 0.0 {
        b = b.map(|v| -v);
        dot = -dot;
    }
    let (wa, wb) = if dot > 0.9995 {
        // Nearly the same rotation: linear, then normalised below.
        (1.0 - t, t)
    } else {
        let theta = dot.min(1.0).acos();
        let s = theta.sin();
        (((1.0 - t) * theta).sin() / s, (t * theta).sin() / s)
    };
    let mut q = [0.0; 4];
    for (i, v) in q.iter_mut().enumerate() {
        *v = wa * a[i] + wb * b[i];
    }
    if dot > 0.9995 {
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if n > 0.0 {
            q = q.map(|v| v / n);
        }
    }
    q
}

// ---- CDR reading --------------------------------------------------------------------------

/// Plain CDR (XCDR1) fields: primitives aligned to their size, counted from after the 4-byte
/// encapsulation header; strings and sequences as a `u32` length then the items.
struct Cdr<'a> {
    data: &'a [u8],
    pos: usize,
    big: bool,
    /// File offset of `data[0]`.
    base: usize,
    what: &'static str,
    /// Prepended to field names in errors (`transforms[2].`).
    prefix: String,
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
            base: offset.saturating_add(4),
            what,
            prefix: String::new(),
        })
    }

    fn offset(&self) -> usize {
        self.base.saturating_add(self.pos.min(self.data.len()))
    }

    fn left(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8], ParseError> {
        let left = self.left();
        if n > left {
            return Err(err(
                self.offset(),
                format!(
                    "{} field {}{field}: expected {n} bytes, found {left}",
                    self.what, self.prefix
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

    fn i32(&mut self, field: &str) -> Result<i32, ParseError> {
        self.array(field).map(i32::from_le_bytes)
    }

    fn f64(&mut self, field: &str) -> Result<f64, ParseError> {
        self.array(field).map(f64::from_le_bytes)
    }

    /// `n` doubles that are not looked at (fixed arrays such as a covariance), `field` named.
    fn skip_f64s(&mut self, n: usize, field: &str) -> Result<(), ParseError> {
        self.pos = self.pos.next_multiple_of(8);
        self.take(n * 8, field).map(|_| ())
    }

    /// A string: `u32` length including the terminating NUL, the bytes, the NUL.
    fn string(&mut self, field: &str) -> Result<String, ParseError> {
        let n = self.u32(field)?;
        let b = self.take(n as usize, field)?;
        let b = b.strip_suffix(&[0]).unwrap_or(b);
        Ok(String::from_utf8_lossy(b).into_owned())
    }

    /// `std_msgs/Header`: stamp (`i32` sec, `u32` nanosec below 10⁹) and frame id.
    fn header(&mut self) -> Result<Header, ParseError> {
        let sec = self.i32("header.stamp.sec")?;
        let nanosec = self.u32("header.stamp.nanosec")?;
        if nanosec >= 1_000_000_000 {
            return Err(err(
                self.offset() - 4,
                format!(
                    "{} field {}header.stamp.nanosec: expected 0..999999999, found {nanosec}",
                    self.what, self.prefix
                ),
            ));
        }
        Ok(Header {
            stamp_ns: i64::from(sec) * 1_000_000_000 + i64::from(nanosec),
            frame_id: self.string("header.frame_id")?,
        })
    }

    /// Seven doubles: a translation (or position) x, y, z and a quaternion x, y, z, w, named
    /// `names` (after the prefix), checked as `check` says. A quaternion error is at its first
    /// field.
    fn transform(&mut self, names: [&str; 7], check: Check) -> Result<Transform, ParseError> {
        let mut v = [0f64; 7];
        let mut quaternion_at = 0;
        for (i, (slot, name)) in v.iter_mut().zip(names).enumerate() {
            *slot = self.f64(name)?;
            let at = self.offset() - 8;
            if i == 3 {
                quaternion_at = at;
            }
            let (finite, unit) = match check {
                Check::Unit => (slot.is_finite(), ""),
                Check::AsF32 => ((*slot as f32).is_finite(), " (as f32)"),
            };
            if !finite {
                return Err(err(
                    at,
                    format!(
                        "{} field {}{name}: expected a finite number{unit}, found {slot:?}",
                        self.what, self.prefix
                    ),
                ));
            }
        }
        let rotation = [v[6], v[3], v[4], v[5]];
        if check == Check::Unit
            && let Some(norm2) = not_unit(rotation)
        {
            let field = names[3].strip_suffix(".x").unwrap_or(names[3]);
            return Err(err(
                quaternion_at,
                format!(
                    "{} field {}{field}: expected a unit quaternion (squared norm within 0.01 of \
                     1), found (x, y, z, w) = ({}, {}, {}, {}), squared norm {norm2}",
                    self.what, self.prefix, v[3], v[4], v[5], v[6]
                ),
            ));
        }
        Ok(Transform {
            translation_m: [v[0], v[1], v[2]],
            rotation,
        })
    }
}

/// How [`Cdr::transform`] checks the numbers it reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Check {
    /// Finite, and a quaternion of unit length within tf2's tolerance.
    Unit,
    /// Finite once rounded to `f32` (OctoMap's precision); the quaternion as it is.
    AsF32,
}

/// Field names of `geometry_msgs/Pose`'s seven numbers, in message order.
const POSE_FIELDS: [&str; 7] = [
    "position.x",
    "position.y",
    "position.z",
    "orientation.x",
    "orientation.y",
    "orientation.z",
    "orientation.w",
];

/// Decodes a `geometry_msgs/msg/PoseStamped` (CDR) at file offset `offset`: its header and
/// pose (position and orientation as a [`Transform`] from the posed frame to
/// `header.frame_id`). Values not finite, or a quaternion not of unit length within tf2's
/// tolerance, are errors. Never panics.
pub fn decode_pose_stamped(
    message: &[u8],
    offset: usize,
) -> Result<(Header, Transform), ParseError> {
    let mut c = Cdr::new(message, offset, "PoseStamped")?;
    let header = c.header()?;
    c.prefix.push_str("pose.");
    let transform = c.transform(POSE_FIELDS, Check::Unit)?;
    Ok((header, transform))
}

/// Decodes a `geometry_msgs/msg/PoseStamped` as OctoMap would take its numbers: each `f64`
/// rounded to `f32` and required finite as `f32`, the quaternion neither checked nor
/// renormalised (OctoMap's `.graph` poses are not either). For readers that pose scans by
/// `PoseStamped` the way `graph2tree` does. Never panics.
pub fn decode_pose_stamped_as_pose(
    message: &[u8],
    offset: usize,
) -> Result<(Header, Pose), ParseError> {
    let mut c = Cdr::new(message, offset, "PoseStamped")?;
    let header = c.header()?;
    c.prefix.push_str("pose.");
    let transform = c.transform(POSE_FIELDS, Check::AsF32)?;
    // Every value was checked finite as f32.
    Ok((header, transform.to_pose().unwrap_or_default()))
}

/// Decodes a `geometry_msgs/msg/TransformStamped` (CDR) at file offset `offset`. Values not
/// finite, or a quaternion not of unit length within tf2's tolerance, are errors. Never panics.
pub fn decode_transform_stamped(
    message: &[u8],
    offset: usize,
) -> Result<TransformStamped, ParseError> {
    let mut c = Cdr::new(message, offset, "TransformStamped")?;
    transform_stamped(&mut c)
}

fn transform_stamped(c: &mut Cdr) -> Result<TransformStamped, ParseError> {
    let header = c.header()?;
    let child_frame_id = c.string("child_frame_id")?;
    let keep = c.prefix.len();
    c.prefix.push_str("transform.");
    let transform = c.transform(TRANSFORM_FIELDS, Check::Unit)?;
    c.prefix.truncate(keep);
    Ok(TransformStamped {
        header,
        child_frame_id,
        transform,
    })
}

/// The fewest bytes one `TransformStamped` takes in CDR: stamp, two string lengths, seven
/// doubles.
const MIN_TRANSFORM_STAMPED_BYTES: usize = 4 + 4 + 4 + 4 + 7 * 8;

/// Decodes a `tf2_msgs/msg/TFMessage` (CDR) at file offset `offset`: its transforms, in message
/// order. A count larger than the bytes left could hold is an error before anything is
/// allocated; every transform is checked as [`decode_transform_stamped`] checks one. Never
/// panics.
pub fn decode_tf_message(
    message: &[u8],
    offset: usize,
) -> Result<Vec<TransformStamped>, ParseError> {
    let mut c = Cdr::new(message, offset, "TFMessage")?;
    let count = c.u32("transforms")? as usize;
    let fit = c.left() / MIN_TRANSFORM_STAMPED_BYTES;
    if count > fit {
        return Err(err(
            c.offset() - 4,
            format!(
                "TFMessage field transforms: expected at most {fit} transforms in the {} bytes \
                 left ({MIN_TRANSFORM_STAMPED_BYTES} bytes each at least), found a count of \
                 {count}",
                c.left()
            ),
        ));
    }
    let mut out = Vec::with_capacity(count);
    for i in 0..count {
        c.prefix = format!("transforms[{i}].");
        out.push(transform_stamped(&mut c)?);
    }
    Ok(out)
}

/// Decodes a `nav_msgs/msg/Odometry` (CDR) at file offset `offset`: its header,
/// `child_frame_id` and `pose.pose` as the transform from `child_frame_id` to
/// `header.frame_id`. The pose covariance and the twist must be present but are not read.
/// Values not finite, or a quaternion not of unit length within tf2's tolerance, are errors.
/// Never panics.
pub fn decode_odometry(message: &[u8], offset: usize) -> Result<TransformStamped, ParseError> {
    let mut c = Cdr::new(message, offset, "Odometry")?;
    let header = c.header()?;
    let child_frame_id = c.string("child_frame_id")?;
    c.prefix.push_str("pose.pose.");
    let transform = c.transform(POSE_FIELDS, Check::Unit)?;
    c.prefix.clear();
    c.skip_f64s(36, "pose.covariance")?;
    c.skip_f64s(6, "twist.twist")?;
    c.skip_f64s(36, "twist.covariance")?;
    Ok(TransformStamped {
        header,
        child_frame_id,
        transform,
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

/// Decodes a `sensor_msgs/msg/PointCloud2` (CDR) at file offset `offset`: its header, its
/// points (from fields `x`, `y`, `z` of any numeric datatype; points with a coordinate not
/// finite as `f32` dropped and counted), colours from an `rgb` field (packed `0x00RRGGBB`,
/// `FLOAT32` or 4-byte integer), an `rgba` field (`0xAARRGGBB`) or `UINT8` fields `r`, `g`,
/// `b`, and a note when a colour field was there but not understood. Rows and points are laid
/// out by `row_step` and `point_step`; organised clouds (`height > 1`) are read row by row.
/// Never panics.
pub fn decode_point_cloud2(
    message: &[u8],
    offset: usize,
) -> Result<(Header, CloudBuilder, Option<String>), ParseError> {
    let mut c = Cdr::new(message, offset, "PointCloud2")?;
    let header = c.header()?;
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
                    shown_names(fields.iter().map(|f| f.name.as_str()))
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
    Ok((header, builder, note))
}

// ---- CDR writing --------------------------------------------------------------------------

/// Writes plain CDR in either byte order.
struct CdrWriter {
    buf: Vec<u8>,
    big: bool,
}

impl CdrWriter {
    fn new(order: ByteOrder) -> Self {
        let big = order == ByteOrder::Big;
        CdrWriter {
            buf: vec![0, u8::from(!big), 0, 0],
            big,
        }
    }

    fn align(&mut self, n: usize) {
        while !(self.buf.len() - 4).is_multiple_of(n) {
            self.buf.push(0);
        }
    }

    fn put<const N: usize>(&mut self, le: [u8; N]) {
        self.align(N);
        let mut a = le;
        if self.big {
            a.reverse();
        }
        self.buf.extend_from_slice(&a);
    }

    fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    fn u32(&mut self, v: u32) {
        self.put(v.to_le_bytes());
    }

    fn f64(&mut self, v: f64) {
        self.put(v.to_le_bytes());
    }

    fn string(&mut self, s: &str) {
        let n = u32::try_from(s.len() + 1).expect("CDR string: over 4 GiB");
        self.u32(n);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    fn header(&mut self, header: &Header) {
        let sec = i32::try_from(header.stamp_ns.div_euclid(1_000_000_000))
            .expect("Header stamp: seconds beyond i32 (builtin_interfaces/Time)");
        self.put(sec.to_le_bytes());
        self.u32(header.stamp_ns.rem_euclid(1_000_000_000) as u32);
        self.string(&header.frame_id);
    }

    /// Translation then quaternion x, y, z, w.
    fn transform(&mut self, t: &Transform) {
        let [qw, qx, qy, qz] = t.rotation;
        for v in t.translation_m.into_iter().chain([qx, qy, qz, qw]) {
            self.f64(v);
        }
    }

    fn transform_stamped(&mut self, t: &TransformStamped) {
        self.header(&t.header);
        self.string(&t.child_frame_id);
        self.transform(&t.transform);
    }
}

/// Encodes a `geometry_msgs/msg/PoseStamped`: `header`, and `pose` as position and
/// orientation.
///
/// # Panics
///
/// If the stamp's seconds do not fit a ROS 2 `Time` (`i32`), or a string is over 4 GiB.
pub fn encode_pose_stamped(header: &Header, pose: &Transform, order: ByteOrder) -> Vec<u8> {
    let mut w = CdrWriter::new(order);
    w.header(header);
    w.transform(pose);
    w.buf
}

/// Encodes a `geometry_msgs/msg/TransformStamped`.
///
/// # Panics
///
/// As [`encode_pose_stamped`].
pub fn encode_transform_stamped(t: &TransformStamped, order: ByteOrder) -> Vec<u8> {
    let mut w = CdrWriter::new(order);
    w.transform_stamped(t);
    w.buf
}

/// Encodes a `tf2_msgs/msg/TFMessage` of `transforms`.
///
/// # Panics
///
/// As [`encode_pose_stamped`], or with more than `u32::MAX` transforms.
pub fn encode_tf_message(transforms: &[TransformStamped], order: ByteOrder) -> Vec<u8> {
    let mut w = CdrWriter::new(order);
    w.u32(u32::try_from(transforms.len()).expect("TFMessage: over 2^32 transforms"));
    for t in transforms {
        w.transform_stamped(t);
    }
    w.buf
}

/// Encodes a `nav_msgs/msg/Odometry` whose `pose.pose` is `t.transform` (of `t.child_frame_id`
/// in `t.header.frame_id`); covariances and twist are zero.
///
/// # Panics
///
/// As [`encode_pose_stamped`].
pub fn encode_odometry(t: &TransformStamped, order: ByteOrder) -> Vec<u8> {
    let mut w = CdrWriter::new(order);
    w.header(&t.header);
    w.string(&t.child_frame_id);
    w.transform(&t.transform);
    for _ in 0..36 + 6 + 36 {
        w.f64(0.0);
    }
    w.buf
}

/// Encodes `scan`'s points (and colours) as a `sensor_msgs/msg/PointCloud2` with `header`: one
/// row, `FLOAT32` fields `x y z` and, with colours, `rgb` (packed `0x00RRGGBB`), `is_bigendian`
/// and the data in `order`. The scan's pose is not written (it is what the poses say).
///
/// # Panics
///
/// As [`encode_pose_stamped`]; if `scan.colors` is `Some` with a length other than
/// `scan.points`', or the scan has more than `u32::MAX / 16` points.
pub fn encode_point_cloud2(header: &Header, scan: &Scan, order: ByteOrder) -> Vec<u8> {
    let colors = scan.colors.as_deref();
    if let Some(c) = colors {
        assert_eq!(c.len(), scan.points.len(), "one colour per point");
    }
    let step: u32 = if colors.is_some() { 16 } else { 12 };
    let width = u32::try_from(scan.points.len())
        .ok()
        .filter(|w| w.checked_mul(step).is_some())
        .expect("PointCloud2 width: over 2^32 / 16 points");
    let mut w = CdrWriter::new(order);
    w.header(header);
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
    w.u8(u8::from(w.big));
    w.u32(step);
    w.u32(step * width);
    w.u32(step * width);
    let big = w.big;
    let bytes4 = |v: [u8; 4]| if big { [v[3], v[2], v[1], v[0]] } else { v };
    for (i, p) in scan.points.iter().enumerate() {
        for v in p {
            w.buf.extend_from_slice(&bytes4(v.to_le_bytes()));
        }
        if let Some([r, g, b]) = colors.and_then(|c| c.get(i)) {
            w.buf
                .extend_from_slice(&bytes4(u32::from_be_bytes([0, *r, *g, *b]).to_le_bytes()));
        }
    }
    let dense = scan.points.iter().flatten().all(|v| v.is_finite());
    w.u8(u8::from(dense));
    w.buf
}

// ---- definitions --------------------------------------------------------------------------

/// The dependency sections every stamped message's definition ends with.
macro_rules! header_sections {
    () => {
        "================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"
    };
}

/// `geometry_msgs/Pose` and its parts, as definition sections.
macro_rules! pose_sections {
    () => {
        "================================================================================
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
"
    };
}

/// `geometry_msgs/Transform` and its parts, as definition sections.
macro_rules! transform_sections {
    () => {
        "================================================================================
MSG: geometry_msgs/Transform
Vector3 translation
Quaternion rotation
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
"
    };
}

/// `sensor_msgs/msg/PointCloud2`'s definition, as rosbag2 stores it (`ros2msg`).
pub const POINT_CLOUD2_DEFINITION: &str = concat!(
    "std_msgs/Header header
uint32 height
uint32 width
PointField[] fields
bool is_bigendian
uint32 point_step
uint32 row_step
uint8[] data
bool is_dense
",
    header_sections!(),
    "================================================================================
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
"
);

/// `geometry_msgs/msg/PoseStamped`'s definition, as rosbag2 stores it (`ros2msg`).
pub const POSE_STAMPED_DEFINITION: &str = concat!(
    "std_msgs/Header header
Pose pose
",
    header_sections!(),
    pose_sections!()
);

/// `geometry_msgs/msg/TransformStamped`'s definition, as rosbag2 stores it (`ros2msg`).
pub const TRANSFORM_STAMPED_DEFINITION: &str = concat!(
    "std_msgs/Header header
string child_frame_id
Transform transform
",
    header_sections!(),
    transform_sections!()
);

/// `tf2_msgs/msg/TFMessage`'s definition, as rosbag2 stores it (`ros2msg`).
pub const TF_MESSAGE_DEFINITION: &str = concat!(
    "geometry_msgs/TransformStamped[] transforms
================================================================================
MSG: geometry_msgs/TransformStamped
std_msgs/Header header
string child_frame_id
Transform transform
",
    header_sections!(),
    transform_sections!()
);

/// `nav_msgs/msg/Odometry`'s definition, as rosbag2 stores it (`ros2msg`).
pub const ODOMETRY_DEFINITION: &str = concat!(
    "std_msgs/Header header
string child_frame_id
geometry_msgs/PoseWithCovariance pose
geometry_msgs/TwistWithCovariance twist
",
    header_sections!(),
    "================================================================================
MSG: geometry_msgs/PoseWithCovariance
Pose pose
float64[36] covariance
",
    pose_sections!(),
    "================================================================================
MSG: geometry_msgs/TwistWithCovariance
Twist twist
float64[36] covariance
================================================================================
MSG: geometry_msgs/Twist
Vector3  linear
Vector3  angular
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
"
);

/// The definition text of a schema this module knows, by its name (`*_SCHEMA`).
pub fn definition(schema: &str) -> Option<&'static str> {
    Some(match schema {
        POINT_CLOUD2_SCHEMA => POINT_CLOUD2_DEFINITION,
        POSE_STAMPED_SCHEMA => POSE_STAMPED_DEFINITION,
        TRANSFORM_STAMPED_SCHEMA => TRANSFORM_STAMPED_DEFINITION,
        TF_MESSAGE_SCHEMA => TF_MESSAGE_DEFINITION,
        ODOMETRY_SCHEMA => ODOMETRY_DEFINITION,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(stamp_ns: i64, frame_id: &str) -> Header {
        Header {
            stamp_ns,
            frame_id: frame_id.into(),
        }
    }

    fn scan(points: &[[f32; 3]], colors: Option<&[[u8; 3]]>) -> Scan {
        Scan {
            points: points.to_vec(),
            colors: colors.map(<[_]>::to_vec),
            pose: Pose::IDENTITY,
        }
    }

    fn unhex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    fn stamped(ns: i64, parent: &str, child: &str, t: [f64; 3], q: [f64; 4]) -> TransformStamped {
        TransformStamped {
            header: header(ns, parent),
            child_frame_id: child.into(),
            transform: Transform {
                translation_m: t,
                rotation: q,
            },
        }
    }

    const H: f64 = std::f64::consts::FRAC_1_SQRT_2;

    // Written by rosbags 0.11.9 (`Typestore.serialize_cdr`, ROS 2 Humble types): a TFMessage
    // of map -> odom at 1.5 s (t = (1, 2, 3), identity) and odom -> base_link at -2 s + 7 ns
    // (t = (0.5, -0.25, 0.125), 90 degrees about z), little and big endian.
    const TF_LE: &str = "0001000002000000010000000065cd1d040000006d617000050000006f646f6d00000000000000000000f03f00000000000000400000000000000840000000000000000000000000000000000000000000000000000000000000f03ffeffffff07000000050000006f646f6d000000000a000000626173655f6c696e6b00000000000000000000000000e03f000000000000d0bf000000000000c03f00000000000000000000000000000000cd3b7f669ea0e63fcd3b7f669ea0e63f";
    const TF_BE: &str = "0000000000000002000000011dcd6500000000046d617000000000056f646f6d000000003ff0000000000000400000000000000040080000000000000000000000000000000000000000000000000000000000003ff0000000000000fffffffe00000007000000056f646f6d000000000000000a626173655f6c696e6b000000000000003fe0000000000000bfd00000000000003fc0000000000000000000000000000000000000000000003fe6a09e667f3bcd3fe6a09e667f3bcd";
    // PoseStamped in "world" at 3 s + 4 ns: position (1.5, -2, 0.25), orientation (0, 1, 0, 0).
    const PS_LE: &str = "00010000030000000400000006000000776f726c6400000000000000000000000000f83f00000000000000c0000000000000d03f0000000000000000000000000000f03f00000000000000000000000000000000";
    const PS_BE: &str = "00000000000000030000000400000006776f726c64000000000000003ff8000000000000c0000000000000003fd000000000000000000000000000003ff000000000000000000000000000000000000000000000";

    fn tf_expected() -> Vec<TransformStamped> {
        vec![
            stamped(
                1_500_000_000,
                "map",
                "odom",
                [1.0, 2.0, 3.0],
                [1.0, 0.0, 0.0, 0.0],
            ),
            stamped(
                -2_000_000_000 + 7,
                "odom",
                "base_link",
                [0.5, -0.25, 0.125],
                [H, 0.0, 0.0, H],
            ),
        ]
    }

    /// An Odometry written by rosbags: "odom" -> "base_footprint" at 10.999999999 s, pose
    /// (4, 5, 6), (0.5, 0.5, 0.5, 0.5), pose covariance 0..35, twist (1, 2, 3, 0, 0, 9), twist
    /// covariance NaN (not read).
    fn odometry_le() -> Vec<u8> {
        let mut s = String::from(
            "000100000a000000ffc99a3b050000006f646f6d000000000f000000626173655f666f6f747072696e740000000000000000104000000000000014400000000000001840000000000000e03f000000000000e03f000000000000e03f000000000000e03f",
        );
        for i in 0..36 {
            s.push_str(&unhex_f64(f64::from(i)));
        }
        for v in [1.0, 2.0, 3.0, 0.0, 0.0, 9.0] {
            s.push_str(&unhex_f64(v));
        }
        for _ in 0..36 {
            s.push_str("000000000000f87f");
        }
        unhex(&s)
    }

    fn unhex_f64(v: f64) -> String {
        v.to_le_bytes().iter().map(|b| format!("{b:02x}")).collect()
    }

    #[test]
    fn tf_message_from_rosbags_both_byte_orders() {
        for (hex, order) in [(TF_LE, ByteOrder::Little), (TF_BE, ByteOrder::Big)] {
            let bytes = unhex(hex);
            assert_eq!(decode_tf_message(&bytes, 0).unwrap(), tf_expected());
            // Our encoder writes the same bytes.
            assert_eq!(encode_tf_message(&tf_expected(), order), bytes);
            // Cut anywhere: an error within the input, never a panic.
            for cut in 0..bytes.len() {
                let e = decode_tf_message(&bytes[..cut], 100).unwrap_err();
                assert!((100..=100 + cut as u64).contains(&e.offset), "{cut}: {e}");
            }
        }
        // The second transform's rotation cut short names it.
        let bytes = unhex(TF_LE);
        let e = decode_tf_message(&bytes[..bytes.len() - 1], 0).unwrap_err();
        assert_eq!(e.offset, bytes.len() as u64 - 8);
        assert!(
            e.message.contains(
                "TFMessage field transforms[1].transform.rotation.w: expected 8 bytes, found 7"
            ),
            "{e}"
        );
        // A count the bytes cannot hold, before any allocation.
        let mut bad = bytes.clone();
        bad[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        let e = decode_tf_message(&bad, 0).unwrap_err();
        assert_eq!(e.offset, 4);
        assert!(e.message.contains("expected at most 2 transforms"), "{e}");
        assert!(e.message.contains("found a count of 4294967295"), "{e}");
        assert_eq!(
            decode_tf_message(&encode_tf_message(&[], ByteOrder::Big), 0).unwrap(),
            vec![]
        );
    }

    #[test]
    fn pose_stamped_from_rosbags_both_byte_orders() {
        let t = Transform {
            translation_m: [1.5, -2.0, 0.25],
            rotation: [0.0, 0.0, 1.0, 0.0],
        };
        let h = header(3_000_000_004, "world");
        for (hex, order) in [(PS_LE, ByteOrder::Little), (PS_BE, ByteOrder::Big)] {
            let bytes = unhex(hex);
            assert_eq!(decode_pose_stamped(&bytes, 0).unwrap(), (h.clone(), t));
            let (h2, p) = decode_pose_stamped_as_pose(&bytes, 0).unwrap();
            assert_eq!((h2, p), (h.clone(), t.to_pose().unwrap()));
            assert_eq!(encode_pose_stamped(&h, &t, order), bytes);
            for cut in 0..bytes.len() {
                assert!(decode_pose_stamped(&bytes[..cut], 0).is_err());
                assert!(decode_pose_stamped_as_pose(&bytes[..cut], 0).is_err());
            }
        }
    }

    #[test]
    fn transform_stamped_round_trip_and_cuts() {
        let t = tf_expected().remove(1);
        for order in [ByteOrder::Little, ByteOrder::Big] {
            let bytes = encode_transform_stamped(&t, order);
            let tf = encode_tf_message(std::slice::from_ref(&t), order);
            assert_eq!(decode_tf_message(&tf, 0).unwrap(), vec![t.clone()]);
            assert_eq!(decode_transform_stamped(&bytes, 0).unwrap(), t);
            for cut in 0..bytes.len() {
                let e = decode_transform_stamped(&bytes[..cut], 7).unwrap_err();
                assert!(e.offset <= 7 + cut as u64, "{e}");
            }
        }
    }

    #[test]
    fn odometry_from_rosbags() {
        let bytes = odometry_le();
        let want = stamped(
            10_999_999_999,
            "odom",
            "base_footprint",
            [4.0, 5.0, 6.0],
            [0.5, 0.5, 0.5, 0.5],
        );
        assert_eq!(decode_odometry(&bytes, 0).unwrap(), want);
        // Ours differs only in the covariances and twist (zero).
        let ours = encode_odometry(&want, ByteOrder::Little);
        assert_eq!(ours.len(), bytes.len());
        let pose_end = bytes.len() - 78 * 8;
        assert_eq!(ours[..pose_end], bytes[..pose_end]);
        for order in [ByteOrder::Little, ByteOrder::Big] {
            assert_eq!(
                decode_odometry(&encode_odometry(&want, order), 0).unwrap(),
                want
            );
        }
        // The twist covariance must be there, though it is not read.
        let e = decode_odometry(&bytes[..bytes.len() - 8], 0).unwrap_err();
        assert!(
            e.message
                .contains("Odometry field twist.covariance: expected 288 bytes, found 280"),
            "{e}"
        );
        for cut in 0..bytes.len() {
            assert!(decode_odometry(&bytes[..cut], 0).is_err());
        }
    }

    #[test]
    fn bad_numbers_are_errors_at_their_field() {
        let h = header(1, "map");
        let nan = Transform {
            translation_m: [0.0, f64::NAN, 0.0],
            rotation: [1.0, 0.0, 0.0, 0.0],
        };
        let bytes = encode_pose_stamped(&h, &nan, ByteOrder::Little);
        // header: sec, nanosec, len, "map\0" = 16 bytes after the encapsulation; y at 8 more.
        let e = decode_pose_stamped(&bytes, 50).unwrap_err();
        assert_eq!(e.offset, 50 + 4 + 16 + 8);
        assert!(
            e.message
                .contains("PoseStamped field pose.position.y: expected a finite number, found NaN"),
            "{e}"
        );
        // Not unit: tf2's tolerance is on the squared norm.
        let long = Transform {
            translation_m: [0.0; 3],
            rotation: [1.006, 0.0, 0.0, 0.0],
        };
        let bytes = encode_pose_stamped(&h, &long, ByteOrder::Big);
        let e = decode_pose_stamped(&bytes, 0).unwrap_err();
        assert_eq!(e.offset, 4 + 16 + 24);
        assert!(
            e.message
                .contains("field pose.orientation: expected a unit quaternion"),
            "{e}"
        );
        // ... which the OctoMap-style reader does not check; it wants finite f32 only.
        assert_eq!(
            decode_pose_stamped_as_pose(&bytes, 0).unwrap().1.rotation,
            [1.006, 0.0, 0.0, 0.0]
        );
        let huge = Transform {
            translation_m: [0.0, 0.0, 1e300],
            rotation: [1.0, 0.0, 0.0, 0.0],
        };
        let bytes = encode_pose_stamped(&h, &huge, ByteOrder::Little);
        let e = decode_pose_stamped_as_pose(&bytes, 0).unwrap_err();
        assert_eq!(e.offset, 4 + 16 + 16);
        assert!(
            e.message
                .contains("pose.position.z: expected a finite number (as f32), found 1e300"),
            "{e}"
        );
        let slightly = Transform {
            translation_m: [0.0; 3],
            rotation: [1.004, 0.0, 0.0, 0.0],
        };
        let bytes = encode_pose_stamped(&h, &slightly, ByteOrder::Little);
        assert_eq!(decode_pose_stamped(&bytes, 0).unwrap().1, slightly);
        // In a TFMessage, the transform's index is named.
        let mut tf = tf_expected();
        tf[1].transform.rotation = [0.0; 4];
        let e = decode_tf_message(&encode_tf_message(&tf, ByteOrder::Little), 0).unwrap_err();
        assert!(
            e.message
                .contains("transforms[1].transform.rotation: expected a unit quaternion"),
            "{e}"
        );
        tf[1].transform.translation_m[0] = f64::INFINITY;
        let e = decode_tf_message(&encode_tf_message(&tf, ByteOrder::Little), 0).unwrap_err();
        assert!(
            e.message.contains(
                "transforms[1].transform.translation.x: expected a finite number, found inf"
            ),
            "{e}"
        );
    }

    #[test]
    fn header_stamps() {
        for ns in [
            0,
            1,
            999_999_999,
            -1,
            -1_000_000_000,
            i64::from(i32::MIN) * 1_000_000_000,
            i64::from(i32::MAX) * 1_000_000_000 + 999_999_999,
        ] {
            let h = header(ns, "f");
            let t = TransformStamped {
                header: h.clone(),
                child_frame_id: "c".into(),
                transform: Transform::IDENTITY,
            };
            for order in [ByteOrder::Little, ByteOrder::Big] {
                assert_eq!(
                    decode_transform_stamped(&encode_transform_stamped(&t, order), 0)
                        .unwrap()
                        .header,
                    h
                );
            }
        }
        // nanosec 10^9 is refused at its offset.
        let mut bytes =
            encode_pose_stamped(&header(0, "m"), &Transform::IDENTITY, ByteOrder::Little);
        bytes[8..12].copy_from_slice(&1_000_000_000u32.to_le_bytes());
        let e = decode_pose_stamped(&bytes, 10).unwrap_err();
        assert_eq!(e.offset, 18);
        assert!(
            e.message
                .contains("header.stamp.nanosec: expected 0..999999999, found 1000000000"),
            "{e}"
        );
    }

    #[test]
    fn point_cloud2_big_endian_by_hand() {
        // The cloud of encode_point_cloud2 laid out big endian by hand: every u32 and float
        // swapped, the encapsulation 00 00 and is_bigendian 1.
        let s = scan(&[[1.0, -2.0, 3.5]], Some(&[[10, 20, 30]]));
        let mut be = vec![0u8, 0, 0, 0];
        let put = |b: &mut Vec<u8>, v: u32| {
            while !(b.len() - 4).is_multiple_of(4) {
                b.push(0);
            }
            b.extend_from_slice(&v.to_be_bytes());
        };
        put(&mut be, 0);
        put(&mut be, 5);
        put(&mut be, 7);
        be.extend_from_slice(b"sensor\0");
        put(&mut be, 1);
        put(&mut be, 1);
        put(&mut be, 4);
        for (i, name) in ["x", "y", "z", "rgb"].iter().enumerate() {
            put(&mut be, name.len() as u32 + 1);
            be.extend_from_slice(name.as_bytes());
            be.push(0);
            put(&mut be, 4 * i as u32);
            be.push(7);
            put(&mut be, 1);
        }
        be.push(1);
        put(&mut be, 16);
        put(&mut be, 16);
        put(&mut be, 16);
        for v in [1.0f32, -2.0, 3.5] {
            be.extend_from_slice(&v.to_be_bytes());
        }
        be.extend_from_slice(&0x000a141eu32.to_be_bytes());
        be.push(1);
        let h = header(5, "sensor");
        assert_eq!(encode_point_cloud2(&h, &s, ByteOrder::Big), be);
        let (h2, b, note) = decode_point_cloud2(&be, 0).unwrap();
        assert_eq!((h2, note), (h.clone(), None));
        assert_eq!(b.finish(Pose::IDENTITY), s);
        let le = encode_point_cloud2(&h, &s, ByteOrder::Little);
        assert_eq!(le.len(), be.len());
        assert_eq!(
            decode_point_cloud2(&le, 0)
                .unwrap()
                .1
                .finish(Pose::IDENTITY),
            s
        );
        for cut in 0..be.len() {
            assert!(decode_point_cloud2(&be[..cut], 0).is_err());
        }
    }

    #[test]
    fn definitions_by_schema() {
        for (schema, first) in [
            (POINT_CLOUD2_SCHEMA, "std_msgs/Header header\nuint32 height"),
            (
                POSE_STAMPED_SCHEMA,
                "std_msgs/Header header\nPose pose\n====",
            ),
            (
                TRANSFORM_STAMPED_SCHEMA,
                "std_msgs/Header header\nstring child_frame_id\nTransform transform\n====",
            ),
            (
                TF_MESSAGE_SCHEMA,
                "geometry_msgs/TransformStamped[] transforms\n====",
            ),
            (
                ODOMETRY_SCHEMA,
                "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n",
            ),
        ] {
            let d = definition(schema).unwrap();
            assert!(d.starts_with(first), "{schema}");
            assert!(d.contains("MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"));
        }
        assert_eq!(definition("std_msgs/msg/String"), None);
    }

    #[test]
    fn transform_algebra() {
        let a = Transform {
            translation_m: [1.0, 2.0, 3.0],
            rotation: [H, 0.0, 0.0, H], // 90 degrees about z
        };
        let p = a.apply([1.0, 0.0, 0.0]);
        for (g, w) in p.iter().zip([1.0, 3.0, 3.0]) {
            assert!((g - w).abs() < 1e-12, "{p:?}");
        }
        let b = Transform {
            translation_m: [-0.5, 0.25, 4.0],
            rotation: [0.5, 0.5, -0.5, 0.5],
        };
        let q = [0.3, -0.7, 2.0];
        let ab = a.compose(&b).apply(q);
        let seq = a.apply(b.apply(q));
        for (x, y) in ab.iter().zip(seq) {
            assert!((x - y).abs() < 1e-12);
        }
        let back = a.inverse().apply(a.apply(q));
        for (x, y) in back.iter().zip(q) {
            assert!((x - y).abs() < 1e-12);
        }
        // Identity on either side, bit for bit.
        assert_eq!(Transform::IDENTITY.compose(&b), b);
        assert_eq!(b.compose(&Transform::IDENTITY), b);
        assert_eq!(Transform::from_pose(&Pose::IDENTITY), Transform::IDENTITY);
        assert_eq!(Transform::IDENTITY.to_pose(), Some(Pose::IDENTITY));
        let far = Transform {
            translation_m: [1e39, 0.0, 0.0],
            ..Transform::IDENTITY
        };
        assert_eq!(far.to_pose(), None);
        assert_eq!(a.check(), Ok(()));
        assert_eq!(
            Transform {
                rotation: [2.0, 0.0, 0.0, 0.0],
                ..a
            }
            .check(),
            Err(TransformProblem::NotUnit { norm2: 4.0 })
        );
        assert!(matches!(
            Transform {
                rotation: [1.0, 0.0, f64::NAN, 0.0],
                ..a
            }
            .check(),
            Err(TransformProblem::NotFinite {
                field: "rotation.y",
                ..
            })
        ));
    }

    #[test]
    fn interpolation() {
        let a = Transform::IDENTITY;
        let b = Transform {
            translation_m: [2.0, -4.0, 6.0],
            rotation: [H, 0.0, 0.0, H],
        };
        let m = a.interpolate(&b, 0.5);
        assert_eq!(m.translation_m, [1.0, -2.0, 3.0]);
        // 90 degrees -> 45 degrees about z.
        let (c, s) = (
            std::f64::consts::FRAC_PI_8.cos(),
            std::f64::consts::FRAC_PI_8.sin(),
        );
        for (g, w) in m.rotation.iter().zip([c, 0.0, 0.0, s]) {
            assert!((g - w).abs() < 1e-12, "{:?}", m.rotation);
        }
        // -q is the same rotation: the shortest arc gives the same midpoint.
        let neg = Transform {
            rotation: b.rotation.map(|v| -v),
            ..b
        };
        let m2 = a.interpolate(&neg, 0.5);
        for (g, w) in m2.rotation.iter().zip([c, 0.0, 0.0, s]) {
            assert!((g - w).abs() < 1e-12, "{:?}", m2.rotation);
        }
        // Endpoints exactly.
        assert_eq!(a.interpolate(&b, 0.0), a);
        assert_eq!(a.interpolate(&b, 1.0), b);
        assert_eq!(a.interpolate(&neg, 1.0), neg);
        // Nearly equal rotations: normalised linear.
        let tiny = Transform {
            rotation: [1.0, 1e-6, 0.0, 0.0],
            ..a
        };
        let n = a.interpolate(&tiny, 0.25).rotation;
        assert!((n.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-12);
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
        let (h, b, note) = decode_point_cloud2(&le, 0).unwrap();
        assert_eq!(h, header(1_000_000_002, "map"));
        assert_eq!(note, None);
        let s = b.finish(Pose::IDENTITY);
        assert_eq!(s.points, vec![[1.5, -2.25, -7.0], [0.0, 1e10, 300.0]]);
        assert_eq!(s.colors, Some(vec![[1, 2, 3], [9, 8, 7]]));
        // Cut before is_dense: the error names the field and its offset.
        let e = decode_point_cloud2(&le[..le.len() - 1], 100).unwrap_err();
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
        let (h, p) = decode_pose_stamped_as_pose(&be, 0).unwrap();
        assert_eq!(h, header(0, ""));
        assert_eq!(p.translation_m, [1.0, 2.0, 3.0]);
        assert_eq!(p.rotation, [0.25, 0.0, 0.0, 0.5]);
        let e = decode_pose_stamped_as_pose(&be[..be.len() - 3], 10).unwrap_err();
        assert_eq!(e.offset, 10 + 4 + 16 + 48);
        assert!(
            e.message
                .contains("pose.orientation.w: expected 8 bytes, found 5"),
            "{}",
            e.message
        );
        let mut xcdr2 = be.clone();
        xcdr2[1] = 7;
        let e = decode_pose_stamped_as_pose(&xcdr2, 10).unwrap_err();
        assert_eq!(e.offset, 10);
        assert!(e.message.contains("found 00 07"), "{}", e.message);
    }

    #[test]
    fn cloud_errors_carry_offsets() {
        let cloud = encode_point_cloud2(
            &header(0, "sensor"),
            &scan(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], None),
            ByteOrder::Little,
        );
        // Find the data length field: it is followed by 24 bytes of data and is_dense.
        let len_at = cloud.len() - 1 - 24 - 4;
        assert_eq!(&cloud[len_at..len_at + 4], &24u32.to_le_bytes());
        let mut bad = cloud.clone();
        bad[len_at - 4..len_at].copy_from_slice(&10u32.to_le_bytes()); // row_step 10 < 24
        let e = decode_point_cloud2(&bad, 1000).unwrap_err();
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
        let e = decode_point_cloud2(&bad, 0).unwrap_err();
        assert_eq!(e.offset, len_at as u64 - 4);
        assert!(e.message.contains("= 3 x 12, found 24"), "{}", e.message);
        // Claiming 4 billion rows of a 24-byte data array errors without allocating.
        let mut bad = cloud.clone();
        bad[height_at..height_at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        let e = decode_point_cloud2(&bad, 0).unwrap_err();
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
        let e = decode_point_cloud2(&bad, 0).unwrap_err();
        assert!(
            e.message.contains("expected x, y and z, found \"x y w\""),
            "{}",
            e.message
        );
    }
}
