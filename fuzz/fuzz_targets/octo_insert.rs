//! Scan insertion itself (`OcTree::insert_scan`): parsed clouds and raw floats through the tree,
//! each input within a time bound.
//!
//! Input: byte 0 chooses the mode and the tree. Bits 0-1: the resolution, one of 0.0001, 0.1,
//! 7.3 and 1000 m (the extremes octo-delta accepts); bit 2: a maximum range (derived from byte
//! 1); bit 3: colours kept; bit 4: raw mode. Raw mode reads the rest as little-endian `f32`
//! triples, the first the sensor origin and the others points (any bit pattern: subnormals,
//! huge values, the origin itself, NaN and infinities); otherwise the rest is a point-cloud file
//! read by every reader of `octo::pipeline::InputFormat` that accepts it (`.graph`, PCD, PLY,
//! XYZ, MCAP). At most 4 scans of 48 points each are inserted, so an input costs at most
//! 192 rays of at most 3 x 65 536 cells.
//!
//! Checks: insertion returns (the target asserts each scan takes less than 20 s; libFuzzer's
//! `-timeout` catches a walk that never ends), never panics, counts every point once (inserted,
//! skipped or beyond range), reports changes in Morton order whose occupancy is what the tree
//! now holds, and the map written as `.ot` and `.bt` reads back.

#![no_main]

use std::time::{Duration, Instant};

use libfuzzer_sys::fuzz_target;
use rovlink_scans::cloud::McapOptions;
use rovlink_mapper::pipeline::InputFormat;
use rovlink_octo::tree::{OcTree, TREE_DEPTH};
use rovlink_octo::{Pose, Scan, files};

const MAX_SCANS: usize = 4;
const MAX_POINTS: usize = 48;
const RESOLUTIONS_M: [f64; 4] = [1e-4, 0.1, 7.3, 1e3];

fn raw_scan(bytes: &[u8]) -> Vec<Scan> {
    let floats: Vec<[f32; 3]> = bytes
        .chunks_exact(12)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]);
            [f(0), f(4), f(8)]
        })
        .collect();
    let Some((&origin, points)) = floats.split_first() else {
        return Vec::new();
    };
    vec![Scan {
        points: points.to_vec(),
        colors: None,
        pose: Pose {
            translation_m: origin,
            rotation: [1.0, 0.0, 0.0, 0.0],
        },
    }]
}

fn parsed_scans(bytes: &[u8]) -> Vec<Scan> {
    let mut scans = Vec::new();
    for format in InputFormat::ALL {
        if let Ok(s) = format.read(bytes, &McapOptions::default()) {
            scans.extend(s);
        }
    }
    scans
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let resolution_m = RESOLUTIONS_M[(mode & 3) as usize];
    let max_range_m = (mode & 4 != 0).then(|| rest.first().map_or(1.0, |&b| b as f64 * 0.37));
    let mut scans = if mode & 16 != 0 {
        raw_scan(rest)
    } else {
        parsed_scans(rest)
    };
    scans.truncate(MAX_SCANS);
    let mut tree = OcTree::new(resolution_m);
    if mode & 8 != 0 {
        tree.enable_color();
    }
    for scan in &mut scans {
        scan.points.truncate(MAX_POINTS);
        if let Some(c) = &mut scan.colors {
            c.truncate(MAX_POINTS);
        }
        let started = Instant::now();
        let up = tree.insert_scan(scan, max_range_m);
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "{} points took {:?}",
            scan.points.len(),
            started.elapsed()
        );
        assert_eq!(up.points, scan.points.len());
        assert!(up.points_skipped + up.points_beyond_range <= up.points);
        assert!(up.occupied_voxels <= up.points - up.points_skipped);
        assert!(up.changes.windows(2).all(|w| w[0].code < w[1].code));
        for ch in &up.changes {
            let (node, _) = tree
                .search(ch.code, TREE_DEPTH)
                .expect("a changed voxel is known");
            let occupied = tree.node(node).log_odds >= 0.0;
            assert_eq!(occupied, ch.occupied, "change {ch:?}");
        }
    }
    let ot = files::read_map(&files::write_ot(&tree)).expect("the .ot reads back");
    assert_eq!(ot.num_nodes(), tree.num_nodes());
    files::read_map(&files::write_bt(&tree)).expect("the .bt reads back");
});
