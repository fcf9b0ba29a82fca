//! octo-delta's robot-log input (MCAP bags, rosbag2 directories) as a hostile user feeds it:
//! a YAML alias bomb as metadata.yaml, a TF chain of 100 000 frames, outputs onto the files of
//! a bag directory, a signal during the walk of a decompressed chunk of a million records, a
//! metadata.yaml that counts clouds its .db3 lacks. The contract: exit 0 or 2 (130/143 when
//! signalled), one line naming the file and what was wrong, never a panic or a hang, no output
//! file after exit 2, the bag untouched.
//!
//! The bags are written here, in Rust (the CDR encoders of `rovlink_scans::ros`, a few MCAP
//! records by hand, SQLite for the `.db3`), so these tests need no Python.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::common::hostile::{
    Run, SignalWhen, Stdin, assert_contract, run_in, signal_when, temp_files,
};
use crate::common::tree;
use nix::sys::signal::Signal;
use rovlink_octo::{Pose, Scan};
use rovlink_scans::ros::{
    ByteOrder, Header, Transform, TransformStamped, encode_point_cloud2, encode_tf_message,
};

const OCTO: &str = env!("TOOL_EXE_octo-delta");
const LIMIT: Duration = Duration::from_secs(60);
const TF: &str = "tf2_msgs/msg/TFMessage";
const CLOUD: &str = "sensor_msgs/msg/PointCloud2";

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn octo(dir: &Path, args: &[&str]) -> Run {
    run_in(dir, OCTO, args, b"", LIMIT)
}

/// Exit 2, one line prefixed with the tool's name containing `needle`, no temporary file.
fn refused(dir: &Path, run: &Run, needle: &str, what: &str) {
    assert_contract(run, &[2], what);
    let lines: Vec<&str> = run.stderr.lines().collect();
    assert_eq!(lines.len(), 1, "{what}: not one line: {:?}", run.stderr);
    assert!(
        lines[0].starts_with("octo-delta: ") && lines[0].contains(needle),
        "{what}: {:?} does not name {needle:?}",
        lines[0]
    );
    assert!(temp_files(dir).is_empty(), "{what}: temporary files left");
}

fn link(stamp_ns: i64, parent: &str, child: &str) -> TransformStamped {
    TransformStamped {
        header: Header {
            stamp_ns,
            frame_id: parent.into(),
        },
        child_frame_id: child.into(),
        transform: Transform {
            translation_m: [0.5, 0.0, 0.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
        },
    }
}

fn cloud(frame: &str) -> Vec<u8> {
    let scan = Scan {
        points: vec![[1.0, 0.0, -0.5], [0.5, 0.7, -1.0], [-0.3, 0.2, -2.0]],
        colors: None,
        pose: Pose::IDENTITY,
    };
    let header = Header {
        stamp_ns: 1_000,
        frame_id: frame.into(),
    };
    encode_point_cloud2(&header, &scan, ByteOrder::Little)
}

// --- MCAP written by hand (the records octo-delta reads) ---

fn record(out: &mut Vec<u8>, opcode: u8, body: &[u8]) {
    out.push(opcode);
    out.extend((body.len() as u64).to_le_bytes());
    out.extend(body);
}

fn string(text: &str) -> Vec<u8> {
    let mut b = (text.len() as u32).to_le_bytes().to_vec();
    b.extend(text.as_bytes());
    b
}

const MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// An MCAP file of `records` (between the Header and the Footer), without a summary.
fn mcap(records: &[u8]) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    let mut header = string("ros2");
    header.extend(string("hostile"));
    record(&mut out, 0x01, &header);
    out.extend(records);
    record(&mut out, 0x02, &[0u8; 20]);
    out.extend(MAGIC);
    out
}

/// Schema, Channel and Message records: one topic per (topic, type), messages in order.
fn messages(list: &[(&str, &str, Vec<u8>)]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut topics: Vec<&str> = Vec::new();
    for (i, (topic, schema, data)) in list.iter().enumerate() {
        let id = match topics.iter().position(|t| t == topic) {
            Some(id) => id as u16 + 1,
            None => {
                topics.push(topic);
                let id = topics.len() as u16;
                let mut body = id.to_le_bytes().to_vec();
                body.extend(string(schema));
                body.extend(string("ros2msg"));
                body.extend(0u32.to_le_bytes());
                record(&mut out, 0x03, &body);
                let mut body = id.to_le_bytes().to_vec();
                body.extend(id.to_le_bytes());
                body.extend(string(topic));
                body.extend(string("cdr"));
                body.extend(0u32.to_le_bytes());
                record(&mut out, 0x04, &body);
                id
            }
        };
        let mut body = id.to_le_bytes().to_vec();
        body.extend((i as u32).to_le_bytes());
        body.extend((i as u64 + 1).to_le_bytes());
        body.extend((i as u64 + 1).to_le_bytes());
        body.extend(data);
        record(&mut out, 0x05, &body);
    }
    out
}

