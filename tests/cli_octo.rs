//! octo-delta as a process: maps equal to OctoMap's (its own tools are the judge: graph2tree,
//! compare_octrees, convert_octree, bt2vrml from Debian's octomap-tools, which `.ci/run`
//! installs), the delta stream rebuilding the map's view, stats, the link, bad input.

use std::path::Path;

use crate::common::{assert_kld_zero, octomap_tool, run};

const OCTO: &str = env!("TOOL_EXE_octo-delta");
const GEB079: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/testdata/maps/geb079.bt");
const APPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/testdata/maps/apple.pcd");

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn synth(dir: &Path, scans: &str) -> std::path::PathBuf {
    let graph = dir.join("survey.graph");
    let out = run(OCTO, &["synth", "--scans", scans, "-o", s(&graph)], b"");
    assert_eq!(out.code, 0, "{}", out.stderr);
    graph
}

#[test]
fn maps_are_octomaps_own_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let graph = synth(dir.path(), "10");
    for res in ["0.1", "0.15"] {
        let (ot, bt) = (dir.path().join("ours.ot"), dir.path().join("ours.bt"));
        let out = run(
            OCTO,
            &[
                "build",
                s(&graph),
                "--res",
                res,
                "--no-color",
                "-o",
                s(&dir.path().join("d.odl")),
                "--ot",
                s(&ot),
                "--bt",
                s(&bt),
            ],
            b"",
        );
        assert_eq!(out.code, 0, "{}", out.stderr);
        let reference = dir.path().join("ref.bt");
        octomap_tool(
            "graph2tree",
            &["-i", s(&graph), "-o", s(&reference), "-res", res],
        );
        let ref_ot = dir.path().join("ref.bt.ot");
        assert!(
            std::fs::read(&ot).unwrap() == std::fs::read(&ref_ot).unwrap(),
            ".ot differs at {res}"
        );
        assert!(
            std::fs::read(&bt).unwrap() == std::fs::read(&reference).unwrap(),
            ".bt differs at {res}"
        );
        assert_kld_zero(&ot, &ref_ot, &format!("res {res}"));
        // bt2vrml reads our .bt.
        octomap_tool("bt2vrml", &[s(&bt)]);
    }
}

#[test]
fn a_full_map_round_trips_through_octomaps_converter() {
    let dir = tempfile::tempdir().unwrap();
    let (odl, view, bt) = (
        dir.path().join("f.odl"),
        dir.path().join("v.ot"),
        dir.path().join("v.bt"),
    );
    let out = run(OCTO, &["full", GEB079, "-o", s(&odl)], b"");
    assert_eq!(out.code, 0, "{}", out.stderr);
    let out = run(OCTO, &["apply", s(&odl), "-o", s(&view)], b"");
    assert_eq!(out.code, 0, "{}", out.stderr);
    octomap_tool("convert_octree", &[s(&view), s(&bt)]);
    assert!(
        std::fs::read(&bt).unwrap() == std::fs::read(GEB079).unwrap(),
        "geb079.bt -> full -> apply -> convert_octree is not geb079.bt"
    );
}

#[test]
fn applied_deltas_equal_the_view_of_the_final_map() {
    let dir = tempfile::tempdir().unwrap();
    let graph = synth(dir.path(), "12");
    for roi in [None, Some("-4,-4,-10,2,3,10")] {
        let (odl, ot, stats) = (
            dir.path().join("d.odl"),
            dir.path().join("m.ot"),
            dir.path().join("s.csv"),
        );
        let mut args = vec![
            "build",
            s(&graph),
            "--res",
            "0.15",
            "-o",
            s(&odl),
            "--ot",
            s(&ot),
            "--stats",
            s(&stats),
            "--coarse-depth",
            "13",
        ];
        if let Some(r) = roi {
            args.extend(["--roi", r]);
        }
        let out = run(OCTO, &args, b"");
        assert_eq!(out.code, 0, "{}", out.stderr);
        let rows = std::fs::read_to_string(&stats).unwrap();
        assert_eq!(rows.lines().count(), 13, "{rows}");
        assert!(rows.starts_with("scan,points,delta_bytes,fine_occupied,fine_free,coarse_occupied,coarse_free,full_bt_bytes,full_ot_bytes,cum_delta_bytes,cum_full_bt_bytes,cum_full_ot_bytes,points_skipped,insert_ms\n"));
        let (v1, v2, full) = (
            dir.path().join("v1.ot"),
            dir.path().join("v2.ot"),
            dir.path().join("f.odl"),
        );
        assert_eq!(run(OCTO, &["apply", s(&odl), "-o", s(&v1)], b"").code, 0);
        let mut fargs = vec!["full", s(&ot), "-o", s(&full), "--coarse-depth", "13"];
        if let Some(r) = roi {
            fargs.extend(["--roi", r]);
        }
        let out = run(OCTO, &fargs, b"");
        assert_eq!(out.code, 0, "{}", out.stderr);
        assert_eq!(run(OCTO, &["apply", s(&full), "-o", s(&v2)], b"").code, 0);
        assert!(
            std::fs::read(&v1).unwrap() == std::fs::read(&v2).unwrap(),
            "views differ (roi {roi:?})"
        );
        let head = String::from_utf8_lossy(&std::fs::read(&v1).unwrap()[..120]).into_owned();
        assert!(head.contains("id OcTree"), "a .graph has no colour: {head}");
        // dump lists one message per scan.
        let out = run(OCTO, &["dump", s(&odl), "--format", "csv"], b"");
        assert_eq!(out.code, 0, "{}", out.stderr);
        assert_eq!(out.stdout_text().lines().count(), 13);
    }
}

