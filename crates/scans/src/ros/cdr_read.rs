//! The CDR reader: plain CDR (XCDR1) fields in either byte order, with errors that name the
//! field and its file offset, and the decoders of the messages built on it (`decode_*`).

use super::transform::{TRANSFORM_FIELDS, not_unit};
use super::{Header, Transform, TransformStamped};
use crate::cloud::{CloudBuilder, Scalar, err, shown_names, unpack_rgb};
use rovlink_octo::{ParseError, Pose};

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

/// The little-endian `f32` at `offset` of `point`; `offset + 4 <= point.len()` is checked by the
/// caller (a field within `point_step`), and a NaN (a dropped point) stands in otherwise.
fn le_f32_at(point: &[u8], offset: usize) -> f32 {
    point
        .get(offset..offset + 4)
        .and_then(|b| <[u8; 4]>::try_from(b).ok())
        .map_or(f32::NAN, f32::from_le_bytes)
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
    if points > 0 && !big && xyz.iter().all(|&(_, s)| s == Scalar::F32) {
        // The layout every lidar driver writes: read each row's points in place, the bounds
        // checked once above (row_step and data length) and by `usable` (a field within
        // point_step), not again for every coordinate.
        for r in 0..height {
            let row = data
                .get(r * row_step..r * row_step + width * point_step)
                .ok_or_else(short)?;
            for point in row.chunks_exact(point_step) {
                let p = xyz.map(|(o, _)| le_f32_at(point, o));
                let rgb = match &colour {
                    None => [0; 3],
                    Some(Colour::Packed(o, s)) => s
                        .read_bits32(point.get(*o..).unwrap_or_default(), big)
                        .map_or([0; 3], unpack_rgb),
                    Some(Colour::Channels(o)) => o.map(|o| point.get(o).copied().unwrap_or(0)),
                };
                builder.push(p, rgb);
            }
        }
    } else if points > 0 {
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
