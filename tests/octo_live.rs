//! octo-delta map and view over real pseudo-terminals through link-sim (the satellite uplink
//! model with 5% frame loss both ways): the view's final .ot is the offline `build | apply`'s,
//! byte for byte, also with the view killed and restarted, the mapper killed and restarted,
//! and an outage; requests are answered (and refused when they must be); the stock Foxglove
//! client sees the map grow; bad bytes on the link are counted, never applied. Every wait is
//! for a sign (a line the tools print, a process ending), with a generous deadline.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::common::watched::{DEADLINE, Watched};
use crate::common::{Reaped, link_sim_pty};

const OCTO: &str = env!("TOOL_EXE_octo-delta");

fn path(dir: &Path, name: &str) -> String {
    dir.join(name).to_str().unwrap().to_string()
}

/// A survey of `scans` scans and the view `apply` gives of its offline `build` stream.
fn offline(dir: &Path, scans: u32) -> (PathBuf, Vec<u8>) {
    let survey = dir.join("survey.graph");
    let run = |args: &[&str]| {
        let out = Command::new(OCTO).args(args).output().unwrap();
        assert!(out.status.success(), "{args:?}: {out:?}");
    };
    run(&[
        "synth",
        "--scans",
        &scans.to_string(),
        "-o",
        survey.to_str().unwrap(),
    ]);
    run(&[
        "build",
        survey.to_str().unwrap(),
        "-q",
        "-o",
        &path(dir, "offline.odl"),
    ]);
    run(&[
        "apply",
        &path(dir, "offline.odl"),
        "-o",
        &path(dir, "offline.ot"),
    ]);
    (survey, std::fs::read(dir.join("offline.ot")).unwrap())
}

/// Starts link-sim --pty with the satellite uplink and downlink and `extra` flags.
fn link(extra: &[&str]) -> (Reaped, String, String) {
    let mut args = vec![
        "--model",
        "satellite-up",
        "--reverse-model",
        "satellite-down",
    ];
    args.extend_from_slice(extra);
    link_sim_pty(&args)
}

/// A survey written as it is recorded, `pace_s` between scans.
fn record(dir: &Path, scans: u32, pace_s: &str) -> Reaped {
    let child = Command::new(OCTO)
        .args(["synth", "--scans", &scans.to_string(), "--pace", pace_s])
        .args(["-o", &path(dir, "live.graph")])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    Reaped(child)
}

fn map_args<'a>(dir: &'a Path, port: &'a str, extra: &[&'a str]) -> Vec<String> {
    let mut a: Vec<String> = ["map", "--follow", "--exit-when-done", "--port", port]
        .iter()
        .map(|s| s.to_string())
        .collect();
    a.push(path(dir, "live.graph"));
    a.extend(extra.iter().map(|s| s.to_string()));
    a
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

/// The byte ranges of a `.graph`: the node count, each node, the edge count.
fn graph_parts(bytes: &[u8]) -> Vec<std::ops::Range<usize>> {
    let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap()) as usize;
    let mut parts = Vec::new();
    parts.push(0..4);
    let mut at = 4;
    for _ in 0..u32_at(0) {
        // Point count, points (tag and three f64 each), pose (vector, quaternion), id.
        let end = at + 4 + 28 * u32_at(at) + 28 + 36 + 4;
        parts.push(at..end);
        at = end;
    }
    parts.push(at..bytes.len());
    parts
}

/// Appends parts `from..to` of `survey` to the file being recorded.
fn append(file: &Path, survey: &[u8], parts: &[std::ops::Range<usize>], from: usize, to: usize) {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(file)
        .unwrap();
    for p in &parts[from..to] {
        f.write_all(&survey[p.clone()]).unwrap();
    }
}

