//! The ROV end's MAVLink drive against stand-in ArduSubs: the Rust one in
//! `tests/common/ardusub.rs` (over UDP, TCP and a pseudo-terminal as a serial port) and the
//! independent pymavlink one in `tests/mavlink/ardusub.py`. The library tests step the drive
//! as the ROV engine steps it, with a demand every 0.1 s of wall time; the process tests run
//! `tdma-run --vehicle mavlink:...` between `link-sim --pty` and the stand-in.

use crate::common::ardusub;

use std::process::{Child, Command as Process, Stdio};
use std::time::{Duration, Instant};

use crate::common::hostile::signal_once;
use ardusub::{ALT_HOLD, Config, GUIDED, MANUAL, StandIn};
use rovlink_field::mavlink::{MavlinkDrive, MavlinkOptions, connect};
use rovlink_link::SimTime;
use rovlink_rcp::autopilot::{Demand, Drive, DriveEvent};
use rovlink_rcp::vehicle::Command;
use rovlink_wire::Nav;
use rovlink_wire::rov::Why;

pub(crate) fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A drive listening on a free UDP port and a stand-in sending to it.
fn udp_pair(options: &MavlinkOptions, config: Config) -> (MavlinkDrive, StandIn) {
    let port = free_udp_port();
    let drive = connect(&format!("udpin:127.0.0.1:{port}"), options).unwrap();
    let standin = StandIn::start(&format!("udpout:127.0.0.1:{port}"), config);
    (drive, standin)
}

fn thrust(surge: f64) -> Command {
    Command::Thrust {
        surge,
        sway: 0.0,
        heave: 0.0,
        yaw: 0.0,
    }
}

fn demand(command: Command, arm: bool, nav: Nav) -> Demand {
    Demand {
        command,
        arm,
        nav,
        heading_hold_deg: None,
        link_up: true,
    }
}

/// Steps `drive` every 0.1 s of wall time (the session clock starts at `clock`) with what
/// `demand_at` says, until `done` holds or `limit_s` passes; returns the events and whether
/// `done` held.
fn drive_until(
    drive: &mut MavlinkDrive,
    clock: Instant,
    limit_s: f64,
    mut demand_at: impl FnMut(f64) -> Demand,
    mut done: impl FnMut(&MavlinkDrive) -> bool,
) -> (Vec<DriveEvent>, bool) {
    let until = Instant::now() + Duration::from_secs_f64(limit_s);
    let mut events = Vec::new();
    let mut next = Instant::now();
    while Instant::now() < until {
        let t_s = clock.elapsed().as_secs_f64();
        drive.step(SimTime::from_secs_f64(t_s), 0.1, &demand_at(t_s));
        events.extend(drive.take_events());
        if done(drive) {
            return (events, true);
        }
        next += Duration::from_millis(100);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    (events, false)
}

/// The notes among `events` that start with `prefix`.
fn notes_starting<'a>(events: &'a [DriveEvent], prefix: &str) -> Vec<&'a String> {
    events
        .iter()
        .filter_map(|e| match e {
            DriveEvent::Note(n) if n.starts_with(prefix) => Some(n),
            _ => None,
        })
        .collect()
}

fn acks(events: &[DriveEvent]) -> Vec<(String, String, bool)> {
    events
        .iter()
        .filter_map(|e| match e {
            DriveEvent::CommandAck {
                command,
                result,
                accepted,
            } => Some((command.clone(), result.clone(), *accepted)),
            _ => None,
        })
        .collect()
}

/// How long a process may take to show a sign or to end when it should, and the limit of
/// the steps that wait for an outcome (the arming, a mode, a GoTo's arrival): only a hang
/// takes this long, however loaded the machine.
const LIMIT: Duration = Duration::from_secs(30);

/// Half surge forward, armed, in MANUAL, until the stand-in is armed and sees x = 500 (within
/// 10 s, a bound on a hang); returns the events.
fn arms_with_half_stick(
    drive: &mut MavlinkDrive,
    standin: &StandIn,
    clock: Instant,
    what: &str,
) -> Vec<DriveEvent> {
    let (events, armed) = drive_until(
        drive,
        clock,
        10.0,
        |_| demand(thrust(50.0), true, Nav::Manual),
        |d| d.state().armed && standin.seen().max_manual_x >= 500,
    );
    assert!(armed, "{what}: not armed: {events:?} {:?}", standin.seen());
    events
}

