//! The ROV end driving a real autopilot: ArduSub over MAVLink 2 (the `mavlink` crate, the
//! ardupilotmega dialect), as a [`Drive`].
//!
//! We speak as a ground station, system [`MavlinkOptions::system_id`] (255, ArduSub's default
//! `SYSID_MYGCS`), and address the autopilot found on the link: the first HEARTBEAT whose
//! autopilot is not `MAV_AUTOPILOT_INVALID` and whose type is not a GCS (a submarine is
//! preferred over anything else that claims to be an autopilot). Only that system and component
//! is listened to afterwards: other ground stations, cameras and gimbals are ignored.
//!
//! What goes out, all from [`Drive::step`] and timed by the session clock it is given:
//! - a GCS HEARTBEAT at [`MavlinkOptions::heartbeat_hz`], from the first step on;
//! - MANUAL_CONTROL at [`MavlinkOptions::manual_control_hz`] once the autopilot is known: the
//!   thrust command scaled as ArduSub reads it ([`manual_control_axes`]), neutral while a GoTo
//!   runs and while the operator's link is lost (a steady neutral stream keeps ArduSub's pilot
//!   input failsafe quiet, so the vehicle holds instead of being disarmed);
//! - HoldHeading closed here on ATTITUDE's yaw into the r (yaw) axis, with the built-in model's
//!   gain ([`rovlink_rcp::vehicle::Vehicle::thrust_for`]);
//! - MAV_CMD_COMPONENT_ARM_DISARM and MAV_CMD_DO_SET_MODE (custom mode, [`custom_mode_of`]) when
//!   the demand asks for an arm state or mode the autopilot does not report, retried every
//!   [`COMMAND_RETRY_S`] until it does; a request that was met is not enforced again until the
//!   demand changes, so a failsafe or another station is not fought;
//! - for a GoTo: GUIDED, then SET_POSITION_TARGET_LOCAL_NED (position and yaw) at once, when
//!   the target changes, when the mode becomes GUIDED, and every [`SETPOINT_RESEND_S`];
//! - MAV_CMD_SET_MESSAGE_INTERVAL for ATTITUDE and LOCAL_POSITION_NED at [`STREAM_HZ`] while
//!   they do not arrive.
//!
//! What comes back: HEARTBEAT (armed, mode: [`nav_of_custom_mode`]), LOCAL_POSITION_NED
//! (position; velocity turned into the body frame), ATTITUDE (roll, pitch, heading, yaw rate),
//! COMMAND_ACK ([`DriveEvent::CommandAck`]) and STATUSTEXT of warning severity or worse
//! ([`DriveEvent::Note`]). An autopilot silent for [`MavlinkOptions::silence_s`] (or never heard)
//! makes [`DriveState::responsive`] false, reported once as [`DriveEvent::Silent`]; the state keeps
//! the last values known.
//!
//! Contract: nothing here panics on any input (a peer's non-finite numbers are dropped, locks
//! that a panicking thread poisoned are still read) and nothing blocks the session: the
//! connection is opened in [`connect`] (a TCP connect waits at most [`TCP_CONNECT_TIMEOUT`]), then
//! a background thread receives with a [`READ_TIMEOUT`] and hands over what it learnt under a
//! lock held for a copy; `step` does at most a few sends (TCP and serial writes time out after
//! [`WRITE_TIMEOUT`]). A send that fails is a [`DriveEvent::Note`], once until sends work again.
//! The messages kept between two steps are bounded ([`MAX_QUEUED`]). Dropping the drive stops
//! the thread and waits for it (at most a read timeout, or a reconnect attempt).
//!
//! Who is listened to. With a key ([`MavlinkOptions::key`], tdma-run's `--mavlink-key-file`)
//! every frame sent is signed (MAVLink 2 signing, 13 bytes more a frame) and a frame heard is
//! used only when it is signed with that key and its timestamp is newer than its stream's last
//! one; without a key nothing is signed or checked. Over UDP the first autopilot heard (its
//! address and system id; with a key, a signed HEARTBEAT) is the only one listened to and
//! answered from then on: a `udpin:` socket no longer follows whoever sent last. What is
//! refused is counted by reason ([`Refusal`], [`DriveEvent::MessagesRefused`], the metrics'
//! `mavlink_refused`) and said once per reason and source ([`DriveEvent::Note`], and on stderr
//! when [`MavlinkOptions::tool`] is set).
//!
//! By concern: `transport.rs` is the connection (the endpoint in the one device grammar, opened
//! by the one opener, MAVLink framing over it, the receiving thread and its gate, TCP's
//! reconnects); `signing.rs` the key and the signatures;
//! `codec.rs` what the messages mean (ArduSub's modes and NAV, the stick axes, what the heard
//! messages leave in the inbox); this file the options and the drive's state machine. The
//! public paths are this module's (`rcp::mavlink::manual_control_axes`, ...).

mod codec;
mod signing;
mod transport;

pub use codec::{
    ALT_HOLD, GUIDED, NEUTRAL_AXES, OTHER_MODE_NAV, POSHOLD, ardusub_mode_name, custom_mode_of,
    demanded_mode, manual_control_axes, nav_of_custom_mode,
};
pub use signing::{KEY_BYTES, KeyError, Refusal, SIGNATURE_BYTES, SigningKey};
pub use transport::{MAX_SOURCES_SAID, parse_endpoint};