#[test]
fn the_live_view_is_the_offline_view_through_loss_and_restarts_of_both_ends() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scans = 16;
    let (survey, want) = offline(d, scans);
    let survey = std::fs::read(survey).unwrap();
    let parts = graph_parts(&survey);
    let live = d.join("live.graph");
    // The recording so far: the node count and 6 scans.
    append(&live, &survey, &parts, 0, 7);
    let (_link, a, b) = link(&["--loss-percent", "5"]);
    let view1_ot = path(d, "view1.ot");
    let mut view1 = Watched::spawn(&["view", "--port", &b, "-o", &view1_ot]);
    let margs = map_args(d, &a, &["--metrics", &path(d, "map1.json")]);
    let mut mapper = Watched::spawn(&strs(&margs));
    // The view is killed once it shows scan 5, as an operator closing it would.
    view1.wait_for("scan 5: ");
    view1.signal(nix::sys::signal::Signal::SIGTERM);
    let (code, said) = view1.finish();
    assert_eq!(code, Some(143), "{said}");
    let first = std::fs::read(&view1_ot).unwrap();
    assert!(first.starts_with(b"# Octomap OcTree file"), "{said}");
    // Four more scans while no view runs; then a new view catches up by itself.
    append(&live, &survey, &parts, 7, 11);
    mapper.wait_for("mapped scan 9");
    let view_ot = path(d, "view.ot");
    let vmetrics = path(d, "view.json");
    let mut view = Watched::spawn(&[
        "view",
        "--port",
        &b,
        "-o",
        &view_ot,
        "--metrics",
        &vmetrics,
        "--exit-after-scan",
        &(scans - 1).to_string(),
    ]);
    view.wait_for("scan 9: ");
    // The mapper is killed and started again: a new stream (the recording read again from
    // its start), which the view follows.
    mapper.signal(nix::sys::signal::Signal::SIGTERM);
    let (code, said) = mapper.finish();
    assert_eq!(code, Some(143), "{said}");
    let margs = map_args(d, &a, &["--metrics", &path(d, "map2.json")]);
    let mut mapper = Watched::spawn(&strs(&margs));
    view.wait_for("began: resynchronising");
    mapper.wait_for("mapped scan 9");
    append(&live, &survey, &parts, 11, parts.len());
    let (code, said) = view.finish();
    assert_eq!(code, Some(0), "{said}");
    let (code, said) = mapper.finish();
    assert_eq!(code, Some(0), "{said}");
    assert!(said.contains("all acknowledged"), "{said}");
    let got = std::fs::read(&view_ot).unwrap();
    assert!(got == want, "the live view differs from the offline one");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&vmetrics).unwrap()).unwrap();
    assert!(m["view"]["mapper_restarts"].as_u64().unwrap() >= 1, "{m}");
    assert_eq!(m["transport"]["malformed"], 0, "{m}");
}

#[test]
fn an_outage_loses_no_change() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scans = 12;
    let (_, want) = offline(d, scans);
    // Out of range from 2 s to 6 s of link time: nothing crosses either way.
    std::fs::write(
        d.join("distance.csv"),
        "t_s,distance_m\n0,1\n2,1\n2.001,5000\n6,5000\n6.001,1\n",
    )
    .unwrap();
    let dist = path(d, "distance.csv");
    let (_link, a, b) = link(&["--range-max-m", "1000", "--distance-file", &dist]);
    let _recorder = record(d, scans, "0.25");
    let view_ot = path(d, "view.ot");
    let view = Watched::spawn(&[
        "view",
        "--port",
        &b,
        "-o",
        &view_ot,
        "--exit-after-scan",
        &(scans - 1).to_string(),
    ]);
    let margs = map_args(d, &a, &["--metrics", &path(d, "map.json")]);
    let mapper = Watched::spawn(&strs(&margs));
    let (code, said) = view.finish();
    assert_eq!(code, Some(0), "{said}");
    let (code, said) = mapper.finish();
    assert_eq!(code, Some(0), "{said}");
    assert!(std::fs::read(&view_ot).unwrap() == want);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("map.json")).unwrap()).unwrap();
    assert!(m["transport"]["resends"].as_u64().unwrap() > 0, "{m}");
    assert!(
        m["transport"]["link_use_of_rate"].as_f64().unwrap() <= 1.0,
        "{m}"
    );
}

