//! Property tests of scan insertion: arbitrary finite points (tiny, huge, subnormal, equal to
//! the origin or a hair from it) and arbitrary sensor poses insert into trees of any accepted
//! resolution without hanging or panicking, every point counted once, every reported change
//! what the tree then holds. Each case runs on its own thread under a time limit, so a ray walk
//! that never ends fails the test instead of hanging it (issue 14: a point at -1e-30 from the
//! origin made `octo-delta build` loop forever).

use std::sync::mpsc;
use std::time::Duration;

use proptest::prelude::*;
use rovlink_octo::tree::{OcTree, TREE_DEPTH};
use rovlink_octo::{Pose, Scan};

/// Finite `f32`s weighted towards the extremes: subnormals, the smallest normals, values whose
/// squares underflow or overflow, ordinary coordinates, zeros.
fn finite_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        3 => any::<u32>()
            .prop_map(f32::from_bits)
            .prop_filter("finite", |v| v.is_finite()),
        2 => -50.0f32..50.0,
        2 => (1u32..0x0080_0000).prop_map(f32::from_bits).prop_flat_map(|v| prop_oneof![Just(v), Just(-v)]),
        2 => prop::sample::select(vec![
            0.0,
            -0.0,
            1e-30,
            -1e-30,
            1e-23,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            1e19,
            -2e19,
            3e37,
            f32::MAX,
            f32::MIN,
        ]),
    ]
}

/// A point: anywhere, or the origin itself, or the origin plus a tiny offset.
fn point(origin: [f32; 3]) -> impl Strategy<Value = [f32; 3]> {
    prop_oneof![
        3 => prop::array::uniform3(finite_f32()),
        1 => Just(origin),
        2 => prop::array::uniform3(prop::sample::select(vec![0.0f32, 1e-30, -1e-30, 1e-45, -1e-45, 1e-38]))
            .prop_map(move |d| [origin[0] + d[0], origin[1] + d[1], origin[2] + d[2]]),
    ]
}

#[derive(Debug, Clone)]
struct Case {
    resolution_m: f64,
    max_range_m: Option<f64>,
    rotation: [f32; 4],
    origin: [f32; 3],
    /// In the map frame, before the pose's inverse.
    points: Vec<[f32; 3]>,
}

fn case() -> impl Strategy<Value = Case> {
    let origin = prop_oneof![
        2 => Just([0.0f32; 3]),
        1 => prop::array::uniform3(finite_f32()),
        1 => prop::array::uniform3(-20.0f32..20.0),
    ];
    (
        prop::sample::select(vec![1e-4, 0.01, 0.1, 0.37, 2.0, 1e3]),
        prop::option::of(prop::sample::select(vec![1e-4, 0.5, 5.0, 1e5])),
        prop_oneof![
            3 => Just([1.0f32, 0.0, 0.0, 0.0]),
            1 => prop::array::uniform4(finite_f32()),
        ],
        origin,
    )
        .prop_flat_map(|(resolution_m, max_range_m, rotation, origin)| {
            prop::collection::vec(point(origin), 0..12).prop_map(move |points| Case {
                resolution_m,
                max_range_m,
                rotation,
                origin,
                points,
            })
        })
}

/// Inserts the case's scan twice (a second pass hits known space) on a thread; `None` if it
/// did not finish within the limit.
fn insert(case: Case) -> Option<Result<(), String>> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut tree = OcTree::new(case.resolution_m);
        let o = case.origin;
        let scan = Scan {
            // Identity rotation: points given in the map frame go to the sensor frame by the
            // translation alone (with another rotation they are simply other points).
            points: case
                .points
                .iter()
                .map(|p| [p[0] - o[0], p[1] - o[1], p[2] - o[2]])
                .collect(),
            colors: None,
            pose: Pose {
                translation_m: o,
                rotation: case.rotation,
            },
        };
        let mut outcome = Ok(());
        for _ in 0..2 {
            let up = tree.insert_scan(&scan, case.max_range_m);
            if up.points != scan.points.len()
                || up.points_skipped + up.points_beyond_range > up.points
            {
                outcome = Err(format!("bad counts {up:?}"));
            }
            for ch in &up.changes {
                let held = tree
                    .search(ch.code, TREE_DEPTH)
                    .map(|(n, _)| tree.node(n).log_odds >= 0.0);
                if held != Some(ch.occupied) {
                    outcome = Err(format!("change {ch:?}, tree holds {held:?}"));
                }
            }
        }
        let _ = tx.send(outcome);
    });
    rx.recv_timeout(Duration::from_secs(30)).ok()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 384, ..ProptestConfig::default() })]

    #[test]
    fn any_finite_points_insert_without_hanging(c in case()) {
        let shown = format!("{c:?}");
        match insert(c) {
            None => prop_assert!(false, "insertion did not finish within 30 s: {shown}"),
            Some(r) => prop_assert_eq!(r, Ok(()), "{}", shown),
        }
    }
}

#[test]
fn the_issue_point_and_its_neighbours_insert_at_once() {
    for (origin, p) in [
        ([0.0f32; 3], [-1e-30f32; 3]),
        ([0.0; 3], [1e-30, -1e-30, 1e-30]),
        ([0.0; 3], [f32::from_bits(1); 3]),
        ([1e-30, 1e-30, 1e-30], [-1e-30; 3]),
        ([0.0; 3], [0.0; 3]),
    ] {
        let case = Case {
            resolution_m: 0.1,
            max_range_m: None,
            rotation: [1.0, 0.0, 0.0, 0.0],
            origin,
            points: vec![p],
        };
        assert_eq!(insert(case), Some(Ok(())), "{origin:?} -> {p:?}");
    }
}