use std::io;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use mavlink::MavHeader;
use mavlink::dialects::ardupilotmega::{
    COMMAND_LONG_DATA, MANUAL_CONTROL_DATA, MavCmd, MavFrame, MavMessage, MavModeFlag, MavResult,
    PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA,
};

use codec::{Autopilot, Inbox};
use rovlink_link::SimTime;
use rovlink_link::device::DeviceSpec;
use rovlink_rcp::autopilot::{Demand, Drive, DriveEvent, DriveState};
use rovlink_rcp::vehicle::{Command, Vehicle, angle_diff_deg};
use rovlink_wire::Nav;
use rovlink_wire::rov::Why;
use signing::Signing;
use transport::{Gate, Shared, lock, receive};

/// How often an arm or mode request the autopilot has not met is sent again, s.
pub const COMMAND_RETRY_S: f64 = 1.5;

/// How often a GoTo's setpoint is sent again while the target stays the same, s.
pub const SETPOINT_RESEND_S: f64 = 1.0;

/// The rate asked of the autopilot for ATTITUDE and LOCAL_POSITION_NED, Hz.
pub const STREAM_HZ: f64 = 10.0;

/// A stream missing for this long is asked for (again), s.
pub const STREAM_MISSING_S: f64 = 2.0;

/// The least time between two requests for the same stream, s.
pub const STREAM_REQUEST_S: f64 = 10.0;

/// How long the receiving thread waits for bytes before it looks at its stop flag.
pub const READ_TIMEOUT: Duration = Duration::from_millis(100);

/// How long a TCP or serial write may wait before it fails.
pub const WRITE_TIMEOUT: Duration = Duration::from_millis(200);

/// How long `tcp:` (`tcpout:`) waits for the autopilot to accept the connection.
pub const TCP_CONNECT_TIMEOUT: Duration = Duration::from_secs(3);

/// How often a closed `tcp:` (`tcpout:`) connection is tried again.
pub const RECONNECT_PERIOD: Duration = Duration::from_secs(1);

/// The most acknowledgements and notes kept between two steps (older ones are dropped).
pub const MAX_QUEUED: usize = 64;

/// LOCAL_POSITION_NED missing for this long means the vehicle has no position estimate, s.
pub const POSITION_STALE_S: f64 = 3.0;

/// Why the autopilot's endpoint could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum MavlinkError {
    /// The endpoint text is not one of the forms ([`parse_endpoint`]).
    #[error("mavlink endpoint '{endpoint}': {reason}")]
    Syntax {
        /// The text given.
        endpoint: String,
        /// What is wrong.
        reason: String,
    },
    /// The endpoint is well-formed but cannot be opened (bind fails, TCP refused, no device).
    #[error("mavlink endpoint '{endpoint}': cannot {action}: {source}")]
    Open {
        /// The endpoint.
        endpoint: String,
        /// What was tried (`bind`, `connect`, `open the serial port`, ...).
        action: &'static str,
        /// Why it failed.
        source: io::Error,
    },
    /// An option out of its range.
    #[error("mavlink options: {0}")]
    Options(String),
}

/// How the ROV end talks to the autopilot.
#[derive(Debug, Clone, PartialEq)]
pub struct MavlinkOptions {
    /// Our system id: 255, ArduSub's default `SYSID_MYGCS` (it takes MANUAL_CONTROL and
    /// counts GCS heartbeats only from that system).
    pub system_id: u8,
    /// Our component id: 190, MAV_COMP_ID_MISSIONPLANNER, what a GCS uses.
    pub component_id: u8,
    /// GCS HEARTBEAT rate, Hz (1: what ArduPilot's GCS failsafe expects).
    pub heartbeat_hz: f64,
    /// MANUAL_CONTROL rate, Hz (10: the rate QGroundControl sends a joystick at; steps come
    /// every 0.1 s, so more is sent at most once a step).
    pub manual_control_hz: f64,
    /// Silence after which the autopilot counts as unresponsive, s (3: three missed 1 Hz
    /// heartbeats).
    pub silence_s: f64,
    /// GoTo arrival distance, m. 0.3: ArduSub's position controller, on a DVL-aided estimate
    /// that wanders by a decimetre or so, settles within a few decimetres; a tighter bound
    /// would leave orders unfinished while the vehicle hovers at its target.
    pub arrival_m: f64,
    /// GoTo arrival heading error, degrees. 5: the built-in model's bound and about what a
    /// compass on a small ROV can be trusted to.
    pub arrival_deg: f64,
    /// The MAVLink 2 signing key: everything sent is signed with it and only what is signed
    /// with it (each frame newer than its stream's last) is used. `None`: nothing signed,
    /// nothing checked.
    pub key: Option<SigningKey>,
    /// A tool's name: refusals are also said on stderr as `TOOL: mavlink: refused ...`
    /// (`None`: only as notes).
    pub tool: Option<&'static str>,
}

impl Default for MavlinkOptions {
    fn default() -> Self {
        MavlinkOptions {
            system_id: 255,
            component_id: 190,
            heartbeat_hz: 1.0,
            manual_control_hz: 10.0,
            silence_s: 3.0,
            arrival_m: 0.3,
            arrival_deg: 5.0,
            key: None,
            tool: None,
        }
    }
}