/// Runs the stock Foxglove client (tests/foxglove/map_client.mjs: `@foxglove/ws-protocol`
/// 0.8.0 on Node) against `url` until it has `count` messages; its JSON lines.
fn stock_client(url: &str, publish: &[&str], count: Option<usize>) -> Vec<serde_json::Value> {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/foxglove/map_client.mjs");
    let mut cmd = Command::new("node");
    cmd.arg(script).arg(url);
    for p in publish {
        cmd.args(["--publish", p]);
    }
    match count {
        Some(n) => cmd.args(["--count", &n.to_string()]),
        None => cmd.arg("--until-scene"),
    };
    let out = cmd
        .args(["--seconds", "200"])
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/foxglove"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn requests_are_answered_or_refused_and_the_stock_foxglove_client_sees_the_map() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (survey, _) = offline(d, 10);
    let (_link, a, b) = link(&[]);
    let token = "0123456789abcdef0123456789abcdef";
    let token_file = crate::common::private_file(d, "token", token);
    // What the operator asks at once: a ROI too far to be one, a ROI move, the map in a box,
    // the whole map, a new coarse depth, then a flood of 40 full-map requests.
    let mut orders = String::from(concat!(
        "{\"type\":\"roi\",\"box\":[-1e300,-1,-1,1e300,1,1]}\n",
        "{\"type\":\"roi\",\"box\":[-4,-4,-30,4,4,0]}\n",
        "not json\n",
        "{\"type\":\"full\",\"box\":[-2,-2,-30,2,2,0]}\n",
        "{\"type\":\"full\"}\n",
        "{\"type\":\"coarse_depth\",\"depth\":12}\n",
    ));
    for _ in 0..40 {
        orders.push_str("{\"type\":\"full\"}\n");
    }
    let orders_file = crate::common::private_file(d, "orders.jsonl", &orders);
    let mapper = Watched::spawn(&[
        "map",
        survey.to_str().unwrap(),
        "--port",
        &a,
        "--metrics",
        &path(d, "map.json"),
    ]);
    let port = crate::common::free_port().to_string();
    let addr = format!("127.0.0.1:{port}");
    let vmetrics = path(d, "view.json");
    let mut view = Watched::spawn(&[
        "view",
        "--port",
        &b,
        "-o",
        &path(d, "view.ot"),
        "--metrics",
        &vmetrics,
        "--orders",
        orders_file.to_str().unwrap(),
        "--foxglove",
        &addr,
        "--foxglove-token-file",
        token_file.to_str().unwrap(),
    ]);
    view.wait_for("scan 9: ");
    // A viewer without the token sees the map; its request is refused, and said.
    let seen = stock_client(&format!("ws://{addr}/"), &[r#"{"type":"full"}"#], None);
    let scenes: Vec<_> = seen
        .iter()
        .filter(|l| l["topic"] == "/octo_delta/view")
        .collect();
    let last = scenes.last().expect("a scene");
    assert!(last["cubes"].as_u64().unwrap() > 100, "{seen:?}");
    // With the token, its request is taken and answered.
    stock_client(
        &format!("ws://{addr}/?token={token}"),
        &[r#"{"type":"full"}"#],
        Some(0),
    );
    // Every request has its reply: the flood was cut at the view (16 waiting at most) and at
    // the mapper (one of a kind per resend timeout).
    view.wait_count("refused by the mapper", 1);
    view.wait_count("accepted by the mapper", 5);
    // An answer travels after its reply (replies go first): the first four accepted (the ROI
    // move, the map in a box, the whole map, the coarse depth) applied before the view stops.
    // Stopping it at the fifth reply instead lost the coarse depth's answer on a busy machine.
    view.wait_count("answered:", 4);
    view.signal(nix::sys::signal::Signal::SIGTERM);
    mapper.signal(nix::sys::signal::Signal::SIGTERM);
    let (code, said) = view.finish();
    assert_eq!(code, Some(143), "{said}");
    assert!(said.contains("--orders line 3: not JSON"), "{said}");
    assert!(said.contains("too many requests waiting"), "{said}");
    assert!(
        said.contains("Foxglove request refused") || said.contains("refused"),
        "{said}"
    );
    let (code, said) = mapper.finish();
    assert_eq!(code, Some(143), "{said}");
    assert!(said.contains("corners within"), "{said}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&vmetrics).unwrap()).unwrap();
    let requests = m["requests"].as_array().unwrap();
    let find = |want: serde_json::Value| {
        requests
            .iter()
            .find(|r| r["request"] == want)
            .unwrap_or_else(|| panic!("no {want} in {requests:?}"))
    };
    let roi_far =
        find(serde_json::json!({"type": "roi", "box": [-1e300, -1.0, -1.0, 1e300, 1.0, 1.0]}));
    assert_eq!(roi_far["refused"], true, "{roi_far}");
    for want in [
        serde_json::json!({"type": "roi", "box": [-4.0, -4.0, -30.0, 4.0, 4.0, 0.0]}),
        serde_json::json!({"type": "full", "box": [-2.0, -2.0, -30.0, 2.0, 2.0, 0.0]}),
        serde_json::json!({"type": "coarse_depth", "depth": 12}),
    ] {
        let r = find(want);
        assert_eq!(r["refused"], false, "{r}");
        assert!(r["applied_s"].as_f64().is_some(), "{r}");
    }
    // The flood: at most 16 waiting at the view, the rest refused there.
    assert!(requests.len() < 46, "{}", requests.len());
    // The view at the end is a map OctoMap reads.
    let ot = std::fs::read(d.join("view.ot")).unwrap();
    assert!(ot.starts_with(b"# Octomap OcTree file"));
}

#[test]
fn bad_bytes_are_counted_never_applied_and_a_mapper_nobody_acknowledges_stays_bounded() {
    use std::net::UdpSocket;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The view on UDP; the test is its peer and sends it what a hostile link would.
    let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
    let view_port = crate::common::free_port();
    let spec = format!("udp:127.0.0.1:{view_port}={}", peer.local_addr().unwrap());
    let vmetrics = path(d, "view.json");
    let mut view = Watched::spawn(&[
        "view",
        "--port",
        &spec,
        "-o",
        &path(d, "view.ot"),
        "--metrics",
        &vmetrics,
    ]);
    view.wait_for("viewing the map");
    let frame =
        |src: u8, dst: u8, payload: &[u8]| rovlink_wire::frame::build(src, dst, payload).unwrap();
    let to = format!("127.0.0.1:{view_port}");
    let mut bad: Vec<Vec<u8>> = vec![
        b"garbage garbage garbage".to_vec(),
        frame(1, 0, &[0x11, 1, 2, 3])[..6].to_vec(),
        frame(2, 0, &[0x11; 20]),
        frame(1, 3, &[0x11; 20]),
        frame(1, 0, &[0x77; 30]),
        frame(1, 0, &[0x12; 17]),
        // A data segment of a stream whose start the view never saw: dropped, a resync asked.
        frame(1, 0, &[0x11, 9, 9, 9, 9, 5, 0, 0, 0, 1, 3, 0xff, 0xff]),
    ];
    let mut corrupt = frame(1, 0, &[0x11, 1, 0, 0, 0, 0, 0, 0, 0, 3, 1, 2, 3]);
    corrupt[8] ^= 0x40;
    bad.push(corrupt);
    for b in &bad {
        peer.send_to(b, &to).unwrap();
    }
    // The view's first words are its resync request; refusing it (after the bad bytes, in
    // order) is the sign that the view has read them all. It never applies anything.
    let mut buf = [0u8; 512];
    peer.set_read_timeout(Some(DEADLINE)).unwrap();
    let (n, _) = peer.recv_from(&mut buf).unwrap();
    assert_eq!(&buf[3..4], &[0x13], "a request segment: {:02x?}", &buf[..n]);
    let id: [u8; 4] = buf[4..8].try_into().unwrap();
    let mut reply = vec![0x14, 1, 0, 0, 0];
    reply.extend_from_slice(&id);
    reply.extend_from_slice(&[1, 0, 0, 0, 0]);
    peer.send_to(&frame(1, 0, &reply), &to).unwrap();
    view.wait_for("refused by the mapper");
    view.signal(nix::sys::signal::Signal::SIGTERM);
    let (code, said) = view.finish();
    assert_eq!(code, Some(143), "{said}");
    assert!(said.contains("no view was received"), "{said}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&vmetrics).unwrap()).unwrap();
    assert_eq!(m["messages"], 0, "{m}");
    assert!(m["carrier"]["foreign_frames"].as_u64().unwrap() >= 2, "{m}");
    assert!(m["carrier"]["crc_failures"].as_u64().unwrap() >= 1, "{m}");
    assert!(m["transport"]["malformed"].as_u64().unwrap() >= 2, "{m}");
    assert!(!d.join("view.ot").exists());

    // A mapper whose operator never answers: a slow shaped rate, a small backlog bound. Its
    // backlog is replaced by full maps, never grows; stopped, it keeps its map whole.
    let (survey, _) = offline(d, 30);
    let sink = UdpSocket::bind("127.0.0.1:0").unwrap();
    let map_port = crate::common::free_port();
    let spec = format!("udp:127.0.0.1:{map_port}={}", sink.local_addr().unwrap());
    let mut mapper = Watched::spawn(&[
        "map",
        survey.to_str().unwrap(),
        "--port",
        &spec,
        "--rate",
        "20000",
        "--backlog-bytes",
        "4096",
        "--metrics",
        &path(d, "map.json"),
        "--ot",
        &path(d, "map.ot"),
    ]);
    mapper.wait_for("mapped scan 29");
    mapper.signal(nix::sys::signal::Signal::SIGTERM);
    let (code, said) = mapper.finish();
    assert_eq!(code, Some(143), "{said}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("map.json")).unwrap()).unwrap();
    assert!(
        m["transport"]["backlog_replacements"].as_u64().unwrap() >= 1,
        "{m}"
    );
    assert_eq!(m["transport"]["all_acknowledged"], false, "{m}");
    assert!(
        m["transport"]["link_use_of_rate"].as_f64().unwrap() <= 1.05,
        "{m}"
    );
    // The map file is the one build makes of the same scans.
    let built = Command::new(OCTO)
        .args([
            "build",
            survey.to_str().unwrap(),
            "-q",
            "-o",
            &path(d, "x.odl"),
        ])
        .args(["--ot", &path(d, "built.ot")])
        .output()
        .unwrap();
    assert!(built.status.success());
    assert!(std::fs::read(d.join("map.ot")).unwrap() == std::fs::read(d.join("built.ot")).unwrap());
}
