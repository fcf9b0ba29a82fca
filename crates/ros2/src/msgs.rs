//! The messages a teleoperation session puts on a ROS 2 graph and takes from it, as CDR:
//! poses, transforms, velocities, images, text and log lines out; velocities and goal poses in.
//! (The map's and the bags' messages are `rovlink_scans::ros`'s.)

use crate::cdr::{ByteOrder, CdrReader, CdrWriter};

/// `geometry_msgs/msg/PoseStamped`.
pub const POSE_STAMPED: &str = "geometry_msgs/msg/PoseStamped";
/// `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
/// `geometry_msgs/msg/Twist`.
pub const TWIST: &str = "geometry_msgs/msg/Twist";
/// `geometry_msgs/msg/TwistStamped`.
pub const TWIST_STAMPED: &str = "geometry_msgs/msg/TwistStamped";
/// `sensor_msgs/msg/CompressedImage`.
pub const COMPRESSED_IMAGE: &str = "sensor_msgs/msg/CompressedImage";
/// `sensor_msgs/msg/Image`.
pub const IMAGE: &str = "sensor_msgs/msg/Image";
/// `std_msgs/msg/String`.
pub const STRING: &str = "std_msgs/msg/String";
/// `nav_msgs/msg/Odometry`.
pub const ODOMETRY: &str = "nav_msgs/msg/Odometry";
/// `std_msgs/msg/Bool`.
pub const BOOL: &str = "std_msgs/msg/Bool";
/// `rcl_interfaces/msg/Log`, what `/rosout` carries.
pub const LOG: &str = "rcl_interfaces/msg/Log";

/// `rcl_interfaces/msg/Log` levels.
pub mod level {
    /// DEBUG.
    pub const DEBUG: u8 = 10;
    /// INFO.
    pub const INFO: u8 = 20;
    /// WARN.
    pub const WARN: u8 = 30;
    /// ERROR.
    pub const ERROR: u8 = 40;
}

/// A rigid transform: translation (m) and rotation as a quaternion x, y, z, w.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rigid {
    /// Translation, m.
    pub translation_m: [f64; 3],
    /// Rotation x, y, z, w.
    pub rotation_xyzw: [f64; 4],
}

impl Rigid {
    /// The rotation's angle about z, radians (yaw, from the x axis towards y).
    pub fn yaw_rad(&self) -> f64 {
        let [qx, qy, qz, qw] = self.rotation_xyzw;
        (2.0 * (qw * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz))
    }
}

/// The rotation by `yaw_rad` about z, as a quaternion x, y, z, w.
pub fn yaw_quaternion(yaw_rad: f64) -> [f64; 4] {
    let half = yaw_rad / 2.0;
    [0.0, 0.0, half.sin(), half.cos()]
}

fn rigid(w: &mut CdrWriter, r: &Rigid) {
    for v in r.translation_m.into_iter().chain(r.rotation_xyzw) {
        w.f64(v);
    }
}

/// A `geometry_msgs/msg/PoseStamped`.
pub fn pose_stamped(stamp_ns: i64, frame_id: &str, pose: &Rigid) -> Vec<u8> {
    let mut w = CdrWriter::new(ByteOrder::Little);
    w.header(stamp_ns, frame_id);
    rigid(&mut w, pose);
    w.into_bytes()
}

/// A `tf2_msgs/msg/TFMessage` of (parent, child, transform) links, all at `stamp_ns`.
pub fn tf_message(stamp_ns: i64, links: &[(&str, &str, Rigid)]) -> Vec<u8> {
    let mut w = CdrWriter::new(ByteOrder::Little);
    w.u32(links.len() as u32);
    for (parent, child, t) in links {
        w.header(stamp_ns, parent);
        w.string(child);
        rigid(&mut w, t);
    }
    w.into_bytes()
}