impl MavlinkOptions {
    fn check(&self) -> Result<(), MavlinkError> {
        let positive = [
            ("heartbeat_hz", self.heartbeat_hz),
            ("manual_control_hz", self.manual_control_hz),
            ("silence_s", self.silence_s),
            ("arrival_m", self.arrival_m),
            ("arrival_deg", self.arrival_deg),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(MavlinkError::Options(format!(
                    "{name}: expected a positive number, found {value}"
                )));
            }
        }
        if self.system_id == 0 {
            return Err(MavlinkError::Options(
                "system_id: expected 1..=255, found 0 (the broadcast id)".to_string(),
            ));
        }
        Ok(())
    }
}

/// A time base for "every so often", on the session clock.
#[derive(Debug, Clone, Copy)]
struct Ticker {
    period_s: f64,
    next: Option<SimTime>,
}

impl Ticker {
    fn new(period_s: f64) -> Ticker {
        Ticker {
            period_s,
            next: None,
        }
    }

    /// True when due at `now`, `slack_s` early allowed (steps jitter in real time); the next
    /// time stays on the grid, or restarts from `now` after a gap.
    fn due(&mut self, now: SimTime, slack_s: f64) -> bool {
        match self.next {
            Some(next) if now.after_secs(slack_s) < next => false,
            Some(next) => {
                let following = next.after_secs(self.period_s);
                self.next = Some(if following <= now {
                    now.after_secs(self.period_s)
                } else {
                    following
                });
                true
            }
            None => {
                self.next = Some(now.after_secs(self.period_s));
                true
            }
        }
    }
}

/// An arm state or mode asked of the autopilot until it reports it.
#[derive(Debug, Clone, Copy, Default)]
struct Request<T> {
    wanted: Option<T>,
    sent_at: Option<SimTime>,
    met: bool,
}

/// What a [`Request`] says at a step.
#[derive(Debug, PartialEq, Eq)]
enum Ask {
    /// Nothing to send.
    Nothing,
    /// Send: the first time for this value (`true`) or a retry.
    Send(bool),
}

impl<T: Copy + PartialEq> Request<T> {
    fn ask(&mut self, want: T, reported: Option<T>, now: SimTime) -> Ask {
        let fresh = self.wanted != Some(want);
        if fresh {
            *self = Request {
                wanted: Some(want),
                sent_at: None,
                met: false,
            };
        }
        if self.met || reported == Some(want) {
            self.met = true;
            return Ask::Nothing;
        }
        match self.sent_at {
            Some(at) if now < at.after_secs(COMMAND_RETRY_S) => Ask::Nothing,
            Some(_) => Ask::Send(false),
            None => Ask::Send(true),
        }
    }
}

/// A stream of the autopilot's that we ask for while it is missing.
#[derive(Debug, Clone, Copy)]
struct Stream {
    message_id: u32,
    count: u64,
    seen_at: Option<SimTime>,
    asked_at: Option<SimTime>,
}

impl Stream {
    fn new(message_id: u32) -> Stream {
        Stream {
            message_id,
            count: 0,
            seen_at: None,
            asked_at: None,
        }
    }

    /// True when the stream should be asked for at `now` (it has `count` messages so far).
    fn wanted(&mut self, count: u64, now: SimTime, since: SimTime) -> bool {
        if count != self.count {
            self.count = count;
            self.seen_at = Some(now);
        }
        let quiet_from = self.seen_at.unwrap_or(since);
        let missing = now >= quiet_from.after_secs(STREAM_MISSING_S) || self.seen_at.is_none();
        let may_ask = self
            .asked_at
            .is_none_or(|at| now >= at.after_secs(STREAM_REQUEST_S));
        if missing && may_ask {
            self.asked_at = Some(now);
            true
        } else {
            false
        }
    }
}

/// A real autopilot behind a MAVLink endpoint, driven as the ROV's vehicle.
pub struct MavlinkDrive {
    endpoint: DeviceSpec,
    options: MavlinkOptions,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    state: DriveState,
    events: Vec<DriveEvent>,
    started_at: Option<SimTime>,
    target: Option<Autopilot>,
    heard: u64,
    heard_at: Option<SimTime>,
    silent: bool,
    custom_mode: Option<u32>,
    noted_mode: Option<u32>,
    have_attitude: bool,
    heartbeat: Ticker,
    manual: Ticker,
    arm: Request<bool>,
    mode: Request<u32>,
    setpoint: Option<([f64; 4], SimTime)>,
    was_guided: bool,
    streams: [Stream; 2],
    /// The last result reported per command, so that retries answered alike say it once.
    reported: Vec<(MavCmd, MavResult)>,
    /// When LOCAL_POSITION_NED last came.
    position_at: Option<SimTime>,
    /// The failed COMMAND_ACK result of the arm request in force.
    arm_result: Option<MavResult>,
    /// The failed COMMAND_ACK result of the mode request in force, and the autopilot's
    /// "Mode change failed" text since it began.
    mode_result: Option<MavResult>,
    mode_text: Option<String>,
    /// The refusals last reported (arm, mode), so that each is said once.
    refusals_said: [Option<String>; 2],
    /// Frames refused by the gate so far, by [`Refusal`] (its order), as last reported.
    refused: [u64; 5],
    send_error: Option<String>,
}

