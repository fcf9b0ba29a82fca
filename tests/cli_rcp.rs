//! Process-level tests of rcp-pack and rcp-dump: the built binaries through pipes and files.

use crate::common::{golden, run, testdata, vector_frames};

const PACK: &str = env!("TOOL_EXE_rcp-pack");
const DUMP: &str = env!("TOOL_EXE_rcp-dump");

fn vectors_jsonl() -> Vec<u8> {
    std::fs::read(testdata("wire-vectors.jsonl")).unwrap()
}

#[test]
fn pack_gives_the_spec_bytes() {
    let out = run(PACK, &[], &vectors_jsonl());
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert_eq!(out.stdout, vector_frames().concat());
    let hex = run(
        PACK,
        &["--hex", testdata("wire-vectors.jsonl").to_str().unwrap()],
        b"",
    );
    assert_eq!(
        hex.stdout_text(),
        std::fs::read_to_string(testdata("wire-vectors.hex")).unwrap()
    );
}

#[test]
fn dump_ndjson_packs_back_byte_for_byte() {
    let noisy = std::fs::read(testdata("noisy.bin")).unwrap();
    let dumped = run(DUMP, &["--format", "ndjson", "-q"], &noisy);
    assert_eq!(dumped.code, 0);
    let packed = run(PACK, &[], &dumped.stdout);
    assert_eq!(packed.code, 0, "{}", packed.stderr);
    // Every good frame of the noisy stream, in order, including the invalid message kept as raw.
    let frames = vector_frames();
    let raw = rovlink_wire::frame::build(0, 1, &[0xaa, 0xbb, 0xcc]).unwrap();
    let expected = [
        &frames[0], &frames[1], &frames[2], &frames[3], &raw, &frames[4],
    ]
    .map(|f| f.as_slice())
    .concat();
    assert_eq!(packed.stdout, expected);
    // The clean vector stream round-trips exactly.
    let clean = vector_frames().concat();
    let again = run(PACK, &[], &run(DUMP, &["-f", "ndjson"], &clean).stdout);
    assert_eq!(again.stdout, clean);
}

#[test]
fn dump_ndjson_reads_back_to_the_same_json() {
    let out = run(DUMP, &["-f", "ndjson"], &vector_frames().concat());
    let lines: Vec<String> = out
        .stdout_text()
        .lines()
        .map(|l| {
            let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
            v.as_object_mut().unwrap().shift_remove("offset");
            v.to_string()
        })
        .collect();
    let expected: Vec<String> = String::from_utf8(vectors_jsonl())
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    assert_eq!(lines, expected);
}

#[test]
fn dump_golden_outputs_of_a_noisy_stream() {
    let noisy = testdata("noisy.bin");
    let path = noisy.to_str().unwrap();
    for (format, ext) in [("text", "txt"), ("ndjson", "ndjson"), ("csv", "csv")] {
        let out = run(DUMP, &["--format", format, path], b"");
        assert_eq!(out.code, 0, "{}", out.stderr);
        golden(&format!("rcp-dump-noisy.{ext}"), &out.stdout_text());
        let stderr = out.stderr.replace(path, "testdata/noisy.bin");
        golden(&format!("rcp-dump-noisy.{ext}.stderr"), &stderr);
    }
}

