//! Coloured maps against OctoMap itself: `tests/octomap/color_tree.cpp`, built here against
//! Debian's `liboctomap-dev`, inserts the same scans into OctoMap's `ColorOcTree` with the
//! colour calls octo-delta's rule stands for (`search`, then `setNodeColor` when brighter), and
//! its `.ot` must equal octo-delta's node by node (log-odds, colour, children) and byte for byte.
//! The structure must also be the `OcTree`'s of the same scans (graph2tree's, `compare_octrees`
//! KLD 0), and a `ColorOcTree` `.bt` (what `convert_octree` writes) must be readable.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{assert_kld_zero, octomap_tool, run};
use rovlink_octo::synth::{SurveyParams, reference_dump, survey};

const OCTO: &str = env!("TOOL_EXE_octo-delta");

fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

/// Compiles the C++ reference once per test binary; fails with what to install.
fn reference() -> PathBuf {
    static BUILT: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    BUILT
        .get_or_init(|| {
            let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/octomap/color_tree.cpp");
            let exe = Path::new(env!("CARGO_TARGET_TMPDIR")).join("octomap_color_tree");
            let out = Command::new("c++")
                .args(["-O2", "-std=c++17", s(&src), "-o", s(&exe)])
                .args(["-loctomap", "-loctomath"])
                .output()
                .unwrap_or_else(|e| {
                    panic!("no C++ compiler ({e}): install g++ and Debian's liboctomap-dev")
                });
            assert!(
                out.status.success(),
                "tests/octomap/color_tree.cpp does not compile against liboctomap (install \
                 Debian's liboctomap-dev: apt-get install liboctomap-dev):\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
            exe
        })
        .clone()
}

/// The scans of `octo-delta synth --seed SEED --scans N` in the reference's dump format.
fn dump_scans(seed: u64, scans: usize) -> Vec<u8> {
    let survey = survey(&SurveyParams {
        seed,
        scans,
        ..SurveyParams::default()
    });
    assert!(
        survey.iter().all(|s| s.colors.is_some()),
        "synth scans are coloured"
    );
    reference_dump(&survey)
}

/// One `.ot` node: its path from the root (child indices), log-odds bits, colour, child mask.
#[derive(Debug, Clone, PartialEq)]
struct OtNode {
    path: Vec<u8>,
    log_odds_bits: u32,
    color: Option<[u8; 3]>,
    mask: u8,
}

/// A `.ot` file's header id and its nodes in pre-order (an independent reader: the test's
/// own, not the library's).
fn ot_nodes(bytes: &[u8]) -> (String, Vec<OtNode>) {
    let mut pos = 0;
    let mut id = String::new();
    loop {
        let end = pos
            + bytes[pos..]
                .iter()
                .position(|&b| b == b'\n')
                .expect("header line");
        let line = std::str::from_utf8(&bytes[pos..end]).expect("ASCII header");
        pos = end + 1;
        if let Some(v) = line.strip_prefix("id ") {
            id = v.to_string();
        }
        if line == "data" {
            break;
        }
    }
    let per = if id == "ColorOcTree" { 8 } else { 5 };
    let mut nodes = Vec::new();
    // (path, children still to read): a pre-order walk driven by the masks.
    let mut stack: Vec<(Vec<u8>, Vec<u8>)> = Vec::new();
    let mut next_path = Some(Vec::new());
    while let Some(path) = next_path.take() {
        let rec = &bytes[pos..pos + per];
        pos += per;
        let mask = rec[per - 1];
        nodes.push(OtNode {
            path: path.clone(),
            log_odds_bits: u32::from_le_bytes([rec[0], rec[1], rec[2], rec[3]]),
            color: (per == 8).then(|| [rec[4], rec[5], rec[6]]),
            mask,
        });
        let kids: Vec<u8> = (0..8u8).rev().filter(|i| mask & (1 << i) != 0).collect();
        stack.push((path, kids));
        while let Some((p, kids)) = stack.last_mut() {
            if let Some(i) = kids.pop() {
                let mut child = p.clone();
                child.push(i);
                next_path = Some(child);
                break;
            }
            stack.pop();
        }
    }
    assert_eq!(pos, bytes.len(), "bytes after the last node");
    (id, nodes)
}

/// Compares two `.ot` files node by node; the message names the first differing node.
fn compare_ot(ours: &Path, theirs: &Path, structure_only: bool) -> usize {
    let (ia, a) = ot_nodes(&std::fs::read(ours).unwrap());
    let (ib, b) = ot_nodes(&std::fs::read(theirs).unwrap());
    for (x, y) in a.iter().zip(&b) {
        let same = if structure_only {
            (&x.path, x.log_odds_bits, x.mask) == (&y.path, y.log_odds_bits, y.mask)
        } else {
            x == y
        };
        assert!(
            same,
            "{} ({ia}) and {} ({ib}) differ first at the node with path {:?} (depth {}): ours \
             log-odds {} colour {:?} children {:#04x}, theirs log-odds {} colour {:?} children \
             {:#04x}",
            ours.display(),
            theirs.display(),
            x.path,
            x.path.len(),
            f32::from_bits(x.log_odds_bits),
            x.color,
            x.mask,
            f32::from_bits(y.log_odds_bits),
            y.color,
            y.mask
        );
    }
    assert_eq!(a.len(), b.len(), "node counts of {ours:?} and {theirs:?}");
    a.len()
}

fn build(dir: &Path, input: &Path, res: &str, extra: &[&str], ot: &Path) {
    let odl = dir.join("d.odl");
    let mut args = vec![
        "build",
        s(input),
        "--res",
        res,
        "-o",
        s(&odl),
        "--ot",
        s(ot),
    ];
    args.extend(extra);
    let out = run(OCTO, &args, b"");
    assert_eq!(out.code, 0, "{}", out.stderr);
}

fn synth(dir: &Path, seed: u64, scans: usize, name: &str) -> PathBuf {
    let path = dir.join(name);
    let (seed, scans) = (seed.to_string(), scans.to_string());
    let out = run(
        OCTO,
        &["synth", "--seed", &seed, "--scans", &scans, "-o", s(&path)],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    path
}

#[test]
fn coloured_maps_are_octomaps_color_octree_node_by_node() {
    let exe = reference();
    let dir = tempfile::tempdir().unwrap();
    let (seed, scans) = (3, 12);
    let mcap = synth(dir.path(), seed, scans, "survey.mcap");
    let dump = dir.path().join("scans.bin");
    std::fs::write(&dump, dump_scans(seed, scans)).unwrap();
    for res in ["0.1", "0.2"] {
        let ours = dir.path().join(format!("ours{res}.ot"));
        let theirs = dir.path().join(format!("theirs{res}.ot"));
        build(dir.path(), &mcap, res, &[], &ours);
        let out = Command::new(&exe)
            .args([s(&dump), res, s(&theirs)])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let nodes = compare_ot(&ours, &theirs, false);
        assert!(
            nodes > 10_000,
            "a survey big enough to prune: {nodes} nodes"
        );
        assert!(
            std::fs::read(&ours).unwrap() == std::fs::read(&theirs).unwrap(),
            "{ours:?} and {theirs:?} differ in bytes (header?)"
        );
        // Pruned: fewer nodes than the tree would have with every leaf at depth 16.
        let (_, n) = ot_nodes(&std::fs::read(&ours).unwrap());
        assert!(
            n.iter().any(|x| x.mask == 0 && x.path.len() < 16),
            "no pruned leaf at {res} m"
        );
    }
}

#[test]
fn coloured_structure_is_the_octree_of_the_same_scans() {
    let dir = tempfile::tempdir().unwrap();
    let (seed, scans) = (5, 12);
    let mcap = synth(dir.path(), seed, scans, "survey.mcap");
    let graph = synth(dir.path(), seed, scans, "survey.graph");
    for res in ["0.1", "0.15"] {
        let colored = dir.path().join("colored.ot");
        let plain = dir.path().join("plain.ot");
        build(dir.path(), &mcap, res, &[], &colored);
        build(dir.path(), &mcap, res, &["--no-color"], &plain);
        let reference = dir.path().join("ref.bt");
        octomap_tool(
            "graph2tree",
            &["-i", s(&graph), "-o", s(&reference), "-res", res],
        );
        let ref_ot = dir.path().join("ref.bt.ot");
        assert!(
            std::fs::read(&plain).unwrap() == std::fs::read(&ref_ot).unwrap(),
            "--no-color map is not graph2tree's at {res} m"
        );
        assert_kld_zero(&plain, &ref_ot, &format!("--no-color at {res} m"));
        // The coloured map: the same nodes with the same values.
        compare_ot(&colored, &ref_ot, true);
    }
}

#[test]
fn a_color_octree_bt_from_convert_octree_is_read_as_its_octree() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mcap = synth(d, 7, 10, "survey.mcap");
    let (colored, plain) = (d.join("colored.ot"), d.join("plain.ot"));
    build(d, &mcap, "0.1", &[], &colored);
    build(d, &mcap, "0.1", &["--no-color"], &plain);
    let (colored_bt, plain_bt) = (d.join("colored.bt"), d.join("plain.bt"));
    octomap_tool("convert_octree", &[s(&colored), s(&colored_bt)]);
    octomap_tool("convert_octree", &[s(&plain), s(&plain_bt)]);
    let bytes = std::fs::read(&colored_bt).unwrap();
    assert!(
        String::from_utf8_lossy(&bytes[..200]).contains("id ColorOcTree"),
        "convert_octree did not write a ColorOcTree .bt"
    );
    // `full` and `apply` take it, and give the OcTree's view.
    let views: Vec<Vec<u8>> = [&colored_bt, &plain_bt]
        .iter()
        .map(|bt| {
            let (odl, view) = (d.join("f.odl"), d.join("v.ot"));
            let out = run(OCTO, &["full", s(bt), "-o", s(&odl)], b"");
            assert_eq!(out.code, 0, "full {bt:?}: {}", out.stderr);
            let out = run(OCTO, &["apply", s(&odl), "-o", s(&view)], b"");
            assert_eq!(out.code, 0, "apply: {}", out.stderr);
            std::fs::read(&view).unwrap()
        })
        .collect();
    assert!(
        views[0] == views[1],
        "the ColorOcTree .bt's view is not the OcTree's"
    );

    // Cut short or damaged: one line naming the file and the offset, exit 2, no output.
    let body = bytes
        .windows(5)
        .position(|w| w == b"data\n")
        .expect("data line")
        + 5;
    let garbage = [&bytes[..body], &[0xffu8; 7][..]].concat();
    for (name, damaged) in [
        ("cut.bt", bytes[..bytes.len() - 5].to_vec()),
        ("garbage.bt", garbage),
    ] {
        let path = d.join(name);
        std::fs::write(&path, &damaged).unwrap();
        let out_file = d.join(format!("{name}.odl"));
        let out = run(OCTO, &["full", s(&path), "-o", s(&out_file)], b"");
        assert_eq!(out.code, 2, "{name}: {}", out.stderr);
        let lines: Vec<&str> = out.stderr.lines().collect();
        assert_eq!(lines.len(), 1, "{name}: one line: {}", out.stderr);
        assert!(
            lines[0].contains(name) && lines[0].contains("offset"),
            "{name}: {}",
            lines[0]
        );
        assert!(!out_file.exists(), "{name}: partial output");
    }
}
