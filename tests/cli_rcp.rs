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

/// Issue 48: the CSV has status version 1's columns, so the docs' vector (no position, WHY
/// no_position) and the same frame with a position and WHY none give different rows; a frame
/// of ST = 0 leaves both cells empty.
#[test]
fn dump_csv_has_the_status_version_1_columns() {
    let known = STATUS_V1
        .replace(r#""position_known":false"#, r#""position_known":true"#)
        .replace(r#""why":"no_position""#, r#""why":"none""#);
    let st0 = known.replace(r#""st":1"#, r#""st":0"#);
    let lines = format!("{STATUS_V1}\n{known}\n{st0}\n");
    let frames = run(PACK, &[], lines.as_bytes());
    assert_eq!(frames.code, 0, "{}", frames.stderr);
    let csv = run(DUMP, &["-q", "-f", "csv"], &frames.stdout);
    assert_eq!(csv.code, 0, "{}", csv.stderr);
    let text = csv.stdout_text();
    let rows: Vec<Vec<&str>> = text.lines().map(|l| l.split(',').collect()).collect();
    let header = &rows[0];
    let at = |name: &str| header.iter().position(|c| *c == name).unwrap();
    assert_eq!(
        (at("position_known"), at("why")),
        (at("yaw_deg") + 1, at("yaw_deg") + 2),
        "after yaw_deg, as in the JSON form: {text}"
    );
    assert_ne!(rows[1], rows[2], "{text}");
    let cells = |i: usize| {
        (
            rows[i][at("st")],
            rows[i][at("position_known")],
            rows[i][at("why")],
        )
    };
    assert_eq!(cells(1), ("1", "false", "no_position"), "{text}");
    assert_eq!(cells(2), ("1", "true", "none"), "{text}");
    assert_eq!(cells(3), ("0", "", ""), "{text}");
    // Every field of the JSON form is a column, as --help says.
    let json = run(DUMP, &["-q", "-f", "ndjson"], &frames.stdout);
    for line in json.stdout_text().lines() {
        let object: serde_json::Value = serde_json::from_str(line).unwrap();
        for key in object.as_object().unwrap().keys() {
            assert!(header.contains(&key.as_str()), "no column {key}: {text}");
        }
    }
}

/// Issue 48: a field the message's form does not have is refused, naming it and its line
/// (misspelt status version 1 fields packed a plain ST = 0 frame, exit 0); what rcp-dump adds
/// is still read, so a dump packs back.
#[test]
fn an_unknown_field_is_refused_naming_it_and_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("out.bin");
    let typo = STATUS_V1.replace(r#""st":1"#, r#""st":0"#).replace(
        r#""position_known":false,"why":"no_position""#,
        r#""wyh":"no_position","positon_known":false"#,
    );
    let order = String::from_utf8(vectors_jsonl()).unwrap().replacen(
        r#""vyaw":-127"#,
        r#""vyaw":-127,"vroll":3"#,
        1,
    );
    for (input, line, field) in [
        (format!("{STATUS_V1}\n{typo}\n"), 2, "wyh"),
        (order, 2, "order.vroll"),
    ] {
        let out = run(PACK, &["-o", target.to_str().unwrap()], input.as_bytes());
        assert_eq!(out.code, 2, "{}", out.stderr);
        assert_eq!(out.stderr.lines().count(), 1, "{}", out.stderr);
        assert!(
            out.stderr.starts_with(&format!(
                "rcp-pack: <stdin>:{line}: field {field}: unknown, expected one of type, "
            )),
            "{}",
            out.stderr
        );
        assert!(!target.exists(), "{field}: an output file was written");
        let skipped = run(PACK, &["--keep-going"], input.as_bytes());
        assert_eq!(skipped.code, 2);
        assert!(
            skipped.stderr.contains("(line skipped)"),
            "{}",
            skipped.stderr
        );
    }
    // A dump of a ST = 1 frame packs back too (the other dumps: the round trips above).
    let frame = run(PACK, &[], format!("{STATUS_V1}\n").as_bytes()).stdout;
    let dumped = run(DUMP, &["-f", "ndjson", "-q"], &frame).stdout;
    let again = run(PACK, &[], &dumped);
    assert_eq!((again.code, again.stdout), (0, frame), "{}", again.stderr);
}

/// RFC 4493's key, the AES-128 key of the secured-frame test vectors.
const KEY_128: &str = "2b7e151628aed2a6abf7158809cf4f3c";

/// wire.md's GoTo operator frame as a JSON line.
const GOTO: &str = r#"{"type":"operator","src":0,"dst":2,"oid":0,"clo":true,"eisn":1,"ic":true,"rit":63,"order":{"type":"goto","x_cm":-250,"y_cm":1200,"z_cm":310,"heading_deg":359}}"#;

/// A key file `name` in `dir` holding `* KEY`, mode 0600.
fn key_file(dir: &std::path::Path, name: &str, key: &str) -> std::path::PathBuf {
    crate::common::private_file(dir, name, &format!("* {key}\n"))
}

/// The frames rcp-pack makes of `input` with `args` (and --hex), one a line.
fn packed_frames(args: &[&str], input: &str) -> Vec<Vec<u8>> {
    let out = run(PACK, &[args, &["--hex"]].concat(), input.as_bytes());
    assert_eq!(out.code, 0, "{}", out.stderr);
    out.stdout_text()
        .lines()
        .map(|l| rovlink_wire::json::decode_hex(l).unwrap())
        .collect()
}

/// rcp-dump's JSON Lines of `frames` with `args`: the exit code and the objects.
fn dumped(args: &[&str], frames: &[u8]) -> (i32, Vec<serde_json::Value>, String) {
    let out = run(DUMP, &[args, &["-f", "ndjson"]].concat(), frames);
    let lines = out
        .stdout_text()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    (out.code, lines, out.stderr)
}

/// A dumped object without what rcp-dump adds (offset, security fields): wire.md's line.
fn message_only(mut v: serde_json::Value) -> String {
    let map = v.as_object_mut().unwrap();
    for key in [
        "offset",
        "secured",
        "encrypted",
        "ctr",
        "ctr_low",
        "verdict",
    ] {
        map.shift_remove(key);
    }
    v.to_string()
}

#[test]
fn secured_frames_pack_and_dump_to_the_same_messages() {
    let dir = tempfile::tempdir().unwrap();
    let key = key_file(dir.path(), "rov.key", KEY_128);
    let k = key.to_str().unwrap();
    let vectors = String::from_utf8(vectors_jsonl()).unwrap();
    let expected: Vec<&str> = vectors.lines().collect();
    for extra in [&[][..], &["--encrypt"][..]] {
        let frames = packed_frames(&[&["--key-file", k], extra].concat(), &vectors);
        let plain = vector_frames();
        for (sealed, plain) in frames.iter().zip(&plain) {
            assert_eq!(sealed.len(), plain.len() + 6);
        }
        let stream = frames.concat();
        let (code, lines, stderr) = dumped(&["--key-file", k], &stream);
        assert_eq!(code, 0, "{stderr}");
        assert!(stderr.contains("verdicts: 5 ok"), "{stderr}");
        let messages: Vec<String> = lines.iter().cloned().map(message_only).collect();
        assert_eq!(messages, expected);
        // Counters per (SRC, DST) from 1: 0->1 appears twice in the vectors.
        let ctrs: Vec<u64> = lines.iter().map(|l| l["ctr"].as_u64().unwrap()).collect();
        assert_eq!(ctrs, [1, 1, 1, 2, 1]);
        for l in &lines {
            assert_eq!(l["secured"], true);
            assert_eq!(l["verdict"], "ok");
            assert_eq!(l["encrypted"], !extra.is_empty());
        }
        // A keyed dump packs back, with its counters, to the same bytes.
        let ndjson = run(DUMP, &["--key-file", k, "-f", "ndjson", "-q"], &stream).stdout;
        let again = run(PACK, &[&["--key-file", k], extra].concat(), &ndjson);
        assert_eq!(again.code, 0, "{}", again.stderr);
        assert_eq!(again.stdout, stream);
        // Without the key: each frame is named secured and unverified, its payload raw.
        let (code, blind, stderr) = dumped(&[], &stream);
        assert_eq!(code, 0, "{stderr}");
        for (l, f) in blind.iter().zip(&frames) {
            assert_eq!(l["type"], "raw");
            assert_eq!(l["verdict"], "unverified");
            assert_eq!(l["secured"], true);
            assert_eq!(l["ctr_low"], 1 + u64::from(l["offset"] == 72));
            assert_eq!(
                l["payload"].as_str().unwrap(),
                rovlink_wire::json::encode_hex(&f[3..f.len() - 2])
            );
        }
        // ... and that dump packs back byte for byte without a key, as any dump does.
        let raw = run(DUMP, &["-f", "ndjson", "-q"], &stream).stdout;
        assert_eq!(run(PACK, &[], &raw).stdout, stream);
    }
}

#[test]
fn secured_dump_text_and_csv_say_the_verdict() {
    let dir = tempfile::tempdir().unwrap();
    let key = key_file(dir.path(), "rov.key", KEY_128);
    let k = key.to_str().unwrap();
    let frames = packed_frames(
        &["--key-file", k, "--encrypt", "--counter", "16385"],
        &format!("{GOTO}\n"),
    )
    .concat();
    let text = run(DUMP, &["--key-file", k], &frames);
    assert_eq!(text.code, 0, "{}", text.stderr);
    assert_eq!(
        text.stdout_text(),
        "@0         0->2  operator oid=0 eisn=1 rit=63 CLO IC | goto ned=(-2.50,12.00,3.10)m \
         heading=359deg  [secured, encrypted, ctr 16385: ok]\n"
    );
    let blind = run(DUMP, &[], &frames);
    assert!(
        blind
            .stdout_text()
            .ends_with("  [secured, encrypted, ctr low bits 1: unverified]\n"),
        "{}",
        blind.stdout_text()
    );
    let csv = run(DUMP, &["--key-file", k, "-f", "csv"], &frames).stdout_text();
    let mut rows = csv.lines();
    assert!(
        rows.next()
            .unwrap()
            .ends_with(",error,secured,encrypted,ctr,ctr_low,verdict")
    );
    assert!(
        rows.next().unwrap().ends_with(",,true,true,16385,,ok"),
        "{csv}"
    );
    // Without the key the CSV keeps version 0's columns and says it in the error column.
    let csv = run(DUMP, &["-f", "csv"], &frames).stdout_text();
    assert!(csv.lines().next().unwrap().ends_with(",payload,error"));
    assert!(
        csv.lines()
            .nth(1)
            .unwrap()
            .ends_with(",\"secured, encrypted, ctr low bits 1: unverified\""),
        "{csv}"
    );
}

#[test]
fn a_wrong_key_a_replay_and_a_plain_frame_fail_verification() {
    let dir = tempfile::tempdir().unwrap();
    let key = key_file(dir.path(), "rov.key", KEY_128);
    let other = key_file(dir.path(), "other.key", &"00".repeat(16));
    let k = key.to_str().unwrap();
    let frames = packed_frames(&["--key-file", k], &format!("{GOTO}\n{GOTO}\n"));
    let stream = frames.concat();

    let (code, lines, stderr) = dumped(&["--key-file", other.to_str().unwrap()], &stream);
    assert_eq!(code, 1, "{stderr}");
    for l in &lines {
        assert_eq!(l["verdict"], "bad_tag");
        assert_eq!(l["type"], "raw");
        assert!(l.get("ctr").is_none());
    }
    assert!(
        stderr.contains("rcp-dump: --key-file: 2 frames of <stdin> failed verification"),
        "{stderr}"
    );

    // The first frame again after the second, and the second twice in a row: replays.
    let replayed = [&frames[0], &frames[1], &frames[0], &frames[1]].map(|f| f.as_slice());
    let (code, lines, stderr) = dumped(&["--key-file", k], &replayed.concat());
    assert_eq!(code, 1, "{stderr}");
    let verdicts: Vec<&str> = lines
        .iter()
        .map(|l| l["verdict"].as_str().unwrap())
        .collect();
    assert_eq!(verdicts, ["ok", "ok", "replay", "replay"]);
    assert!(
        stderr.contains("offset 44: frame 0->2 refused: replay"),
        "{stderr}"
    );
    let summary = dir.path().join("summary.json");
    let out = run(
        DUMP,
        &[
            "-q",
            "--key-file",
            k,
            "--summary",
            summary.to_str().unwrap(),
        ],
        &replayed.concat(),
    );
    assert_eq!(out.code, 1);
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert_eq!(v["verdicts"], serde_json::json!({"ok": 2, "replay": 2}));
    // Every frame is listed: a refused one as its raw payload.
    assert_eq!(
        lines[2]["payload"].as_str().unwrap(),
        rovlink_wire::json::encode_hex(&frames[0][3..frames[0].len() - 2])
    );

    let plain = vector_frames().concat();
    let (code, lines, _) = dumped(&["--key-file", k], &plain);
    assert_eq!(code, 1);
    assert!(lines.iter().all(|l| l["verdict"] == "unsecured"));
    assert_eq!(
        lines
            .iter()
            .map(|l| message_only(l.clone()))
            .collect::<Vec<_>>(),
        String::from_utf8(vectors_jsonl())
            .unwrap()
            .lines()
            .collect::<Vec<_>>()
    );
}

#[test]
fn counters_can_be_set_per_line_and_bad_ones_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let key = key_file(dir.path(), "rov.key", KEY_128);
    let k = key.to_str().unwrap();
    let with = |ctr: &str| GOTO.replace("}}", &format!("}},\"ctr\":{ctr}}}"));
    // A replay is named as one when its counter is within 2^14 of the highest accepted (a
    // receiver restores a counter from its low bits); one older than that fails as bad_tag.
    let input = format!(
        "{}\n{GOTO}\n{}\n{}\n",
        with("40000"),
        with("39999"),
        with("3")
    );
    let out = run(PACK, &["--key-file", k], input.as_bytes());
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(
        out.stderr.contains(
            "<stdin>:3: counter 39999 of 0>2 is not above 40001, sealed before: a receiver \
             refuses this frame as a replay"
        ),
        "{}",
        out.stderr
    );
    let (_, lines, _) = dumped(&["--key-file", k], &out.stdout);
    let seen: Vec<(u64, &str)> = lines
        .iter()
        .map(|l| {
            (
                l["ctr"].as_u64().or(l["ctr_low"].as_u64()).unwrap(),
                l["verdict"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        seen,
        [
            (40000, "ok"),
            (40001, "ok"),
            (39999 % 16384, "replay"),
            (3, "bad_tag")
        ]
    );
    for (ctr, expected) in [
        ("0", "found 0"),
        ("281474976710656", "found 281474976710656"),
        ("\"7\"", "found \"7\""),
    ] {
        let out = run(
            PACK,
            &["--key-file", k],
            format!("{}\n", with(ctr)).as_bytes(),
        );
        assert_eq!(out.code, 2);
        assert_eq!(
            out.stderr.trim(),
            format!(
                "rcp-pack: <stdin>:1: field ctr: expected an integer 1..=281474976710655, {expected}"
            )
        );
    }
    // Without --key-file the field is ignored, as before.
    let plain = run(PACK, &[], format!("{}\n", with("0")).as_bytes());
    assert_eq!((plain.code, plain.stdout), (0, vector_frames()[2].clone()));
    // A frame no key covers (vehicle to vehicle) is a bad line.
    let between = r#"{"type":"raw","src":1,"dst":2,"payload":"00"}"#;
    let out = run(PACK, &["--key-file", k], format!("{between}\n").as_bytes());
    assert_eq!(out.code, 2);
    assert!(
        out.stderr
            .starts_with("rcp-pack: <stdin>:1: no key for frames from 1 to 2 in the key file"),
        "{}",
        out.stderr
    );
    assert_eq!(out.stderr.lines().count(), 1);
    assert_eq!(run(PACK, &["--key-file", k, "--counter", "0"], b"").code, 2);
    assert_eq!(run(PACK, &["--encrypt"], b"").code, 2);
}

#[test]
fn new_key_writes_a_private_file_once_and_never_shows_the_key() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("new.key");
    let p = path.to_str().unwrap();
    let out = run(PACK, &["--new-key", p, "--key-bits", "256"], b"");
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(out.stdout.is_empty());
    let text = std::fs::read_to_string(&path).unwrap();
    let key = text.lines().find(|l| l.starts_with("* ")).unwrap();
    assert_eq!(key.len(), 2 + 64);
    assert!(!out.stderr.contains(&key[2..18]), "{}", out.stderr);
    assert!(out.stderr.contains("256-bit"), "{}", out.stderr);
    let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600);
    // It serves at once: what it seals, it verifies.
    let frames = packed_frames(&["--key-file", p], &format!("{GOTO}\n")).concat();
    assert_eq!(run(DUMP, &["--key-file", p], &frames).code, 0);

    let again = run(PACK, &["--new-key", p], b"");
    assert_eq!(again.code, 2);
    assert_eq!(
        again.stderr.trim(),
        format!(
            "rcp-pack: --new-key: {p}: exists; a key file is never overwritten (remove it first)"
        )
    );
    assert_eq!(std::fs::read_to_string(&path).unwrap(), text);
    for args in [
        vec!["--new-key", p, "--key-bits", "64"],
        vec!["--key-bits", "128"],
        vec!["--new-key", p, "--key-file", p],
    ] {
        let out = run(PACK, &args, b"");
        assert_eq!(out.code, 2, "{args:?}");
        assert_eq!(out.stderr.lines().count(), 1, "{}", out.stderr);
    }
}

#[test]
fn hostile_key_files_are_refused_in_one_line() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let open = key_file(dir.path(), "open.key", KEY_128);
    std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o644)).unwrap();
    let empty = crate::common::private_file(dir.path(), "empty.key", "");
    let short = key_file(dir.path(), "short.key", &KEY_128[..30]);
    let cases = [
        (open.clone(), "permissions 0644 are too open"),
        (empty, "0 bytes: expected 1..="),
        (
            dir.path().to_path_buf(),
            "expected a regular file, found a directory",
        ),
        ("/dev/zero".into(), "expected a regular file"),
        (
            short,
            "line 1: key: expected 32 hex digits (128 bits) or 64 (256 bits), found 30",
        ),
        (dir.path().join("absent.key"), "cannot read"),
    ];
    for (path, expected) in cases {
        let p = path.to_str().unwrap();
        for (bin, stdin) in [(PACK, format!("{GOTO}\n")), (DUMP, String::new())] {
            let out = run(bin, &["--key-file", p], stdin.as_bytes());
            assert_eq!(out.code, 2, "{p}: {}", out.stderr);
            assert!(out.stdout.is_empty(), "{p}");
            assert_eq!(out.stderr.lines().count(), 1, "{p}: {}", out.stderr);
            assert!(out.stderr.contains("--key-file: "), "{}", out.stderr);
            assert!(out.stderr.contains(expected), "{p}: {}", out.stderr);
            assert!(!out.stderr.contains(&KEY_128[..16]), "{}", out.stderr);
        }
    }
}

