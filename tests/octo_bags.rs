//! octo-delta on robot logs written by the real ROS 2 writers (Python `rosbags` for rosbag2
//! sqlite3 and mcap storage, the official `mcap` and `mcap_ros2` writers for MCAP with zstd, lz4
//! and no compression, rosbag2's zstd FILE and MESSAGE compression; `tests/bags/survey_bag.py`), posed by /tf + /tf_static, PoseStamped or
//! Odometry: every map must be graph2tree's map of the same scans (the .bt byte for byte, and
//! compare_octrees' KLD 0). Also the ways a log can be unusable: no pose, malformed TF, a
//! database that is not a bag, a cut compressed chunk: exit 2, one line, no output left.
//!
//! `.ci/run` installs the Python packages (pip) and OctoMap's tools (apt); without them these
//! tests fail saying what to install.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use crate::common::{assert_kld_zero, octomap_tool, run};

const OCTO: &str = env!("TOOL_EXE_octo-delta");
const WRITER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/bags/survey_bag.py");
const RES: &str = "0.2";

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A 6-scan survey and graph2tree's map of it, made once for all tests.
struct Survey {
    _dir: tempfile::TempDir,
    graph: PathBuf,
    reference_bt: Vec<u8>,
    reference_bt_path: PathBuf,
}

fn survey() -> &'static Survey {
    static SURVEY: OnceLock<Survey> = OnceLock::new();
    SURVEY.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let graph = dir.path().join("survey.graph");
        let out = run(OCTO, &["synth", "--scans", "6", "-o", s(&graph)], b"");
        assert_eq!(out.code, 0, "{}", out.stderr);
        let reference = dir.path().join("ref.bt");
        octomap_tool(
            "graph2tree",
            &["-i", s(&graph), "-o", s(&reference), "-res", RES],
        );
        Survey {
            reference_bt: std::fs::read(&reference).unwrap(),
            reference_bt_path: reference,
            graph,
            _dir: dir,
        }
    })
}

/// Writes a bag of the survey with the real writers; `extra` are survey_bag.py flags.
fn write_bag(dir: &Path, kind: &str, extra: &[&str]) -> PathBuf {
    let mut out = dir.join(format!("bag-{kind}"));
    if kind.starts_with("mcap") {
        out.set_extension("mcap");
    }
    let result = Command::new("python3")
        .arg(WRITER)
        .args([
            "--graph",
            s(&survey().graph),
            "--kind",
            kind,
            "--out",
            s(&out),
        ])
        .args(extra)
        .output()
        .unwrap_or_else(|e| panic!("python3 not runnable ({e})"));
    assert!(
        result.status.success(),
        "{WRITER} --kind {kind} {extra:?} failed (it needs `pip install mcap mcap-ros2-support \
         rosbags`): {}",
        String::from_utf8_lossy(&result.stderr)
    );
    out
}

/// Builds `input`'s map (no colour, .bt) with `flags`; returns the outcome and the .bt path.
fn build(dir: &Path, input: &Path, flags: &[&str]) -> (crate::common::Outcome, PathBuf) {
    let bt = dir.join("ours.bt");
    let _ = std::fs::remove_file(&bt);
    let mut args = vec!["build", s(input), "--res", RES, "-q", "-o"];
    let odl = dir.join("d.odl");
    args.push(s(&odl));
    args.extend(["--bt", s(&bt)]);
    args.extend(flags);
    let out = run(OCTO, &args, b"");
    (out, bt)
}

/// The map of `input` is graph2tree's: same .bt bytes, KLD 0.
fn assert_same_map(dir: &Path, input: &Path, flags: &[&str], what: &str) -> crate::common::Outcome {
    let (out, bt) = build(dir, input, flags);
    assert_eq!(out.code, 0, "{what}: {}", out.stderr);
    let ours = std::fs::read(&bt).unwrap();
    assert!(
        ours == survey().reference_bt,
        "{what}: the .bt differs from graph2tree's ({} vs {} bytes)",
        ours.len(),
        survey().reference_bt.len()
    );
    // compare_octrees reads OcTree .ot files: the map again without colour.
    let ot = dir.join("ours.ot");
    let mut args = vec![
        "build",
        s(input),
        "--res",
        RES,
        "-q",
        "--no-color",
        "-o",
        "-",
    ];
    args.extend(["--ot", s(&ot)]);
    args.extend(flags);
    let plain = run(OCTO, &args, b"");
    assert_eq!(plain.code, 0, "{what}: {}", plain.stderr);
    let reference_ot = survey().reference_bt_path.with_extension("bt.ot");
    assert_kld_zero(&ot, &reference_ot, what);
    out
}