/// Arms, streams half-stick surge, switches modes and runs a GoTo; checks what the stand-in
/// saw and that the drive's state is the stand-in's pose.
fn exercise(drive: &mut MavlinkDrive, standin: &StandIn) {
    let clock = Instant::now();
    let events = arms_with_half_stick(drive, standin, clock, "udp");
    assert!(drive.state().responsive);
    assert_eq!(drive.autopilot(), Some((1, 1)));
    let notes: Vec<&DriveEvent> = events
        .iter()
        .filter(|e| matches!(e, DriveEvent::Note(n) if n.contains("autopilot found: system 1 component 1, MAV_TYPE_SUBMARINE")))
        .collect();
    assert_eq!(notes.len(), 1, "{events:?}");
    let ack_list = acks(&events);
    assert!(
        ack_list.contains(&(
            "MAV_CMD_COMPONENT_ARM_DISARM".into(),
            "MAV_RESULT_ACCEPTED".into(),
            true
        )),
        "{events:?}"
    );
    // Depth hold: ALT_HOLD.
    let (_, depth) = drive_until(
        drive,
        clock,
        10.0,
        |_| demand(thrust(0.0), true, Nav::DepthHold),
        |d| d.state().nav == Nav::DepthHold,
    );
    assert!(depth, "{:?}", standin.seen());
    // A GoTo: GUIDED, the setpoint, arrival.
    let goal = Command::GoTo {
        x: 1.5,
        y: 1.0,
        z: 0.5,
        heading_deg: 90.0,
    };
    let (events, reached) = drive_until(
        drive,
        clock,
        30.0,
        |_| demand(goal, true, Nav::Guided),
        |d| d.reached([1.5, 1.0, 0.5], 90.0),
    );
    let seen = standin.seen();
    assert!(reached, "{events:?} {seen:?} {:?}", drive.state());
    assert_eq!(drive.state().nav, Nav::Guided);
    assert_eq!(seen.modes.first(), Some(&ALT_HOLD), "{seen:?}");
    assert!(seen.modes.contains(&GUIDED), "{seen:?}");
    let (point, local) = *seen.setpoints.last().expect("a setpoint");
    assert!(local, "frame");
    assert_eq!(point[..3], [1.5, 1.0, 0.5]);
    assert!(
        (point[3] - std::f32::consts::FRAC_PI_2).abs() < 1e-6,
        "{point:?}"
    );
    // Setpoints are repeated about once a second, not every step.
    assert!(seen.setpoints.len() < 20, "{}", seen.setpoints.len());
    // Neutral sticks while the GoTo runs.
    assert_eq!(seen.last_manual, Some([0, 0, 500, 0]));
    // Back to manual, idle: ALT_HOLD (every stick mode holds depth); the pose the drive
    // reports is the stand-in's own.
    let (_, manual) = drive_until(
        drive,
        clock,
        10.0,
        |_| demand(thrust(0.0), true, Nav::Manual),
        |d| d.state().nav == Nav::DepthHold,
    );
    assert!(manual);
    // Once its latest report is in (at 10 Hz, sooner or later on a loaded machine): stepped
    // until then, not for a guessed time.
    drive_until(
        drive,
        clock,
        10.0,
        |_| demand(thrust(0.0), true, Nav::Manual),
        |d| {
            let (seen, state) = (standin.seen(), d.state());
            state.distance_to(seen.position_m) < 0.05
                && (state.heading_deg - seen.heading_deg).abs() < 1.0
        },
    );
    let seen = standin.seen();
    let state = drive.state();
    let error = state.distance_to(seen.position_m);
    assert!(error < 0.05, "{state:?} vs {seen:?}");
    assert!(
        (state.heading_deg - seen.heading_deg).abs() < 1.0,
        "{state:?} {seen:?}"
    );
    assert_eq!(seen.modes.last(), Some(&ALT_HOLD));
    assert!(!seen.modes.contains(&MANUAL), "{seen:?}");
    // We speak as system 255 component 190, a heartbeat a second.
    assert_eq!(seen.gcs, Some((255, 190)));
    let elapsed_s = clock.elapsed().as_secs_f64();
    assert!(
        f64::from(seen.gcs_heartbeats) >= elapsed_s - 1.5
            && f64::from(seen.gcs_heartbeats) <= elapsed_s + 1.5,
        "{} heartbeats in {elapsed_s} s",
        seen.gcs_heartbeats
    );
    // MANUAL_CONTROL at about 10 Hz.
    let rate_hz = f64::from(seen.manual_controls) / elapsed_s;
    assert!((6.0..=11.0).contains(&rate_hz), "{rate_hz} Hz");
}

#[test]
fn the_drive_arms_switches_modes_streams_sticks_and_flies_a_goto_over_udp() {
    let (mut drive, standin) = udp_pair(
        &MavlinkOptions::default(),
        Config {
            camera_too: true,
            ..Config::default()
        },
    );
    exercise(&mut drive, &standin);
    // The camera's heartbeat and position (component 100) never counted.
    assert!(drive.state().position_m.iter().all(|v| v.abs() < 10.0));
    standin.stop();
}

#[test]
fn the_drive_speaks_over_tcp_and_a_serial_port() {
    // tcpout: the stand-in listens.
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let config = mavlink::TcpConfig::from_listener(listener).unwrap();
    let accept = std::thread::spawn(move || {
        use mavlink::Connectable;
        config.connect::<mavlink::dialects::ardupilotmega::MavMessage>()
    });
    let mut drive = connect(
        &format!("tcpout:127.0.0.1:{port}"),
        &MavlinkOptions::default(),
    )
    .unwrap();
    let standin = StandIn::on_connection(accept.join().unwrap().unwrap(), Config::default());
    arms_with_half_stick(&mut drive, &standin, Instant::now(), "tcp");
    drop(drive);
    standin.stop();

    // tcpin: the drive listens; the autopilot connects, goes away, and a new one connects.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut drive = connect(
        &format!("tcpin:127.0.0.1:{port}"),
        &MavlinkOptions::default(),
    )
    .unwrap();
    let address = format!("tcpout:127.0.0.1:{port}");
    let standin = StandIn::start(&address, Config::default());
    let events = arms_with_half_stick(&mut drive, &standin, Instant::now(), "tcpin");
    assert!(
        events.contains(&DriveEvent::Note(
            "mavlink: TCP connection established".into()
        )),
        "{events:?}"
    );
    standin.stop();
    let standin = StandIn::start(&address, Config::default());
    let (events, again) = drive_until(
        &mut drive,
        Instant::now(),
        5.0,
        |_| demand(thrust(50.0), true, Nav::Manual),
        |_| standin.seen().manual_controls > 0,
    );
    assert!(again, "tcpin, second connection: {events:?}");
    assert!(
        events.iter().any(
            |e| matches!(e, DriveEvent::Note(n) if n.starts_with("mavlink: TCP connection closed"))
        ),
        "{events:?}"
    );
    drop(drive);
    standin.stop();

    // serial: a pseudo-terminal, the stand-in on its master side.
    use nix::fcntl::OFlag;
    use nix::pty::{grantpt, posix_openpt, ptsname_r, unlockpt};
    let master = posix_openpt(OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_CLOEXEC).unwrap();
    grantpt(&master).unwrap();
    unlockpt(&master).unwrap();
    let path = ptsname_r(&master).unwrap();
    let mut drive = connect(&format!("serial:{path}:115200"), &MavlinkOptions::default()).unwrap();
    let standin = StandIn::on_pty(master.into(), Config::default());
    arms_with_half_stick(&mut drive, &standin, Instant::now(), "serial");
    // Dropping the drive waits for its thread, at most a read timeout. With the autopilot
    // silent, a read that waited for bytes would wait for ever: a hang, not a slow machine,
    // is what the bound catches.
    standin.set_silent(true);
    let (dropped, done) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        drop(drive);
        let _ = dropped.send(());
    });
    assert!(
        done.recv_timeout(Duration::from_secs(10)).is_ok(),
        "dropping the serial drive waits on the silent port"
    );
    standin.stop();
}

