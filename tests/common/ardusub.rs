//! A stand-in ArduSub for the tests, on the `mavlink` crate, run as threads inside the test
//! process: it speaks as system 1 component 1 (MAV_TYPE_SUBMARINE, MAV_AUTOPILOT_ARDUPILOTMEGA),
//! sends HEARTBEAT at 1 Hz and LOCAL_POSITION_NED and ATTITUDE at 10 Hz, answers COMMAND_LONG
//! with COMMAND_ACK (arm/disarm, DO_SET_MODE with ArduSub's custom modes, SET_MESSAGE_INTERVAL)
//! and moves simply: armed in a stick mode, MANUAL_CONTROL x/y/r are body velocities (1000 =
//! 1 m/s, 30 degrees/s) and z is ArduSub's throttle (0 = full down at 0.5 m/s); armed in GUIDED,
//! it goes to the last SET_POSITION_TARGET_LOCAL_NED at 0.5 m/s and turns to its yaw. Like
//! ArduSub it takes MANUAL_CONTROL and commands only when they are addressed to it, and setpoints
//! only in GUIDED. Everything it saw is kept in [`Seen`].
//!
//! What the real ArduSub SITL showed, it does too: no LOCAL_POSITION_NED and GUIDED and
//! POSHOLD refused (MAV_RESULT_FAILED and STATUSTEXT "Mode change failed: GUIDED requires
//! position") until it has a position ([`Config::position_after_s`], never without a position
//! source); positive buoyancy (it rises at [`BUOYANT_RISE_MPS`] with neutral sticks unless a
//! depth-holding mode holds it: ALT_HOLD, POSHOLD, GUIDED); and the GCS failsafe (armed, a GCS
//! once heard, then neither its HEARTBEAT nor its MANUAL_CONTROL for [`GCS_FAILSAFE_S`]:
//! disarmed).
#![allow(dead_code)]

use std::io::Write;
use std::os::fd::{AsFd, OwnedFd};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::{
    ATTITUDE_DATA, COMMAND_ACK_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavCmd,
    MavFrame, MavMessage, MavModeFlag, MavResult, MavSeverity, MavState, MavType, STATUSTEXT_DATA,
};
use mavlink::{MavConnection, MavHeader, MavlinkReader, MavlinkVersion};

/// ArduSub's custom mode numbers the stand-in accepts.
pub const MANUAL: u32 = 19;
/// STABILIZE.
pub const STABILIZE: u32 = 0;
/// ALT_HOLD.
pub const ALT_HOLD: u32 = 2;
/// POSHOLD.
pub const POSHOLD: u32 = 16;
/// GUIDED.
pub const GUIDED: u32 = 4;

/// How fast the buoyant vehicle rises where nothing holds its depth, m/s (SITL: 0.89 m to
/// 0.09 m in 10 s in STABILIZE with neutral sticks).
pub const BUOYANT_RISE_MPS: f64 = 0.08;

/// How long without its GCS's HEARTBEAT and MANUAL_CONTROL before an armed ArduSub disarms, s.
pub const GCS_FAILSAFE_S: f64 = 5.0;

/// How the stand-in behaves.
#[derive(Debug, Clone)]
pub struct Config {
    /// Its system id.
    pub system_id: u8,
    /// Answer arm requests with MAV_RESULT_DENIED (and stay disarmed).
    pub deny_arm: bool,
    /// Also send, from component 100, a camera's heartbeat (autopilot INVALID) and a wrong
    /// LOCAL_POSITION_NED, which a GCS must ignore.
    pub camera_too: bool,
    /// Where it starts, NED m.
    pub start_m: [f64; 3],
    /// When its EKF has a position, s after it starts (`None`: never, no position source).
    pub position_after_s: Option<f64>,
    /// Until this long after it starts, ALT_HOLD and POSHOLD are refused ("Mode change
    /// failed: ALT_HOLD need alt estimate", as SITL at boot), s.
    pub depth_after_s: f64,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            system_id: 1,
            deny_arm: false,
            camera_too: false,
            start_m: [0.0; 3],
            position_after_s: Some(0.0),
            depth_after_s: 0.0,
        }
    }
}

