//! The live Foxglove view (`rcp::foxglove`) against an independent client: the Python
//! Foxglove WebSocket client of tests/foxglove/client.py (the `websockets` package). Poses and
//! images published through the Observer API arrive, decoded, equal to what was published;
//! a Twist (as Foxglove's Teleop panel publishes it) and JSON orders come out of LiveOrders;
//! garbage, cut connections and a stuck client break nothing; bad and busy addresses are
//! errors; stopping is prompt. The clients carry the control token in their URL; without a
//! token configured, or without it in the URL, nothing a client publishes becomes an order.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use base64::Engine;
use rovlink_field::foxglove::{self, LiveOrders, LiveView, Policy, Token};
use rovlink_link::SimTime;
use rovlink_rcp::orders::{Live, OrderSource};
use rovlink_rcp::report::Observer;
use rovlink_rcp::{Event, ImageSettings, PoseSample, Role};
use rovlink_wire::Nav;
use rovlink_wire::operator::Order;
use serde_json::Value;

const CLIENT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/foxglove/client.py");

/// The control token of the views these tests start.
const TOKEN: &str = "test-token-0123456789abcdef";

/// Starts the client against `view` with `args`, the control token in its URL; its JSON goes
/// to `out`.
fn client(view: &LiveView, out: &Path, args: &[&str]) -> Child {
    client_at(
        &format!("ws://127.0.0.1:{}/?token={TOKEN}", view.port()),
        out,
        args,
    )
}

/// Starts the client against `url` with `args`; its JSON goes to `out`.
fn client_at(url: &str, out: &Path, args: &[&str]) -> Child {
    Command::new("python3")
        .arg(CLIENT)
        .args(["--url", url])
        .args(["--out", out.to_str().unwrap()])
        .args(args)
        .stdin(Stdio::null())
        .spawn()
        .expect("python3 runs tests/foxglove/client.py")
}

/// Waits for the client (at most `limit`) and reads what it saw.
fn finish(mut child: Child, out: &Path, limit: Duration) -> Value {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success(), "client.py failed: {status}");
            break;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("client.py still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    serde_json::from_slice(&std::fs::read(out).unwrap()).unwrap()
}

