//! The ROV end's MAVLink drive against stand-in ArduSubs: the Rust one in
//! `tests/common/ardusub.rs` (over UDP, TCP and a pseudo-terminal as a serial port) and the
//! independent pymavlink one in `tests/mavlink/ardusub.py`. The drive is stepped as the ROV
//! engine steps it, with a demand every 0.1 s of wall time.

#[path = "common/ardusub.rs"]
mod ardusub;

use std::process::{Child, Command as Process, Stdio};
use std::time::{Duration, Instant};

use ardusub::{ALT_HOLD, Config, GUIDED, MANUAL, StandIn};
use rovlink::link::SimTime;
use rovlink::rcp::drive::{Demand, Drive, DriveEvent};
use rovlink::rcp::mavlink::{MavlinkDrive, MavlinkOptions, connect};
use rovlink::vehicle::Command;
use rovlink::wire::Nav;

fn free_udp_port() -> u16 {
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

/// Half surge forward, armed, in MANUAL, until the stand-in is armed and sees x = 500 (5 s at
/// most); returns the events.
fn arms_with_half_stick(
    drive: &mut MavlinkDrive,
    standin: &StandIn,
    clock: Instant,
    what: &str,
) -> Vec<DriveEvent> {
    let (events, armed) = drive_until(
        drive,
        clock,
        5.0,
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
        4.0,
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
        12.0,
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
    // Back to manual, idle: the pose the drive reports is the stand-in's own.
    let (_, manual) = drive_until(
        drive,
        clock,
        4.0,
        |_| demand(thrust(0.0), true, Nav::Manual),
        |d| d.state().nav == Nav::Manual,
    );
    assert!(manual);
    std::thread::sleep(Duration::from_millis(300));
    drive.step(
        SimTime::from_secs_f64(clock.elapsed().as_secs_f64()),
        0.1,
        &demand(thrust(0.0), true, Nav::Manual),
    );
    let seen = standin.seen();
    let state = drive.state();
    let error = state.distance_to(seen.position_m);
    assert!(error < 0.05, "{state:?} vs {seen:?}");
    assert!(
        (state.heading_deg - seen.heading_deg).abs() < 1.0,
        "{state:?} {seen:?}"
    );
    assert_eq!(seen.modes.last(), Some(&MANUAL));
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
    assert!((8.0..=11.0).contains(&rate_hz), "{rate_hz} Hz");
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
    let started = Instant::now();
    drop(drive);
    assert!(started.elapsed() < Duration::from_millis(500));
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
    let (_, heard) = drive_until(&mut drive, clock, 3.0, idle, |d| d.state().responsive);
    assert!(heard);
    let before = drive.state();
    standin.set_silent(true);
    let (events, silent) = drive_until(&mut drive, clock, 3.0, idle, |d| !d.state().responsive);
    assert!(silent);
    assert!(
        matches!(events.as_slice(), [DriveEvent::Silent { silent_s }] if *silent_s >= 1.0 && *silent_s < 1.3),
        "{events:?}"
    );
    // The last known pose stays.
    assert_eq!(drive.state().position_m, before.position_m);
    standin.set_silent(false);
    let (events, back) = drive_until(&mut drive, clock, 3.0, idle, |d| d.state().responsive);
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
    let (events, _) = drive_until(
        &mut drive,
        Instant::now(),
        4.5,
        |_| demand(thrust(50.0), true, Nav::Manual),
        |_| false,
    );
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
    let mut python = pymavlink_standin(&[
        "--connect",
        &format!("udpout:127.0.0.1:{port}"),
        "--report",
        report.to_str().unwrap(),
        "--seconds",
        "60",
    ]);
    let clock = Instant::now();
    let (events, armed) = drive_until(
        &mut drive,
        clock,
        15.0, // python3 and pymavlink take a while to start
        |_| demand(thrust(50.0), true, Nav::Manual),
        |d| d.state().armed,
    );
    assert!(armed, "{events:?}");
    // Two seconds of half stick, then a GoTo.
    drive_until(
        &mut drive,
        clock,
        2.0,
        |_| demand(thrust(50.0), true, Nav::Manual),
        |_| false,
    );
    let start = drive.state().position_m;
    assert!(start[0] > 0.2, "it moved forward: {start:?}");
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
        12.0,
        |_| demand(goto, true, Nav::Guided),
        |d| d.reached(goal, 45.0),
    );
    assert!(reached, "{events:?} {:?}", drive.state());
    std::thread::sleep(Duration::from_millis(300));
    drive.step(
        SimTime::from_secs_f64(clock.elapsed().as_secs_f64()),
        0.1,
        &demand(goto, true, Nav::Guided),
    );
    let ours = drive.state().position_m;
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(python.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let status = python.wait().unwrap();
    assert!(status.success(), "{status:?}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(report["armed"], true, "{report}");
    assert_eq!(report["gcs"], serde_json::json!([255, 190]), "{report}");
    let max_x = report["max_manual_x"].as_i64().unwrap();
    assert!((495..=510).contains(&max_x), "{report}");
    assert!(
        report["modes"]
            .as_array()
            .unwrap()
            .contains(&serde_json::json!(4)),
        "{report}"
    );
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
