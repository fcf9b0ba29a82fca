//! The CDR writer: plain CDR in either byte order ([`ByteOrder`]), and the encoders of the
//! messages built on it (`encode_*`).

use super::{Header, Transform, TransformStamped};
use rovlink_octo::Scan;

pub use rovlink_ros2::cdr::ByteOrder;
use rovlink_ros2::cdr::CdrWriter;

/// The parts the bag encoders share, written with the ROS 2 layer's CDR writer.
trait RosParts {
    /// A `std_msgs/Header`.
    fn ros_header(&mut self, header: &Header);
    /// Translation then quaternion x, y, z, w.
    fn transform(&mut self, t: &Transform);
    /// A `geometry_msgs/TransformStamped`.
    fn transform_stamped(&mut self, t: &TransformStamped);
}

impl RosParts for CdrWriter {
    fn ros_header(&mut self, header: &Header) {
        self.header(header.stamp_ns, &header.frame_id);
    }

    fn transform(&mut self, t: &Transform) {
        let [qw, qx, qy, qz] = t.rotation;
        for v in t.translation_m.into_iter().chain([qx, qy, qz, qw]) {
            self.f64(v);
        }
    }

    fn transform_stamped(&mut self, t: &TransformStamped) {
        self.ros_header(&t.header);
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
    w.ros_header(header);
    w.transform(pose);
    w.into_bytes()
}

/// Encodes a `geometry_msgs/msg/TransformStamped`.
///
/// # Panics
///
/// As [`encode_pose_stamped`].
pub fn encode_transform_stamped(t: &TransformStamped, order: ByteOrder) -> Vec<u8> {
    let mut w = CdrWriter::new(order);
    w.transform_stamped(t);
    w.into_bytes()
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
    w.into_bytes()
}

/// Encodes a `nav_msgs/msg/Odometry` whose `pose.pose` is `t.transform` (of `t.child_frame_id`
/// in `t.header.frame_id`); covariances and twist are zero.
///
/// # Panics
///
/// As [`encode_pose_stamped`].
pub fn encode_odometry(t: &TransformStamped, order: ByteOrder) -> Vec<u8> {
    let mut w = CdrWriter::new(order);
    w.ros_header(&t.header);
    w.string(&t.child_frame_id);
    w.transform(&t.transform);
    for _ in 0..36 + 6 + 36 {
        w.f64(0.0);
    }
    w.into_bytes()
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
    w.ros_header(header);
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
    w.u8(u8::from(w.is_big()));
    w.u32(step);
    w.u32(step * width);
    w.u32(step * width);
    let big = w.is_big();
    let bytes4 = |v: [u8; 4]| if big { [v[3], v[2], v[1], v[0]] } else { v };
    for (i, p) in scan.points.iter().enumerate() {
        for v in p {
            w.raw().extend_from_slice(&bytes4(v.to_le_bytes()));
        }
        if let Some([r, g, b]) = colors.and_then(|c| c.get(i)) {
            w.raw()
                .extend_from_slice(&bytes4(u32::from_be_bytes([0, *r, *g, *b]).to_le_bytes()));
        }
    }
    let dense = scan.points.iter().flatten().all(|v| v.is_finite());
    w.u8(u8::from(dense));
    w.into_bytes()
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
    w.ros_header(header);
    w.u8(u8::from(binary));
    w.string(id);
    w.f64(resolution_m);
    w.bytes(data);
    w.into_bytes()
}