/// A Chunk record holding `records` zstd-compressed (CRC 0: not checked).
fn zstd_chunk(records: &[u8]) -> Vec<u8> {
    let compressed = zstd::encode_all(records, 3).unwrap();
    let mut body = Vec::new();
    body.extend(0u64.to_le_bytes());
    body.extend(0u64.to_le_bytes());
    body.extend((records.len() as u64).to_le_bytes());
    body.extend(0u32.to_le_bytes());
    body.extend(string("zstd"));
    body.extend((compressed.len() as u64).to_le_bytes());
    body.extend(compressed);
    let mut out = Vec::new();
    record(&mut out, 0x06, &body);
    out
}

/// An MCAP bag at `path`: one /tf_static message of `links`, then one cloud in `frame`.
fn tf_bag(path: &Path, links: &[TransformStamped], frame: &str) {
    let records = messages(&[
        (
            "/tf_static",
            TF,
            encode_tf_message(links, ByteOrder::Little),
        ),
        ("/points", CLOUD, cloud(frame)),
    ]);
    std::fs::write(path, mcap(&records)).unwrap();
}

// --- rosbag2 (sqlite3 storage) written with SQLite ---

const METADATA: &str = "\
rosbag2_bagfile_information:
  version: 5
  storage_identifier: sqlite3
  relative_file_paths:
    - bag_0.db3
  topics_with_message_count:
    - topic_metadata:
        name: /tf_static
        type: tf2_msgs/msg/TFMessage
        serialization_format: cdr
        offered_qos_profiles: \"\"
      message_count: 1
    - topic_metadata:
        name: /points
        type: sensor_msgs/msg/PointCloud2
        serialization_format: cdr
        offered_qos_profiles: \"\"
      message_count: 1
  compression_format: \"\"
  compression_mode: \"\"
";

/// A rosbag2 directory `dir/bag` (metadata.yaml, bag_0.db3): one static link map -> sensor and
/// one cloud in sensor; with `topics` false the database's topics table is left empty.
fn rosbag2(dir: &Path, topics: bool) -> PathBuf {
    let bag = dir.join("bag");
    std::fs::create_dir_all(&bag).unwrap();
    std::fs::write(bag.join("metadata.yaml"), METADATA).unwrap();
    let conn = rusqlite::Connection::open(bag.join("bag_0.db3")).unwrap();
    conn.execute_batch(
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
             serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);
         CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
             timestamp INTEGER NOT NULL, data BLOB NOT NULL);",
    )
    .unwrap();
    if topics {
        conn.execute_batch(
            "INSERT INTO topics VALUES (1, '/tf_static', 'tf2_msgs/msg/TFMessage', 'cdr', ''),
                                       (2, '/points', 'sensor_msgs/msg/PointCloud2', 'cdr', '');",
        )
        .unwrap();
    }
    let tf = encode_tf_message(&[link(0, "map", "sensor")], ByteOrder::Little);
    conn.execute(
        "INSERT INTO messages VALUES (1, 1, 1, ?1), (2, 2, 2, ?2)",
        (tf, cloud("sensor")),
    )
    .unwrap();
    bag
}

#[test]
fn outputs_onto_a_bag_directorys_own_files_are_refused_and_the_bag_kept() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bag = rosbag2(d, true);
    let before = tree(&bag);
    let db3 = bag.join("bag_0.db3");
    let yaml = bag.join("metadata.yaml");
    let out = d.join("out.odl");
    // Each way of naming the bag, each output flag, onto each of its files.
    let cases: [(&Path, &str, &Path); 6] = [
        (&bag, "-o", &db3),
        (&bag, "--bt", &yaml),
        (&yaml, "--ot", &db3),
        (&db3, "-o", &yaml),
        (&yaml, "--stats", &yaml),
        (&db3, "--bt", &db3),
    ];
    for (input, flag, target) in cases {
        let mut args = vec!["build", "-q", s(input)];
        if flag != "-o" {
            args.extend(["-o", s(&out)]);
        }
        args.extend([flag, s(target)]);
        let what = format!("build {} {flag} {}", input.display(), target.display());
        let r = octo(d, &args);
        refused(d, &r, "refusing to overwrite an input", &what);
        assert!(!out.exists(), "{what}: left {}", out.display());
        assert_eq!(tree(&bag), before, "{what}: the bag changed");
    }
    // A new file inside the bag directory is fine, and so is writing it again.
    let inside = bag.join("map.odl");
    for _ in 0..2 {
        let r = octo(d, &["build", "-q", s(&bag), "-o", s(&inside)]);
        assert_contract(&r, &[0], "build into the bag directory");
    }
    assert!(inside.is_file());
}

