//! octo-delta on a live ROS 2 graph against a real DDS: Eclipse Cyclone DDS (PyPI `cyclonedds`,
//! the C library in its wheel; `tests/ros2/cyclone_peer.py`, unicast on loopback) publishes a
//! survey bag's clouds, `/tf` and `/tf_static` live, two clouds a second. The mapper reads them
//! (`ros2:/points`) and streams the map over `link-sim --pty` with the satellite models to the
//! view, which publishes it back on the graph; a Cyclone subscriber that joins after the run
//! gets the last `octomap_msgs/msg/Octomap`, which Debian's liboctomap decodes as RViz does
//! (`tests/ros2/octomap_msg.cpp`) into the view's own `.ot`, byte for byte, and the same map the
//! bag gives offline. Each test has its own domain id, so tests running at once do not hear
//! each other. Every wait is for a sign (a line said, a process ending, a file's rows).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU16, Ordering};
use std::time::{Duration, Instant};

use crate::common::link_sim_pty;
use crate::common::watched::{DEADLINE, Watched};

const OCTO: &str = env!("TOOL_EXE_octo-delta");
const PEER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/ros2/cyclone_peer.py");
const BAG_WRITER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/bags/survey_bag.py");

fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

/// A domain id no other test of this run uses: a random base, then one per test.
fn domain() -> String {
    static NEXT: AtomicU16 = AtomicU16::new(0);
    static BASE: std::sync::OnceLock<u16> = std::sync::OnceLock::new();
    let base = *BASE.get_or_init(|| {
        let mut b = [0u8; 2];
        std::fs::File::open("/dev/urandom")
            .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut b))
            .expect("/dev/urandom");
        1 + u16::from_le_bytes(b) % 180
    });
    (base + NEXT.fetch_add(1, Ordering::Relaxed) % 50).to_string()
}