/// A `geometry_msgs/msg/TwistStamped`: linear (m/s) and angular (rad/s) velocity.
pub fn twist_stamped(
    stamp_ns: i64,
    frame_id: &str,
    linear: [f64; 3],
    angular: [f64; 3],
) -> Vec<u8> {
    let mut w = CdrWriter::new(ByteOrder::Little);
    w.header(stamp_ns, frame_id);
    for v in linear.into_iter().chain(angular) {
        w.f64(v);
    }
    w.into_bytes()
}

/// A `geometry_msgs/msg/Twist`.
pub fn twist(linear: [f64; 3], angular: [f64; 3]) -> Vec<u8> {
    let mut w = CdrWriter::new(ByteOrder::Little);
    for v in linear.into_iter().chain(angular) {
        w.f64(v);
    }
    w.into_bytes()
}

/// A `sensor_msgs/msg/CompressedImage` (`format`: `png` or `jpeg`).
pub fn compressed_image(stamp_ns: i64, frame_id: &str, format: &str, data: &[u8]) -> Vec<u8> {
    let mut w = CdrWriter::new(ByteOrder::Little);
    w.header(stamp_ns, frame_id);
    w.string(format);
    w.bytes(data);
    w.into_bytes()
}

/// A `std_msgs/msg/String`.
pub fn string(text: &str) -> Vec<u8> {
    let mut w = CdrWriter::new(ByteOrder::Little);
    w.string(text);
    w.into_bytes()
}

/// A `std_msgs/msg/Bool`.
pub fn boolean(value: bool) -> Vec<u8> {
    let mut w = CdrWriter::new(ByteOrder::Little);
    w.u8(u8::from(value));
    w.into_bytes()
}

/// A `nav_msgs/msg/Odometry`: the pose of `child_frame_id` in the header's frame and its
/// velocity in `child_frame_id` (linear, angular); covariances zero.
pub fn odometry(
    stamp_ns: i64,
    frame_id: &str,
    child_frame_id: &str,
    pose: &Rigid,
    linear: [f64; 3],
    angular: [f64; 3],
) -> Vec<u8> {
    let mut w = CdrWriter::new(ByteOrder::Little);
    w.header(stamp_ns, frame_id);
    w.string(child_frame_id);
    rigid(&mut w, pose);
    for _ in 0..36 {
        w.f64(0.0);
    }
    for v in linear.into_iter().chain(angular) {
        w.f64(v);
    }
    for _ in 0..36 {
        w.f64(0.0);
    }
    w.into_bytes()
}

/// What a `nav_msgs/msg/Odometry` says.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Stamp, ns.
    pub stamp_ns: i64,
    /// The frame the pose is in.
    pub frame_id: String,
    /// The frame the velocity is in.
    pub child_frame_id: String,
    /// The pose.
    pub pose: Rigid,
    /// Linear velocity, m/s, in `child_frame_id`.
    pub linear: [f64; 3],
    /// Angular velocity, rad/s, in `child_frame_id`.
    pub angular: [f64; 3],
}

/// Reads a `nav_msgs/msg/Odometry`; every number finite, the quaternion of unit length.
pub fn decode_odometry(message: &[u8]) -> Result<Odometry, String> {
    let mut r = CdrReader::new(message, "Odometry")?;
    let (stamp_ns, frame_id) = r.header()?;
    let child_frame_id = r.string("child_frame_id")?;
    let mut p = [0.0; 7];
    for v in &mut p {
        *v = r.f64("pose.pose")?;
    }
    for _ in 0..36 {
        r.f64("pose.covariance")?;
    }
    let mut t = [0.0; 6];
    for v in &mut t {
        *v = r.f64("twist.twist")?;
    }
    for _ in 0..36 {
        r.f64("twist.covariance")?;
    }
    let norm2 = p[3] * p[3] + p[4] * p[4] + p[5] * p[5] + p[6] * p[6];
    if (norm2 - 1.0).abs() > 0.01 {
        return Err(format!(
            "Odometry: pose.pose.orientation: expected a unit quaternion, found norm² {norm2}"
        ));
    }
    Ok(Odometry {
        stamp_ns,
        frame_id,
        child_frame_id,
        pose: Rigid {
            translation_m: [p[0], p[1], p[2]],
            rotation_xyzw: [p[3], p[4], p[5], p[6]],
        },
        linear: [t[0], t[1], t[2]],
        angular: [t[3], t[4], t[5]],
    })
}

