//! Property tests of `octo::ros` (CDR messages, transforms) and `octo::tf` (TF buffer, pose
//! tracks): random bytes to every decoder never panic and errors point into the input; random
//! messages (any `f64`, NaNs included, empty and odd frame ids) round-trip through the encoders
//! in both byte orders or are refused; random TF fed to a `TfTree` never panics; a lookup at a
//! sample's stamp gives the sample bit for bit, also through identity static links; a
//! transform composed with its inverse is the identity; interpolated lookups stay between
//! their samples.

use proptest::prelude::*;
use rovlink_scans::ros::{
    self, ByteOrder, Header, Transform, TransformStamped, decode_odometry, decode_point_cloud2,
    decode_pose_stamped, decode_pose_stamped_as_pose, decode_tf_message, decode_transform_stamped,
};
use rovlink_scans::tf::{PoseTrack, TfTree, Unavailable};

// ---- strategies -------------------------------------------------------------------------

/// Any `f64`, weighted towards ordinary values and the special ones.
fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        1 => any::<u64>().prop_map(f64::from_bits),
        4 => -100.0f64..100.0,
        1 => prop::sample::select(vec![0.0, -0.0, 1.0, f64::NAN, f64::INFINITY, 1e300]),
    ]
}

/// A unit quaternion (w, x, y, z), from a random direction.
fn unit_quaternion() -> impl Strategy<Value = [f64; 4]> {
    prop::array::uniform4(-1.0f64..1.0)
        .prop_filter("not near zero", |q| {
            q.iter().map(|v| v * v).sum::<f64>() > 1e-3
        })
        .prop_map(|q| {
            let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            q.map(|v| v / n)
        })
}

fn unit_transform() -> impl Strategy<Value = Transform> {
    (prop::array::uniform3(-50.0f64..50.0), unit_quaternion()).prop_map(
        |(translation_m, rotation)| Transform {
            translation_m,
            rotation,
        },
    )
}

/// A transform that may be anything: unit, or random numbers (NaN, non-unit).
fn any_transform() -> impl Strategy<Value = Transform> {
    prop_oneof![
        3 => unit_transform(),
        1 => (prop::array::uniform3(any_f64()), prop::array::uniform4(any_f64())).prop_map(
            |(translation_m, rotation)| Transform { translation_m, rotation }
        ),
    ]
}

fn frame() -> impl Strategy<Value = String> {
    prop::sample::select(vec!["", "a", "b", "c", "d", "map", "odom", "é/ü"]).prop_map(String::from)
}

/// Stamps a ROS 2 `Time` holds.
fn stamp() -> impl Strategy<Value = i64> {
    prop_oneof![
        3 => 0i64..50,
        1 => (i64::from(i32::MIN) * 1_000_000_000)..=(i64::from(i32::MAX) * 1_000_000_000 + 999_999_999),
    ]
}

fn transform_stamped() -> impl Strategy<Value = TransformStamped> {
    (stamp(), frame(), frame(), any_transform()).prop_map(|(stamp_ns, parent, child, t)| {
        TransformStamped {
            header: Header {
                stamp_ns,
                frame_id: parent,
            },
            child_frame_id: child,
            transform: t,
        }
    })
}

fn order() -> impl Strategy<Value = ByteOrder> {
    prop::sample::select(vec![ByteOrder::Little, ByteOrder::Big])
}

fn valid(t: &Transform) -> bool {
    t.check().is_ok()
}

/// Bitwise equality of transforms (NaN and signed zeros told apart).
fn bits(t: &Transform) -> Vec<u64> {
    t.translation_m
        .iter()
        .chain(&t.rotation)
        .map(|v| v.to_bits())
        .collect()
}

fn close(a: [f64; 3], b: [f64; 3], tolerance: f64) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tolerance)
}