#[test]
fn a_database_without_the_topics_its_metadata_counts_is_an_error_not_an_empty_map() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let good = rosbag2(&d.join("good"), true);
    let r = octo(d, &["build", "-q", s(&good), "-o", "good.odl"]);
    assert_contract(&r, &[0], "the bag with its topics");
    let bag = rosbag2(d, false);
    let r = octo(d, &["build", "-q", s(&bag), "-o", "out.odl"]);
    refused(
        d,
        &r,
        "cloud topic \"/points\": expected 1 messages (as the bag says), found none",
        "a .db3 without topics",
    );
    assert!(!d.join("out.odl").exists());
}

#[test]
fn a_fifo_where_a_bag_file_is_expected_is_refused_without_waiting() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bag = rosbag2(d, true);
    let db3 = bag.join("bag_0.db3");
    std::fs::remove_file(&db3).unwrap();
    nix::unistd::mkfifo(&db3, nix::sys::stat::Mode::S_IRWXU).unwrap();
    // The directory, its metadata and the .db3 named alone: each reads the FIFO, which has no
    // writer (opening it for reading would block forever).
    for input in [&bag, &bag.join("metadata.yaml"), &db3] {
        let r = octo(d, &["build", "-q", s(input), "-o", "out.odl"]);
        refused(
            d,
            &r,
            "expected a regular file, found a FIFO",
            &format!("a FIFO .db3 via {}", input.display()),
        );
        assert!(r.stderr.contains("bag_0.db3: "), "{}", r.stderr);
        assert!(!d.join("out.odl").exists());
    }
    // The same for metadata.yaml. (A FIFO named as a bag file on the command line, such as
    // `live.mcap`, is read as a stream, as it was, and a signal ends the wait for its writer.)
    std::fs::remove_file(&db3).unwrap();
    let yaml = bag.join("metadata.yaml");
    std::fs::remove_file(&yaml).unwrap();
    nix::unistd::mkfifo(&yaml, nix::sys::stat::Mode::S_IRWXU).unwrap();
    let r = octo(d, &["build", "-q", s(&bag), "-o", "out.odl"]);
    refused(
        d,
        &r,
        "metadata.yaml: opening: expected a regular file, found a FIFO",
        "FIFO yaml",
    );
}

#[test]
fn a_file_listed_twice_or_too_many_files_in_metadata_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bag = rosbag2(d, true);
    let listed = |names: &[String]| {
        let list: String = names.iter().map(|n| format!("    - {n}\n")).collect();
        METADATA.replace("    - bag_0.db3\n", &list)
    };
    // Listed twice, its clouds would be inserted twice.
    let twice = vec!["bag_0.db3".to_string(); 2];
    std::fs::write(bag.join("metadata.yaml"), listed(&twice)).unwrap();
    let r = octo(d, &["build", "-q", s(&bag), "-o", "out.odl"]);
    refused(
        d,
        &r,
        "relative_file_paths[1]: \"bag_0.db3\" is listed twice (first at [0])",
        "a file listed twice",
    );
    // 100 000 entries (each would hold an open SQLite connection) are refused before any open.
    let many: Vec<String> = (0..100_000).map(|i| format!("bag_{i}.db3")).collect();
    std::fs::write(bag.join("metadata.yaml"), listed(&many)).unwrap();
    let r = octo(d, &["build", "-q", s(&bag), "-o", "out.odl"]);
    refused(
        d,
        &r,
        "relative_file_paths: expected at most 1000 files, found 100000",
        "100 000 files",
    );
    assert!(!d.join("out.odl").exists());
}