#[test]
fn link_reports_when_each_scan_arrives() {
    let dir = tempfile::tempdir().unwrap();
    let graph = synth(dir.path(), "4");
    let out = run(
        OCTO,
        &[
            "build",
            s(&graph),
            "--res",
            "0.2",
            "-o",
            s(&dir.path().join("d.odl")),
            "--link",
            "satellite-up",
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(
        out.stderr.contains("link satellite-up: 4 messages"),
        "{}",
        out.stderr
    );
    assert!(
        out.stderr.contains("scan ready -> shown at the operator"),
        "{}",
        out.stderr
    );
}

#[test]
fn point_clouds_build_coloured_maps_that_octomap_reads() {
    let dir = tempfile::tempdir().unwrap();
    let (ot, bt) = (dir.path().join("a.ot"), dir.path().join("a.bt"));
    let out = run(
        OCTO,
        &[
            "build",
            APPLE,
            "--res",
            "0.01",
            "--origin",
            "0,0,0",
            "-o",
            s(&dir.path().join("a.odl")),
            "--ot",
            s(&ot),
            "--bt",
            s(&bt),
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    let head = String::from_utf8_lossy(&std::fs::read(&ot).unwrap()[..140]).into_owned();
    assert!(head.contains("id ColorOcTree"), "{head}");
    octomap_tool("bt2vrml", &[s(&bt)]);
    octomap_tool("convert_octree", &[s(&ot), s(&dir.path().join("b.ot"))]);
}

#[test]
fn bad_inputs_are_one_line_errors_with_offsets_and_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let graph = synth(dir.path(), "2");
    let bytes = std::fs::read(&graph).unwrap();
    let cut = dir.path().join("cut.graph");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let odl = dir.path().join("never.odl");
    let out = run(OCTO, &["build", s(&cut), "-o", s(&odl)], b"");
    assert_eq!(out.code, 2, "{}", out.stderr);
    assert!(out.stderr.contains("cut.graph: offset"), "{}", out.stderr);
    assert_eq!(out.stderr.lines().count(), 1, "{}", out.stderr);
    assert!(!odl.exists(), "no half-finished output");

    let junk = dir.path().join("junk.odl");
    std::fs::write(&junk, b"ODL1\x01\x00garbage").unwrap();
    let out = run(OCTO, &["dump", s(&junk)], b"");
    assert_eq!(out.code, 2);
    assert!(out.stderr.contains("junk.odl: offset"), "{}", out.stderr);

    let notmap = dir.path().join("x.ot");
    std::fs::write(
        &notmap,
        b"# Octomap OcTree file\nid OcTree\nsize 3\nres 0.1\ndata\n\x00\x00",
    )
    .unwrap();
    let out = run(OCTO, &["full", s(&notmap)], b"");
    assert_eq!(out.code, 2);
    assert!(out.stderr.contains("x.ot: offset"), "{}", out.stderr);

    let out = run(OCTO, &["build", s(&graph), "--roi", "1,2,3"], b"");
    assert_eq!(out.code, 2);
}

#[test]
fn points_outside_the_key_range_are_counted_not_wrapped() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("far.xyz");
    std::fs::write(&xyz, "1 0 0\n5000 0 0\n0 -4000 0\n0.5 0.5 0\n").unwrap();
    let ot = dir.path().join("far.ot");
    let out = run(
        OCTO,
        &[
            "build",
            s(&xyz),
            "--res",
            "0.1",
            "-o",
            s(&dir.path().join("d.odl")),
            "--ot",
            s(&ot),
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(
        out.stderr
            .contains("4 points (2 outside the map's key range skipped"),
        "{}",
        out.stderr
    );
}

#[test]
fn mcap_surveys_build_the_same_map_as_graphs_and_keep_colour() {
    let dir = tempfile::tempdir().unwrap();
    let graph = synth(dir.path(), "5");
    let mcap = dir.path().join("survey.mcap");
    let out = run(OCTO, &["synth", "--scans", "5", "-o", s(&mcap)], b"");
    assert_eq!(out.code, 0, "{}", out.stderr);
    let (a, b, c) = (
        dir.path().join("g.ot"),
        dir.path().join("m.ot"),
        dir.path().join("mc.ot"),
    );
    let d = s(&dir.path().join("d.odl")).to_string();
    assert_eq!(
        run(
            OCTO,
            &["build", s(&graph), "--res", "0.2", "-o", &d, "--ot", s(&a)],
            b""
        )
        .code,
        0
    );
    let out = run(
        OCTO,
        &[
            "build",
            s(&mcap),
            "--res",
            "0.2",
            "--no-color",
            "-o",
            &d,
            "--ot",
            s(&b),
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(
        std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(),
        "MCAP and .graph maps differ"
    );
    let out = run(
        OCTO,
        &["build", s(&mcap), "--res", "0.2", "-o", &d, "--ot", s(&c)],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    let head = String::from_utf8_lossy(&std::fs::read(&c).unwrap()[..140]).into_owned();
    assert!(head.contains("id ColorOcTree"), "{head}");
    octomap_tool("convert_octree", &[s(&c), s(&dir.path().join("copy.ot"))]);
}