#[test]
fn secured_frames_match_an_independent_python_implementation() {
    use std::process::Command;
    let probe = Command::new("python3")
        .args(["-c", "import cryptography"])
        .output();
    match probe {
        Err(e) => {
            println!("skipped: python3 cannot be started ({e})");
            return;
        }
        Ok(o) if !o.status.success() => {
            println!(
                "skipped: the Python module `cryptography` is missing (pip install cryptography)"
            );
            return;
        }
        Ok(_) => {}
    }
    let dir = tempfile::tempdir().unwrap();
    let k128 = key_file(dir.path(), "k128", KEY_128);
    let key_256 = "603deb1015ca71be2b73aef0857d77811f352c073b6108d72d9810a30914dff4";
    let k256 = key_file(dir.path(), "k256", key_256);
    let rov = String::from_utf8(vectors_jsonl())
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .to_string();
    let mut groups: Vec<String> = Vec::new();
    let cases = [
        (&k128, KEY_128, GOTO, "1", false),
        (&k128, KEY_128, GOTO, "16385", true),
        (&k128, KEY_128, rov.as_str(), "16385", false),
        (&k128, KEY_128, rov.as_str(), "1", true),
        (&k256, key_256, GOTO, "12345", true),
    ];
    for (file, key, line, counter, encrypt) in cases {
        let plain = packed_frames(&[], &format!("{line}\n")).concat();
        let mut args = vec!["--key-file", file.to_str().unwrap(), "--counter", counter];
        if encrypt {
            args.push("--encrypt");
        }
        let sealed = packed_frames(&args, &format!("{line}\n")).concat();
        groups.extend([
            key.to_string(),
            if encrypt {
                format!("e:{counter}")
            } else {
                counter.to_string()
            },
            rovlink_wire::json::encode_hex(&plain),
            rovlink_wire::json::encode_hex(&sealed),
        ]);
    }
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/secured-frame-check.py");
    let out = Command::new("python3")
        .arg(&script)
        .args(&groups)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        stdout.lines().filter(|l| l.starts_with("ok ")).count(),
        cases.len(),
        "{stdout}"
    );
    // The script tells a wrong frame from a right one.
    let mut wrong = groups[..4].to_vec();
    wrong[1] = "2".into();
    let out = Command::new("python3")
        .arg(&script)
        .args(&wrong)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
}

#[test]
fn image_trunks_are_sealed_and_a_trunk_without_room_for_the_tag_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let key = key_file(dir.path(), "rov.key", KEY_128);
    let k = key.to_str().unwrap();
    let image = dir.path().join("image.bin");
    std::fs::write(&image, (0..500u32).map(|i| i as u8).collect::<Vec<_>>()).unwrap();
    let i = image.to_str().unwrap();
    let sealed = run(PACK, &["--image", i, "--key-file", k, "--encrypt"], b"");
    assert_eq!(sealed.code, 0, "{}", sealed.stderr);
    let (code, lines, stderr) = dumped(&["--key-file", k], &sealed.stdout);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(lines.len(), 13);
    assert!(
        lines
            .iter()
            .all(|l| l["verdict"] == "ok" && l["type"] == "rov")
    );
    assert_eq!(lines[12]["ctr"], 13);
    let full = run(
        PACK,
        &["--image", i, "--trunk", "242", "--key-file", k],
        b"",
    );
    assert_eq!(full.code, 2);
    assert_eq!(
        full.stderr.trim(),
        format!(
            "rcp-pack: {i}: trunk 0: message of 255 bytes: a secured frame carries at most 249"
        )
    );
}
