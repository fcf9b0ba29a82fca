//! `rovlink_scans::bag` reads the bags that the real ROS 2 writers write: the `mcap` and
//! `mcap-ros2-support` Python writers (zstd, lz4 and uncompressed chunks, unchunked) and
//! `rosbags` (rosbag2 directories with sqlite3 or mcap storage, payloads plain or
//! zstd-compressed one by one), through `tests/bags/write_bag.py`.
//!
//! Needs `python3` with `mcap`, `mcap-ros2-support` and `rosbags` (`.ci/run` installs them):
//! without them these tests fail, saying what to install.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::AtomicBool;

use rovlink_scans::bag::Bag;

const CLOUD: &str = "sensor_msgs/msg/PointCloud2";
const TF: &str = "tf2_msgs/msg/TFMessage";

/// (topic, type, log time, payload).
type Written = (String, String, u64, Vec<u8>);

fn hex(b: &[u8]) -> String {
    b.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len() / 2)
        .map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).unwrap())
        .collect()
}

/// Writes `messages` as a bag of `kind` at `out` with the real writers; what was written (the
/// script reads MCAP files back with the official reader).
fn write(kind: &str, out: &Path, messages: &[Written]) -> Vec<(String, u64, Vec<u8>)> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/bags/write_bag.py");
    let mut child = Command::new("python3")
        .arg(&script)
        .args(["--kind", kind, "--out"])
        .arg(out)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| {
            panic!(
                "python3 not runnable ({e}): install Python 3 and then `python3 -m pip install \
                 mcap mcap-ros2-support rosbags`"
            )
        });
    let mut input = String::new();
    for (topic, ty, t, data) in messages {
        input.push_str(&format!(
            "{{\"topic\":\"{topic}\",\"type\":\"{ty}\",\"log_time_ns\":{t},\"cdr\":\"{}\"}}\n",
            hex(data)
        ));
    }
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let output = child.wait_with_output().unwrap();
    assert!(
        output.status.success(),
        "write_bag.py --kind {kind} failed ({}): {}\n(the Python writers are needed: \
         `python3 -m pip install mcap mcap-ros2-support rosbags`)",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout)
        .unwrap()
        .lines()
        .map(|line| {
            let v: serde_json::Value = serde_json::from_str(line).unwrap();
            (
                v["topic"].as_str().unwrap().to_string(),
                v["log_time_ns"].as_u64().unwrap(),
                unhex(v["cdr"].as_str().unwrap()),
            )
        })
        .collect()
}

/// Clouds on `/points` (some big, so MCAP files get several chunks) and TF on `/tf`.
fn messages() -> Vec<Written> {
    let mut out = Vec::new();
    for i in 0..12u64 {
        let t = 1_700_000_000_000_000_000 + i * 50_000_000;
        let tf: Vec<u8> = (0..40).map(|k| (k as u64 * 7 + i) as u8).collect();
        out.push(("/tf".into(), TF.into(), t, tf));
        if i % 3 == 0 {
            let len = 1000 + 3000 * i as usize;
            let cloud: Vec<u8> = (0..len).map(|k| (k as u64 * 31 + i) as u8).collect();
            out.push(("/points".into(), CLOUD.into(), t + 1, cloud));
        }
    }
    out
}

/// Every message of `bag`: (topic name, log time, payload), and the topics (name, type,
/// encoding, count).
#[allow(clippy::type_complexity)]
fn read(
    path: &Path,
) -> (
    Vec<(String, u64, Vec<u8>)>,
    Vec<(String, String, String, Option<u64>)>,
) {
    let mut bag = Bag::open(path).unwrap_or_else(|e| panic!("{e}"));
    let topics: Vec<_> = bag
        .topics()
        .iter()
        .map(|t| {
            (
                t.name.clone(),
                t.schema.clone(),
                t.encoding.clone(),
                t.messages,
            )
        })
        .collect();
    let names: Vec<String> = topics.iter().map(|t| t.0.clone()).collect();
    let all: Vec<usize> = (0..names.len()).collect();
    let stop = AtomicBool::new(false);
    let got = bag
        .messages(&all, &stop)
        .unwrap()
        .map(|m| {
            let m = m.unwrap_or_else(|e| panic!("{e}"));
            (names[m.topic].clone(), m.log_time_ns, m.data)
        })
        .collect();
    (got, topics)
}

fn expected_topics() -> Vec<(String, String, String, Option<u64>)> {
    vec![
        ("/tf".into(), TF.into(), "cdr".into(), Some(12)),
        ("/points".into(), CLOUD.into(), "cdr".into(), Some(4)),
    ]
}

fn plain(messages: &[Written]) -> Vec<(String, u64, Vec<u8>)> {
    messages
        .iter()
        .map(|(topic, _, t, d)| (topic.clone(), *t, d.clone()))
        .collect()
}

