//! A live ROS 2 graph's messages from any bytes: `scans::live::LivePoser` fed a run of
//! messages (a kind byte and a length byte before each: static TF, dynamic TF, pose, cloud)
//! and asked for its clouds at growing times never panics, hands out at most one item per
//! cloud, poses only with finite numbers, and keeps at most `max_pending` clouds waiting.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_scans::live::{LiveOptions, LivePoseSource, LivePoser};
use rovlink_scans::recording::Item;
use rovlink_scans::ros;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, mut rest)) = data.split_first() else {
        return;
    };
    let source = match mode % 3 {
        0 => LivePoseSource::Tf,
        1 => LivePoseSource::Track {
            topic: "/pose".into(),
            schema: ros::ODOMETRY_SCHEMA.into(),
        },
        _ => LivePoseSource::Fixed,
    };
    let options = LiveOptions {
        source,
        wait_ns: i64::from(mode >> 2) * 1_000,
        max_pending: 3,
        ..LiveOptions::default()
    };
    let mut p = LivePoser::new(options);
    let (mut clouds, mut items, mut now) = (0u64, 0u64, 0i64);
    while let [kind, len, tail @ ..] = rest {
        let n = usize::from(*len).min(tail.len());
        let (message, next) = tail.split_at(n);
        rest = next;
        now += 500;
        match kind % 4 {
            0 => drop(p.tf(message, true)),
            1 => drop(p.tf(message, false)),
            2 => drop(p.pose(message)),
            _ => {
                if let Ok(dropped) = p.cloud(message, now) {
                    clouds += 1;
                    items += u64::from(dropped.is_some());
                }
            }
        }
        assert!(p.pending() <= 3);
        for item in p.ready(now) {
            items += 1;
            if let Item::Scan(s) = item {
                assert!(s.pose.translation_m.iter().all(|v| v.is_finite()));
            }
        }
    }
    items += p.flush().len() as u64;
    assert_eq!(items, clouds, "every cloud handed out once");
});