#[test]
fn a_silent_autopilot_is_unresponsive_then_heard_again() {
    let options = MavlinkOptions {
        silence_s: 1.0,
        ..MavlinkOptions::default()
    };
    let (mut drive, standin) = udp_pair(&options, Config::default());
    let clock = Instant::now();
    let idle = |_| demand(thrust(0.0), false, Nav::Manual);
    let (_, heard) = drive_until(&mut drive, clock, 10.0, idle, |d| d.state().responsive);
    assert!(heard);
    let before = drive.state();
    standin.set_silent(true);
    let (events, silent) = drive_until(&mut drive, clock, 10.0, idle, |d| !d.state().responsive);
    assert!(silent);
    // Reported once, at the first step after 1 s of silence: never before; later only by a
    // step that came late (the upper bound is one on a hang).
    assert!(
        matches!(events.as_slice(), [DriveEvent::Silent { silent_s }] if *silent_s >= 1.0 && *silent_s < 5.0),
        "{events:?}"
    );
    // The last known pose stays.
    assert_eq!(drive.state().position_m, before.position_m);
    standin.set_silent(false);
    let (events, back) = drive_until(&mut drive, clock, 10.0, idle, |d| d.state().responsive);
    assert!(back);
    assert!(events.contains(&DriveEvent::Heard), "{events:?}");
    standin.stop();
}

#[test]
fn a_denied_arm_is_reported_once_and_the_session_goes_on() {
    let (mut drive, standin) = udp_pair(
        &MavlinkOptions::default(),
        Config {
            deny_arm: true,
            ..Config::default()
        },
    );
    // The 4.5 s below start once the autopilot is found (its first arm request goes then),
    // however late the stand-in's first heartbeat comes.
    let clock = Instant::now();
    let half_stick = |_| demand(thrust(50.0), true, Nav::Manual);
    let (mut events, found) = drive_until(&mut drive, clock, 10.0, half_stick, |d| {
        d.autopilot().is_some()
    });
    assert!(found, "{events:?}");
    let (more, _) = drive_until(&mut drive, clock, 4.5, half_stick, |_| false);
    events.extend(more);
    let seen = standin.stop();
    let arms: Vec<_> = seen
        .commands
        .iter()
        .filter(|(c, ..)| format!("{c:?}") == "MAV_CMD_COMPONENT_ARM_DISARM")
        .collect();
    // Retried every 1.5 s while refused: 3 or 4 tries in 4.5 s.
    assert!((2..=4).contains(&arms.len()), "{arms:?}");
    assert_eq!(
        acks(&events)
            .into_iter()
            .filter(|(c, ..)| c == "MAV_CMD_COMPONENT_ARM_DISARM")
            .collect::<Vec<_>>(),
        [(
            "MAV_CMD_COMPONENT_ARM_DISARM".to_string(),
            "MAV_RESULT_DENIED".to_string(),
            false
        )],
        "{events:?}"
    );
    assert!(!drive.state().armed);
    assert!(drive.state().responsive);
    // The sticks kept flowing.
    assert!(seen.manual_controls > 30, "{}", seen.manual_controls);
}

/// Runs `tests/mavlink/ardusub.py` with `args`; it writes its report to `report` at exit.
fn pymavlink_standin(args: &[&str]) -> Child {
    Process::new("python3")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/mavlink/ardusub.py"
        ))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("python3 runs")
}

/// Starts the pymavlink stand-in sending to `port` (with `extra` arguments; its report to
/// `report`) and has `drive` arm it with half a stick forward, in MANUAL; returns it and the
/// session clock.
fn pymavlink_standin_armed(
    drive: &mut MavlinkDrive,
    port: u16,
    report: &std::path::Path,
    extra: &[&str],
) -> (Child, Instant) {
    let to = format!("udpout:127.0.0.1:{port}");
    let report = report.to_str().unwrap();
    let args = ["--connect", &to, "--report", report, "--seconds", "60"];
    let python = pymavlink_standin(&[&args[..], extra].concat());
    let clock = Instant::now();
    let (events, armed) = drive_until(
        drive,
        clock,
        15.0, // python3 and pymavlink take a while to start
        |_| demand(thrust(50.0), true, Nav::Manual),
        |d| d.state().armed,
    );
    assert!(armed, "{events:?}");
    (python, clock)
}

