//! `octo-delta apply --mcap`: the operator's view as Foxglove plays it, read back with the
//! official Python readers (`mcap`, and `jsonschema` against the schema the file carries, by
//! tests/octo_view/check_view.py): one scene update per stream message, logged when the
//! operator got it, and the scene at the end is the applied `.ot` view, voxel for voxel, fine
//! and coarse apart. Bad arrivals files and bad outputs: exit 2, one line, no file.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::common::hostile::{self, assert_contract};
use crate::common::run;
use rovlink_octo::delta::{self, ViewSpec};
use rovlink_octo::files;
use rovlink_octo::tree::{Key, TREE_DEPTH, morton, unmorton};

const OCTO: &str = env!("TOOL_EXE_octo-delta");
const CHECK: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/octo_view/check_view.py");
const ROI: &str = "0,-12,-5,14,12,5";

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn octo(args: &[&str]) {
    let out = run(OCTO, args, b"");
    assert_eq!(out.code, 0, "octo-delta {args:?}: {}", out.stderr);
}

/// A small coloured survey built with a link: the stream and its arrivals.
fn survey(dir: &Path) -> (PathBuf, PathBuf) {
    let bag = dir.join("survey.mcap");
    octo(&["synth", "--scans", "6", "-o", s(&bag)]);
    let (odl, csv) = (dir.join("d.odl"), dir.join("a.csv"));
    octo(&[
        "build",
        s(&bag),
        "--roi",
        ROI,
        "-o",
        s(&odl),
        "--link",
        "satellite-up",
        "--arrivals",
        s(&csv),
        "-q",
    ]);
    (odl, csv)
}

/// What check_view.py saw.
struct Shown {
    messages: usize,
    log_time_ns: Vec<u64>,
    publish_time_ns: Vec<u64>,
    fine: Vec<Vec<f64>>,
    coarse: Vec<Vec<f64>>,
}