/// Opens `endpoint` (see [`parse_endpoint`]) and starts listening for the autopilot. A syntax
/// error or an endpoint that cannot be opened (bind fails, TCP refused or unanswered for
/// [`TCP_CONNECT_TIMEOUT`], no such serial device) is an error naming the endpoint and why. It
/// does not wait for the autopilot: an absent autopilot shows as silence.
pub fn connect(endpoint: &str, options: &MavlinkOptions) -> Result<MavlinkDrive, MavlinkError> {
    options.check()?;
    let parsed = parse_endpoint(endpoint)?;
    let (conn, reopen) = transport::open(&parsed, endpoint)?;
    let conn = conn.map(Arc::new);
    let shared = Arc::new(Shared {
        conn: Mutex::new(conn),
        inbox: Mutex::new(Inbox::default()),
        stop: AtomicBool::new(false),
        // Link id 0: our one link to the autopilot.
        signing: options
            .key
            .clone()
            .map(|key| Arc::new(Signing::new(key, 0))),
    });
    let thread_shared = Arc::clone(&shared);
    let gate = Gate::new(options.system_id, options.tool);
    let thread = std::thread::Builder::new()
        .name("mavlink-receive".to_string())
        .spawn(move || receive(&thread_shared, reopen, gate))
        .map_err(|source| MavlinkError::Open {
            endpoint: endpoint.to_string(),
            action: "start its receiving thread",
            source,
        })?;
    Ok(MavlinkDrive {
        endpoint: parsed,
        options: options.clone(),
        shared,
        thread: Some(thread),
        state: DriveState::unheard(Why::Nothing),
        events: Vec::new(),
        started_at: None,
        target: None,
        heard: 0,
        heard_at: None,
        silent: false,
        custom_mode: None,
        noted_mode: None,
        have_attitude: false,
        heartbeat: Ticker::new(1.0 / options.heartbeat_hz),
        manual: Ticker::new(1.0 / options.manual_control_hz),
        arm: Request::default(),
        mode: Request::default(),
        setpoint: None,
        was_guided: false,
        streams: [Stream::new(30), Stream::new(32)],
        reported: Vec::new(),
        position_at: None,
        arm_result: None,
        mode_result: None,
        mode_text: None,
        refusals_said: [None, None],
        refused: [0; 5],
        send_error: None,
    })
}

impl MavlinkDrive {
    /// The endpoint, as parsed.
    pub fn endpoint(&self) -> &DeviceSpec {
        &self.endpoint
    }

    /// The autopilot's system and component ids, once its HEARTBEAT was heard.
    pub fn autopilot(&self) -> Option<(u8, u8)> {
        self.target.map(|a| (a.system, a.component))
    }

    /// Frames refused so far, by reason (those not yet taken by a step included).
    pub fn refused(&self) -> [(Refusal, u64); 5] {
        let counts = lock(&self.shared.inbox).refused;
        std::array::from_fn(|k| (Refusal::ALL[k], counts[k]))
    }

    /// True when what is sent is signed (a key was given).
    pub fn signed(&self) -> bool {
        self.shared.signing.is_some()
    }

    /// The autopilot's custom mode from its last HEARTBEAT.
    pub fn custom_mode(&self) -> Option<u32> {
        self.custom_mode
    }

    fn send(&mut self, message: &MavMessage) {
        let conn = lock(&self.shared.conn).clone();
        let Some(conn) = conn else {
            return; // TCP (re)connecting: nothing to send on.
        };
        let header = MavHeader {
            system_id: u32::from(self.options.system_id),
            component_id: self.options.component_id,
            sequence: 0,
        };
        match conn.send(&header, message, self.shared.signing.as_deref()) {
            Ok(_) => self.send_error = None,
            Err(error) => {
                let text = format!("mavlink {}: send failed: {error}", self.endpoint);
                if self.send_error.as_deref() != Some(text.as_str()) {
                    self.events.push(DriveEvent::Note(text.clone()));
                    self.send_error = Some(text);
                }
            }
        }
    }

