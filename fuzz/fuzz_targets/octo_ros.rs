//! ROS 2 CDR messages from any bytes: every `octo::ros` decoder (`TFMessage`,
//! `TransformStamped`, `PoseStamped` both ways, `Odometry`, `PointCloud2`) never panics and a
//! rejected input's error offset lies within the input; an accepted message re-encodes (in the
//! byte order the input used) to bytes that decode to the same values, bit for bit; every
//! accepted transform is finite with a unit quaternion; and the transforms decoded are fed
//! into a `TfTree` (the first byte choosing static or dynamic) and a `PoseTrack`, then looked
//! up between every pair of frames at every stamp seen and around it, which never panics and
//! gives finite transforms, a sample's own numbers at its stamp.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_scans::ros::{
    self, ByteOrder, Transform, decode_odometry, decode_point_cloud2, decode_pose_stamped,
    decode_pose_stamped_as_pose, decode_tf_message, decode_transform_stamped,
};
use rovlink_scans::tf::{PoseTrack, TfTree};

const OFFSET: usize = 1000;

fn bits(t: &Transform) -> Vec<u64> {
    t.translation_m
        .iter()
        .chain(&t.rotation)
        .map(|v| v.to_bits())
        .collect()
}

fn within<T>(r: &Result<T, rovlink_octo::ParseError>, len: usize) {
    if let Err(e) = r {
        assert!(
            (OFFSET as u64..=(OFFSET + len) as u64).contains(&e.offset),
            "offset {} outside the input: {e}",
            e.offset
        );
    }
}

fuzz_target!(|data: &[u8]| {
    let order = if data.get(1) == Some(&0) {
        ByteOrder::Big
    } else {
        ByteOrder::Little
    };
    let n = data.len();
    let tf = decode_tf_message(data, OFFSET);
    within(&tf, n);
    let one = decode_transform_stamped(data, OFFSET);
    within(&one, n);
    let pose = decode_pose_stamped(data, OFFSET);
    within(&pose, n);
    let as_pose = decode_pose_stamped_as_pose(data, OFFSET);
    within(&as_pose, n);
    let odom = decode_odometry(data, OFFSET);
    within(&odom, n);
    let cloud = decode_point_cloud2(data, OFFSET);
    within(&cloud, n);

    let mut transforms = Vec::new();
    if let Ok(v) = &tf {
        let back = decode_tf_message(&ros::encode_tf_message(v, order), 0).expect("re-encoded");
        assert_eq!(&back, v);
        transforms.extend(v.iter().cloned());
    }
    if let Ok(t) = &one {
        let back = decode_transform_stamped(&ros::encode_transform_stamped(t, order), 0)
            .expect("re-encoded");
        assert_eq!(&back, t);
        transforms.push(t.clone());
    }
    if let Ok(t) = &odom {
        let back = decode_odometry(&ros::encode_odometry(t, order), 0).expect("re-encoded");
        assert_eq!(&back, t);
        transforms.push(t.clone());
    }
    if let Ok((h, t)) = &pose {
        let back = decode_pose_stamped(&ros::encode_pose_stamped(h, t, order), 0).expect("re");
        assert_eq!((&back.0, bits(&back.1)), (h, bits(t)));
        assert_eq!(as_pose.as_ref().ok().map(|p| p.1), t.to_pose());
    }
    if let Ok((h, b, _)) = cloud {
        let scan = b.finish(rovlink_octo::Pose::IDENTITY);
        assert!(scan.points.iter().flatten().all(|v| v.is_finite()));
        let again = ros::encode_point_cloud2(&h, &scan, order);
        let (h2, b2, _) = decode_point_cloud2(&again, 0).expect("re-encoded cloud");
        assert_eq!(h2, h);
        assert_eq!(b2.finish(rovlink_octo::Pose::IDENTITY), scan);
    }
    for t in &transforms {
        assert!(t.transform.check().is_ok(), "{t:?}");
    }

    let is_static = data.first().is_some_and(|b| b & 1 == 1);
    let mut tree = TfTree::new();
    let mut track = PoseTrack::new();
    for t in &transforms {
        let _ = tree.add(t, is_static);
        track
            .add(&t.header, &t.transform)
            .expect("checked transforms");
    }
    let finished = tree.finish().is_ok();
    track.finish();
    // At a sample's stamp, the last sample added with that stamp, bit for bit.
    let mut last_at = std::collections::BTreeMap::new();
    for t in &transforms {
        last_at.insert(t.header.stamp_ns, t.transform);
    }
    for (s, t) in &last_at {
        assert_eq!(bits(&track.lookup(*s).expect("a sample's stamp")), bits(t));
    }
    let frames: Vec<String> = tree.frames().map(str::to_string).collect();
    let stamps: Vec<i64> = transforms.iter().map(|t| t.header.stamp_ns).collect();
    for &s in &stamps {
        for stamp_ns in [s.saturating_sub(1), s, s.saturating_add(1)] {
            if let Ok(t) = track.lookup(stamp_ns) {
                assert!(
                    t.translation_m
                        .iter()
                        .chain(&t.rotation)
                        .all(|v| v.is_finite())
                );
            }
            for fixed in frames.iter().take(8) {
                for frame in frames.iter().take(8) {
                    let got = tree.lookup(fixed, frame, stamp_ns);
                    assert!(finished || got.is_err());
                    if let Ok(t) = got {
                        assert!(
                            t.translation_m
                                .iter()
                                .chain(&t.rotation)
                                .all(|v| v.is_finite())
                        );
                    }
                }
            }
        }
    }
});
