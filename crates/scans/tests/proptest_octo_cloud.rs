//! Property tests of the point-cloud readers (`rovlink_scans::cloud`): random clouds written in
//! every format (by the library's writers and by independent writers here that add fields the
//! readers must skip) read back to the same points, colours and pose; random bytes, and random
//! mutations and truncations of valid files, never make a reader panic, and whatever a reader
//! accepts has finite points and one colour per point.

use proptest::prelude::*;
use rovlink_octo::{Pose, Scan};
use rovlink_scans::cloud::{
    self, CloudFormat, McapOptions, PcdData, PlyFormat, read_mcap, read_pcd, read_ply, read_xyz,
    write_clouds_mcap, write_pcd, write_ply, write_ply_as, write_xyz,
};

// ---- strategies -------------------------------------------------------------------------

fn finite() -> impl Strategy<Value = f32> {
    use proptest::num::f32::{NEGATIVE, NORMAL, POSITIVE, SUBNORMAL, ZERO};
    prop_oneof![
        4 => -1000.0f32..1000.0,
        1 => POSITIVE | NEGATIVE | NORMAL | SUBNORMAL | ZERO,
    ]
}

fn pose() -> impl Strategy<Value = Pose> {
    prop_oneof![
        1 => Just(Pose::IDENTITY),
        3 => ([finite(), finite(), finite()], [finite(), finite(), finite(), finite()])
            .prop_map(|(translation_m, rotation)| Pose { translation_m, rotation }),
    ]
}

fn scan() -> impl Strategy<Value = Scan> {
    (
        proptest::collection::vec([finite(), finite(), finite()], 0..40),
        any::<bool>(),
        proptest::collection::vec(any::<[u8; 3]>(), 40),
        pose(),
    )
        .prop_map(|(points, colored, colors, pose)| Scan {
            colors: colored.then(|| colors[..points.len()].to_vec()),
            points,
            pose,
        })
}

/// A scan where some points are NaN or infinite (an organised cloud's holes).
fn scan_with_holes() -> impl Strategy<Value = Scan> {
    (
        scan(),
        proptest::collection::vec(
            prop_oneof![Just(f32::NAN), Just(f32::INFINITY), Just(f32::NEG_INFINITY)],
            40,
        ),
        proptest::collection::vec((any::<bool>(), 0usize..3), 40),
    )
        .prop_map(|(mut s, bad, holes)| {
            for (i, p) in s.points.iter_mut().enumerate() {
                if holes[i].0 {
                    p[holes[i].1] = bad[i];
                }
            }
            s
        })
}

/// `scan` without its non-finite points (and their colours), as the readers give it.
fn finite_only(scan: &Scan) -> Scan {
    let keep: Vec<bool> = scan
        .points
        .iter()
        .map(|p| p.iter().all(|c| c.is_finite()))
        .collect();
    Scan {
        points: scan
            .points
            .iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(p, _)| *p)
            .collect(),
        colors: scan.colors.as_ref().map(|c| {
            c.iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(c, _)| *c)
                .collect()
        }),
        pose: scan.pose,
    }
}

fn without_pose(scan: &Scan) -> Scan {
    Scan {
        pose: Pose::IDENTITY,
        ..scan.clone()
    }
}

// ---- independent writers with fields to skip ---------------------------------------------