    fn command(&mut self, target: Autopilot, command: MavCmd, params: [f32; 3]) {
        let [param1, param2, param3] = params;
        self.send(&MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1,
            param2,
            param3,
            command,
            target_system: target.system,
            target_component: target.component,
            ..COMMAND_LONG_DATA::DEFAULT
        }));
    }

    /// What stands in the way of the demand: [`DriveState::why`], and a
    /// [`DriveEvent::Refused`] when an arm or mode refusal begins or its story grows.
    fn refusals(&mut self) {
        if self.arm.met {
            self.arm_result = None;
        }
        if self.mode.met {
            self.mode_result = None;
            self.mode_text = None;
        }
        let arm = self.arm_result.map(|result| {
            let what = if self.arm.wanted == Some(true) {
                "arm"
            } else {
                "disarm"
            };
            format!("{what} refused: {result:?}")
        });
        let mode = (self.mode_result.is_some() || self.mode_text.is_some()).then(|| {
            let name = self
                .mode
                .wanted
                .map_or_else(String::new, |m| format!("{} ({m}) ", ardusub_mode_name(m)));
            let parts: Vec<String> = self
                .mode_result
                .map(|r| format!("{r:?}"))
                .into_iter()
                .chain(self.mode_text.clone())
                .collect();
            format!("mode {name}refused: {}", parts.join("; "))
        });
        for (k, (reason, why)) in [
            (arm.clone(), Why::ArmRefused),
            (mode.clone(), Why::ModeRefused),
        ]
        .into_iter()
        .enumerate()
        {
            if reason != self.refusals_said[k] {
                if let Some(reason) = &reason {
                    self.events.push(DriveEvent::Refused {
                        why,
                        reason: reason.clone(),
                    });
                }
                self.refusals_said[k] = reason;
            }
        }
        self.state.why = if !self.state.responsive {
            Why::VehicleSilent
        } else if arm.is_some() {
            Why::ArmRefused
        } else if mode.is_some() {
            Why::ModeRefused
        } else {
            Why::Nothing
        };
    }

    /// Forgets the result reported for `command`: a new request's answer is news.
    fn forget_result(&mut self, command: MavCmd) {
        self.reported.retain(|(c, _)| *c != command);
    }

    /// Takes over what the receiving thread learnt.
    fn absorb(&mut self, now: SimTime) {
        let (autopilot, heard, heartbeat, position, attitude, counts, acks, notes, refused) = {
            let mut inbox = lock(&self.shared.inbox);
            (
                inbox.autopilot,
                inbox.heard,
                inbox.heartbeat,
                inbox.position,
                inbox.attitude,
                [inbox.attitudes, inbox.positions],
                std::mem::take(&mut inbox.acks),
                std::mem::take(&mut inbox.notes),
                inbox.refused,
            )
        };
        for note in &notes {
            if note.contains("Mode change failed") && !self.mode.met {
                self.mode_text = Some(note.clone());
            }
        }
        self.events.extend(notes.into_iter().map(DriveEvent::Note));
        for (k, reason) in Refusal::ALL.into_iter().enumerate() {
            let count = refused[k] - self.refused[k];
            if count > 0 {
                self.events.push(DriveEvent::MessagesRefused {
                    reason: reason.name(),
                    count,
                });
            }
        }
        self.refused = refused;
        if autopilot != self.target {
            self.target = autopilot;
            self.streams = [Stream::new(30), Stream::new(32)];
        }
        let started_at = *self.started_at.get_or_insert(now);
        if heard != self.heard {
            self.heard = heard;
            self.heard_at = Some(now);
            if self.silent {
                self.silent = false;
                self.events.push(DriveEvent::Heard);
            }
        }
        let quiet_s = now.0.saturating_sub(self.heard_at.unwrap_or(started_at).0) as f64 * 1e-9;
        self.state.responsive = self.heard_at.is_some() && quiet_s < self.options.silence_s;
        if !self.state.responsive && !self.silent && quiet_s >= self.options.silence_s {
            self.silent = true;
            self.events.push(DriveEvent::Silent { silent_s: quiet_s });
        }
        if let Some((armed, custom_mode)) = heartbeat {
            self.state.armed = armed;
            self.custom_mode = Some(custom_mode);
            self.state.nav = match nav_of_custom_mode(custom_mode) {
                Some(nav) => nav,
                None => {
                    if self.noted_mode != Some(custom_mode) {
                        self.events.push(DriveEvent::Note(format!(
                            "mavlink: the autopilot is in {} ({custom_mode}), which NAV has no value for: reported as NAV {}",
                            ardusub_mode_name(custom_mode),
                            OTHER_MODE_NAV.bits()
                        )));
                    }
                    OTHER_MODE_NAV
                }
            };
            self.noted_mode = Some(custom_mode);
        }
        if let Some([roll, pitch, yaw, yaw_rate]) = attitude {
            self.have_attitude = true;
            self.state.roll_deg = angle_diff_deg(roll.to_degrees(), 0.0);
            self.state.pitch_deg = angle_diff_deg(pitch.to_degrees(), 0.0);
            self.state.heading_deg = yaw.to_degrees().rem_euclid(360.0);
            self.state.velocity[3] = yaw_rate.to_degrees();
        }
        if counts[1] != self.streams[1].count {
            self.position_at = Some(now);
        }
        self.state.position_known = self
            .position_at
            .is_some_and(|at| now < at.after_secs(POSITION_STALE_S));
        if let Some([x, y, z, vn, ve, vd]) = position {
            self.state.position_m = [x, y, z];
            let psi = self.state.heading_deg.to_radians();
            self.state.velocity[0] = vn * psi.cos() + ve * psi.sin();
            self.state.velocity[1] = -vn * psi.sin() + ve * psi.cos();
            self.state.velocity[2] = vd;
        }
        for (command, result) in acks {
            let accepted = matches!(
                result,
                MavResult::MAV_RESULT_ACCEPTED | MavResult::MAV_RESULT_IN_PROGRESS
            );
            if !accepted && command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM && !self.arm.met {
                self.arm_result = Some(result);
            }
            if !accepted && command == MavCmd::MAV_CMD_DO_SET_MODE && !self.mode.met {
                self.mode_result = Some(result);
            }
            if self.reported.contains(&(command, result)) {
                continue;
            }
            self.forget_result(command);
            self.reported.push((command, result));
            self.events.push(DriveEvent::CommandAck {
                command: format!("{command:?}"),
                result: format!("{result:?}"),
                accepted: matches!(
                    result,
                    MavResult::MAV_RESULT_ACCEPTED | MavResult::MAV_RESULT_IN_PROGRESS
                ),
            });
        }
        if let Some(target) = self.target {
            for (k, count) in counts.into_iter().enumerate() {
                if self.streams[k].wanted(count, now, started_at) {
                    let interval_us = 1e6 / STREAM_HZ;
                    let id = self.streams[k].message_id as f32;
                    self.command(
                        target,
                        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                        [id, interval_us as f32, 0.0],
                    );
                }
            }
        }
    }

    /// The thrust, percent, that the demand's command asks of the sticks (HoldHeading closed
    /// on the reported heading, a GoTo through the built-in model's controller).
    fn thrust_percent(&self, demand: &Demand) -> [f64; 4] {
        let mut model = Vehicle::new(self.state.position_m);
        model.heading_deg = self.state.heading_deg;
        model.heading_hold_deg = demand.heading_hold_deg.filter(|_| self.have_attitude);
        model.thrust_for(demand.command)
    }
}