#[test]
fn mcap_files_of_every_compression() {
    let dir = tempfile::tempdir().unwrap();
    let messages = messages();
    for kind in ["mcap-zstd", "mcap-lz4", "mcap-none", "mcap-unchunked"] {
        let path = dir.path().join(format!("{kind}.mcap"));
        let written = write(kind, &path, &messages);
        assert_eq!(
            written,
            plain(&messages),
            "{kind}: the writer wrote what it was given"
        );
        let (got, topics) = read(&path);
        assert_eq!(topics, expected_topics(), "{kind}");
        assert_eq!(got, written, "{kind}");
        // Only one topic, and the same bytes from memory.
        let mut bag = Bag::from_mcap_bytes("stdin", std::fs::read(&path).unwrap()).unwrap();
        let stop = AtomicBool::new(false);
        let clouds: Vec<_> = bag
            .messages(&[1], &stop)
            .unwrap()
            .map(|m| m.unwrap().data)
            .collect();
        let want: Vec<_> = messages
            .iter()
            .filter(|m| m.0 == "/points")
            .map(|m| m.3.clone())
            .collect();
        assert_eq!(clouds, want, "{kind}");
    }
}

#[test]
fn rosbag2_directories_by_directory_metadata_and_file() {
    let dir = tempfile::tempdir().unwrap();
    let messages = messages();
    for (kind, ext) in [
        ("db3", "db3"),
        ("db3-message-zstd", "db3"),
        ("rosbag2-mcap", "mcap"),
    ] {
        let bag = dir.path().join(kind);
        write(kind, &bag, &messages);
        let file = bag.join(format!("{kind}.{ext}"));
        assert!(file.is_file(), "{kind}: {} written", file.display());
        for path in [bag.clone(), bag.join("metadata.yaml"), file] {
            let (got, topics) = read(&path);
            assert_eq!(topics, expected_topics(), "{kind} {}", path.display());
            assert_eq!(got, plain(&messages), "{kind} {}", path.display());
        }
        assert!(Bag::is_bag_path(&bag));
    }
}

#[test]
fn db3_messages_come_in_time_order() {
    let dir = tempfile::tempdir().unwrap();
    let mut messages = messages();
    messages.reverse();
    let bag = dir.path().join("reversed");
    write("db3", &bag, &messages);
    let (got, _) = read(&bag);
    let mut want = plain(&messages);
    want.sort_by_key(|m| m.1);
    assert_eq!(got, want);
}

#[test]
fn mcap_ros2_writer_clouds_read_as_scans() {
    let dir = tempfile::tempdir().unwrap();
    let path: PathBuf = dir.path().join("ros2.mcap");
    let messages: Vec<Written> = (1..=3)
        .map(|i| {
            (
                "/cloud".to_string(),
                CLOUD.to_string(),
                i * 1_000,
                Vec::new(),
            )
        })
        .collect();
    let written = write("mcap-ros2", &path, &messages);
    assert_eq!(written.len(), 3);
    let (got, topics) = read(&path);
    assert_eq!(
        topics,
        [("/cloud".into(), CLOUD.into(), "cdr".into(), Some(3))]
    );
    assert_eq!(got, written);
    let scans = rovlink_scans::cloud::read_mcap(
        &std::fs::read(&path).unwrap(),
        &rovlink_scans::cloud::McapOptions::default(),
    )
    .unwrap();
    assert_eq!(scans.scans.len(), 3);
    assert_eq!(scans.scans[0].points, vec![[1.0, 2.0, 3.0]]);
    assert_eq!(scans.log_times_ns, [1_000, 2_000, 3_000]);
}

/// Reading speed and memory: `BAG_BENCH_FILE=big.mcap cargo test --release -p rovlink-scans --test bag_writers
/// -- --ignored read_speed --nocapture` under `/usr/bin/time -v` (peak RSS).
#[test]
#[ignore = "a measurement on a file given by BAG_BENCH_FILE"]
fn read_speed() {
    let path = std::env::var("BAG_BENCH_FILE").expect("BAG_BENCH_FILE: a bag to read");
    let start = std::time::Instant::now();
    let mut bag = Bag::open(Path::new(&path)).unwrap();
    let all: Vec<usize> = (0..bag.topics().len()).collect();
    let stop = AtomicBool::new(false);
    let (mut n, mut bytes) = (0u64, 0u64);
    for m in bag.messages(&all, &stop).unwrap() {
        n += 1;
        bytes += m.unwrap().data.len() as u64;
    }
    let s = start.elapsed().as_secs_f64();
    println!(
        "{n} messages, {:.1} MB of payload in {s:.3} s: {:.0} MB/s",
        bytes as f64 / 1e6,
        bytes as f64 / 1e6 / s
    );
}