/// An `rcl_interfaces/msg/Log` line from `name` at `level` ([`level`]).
pub fn log(stamp_ns: i64, level: u8, name: &str, text: &str) -> Vec<u8> {
    let mut w = CdrWriter::new(ByteOrder::Little);
    w.time(stamp_ns);
    w.u8(level);
    w.string(name);
    w.string(text);
    w.string("");
    w.string("");
    w.u32(0);
    w.into_bytes()
}

/// Reads a `geometry_msgs/msg/Twist`: linear and angular velocity, every number finite.
pub fn decode_twist(message: &[u8]) -> Result<([f64; 3], [f64; 3]), String> {
    let mut r = CdrReader::new(message, "Twist")?;
    let mut v = [0.0; 6];
    for (k, name) in [
        "linear.x",
        "linear.y",
        "linear.z",
        "angular.x",
        "angular.y",
        "angular.z",
    ]
    .iter()
    .enumerate()
    {
        v[k] = r.f64(name)?;
    }
    Ok(([v[0], v[1], v[2]], [v[3], v[4], v[5]]))
}

/// Reads a `geometry_msgs/msg/PoseStamped`: stamp (ns), frame, and the pose, every number
/// finite and the quaternion of unit length (tf2's tolerance, `|norm² - 1| <= 0.01`).
pub fn decode_pose_stamped(message: &[u8]) -> Result<(i64, String, Rigid), String> {
    let mut r = CdrReader::new(message, "PoseStamped")?;
    let (stamp_ns, frame) = r.header()?;
    let mut v = [0.0; 7];
    for (k, name) in [
        "pose.position.x",
        "pose.position.y",
        "pose.position.z",
        "pose.orientation.x",
        "pose.orientation.y",
        "pose.orientation.z",
        "pose.orientation.w",
    ]
    .iter()
    .enumerate()
    {
        v[k] = r.f64(name)?;
    }
    let norm2 = v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6];
    if (norm2 - 1.0).abs() > 0.01 {
        return Err(format!(
            "PoseStamped: pose.orientation: expected a unit quaternion, found norm² {norm2}"
        ));
    }
    Ok((
        stamp_ns,
        frame,
        Rigid {
            translation_m: [v[0], v[1], v[2]],
            rotation_xyzw: [v[3], v[4], v[5], v[6]],
        },
    ))
}

/// A `sensor_msgs/msg/Image` as sent: its size, encoding (`rgb8`, `mono8`, ...), row step and
/// pixel bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawImage<'a> {
    /// Pixels across.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// The pixel encoding, as ROS names it.
    pub encoding: String,
    /// Bytes per row.
    pub step: usize,
    /// The rows.
    pub data: &'a [u8],
}

/// Reads a `sensor_msgs/msg/Image` of at most `max_bytes` of pixels; the rows must fit the
/// data (`step * height <= data`). Never panics.
pub fn decode_image(message: &[u8], max_bytes: usize) -> Result<RawImage<'_>, String> {
    let mut r = CdrReader::new(message, "Image")?;
    r.header()?;
    let height = r.u32("height")? as usize;
    let width = r.u32("width")? as usize;
    let encoding = r.string("encoding")?;
    r.u8("is_bigendian")?;
    let step = r.u32("step")? as usize;
    let data = r.bytes("data", max_bytes)?;
    if step.checked_mul(height).is_none_or(|n| n > data.len()) {
        return Err(format!(
            "Image: {height} rows of {step} bytes do not fit its {} bytes",
            data.len()
        ));
    }
    Ok(RawImage {
        width,
        height,
        encoding,
        step,
        data,
    })
}