/// The velocities full thrust stands for in [`DriveState::commanded_velocity`]: the built-in
/// model's (0.5 m/s, 30 degrees/s). The autopilot's real response is its own; these only say
/// what was asked, in the units of the other outputs.
const NOMINAL_FULL: [f64; 4] = [0.5, 0.5, 0.5, 30.0];

impl Drive for MavlinkDrive {
    fn step(&mut self, now: SimTime, dt_s: f64, demand: &Demand) {
        self.absorb(now);
        let slack_s = if dt_s.is_finite() {
            dt_s.max(0.0) / 2.0
        } else {
            0.0
        };
        if self.heartbeat.due(now, slack_s) {
            self.send(&codec::gcs_heartbeat());
        }
        let goto = match demand.command {
            Command::GoTo {
                x,
                y,
                z,
                heading_deg,
            } => Some([x, y, z, heading_deg]),
            Command::Thrust { .. } => None,
        };
        let sticks_live = demand.link_up && goto.is_none();
        let thrust = if sticks_live || goto.is_some() {
            self.thrust_percent(demand)
        } else {
            [0.0; 4]
        };
        self.state.commanded_velocity = [0, 1, 2, 3].map(|k| thrust[k] / 100.0 * NOMINAL_FULL[k]);
        let Some(target) = self.target else {
            self.refusals();
            return; // Nothing to address yet.
        };
        if self.manual.due(now, slack_s) {
            let [x, y, z, r] = if sticks_live {
                manual_control_axes(thrust)
            } else {
                NEUTRAL_AXES
            };
            self.send(&MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
                x,
                y,
                z,
                r,
                buttons: 0,
                target: target.system,
            }));
        }
        let armed = Some(self.state.armed).filter(|_| self.custom_mode.is_some());
        match self.arm.ask(demand.arm, armed, now) {
            Ask::Nothing => {}
            Ask::Send(fresh) => {
                if fresh {
                    self.forget_result(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM);
                    self.arm_result = None;
                }
                self.arm.sent_at = Some(now);
                let param1 = if demand.arm { 1.0 } else { 0.0 };
                self.command(
                    target,
                    MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                    [param1, 0.0, 0.0],
                );
            }
        }
        // A GoTo needs a position: without one the vehicle holds its depth (the ROV engine
        // refuses such GoTos; this covers a drive stepped by other callers).
        let position_known = self.state.position_known;
        let goto = goto.filter(|_| position_known);
        let nav = if goto.is_some() {
            Nav::Guided
        } else if demand.nav == Nav::Guided && !position_known {
            Nav::DepthHold
        } else {
            demand.nav
        };
        if let Some(mode) = demanded_mode(nav, position_known) {
            match self.mode.ask(mode, self.custom_mode, now) {
                Ask::Nothing => {}
                Ask::Send(fresh) => {
                    if fresh {
                        self.forget_result(MavCmd::MAV_CMD_DO_SET_MODE);
                        self.mode_result = None;
                        self.mode_text = None;
                    }
                    self.mode.sent_at = Some(now);
                    let custom = f32::from(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.bits());
                    self.command(
                        target,
                        MavCmd::MAV_CMD_DO_SET_MODE,
                        [custom, mode as f32, 0.0],
                    );
                }
            }
        }
        self.refusals();
        let guided = self.custom_mode == Some(GUIDED);
        let became_guided = guided && !self.was_guided;
        self.was_guided = guided;
        match goto {
            Some(point) if point.iter().all(|v| v.is_finite()) => {
                let due = match self.setpoint {
                    Some((last, at)) => {
                        last != point
                            || became_guided
                            || now >= at.after_secs(SETPOINT_RESEND_S - slack_s)
                    }
                    None => true,
                };
                if due {
                    self.setpoint = Some((point, now));
                    let [x, y, z, heading_deg] = point;
                    let ignore = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
                        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
                        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE
                        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
                        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
                        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
                        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE;
                    self.send(&MavMessage::SET_POSITION_TARGET_LOCAL_NED(
                        SET_POSITION_TARGET_LOCAL_NED_DATA {
                            time_boot_ms: (now.0 / 1_000_000) as u32,
                            x: x as f32,
                            y: y as f32,
                            z: z as f32,
                            yaw: angle_diff_deg(heading_deg, 0.0).to_radians() as f32,
                            type_mask: ignore,
                            target_system: target.system,
                            target_component: target.component,
                            coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
                            ..SET_POSITION_TARGET_LOCAL_NED_DATA::DEFAULT
                        },
                    ));
                }
            }
            _ => self.setpoint = None,
        }
    }

    fn state(&self) -> DriveState {
        self.state
    }

    fn arrival_m(&self) -> f64 {
        self.options.arrival_m
    }

    fn arrival_deg(&self) -> f64 {
        self.options.arrival_deg
    }

    fn take_events(&mut self) -> Vec<DriveEvent> {
        std::mem::take(&mut self.events)
    }

    fn needs_hold(&self) -> bool {
        // ArduSub in a stick mode with neutral sticks keeps its depth (ALT_HOLD) but not its
        // place: the hold is GUIDED at the setpoint.
        true
    }
}