#[test]
fn dump_writes_a_json_summary() {
    let dir = tempfile::tempdir().unwrap();
    let summary = dir.path().join("summary.json");
    let noisy = testdata("noisy.bin");
    let out = run(
        DUMP,
        &[
            "-q",
            "-f",
            "ndjson",
            noisy.to_str().unwrap(),
            "--summary",
            summary.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert_eq!(v["bytes_in"], 127);
    assert_eq!(v["frames"], 6);
    assert_eq!(v["crc_failures"], 2);
    assert_eq!(v["truncated"], 3);
    assert_eq!(v["bytes_skipped"], 33);
    assert_eq!(v["invalid_messages"], 1);
}

#[test]
fn dump_strict_fails_on_a_noisy_stream_only() {
    let noisy = std::fs::read(testdata("noisy.bin")).unwrap();
    let out = run(DUMP, &["--strict", "-q"], &noisy);
    assert_eq!(out.code, 1);
    assert!(
        out.stderr
            .contains("--strict: <stdin> is not a clean frame stream"),
        "{}",
        out.stderr
    );
    assert!(out.stderr.contains(
        "6 frames ok (1 invalid messages), 2 CRC failures, 3 truncated, 33 of 127 bytes skipped"
    ));
    let clean = run(DUMP, &["--strict"], &vector_frames().concat());
    assert_eq!(clean.code, 0, "{}", clean.stderr);
}

#[test]
fn bad_line_stops_with_line_field_and_nothing_after() {
    let text = String::from_utf8(vectors_jsonl()).unwrap();
    let bad = text.replacen(r#""vx":100"#, r#""vx":200"#, 1);
    let out = run(PACK, &[], bad.as_bytes());
    assert_eq!(out.code, 2);
    assert_eq!(
        out.stderr.trim(),
        "rcp-pack: <stdin>:2: field order.vx: expected an integer -127..=127, found 200"
    );
    // Only the frame of line 1 was written.
    assert_eq!(out.stdout, vector_frames()[0]);
}

#[test]
fn bad_line_with_output_file_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("out.bin");
    let input = dir.path().join("in.jsonl");
    let text = String::from_utf8(vectors_jsonl()).unwrap();
    std::fs::write(&input, text.replacen(r#""st":0"#, r#""st":"zero""#, 1)).unwrap();
    let out = run(
        PACK,
        &[input.to_str().unwrap(), "-o", target.to_str().unwrap()],
        b"",
    );
    assert_eq!(out.code, 2);
    assert!(
        out.stderr
            .contains("in.jsonl:1: field st: expected an integer 0..=63, found \"zero\""),
        "{}",
        out.stderr
    );
    assert!(!target.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        1,
        "no temporary file left"
    );
    let ok = run(
        PACK,
        &[
            testdata("wire-vectors.jsonl").to_str().unwrap(),
            "-o",
            target.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(ok.code, 0);
    assert_eq!(std::fs::read(&target).unwrap(), vector_frames().concat());
}

#[test]
fn keep_going_skips_and_reports() {
    let text = String::from_utf8(vectors_jsonl()).unwrap();
    let bad = format!(
        "{}\nnot json\n\n",
        text.replacen(r#""rit":12"#, r#""rit":64"#, 1)
    );
    let out = run(PACK, &["--keep-going"], bad.as_bytes());
    assert_eq!(out.code, 2);
    assert!(
        out.stderr
            .contains("<stdin>:5: field rit: expected an integer 0..=63, found 64 (line skipped)")
    );
    assert!(
        out.stderr.contains("<stdin>:7: not valid JSON at column 2"),
        "{}",
        out.stderr
    );
    assert!(out.stderr.contains("4 frames packed, 2 bad lines skipped"));
    assert_eq!(out.stdout, vector_frames()[..4].concat());
}

#[test]
fn image_is_cut_into_trunks() {
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("image.debt");
    let data: Vec<u8> = (0..100u8).collect();
    std::fs::write(&image, &data).unwrap();
    let out = run(
        PACK,
        &[
            "--image",
            image.to_str().unwrap(),
            "--trunk",
            "39",
            "--src",
            "2",
            "--isn",
            "1",
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    let dumped = run(DUMP, &["-f", "ndjson"], &out.stdout);
    let msgs: Vec<serde_json::Value> = dumped
        .stdout_text()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(msgs.len(), 3);
    let flags: Vec<(bool, bool, u64, u64)> = msgs
        .iter()
        .map(|m| {
            (
                m["ft"].as_bool().unwrap(),
                m["lt"].as_bool().unwrap(),
                m["itsn"].as_u64().unwrap(),
                m["isn"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        flags,
        vec![
            (true, false, 0, 1),
            (false, false, 1, 1),
            (false, true, 2, 1)
        ]
    );
    let joined: String = msgs
        .iter()
        .map(|m| m["trunk"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(rovlink_wire::json::decode_hex(&joined).unwrap(), data);
    assert!(msgs.iter().all(|m| m["src"] == 2 && m["dst"] == 0));
    // The paper's PDU: 39-byte trunks give 57-byte frames.
    assert_eq!(out.stdout.len(), 57 * 2 + (5 + 13 + 22));
}

#[test]
fn image_refuses_more_than_64_trunks() {
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("big.debt");
    std::fs::write(&image, vec![7u8; 3000]).unwrap();
    let out = run(PACK, &["--image", image.to_str().unwrap()], b"");
    assert_eq!(out.code, 2);
    assert!(
        out.stderr.contains("3000 bytes need 77 trunks of 39 bytes, at most 64 fit (ITSN is 6 bits); use --trunk 47 or more"),
        "{}",
        out.stderr
    );
    assert!(out.stdout.is_empty());
    let empty = dir.path().join("empty");
    std::fs::write(&empty, b"").unwrap();
    assert_eq!(
        run(PACK, &["--image", empty.to_str().unwrap()], b"").code,
        2
    );
}

#[test]
fn missing_file_and_bad_usage_exit_2() {
    let out = run(DUMP, &["/nonexistent/frames.bin"], b"");
    assert_eq!(out.code, 2);
    assert_eq!(
        out.stderr.trim(),
        "rcp-dump: /nonexistent/frames.bin: cannot open: No such file or directory (os error 2)"
    );
    assert_eq!(run(DUMP, &["--format", "xml"], b"").code, 2);
    assert_eq!(run(PACK, &["--trunk", "0", "--image", "x"], b"").code, 2);
}

#[test]
fn help_has_examples() {
    for bin in [PACK, DUMP] {
        let out = run(bin, &["--help"], b"");
        assert_eq!(out.code, 0);
        assert!(out.stdout_text().contains("Examples:"));
        assert!(out.stdout_text().contains("Exit codes:"));
    }
}

#[test]
fn broken_pipe_downstream_is_success() {
    use std::io::{BufRead, BufReader, Write};
    use std::process::{Command, Stdio};
    for format in ["text", "ndjson", "csv"] {
        let frames = vector_frames().concat().repeat(20_000);
        let mut child = Command::new(DUMP)
            .args(["-q", "-f", format])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut stdin = child.stdin.take().unwrap();
        let writer = std::thread::spawn(move || {
            let _ = stdin.write_all(&frames);
        });
        let mut first = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut first)
            .unwrap();
        assert!(!first.is_empty());
        // stdout is dropped here: the reader has gone away, as with `| head -1`.
        let status = child.wait().unwrap();
        let _ = writer.join();
        assert_eq!(status.code(), Some(0), "format {format}");
    }
}

#[test]
fn closed_stderr_is_no_panic() {
    use std::io::Write;
    use std::process::{Command, Stdio};
    let mut child = Command::new(DUMP)
        .args(["-f", "ndjson"])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stderr.take());
    let mut stdin = child.stdin.take().unwrap();
    stdin
        .write_all(&std::fs::read(testdata("noisy.bin")).unwrap())
        .unwrap();
    drop(stdin);
    assert_eq!(child.wait().unwrap().code(), Some(0));
}

#[test]
fn output_to_a_directory_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        PACK,
        &[
            testdata("wire-vectors.jsonl").to_str().unwrap(),
            "-o",
            dir.path().to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.code, 2);
    assert!(
        out.stderr.contains("is a directory, expected a file"),
        "{}",
        out.stderr
    );
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    let parent = dir.path().parent().unwrap();
    let leftovers = std::fs::read_dir(parent)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .contains(".tmp-")
        })
        .count();
    assert_eq!(leftovers, 0);
}

#[test]
fn options_that_need_another_are_refused_alone() {
    let vectors = testdata("wire-vectors.jsonl");
    let v = vectors.to_str().unwrap();
    for args in [
        vec!["--src", "3", v],
        vec!["--trunk", "10", v],
        vec!["--isn", "1", v],
        vec!["--dst", "4", v],
    ] {
        let out = run(PACK, &args, b"");
        assert_eq!(out.code, 2, "{args:?}");
        assert!(out.stderr.contains("--image"), "{}", out.stderr);
    }
    let frames = testdata("noisy.bin");
    for args in [
        vec!["--baud", "9600", frames.to_str().unwrap()],
        vec!["--idle-ms", "5", frames.to_str().unwrap()],
    ] {
        let out = run(DUMP, &args, b"");
        assert_eq!(out.code, 2, "{args:?}");
        assert!(out.stderr.contains("--port"), "{}", out.stderr);
    }
    assert_eq!(
        run(DUMP, &["--port", "/dev/null", "--baud", "0"], b"").code,
        2
    );
}

#[test]
fn bad_summary_path_fails_before_any_output() {
    let dir = tempfile::tempdir().unwrap();
    let out_file = dir.path().join("out.txt");
    let out = run(
        DUMP,
        &[
            "-q",
            "-o",
            out_file.to_str().unwrap(),
            "--summary",
            "/nonexistent/dir/s.json",
            testdata("noisy.bin").to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.code, 2);
    assert!(
        out.stderr.contains(
            "--summary: cannot create /nonexistent/dir/s.json: /nonexistent/dir does not exist"
        ),
        "{}",
        out.stderr
    );
    assert!(!out_file.exists());
}

/// Status version 1 (ST = 1): NP and WHY after the basic block, before the trunk.
const STATUS_V1: &str = r#"{"type":"rov","src":1,"dst":0,"ft":true,"lt":false,"st":1,"isn":1,"ci":false,"itsn":0,"rd":true,"eoid":1,"loc":false,"hh":true,"arm":true,"nav":"guided","x_cm":0,"y_cm":0,"z_cm":0,"roll_deg":359,"pitch_deg":1,"yaw_deg":180,"position_known":false,"why":"no_position","trunk":"00010203"}"#;

#[test]
fn status_version_1_packs_dumps_and_reads_back() {
    let hex = run(PACK, &["--hex"], format!("{STATUS_V1}\n").as_bytes());
    assert_eq!(hex.code, 0, "{}", hex.stderr);
    // ST 1 in byte 0 of the payload, byte 13 NP 1 WHY 3, then the trunk.
    assert_eq!(
        hex.stdout_text(),
        "5510128180dc00000000000002d0036783000102033459\n"
    );
    let frame = run(PACK, &[], format!("{STATUS_V1}\n").as_bytes()).stdout;
    let text = run(DUMP, &["-q"], &frame);
    assert!(
        text.stdout_text()
            .contains("NP why=no_position ned=(0.00,0.00,0.00)m"),
        "{}",
        text.stdout_text()
    );
    let json = run(DUMP, &["-f", "ndjson", "-q"], &frame);
    let mut line: serde_json::Value = serde_json::from_str(json.stdout_text().trim()).unwrap();
    line.as_object_mut().unwrap().shift_remove("offset");
    assert_eq!(line.to_string(), STATUS_V1);
    // ST 0 has neither field: a line that gives one is refused, naming it.
    let st0 = STATUS_V1.replace(r#""st":1"#, r#""st":0"#);
    let refused = run(PACK, &[], format!("{st0}\n").as_bytes());
    assert_eq!(refused.code, 2);
    assert!(
        refused
            .stderr
            .contains("field position_known: expected st 1 for a status with position_known false"),
        "{}",
        refused.stderr
    );
}