#[test]
fn a_yaml_alias_bomb_in_metadata_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bag = rosbag2(d, true);
    // Twelve lines that a loader copying each alias's value expands to 10^12 nodes.
    let mut yaml = String::from("a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n");
    for i in 1..12 {
        let refs = vec![format!("*a{}", i - 1); 10].join(", ");
        yaml += &format!("a{i}: &a{i} [{refs}]\n");
    }
    yaml += "rosbag2_bagfile_information: *a11\n";
    std::fs::write(bag.join("metadata.yaml"), yaml).unwrap();
    let started = Instant::now();
    let r = run_in(
        d,
        OCTO,
        &["build", "-q", s(&bag), "-o", "out.odl"],
        b"",
        LIMIT,
    );
    refused(
        d,
        &r,
        "metadata.yaml: rosbag2 metadata: line 2 column 10: expected plain YAML (rosbag2 writes \
         no anchors or aliases), found an alias",
        "alias bomb",
    );
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "took {:?}",
        started.elapsed()
    );
    // Deep nesting stops at the parser's recursion limit.
    std::fs::write(
        bag.join("metadata.yaml"),
        format!("x: {}{}\n", "[".repeat(100_000), "]".repeat(100_000)),
    )
    .unwrap();
    let r = octo(d, &["build", "-q", s(&bag), "-o", "out.odl"]);
    refused(d, &r, "recursion limit exceeded", "deep nesting");
}

#[test]
fn a_tf_chain_of_a_hundred_thousand_frames_is_read_in_seconds() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    const N: usize = 100_000;
    let chain: Vec<TransformStamped> = (0..N)
        .map(|i| link(0, &format!("f{i}"), &format!("f{}", i + 1)))
        .collect();
    let frame = format!("f{N}");
    tf_bag(&d.join("chain.mcap"), &chain, &frame);
    // Checking the chain for cycles was quadratic in its length (110 s for this one).
    for fixed in [None, Some("f50000")] {
        let mut args = vec!["build", "-q", "chain.mcap", "-o", "out.odl"];
        args.extend(fixed.iter().flat_map(|f| ["--fixed-frame", f]));
        let started = Instant::now();
        let r = octo(d, &args);
        assert_contract(&r, &[0], "a chain of 100 000 frames");
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "{fixed:?}: took {:?}",
            started.elapsed()
        );
    }
    // The same chain closed into a cycle is an error naming it.
    let mut cycle = chain;
    cycle.push(link(0, &frame, "f0"));
    tf_bag(&d.join("cycle.mcap"), &cycle, &frame);
    std::fs::remove_file(d.join("out.odl")).unwrap();
    let started = Instant::now();
    let r = octo(d, &["build", "-q", "cycle.mcap", "-o", "out.odl"]);
    refused(
        d,
        &r,
        "TF frames form a cycle: expected a tree",
        "a long cycle",
    );
    // Named by its first frames and its length, in a line that stays short.
    assert!(r.stderr.len() < 400, "{} bytes", r.stderr.len());
    assert!(r.stderr.contains("(100001 frames in all)"), "{}", r.stderr);
    assert!(started.elapsed() < Duration::from_secs(20));
    assert!(!d.join("out.odl").exists());
}

#[test]
fn a_signal_stops_the_walk_of_a_huge_decompressed_chunk_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 256 MiB of zeros compress to a few kB; decompressed they are 30 million empty records,
    // walked when the file (it has no summary) is opened.
    let zeros = vec![0u8; 256 << 20];
    std::fs::write(d.join("bomb.mcap"), mcap(&zstd_chunk(&zeros))).unwrap();
    drop(zeros);
    let r = octo(d, &["build", "-q", "bomb.mcap", "-o", "out.odl"]);
    refused(d, &r, "bomb.mcap: ", "a chunk of zeros");
    // Where a whole walk ends: the error the run above gives at the end of the chunk.
    let end_of_walk = "decompressed offset 268435449";
    assert!(r.stderr.contains(end_of_walk), "{}", r.stderr);
    for signal in [Signal::SIGINT, Signal::SIGTERM] {
        // Signalled as soon as its handlers are in place: during the open, the zstd
        // decompression (which does not poll) or the walk, it ends as interrupted, and it never
        // walks to the end of the chunk (which takes seconds; the signal comes within ms).
        let r = signal_when(
            d,
            OCTO,
            &["build", "-q", "bomb.mcap", "-o", "out.odl"],
            Stdin::Bytes(b""),
            SignalWhen {
                signal,
                ready: &|_| true,
            },
            LIMIT,
        );
        let code = if signal == Signal::SIGINT { 130 } else { 143 };
        assert_contract(&r, &[code], &format!("{signal:?} during the walk"));
        assert!(
            !r.stderr.contains(end_of_walk),
            "{signal:?}: walked to the end of the chunk: {}",
            r.stderr
        );
        assert!(temp_files(d).is_empty());
    }
}