impl Drop for MavlinkDrive {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            // The thread looks at the flag after each read timeout (or reconnect attempt).
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_endpoint_form_of_the_device_grammar_is_an_autopilot_endpoint() {
        // The grammar itself is device.rs's; here, which forms an autopilot takes, aliases too.
        for (text, canonical) in [
            ("udpin:0.0.0.0:14550", "udpin:0.0.0.0:14550"),
            ("udp:0.0.0.0:14550", "udpin:0.0.0.0:14550"),
            ("udpout:192.168.2.2:14551", "udpout:192.168.2.2:14551"),
            (
                "udp:0.0.0.0:14550=127.0.0.1:14551",
                "udp:0.0.0.0:14550=127.0.0.1:14551",
            ),
            ("tcpout:localhost:5760", "tcp:localhost:5760"),
            ("tcp:127.0.0.1:5760", "tcp:127.0.0.1:5760"),
            ("tcpin:[::1]:5761", "tcpin:[::1]:5761"),
            ("serial:/dev/ttyACM0:115200", "serial:/dev/ttyACM0:115200"),
        ] {
            let parsed = parse_endpoint(text).unwrap();
            assert_eq!(parsed.to_string(), canonical, "{text}");
        }
    }

    #[test]
    fn bad_endpoints_say_what_is_wrong() {
        let cases = [
            (
                "14550",
                "a serial autopilot needs its baud rate), found '14550'",
            ),
            ("/dev/ttyACM0", "expected udpin:HOST:PORT"),
            ("pty", "found 'pty'"),
            ("udpin:14550", "expected HOST:PORT, found '14550'"),
            ("udpin::14550", "found no host"),
            (
                "udpout:host:port",
                "expected a port number 0..=65535 after the host, found 'port'",
            ),
            ("tcpout:127.0.0.1:0", "expected a port to connect to"),
            ("tcpout:::1:5760", "an IPv6 host in brackets"),
            ("serial:/dev/ttyACM0", "expected serial:PATH:BAUD"),
            ("serial::115200", "expected a device path"),
            ("serial:/dev/ttyACM0:fast", "found 'fast'"),
            ("file:log.tlog", "no device kind 'file'"),
        ];
        for (text, part) in cases {
            let error = parse_endpoint(text).unwrap_err().to_string();
            assert!(
                error.starts_with(&format!("mavlink endpoint '{text}': ")),
                "{error}"
            );
            assert!(error.contains(part), "{text}: {error}");
            assert!(!error.contains('\n'), "{error}");
        }
    }

    #[test]
    fn modes_map_both_ways() {
        for (mode, nav) in [
            (19, Nav::Manual),
            (0, Nav::Stabilize),
            (2, Nav::DepthHold),
            (16, Nav::HoldPosition),
            (4, Nav::Guided),
        ] {
            assert_eq!(nav_of_custom_mode(mode), Some(nav));
            assert_eq!(custom_mode_of(nav), Some(mode));
        }
        for other in [1, 3, 7, 9, 20, 21, 99] {
            assert_eq!(nav_of_custom_mode(other), None, "{other}");
        }
        for reserved in 5..8 {
            assert_eq!(custom_mode_of(Nav::Unknown(reserved)), None);
        }
        assert_eq!(ardusub_mode_name(9), "SURFACE");
        assert_eq!(ardusub_mode_name(12), "mode 12");
        assert_eq!(OTHER_MODE_NAV.bits(), 5);
    }

    #[test]
    fn sticks_scale_as_ardusub_reads_them() {
        assert_eq!(manual_control_axes([0.0; 4]), NEUTRAL_AXES);
        // Half surge forward: x 500; full sway starboard; full yaw anticlockwise.
        assert_eq!(
            manual_control_axes([50.0, 100.0, 0.0, -100.0]),
            [500, 1000, 500, -1000]
        );
        // Heave down (positive in NED) lowers ArduSub's throttle z below 500.
        assert_eq!(manual_control_axes([0.0, 0.0, 100.0, 0.0]), [0, 0, 0, 0]);
        assert_eq!(
            manual_control_axes([0.0, 0.0, -100.0, 0.0]),
            [0, 0, 1000, 0]
        );
        assert_eq!(manual_control_axes([0.0, 0.0, 50.4, 0.0])[2], 248);
        // Out of range and not-a-number.
        assert_eq!(
            manual_control_axes([250.0, -1e9, f64::NAN, f64::INFINITY]),
            [1000, -1000, 500, 1000]
        );
    }

    #[test]
    fn ticker_keeps_its_grid_through_jitter() {
        let mut tick = Ticker::new(0.1);
        let mut sent = 0;
        // Steps every 0.1 s with +-30 ms of jitter: one send per step.
        for k in 0..100u64 {
            let jitter_ms = [0i64, 30, -30, 10][(k % 4) as usize];
            let t_ns = (k as i64 * 100 + 1000 + jitter_ms) as u64 * 1_000_000;
            if tick.due(SimTime(t_ns), 0.05) {
                sent += 1;
            }
        }
        assert_eq!(sent, 100);
        // A 1 Hz ticker stepped at 10 Hz sends every tenth step.
        let mut slow = Ticker::new(1.0);
        let due: Vec<u64> = (0..35u64)
            .filter(|k| slow.due(SimTime(k * 100_000_000), 0.05))
            .collect();
        assert_eq!(due, [0, 10, 20, 30]);
        // After a gap it restarts from the step, not with a burst.
        assert!(slow.due(SimTime::from_secs_f64(10.0), 0.05));
        assert!(!slow.due(SimTime::from_secs_f64(10.1), 0.05));
    }

