//! The messages a session takes from a ROS 2 graph, from any bytes: `rovlink_ros2::msgs`'s
//! decoders (Twist, PoseStamped, Odometry, Image, CompressedImage) never panic, accept only
//! finite numbers and unit quaternions, hand out no more bytes than the bound and the input,
//! and an accepted Twist, PoseStamped or Odometry written again (little endian) decodes to the
//! same values; an accepted Image's rows fit its data, and the ROV's camera makes a picture of
//! it or says why not.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_ros2::msgs;

fuzz_target!(|data: &[u8]| {
    if let Ok((l, a)) = msgs::decode_twist(data) {
        assert!(l.iter().chain(&a).all(|v| v.is_finite()));
        assert_eq!(msgs::decode_twist(&msgs::twist(l, a)), Ok((l, a)));
    }
    if let Ok((stamp, frame, pose)) = msgs::decode_pose_stamped(data) {
        let again = msgs::pose_stamped(stamp, &frame, &pose);
        assert_eq!(msgs::decode_pose_stamped(&again), Ok((stamp, frame, pose)));
    }
    if let Ok(o) = msgs::decode_odometry(data) {
        let again = msgs::odometry(
            o.stamp_ns,
            &o.frame_id,
            &o.child_frame_id,
            &o.pose,
            o.linear,
            o.angular,
        );
        assert_eq!(msgs::decode_odometry(&again), Ok(o));
    }
    if let Ok(img) = msgs::decode_image(data, 1 << 16) {
        assert!(img.data.len() <= data.len() && img.data.len() <= 1 << 16);
        assert!(img.step.saturating_mul(img.height) <= img.data.len());
        let _ = rovlink_field::ros2_camera::raw_picture(&img);
    }
    if let Ok((_, bytes)) = msgs::decode_compressed_image(data, 1 << 16) {
        assert!(bytes.len() <= data.len());
    }
});