// ---- properties -------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..300), offset in 0usize..1000) {
        let mut framed = vec![0u8, 1, 0, 0];
        framed.extend_from_slice(&bytes);
        for input in [&bytes[..], &framed[..]] {
            let end = (offset + input.len()) as u64;
            let offsets = [
                decode_tf_message(input, offset).err().map(|e| e.offset),
                decode_transform_stamped(input, offset).err().map(|e| e.offset),
                decode_pose_stamped(input, offset).err().map(|e| e.offset),
                decode_pose_stamped_as_pose(input, offset).err().map(|e| e.offset),
                decode_odometry(input, offset).err().map(|e| e.offset),
                decode_point_cloud2(input, offset).err().map(|e| e.offset),
            ];
            for at in offsets.into_iter().flatten() {
                prop_assert!((offset as u64..=end).contains(&at), "offset {at} outside {offset}..={end}");
            }
        }
    }

    #[test]
    fn messages_round_trip_or_are_refused(
        transforms in prop::collection::vec(transform_stamped(), 0..5),
        order in order(),
    ) {
        let all_valid = transforms.iter().all(|t| valid(&t.transform));
        let bytes = ros::encode_tf_message(&transforms, order);
        match decode_tf_message(&bytes, 0) {
            Ok(back) => {
                prop_assert!(all_valid);
                prop_assert_eq!(back.len(), transforms.len());
                for (b, t) in back.iter().zip(&transforms) {
                    prop_assert_eq!(&b.header, &t.header);
                    prop_assert_eq!(&b.child_frame_id, &t.child_frame_id);
                    prop_assert_eq!(bits(&b.transform), bits(&t.transform));
                }
            }
            Err(e) => prop_assert!(!all_valid, "{e}"),
        }
        for cut in 0..bytes.len() {
            prop_assert!(decode_tf_message(&bytes[..cut], 0).is_err());
        }
        for t in &transforms {
            let ok = valid(&t.transform);
            let one = ros::encode_transform_stamped(t, order);
            prop_assert_eq!(decode_transform_stamped(&one, 0).is_ok(), ok);
            let odom = ros::encode_odometry(t, order);
            prop_assert_eq!(decode_odometry(&odom, 0).ok().map(|o| bits(&o.transform)), ok.then(|| bits(&t.transform)));
            let pose = ros::encode_pose_stamped(&t.header, &t.transform, order);
            prop_assert_eq!(decode_pose_stamped(&pose, 0).is_ok(), ok);
            if let Ok((h, p)) = decode_pose_stamped_as_pose(&pose, 0) {
                prop_assert_eq!(h, t.header.clone());
                prop_assert_eq!(Some(p), t.transform.to_pose());
            } else {
                prop_assert!(t.transform.to_pose().is_none());
            }
        }
    }

    #[test]
    fn random_tf_never_panics(
        adds in prop::collection::vec((transform_stamped(), any::<bool>()), 0..24),
        queries in prop::collection::vec((frame(), frame(), stamp()), 0..8),
    ) {
        let mut tree = TfTree::new();
        for (t, is_static) in &adds {
            let before = tree.clone();
            if tree.add(t, *is_static).is_err() {
                prop_assert_eq!(&tree, &before);
            }
        }
        let finished = tree.finish().is_ok();
        for (fixed, frame, stamp_ns) in &queries {
            let got = tree.lookup(fixed, frame, *stamp_ns);
            if !finished {
                prop_assert_eq!(got, Err(Unavailable::NotFinished));
            } else if let Ok(t) = got {
                prop_assert!(t.translation_m.iter().chain(&t.rotation).all(|v| v.is_finite()));
            } else if let Err(e) = got {
                prop_assert!(!e.to_string().is_empty());
            }
            let _ = tree.root_of(frame);
        }
    }

    #[test]
    fn sample_stamps_give_the_samples_bit_for_bit(
        parents in prop::collection::vec(any::<prop::sample::Index>(), 1..6),
        samples in prop::collection::vec((0usize..6, 0i64..40, unit_transform()), 1..30),
    ) {
        // Frames f0 (the root) .. fn; f(i+1)'s parent is an earlier frame. Link 0 (f0 -> f1)
        // is dynamic with the samples; the others are static identity links.
        let name = |i: usize| format!("f{i}");
        let mut tree = TfTree::new();
        let mut parent_of = vec![0usize];
        for (i, p) in parents.iter().enumerate().skip(1) {
            let parent = p.index(i + 1);
            parent_of.push(parent);
            let t = TransformStamped {
                header: Header { stamp_ns: 0, frame_id: name(parent) },
                child_frame_id: name(i + 1),
                transform: Transform::IDENTITY,
            };
            tree.add(&t, true).unwrap();
        }
        let mut last_at = std::collections::BTreeMap::new();
        for (_, stamp_ns, t) in &samples {
            let s = TransformStamped {
                header: Header { stamp_ns: *stamp_ns, frame_id: name(0) },
                child_frame_id: name(1),
                transform: *t,
            };
            tree.add(&s, false).unwrap();
            last_at.insert(*stamp_ns, *t);
        }
        tree.finish().unwrap();
        // Every frame below f1 (through identity links) at a sample stamp: the sample exactly.
        let below_f1 = |mut i: usize| {
            while i > 1 { i = parent_of[i - 1]; }
            i == 1
        };
        for (stamp_ns, t) in &last_at {
            for f in 1..=parents.len() {
                let got = tree.lookup(&name(0), &name(f), *stamp_ns).unwrap();
                if below_f1(f) {
                    prop_assert_eq!(bits(&got), bits(t));
                } else {
                    prop_assert_eq!(got, Transform::IDENTITY);
                }
            }
        }
        // Between two samples the translation lies between theirs.
        let stamps: Vec<i64> = last_at.keys().copied().collect();
        for w in stamps.windows(2) {
            let (a, b) = (last_at[&w[0]], last_at[&w[1]]);
            if w[1] - w[0] > 1 {
                let got = tree.lookup(&name(0), &name(1), w[0] + 1).unwrap();
                for k in 0..3 {
                    let (lo, hi) = (a.translation_m[k].min(b.translation_m[k]), a.translation_m[k].max(b.translation_m[k]));
                    prop_assert!(got.translation_m[k] >= lo - 1e-9 && got.translation_m[k] <= hi + 1e-9);
                }
                let n2: f64 = got.rotation.iter().map(|v| v * v).sum();
                prop_assert!((n2 - 1.0).abs() < 1e-9);
            }
        }
        // The same samples as a pose track.
        let mut track = PoseTrack::new();
        for (_, stamp_ns, t) in &samples {
            track.add(&Header { stamp_ns: *stamp_ns, frame_id: name(0) }, t).unwrap();
        }
        track.finish();
        for (stamp_ns, t) in &last_at {
            prop_assert_eq!(bits(&track.lookup(*stamp_ns).unwrap()), bits(t));
        }
        let first = *stamps.first().unwrap();
        let is_before = matches!(track.lookup(first - 1), Err(Unavailable::Before { .. }));
        prop_assert!(is_before);
    }

    #[test]
    fn compose_with_inverse_is_identity(t in unit_transform(), u in unit_transform(), p in prop::array::uniform3(-10.0f64..10.0)) {
        for x in [t.compose(&t.inverse()), t.inverse().compose(&t)] {
            prop_assert!(close(x.apply(p), p, 1e-9), "{x:?}");
        }
        prop_assert!(close(t.compose(&u).apply(p), t.apply(u.apply(p)), 1e-9));
        prop_assert_eq!(bits(&Transform::IDENTITY.compose(&t)), bits(&t));
        prop_assert_eq!(bits(&t.compose(&Transform::IDENTITY)), bits(&t));
        // Interpolation endpoints are exact; the midpoint of t and t is t.
        prop_assert_eq!(bits(&t.interpolate(&u, 0.0)), bits(&t));
        prop_assert_eq!(bits(&t.interpolate(&u, 1.0)), bits(&u));
        let m = t.interpolate(&t, 0.5);
        prop_assert!(close(m.apply(p), t.apply(p), 1e-9));
    }
}