/// Reads a `sensor_msgs/msg/CompressedImage` of at most `max_bytes`: its format and bytes.
pub fn decode_compressed_image(
    message: &[u8],
    max_bytes: usize,
) -> Result<(String, &[u8]), String> {
    let mut r = CdrReader::new(message, "CompressedImage")?;
    r.header()?;
    let format = r.string("format")?;
    let data = r.bytes("data", max_bytes)?;
    Ok((format, data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn velocities_and_poses_read_back() {
        let t = twist([0.5, -0.25, 0.0], [0.0, 0.0, 0.1]);
        assert_eq!(
            decode_twist(&t).unwrap(),
            ([0.5, -0.25, 0.0], [0.0, 0.0, 0.1])
        );
        let pose = Rigid {
            translation_m: [3.0, 1.0, 2.0],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        };
        let m = pose_stamped(5, "ned", &pose);
        assert_eq!(decode_pose_stamped(&m).unwrap(), (5, "ned".into(), pose));
        let bad = Rigid {
            rotation_xyzw: [0.0, 0.0, 0.0, 2.0],
            ..pose
        };
        assert!(decode_pose_stamped(&pose_stamped(5, "ned", &bad)).is_err());
        for cut in 0..t.len() {
            assert!(decode_twist(&t[..cut]).is_err());
        }
    }

    #[test]
    fn images_read_back_and_lies_are_refused() {
        let m = compressed_image(1, "camera", "png", &[1, 2, 3]);
        assert_eq!(
            decode_compressed_image(&m, 10).unwrap(),
            ("png".into(), &[1u8, 2, 3][..])
        );
        assert!(decode_compressed_image(&m, 2).is_err());
        let mut w = CdrWriter::new(ByteOrder::Little);
        w.header(0, "cam");
        w.u32(2); // height
        w.u32(2); // width
        w.string("mono8");
        w.u8(0);
        w.u32(2);
        w.bytes(&[1, 2, 3, 4]);
        let m = w.into_bytes();
        let img = decode_image(&m, 100).unwrap();
        assert_eq!(
            (img.width, img.height, img.step, img.data),
            (2, 2, 2, &[1u8, 2, 3, 4][..])
        );
        for cut in 0..m.len() {
            assert!(decode_image(&m[..cut], 100).is_err());
        }
    }

    #[test]
    fn a_yaw_reads_back_from_its_quaternion() {
        for yaw in [0.0, 0.5, -2.0, 3.0] {
            let r = Rigid {
                translation_m: [0.0; 3],
                rotation_xyzw: yaw_quaternion(yaw),
            };
            assert!((r.yaw_rad() - yaw).abs() < 1e-12, "{yaw}");
        }
    }

    #[test]
    fn odometry_reads_back() {
        let pose = Rigid {
            translation_m: [1.0, 2.0, -3.0],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        };
        let m = odometry(
            7,
            "odom",
            "base_link",
            &pose,
            [0.5, 0.0, 0.0],
            [0.0, 0.0, 0.1],
        );
        let o = decode_odometry(&m).unwrap();
        assert_eq!(
            (o.pose, o.linear, o.angular[2]),
            (pose, [0.5, 0.0, 0.0], 0.1)
        );
        assert_eq!(
            (o.frame_id.as_str(), o.child_frame_id.as_str()),
            ("odom", "base_link")
        );
        for cut in 0..m.len() {
            assert!(decode_odometry(&m[..cut]).is_err());
        }
    }

    #[test]
    fn a_log_line_is_laid_out_as_rcl_interfaces_log() {
        let m = log(1_000_000_001, level::WARN, "tdma_run", "x");
        // stamp (8), level (1), pad (3), name, msg, file, function, line.
        assert_eq!(&m[4..12], &[1, 0, 0, 0, 1, 0, 0, 0]);
        assert_eq!(m[12], 30);
        assert_eq!(&m[16..20], &[9, 0, 0, 0]);
    }
}