/// Stops the pymavlink stand-in (it writes its report on SIGTERM, once it catches it) and
/// returns its report, in which it was armed by our ground station, system 255 component 190,
/// and (`guided`) switched to GUIDED (4) for a GoTo.
fn stop_pymavlink_standin(
    python: &mut Child,
    report: &std::path::Path,
    guided: bool,
) -> serde_json::Value {
    signal_once(python, nix::sys::signal::Signal::SIGTERM, &|| true, LIMIT);
    let status = crate::common::wait_for_exit(python, LIMIT);
    assert!(status.success(), "{status:?}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    assert_eq!(report["armed"], true, "{report}");
    assert_eq!(report["gcs"], serde_json::json!([255, 190]), "{report}");
    assert!(
        !guided
            || report["modes"]
                .as_array()
                .unwrap()
                .contains(&serde_json::json!(4)),
        "{report}"
    );
    report
}

#[test]
fn the_drive_works_against_the_pymavlink_standin() {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("report.json");
    let port = free_udp_port();
    let mut drive = connect(
        &format!("udpin:127.0.0.1:{port}"),
        &MavlinkOptions::default(),
    )
    .unwrap();
    let (mut python, clock) = pymavlink_standin_armed(&mut drive, port, &report, &[]);
    // Half stick until it has moved forward (about 0.5 m/s: under a second, later on a loaded
    // machine), then a GoTo.
    let (_, moved) = drive_until(
        &mut drive,
        clock,
        10.0,
        |_| demand(thrust(50.0), true, Nav::Manual),
        |d| d.state().position_m[0] > 0.2,
    );
    let start = drive.state().position_m;
    assert!(moved, "it moved forward: {start:?}");
    let goal = [start[0] + 1.0, start[1] - 0.5, 1.0];
    let goto = Command::GoTo {
        x: goal[0],
        y: goal[1],
        z: goal[2],
        heading_deg: 45.0,
    };
    let (events, reached) = drive_until(
        &mut drive,
        clock,
        30.0,
        |_| demand(goto, true, Nav::Guided),
        |d| d.reached(goal, 45.0),
    );
    assert!(reached, "{events:?} {:?}", drive.state());
    // Stop there (manual asked: ALT_HOLD, sticks neutral), then compare poses.
    let stop = |_| demand(thrust(0.0), true, Nav::Manual);
    let (_, stopped) = drive_until(&mut drive, clock, 10.0, stop, |d| {
        d.state().nav == Nav::DepthHold
    });
    assert!(stopped);
    // In ALT_HOLD with neutral sticks it stands still: once its reports have stopped changing
    // (five steps alike, however late they come), ours is its last position.
    let (mut last, mut alike) = (None, 0);
    let (_, still) = drive_until(&mut drive, clock, 10.0, stop, |d| {
        let now = d.state().position_m;
        alike = if last == Some(now) { alike + 1 } else { 0 };
        last = Some(now);
        alike >= 5
    });
    assert!(still, "still moving: {:?}", drive.state());
    let ours = drive.state().position_m;
    let report = stop_pymavlink_standin(&mut python, &report, true);
    let max_x = report["max_manual_x"].as_i64().unwrap();
    assert!((495..=510).contains(&max_x), "{report}");
    let setpoint = &report["setpoints"].as_array().unwrap().last().unwrap();
    for k in 0..3 {
        assert!(
            (setpoint[k].as_f64().unwrap() - goal[k]).abs() < 1e-3,
            "{report}"
        );
    }
    assert!((setpoint[3].as_f64().unwrap() - 45f64.to_radians()).abs() < 1e-3);
    assert_eq!(report["setpoint_frame"], 1, "MAV_FRAME_LOCAL_NED: {report}");
    let theirs: Vec<f64> = report["position"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let error = (0..3)
        .map(|k| (ours[k] - theirs[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(error < 0.05, "ours {ours:?} theirs {theirs:?}");
}

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");

fn last_track_position(track: &std::path::Path) -> [f64; 3] {
    let text = std::fs::read_to_string(track).unwrap();
    let last = text.lines().last().expect("a track row");
    let fields: Vec<f64> = last
        .split(',')
        .skip(1)
        .take(3)
        .map(|v| v.parse().unwrap())
        .collect();
    [fields[0], fields[1], fields[2]]
}

/// A field session in `dir`: link-sim between `tdma-run --role rov --vehicle
/// mavlink:udpin:...` (17 s, metrics in rov.json, with `rov_args`) and an operator (15 s,
/// orders from the FIFO `orders`, op.json, telemetry.jsonl), the Rust stand-in as the
/// autopilot.
struct FieldSession {
    link: crate::common::Reaped,
    rov: Child,
    /// The ROV end's stderr from "answering every slot" on (read aside).
    rov_said: std::thread::JoinHandle<String>,
    standin: StandIn,
    operator: Child,
    /// The operator's stderr, read aside.
    op_said: std::thread::JoinHandle<String>,
    /// The operator's orders, open until dropped.
    fifo: std::fs::File,
    /// The UDP port the ROV end listens on for the autopilot.
    port: u16,
}

impl FieldSession {
    fn start(dir: &std::path::Path, rov_args: &[&str]) -> FieldSession {
        let path = |name: &str| dir.join(name).to_str().unwrap().to_string();
        nix::unistd::mkfifo(dir.join("orders").as_path(), nix::sys::stat::Mode::S_IRWXU).unwrap();
        let (link, a, b) =
            crate::common::link_sim_pty(&["--model", "s100", "--half-duplex", "false"]);
        let port = free_udp_port();
        let mut rov = Process::new(TDMA_RUN)
            .args(["--role", "rov", "--port", &b, "--duration", "17"])
            .args(["--vehicle", &format!("mavlink:udpin:127.0.0.1:{port}")])
            .args(["--image-size", "400", "--metrics", &path("rov.json")])
            .args(rov_args)
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The stand-in and the operator start once the ROV listens (on the vehicle's port and
        // the link's: it says so), not after a guess.
        let rov_said = crate::common::said_until(&mut rov, "ROV: answering every slot", LIMIT);
        let standin = StandIn::start(&format!("udpout:127.0.0.1:{port}"), Config::default());
        let mut operator = Process::new(TDMA_RUN)
            .args(["--role", "operator", "--port", &a, "--duration", "15"])
            .args(["--ipg", "200", "--image-size", "400"])
            .args(["--orders", &path("orders"), "--metrics", &path("op.json")])
            .args(["--telemetry", &path("telemetry.jsonl")])
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let op_stderr = operator.stderr.take().unwrap();
        let op_said = std::thread::spawn(move || std::io::read_to_string(op_stderr).unwrap());
        let fifo = crate::common::fifo_writer(path("orders"), &mut operator, LIMIT);
        FieldSession {
            link,
            rov,
            rov_said,
            standin,
            operator,
            op_said,
            fifo,
            port,
        }
    }

    /// Waits for both ends to end (the operator first, then its FIFO is closed), stops the
    /// stand-in and link-sim; checks that both ends succeeded and returns the ROV end's stderr
    /// and what the stand-in saw.
    fn finish(self) -> (String, ardusub::Seen) {
        let FieldSession {
            mut link,
            mut rov,
            rov_said,
            standin,
            mut operator,
            op_said,
            fifo,
            ..
        } = self;
        let op_status = crate::common::wait_for_exit(&mut operator, LIMIT);
        drop(fifo);
        let op_err = op_said.join().unwrap();
        let rov_status = crate::common::wait_for_exit(&mut rov, LIMIT);
        let seen = standin.stop();
        let _ = link.kill();
        let _ = link.wait();
        let rov_err = rov_said.join().unwrap();
        assert!(op_status.success(), "{op_err}");
        assert!(rov_status.success(), "{rov_err}");
        (rov_err, seen)
    }

    /// Sends the operator an order line.
    fn order(&mut self, line: &str) {
        use std::io::Write;
        writeln!(self.fifo, "{line}").unwrap();
        self.fifo.flush().unwrap();
    }
}

#[test]
fn tdma_run_drives_the_standin_through_link_sim_with_live_orders() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let mut session = FieldSession::start(dir.path(), &["--track", &path("track.csv")]);
    // Half stick forward until the autopilot has it, then stop and go to a point; the FIFO
    // stays open until the operator ends.
    session.order(
        r#"{"type":"velocity","vx":64,"vy":0,"vz":0,"vyaw":0,"arm":true,"disarm":false,"nav":"manual"}"#,
    );
    let typed = Instant::now();
    while session.standin.seen().max_manual_x < 495 {
        assert!(
            session.operator.try_wait().unwrap().is_none(),
            "the operator ended before the half stick reached the autopilot: {:?}",
            session.standin.seen()
        );
        assert!(
            typed.elapsed() < LIMIT,
            "the half stick never reached the autopilot: {:?}",
            session.standin.seen()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    session.order(
        r#"{"type":"velocity","vx":0,"vy":0,"vz":0,"vyaw":0,"arm":true,"disarm":false,"nav":"manual"}"#,
    );
    session.order(r#"{"type":"goto","x_cm":150,"y_cm":50,"z_cm":50,"heading_deg":90}"#);
    let (rov_err, seen) = session.finish();
    assert!(seen.ever_armed, "{seen:?}\n{rov_err}");
    // vx 64 of 127 is 50.4 % of full stick: x 504.
    assert!((495..=510).contains(&seen.max_manual_x), "{seen:?}");
    assert!(seen.modes.contains(&GUIDED), "{seen:?}");
    let (point, local) = *seen.setpoints.last().expect("a setpoint");
    assert!(local);
    assert_eq!(point[..3], [1.5, 0.5, 0.5]);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path("rov.json")).unwrap()).unwrap();
    assert_eq!(r["orders_executed"], 1, "{r}\n{rov_err}");
    let o: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path("op.json")).unwrap()).unwrap();
    assert_eq!(o["orders_acknowledged"], 1, "{o}");
    // The ROV's track is the autopilot's pose: the GoTo was reached and the vehicle stopped.
    let tracked = last_track_position(&dir.path().join("track.csv"));
    let error = (0..3)
        .map(|k| (tracked[k] - seen.position_m[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(
        error < 0.3,
        "track {tracked:?}, autopilot {:?}",
        seen.position_m
    );
    assert!(
        (0..3).all(|k| (seen.position_m[k] - [1.5, 0.5, 0.5][k]).abs() < 0.3),
        "{seen:?}"
    );
    // The operator's telemetry: the last status is the autopilot's own position, and the goto
    // was acknowledged.
    let telemetry: Vec<serde_json::Value> = std::fs::read_to_string(path("telemetry.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let status = telemetry
        .iter()
        .rev()
        .find(|t| t["type"] == "rov")
        .expect("a status in the telemetry");
    let reported = ["x_cm", "y_cm", "z_cm"].map(|k| status[k].as_f64().unwrap() / 100.0);
    let error = (0..3)
        .map(|k| (reported[k] - seen.position_m[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(
        error < 0.3,
        "telemetry {status}, autopilot {:?}",
        seen.position_m
    );
    assert_eq!(status["arm"], true, "{status}");
    assert!(
        telemetry
            .iter()
            .any(|t| t["type"] == "order" && t["state"] == "acknowledged"),
        "{telemetry:?}"
    );
}

#[test]
fn an_unreachable_autopilot_is_exit_2_with_one_line() {
    // A port held closed for the test, not one assumed closed (port 1 once had a listener).
    let closed = crate::common::ClosedPort::hold();
    let tcp = format!("mavlink:tcpout:127.0.0.1:{}", closed.port);
    for endpoint in [
        tcp.as_str(),
        "mavlink:serial:/dev/nonexistent:115200",
        "mavlink:udpout:127.0.0.1:notaport",
    ] {
        let out = Process::new(TDMA_RUN)
            .args([
                "--role",
                "rov",
                "--port",
                "/dev/null",
                "--vehicle",
                endpoint,
            ])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{endpoint}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(
            stderr.starts_with(&format!(
                "tdma-run: --vehicle: mavlink endpoint '{}': ",
                endpoint.trim_start_matches("mavlink:")
            )),
            "{stderr}"
        );
    }
}

#[test]
fn garbage_and_non_finite_numbers_on_the_link_change_nothing() {
    use mavlink::dialects::ardupilotmega::{
        ATTITUDE_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavMessage,
        MavModeFlag, MavState, MavType,
    };
    let port = free_udp_port();
    let mut drive = connect(
        &format!("udpin:127.0.0.1:{port}"),
        &MavlinkOptions::default(),
    )
    .unwrap();
    let peer = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    peer.connect(("127.0.0.1", port)).unwrap();
    let frame = |message: &MavMessage| {
        let mut bytes = Vec::new();
        let header = mavlink::MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 0,
        };
        mavlink::write_versioned_msg(&mut bytes, mavlink::MavlinkVersion::V2, header, message)
            .unwrap();
        bytes
    };
    let heartbeat = frame(&MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 19,
        mavtype: MavType::MAV_TYPE_SUBMARINE,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    }));
    let nan_position = frame(&MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        x: f32::NAN,
        y: f32::INFINITY,
        ..LOCAL_POSITION_NED_DATA::DEFAULT
    }));
    // Finite but beyond the toolkit's 100 km site, and an angle beyond 2π.
    let far_position = frame(&MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        x: -1e38,
        z: 1e38,
        ..LOCAL_POSITION_NED_DATA::DEFAULT
    }));
    let wild_attitude = frame(&MavMessage::ATTITUDE(ATTITUDE_DATA {
        yaw: 1e38,
        ..ATTITUDE_DATA::DEFAULT
    }));
    // Pseudo-random bytes, truncated frames and frames with a wrong checksum.
    let mut seed = 0x2545_f491_u32;
    let mut noise = || {
        seed ^= seed << 13;
        seed ^= seed >> 17;
        seed ^= seed << 5;
        seed
    };
    let clock = Instant::now();
    let (events, _) = drive_until(
        &mut drive,
        clock,
        2.0,
        |_| demand(thrust(0.0), false, Nav::Manual),
        |_| {
            for _ in 0..20 {
                let len = (noise() % 300) as usize;
                let junk: Vec<u8> = (0..len).map(|_| noise() as u8).collect();
                peer.send(&junk).unwrap();
                let mut broken = heartbeat.clone();
                let k = noise() as usize % broken.len();
                broken[k] ^= 0x5a;
                peer.send(&broken).unwrap();
                peer.send(&heartbeat[..heartbeat.len() / 2]).unwrap();
            }
            peer.send(&heartbeat).unwrap();
            peer.send(&nan_position).unwrap();
            peer.send(&far_position).unwrap();
            peer.send(&wild_attitude).unwrap();
            false
        },
    );
    let state = drive.state();
    assert!(state.responsive, "{events:?}");
    assert_eq!(drive.autopilot(), Some((1, 1)));
    assert_eq!(
        state.position_m, [0.0; 3],
        "non-finite and out-of-range positions are dropped"
    );
    assert_eq!(state.heading_deg, 0.0, "an angle beyond 2π is dropped");
    // One warning per kind of message, however many were dropped.
    let warnings = notes_starting(&events, "warning:");
    assert_eq!(warnings.len(), 2, "{events:?}");
    assert!(
        warnings[0].contains("LOCAL_POSITION_NED dropped: field x"),
        "{warnings:?}"
    );
    assert!(
        warnings[1].contains("ATTITUDE dropped: field yaw: expected within ±6.28"),
        "{warnings:?}"
    );
    assert!(
        events.iter().all(|e| matches!(e, DriveEvent::Note(n)
            if n.contains("autopilot found")
                || n.contains("UDP: the autopilot is system 1 at")
                || n.starts_with("warning:"))),
        "{events:?}"
    );
}

#[test]
fn neutral_sticks_in_any_stick_mode_hold_the_buoyant_vehicles_depth() {
    // The stand-in rises at BUOYANT_RISE_MPS unless a depth-holding mode holds it, as the real
    // BlueROV2 does in STABILIZE (SITL: 0.89 m to 0.09 m in 10 s).
    let (mut drive, standin) = udp_pair(
        &MavlinkOptions::default(),
        Config {
            start_m: [0.0, 0.0, 1.0],
            ..Config::default()
        },
    );
    let clock = Instant::now();
    for nav in [Nav::Stabilize, Nav::Manual, Nav::DepthHold] {
        let (events, held) = drive_until(
            &mut drive,
            clock,
            10.0,
            |_| demand(thrust(0.0), true, nav),
            |d| d.state().armed && d.state().nav == Nav::DepthHold,
        );
        assert!(held, "{nav}: {events:?} {:?}", standin.seen());
    }
    // Three seconds of neutral sticks, however slowly they pass: the depth stays (floating,
    // it would have risen 0.24 m).
    let depth = standin.seen().position_m[2];
    let from = Instant::now();
    drive_until(
        &mut drive,
        clock,
        10.0,
        |_| demand(thrust(0.0), true, Nav::Stabilize),
        |_| from.elapsed() >= Duration::from_secs(3),
    );
    let seen = standin.stop();
    assert!((seen.position_m[2] - depth).abs() < 0.02, "{seen:?}");
    assert!(depth > 0.9, "{depth}");
    assert_eq!(seen.modes, [ALT_HOLD], "{seen:?}");
}

#[test]
fn guided_refused_without_a_position_is_reported_and_the_position_unknown() {
    // The stand-in gets its position 3 s after start, as SITL does about 40 s after boot.
    let (mut drive, standin) = udp_pair(
        &MavlinkOptions::default(),
        Config {
            position_after_s: Some(3.0),
            ..Config::default()
        },
    );
    let clock = Instant::now();
    let (events, found) = drive_until(
        &mut drive,
        clock,
        10.0,
        |_| demand(thrust(0.0), true, Nav::HoldPosition),
        |d| d.state().armed && d.state().nav == Nav::DepthHold,
    );
    assert!(found, "{events:?}");
    // No position: hold_position is ALT_HOLD, and the state says the position is unknown.
    assert!(!drive.state().position_known, "{:?}", drive.state());
    // Asked for GUIDED (an operator's guided without a GoTo) while there is no position: the
    // drive keeps ALT_HOLD instead of asking; once the position comes, GUIDED.
    let (events, guided) = drive_until(
        &mut drive,
        clock,
        10.0,
        |_| demand(thrust(0.0), true, Nav::Guided),
        |d| d.state().nav == Nav::Guided,
    );
    assert!(guided, "{events:?}");
    assert!(drive.state().position_known);
    let seen = standin.stop();
    assert_eq!(
        seen.modes_refused, 0,
        "GUIDED asked without a position: {seen:?}"
    );
    assert_eq!(seen.modes, [ALT_HOLD, GUIDED], "{seen:?}");
}

#[test]
fn a_mode_the_autopilot_refuses_is_said_with_its_words_and_a_goto_without_position_is_held_back() {
    // ArduSub SITL refuses ALT_HOLD for its first moments ("Mode change failed: ALT_HOLD need
    // alt estimate"), and has no position at all without a position source (GPS1_TYPE 0).
    let (mut drive, standin) = udp_pair(
        &MavlinkOptions::default(),
        Config {
            position_after_s: None,
            depth_after_s: 2.0,
            ..Config::default()
        },
    );
    let clock = Instant::now();
    let (events, refused) = drive_until(
        &mut drive,
        clock,
        10.0,
        |_| demand(thrust(0.0), true, Nav::Stabilize),
        |d| d.state().why == Why::ModeRefused,
    );
    assert!(refused, "{events:?}");
    let (more, held) = drive_until(
        &mut drive,
        clock,
        10.0,
        |_| demand(thrust(0.0), true, Nav::Stabilize),
        |d| d.state().nav == Nav::DepthHold && d.state().armed,
    );
    assert!(held, "{more:?}");
    assert_eq!(drive.state().why, Why::Nothing);
    let refusals: Vec<&DriveEvent> = events
        .iter()
        .chain(&more)
        .filter(|e| matches!(e, DriveEvent::Refused { .. }))
        .collect();
    // Said once per story: the ACK, then the autopilot's words with it (they may come
    // together).
    assert!(
        (1..=2).contains(&refusals.len())
            && matches!(refusals.last(), Some(DriveEvent::Refused { why: Why::ModeRefused, reason })
                if reason.contains("ALT_HOLD (2)") && reason.contains("MAV_RESULT_FAILED")
                    && reason.contains("Mode change failed: ALT_HOLD need alt estimate")),
        "{refusals:?}"
    );
    assert!(!drive.state().position_known);
    // A GoTo demand without a position: GUIDED is not asked for, no setpoint goes, the depth
    // is held.
    let goal = Command::GoTo {
        x: 1.0,
        y: 0.0,
        z: 0.5,
        heading_deg: 0.0,
    };
    let from = Instant::now();
    drive_until(
        &mut drive,
        clock,
        10.0,
        |_| demand(goal, true, Nav::Guided),
        |_| from.elapsed() >= Duration::from_secs(2),
    );
    let seen = standin.stop();
    assert!(seen.setpoints.is_empty(), "{seen:?}");
    assert_eq!(seen.modes, [ALT_HOLD], "{seen:?}");
}

#[test]
fn the_stand_in_disarms_on_a_lost_gcs_as_ardusub_does() {
    let (mut drive, standin) = udp_pair(&MavlinkOptions::default(), Config::default());
    arms_with_half_stick(&mut drive, &standin, Instant::now(), "failsafe");
    // The ROV end gone: no HEARTBEAT, no MANUAL_CONTROL. ArduSub's GCS failsafe disarms 5 s on.
    drop(drive);
    let gone = Instant::now();
    while standin.seen().armed {
        assert!(gone.elapsed() < LIMIT, "{:?}", standin.seen());
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(gone.elapsed() >= Duration::from_secs_f64(ardusub::GCS_FAILSAFE_S - 0.2));
    assert_eq!(standin.stop().failsafes, 1);
}

/// A MAVLink 2 frame from system 1 component 1, unsigned.
fn frame_from_system_1(message: &mavlink::dialects::ardupilotmega::MavMessage) -> Vec<u8> {
    let mut bytes = Vec::new();
    let header = mavlink::MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 0,
    };
    mavlink::write_versioned_msg(&mut bytes, mavlink::MavlinkVersion::V2, header, message).unwrap();
    bytes
}

/// A spoofer's frames as system 1: a disarmed submarine in STABILIZE at (40, 40, 4), heading
/// 180 degrees.
pub(crate) fn spoofed_frames() -> Vec<Vec<u8>> {
    use mavlink::dialects::ardupilotmega::{
        ATTITUDE_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavMessage,
        MavModeFlag, MavState, MavType,
    };
    [
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_SUBMARINE,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }),
        MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
            x: 40.0,
            y: 40.0,
            z: 4.0,
            ..LOCAL_POSITION_NED_DATA::DEFAULT
        }),
        MavMessage::ATTITUDE(ATTITUDE_DATA {
            yaw: std::f32::consts::PI,
            ..ATTITUDE_DATA::DEFAULT
        }),
    ]
    .iter()
    .map(frame_from_system_1)
    .collect()
}

#[test]
fn a_spoofer_on_another_port_moves_nothing_and_diverts_nothing() {
    // The issue's attack on udpin: HEARTBEAT, position and attitude as system 1 from another
    // port, after the real autopilot was heard.
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let mut session = FieldSession::start(dir.path(), &[]);
    session.order(
        r#"{"type":"velocity","vx":0,"vy":0,"vz":0,"vyaw":0,"arm":true,"disarm":false,"nav":"manual"}"#,
    );
    let port = session.port;
    let standin = &session.standin;
    // Armed through the ROV end: the autopilot is known (MANUAL_CONTROL needs it).
    let wait = |what: &str, done: &dyn Fn(&ardusub::Seen) -> bool| {
        let since = Instant::now();
        while !done(&standin.seen()) {
            assert!(since.elapsed() < LIMIT, "{what}: {:?}", standin.seen());
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    wait("armed by the ROV end", &|s| {
        s.armed && s.manual_controls > 0
    });
    // The spoofer: from its own port, every 20 ms, until told to stop.
    let spoofer = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let spoofer_port = spoofer.local_addr().unwrap().port();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let spoofing = {
        let (socket, stop) = (spoofer.try_clone().unwrap(), std::sync::Arc::clone(&stop));
        std::thread::spawn(move || {
            let frames = spoofed_frames();
            let mut sent = 0u64;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) && sent < 3000 {
                for frame in &frames {
                    let _ = socket.send_to(frame, ("127.0.0.1", port));
                    sent += 1;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            sent
        })
    };
    // While it spoofs, the ROV end's heartbeats and sticks still reach the real autopilot.
    let before = standin.seen();
    wait("heartbeats and sticks during the spoof", &|s| {
        s.gcs_heartbeats >= before.gcs_heartbeats + 3
            && s.manual_controls >= before.manual_controls + 30
    });
    let (rov_err, seen) = session.finish();
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let spoofed = spoofing.join().unwrap();
    assert!(spoofed > 0);
    // The autopilot was never left without its GCS, and nothing went to the spoofer.
    assert_eq!(seen.failsafes, 0, "{seen:?}");
    assert!(seen.armed, "{seen:?}");
    spoofer.set_nonblocking(true).unwrap();
    let mut buf = [0u8; 512];
    let answered = spoofer.recv_from(&mut buf);
    assert!(
        matches!(&answered, Err(e) if e.kind() == std::io::ErrorKind::WouldBlock),
        "the ROV end answered the spoofer: {answered:?}"
    );
    // The operator saw the real autopilot's pose and state, never the spoofer's.
    let statuses: Vec<serde_json::Value> = std::fs::read_to_string(path("telemetry.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|t| t["type"] == "rov")
        .collect();
    assert!(statuses.len() > 10, "{statuses:?}");
    for status in &statuses {
        let xyz = ["x_cm", "y_cm", "z_cm"].map(|k| status[k].as_f64().unwrap() / 100.0);
        assert!(
            xyz.iter().all(|v| v.abs() < 5.0),
            "the spoofer's position reached the operator: {status}"
        );
    }
    assert_eq!(statuses.last().unwrap()["arm"], true);
    // Counted, and said once: the pin, and the spoofer's address.
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path("rov.json")).unwrap()).unwrap();
    let dropped = r["mavlink_refused"]["other_address"].as_u64().unwrap_or(0);
    assert!(dropped > 0 && dropped <= spoofed, "{r}");
    let pinned: Vec<&str> = rov_err
        .lines()
        .filter(|l| l.contains("the autopilot is system 1 at 127.0.0.1:"))
        .collect();
    assert_eq!(pinned.len(), 1, "{rov_err}");
    let refusals: Vec<&str> = rov_err
        .lines()
        .filter(|l| l.contains("mavlink: refused"))
        .collect();
    assert_eq!(refusals.len(), 1, "{rov_err}");
    assert!(
        refusals[0].starts_with(&format!(
            "tdma-run: mavlink: refused a datagram from 127.0.0.1:{spoofer_port}: "
        )),
        "{rov_err}"
    );
    assert!(
        rov_err.contains("tdma-run: warning: MAVLink is unsigned"),
        "{rov_err}"
    );
}

/// A key file with `key` in hex, mode 0600, in `dir`.
pub(crate) fn key_file(dir: &std::path::Path, key: [u8; 32]) -> std::path::PathBuf {
    let hex: String = key.iter().map(|b| format!("{b:02x}")).collect();
    crate::common::private_file(dir, "mavlink.key", &format!("{hex}\n"))
}

/// A drive on a free UDP port (`udpin:`) signing with `key`, read from a key file in `dir`:
/// the key file, where a stand-in's report goes, the port and the drive.
fn signed_drive(
    dir: &std::path::Path,
    key: [u8; 32],
) -> (std::path::PathBuf, std::path::PathBuf, u16, MavlinkDrive) {
    let key_path = key_file(dir, key);
    let port = free_udp_port();
    let options = MavlinkOptions {
        key: Some(rovlink_field::mavlink::SigningKey::read(&key_path).unwrap()),
        ..MavlinkOptions::default()
    };
    let drive = connect(&format!("udpin:127.0.0.1:{port}"), &options).unwrap();
    (key_path, dir.join("report.json"), port, drive)
}

fn refused(drive: &MavlinkDrive, reason: &str) -> u64 {
    drive
        .refused()
        .iter()
        .find(|(r, _)| r.name() == reason)
        .map_or(0, |(_, n)| *n)
}

#[test]
fn a_signed_session_with_the_pymavlink_standin_uses_only_what_the_key_signed() {
    let dir = tempfile::tempdir().unwrap();
    let key: [u8; 32] = std::array::from_fn(|k| (k as u8).wrapping_mul(37) ^ 0xa5);
    let (key_path, report, port, mut drive) = signed_drive(dir.path(), key);
    assert!(drive.signed());
    // The stand-in signs with the key (pymavlink's signing), takes only what it signed, and
    // sends every second an unsigned position at (40, 40, 4), one signed with another key and
    // a replay of its first signed position.
    let extra = ["--key-file", key_path.to_str().unwrap(), "--forgeries"];
    let (mut python, clock) = pymavlink_standin_armed(&mut drive, port, &report, &extra);
    let forged = [40.0, 40.0, 4.0];
    let goal = [1.0, -0.5, 1.0];
    let goto = Command::GoTo {
        x: goal[0],
        y: goal[1],
        z: goal[2],
        heading_deg: 45.0,
    };
    let mut worst = f64::INFINITY;
    let (events, reached) = drive_until(
        &mut drive,
        clock,
        30.0,
        |_| demand(goto, true, Nav::Guided),
        |d| {
            worst = worst.min(d.state().distance_to(forged));
            d.reached(goal, 45.0)
                && ["unsigned", "bad_signature", "replayed"]
                    .iter()
                    .all(|r| refused(d, r) >= 2)
        },
    );
    assert!(
        reached,
        "{events:?} {:?} {:?}",
        drive.state(),
        drive.refused()
    );
    assert!(
        worst > 30.0,
        "a forged position was used: {worst} m from it"
    );
    // Each refusal said once, naming the stand-in's address.
    let notes = notes_starting(&events, "mavlink: refused");
    assert!(notes.len() <= 3, "{notes:?}");
    assert_eq!(refused(&drive, "other_address"), 0);
    let report = stop_pymavlink_standin(&mut python, &report, true);
    // Everything the drive sent verified with pymavlink's signing.
    assert_eq!(report["bad_signatures"], 0, "{report}");
    assert!(report["forgeries"].as_u64().unwrap() >= 2, "{report}");
}

#[test]
fn an_autopilot_whose_signing_clock_is_behind_catches_up_with_ours() {
    // Its first signed messages are ten minutes old (refused: a replay would look so), but it
    // is answered, hears our newer timestamps and catches up, as ArduPilot does.
    let dir = tempfile::tempdir().unwrap();
    let (key_path, report, port, mut drive) = signed_drive(dir.path(), [0x3c; 32]);
    let extra = [
        "--key-file",
        key_path.to_str().unwrap(),
        "--key-behind",
        "600",
    ];
    let (mut python, _) = pymavlink_standin_armed(&mut drive, port, &report, &extra);
    assert!(refused(&drive, "replayed") > 0, "{:?}", drive.refused());
    assert_eq!(drive.autopilot(), Some((1, 1)));
    let report = stop_pymavlink_standin(&mut python, &report, false);
    assert_eq!(report["bad_signatures"], 0, "{report}");
}

#[test]
fn with_a_key_an_unsigned_autopilot_is_never_listened_to() {
    let options = MavlinkOptions {
        key: Some(rovlink_field::mavlink::SigningKey([7; 32])),
        ..MavlinkOptions::default()
    };
    let (mut drive, standin) = udp_pair(&options, Config::default());
    let clock = Instant::now();
    let (events, _) = drive_until(
        &mut drive,
        clock,
        10.0,
        |_| demand(thrust(50.0), true, Nav::Manual),
        |d| refused(d, "unsigned") >= 30,
    );
    assert!(refused(&drive, "unsigned") >= 30, "{events:?}");
    assert_eq!(drive.autopilot(), None);
    assert!(!drive.state().responsive);
    assert_eq!(drive.state().position_m, [0.0; 3]);
    // Nothing was sent to it (no autopilot is known, and a udpin socket answers only a
    // signed sender), so it never armed.
    let seen = standin.stop();
    assert_eq!(seen.gcs_heartbeats, 0, "{seen:?}");
    assert!(!seen.ever_armed);
    let said: Vec<&DriveEvent> = events
        .iter()
        .filter(|e| matches!(e, DriveEvent::Note(n) if n.starts_with("mavlink: refused an unsigned message")))
        .collect();
    // Once per source: the stand-in's autopilot component, and its camera if any.
    assert_eq!(said.len(), 1, "{events:?}");
    assert!(
        events.iter().any(|e| matches!(
            e,
            DriveEvent::MessagesRefused {
                reason: "unsigned",
                ..
            }
        )),
        "{events:?}"
    );
}
