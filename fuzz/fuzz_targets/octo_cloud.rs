//! The point-cloud readers of `octo::cloud` (PCD, PLY, XYZ, MCAP) on arbitrary bytes.
//!
//! Checks: no reader (nor `sniff`) panics; every accepted scan has finite points, exactly one
//! colour per point when it has colours, and a finite pose; an accepted MCAP result has one log
//! time per scan; and what is accepted, written back by the library's writers, reads back the
//! same: PCD in all three data forms (pose included), PLY (binary and ASCII), XYZ (an empty
//! scan's colours aside), MCAP (every scan, with its pose).

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_octo::Scan;
use rovlink_scans::cloud::{
    self, McapOptions, PcdData, PlyFormat, read_mcap, read_pcd, read_ply, read_xyz,
    write_clouds_mcap, write_pcd, write_ply, write_ply_as, write_xyz,
};

fn check(scan: &Scan) {
    for p in &scan.points {
        assert!(p.iter().all(|c| c.is_finite()), "non-finite point {p:?}");
    }
    if let Some(colors) = &scan.colors {
        assert_eq!(colors.len(), scan.points.len(), "one colour per point");
    }
    let pose = scan.pose;
    assert!(
        pose.translation_m
            .iter()
            .chain(&pose.rotation)
            .all(|v| v.is_finite()),
        "non-finite pose {pose:?}"
    );
}

fuzz_target!(|data: &[u8]| {
    let _ = cloud::sniff(data);
    if let Ok(scan) = read_pcd(data) {
        check(&scan);
        for form in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
            let back = read_pcd(&write_pcd(&scan, form)).expect("written PCD reads back");
            assert_eq!(back, scan, "PCD {form:?} round trip");
        }
    }
    if let Ok(scan) = read_ply(data) {
        check(&scan);
        assert_eq!(
            read_ply(&write_ply(&scan)).expect("written PLY reads back"),
            scan
        );
        let ascii = write_ply_as(&scan, PlyFormat::Ascii);
        assert_eq!(
            read_ply(&ascii).expect("written ASCII PLY reads back"),
            scan
        );
    }
    if let Ok(scan) = read_xyz(data) {
        check(&scan);
        let mut back = read_xyz(&write_xyz(&scan)).expect("written XYZ reads back");
        if scan.points.is_empty() {
            back.colors.clone_from(&scan.colors);
        }
        assert_eq!(back, scan, "XYZ round trip");
    }
    if let Ok(read) = read_mcap(data, &McapOptions::default()) {
        read.scans.iter().for_each(check);
        assert_eq!(read.scans.len(), read.log_times_ns.len());
        let again = read_mcap(&write_clouds_mcap(&read.scans), &McapOptions::default())
            .expect("written MCAP reads back");
        assert_eq!(again.scans, read.scans, "MCAP round trip");
    }
});
