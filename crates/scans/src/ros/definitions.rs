//! The messages' schema names (`*_SCHEMA`) and their `ros2msg` definition texts
//! (`*_DEFINITION`, as rosbag2 and MCAP store them), for writing bags.

/// Schema name of point clouds: ROS 2's `sensor_msgs/msg/PointCloud2`.
pub const POINT_CLOUD2_SCHEMA: &str = "sensor_msgs/msg/PointCloud2";
/// Schema name of stamped poses: ROS 2's `geometry_msgs/msg/PoseStamped`.
pub const POSE_STAMPED_SCHEMA: &str = rovlink_ros2::msgs::POSE_STAMPED;
/// Schema name of stamped transforms: ROS 2's `geometry_msgs/msg/TransformStamped`.
pub const TRANSFORM_STAMPED_SCHEMA: &str = "geometry_msgs/msg/TransformStamped";
/// Schema name of the `/tf` and `/tf_static` messages: ROS 2's `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE_SCHEMA: &str = rovlink_ros2::msgs::TF_MESSAGE;
/// Schema name of odometry: ROS 2's `nav_msgs/msg/Odometry`.
pub const ODOMETRY_SCHEMA: &str = "nav_msgs/msg/Odometry";
/// The schema name of OctoMap's map message (octomap_msgs, ROS 2 branch).
pub const OCTOMAP_SCHEMA: &str = "octomap_msgs/msg/Octomap";

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
}