/// Waits until `n` clients are connected.
fn wait_for_clients(view: &LiveView, n: usize) {
    let start = Instant::now();
    while view.clients() < n {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "no client connected"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Calls `publish` every `every` until `child` (a client) has ended: what a client's window
/// must see is published for as long as it is open, however late it opened or reads. Fails
/// after `limit`.
fn publish_until_ended(
    child: &mut Child,
    every: Duration,
    limit: Duration,
    mut publish: impl FnMut(),
) {
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        assert!(
            start.elapsed() < limit,
            "client.py still running after {limit:?}"
        );
        publish();
        std::thread::sleep(every);
    }
}

/// The longest one call of the Observer API may take. A call that waited on a client would
/// wait as long as the client does not read (seconds, for the stuck client below); a loaded
/// machine may preempt a call for tens of milliseconds. So this bounds a hang, not speed.
const SLOWEST_POSE: Duration = Duration::from_secs(1);

/// The longest an image may take to publish: its decoding and PNG cost tens of milliseconds
/// (more in a debug build on a loaded machine); a wait for the stuck client would be seconds.
const SLOWEST_IMAGE: Duration = Duration::from_secs(2);

fn pose(t_s: f64, position_m: [f64; 3], heading_deg: f64) -> PoseSample {
    PoseSample {
        t_s,
        position_m,
        heading_deg,
        velocity: [0.1, 0.0, 0.0, 1.0],
        commanded_velocity: [0.2, 0.0, 0.0, 0.0],
        goal_m: Some([3.0, 0.0, 0.5]),
        backtrack_m: None,
        link_up: true,
    }
}

/// A built-in picture's DEBT stream, as the ROV sends it, and the trunks it is cut in.
fn image_stream() -> (Vec<u8>, Vec<Vec<u8>>) {
    let picture = rovlink_rcp::camera::builtin_picture(160, 120, 3);
    let trunks = rovlink_rcp::trunks_of(&picture, &ImageSettings::default());
    (trunks.concat(), trunks)
}

fn count(seen: &Value, topic: &str) -> u64 {
    seen[topic].as_u64().unwrap_or(0)
}

fn png_size(message: &Value) -> (u32, u32) {
    assert_eq!(message["format"], "png");
    let png = base64::engine::general_purpose::STANDARD
        .decode(message["data"].as_str().unwrap())
        .unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let be = |at: usize| u32::from_be_bytes(png[at..at + 4].try_into().unwrap());
    (be(16), be(20))
}

/// A token file holding [`TOKEN`] in `dir` (mode 0600, as tdma-run wants it).
fn token_file(dir: &Path) -> std::path::PathBuf {
    crate::common::private_file(dir, "token", &format!("{TOKEN}\n"))
}

/// A policy with the control token [`TOKEN`].
fn with_token() -> Policy {
    Policy {
        token: Some(Token::parse(TOKEN.as_bytes()).unwrap()),
        ..Policy::default()
    }
}

fn start(role: Role) -> (LiveView, LiveOrders) {
    foxglove::start("127.0.0.1:0", role, &with_token()).expect("a server on a free port")
}

#[test]
fn a_client_receives_poses_and_images_as_they_are_published() {
    let (mut view, _orders) = start(Role::Operator);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seen.json");
    // The client's window (from its start) leaves seconds to spare after the two seconds of
    // publishing below, however slowly it connects.
    let mut child = client(
        &view,
        &out,
        &[
            "--topics",
            "/rov/pose,/rov/goal,/camera/image,/camera/preview,/link/log,/session/log",
            "--seconds",
            "8",
        ],
    );
    wait_for_clients(&view, 1);
    let (stream, trunks) = image_stream();
    let before_ns = rovlink_field::mcap_log::wall_clock_ns();
    let mut slowest_pose = Duration::ZERO;
    // Forty poses 50 ms apart, an image every tenth: counted, not timed, so that a slow
    // machine publishes them all.
    for k in 0..40u32 {
        assert!(
            child.try_wait().unwrap().is_none(),
            "client.py's window ended before the poses were published"
        );
        let t_s = f64::from(k) * 0.05;
        let call = Instant::now();
        view.pose(1, &pose(t_s, [f64::from(k) * 0.1, -1.0, 2.0], 10.0));
        slowest_pose = slowest_pose.max(call.elapsed());
        if k.is_multiple_of(10) {
            // A trunk more each time: a preview is sent only when new trunks changed it.
            let n = (8 + k as usize / 10).min(trunks.len());
            view.event(
                1,
                Role::Operator,
                t_s,
                &Event::ImageProgress {
                    trunks: n,
                    of: None,
                    prefix: trunks[..n].concat(),
                },
            );
            view.image(1, t_s, &stream);
            view.event(1, Role::Operator, t_s, &Event::OrderAcknowledged(k.into()));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    // The last pose, and nothing after it: the client's last pose must be this one. It is
    // published again (the same pose, the same event) until the client's window ends, so it
    // is the last whenever the client reads it.
    let last_pose = pose(99.0, [12.5, -3.25, 7.0], 90.0);
    let mut repeats = 0;
    publish_until_ended(
        &mut child,
        Duration::from_millis(50),
        Duration::from_secs(30),
        || {
            let call = Instant::now();
            view.pose(1, &last_pose);
            slowest_pose = slowest_pose.max(call.elapsed());
            view.event(1, Role::Operator, 99.0, &Event::AnswersLost);
            repeats += 1;
        },
    );
    let seen = finish(child, &out, Duration::from_secs(15));
    let after_ns = rovlink_field::mcap_log::wall_clock_ns();
    eprintln!(
        "received {seen:.200}; 40 poses published and the last {repeats} times, slowest \
         Observer::pose {slowest_pose:?}"
    );

    assert!(count(&seen, "/rov/pose") >= 10, "{seen}");
    assert!(count(&seen, "/rov/goal") >= 10, "{seen}");
    assert!(count(&seen, "/camera/image") >= 2, "{seen}");
    assert!(count(&seen, "/camera/preview") >= 2, "{seen}");
    assert!(count(&seen, "/session/log") >= 2, "{seen}");
    let last = &seen["last"]["/rov/pose"];
    assert_eq!(last["frame_id"], "ned");
    let position = &last["pose"]["position"];
    assert_eq!(
        (&position["x"], &position["y"], &position["z"]),
        (&Value::from(12.5), &Value::from(-3.25), &Value::from(7.0)),
        "{last}"
    );
    let q = &last["pose"]["orientation"];
    let half = 45f64.to_radians();
    assert!((q["z"].as_f64().unwrap() - half.sin()).abs() < 1e-12, "{q}");
    assert!((q["w"].as_f64().unwrap() - half.cos()).abs() < 1e-12, "{q}");
    // Wall-clock log times, and the message's own timestamp is the same instant.
    let log_ns = seen["log_time_ns"]["/rov/pose"].as_u64().unwrap();
    assert!((before_ns..=after_ns).contains(&log_ns), "{log_ns}");
    assert_eq!(
        last["timestamp"]["sec"].as_u64().unwrap(),
        log_ns / 1_000_000_000
    );
    assert_eq!(png_size(&seen["last"]["/camera/image"]), (160, 120));
    // The preview is JPEG (a picture still arriving; a fraction of its PNG), full size.
    let preview = &seen["last"]["/camera/preview"];
    assert_eq!(preview["format"], "jpeg");
    let jpeg = base64::engine::general_purpose::STANDARD
        .decode(preview["data"].as_str().unwrap())
        .unwrap();
    let decoded = image::load_from_memory_with_format(&jpeg, image::ImageFormat::Jpeg).unwrap();
    assert_eq!((decoded.width(), decoded.height()), (160, 120));
    assert_eq!(
        seen["last"]["/link/log"]["message"],
        "answers lost: no ROV frame for 5 s"
    );
    assert_eq!(seen["last"]["/link/log"]["level"], 3);
    assert!(
        seen["last"]["/session/log"]["message"]
            .as_str()
            .unwrap()
            .ends_with("acknowledged"),
        "{seen}"
    );
    // The channels carry the MCAP log's schemas.
    assert_eq!(seen["schemas"]["/rov/pose"], "foxglove.PoseInFrame");
    assert_eq!(seen["schemas"]["/link/frames"], "rovlink.LinkFrame");
    assert_eq!(seen["schemas"]["/camera/image"], "foxglove.CompressedImage");
    assert_eq!(seen["server"]["name"], "tdma-run operator");
    assert!(slowest_pose < SLOWEST_POSE, "{slowest_pose:?}");
    view.stop();
}

/// Every Live value the source yields within `limit`, until `enough` says so.
fn drain(orders: &mut LiveOrders, limit: Duration, enough: impl Fn(&[Live]) -> bool) -> Vec<Live> {
    let start = Instant::now();
    let mut got = Vec::new();
    while start.elapsed() < limit && !enough(&got) {
        got.extend(orders.poll(SimTime::ZERO));
        std::thread::sleep(Duration::from_millis(20));
    }
    got
}

#[test]
fn a_teleop_twist_and_json_orders_come_out_as_live_orders() {
    let (view, mut orders) = start(Role::Operator);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.json");
    let goto = r#"{"type":"goto","x_cm":300,"y_cm":-20,"z_cm":50,"heading_deg":90}"#;
    let child = client(
        &view,
        &out,
        &[
            "--topics",
            "/rov/pose",
            "--seconds",
            "3",
            "--publish-twist",
            "--publish-order",
            goto,
            "--publish-order",
            r#"{"type":"cancel"}"#,
        ],
    );
    let got = drain(&mut orders, Duration::from_secs(10), |got| {
        got.contains(&Live::Cancel) && got.iter().any(|l| matches!(l, Live::Joystick { .. }))
    });
    let seen = finish(child, &out, Duration::from_secs(10));
    assert!(seen["published"].as_u64().unwrap() >= 3, "{seen}");
    let stick = Live::Joystick {
        joystick: rovlink_rcp::operator::Joystick {
            vx: 50.0,
            vy: 0.0,
            vz: 0.0,
            vyaw: -25.0,
        },
        arm: true,
        disarm: false,
        nav: Nav::Manual,
    };
    assert!(got.contains(&stick), "{got:?}");
    let order = Live::Order(Order::GoTo {
        x_cm: 300,
        y_cm: -20,
        z_cm: 50,
        heading_deg: 90,
    });
    let at = |wanted: &Live| got.iter().position(|l| l == wanted);
    assert!(at(&order).unwrap() < at(&Live::Cancel).unwrap(), "{got:?}");
    assert_eq!(got.iter().filter(|l| **l == order).count(), 1, "{got:?}");
    assert!(
        orders.take_warnings().is_empty(),
        "good messages give no warning"
    );

    // The Teleop panel stops publishing when the button is released: the Twist holds for
    // TWIST_HOLD, then the joystick goes neutral.
    let released = Instant::now();
    let neutral = Live::scripted_joystick(rovlink_rcp::operator::Joystick::default());
    let got = drain(&mut orders, Duration::from_secs(10), |got| {
        got.contains(&neutral)
    });
    assert_eq!(got.last(), Some(&neutral), "{got:?}");
    assert!(released.elapsed() <= foxglove::TWIST_HOLD + Duration::from_secs(1));
    // The ROS 2 schema name on a topic of the user's choosing, and a full-left turn.
    let out = dir.path().join("b.json");
    let child = client(
        &view,
        &out,
        &[
            "--seconds",
            "3",
            "--publish-twist",
            r#"{"linear":{"x":0,"y":1,"z":0.5},"angular":{"x":0,"y":0,"z":1}}"#,
            "--twist-topic",
            "/teleop",
            "--twist-schema",
            "geometry_msgs/msg/Twist",
        ],
    );
    let got = drain(&mut orders, Duration::from_secs(10), |got| !got.is_empty());
    finish(child, &out, Duration::from_secs(10));
    let Some(Live::Joystick { joystick, .. }) = got.first() else {
        panic!("{got:?}");
    };
    assert_eq!(
        [joystick.vx, joystick.vy, joystick.vz, joystick.vyaw],
        [0.0, -100.0, -50.0, -100.0],
        "left, up and counter-clockwise in ROS are port, up and anticlockwise yaw here"
    );
}

#[test]
fn garbage_cut_connections_and_stuck_clients_break_nothing() {
    let (mut view, mut orders) = start(Role::Operator);
    let dir = tempfile::tempdir().unwrap();
    let (stream, _) = image_stream();
    let hostile = dir.path().join("hostile.json");
    let stuck = dir.path().join("stuck.json");
    let mut garbage = client(
        &view,
        &hostile,
        &["--topics", "/rov/pose", "--seconds", "4", "--garbage"],
    );
    // Stuck for longer than a call may take (SLOWEST_IMAGE): a call that waited for it
    // would show.
    let mut stalled = client(&view, &stuck, &["--seconds", "5", "--stall"]);
    wait_for_clients(&view, 2);
    let started = Instant::now();
    let (mut slowest_pose, mut slowest_image) = (Duration::ZERO, Duration::ZERO);
    let mut k: u32 = 0;
    // Publishing goes on while either client is there: the hostile one is served however
    // late it subscribes, and the stuck one is published to all through its stall.
    let running = |child: &mut Child| child.try_wait().unwrap().is_none();
    while running(&mut garbage) || running(&mut stalled) {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "client.py still running"
        );
        let call = Instant::now();
        view.pose(1, &pose(f64::from(k), [1.0, 2.0, 3.0], 0.0));
        slowest_pose = slowest_pose.max(call.elapsed());
        if k.is_multiple_of(20) {
            let call = Instant::now();
            view.image(1, f64::from(k), &stream);
            slowest_image = slowest_image.max(call.elapsed());
        }
        k += 1;
        std::thread::sleep(Duration::from_millis(2));
    }
    let hostile_seen = finish(garbage, &hostile, Duration::from_secs(15));
    let stuck_seen = finish(stalled, &stuck, Duration::from_secs(15));
    eprintln!(
        "{k} poses, slowest {slowest_pose:?}; slowest image (decoded, PNG) {slowest_image:?}; \
         stuck client: {stuck_seen:.300}"
    );
    // The hostile client was served all along, and told what was wrong.
    assert!(count(&hostile_seen, "/rov/pose") > 0, "{hostile_seen}");
    assert!(
        !hostile_seen["statuses"].as_array().unwrap().is_empty(),
        "{hostile_seen}"
    );
    // Publishing never waited for the stuck client (an image costs its decoding and PNG, tens
    // of milliseconds; the bound is one on a wait for the client, seconds).
    assert!(slowest_pose < SLOWEST_POSE, "{slowest_pose:?}");
    assert!(slowest_image < SLOWEST_IMAGE, "{slowest_image:?}");
    // Nothing the garbage said became an order; all of it was reported, in short lines. (The
    // server reports as it reads: the warnings are gathered until all are in.)
    let expected = [
        "refused: expected encoding json",
        "refused: expected topic /orders",
        "message skipped: expected a JSON object",
        "field linear.x: expected a number, found null",
        "expected at most 65536 bytes, found 104",
        "field x_cm",
    ];
    let (mut warnings, mut became_orders) = (Vec::new(), Vec::new());
    let gathering = Instant::now();
    while !expected
        .iter()
        .all(|text| warnings.iter().any(|w: &String| w.contains(text)))
        && gathering.elapsed() < Duration::from_secs(10)
    {
        became_orders.extend(orders.poll(SimTime::ZERO));
        warnings.extend(orders.take_warnings());
        std::thread::sleep(Duration::from_millis(20));
    }
    became_orders.extend(orders.poll(SimTime::ZERO));
    assert!(became_orders.is_empty(), "{became_orders:?}");
    let has = |text: &str| warnings.iter().any(|w| w.contains(text));
    assert!(has("refused: expected encoding json"), "{warnings:#?}");
    assert!(has("refused: expected topic /orders"), "{warnings:#?}");
    assert!(
        has("message skipped: expected a JSON object"),
        "{warnings:#?}"
    );
    assert!(
        has("field linear.x: expected a number, found null"),
        "{warnings:#?}"
    );
    assert!(
        has("expected at most 65536 bytes, found 104"),
        "{warnings:#?}"
    );
    assert!(has("field x_cm"), "{warnings:#?}");
    assert!(
        warnings.iter().all(|w| w.len() < 400 && !w.contains('\n')),
        "{warnings:#?}"
    );

    // Everyone left; a new client is served as the first was.
    let start = Instant::now();
    while view.clients() > 0 && start.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(view.clients(), 0);
    let out = dir.path().join("after.json");
    let mut child = client(&view, &out, &["--topics", "/rov/pose", "--seconds", "3"]);
    wait_for_clients(&view, 1);
    let mut k = 0u32;
    publish_until_ended(
        &mut child,
        Duration::from_millis(25),
        Duration::from_secs(30),
        || {
            view.pose(1, &pose(f64::from(k), [4.0, 5.0, 6.0], 0.0));
            k += 1;
        },
    );
    let seen = finish(child, &out, Duration::from_secs(10));
    assert!(count(&seen, "/rov/pose") > 0, "{seen}");
}

#[test]
fn a_rov_end_offers_no_publishing() {
    let (view, mut orders) = start(Role::Rov);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rov.json");
    let child = client(
        &view,
        &out,
        &["--seconds", "3", "--publish-order", r#"{"type":"cancel"}"#],
    );
    let seen = finish(child, &out, Duration::from_secs(10));
    assert_eq!(seen["server"]["name"], "tdma-run rov");
    // Refused without a word to the client: nothing it could do would change that.
    assert_eq!(seen["statuses"], Value::Array(vec![]), "{seen}");
    assert!(orders.poll(SimTime::ZERO).is_empty());
    let warnings = orders.take_warnings();
    assert!(
        warnings.len() == 1 && warnings[0].contains("takes no orders"),
        "{warnings:?}"
    );
}

/// Publishes a GoTo and Twists from a client at `url`; the orders that came of them and the
/// warnings, once the client has ended.
fn publish_from(
    view: &LiveView,
    url: &str,
    orders: &mut LiveOrders,
) -> (Vec<Live>, Vec<String>, Value) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seen.json");
    let goto = r#"{"type":"goto","x_cm":700,"y_cm":-500,"z_cm":300,"heading_deg":90}"#;
    let child = client_at(
        url,
        &out,
        &["--seconds", "2", "--publish-twist", "--publish-order", goto],
    );
    let seen = finish(child, &out, Duration::from_secs(15));
    // The server has handled all the client sent once it has let the client go.
    let start = Instant::now();
    while view.clients() > 0 {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "the client stays"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let (mut got, mut warnings) = (Vec::new(), Vec::new());
    got.extend(orders.poll(SimTime::ZERO));
    warnings.extend(orders.take_warnings());
    (got, warnings, seen)
}

#[test]
fn without_a_token_the_view_takes_no_orders() {
    let (view, mut orders) =
        foxglove::start("127.0.0.1:0", Role::Operator, &Policy::default()).unwrap();
    let url = format!("ws://127.0.0.1:{}", view.port());
    let (got, warnings, seen) = publish_from(&view, &url, &mut orders);
    assert!(got.is_empty(), "{got:?}");
    assert_eq!(warnings.len(), 1, "once per client: {warnings:?}");
    assert!(
        warnings[0].contains("the live view is view-only; control needs --foxglove-token-file"),
        "{warnings:?}"
    );
    assert!(seen["statuses"].to_string().contains("view-only"), "{seen}");
}

#[test]
fn with_a_token_only_the_client_that_carries_it_gives_orders() {
    let (view, mut orders) = start(Role::Operator);
    let url = format!("ws://127.0.0.1:{}", view.port());
    let (got, warnings, _) = publish_from(&view, &url, &mut orders);
    assert!(got.is_empty(), "{got:?}");
    assert!(
        warnings.len() == 1 && warnings[0].contains("its URL has no control token"),
        "{warnings:?}"
    );
    let (got, warnings, _) = publish_from(&view, &format!("{url}/?token={TOKEN}"), &mut orders);
    assert!(warnings.is_empty(), "{warnings:?}");
    assert!(got.contains(&Live::Order(Order::GoTo {
        x_cm: 700,
        y_cm: -500,
        z_cm: 300,
        heading_deg: 90
    })));
    assert!(
        got.iter().any(|l| matches!(l, Live::Joystick { .. })),
        "{got:?}"
    );
}

/// A policy with the control token and TLS, from testdata/tls (a self-signed `localhost`).
fn with_tls() -> Policy {
    let read = |name: &str| std::fs::read(crate::common::testdata(&format!("tls/{name}"))).unwrap();
    Policy {
        tls: Some(
            rovlink_field::foxglove_gate::tls_config(
                &read("localhost.crt"),
                &read("localhost.key"),
            )
            .unwrap(),
        ),
        ..with_token()
    }
}

#[test]
fn over_tls_the_token_holder_drives_and_plain_clients_are_not_served() {
    let (view, mut orders) = foxglove::start("127.0.0.1:0", Role::Operator, &with_tls()).unwrap();
    assert_eq!(view.scheme(), "wss");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seen.json");
    let cafile = crate::common::testdata("tls/localhost.crt");
    let goto = r#"{"type":"goto","x_cm":700,"y_cm":-500,"z_cm":300,"heading_deg":90}"#;
    let child = client_at(
        &format!("wss://127.0.0.1:{}/?token={TOKEN}", view.port()),
        &out,
        &[
            "--seconds",
            "2",
            "--publish-order",
            goto,
            "--cafile",
            cafile.to_str().unwrap(),
        ],
    );
    let seen = finish(child, &out, Duration::from_secs(15));
    assert_eq!(seen["server"]["name"], "tdma-run operator", "{seen}");
    let start = Instant::now();
    let mut got = Vec::new();
    while got.is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "no order over TLS"
        );
        got.extend(orders.poll(SimTime::ZERO));
        std::thread::sleep(Duration::from_millis(10));
    }
    assert_eq!(
        got,
        [Live::Order(Order::GoTo {
            x_cm: 700,
            y_cm: -500,
            z_cm: 300,
            heading_deg: 90
        })]
    );
    // A plain ws:// client gets no WebSocket from a TLS port.
    let status = Command::new("python3")
        .arg(CLIENT)
        .args(["--url", &format!("ws://127.0.0.1:{}/", view.port())])
        .args(["--out", dir.path().join("plain.json").to_str().unwrap()])
        .args(["--seconds", "1"])
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert!(!status.success());
    assert!(orders.poll(SimTime::ZERO).is_empty());
}

#[test]
fn control_off_loopback_needs_insecure() {
    let error = foxglove::start("0.0.0.0:0", Role::Operator, &with_token())
        .err()
        .unwrap()
        .to_string();
    assert!(
        error.starts_with("--foxglove 0.0.0.0:0: control (--foxglove-token-file)")
            && error.contains("--foxglove-insecure"),
        "{error}"
    );
    let insecure = Policy {
        insecure: true,
        ..with_token()
    };
    let (view, _orders) = foxglove::start("0.0.0.0:0", Role::Operator, &insecure).unwrap();
    assert!(view.exposed());
    let (view, _orders) = foxglove::start("0.0.0.0:0", Role::Operator, &Policy::default()).unwrap();
    assert!(view.exposed(), "view-only needs nothing more");
    let (view, _orders) = foxglove::start("0.0.0.0:0", Role::Operator, &with_tls()).unwrap();
    assert!(
        view.exposed() && view.scheme() == "wss",
        "TLS needs nothing more"
    );
}

#[test]
fn bad_and_busy_addresses_are_errors() {
    let (view, _orders) = start(Role::Operator);
    let busy = format!("127.0.0.1:{}", view.port());
    let error = foxglove::start(&busy, Role::Operator, &with_token())
        .err()
        .unwrap()
        .to_string();
    assert!(
        error.starts_with(&format!("--foxglove {busy}: cannot listen: ")),
        "{error}"
    );
    for bad in ["nonsense", "127.0.0.1:http", ":8765", "::1:8765"] {
        let error = foxglove::start(bad, Role::Operator, &with_token())
            .err()
            .unwrap()
            .to_string();
        assert!(
            error.starts_with("--foxglove: expected HOST:PORT") && error.contains(bad),
            "{bad}: {error}"
        );
    }
    let error = foxglove::start("no-such-host.invalid:8765", Role::Operator, &with_token())
        .err()
        .unwrap()
        .to_string();
    assert!(error.contains("cannot listen"), "{error}");
    // Not an address of this machine.
    let error = foxglove::start("192.0.2.1:8765", Role::Operator, &with_token())
        .err()
        .unwrap()
        .to_string();
    assert!(error.contains("cannot listen"), "{error}");
}

#[test]
fn stopping_is_prompt_and_tells_the_clients() {
    let (view, _orders) = start(Role::Operator);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c.json");
    let child = client(&view, &out, &["--seconds", "20"]);
    wait_for_clients(&view, 1);
    let port = view.port();
    let started = Instant::now();
    view.stop();
    let took = started.elapsed();
    let seen = finish(child, &out, Duration::from_secs(10));
    // Stop waits STOP_WAIT at most, never for the client's 20 s; the rest is slack for a
    // loaded machine.
    assert!(
        took < foxglove::STOP_WAIT + Duration::from_secs(4),
        "stop took {took:?}"
    );
    assert_eq!(seen["closed_by_server"], true, "{seen}");
    // The port is free again (once the server's shutdown, which may outlast STOP_WAIT on a
    // loaded machine, has let it go).
    let rebinding = Instant::now();
    let again = loop {
        match foxglove::start(&format!("127.0.0.1:{port}"), Role::Operator, &with_token()) {
            Ok((again, _orders)) => break again,
            Err(e) => assert!(
                rebinding.elapsed() < Duration::from_secs(10),
                "the port is not free after stop: {e}"
            ),
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    drop(again);
}

#[test]
fn an_operator_driven_from_foxglove_over_link_sim() {
    const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let (mut link, a, b) = crate::common::link_sim_pty(&crate::common::TEST_S100);
    let mut rov = Command::new(TDMA_RUN)
        .args(["--role", "rov", "--port", &b, "--duration", "14"])
        .args(["--image-size", "400", "--metrics", &path("rov.json")])
        .args(["--track", &path("track.csv")])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The operator starts once the ROV listens on its port (it says so), not after a guess.
    let rov_said = crate::common::said_until(
        &mut rov,
        "ROV: answering every slot",
        Duration::from_secs(30),
    );
    let port = crate::common::free_port().to_string();
    let address = format!("127.0.0.1:{port}");
    let mut operator = Command::new(TDMA_RUN)
        .args(["--role", "operator", "--port", &a, "--ipg", "150"])
        .args(["--duration", "10", "--image-size", "400"])
        .args(["--foxglove", &address, "--metrics", &path("op.json")])
        .arg("--foxglove-token-file")
        .arg(token_file(dir.path()))
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let out = dir.path().join("seen.json");
    let goto = r#"{"type":"goto","x_cm":300,"y_cm":-20,"z_cm":50,"heading_deg":90}"#;
    let seen_by = Command::new("python3")
        .arg(CLIENT)
        .args(["--url", &format!("ws://{address}/?token={TOKEN}")])
        .args(["--connect-within", "5"])
        .args(["--out", out.to_str().unwrap(), "--seconds", "8"])
        .args(["--topics", "/rov/pose,/camera/image,/link/frames"])
        .args(["--publish-order", goto])
        .stdin(Stdio::null())
        .spawn()
        .unwrap();
    let seen = finish(seen_by, &out, Duration::from_secs(20));
    let operator_status = crate::common::wait_for_exit(&mut operator, Duration::from_secs(20));
    let rov_status = crate::common::wait_for_exit(&mut rov, Duration::from_secs(20));
    let _ = link.kill();
    let _ = link.wait();
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut operator.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(operator_status.success(), "operator: {stderr}");
    assert!(
        rov_status.success(),
        "ROV: {rov_status:?}: {}",
        rov_said.join().unwrap()
    );

    // The operator's view: the pose of every status, completed images, the frames.
    assert!(count(&seen, "/rov/pose") >= 5, "{seen}");
    assert!(count(&seen, "/camera/image") >= 1, "{seen}");
    assert!(count(&seen, "/link/frames") >= 10, "{seen}");
    assert!(png_size(&seen["last"]["/camera/image"]).0 > 0);
    eprintln!(
        "Foxglove client saw: /rov/pose {}, /camera/image {}, /link/frames {}",
        count(&seen, "/rov/pose"),
        count(&seen, "/camera/image"),
        count(&seen, "/link/frames")
    );
    // The client's GoTo went down the link once, was executed and acknowledged.
    let json = |name: &str| -> Value {
        serde_json::from_slice(&std::fs::read(dir.path().join(name)).unwrap()).unwrap()
    };
    let (op, r) = (json("op.json"), json("rov.json"));
    assert_eq!(op["orders_sent"], 1, "{op}");
    assert_eq!(op["orders_acknowledged"], 1, "{op}");
    assert_eq!(r["orders_executed"], 1, "{r}");
    assert_eq!(r["orders_executed_twice"], 0, "{r}");
    let track = std::fs::read_to_string(dir.path().join("track.csv")).unwrap();
    assert!(
        track.lines().any(|l| l.contains(",3.0000,-0.2000,0.5000,")),
        "the ROV's goal is the client's GoTo: {track:.500}"
    );
}

#[test]
fn a_late_subscriber_gets_the_start_line_then_the_latest() {
    let (mut view, _orders) = start(Role::Operator);
    view.session_started("operator: IPG 150.0 ms on /dev/test, 60 s");
    // A quiet session: the start line is all there is.
    let dir = tempfile::tempdir().unwrap();
    let quiet = dir.path().join("quiet.json");
    let args = ["--topics", "/session/log", "--seconds", "2"];
    let seen = finish(
        client(&view, &quiet, &args),
        &quiet,
        Duration::from_secs(15),
    );
    assert_eq!(count(&seen, "/session/log"), 1, "{seen}");
    let line = &seen["first"]["/session/log"];
    assert_eq!(
        line["message"], "operator: IPG 150.0 ms on /dev/test, 60 s",
        "{seen}"
    );
    assert_eq!(line["level"], 2, "INFO");
    assert_eq!(line["name"], "tdma-run");
    // Something happened since: the start line first, then the latest.
    view.event(1, Role::Operator, 3.0, &Event::OrderAcknowledged(4));
    let later = dir.path().join("later.json");
    let seen = finish(
        client(&view, &later, &args),
        &later,
        Duration::from_secs(15),
    );
    assert_eq!(count(&seen, "/session/log"), 2, "{seen}");
    assert_eq!(
        seen["first"]["/session/log"]["message"], "operator: IPG 150.0 ms on /dev/test, 60 s",
        "{seen}"
    );
    assert_eq!(
        seen["last"]["/session/log"]["message"], "order 4 acknowledged",
        "{seen}"
    );
}

#[test]
fn trickling_connections_from_one_address_keep_no_viewer_out() {
    use rovlink_field::foxglove_gate::{MAX_CONNECTIONS, MAX_CONNECTIONS_PER_PEER};
    use std::io::{Read, Write};
    let (view, _orders) = start(Role::Operator);
    let port = view.port();
    // More connections from 127.0.0.1 than the gate carries in all, each trickling an upgrade
    // request that is never whole: before the deadline was for the whole request, each byte
    // within 5 s of the last kept every slot taken for as long as the bytes came.
    let mut tricklers: Vec<Option<std::net::TcpStream>> = (0..=MAX_CONNECTIONS)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
            let _ = s.write_all(b"GET / HTTP/1.1\r\nHost: x\r\nX-Slow: ");
            s.set_nonblocking(true).unwrap();
            Some(s)
        })
        .collect();
    // The sign that the gate has reached a limit: it refused one.
    let mut said = Vec::new();
    let started = Instant::now();
    while !said.iter().any(|l: &String| l.contains(": refused: ")) {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "no refusal: {said:?}"
        );
        said.extend(view.take_refusals());
        std::thread::sleep(Duration::from_millis(10));
    }
    // A viewer from another address is served while they trickle (without the per-peer limit
    // it would be closed at once: every slot would be taken).
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("viewer.json");
    let viewer = client_at(
        &format!("ws://127.0.0.1:{port}/?token={TOKEN}"),
        &out,
        &["--source", "127.0.0.2", "--seconds", "1"],
    );
    let seen = finish(viewer, &out, Duration::from_secs(15));
    assert_eq!(seen["server"]["name"], "tdma-run operator", "{seen}");
    // The tricklers go on, a byte at a time, until the gate has closed every one: those it
    // held are closed at the deadline of their whole request, however the bytes come.
    let started = Instant::now();
    while tricklers.iter().any(Option::is_some) {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "{} connections still open",
            tricklers.iter().flatten().count()
        );
        for slot in tricklers.iter_mut() {
            let Some(s) = slot else { continue };
            let closed = match s.read(&mut [0u8; 64]) {
                Ok(_) => true,
                Err(e) => e.kind() != std::io::ErrorKind::WouldBlock,
            };
            if closed || s.write_all(b"a").is_err() {
                *slot = None;
            }
        }
        said.extend(view.take_refusals());
        std::thread::sleep(Duration::from_millis(200));
    }
    said.extend(view.take_refusals());
    eprintln!("{said:#?}");
    assert!(
        said.iter().any(|l| l.contains(&format!(
            "refused: {MAX_CONNECTIONS_PER_PEER} connections from this address"
        ))),
        "{said:?}"
    );
    assert!(
        said.iter()
            .any(|l| l.contains("its upgrade request was not whole within 5 s")),
        "{said:?}"
    );
    assert!(said.iter().all(|l| !l.contains("all 256")), "{said:?}");
}

#[test]
fn the_help_says_the_gates_limits() {
    use rovlink_field::foxglove_gate::{
        MAX_CONNECTIONS, MAX_CONNECTIONS_PER_PEER, REQUEST_TIMEOUT,
    };
    let limits = format!(
        "The port carries at most {MAX_CONNECTIONS} connections, {MAX_CONNECTIONS_PER_PEER} \
         from one address (in handshake or open), each upgrade request whole within {} s of \
         connecting",
        REQUEST_TIMEOUT.as_secs()
    );
    for (tool, args) in [
        (env!("TOOL_EXE_tdma-run"), &["--help"][..]),
        (env!("TOOL_EXE_octo-delta"), &["view", "--help"][..]),
    ] {
        let help = Command::new(tool).args(args).output().unwrap();
        assert!(help.status.success(), "{tool} {args:?}");
        let text = String::from_utf8_lossy(&help.stdout);
        let text: Vec<&str> = text.split_whitespace().collect();
        assert!(text.join(" ").contains(&limits), "{tool} {args:?}");
    }
}
