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
//! - `nav_msgs/msg/Odometry`, its `pose.pose` ([`decode_odometry`], [`encode_odometry`]);
//! - `octomap_msgs/msg/Octomap`, written only ([`encode_octomap`]).
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
//!
//! [`ParseError`]: rovlink_octo::ParseError
//!
//! # Where things are
//!
//! - `transform.rs`: [`Transform`] and its algebra (apply, compose, inverse, interpolate), and
//!   tf2's checks of a transform's numbers;
//! - `cdr_read.rs`: the CDR reader and the decoders (`decode_*`);
//! - `cdr_write.rs`: the CDR writer and the encoders (`encode_*`, [`ByteOrder`]);
//! - `definitions.rs`: the schema names (`*_SCHEMA`) and definition texts (`*_DEFINITION`);
//! - here: the message types both directions share ([`Header`], [`TransformStamped`]).

mod cdr_read;
mod cdr_write;
mod definitions;
mod transform;

pub use cdr_read::{
    decode_odometry, decode_point_cloud2, decode_pose_stamped, decode_pose_stamped_as_pose,
    decode_tf_message, decode_transform_stamped,
};
pub use cdr_write::{
    ByteOrder, encode_octomap, encode_odometry, encode_point_cloud2, encode_pose_stamped,
    encode_tf_message, encode_transform_stamped,
};
pub use definitions::{
    OCTOMAP_SCHEMA, ODOMETRY_DEFINITION, ODOMETRY_SCHEMA, POINT_CLOUD2_DEFINITION,
    POINT_CLOUD2_SCHEMA, POSE_STAMPED_DEFINITION, POSE_STAMPED_SCHEMA, TF_MESSAGE_DEFINITION,
    TF_MESSAGE_SCHEMA, TRANSFORM_STAMPED_DEFINITION, TRANSFORM_STAMPED_SCHEMA, definition,
};
pub use transform::{Transform, TransformProblem};

/// `std_msgs/Header`: when and in which frame a message's data was taken.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct Header {
    /// The stamp (`builtin_interfaces/Time`: `i32` seconds and `u32` nanoseconds) in
    /// nanoseconds since the epoch; negative before it.
    pub stamp_ns: i64,
    /// The coordinate frame the data is in (for a transform: the parent frame).
    pub frame_id: String,
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

#[cfg(test)]
mod tests;