    #[test]
    fn a_request_is_retried_until_met_then_left_alone() {
        let t = SimTime::from_secs_f64;
        let mut arm: Request<bool> = Request::default();
        // Met at once: nothing to send.
        assert_eq!(arm.ask(false, Some(false), t(0.0)), Ask::Nothing);
        // The demand changes: send, then retry every COMMAND_RETRY_S while it differs.
        assert_eq!(arm.ask(true, Some(false), t(1.0)), Ask::Send(true));
        arm.sent_at = Some(t(1.0));
        assert_eq!(arm.ask(true, Some(false), t(2.0)), Ask::Nothing);
        assert_eq!(arm.ask(true, Some(false), t(2.5)), Ask::Send(false));
        arm.sent_at = Some(t(2.5));
        assert_eq!(arm.ask(true, Some(true), t(3.0)), Ask::Nothing);
        // Met: a disarm from elsewhere (a failsafe) is not fought.
        assert_eq!(arm.ask(true, Some(false), t(9.0)), Ask::Nothing);
        // Unknown state: ask.
        let mut mode: Request<u32> = Request::default();
        assert_eq!(mode.ask(4, None, t(0.0)), Ask::Send(true));
    }

    #[test]
    fn a_missing_stream_is_asked_for_at_most_every_ten_seconds() {
        let t = SimTime::from_secs_f64;
        let mut stream = Stream::new(32);
        assert!(stream.wanted(0, t(0.0), t(0.0)));
        assert!(!stream.wanted(0, t(5.0), t(0.0)));
        assert!(stream.wanted(0, t(10.0), t(0.0)));
        // Arriving: not asked for again while it flows.
        assert!(!stream.wanted(1, t(10.5), t(0.0)));
        assert!(!stream.wanted(50, t(25.0), t(0.0)));
        // Stops for more than STREAM_MISSING_S: asked for again.
        assert!(stream.wanted(50, t(27.5), t(0.0)));
    }

    #[test]
    fn bad_options_are_refused() {
        for options in [
            MavlinkOptions {
                heartbeat_hz: 0.0,
                ..MavlinkOptions::default()
            },
            MavlinkOptions {
                silence_s: f64::NAN,
                ..MavlinkOptions::default()
            },
            MavlinkOptions {
                system_id: 0,
                ..MavlinkOptions::default()
            },
        ] {
            let error = connect("udpin:127.0.0.1:0", &options)
                .err()
                .unwrap()
                .to_string();
            assert!(error.starts_with("mavlink options: "), "{error}");
        }
    }

    #[test]
    fn endpoints_that_cannot_be_opened_are_errors() {
        let options = MavlinkOptions::default();
        let serial = connect("serial:/dev/nonexistent:115200", &options)
            .err()
            .unwrap();
        assert!(
            serial
                .to_string()
                .starts_with("mavlink endpoint 'serial:/dev/nonexistent:115200': cannot open: "),
            "{serial}"
        );
        // A port in use: bind fails.
        let taken = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let port = taken.local_addr().unwrap().port();
        let text = format!("udpin:127.0.0.1:{port}");
        let error = connect(&text, &options).err().unwrap().to_string();
        assert!(
            error.starts_with(&format!("mavlink endpoint '{text}': cannot bind: ")),
            "{error}"
        );
        // TCP refused: a port just released has nobody listening.
        let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = closed.local_addr().unwrap().port();
        drop(closed);
        let text = format!("tcpout:127.0.0.1:{port}");
        let error = connect(&text, &options).err().unwrap().to_string();
        assert!(
            error.starts_with(&format!("mavlink endpoint '{text}': cannot connect: ")),
            "{error}"
        );
    }

    #[test]
    fn an_absent_autopilot_is_silence_and_the_drive_stops_promptly() {
        let mut drive = connect("udpin:127.0.0.1:0", &MavlinkOptions::default()).unwrap();
        let demand = Demand {
            command: Command::Thrust {
                surge: 50.0,
                sway: 0.0,
                heave: 0.0,
                yaw: 0.0,
            },
            arm: true,
            nav: Nav::Manual,
            heading_hold_deg: None,
            link_up: true,
        };
        let mut events = Vec::new();
        for k in 0..40u64 {
            drive.step(SimTime(k * 100_000_000), 0.1, &demand);
            events.extend(drive.take_events());
        }
        assert!(!drive.state().responsive);
        assert_eq!(events.len(), 1, "{events:?}");
        assert!(
            matches!(events[0], DriveEvent::Silent { silent_s } if (silent_s - 3.0).abs() < 1e-9)
        );
        assert_eq!(drive.autopilot(), None);
        // Commanded velocity follows the demand even with nobody to send it to.
        assert!((drive.state().commanded_velocity[0] - 0.25).abs() < 1e-9);
        let started = std::time::Instant::now();
        drop(drive);
        assert!(started.elapsed() < Duration::from_millis(500));
    }

    proptest::proptest! {
        #[test]
        fn parsing_never_panics(text in "\\PC{0,40}") {
            let _ = parse_endpoint(&text);
        }
    }
}