/// What the stand-in saw and where it is.
#[derive(Debug, Clone, Default)]
pub struct Seen {
    /// Armed now.
    pub armed: bool,
    /// Was armed at some point.
    pub ever_armed: bool,
    /// The custom mode now.
    pub mode: u32,
    /// Every mode it was switched to, in order.
    pub modes: Vec<u32>,
    /// GCS heartbeats received, and the (system, component) of the last.
    pub gcs_heartbeats: u32,
    /// The sender of the last GCS heartbeat.
    pub gcs: Option<(u32, u8)>,
    /// MANUAL_CONTROL messages addressed to it.
    pub manual_controls: u32,
    /// The largest x seen.
    pub max_manual_x: i16,
    /// The last x, y, z, r.
    pub last_manual: Option<[i16; 4]>,
    /// Every setpoint: x, y, z (m), yaw (rad), and whether its frame was MAV_FRAME_LOCAL_NED.
    pub setpoints: Vec<([f32; 4], bool)>,
    /// Every COMMAND_LONG addressed to it: command, param1, param2.
    pub commands: Vec<(MavCmd, f32, f32)>,
    /// Position, NED m.
    pub position_m: [f64; 3],
    /// Heading, degrees 0..360.
    pub heading_deg: f64,
    /// Mode changes refused for want of a position.
    pub modes_refused: u32,
    /// Times the GCS failsafe disarmed it.
    pub failsafes: u32,
}

/// A running stand-in.
pub struct StandIn {
    seen: Arc<Mutex<Seen>>,
    silent: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

type Sender = Box<dyn FnMut(&MavHeader, &MavMessage) + Send>;

impl StandIn {
    /// Starts on a MAVLink connection string of the crate's (`udpout:127.0.0.1:PORT`, ...).
    pub fn start(address: &str, config: Config) -> StandIn {
        let mut conn = mavlink::connect::<MavMessage>(address).expect("stand-in connects");
        conn.set_allow_recv_any_version(true);
        Self::on_connection(conn, config)
    }

    /// Starts on an open connection.
    pub fn on_connection(conn: mavlink::Connection<MavMessage>, config: Config) -> StandIn {
        let conn = Arc::new(conn);
        let stop = Arc::new(AtomicBool::new(false));
        let (to_sim, from_link) = channel();
        let reader = {
            let (conn, stop) = (Arc::clone(&conn), Arc::clone(&stop));
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    match conn.try_recv() {
                        Ok(message) => {
                            if to_sim.send(message).is_err() {
                                return;
                            }
                        }
                        Err(_) => std::thread::sleep(Duration::from_millis(2)),
                    }
                }
            })
        };
        let send: Sender = Box::new(move |header, message| {
            let _ = conn.send(header, message);
        });
        Self::run(config, from_link, send, stop, reader)
    }

    /// Starts on a pseudo-terminal's master side (the drive opens the slave as `serial:`).
    pub fn on_pty(master: OwnedFd, config: Config) -> StandIn {
        let stop = Arc::new(AtomicBool::new(false));
        let (to_sim, from_link) = channel();
        let read_side = std::fs::File::from(master.as_fd().try_clone_to_owned().expect("dup"));
        let mut write_side = std::fs::File::from(master);
        let reader = std::thread::spawn(move || {
            let mut reader = MavlinkReader::new(read_side);
            while let Ok(message) = reader.read_any_message::<MavMessage>() {
                if to_sim.send(message).is_err() {
                    return;
                }
            }
        });
        let send: Sender = Box::new(move |header, message| {
            let _ =
                mavlink::write_versioned_msg(&mut write_side, MavlinkVersion::V2, *header, message);
            let _ = write_side.flush();
        });
        Self::run(config, from_link, send, stop, reader)
    }

    fn run(
        config: Config,
        from_link: Receiver<(MavHeader, MavMessage)>,
        send: Sender,
        stop: Arc<AtomicBool>,
        reader: JoinHandle<()>,
    ) -> StandIn {
        let seen = Arc::new(Mutex::new(Seen {
            mode: MANUAL,
            position_m: config.start_m,
            ..Seen::default()
        }));
        let silent = Arc::new(AtomicBool::new(false));
        let sim = {
            let (seen, silent, stop) = (Arc::clone(&seen), Arc::clone(&silent), Arc::clone(&stop));
            std::thread::spawn(move || simulate(config, from_link, send, &seen, &silent, &stop))
        };
        StandIn {
            seen,
            silent,
            stop,
            threads: vec![sim, reader],
        }
    }

    /// What it saw so far.
    pub fn seen(&self) -> Seen {
        self.seen.lock().unwrap().clone()
    }

    /// Stops (or resumes) sending anything, as an autopilot that went silent.
    pub fn set_silent(&self, silent: bool) {
        self.silent.store(silent, Ordering::Relaxed);
    }

    /// Stops its threads and returns what it saw.
    pub fn stop(mut self) -> Seen {
        self.stop.store(true, Ordering::Relaxed);
        // The pty reader ends when the master closes (with the simulation thread's writer).
        let sim = self.threads.remove(0);
        sim.join().unwrap();
        self.seen()
    }
}