fn run_ok(exe: &str, args: &[&str]) -> String {
    let out = Command::new(exe).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{exe} {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A coloured survey of `scans` clouds as an MCAP bag (clouds, /tf, /tf_static) written by the
/// real writers.
fn survey_bag(dir: &Path, scans: u32) -> PathBuf {
    let graph = dir.join("survey.graph");
    let bag = dir.join("survey.mcap");
    run_ok(
        OCTO,
        &["synth", "--scans", &scans.to_string(), "-o", s(&graph)],
    );
    run_ok(
        "python3",
        &[
            BAG_WRITER,
            "--graph",
            s(&graph),
            "--kind",
            "mcap-none",
            "--pose",
            "tf",
            "--color",
            "--out",
            s(&bag),
        ],
    );
    bag
}

/// The Cyclone peer playing `bag` live on `domain`, once the mapper's readers have matched
/// (it ends by itself, after its own deadline at worst).
fn play(domain: &str, bag: &Path) -> std::process::Child {
    Command::new("python3")
        .args([PEER, "--domain", domain, "--timeout", "200", "play", s(bag)])
        .args(["--period", "0.5"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 runs the Cyclone peer")
}

/// Waits for the peer to end; its JSON line.
fn peer_result(peer: std::process::Child) -> serde_json::Value {
    let out = peer.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the Cyclone peer failed (it needs `pip install cyclonedds mcap`): {text} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(text.trim()).unwrap()
}

/// A late Cyclone subscriber to `topic` (an Octomap, or with `cloud` a PointCloud2): the fields
/// and the data of the first message it gets whose data has `bytes` bytes.
fn latched(
    dir: &Path,
    domain: &str,
    topic: &str,
    name: &str,
    bytes: usize,
) -> (serde_json::Value, Vec<u8>) {
    latched_of(dir, domain, topic, name, bytes, "octomap")
}

fn latched_of(
    dir: &Path,
    domain: &str,
    topic: &str,
    name: &str,
    bytes: usize,
    kind: &str,
) -> (serde_json::Value, Vec<u8>) {
    let out = dir.join(name);
    let bytes = bytes.to_string();
    run_ok(
        "python3",
        &[
            PEER,
            "--domain",
            domain,
            "--timeout",
            "120",
            "latched",
            topic,
            "--type",
            kind,
            "--out",
            s(&out),
            "--expect-bytes",
            &bytes,
        ],
    );
    let fields = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let data = std::fs::read(out.with_file_name(format!("{name}.data"))).unwrap();
    (fields, data)
}

/// Compiles the liboctomap decoder once.
fn decoder() -> PathBuf {
    static BUILT: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    BUILT
        .get_or_init(|| {
            let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ros2/octomap_msg.cpp");
            let exe = Path::new(env!("CARGO_TARGET_TMPDIR")).join("octomap_msg");
            let out = Command::new("c++")
                .args(["-O1", "-std=c++17", s(&src), "-o", s(&exe)])
                .args(["-loctomap", "-loctomath"])
                .output()
                .expect("a C++ compiler (g++) and Debian's liboctomap-dev");
            assert!(
                out.status.success(),
                "tests/ros2/octomap_msg.cpp: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            exe
        })
        .clone()
}

/// The decoder's verdict on a message's data: (its JSON line, the file it wrote).
fn decode(
    dir: &Path,
    fields: &serde_json::Value,
    data: &[u8],
    map: &Path,
) -> (serde_json::Value, Vec<u8>) {
    let binary = fields["binary"].as_bool().unwrap();
    let data_file = dir.join("msg.data");
    std::fs::write(&data_file, data).unwrap();
    let written = dir.join(if binary { "decoded.bt" } else { "decoded.ot" });
    let res = fields["resolution"].as_f64().unwrap().to_string();
    let line = run_ok(
        s(&decoder()),
        &[
            fields["id"].as_str().unwrap(),
            if binary { "1" } else { "0" },
            &res,
            s(&data_file),
            s(&written),
            s(map),
        ],
    );
    (
        serde_json::from_str(line.trim()).unwrap(),
        std::fs::read(&written).unwrap(),
    )
}

/// The body of a map file (after its `data` line).
fn body(file: &[u8]) -> &[u8] {
    let at = file
        .windows(5)
        .position(|w| w == b"data\n")
        .expect("a map file's data line");
    &file[at + 5..]
}

#[test]
fn a_live_survey_maps_over_the_satellite_link_and_a_late_rviz_gets_the_view() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scans = 10;
    let bag = survey_bag(d, scans);
    // Offline: the bag built, its stream applied: the view the operator must end with.
    let offline = d.join("offline.odl");
    let want_ot = d.join("want.ot");
    run_ok(OCTO, &["build", s(&bag), "-q", "-o", s(&offline)]);
    run_ok(OCTO, &["apply", s(&offline), "-o", s(&want_ot)]);
    let want = std::fs::read(&want_ot).unwrap();

    let domain = domain();
    let (_link, a, b) = link_sim_pty(&[
        "--model",
        "satellite-up",
        "--reverse-model",
        "satellite-down",
    ]);
    let view_ot = d.join("view.ot");
    let vmetrics = d.join("view.json");
    let mut view = Watched::spawn(&[
        "view",
        "--port",
        &b,
        "-o",
        s(&view_ot),
        "--metrics",
        s(&vmetrics),
        "--ros2",
        "--ros2-domain",
        &domain,
        "--ros2-full-topic",
        "/octo_delta/octomap_full",
        "--ros2-period",
        "0.2",
    ]);
    view.wait_for("ROS 2: the view on /octo_delta/octomap");
    let mut mapper = Watched::spawn(&[
        "map",
        "ros2:/points",
        "--ros2-domain",
        &domain,
        "--port",
        &a,
    ]);
    let peer = play(&domain, &bag);
    let played = peer_result(peer);
    assert_eq!(played["clouds"], scans, "{played}");
    mapper.wait_for(&format!("mapped scan {}", scans - 1));
    view.wait_for(&format!("scan {}: ", scans - 1));
    // The run is over; RViz starts now and gets the view.
    // It waits for the final map by its size (a late joiner may get older ones first).
    let want_tree = rovlink_octo::files::read_map(&want).unwrap();
    let want_bt = rovlink_octo::files::write_bt(&want_tree);
    let full_topic = "/octo_delta/octomap_full";
    let (full, full_data) = latched(d, &domain, full_topic, "full.json", body(&want).len());
    let bin_topic = "/octo_delta/octomap";
    let (bin, bin_data) = latched(d, &domain, bin_topic, "bin.json", body(&want_bt).len());
    // The voxels as points (what Foxglove draws): one per occupied leaf, x y z rgb.
    let mut occupied = 0;
    want_tree.for_each_leaf(|_, _, v| occupied += usize::from(v.log_odds >= 0.0));
    let voxels = "/octo_delta/voxels";
    let (cloud, _) = latched_of(d, &domain, voxels, "voxels.json", occupied * 16, "cloud");
    assert_eq!(cloud["width"], occupied, "{cloud}");
    assert_eq!(
        cloud["fields"],
        serde_json::json!(["x", "y", "z", "rgb"]),
        "{cloud}"
    );
    assert_eq!(cloud["frame_id"], "map", "{cloud}");
    mapper.signal(nix::sys::signal::Signal::SIGTERM);
    let (code, said) = mapper.finish();
    assert_eq!(code, Some(143), "{said}");
    view.signal(nix::sys::signal::Signal::SIGTERM);
    let (code, said) = view.finish();
    assert_eq!(code, Some(143), "{said}");
    let got = std::fs::read(&view_ot).unwrap();
    assert!(
        got == want,
        "the live view differs from the bag's offline view: {said}"
    );

    // The full map: a ColorOcTree whose data is the view's .ot body; liboctomap reads it
    // into the same .ot.
    assert_eq!(full["id"], "ColorOcTree", "{full}");
    assert_eq!(full["binary"], false, "{full}");
    assert_eq!(full["frame_id"], "map", "{full}");
    assert_eq!(full["resolution"], 0.1, "{full}");
    assert!(
        full_data == body(&got),
        "the full Octomap's data is not the view's .ot body"
    );
    let (verdict, rewritten) = decode(d, &full, &full_data, &view_ot);
    assert_eq!(verdict["mismatches"], 0, "{verdict}");
    assert!(
        rewritten == got,
        "liboctomap's .ot of the message differs from the view's"
    );
    // The binary map RViz's occupancy display takes: every leaf as the view has it.
    assert_eq!(bin["id"], "OcTree", "{bin}");
    assert_eq!(bin["binary"], true, "{bin}");
    let (verdict, _) = decode(d, &bin, &bin_data, &view_ot);
    assert_eq!(verdict["mismatches"], 0, "{verdict}");
    assert!(verdict["leaves"].as_u64().unwrap() > 1000, "{verdict}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&vmetrics).unwrap()).unwrap();
    assert!(m["ros2"]["maps"].as_u64().unwrap() >= 1, "{m}");
}

/// Waits until `file` has `rows` lines.
fn wait_rows(file: &Path, rows: usize) {
    let t0 = Instant::now();
    while std::fs::read_to_string(file).map_or(0, |t| t.lines().count()) < rows {
        assert!(
            t0.elapsed() < DEADLINE,
            "{file:?}: not {rows} rows in {DEADLINE:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn build_from_a_live_topic_ends_on_sigterm_with_the_bags_map_whole() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scans = 6;
    let bag = survey_bag(d, scans);
    let want_ot = d.join("want.ot");
    run_ok(
        OCTO,
        &[
            "build",
            s(&bag),
            "-q",
            "-o",
            s(&d.join("offline.odl")),
            "--ot",
            s(&want_ot),
        ],
    );
    let domain = domain();
    let live_ot = d.join("live.ot");
    let stats = d.join("live.csv");
    let build = Watched::spawn(&[
        "build",
        "ros2:/points",
        "--ros2-domain",
        &domain,
        "-o",
        s(&d.join("live.odl")),
        "--ot",
        s(&live_ot),
        "--stats",
        s(&stats),
    ]);
    let played = peer_result(play(&domain, &bag));
    assert_eq!(played["clouds"], scans, "{played}");
    wait_rows(&stats, scans as usize + 1);
    build.signal(nix::sys::signal::Signal::SIGTERM);
    let (code, said) = build.finish();
    assert_eq!(code, Some(143), "{said}");
    assert!(said.contains("interrupted by SIGTERM"), "{said}");
    assert!(
        std::fs::read(&live_ot).unwrap() == std::fs::read(&want_ot).unwrap(),
        "the live topic's map differs from the bag's: {said}"
    );
    // The stream is whole: it applies to the same map.
    let applied = d.join("applied.ot");
    run_ok(OCTO, &["apply", s(&d.join("live.odl")), "-o", s(&applied)]);
    let offline = d.join("offline.ot");
    run_ok(
        OCTO,
        &["apply", s(&d.join("offline.odl")), "-o", s(&offline)],
    );
    assert!(std::fs::read(&applied).unwrap() == std::fs::read(&offline).unwrap());
}

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");
/// Further north than the kinematic model's drift takes a vehicle without orders while the
/// tests listen (0.25 m in 8 s), and less far than the tests' Twist takes it (about 1.2 m).
const MOVED_M: f64 = 0.6;

/// The ROV end in real time on `port` (`extra`: its camera or vehicle flags), once it listens.
fn rov_end(port: &str, image_size: &str, extra: &[&str]) -> Watched {
    let mut args = vec![
        "--role",
        "rov",
        "--port",
        port,
        "--duration",
        "600",
        "--image-size",
        image_size,
    ];
    args.extend_from_slice(extra);
    let mut rov = Watched::spawn_exe(TDMA_RUN, &args);
    rov.wait_for("ROV: answering every slot");
    rov
}

/// The operator end in real time on `port` (`extra`: its other flags), its standard output
/// and error watched.
fn operator_end(port: &str, image_size: &str, extra: &[&str]) -> Watched {
    let mut args = vec![
        "--role",
        "operator",
        "--port",
        port,
        "--ipg",
        "150",
        "--duration",
        "600",
        "--image-size",
        image_size,
    ];
    args.extend_from_slice(extra);
    Watched::spawn_exe_both(TDMA_RUN, &args)
}

/// The operator and the ROV in real time over `link-sim --pty`, the operator on the graph
/// (`extra` its ROS 2 flags); the peer's `session` report with `peer` flags. Returns the report
/// and what the operator said.
fn session_on_the_graph(
    domain: &str,
    extra: &[&str],
    peer: &[&str],
) -> (serde_json::Value, String) {
    let (_link, a, b) = link_sim_pty(&crate::common::TEST_S100);
    let rov = rov_end(&b, "400", &[]);
    let mut args = vec!["--ros2", "--ros2-domain", domain];
    args.extend_from_slice(extra);
    let mut op = operator_end(&a, "400", &args);
    op.wait_for("operator: IPG");
    let out = Command::new("python3")
        .args([PEER, "--domain", domain, "session", "--seconds", "200"])
        .args(peer)
        .output()
        .expect("python3 runs the Cyclone peer");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    op.signal(nix::sys::signal::Signal::SIGTERM);
    let (code, said) = op.finish();
    rov.signal(nix::sys::signal::Signal::SIGTERM);
    let _ = rov.finish();
    assert!(
        out.status.success(),
        "the Cyclone peer failed: {text} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    // A real-time end stopped by a signal keeps its outputs and ends with 0.
    assert_eq!(code, Some(0), "{said}");
    assert!(said.contains("stopped after"), "{said}");
    (serde_json::from_str(text.trim()).unwrap(), said)
}

fn distance(a: &serde_json::Value, b: [f64; 3]) -> f64 {
    (0..3)
        .map(|k| (a[k].as_f64().unwrap() - b[k]).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn with_control_a_ros2_twist_moves_the_vehicle_and_a_goal_pose_is_acknowledged_and_reached() {
    let domain = domain();
    let (r, said) = session_on_the_graph(
        &domain,
        &["--ros2-control"],
        &[
            "--twist",
            "0.5,0,0,0",
            "--twist-seconds",
            "3",
            "--goal",
            "1,-1,0.5",
            "--goal-at",
            "8",
            "--until-goal",
            "0.3",
        ],
    );
    assert_eq!(r["ok"], true, "the goal was not reached: {r}");
    assert!(said.contains("control on"), "{said}");
    // Heard on the graph: poses, tf and velocities, decodable images, the status, the log.
    for topic in ["pose", "tf", "velocity", "status"] {
        assert!(r["counts"][topic].as_u64().unwrap() >= 5, "{topic}: {r}");
    }
    assert!(r["images_decoded"].as_u64().unwrap() >= 1, "{r}");
    let logs = r["logs"].to_string();
    assert!(logs.contains("acknowledged"), "{r}");
    assert!(r["status"]["frames"]["sent"].as_u64().unwrap() > 0, "{r}");
    // The Twist (surge 50 % for 3 s, held 2 s more) moved the vehicle north by more than
    // the model's drift does in the same time (0.25 m in 8 s without orders); the goal lies
    // back south-west of where the Twist left it.
    let start = r["start"][0].as_f64().unwrap();
    assert!(r["max_x"].as_f64().unwrap() > start + MOVED_M, "{r}");
    assert!(distance(&r["last"], [1.0, -1.0, 0.5]) <= 0.3, "{r}");
}

#[test]
fn without_control_the_graph_gives_no_order_and_it_is_said_once() {
    let domain = domain();
    let (r, said) = session_on_the_graph(
        &domain,
        &[],
        &[
            "--twist",
            "0.5,0,0,0",
            "--twist-seconds",
            "3",
            "--goal",
            "2,1,0.5",
            "--goal-at",
            "4",
            "--poses-after-goal",
            "20",
        ],
    );
    assert_eq!(r["ok"], true, "{r}");
    assert_eq!(said.matches("view-only").count(), 1, "{said}");
    // No order was sent, and the vehicle only drifted (the Twist would move it further).
    assert!(!r["logs"].to_string().contains("order"), "{r}");
    let start = r["start"][0].as_f64().unwrap();
    assert!(
        r["max_x"].as_f64().unwrap() < start + MOVED_M,
        "the Twist was obeyed: {r}"
    );
}

/// The first picture file that appears in `dir`.
fn first_picture(dir: &Path) -> PathBuf {
    let t0 = Instant::now();
    loop {
        let found = std::fs::read_dir(dir).ok().and_then(|entries| {
            entries
                .flatten()
                .map(|e| e.path())
                .find(|p| p.extension().is_some_and(|x| x == "png"))
        });
        if let Some(p) = found {
            return p;
        }
        assert!(
            t0.elapsed() < DEADLINE,
            "no picture in {dir:?} in {DEADLINE:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn the_rovs_camera_can_be_a_ros2_image_topic_raw_or_compressed() {
    for topic in ["/cam/image_raw", "/cam/image_raw/compressed"] {
        let dir = tempfile::tempdir().unwrap();
        let rx = dir.path().join("rx");
        let domain = domain();
        let mut camera = Command::new("python3")
            .args([PEER, "--domain", &domain, "camera", "--topic", topic])
            .args(["--seconds", "200"])
            .stdout(Stdio::null())
            .spawn()
            .expect("python3 runs the Cyclone peer");
        let (_link, a, b) = link_sim_pty(&crate::common::TEST_S100);
        let camera_flag = format!("ros2:{topic}");
        let rov = rov_end(
            &b,
            "600",
            &["--camera", &camera_flag, "--ros2-domain", &domain],
        );
        let mut op = operator_end(&a, "600", &["--images-out", s(&rx)]);
        op.wait_for("operator: IPG");
        let picture = first_picture(&rx);
        op.signal(nix::sys::signal::Signal::SIGTERM);
        let _ = op.finish();
        rov.signal(nix::sys::signal::Signal::SIGTERM);
        let _ = rov.finish();
        let _ = camera.kill();
        let _ = camera.wait();
        let img = image::open(&picture).unwrap().to_luma8();
        assert_eq!(img.dimensions(), (64, 48), "{topic}");
        let (dark, bright) = (img.get_pixel(8, 24)[0], img.get_pixel(56, 24)[0]);
        assert!(dark < 100 && bright > 150, "{topic}: {dark} {bright}");
    }
}

#[test]
fn a_vehicle_on_ros2_is_armed_driven_by_the_sticks_and_sent_to_a_goal_and_its_odometry_is_the_status()
 {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let domain = domain();
    let script = d.join("script.csv");
    std::fs::write(&script, "t_s,vx,vy,vz,vyaw\n0,50,0,0,0\n3,0,0,0,0\n").unwrap();
    let waypoints = d.join("wp.csv");
    std::fs::write(&waypoints, "t_s,x_m,y_m,z_m,heading_deg\n5,3,1,0.5,90\n").unwrap();
    // The stand-in ends once it has held the goal for a second.
    let vehicle = Command::new("python3")
        .args([PEER, "--domain", &domain, "vehicle", "--seconds", "200"])
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 runs the Cyclone peer");
    let (_link, a, b) = link_sim_pty(&crate::common::TEST_S100);
    let rov = rov_end(&b, "400", &["--vehicle", "ros2", "--ros2-domain", &domain]);
    let mut op = operator_end(
        &a,
        "400",
        &[
            "--script",
            s(&script),
            "--waypoints",
            s(&waypoints),
            "--telemetry",
            "-",
        ],
    );
    let out = vehicle.wait_with_output().unwrap();
    // The operator hears the goal reached in a status: north 3, east 1, down 0.5, heading 90.
    op.wait_for(r#""x_cm":300,"y_cm":100,"z_cm":50,"roll_deg":0,"pitch_deg":0,"yaw_deg":90"#);
    op.signal(nix::sys::signal::Signal::SIGTERM);
    let (_, op_said) = op.finish();
    rov.signal(nix::sys::signal::Signal::SIGTERM);
    let (_, rov_said) = rov.finish();
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["ok"], true, "{r} {rov_said} {op_said}");
    assert_eq!(r["armed_seen"], true, "{r}");
    // The sticks at 50 % went out as a Twist of 0.5 (full = 1).
    let x = r["max_twist_x"].as_f64().unwrap();
    assert!((x - 0.5).abs() < 0.02, "{r}");
    // The GoTo north 3, east 1, down 0.5, heading east went out in ENU: east 1, north 3, up
    // -0.5, yaw 0; the vehicle ended there.
    assert_eq!(
        r["goals"][0],
        serde_json::json!([1.0, 3.0, -0.5, 0.0]),
        "{r}"
    );
    assert_eq!(r["final"], serde_json::json!([1.0, 3.0, -0.5]), "{r}");
    assert!(rov_said.contains("vehicle on ROS 2"), "{rov_said}");
}