#[test]
fn every_bag_kind_gives_graph2trees_map() {
    let dir = tempfile::tempdir().unwrap();
    for kind in [
        "db3",
        "db3-file-zstd",
        "db3-message-zstd",
        "rosbag2-mcap",
        "mcap-zstd",
        "mcap-lz4",
        "mcap-none",
        "mcap-ros2",
    ] {
        // Coloured, organised clouds with NaN holes, posed by a TF chain.
        let bag = write_bag(dir.path(), kind, &["--color", "--organised"]);
        assert_same_map(dir.path(), &bag, &[], kind);
    }
}

#[test]
fn a_rosbag2_directory_opens_by_its_directory_metadata_or_database() {
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), "db3", &[]);
    let db3 = std::fs::read_dir(&bag)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "db3"))
        .expect("a .db3 in the bag");
    for input in [bag.clone(), bag.join("metadata.yaml"), db3] {
        assert_same_map(dir.path(), &input, &[], &input.display().to_string());
    }
}

#[test]
fn pose_topics_pose_the_clouds() {
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), "mcap-zstd", &["--pose", "pose"]);
    assert_same_map(dir.path(), &bag, &[], "PoseStamped found by its schema");
    assert_same_map(
        dir.path(),
        &bag,
        &["--pose-topic", "/pose"],
        "PoseStamped named",
    );
    let bag = write_bag(dir.path(), "db3", &["--pose", "odom"]);
    assert_same_map(
        dir.path(),
        &bag,
        &["--pose-topic", "/odom"],
        "Odometry named",
    );
    let bag = write_bag(dir.path(), "rosbag2-mcap", &["--pose", "transform"]);
    assert_same_map(
        dir.path(),
        &bag,
        &["--pose-topic", "/sensor_pose"],
        "TransformStamped named",
    );
}

#[test]
fn a_cloud_without_a_pose_is_skipped_with_one_warning_naming_the_frames() {
    let dir = tempfile::tempdir().unwrap();
    // One more cloud, stamped after the last transform.
    let bag = write_bag(dir.path(), "mcap-lz4", &["--late"]);
    let out = assert_same_map(dir.path(), &bag, &[], "late cloud");
    let warnings: Vec<&str> = out
        .stderr
        .lines()
        .filter(|l| l.contains("skipped"))
        .collect();
    assert_eq!(warnings.len(), 1, "{}", out.stderr);
    assert!(
        warnings[0].contains("sensor") && warnings[0].contains("map"),
        "{}",
        out.stderr
    );
}

#[test]
fn a_bag_without_poses_is_an_error_unless_origin_is_given() {
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), "mcap-none", &["--pose", "none"]);
    let (out, bt) = build(dir.path(), &bag, &[]);
    assert_eq!(out.code, 2, "{}", out.stderr);
    assert_eq!(out.stderr.trim().lines().count(), 1, "{}", out.stderr);
    assert!(
        out.stderr.contains("bag-mcap-none.mcap") && out.stderr.contains("--origin"),
        "{}",
        out.stderr
    );
    assert!(!bt.exists(), "no output after an error");
    let (out, bt) = build(dir.path(), &bag, &["--origin", "0,0,0"]);
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(bt.exists());
}

#[test]
fn the_fixed_frame_can_be_named_and_must_exist() {
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), "mcap-zstd", &[]);
    assert_same_map(dir.path(), &bag, &["--fixed-frame", "map"], "map named");
    // /tf named as the pose topic: read with /tf_static beside it.
    assert_same_map(dir.path(), &bag, &["--pose-topic", "/tf"], "/tf named");
    let (out, _) = build(dir.path(), &bag, &["--fixed-frame", "nowhere"]);
    assert_eq!(out.code, 2, "{}", out.stderr);
    assert!(out.stderr.contains("nowhere"), "{}", out.stderr);
}