/// PLY with, per vertex, a list before y, a double y, a short normal and colours, a camera
/// element before the vertices and faces after them.
fn ply_with_extras(scan: &Scan, format: PlyFormat, lists: &[u8]) -> Vec<u8> {
    let name = match format {
        PlyFormat::Ascii => "ascii",
        PlyFormat::BinaryLittleEndian => "binary_little_endian",
        PlyFormat::BinaryBigEndian => "binary_big_endian",
    };
    let mut out = format!(
        "ply\nformat {name} 1.0\ncomment extras\nelement camera 1\nproperty list uchar float k\n\
         property int id\nelement vertex {}\nproperty float x\nproperty list uint8 int32 idx\n\
         property float64 y\nproperty float z\nproperty int16 nx\n{}element face 2\n\
         property list uchar int vertex_indices\nend_header\n",
        scan.points.len(),
        if scan.colors.is_some() {
            "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        } else {
            ""
        }
    )
    .into_bytes();
    let big = format == PlyFormat::BinaryBigEndian;
    macro_rules! put {
        ($v:expr) => {{
            let v = $v;
            out.extend_from_slice(&if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }};
    }
    match format {
        PlyFormat::Ascii => {
            out.extend_from_slice(b"2 0.5 1.5 7\n");
            for (i, p) in scan.points.iter().enumerate() {
                let n = lists[i % lists.len()] % 4;
                let mut line = format!("{} {n}", p[0]);
                for k in 0..n {
                    line.push_str(&format!(" {k}"));
                }
                line.push_str(&format!(" {} {} -3", f64::from(p[1]), p[2]));
                if let Some(c) = &scan.colors {
                    line.push_str(&format!(" {} {} {}", c[i][0], c[i][1], c[i][2]));
                }
                line.push('\n');
                out.extend_from_slice(line.as_bytes());
            }
            out.extend_from_slice(b"3 0 1 2\n3 2 1 0\n");
        }
        _ => {
            out.push(2);
            put!(0.5f32);
            put!(1.5f32);
            put!(7i32);
            for (i, p) in scan.points.iter().enumerate() {
                put!(p[0]);
                let n = lists[i % lists.len()] % 4;
                out.push(n);
                for k in 0..n {
                    put!(i32::from(k));
                }
                put!(f64::from(p[1]));
                put!(p[2]);
                put!(-3i16);
                if let Some(c) = &scan.colors {
                    out.extend_from_slice(&c[i]);
                }
            }
            for face in [[0i32, 1, 2], [2, 1, 0]] {
                out.push(3);
                for k in face {
                    put!(k);
                }
            }
        }
    }
    out
}

/// Binary PCD with a 3-float normal before the coordinates, a double z, padding and `rgba`.
fn pcd_with_extras(scan: &Scan) -> Vec<u8> {
    let n = scan.points.len();
    let rgba = scan.colors.is_some();
    let t = scan.pose.translation_m;
    let q = scan.pose.rotation;
    let mut out = format!(
        "# .PCD v0.7\nVERSION 0.7\nFIELDS normal x y z _{}\nSIZE 4 4 4 8 1{}\nTYPE F F F F U{}\n\
         COUNT 3 1 1 1 3{}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT {} {} {} {} {} {} {}\nPOINTS {n}\n\
         DATA binary\n",
        if rgba { " rgba" } else { "" },
        if rgba { " 4" } else { "" },
        if rgba { " U" } else { "" },
        if rgba { " 1" } else { "" },
        t[0],
        t[1],
        t[2],
        q[0],
        q[1],
        q[2],
        q[3],
    )
    .into_bytes();
    for (i, p) in scan.points.iter().enumerate() {
        out.extend_from_slice(&[0x7f; 12]);
        out.extend_from_slice(&p[0].to_le_bytes());
        out.extend_from_slice(&p[1].to_le_bytes());
        out.extend_from_slice(&f64::from(p[2]).to_le_bytes());
        out.extend_from_slice(&[1, 2, 3]);
        if let Some(c) = &scan.colors {
            let [r, g, b] = c[i];
            out.extend_from_slice(&u32::from_be_bytes([0xff, r, g, b]).to_le_bytes());
        }
    }
    out
}

// ---- invariants -----------------------------------------------------------------------------

fn check_scan(scan: &Scan) {
    for p in &scan.points {
        assert!(p.iter().all(|c| c.is_finite()), "non-finite point {p:?}");
    }
    if let Some(c) = &scan.colors {
        assert_eq!(c.len(), scan.points.len(), "one colour per point");
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

/// Every reader on `bytes`: no panic, and what is accepted satisfies the invariants.
fn read_all(bytes: &[u8]) {
    let _ = CloudFormat::sniff(bytes);
    for format in CloudFormat::ALL {
        if let Ok(scans) = cloud::read(format, bytes, &McapOptions::default()) {
            scans.iter().for_each(check_scan);
        }
    }
    let named = McapOptions {
        cloud_topic: Some("/points".into()),
        pose_topic: Some("/pose".into()),
    };
    if let Ok(read) = read_mcap(bytes, &named) {
        read.scans.iter().for_each(check_scan);
        assert_eq!(read.scans.len(), read.log_times_ns.len());
    }
}

#[derive(Debug, Clone)]
enum Mutation {
    Flip(usize, u8),
    Insert(usize, u8),
    Remove(usize, usize),
    Truncate(usize),
    /// Replace the `n`th run of ASCII digits with this number.
    Number(usize, u64),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => (any::<usize>(), 1u8..=255).prop_map(|(i, x)| Mutation::Flip(i, x)),
        1 => (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Insert(i, b)),
        1 => (any::<usize>(), 1usize..16).prop_map(|(i, n)| Mutation::Remove(i, n)),
        1 => any::<usize>().prop_map(Mutation::Truncate),
        2 => (
            0usize..24,
            prop_oneof![
                Just(0u64),
                Just(1),
                Just(u64::from(u32::MAX)),
                Just(u64::MAX),
                0u64..100_000
            ]
        )
            .prop_map(|(n, v)| Mutation::Number(n, v)),
    ]
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation) {
    let len = bytes.len();
    match *m {
        Mutation::Flip(i, x) if len > 0 => bytes[i % len] ^= x,
        Mutation::Insert(i, b) => bytes.insert(i % (len + 1), b),
        Mutation::Remove(i, n) if len > 0 => {
            let start = i % len;
            bytes.drain(start..(start + n).min(len));
        }
        Mutation::Truncate(i) => bytes.truncate(i % (len + 1)),
        Mutation::Number(n, v) => {
            let mut runs = Vec::new();
            let mut i = 0;
            while i < len {
                if bytes[i].is_ascii_digit() {
                    let start = i;
                    while i < len && bytes[i].is_ascii_digit() {
                        i += 1;
                    }
                    runs.push(start..i);
                } else {
                    i += 1;
                }
            }
            if let Some(r) = runs.get(n) {
                bytes.splice(r.clone(), v.to_string().into_bytes());
            }
        }
        _ => {}
    }
}

/// A valid file of a random scan in a random format.
fn valid_file() -> impl Strategy<Value = Vec<u8>> {
    (
        proptest::collection::vec(scan(), 1..3),
        0usize..11,
        proptest::collection::vec(any::<u8>(), 1..8),
    )
        .prop_map(|(scans, which, lists)| {
            let s = &scans[0];
            match which {
                0 => write_pcd(s, PcdData::Ascii),
                1 => write_pcd(s, PcdData::Binary),
                2 => write_pcd(s, PcdData::BinaryCompressed),
                3 => pcd_with_extras(s),
                4 => write_ply_as(s, PlyFormat::Ascii),
                5 => write_ply(s),
                6 => ply_with_extras(s, PlyFormat::BinaryBigEndian, &lists),
                7 => ply_with_extras(s, PlyFormat::Ascii, &lists),
                8 => write_xyz(s),
                _ => write_clouds_mcap(&scans),
            }
        })
}

// ---- properties -----------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn pcd_round_trips(s in scan()) {
        for data in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
            let bytes = write_pcd(&s, data);
            prop_assert_eq!(CloudFormat::sniff(&bytes), Some(CloudFormat::Pcd));
            prop_assert_eq!(read_pcd(&bytes).unwrap(), s.clone(), "{:?}", data);
        }
        let extras = read_pcd(&pcd_with_extras(&s)).unwrap();
        prop_assert_eq!(extras, s);
    }

    #[test]
    fn pcd_drops_holes(s in scan_with_holes()) {
        for data in [PcdData::Binary, PcdData::BinaryCompressed, PcdData::Ascii] {
            prop_assert_eq!(read_pcd(&write_pcd(&s, data)).unwrap(), finite_only(&s));
        }
    }

    #[test]
    fn ply_round_trips(s in scan(), lists in proptest::collection::vec(any::<u8>(), 1..8)) {
        let want = without_pose(&s);
        for format in [PlyFormat::Ascii, PlyFormat::BinaryLittleEndian, PlyFormat::BinaryBigEndian] {
            let bytes = write_ply_as(&s, format);
            prop_assert_eq!(CloudFormat::sniff(&bytes), Some(CloudFormat::Ply));
            prop_assert_eq!(read_ply(&bytes).unwrap(), want.clone(), "{:?}", format);
            let extras = read_ply(&ply_with_extras(&s, format, &lists)).unwrap();
            prop_assert_eq!(extras, want.clone(), "extras {:?}", format);
        }
    }

    #[test]
    fn xyz_round_trips(s in scan()) {
        let mut want = without_pose(&s);
        if want.points.is_empty() {
            want.colors = None; // an empty file says nothing about colours
        }
        let bytes = write_xyz(&s);
        prop_assert_eq!(read_xyz(&bytes).unwrap(), want.clone());
        // The same with commas and a header line.
        let text = String::from_utf8(bytes).unwrap().replace(' ', ", ");
        let with_header = format!("# written by a test\nx, y, z, r, g, b\n{text}");
        prop_assert_eq!(read_xyz(with_header.as_bytes()).unwrap(), want);
    }

    #[test]
    fn mcap_round_trips(scans in proptest::collection::vec(scan_with_holes(), 0..4)) {
        let bytes = write_clouds_mcap(&scans);
        let read = read_mcap(&bytes, &McapOptions::default()).unwrap();
        let want: Vec<Scan> = scans.iter().map(finite_only).collect();
        prop_assert_eq!(read.scans, want);
        prop_assert_eq!(read.log_times_ns.len(), scans.len());
    }

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        read_all(&bytes);
        // And behind each format's signature.
        for prefix in [&b"ply\nformat ascii 1.0\n"[..], b"# .PCD v0.7\nFIELDS x y z\n", rovlink_magic()] {
            let mut b = prefix.to_vec();
            b.extend_from_slice(&bytes);
            read_all(&b);
        }
    }

    #[test]
    fn mutated_files_never_panic(
        file in valid_file(),
        mutations in proptest::collection::vec(mutation(), 1..5),
    ) {
        let mut bytes = file;
        for m in &mutations {
            apply(&mut bytes, m);
        }
        read_all(&bytes);
    }

    #[test]
    fn truncated_files_never_panic(file in valid_file(), cut in any::<usize>()) {
        read_all(&file[..cut % (file.len() + 1)]);
    }
}

fn rovlink_magic() -> &'static [u8] {
    b"\x89MCAP0\r\n"
}