fn check_view(mcap: &Path) -> Shown {
    let out = Command::new("python3")
        .args([CHECK, s(mcap)])
        .output()
        .unwrap_or_else(|e| panic!("python3 not runnable ({e}): install Python 3 with the packages mcap and jsonschema (python3 -m pip install mcap jsonschema)"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "check_view.py: {stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let nums = |k: &str| -> Vec<u64> {
        v[k].as_array()
            .unwrap()
            .iter()
            .map(|t| t.as_u64().unwrap())
            .collect()
    };
    let cubes = |k: &str| -> Vec<Vec<f64>> {
        v[k].as_array()
            .unwrap()
            .iter()
            .map(|c| {
                c.as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect()
            })
            .collect()
    };
    Shown {
        messages: v["messages"].as_u64().unwrap() as usize,
        log_time_ns: nums("log_time_ns"),
        publish_time_ns: nums("publish_time_ns"),
        fine: cubes("fine"),
        coarse: cubes("coarse"),
    }
}

/// Fine voxels a list of cubes covers: key -> colour (r, g, b as 0..=255), each once.
fn cube_voxels(cubes: &[Vec<f64>], res: f64) -> HashMap<Key, [u8; 3]> {
    let mut out = HashMap::new();
    for c in cubes {
        let lo: Vec<i64> = (0..3)
            .map(|a| ((c[a] - c[3 + a] / 2.0) / res).round() as i64 + 32768)
            .collect();
        let n: Vec<i64> = (0..3).map(|a| (c[3 + a] / res).round() as i64).collect();
        let rgb = [c[6], c[7], c[8]].map(|x| (x * 255.0).round() as u8);
        for x in 0..n[0] {
            for y in 0..n[1] {
                for z in 0..n[2] {
                    let k = [lo[0] + x, lo[1] + y, lo[2] + z].map(|v| v as u16);
                    assert!(out.insert(k, rgb).is_none(), "voxel {k:?} in two cubes");
                }
            }
        }
    }
    out
}

/// Fine voxels of a `.ot` view's occupied leaves, split by whether their coarse voxel meets
/// the ROI: (fine: key -> colour, coarse: keys).
fn ot_voxels(ot: &Path, spec: &ViewSpec) -> (HashMap<Key, [u8; 3]>, Vec<Key>) {
    let tree = files::read_map(&std::fs::read(ot).unwrap()).unwrap();
    let (mut fine, mut coarse) = (HashMap::new(), Vec::new());
    tree.for_each_leaf(|code, depth, v| {
        if v.log_odds < 0.0 {
            return;
        }
        let n = 1u32 << (TREE_DEPTH - depth);
        let k0 = unmorton(code);
        for x in 0..n {
            for y in 0..n {
                for z in 0..n {
                    let k =
                        [k0[0] as u32 + x, k0[1] as u32 + y, k0[2] as u32 + z].map(|c| c as u16);
                    if spec.coarse_in_roi(morton(k) >> spec.coarse_shift()) {
                        fine.insert(k, v.color.expect("a coloured view"));
                    } else {
                        coarse.push(k);
                    }
                }
            }
        }
    });
    (fine, coarse)
}

fn arrival_times_ns(csv: &Path) -> Vec<u64> {
    let text = std::fs::read_to_string(csv).unwrap();
    text.lines()
        .skip(1)
        .map(|l| (l.split(',').nth(4).unwrap().parse::<f64>().unwrap() * 1e9).round() as u64)
        .collect()
}

#[test]
fn foxglove_plays_the_view_as_the_operator_saw_it() {
    let dir = tempfile::tempdir().unwrap();
    let (odl, csv) = survey(dir.path());
    let (ot, mcap) = (dir.path().join("v.ot"), dir.path().join("v.mcap"));
    octo(&[
        "apply",
        s(&odl),
        "-o",
        s(&ot),
        "--mcap",
        s(&mcap),
        "--arrivals",
        s(&csv),
    ]);
    let (header, msgs) = delta::decode_stream(&std::fs::read(&odl).unwrap()).unwrap();
    let shown = check_view(&mcap);
    assert_eq!(shown.messages, msgs.len());
    assert_eq!(shown.log_time_ns, arrival_times_ns(&csv));
    assert_eq!(shown.publish_time_ns, shown.log_time_ns);
    let spec = header.spec;
    let (want_fine, want_coarse) = ot_voxels(&ot, &spec);
    assert!(
        !want_fine.is_empty() && !want_coarse.is_empty(),
        "the ROI cuts the survey"
    );
    let fine = cube_voxels(&shown.fine, spec.resolution_m);
    assert_eq!(fine.len(), want_fine.len());
    for (k, rgb) in &want_fine {
        assert_eq!(fine.get(k), Some(rgb), "fine voxel {k:?}");
    }
    let coarse = cube_voxels(&shown.coarse, spec.resolution_m);
    assert_eq!(coarse.len(), want_coarse.len());
    assert!(want_coarse.iter().all(|k| coarse.contains_key(k)));
    assert!(
        shown.coarse.iter().all(|c| c[9] < 1.0),
        "coarse voxels are translucent"
    );
    assert!(
        shown.fine.iter().all(|c| c[9] == 1.0),
        "fine voxels are opaque"
    );
    // The .ot is the same with or without --mcap.
    let plain = dir.path().join("plain.ot");
    octo(&["apply", s(&odl), "-o", s(&plain)]);
    assert_eq!(std::fs::read(&plain).unwrap(), std::fs::read(&ot).unwrap());
}

#[test]
fn without_arrivals_messages_are_a_scan_period_apart() {
    let dir = tempfile::tempdir().unwrap();
    let (odl, _) = survey(dir.path());
    let mcap = dir.path().join("v.mcap");
    // -o is not needed with --mcap; --messages cuts both.
    octo(&[
        "apply",
        s(&odl),
        "--mcap",
        s(&mcap),
        "--scan-period",
        "0.5",
        "--messages",
        "3",
    ]);
    let shown = check_view(&mcap);
    assert_eq!(shown.log_time_ns, vec![0, 500_000_000, 1_000_000_000]);
    let ot = dir.path().join("v3.ot");
    octo(&["apply", s(&odl), "-o", s(&ot), "--messages", "3"]);
    let (header, _) = delta::decode_stream(&std::fs::read(&odl).unwrap()).unwrap();
    let (want_fine, want_coarse) = ot_voxels(&ot, &header.spec);
    let res = header.spec.resolution_m;
    assert_eq!(cube_voxels(&shown.fine, res).len(), want_fine.len());
    assert_eq!(cube_voxels(&shown.coarse, res).len(), want_coarse.len());
    // A full map as one message: the same scene.
    let full = dir.path().join("full.odl");
    octo(&["full", s(&ot), "--roi", ROI, "-o", s(&full)]);
    let one = dir.path().join("one.mcap");
    octo(&["apply", s(&full), "--mcap", s(&one)]);
    let shown = check_view(&one);
    assert_eq!(shown.log_time_ns, vec![0]);
    assert_eq!(cube_voxels(&shown.fine, res).len(), want_fine.len());
    assert_eq!(cube_voxels(&shown.coarse, res).len(), want_coarse.len());
}

#[test]
fn bad_arrivals_and_bad_outputs_fail_whole() {
    let dir = tempfile::tempdir().unwrap();
    let (odl, csv) = survey(dir.path());
    let text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let write = |name: &str, body: String| {
        let p = dir.path().join(name);
        std::fs::write(&p, body).unwrap();
        p
    };
    let header_bad = write("h.csv", text.replacen("t_shown_s", "t_seen_s", 1));
    let field_bad = write("f.csv", text.replacen(",0.", ",x.", 1));
    let short = write("s.csv", lines[..3].join("\n") + "\n");
    let row = lines[2].replacen("1,", "7,", 1);
    let mut renumbered = lines.clone();
    renumbered[2] = &row;
    let renumbered = write("w.csv", renumbered.join("\n") + "\n");
    let mcap = dir.path().join("v.mcap");
    let limit = Duration::from_secs(20);
    let missing = dir.path().join("none.csv");
    let cases: Vec<(&Path, &str)> = vec![
        (
            &header_bad,
            "h.csv: line 1, column header: expected `scan,bytes",
        ),
        (&field_bad, "f.csv: line 2, column "),
        (
            &short,
            "s.csv: line 4, column scan: expected a row for message 2",
        ),
        (
            &renumbered,
            "w.csv: line 3, column scan: expected 1 (message 1 of the stream), found 7",
        ),
        (&missing, "none.csv"),
    ];
    for (arrivals, want) in cases {
        let args = [
            "apply",
            s(&odl),
            "--mcap",
            s(&mcap),
            "--arrivals",
            s(arrivals),
        ];
        let r = hostile::run(OCTO, &args, b"", limit);
        assert_contract(&r, &[2], want);
        assert_eq!(r.stderr.lines().count(), 1, "{want}: {}", r.stderr);
        assert!(r.stderr.contains(want), "expected {want:?} in {}", r.stderr);
        assert!(!mcap.exists(), "{want}: a file was left");
    }
    let bad_outputs: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--mcap", s(&odl)], "--mcap"),
        (
            vec!["--mcap", "/nonexistent-dir/v.mcap"],
            "--mcap: cannot create /nonexistent-dir/v.mcap",
        ),
        (vec!["--mcap", s(dir.path())], "is a directory"),
        (vec!["-o", "-", "--mcap", "-"], "--mcap"),
        (vec!["--arrivals", s(&csv)], "--mcap"),
        (vec![], "--output"),
        (
            vec![
                "--mcap",
                s(&mcap),
                "--arrivals",
                s(&csv),
                "--scan-period",
                "2",
            ],
            "--scan-period",
        ),
    ];
    let before = std::fs::read(&odl).unwrap();
    for (extra, want) in bad_outputs {
        let mut args = vec!["apply", s(&odl)];
        args.extend(extra);
        let r = hostile::run(OCTO, &args, b"", limit);
        assert_contract(&r, &[2], want);
        assert_eq!(r.stderr.lines().count(), 1, "{want}: {}", r.stderr);
        assert!(r.stderr.contains(want), "expected {want:?} in {}", r.stderr);
        assert!(!mcap.exists(), "{want}: a file was left");
    }
    assert_eq!(
        std::fs::read(&odl).unwrap(),
        before,
        "the input is untouched"
    );
    // A damaged stream: nothing written either.
    let mut damaged = before.clone();
    let last = damaged.len() - 1;
    damaged[last] ^= 0x55;
    let bad = dir.path().join("bad.odl");
    std::fs::write(&bad, damaged).unwrap();
    let r = hostile::run(OCTO, &["apply", s(&bad), "--mcap", s(&mcap)], b"", limit);
    assert_contract(&r, &[2], "damaged stream");
    assert!(r.stderr.contains("bad.odl: offset"), "{}", r.stderr);
    assert!(!mcap.exists());
    assert!(hostile::temp_files(dir.path()).is_empty());
}