/// An unusable log: exit 2, one line naming the file, no output files.
fn assert_refused(dir: &Path, input: &Path, needle: &str) {
    let (out, bt) = build(dir, input, &[]);
    assert_eq!(out.code, 2, "{}: {}", input.display(), out.stderr);
    assert_eq!(out.stderr.trim().lines().count(), 1, "{}", out.stderr);
    assert!(
        out.stderr.contains(needle),
        "expected {needle:?} in: {}",
        out.stderr
    );
    assert!(!bt.exists(), "no .bt after an error");
    assert!(!dir.join("d.odl").exists(), "no stream after an error");
}

#[test]
fn malformed_tf_is_refused_naming_the_frames() {
    let dir = tempfile::tempdir().unwrap();
    for (fault, needle) in [
        ("cycle", "cycle"),
        ("two-parents", "sensor"),
        ("nan", "NaN"),
    ] {
        let bag = write_bag(dir.path(), "mcap-none", &["--tf-fault", fault]);
        assert_refused(dir.path(), &bag, needle);
    }
}

#[test]
fn a_database_that_is_not_a_bag_and_a_cut_chunk_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let not_bag = dir.path().join("other.db3");
    let made = Command::new("python3")
        .arg("-c")
        .arg(format!(
            "import sqlite3; c = sqlite3.connect({:?}); c.execute('create table t(x)'); c.commit()",
            s(&not_bag)
        ))
        .status()
        .unwrap();
    assert!(made.success());
    assert_refused(dir.path(), &not_bag, "other.db3");

    let bag = write_bag(dir.path(), "mcap-zstd", &[]);
    let bytes = std::fs::read(&bag).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    assert_refused(dir.path(), &cut, "cut.mcap");
}

#[test]
fn a_bag_one_pass_cannot_pose_is_built_again_in_two_passes() {
    // map -> odom (3 m along x) logged after the first cloud: a build to files reads the bag in
    // one pass, finds at its end that the first cloud was posed in odom, says so once and
    // builds again; a build to standard output reads every transform first. Same map, same
    // stream.
    let dir = tempfile::tempdir().unwrap();
    let bag = write_bag(dir.path(), "mcap-zstd", &["--late-root", "3"]);
    let bt = |name: &str| dir.path().join(format!("{name}.bt"));
    let build_to = |input: &str, output: &str, bt: &Path, stdin: &[u8]| {
        let out = run(
            OCTO,
            &["build", input, "--res", RES, "-o", output, "--bt", s(bt)],
            stdin,
        );
        assert_eq!(out.code, 0, "{output}: {}", out.stderr);
        let again = out
            .stderr
            .lines()
            .filter(|l| l.contains("building again with every transform read first"))
            .map(str::to_string)
            .collect::<Vec<_>>();
        (out, again, std::fs::read(bt).unwrap())
    };
    let odl = dir.path().join("one.odl");
    let (_, again, one) = build_to(s(&bag), s(&odl), &bt("one"), b"");
    assert_eq!(again.len(), 1, "{again:?}");
    assert!(
        again[0].contains("bag-mcap-zstd.mcap") && again[0].contains("\"sensor\""),
        "{}",
        again[0]
    );
    let (out, again, two) = build_to(s(&bag), "-", &bt("two"), b"");
    assert!(again.is_empty(), "{again:?}");
    assert_eq!(
        std::fs::read(&odl).unwrap(),
        out.stdout,
        "the streams differ"
    );
    assert_eq!(one, two, "the maps differ");
    // The root's 3 m are in both: not graph2tree's map of the survey.
    assert_ne!(one, survey().reference_bt);
    // A stream written as it goes (a pipe behind /dev/stdout): two passes from the start, the
    // stream once.
    let (out, again, _) = build_to(s(&bag), "/dev/stdout", &bt("dev"), b"");
    assert!(again.is_empty(), "{again:?}");
    assert_eq!(
        std::fs::read(&odl).unwrap(),
        out.stdout,
        "the streams differ"
    );
    // On standard input the bag cannot be read again: two passes from the start, to files too.
    let stdin = std::fs::read(&bag).unwrap();
    let (_, again, from_stdin) = build_to("-", s(&dir.path().join("in.odl")), &bt("in"), &stdin);
    assert!(again.is_empty(), "{again:?}");
    assert_eq!(from_stdin, two, "the maps differ");
}