impl Drop for StandIn {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn wrap_pi(angle: f64) -> f64 {
    (angle + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

fn simulate(
    config: Config,
    from_link: Receiver<(MavHeader, MavMessage)>,
    mut send: Sender,
    seen: &Mutex<Seen>,
    silent: &AtomicBool,
    stop: &AtomicBool,
) {
    let me = MavHeader {
        system_id: u32::from(config.system_id),
        component_id: 1,
        sequence: 0,
    };
    let camera = MavHeader {
        component_id: 100,
        ..me
    };
    let started = Instant::now();
    let mut next_tick = started;
    let mut next_heartbeat = started;
    let mut sticks: Option<([i16; 4], Instant)> = None;
    let mut target: Option<[f32; 4]> = None;
    let mut yaw = 0.0f64;
    let mut gcs_heard: Option<Instant> = None;
    let mut texts: Vec<String> = Vec::new();
    let has_position = |now: Instant| {
        config
            .position_after_s
            .is_some_and(|after| now.duration_since(started).as_secs_f64() >= after)
    };
    while !stop.load(Ordering::Relaxed) {
        let wait = next_tick.saturating_duration_since(Instant::now());
        match from_link.recv_timeout(wait) {
            Ok((header, message)) => {
                let mut s = seen.lock().unwrap();
                let addressed = |system: u8| system == config.system_id;
                match message {
                    MavMessage::HEARTBEAT(h) if h.mavtype == MavType::MAV_TYPE_GCS => {
                        gcs_heard = Some(Instant::now());
                        s.gcs_heartbeats += 1;
                        s.gcs = Some((header.system_id, header.component_id));
                    }
                    MavMessage::MANUAL_CONTROL(m) if addressed(m.target) => {
                        gcs_heard = Some(Instant::now());
                        s.manual_controls += 1;
                        s.max_manual_x = s.max_manual_x.max(m.x);
                        s.last_manual = Some([m.x, m.y, m.z, m.r]);
                        sticks = Some(([m.x, m.y, m.z, m.r], Instant::now()));
                    }
                    MavMessage::SET_POSITION_TARGET_LOCAL_NED(p) if addressed(p.target_system) => {
                        let local = p.coordinate_frame == MavFrame::MAV_FRAME_LOCAL_NED;
                        s.setpoints.push(([p.x, p.y, p.z, p.yaw], local));
                        if s.mode == GUIDED && local {
                            target = Some([p.x, p.y, p.z, p.yaw]);
                        }
                    }
                    MavMessage::COMMAND_LONG(c) if addressed(c.target_system) => {
                        s.commands.push((c.command, c.param1, c.param2));
                        let result = match c.command {
                            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM if config.deny_arm => {
                                MavResult::MAV_RESULT_DENIED
                            }
                            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
                                s.armed = c.param1 > 0.5;
                                s.ever_armed |= s.armed;
                                MavResult::MAV_RESULT_ACCEPTED
                            }
                            MavCmd::MAV_CMD_DO_SET_MODE => {
                                let mode = c.param2 as u32;
                                let needs_position = [POSHOLD, GUIDED].contains(&mode);
                                let needs_depth = [ALT_HOLD, POSHOLD].contains(&mode);
                                if needs_depth
                                    && started.elapsed().as_secs_f64() < config.depth_after_s
                                {
                                    s.modes_refused += 1;
                                    let name = if mode == ALT_HOLD {
                                        "ALT_HOLD"
                                    } else {
                                        "POSHOLD"
                                    };
                                    texts.push(format!(
                                        "Mode change failed: {name} need alt estimate"
                                    ));
                                    MavResult::MAV_RESULT_FAILED
                                } else if needs_position && !has_position(Instant::now()) {
                                    s.modes_refused += 1;
                                    let name = if mode == GUIDED { "GUIDED" } else { "POSHOLD" };
                                    texts.push(format!(
                                        "Mode change failed: {name} requires position"
                                    ));
                                    MavResult::MAV_RESULT_FAILED
                                } else if [MANUAL, STABILIZE, ALT_HOLD, POSHOLD, GUIDED]
                                    .contains(&mode)
                                {
                                    if s.mode != mode {
                                        s.modes.push(mode);
                                        target = None;
                                    }
                                    s.mode = mode;
                                    MavResult::MAV_RESULT_ACCEPTED
                                } else {
                                    MavResult::MAV_RESULT_DENIED
                                }
                            }
                            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => MavResult::MAV_RESULT_ACCEPTED,
                            _ => MavResult::MAV_RESULT_UNSUPPORTED,
                        };
                        if !silent.load(Ordering::Relaxed) {
                            for text in texts.drain(..) {
                                let mut bytes = [0u8; 50];
                                bytes[..text.len()].copy_from_slice(text.as_bytes());
                                send(
                                    &me,
                                    &MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                                        severity: MavSeverity::MAV_SEVERITY_WARNING,
                                        text: bytes.into(),
                                    }),
                                );
                            }
                            send(
                                &me,
                                &MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                                    command: c.command,
                                    result,
                                }),
                            );
                        }
                    }
                    _ => {}
                }
                continue;
            }
            Err(RecvTimeoutError::Disconnected) => return,
            Err(RecvTimeoutError::Timeout) => {}
        }
        // A 10 Hz tick: move, then report.
        let dt = 0.1;
        next_tick += Duration::from_millis(100);
        let mut s = seen.lock().unwrap();
        if s.armed && gcs_heard.is_some_and(|at| at.elapsed().as_secs_f64() >= GCS_FAILSAFE_S) {
            s.armed = false;
            s.failsafes += 1;
            gcs_heard = None;
        }
        let fresh = sticks.filter(|(_, at)| at.elapsed() < Duration::from_secs(1));
        let mut velocity_ned = [0.0f64; 3];
        let mut yaw_rate = 0.0f64;
        if s.armed && s.mode == GUIDED {
            if let Some([x, y, z, yaw_target]) = target {
                let error = [
                    f64::from(x) - s.position_m[0],
                    f64::from(y) - s.position_m[1],
                    f64::from(z) - s.position_m[2],
                ];
                let distance = error.iter().map(|e| e * e).sum::<f64>().sqrt();
                let speed = (distance / dt).min(0.5);
                if distance > 1e-9 {
                    velocity_ned = error.map(|e| e / distance * speed);
                }
                let turn = wrap_pi(f64::from(yaw_target) - yaw);
                yaw_rate = (turn / dt).clamp(-30f64.to_radians(), 30f64.to_radians());
            }
        } else if let (true, Some(([x, y, z, r], _))) = (s.armed, fresh) {
            let (surge, sway) = (f64::from(x) / 1000.0, f64::from(y) / 1000.0);
            velocity_ned = [
                surge * yaw.cos() - sway * yaw.sin(),
                surge * yaw.sin() + sway * yaw.cos(),
                (500.0 - f64::from(z)) / 500.0 * 0.5,
            ];
            yaw_rate = f64::from(r) / 1000.0 * 30f64.to_radians();
        }
        let depth_held = s.armed && [ALT_HOLD, POSHOLD, GUIDED].contains(&s.mode);
        if depth_held && s.mode != GUIDED {
            // The throttle stick climbs or dives; centred, the depth stays.
            velocity_ned[2] =
                fresh.map_or(0.0, |([.., z, _], _)| (500.0 - f64::from(z)) / 500.0 * 0.5);
        } else if !depth_held {
            velocity_ned[2] -= BUOYANT_RISE_MPS;
        }
        for (p, v) in s.position_m.iter_mut().zip(velocity_ned) {
            *p += v * dt;
        }
        // Buoyant: no higher than the surface.
        s.position_m[2] = s.position_m[2].max(0.0);
        yaw = wrap_pi(yaw + yaw_rate * dt);
        s.heading_deg = yaw.to_degrees().rem_euclid(360.0);
        let (armed, mode, position) = (s.armed, s.mode, s.position_m);
        drop(s);
        if silent.load(Ordering::Relaxed) {
            continue;
        }
        let boot_ms = started.elapsed().as_millis() as u32;
        if Instant::now() >= next_heartbeat {
            next_heartbeat += Duration::from_secs(1);
            let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
            if armed {
                base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
            }
            if config.camera_too {
                send(
                    &camera,
                    &MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                        custom_mode: 0,
                        mavtype: MavType::MAV_TYPE_CAMERA,
                        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                        base_mode: MavModeFlag::empty(),
                        system_status: MavState::MAV_STATE_ACTIVE,
                        mavlink_version: 3,
                    }),
                );
            }
            send(
                &me,
                &MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                    custom_mode: mode,
                    mavtype: MavType::MAV_TYPE_SUBMARINE,
                    autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                    base_mode,
                    system_status: MavState::MAV_STATE_ACTIVE,
                    mavlink_version: 3,
                }),
            );
        }
        if config.camera_too {
            send(
                &camera,
                &MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                    time_boot_ms: boot_ms,
                    x: 99.0,
                    y: 99.0,
                    z: 99.0,
                    ..LOCAL_POSITION_NED_DATA::DEFAULT
                }),
            );
        }
        if has_position(Instant::now()) {
            send(
                &me,
                &MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                    time_boot_ms: boot_ms,
                    x: position[0] as f32,
                    y: position[1] as f32,
                    z: position[2] as f32,
                    vx: velocity_ned[0] as f32,
                    vy: velocity_ned[1] as f32,
                    vz: velocity_ned[2] as f32,
                }),
            );
        }
        send(
            &me,
            &MavMessage::ATTITUDE(ATTITUDE_DATA {
                time_boot_ms: boot_ms,
                roll: 0.0,
                pitch: 0.0,
                yaw: yaw as f32,
                rollspeed: 0.0,
                pitchspeed: 0.0,
                yawspeed: yaw_rate as f32,
            }),
        );
    }
}
