//! The CDR writer: plain CDR in either byte order ([`ByteOrder`]), and the encoders of the
//! messages built on it (`encode_*`).

use super::{Header, Transform, TransformStamped};
use rovlink_octo::Scan;

/// The byte order an encoder writes (the decoders read both).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum ByteOrder {
    /// Little endian (encapsulation `00 01`), what ROS 2 writes on every common machine.
    #[default]
    Little,
    /// Big endian (encapsulation `00 00`).
    Big,
}

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

/// Encodes an `octomap_msgs/msg/Octomap` (ROS 2 branch): `header`, `binary`, `id` (the tree
/// type, `OcTree` or `ColorOcTree`: RViz's display must be of that type), `resolution_m`, and
/// `data`, the tree stream alone (the body of a `.bt` when `binary`, of a `.ot` otherwise; no
/// file header). Octomap's `data` is `int8[]`: the same bytes.
///
/// # Panics
///
/// As [`encode_pose_stamped`].
pub fn encode_octomap(
    header: &Header,
    binary: bool,
    id: &str,
    resolution_m: f64,
    data: &[u8],
    order: ByteOrder,
) -> Vec<u8> {
    let mut w = CdrWriter::new(order);
    w.header(header);
    w.u8(u8::from(binary));
    w.string(id);
    w.f64(resolution_m);
    let n = u32::try_from(data.len()).expect("Octomap data: over 4 GiB");
    w.u32(n);
    w.buf.extend_from_slice(data);
    w.buf
}
