//! A whole teleoperation session in virtual time: operator, link and ROV in one process.
//!
//! The operator is side A of a [`Link`], the ROV side B. The loop takes the earliest of: a link
//! event, the operator's next slot, the ROV's next vehicle step, the next scripted joystick
//! change or waypoint; the ROV answers a delivered operator frame at the instant it arrives. The
//! ROV's distance to the buoy (the operator's modem) sets the link's distance at every vehicle
//! step, so the range model cuts the link when the vehicle strays.

use std::sync::atomic::{AtomicBool, Ordering};

use serde::Serialize;

use std::collections::HashMap;

use super::harness::{OperatorEnd, Out, RovEnd, Tally};
use super::operator::{Joystick, SlotContent};
use super::rov::{Rov, RovConfig};
use super::rules;
use super::{Event, ImageSettings, PoseSample};
use crate::debt;
use crate::link::{Distance, Fate, Link, Model, ModelError, Report, Side, SimTime};
use crate::stats::Running;
use crate::wire::frame::Frame;
use crate::wire::{Message, MessageRepr};

/// A GoTo order sent at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoint {
    /// When the operator queues it, s.
    pub t_s: f64,
    /// Target, NED m.
    pub position_m: [f64; 3],
    /// Heading, degrees.
    pub heading_deg: f64,
}

/// A joystick change at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JoystickChange {
    /// When, s.
    pub t_s: f64,
    /// The new state.
    pub joystick: Joystick,
}

/// Everything a simulated session needs.
#[derive(Debug, Clone)]
pub struct SessionConfig {
    /// The link model (both directions).
    pub model: Model,
    /// Seed of the link's random streams.
    pub seed: u64,
    /// Inter-packet gap, s.
    pub ipg_s: f64,
    /// Length of the session, s.
    pub duration_s: f64,
    /// The operator modem's position, NED m.
    pub buoy_m: [f64; 3],
    /// The ROV's initial position, NED m.
    pub start_m: [f64; 3],
    /// Joystick changes, sorted by time.
    pub script: Vec<JoystickChange>,
    /// GoTo orders, sorted by time.
    pub waypoints: Vec<Waypoint>,
    /// Image settings at the start.
    pub settings: ImageSettings,
    /// The camera's pictures, cycled.
    pub images: Vec<debt::Image>,
}

/// The shortest inter-packet gap, s (a slot shorter than a millisecond carries no frame).
pub const MIN_IPG_S: f64 = 1e-3;
/// The longest inter-packet gap, s (10 minutes).
pub const MAX_IPG_S: f64 = 600.0;
/// The longest session, s (a week).
pub const MAX_DURATION_S: f64 = 7.0 * 86_400.0;
/// The farthest a buoy or a start position may be from the site's origin along any axis, m: no
/// real site is 100 km across.
pub const MAX_POSITION_M: f64 = 100_000.0;
/// The farthest a waypoint may be along any axis, m: what a GoTo order carries (i16 cm).
pub const MAX_WAYPOINT_M: f64 = 327.67;
/// The smallest encoded image, bytes.
pub const MIN_IMAGE_BYTES: u16 = 16;

/// A session setting out of its range: `what`, what it must be, what it is.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{what}: expected {expected}, found {found}")]
pub struct ConfigError {
    /// The setting, e.g. `IPG` or `waypoint 3`.
    pub what: String,
    /// Its range, with units.
    pub expected: String,
    /// The value given, with units.
    pub found: String,
}

fn out_of_range(
    what: impl Into<String>,
    expected: impl Into<String>,
    found: String,
) -> ConfigError {
    ConfigError {
        what: what.into(),
        expected: expected.into(),
        found,
    }
}

/// A number as a user would write it: `1e300`, not 301 digits.
fn number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e15).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Checks a position: finite, at most `limit_m` from the origin along each axis.
fn check_position(
    what: impl Into<String>,
    position_m: [f64; 3],
    limit_m: f64,
) -> Result<(), ConfigError> {
    if position_m
        .iter()
        .all(|v| v.is_finite() && v.abs() <= limit_m)
    {
        return Ok(());
    }
    let [x, y, z] = position_m;
    Err(out_of_range(
        what,
        format!("X,Y,Z each in -{limit_m} m ..= {limit_m} m"),
        format!("{},{},{} m", number(x), number(y), number(z)),
    ))
}

/// Checks a scripted time: finite, 0 ..= [`MAX_DURATION_S`], not before the previous one.
fn check_time(what: impl Into<String>, t_s: f64, previous_s: f64) -> Result<(), ConfigError> {
    if t_s.is_finite() && (0.0..=MAX_DURATION_S).contains(&t_s) && t_s >= previous_s {
        return Ok(());
    }
    Err(out_of_range(
        what,
        format!("a time in {previous_s} s ..= {MAX_DURATION_S} s (sorted)"),
        format!("{} s", number(t_s)),
    ))
}

impl JoystickChange {
    /// Checks the time (0 ..= a week) and each axis (-100 % ..= 100 %); `what` names it.
    pub fn check(&self, what: impl Into<String>) -> Result<(), ConfigError> {
        let what = what.into();
        check_time(what.clone(), self.t_s, 0.0)?;
        let j = self.joystick;
        for v in [j.vx, j.vy, j.vz, j.vyaw] {
            if !(v.is_finite() && v.abs() <= 100.0) {
                return Err(out_of_range(
                    what,
                    "vx,vy,vz,vyaw each in -100 % ..= 100 % of full thrust",
                    format!("{} %", number(v)),
                ));
            }
        }
        Ok(())
    }
}

impl Waypoint {
    /// Checks the time (0 ..= a week), the target (within a GoTo order's
    /// ±[`MAX_WAYPOINT_M`]) and the heading (finite); `what` names it.
    pub fn check(&self, what: impl Into<String>) -> Result<(), ConfigError> {
        let what = what.into();
        check_time(what.clone(), self.t_s, 0.0)?;
        check_position(what.clone(), self.position_m, MAX_WAYPOINT_M)?;
        if !self.heading_deg.is_finite() {
            return Err(out_of_range(
                what,
                "a finite heading in degrees",
                format!("{} degrees", self.heading_deg),
            ));
        }
        Ok(())
    }
}

impl SessionConfig {
    /// Checks every setting against its range; the first one out of range is the error. The
    /// model is checked when the link is built.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.duration_s.is_finite()
            && self.duration_s > 0.0
            && self.duration_s <= MAX_DURATION_S)
        {
            return Err(out_of_range(
                "duration",
                format!("more than 0 s, at most {MAX_DURATION_S} s (a week)"),
                format!("{} s", number(self.duration_s)),
            ));
        }
        check_position("buoy position", self.buoy_m, MAX_POSITION_M)?;
        check_position("start position", self.start_m, MAX_POSITION_M)?;
        if !(self.ipg_s.is_finite() && (MIN_IPG_S..=MAX_IPG_S).contains(&self.ipg_s)) {
            return Err(out_of_range(
                "IPG",
                "1 ms ..= 10 min",
                format!("{} ms", number(self.ipg_s * 1e3)),
            ));
        }
        let mut previous_s = 0.0;
        for (k, change) in self.script.iter().enumerate() {
            let what = format!("joystick change {}", k + 1);
            check_time(what.clone(), change.t_s, previous_s)?;
            previous_s = change.t_s;
            change.check(what)?;
        }
        let mut previous_s = 0.0;
        for (k, waypoint) in self.waypoints.iter().enumerate() {
            let what = format!("waypoint {}", k + 1);
            check_time(what.clone(), waypoint.t_s, previous_s)?;
            previous_s = waypoint.t_s;
            waypoint.check(what)?;
        }
        let settings = &self.settings;
        let max_trunk = crate::wire::rov::MAX_TRUNK_BYTES;
        if settings.trunk_bytes == 0 || usize::from(settings.trunk_bytes) > max_trunk {
            return Err(out_of_range(
                "trunk size",
                format!("1 ..= {max_trunk} bytes (what a ROV frame carries)"),
                format!("{} bytes", settings.trunk_bytes),
            ));
        }
        if settings.size_bytes < MIN_IMAGE_BYTES {
            return Err(out_of_range(
                "image size",
                format!("{MIN_IMAGE_BYTES} ..= 65535 bytes"),
                format!("{} bytes", settings.size_bytes),
            ));
        }
        for (k, image) in self.images.iter().enumerate() {
            let side = debt::MAX_SIDE;
            if image.width == 0
                || image.height == 0
                || image.width > side
                || image.height > side
                || image.data.len() != image.width * image.height * image.channels
            {
                return Err(out_of_range(
                    format!("camera picture {}", k + 1),
                    format!("1x1 ..= {side}x{side} pixels (what DEBT holds)"),
                    format!("{}x{} pixels", image.width, image.height),
                ));
            }
        }
        Ok(())
    }
}

/// The IPG wire.md derives from a model for a session, the one-hop case of a network's slot
/// ([`rules::hop_s`] out, its guard, and back): the operator's frame, the ROV's frame with a
/// trunk of `settings.trunk_bytes`, at the distance between `start_m` and `buoy_m`.
pub fn auto_ipg_for(
    model: &Model,
    settings: &ImageSettings,
    start_m: [f64; 3],
    buoy_m: [f64; 3],
) -> f64 {
    let distance_m = crate::geometry::distance_m(start_m, buoy_m);
    let rov_frame_bytes = rules::rov_frame_bytes(settings.trunk_bytes);
    rules::hop_s(model, rules::OPERATOR_FRAME_BYTES, distance_m)
        + rules::guard_s(model)
        + rules::hop_s(model, rov_frame_bytes, distance_m)
}

/// One direction's figures.
#[derive(Debug, Clone, Default, Serialize)]
pub struct DirectionMetrics {
    /// Bits of delivered frames per second, kbit/s.
    pub throughput_kbps: f64,
    /// Mean delay (arrival minus send), ms; none where one end cannot know it (real time).
    pub delay_ms: Option<f64>,
    /// Standard deviation of the delay, ms; none where the delay is unknown.
    pub jitter_ms: Option<f64>,
    /// Mean time between consecutive deliveries, ms.
    pub iat_ms: f64,
    /// Standard deviation of that time, ms.
    pub iat_sigma_ms: f64,
    /// Frames sent.
    pub frames_sent: u64,
    /// Frames delivered intact.
    pub frames_delivered: u64,
}

/// The session's figures (`--metrics`).
#[derive(Debug, Clone, Default, Serialize)]
pub struct Metrics {
    /// Whose figures: `simulation` (both ends, every field), or in real time `operator` or
    /// `rov` (one end: the frames it sent and those it received; the far end's halves are 0).
    pub measured_by: &'static str,
    /// ROV to operator.
    pub rov_to_operator: DirectionMetrics,
    /// Operator to ROV.
    pub operator_to_rov: DirectionMetrics,
    /// Images the ROV started sending (simulation, or the ROV end in real time).
    pub images_started: u64,
    /// Images the operator completed.
    pub images_completed: u64,
    /// Mean time between completed images, s.
    pub image_period_s: Option<f64>,
    /// High-level orders queued by the operator.
    pub orders_sent: u64,
    /// Of those, acknowledged by the ROV's EOID.
    pub orders_acknowledged: u64,
    /// Orders the ROV executed.
    pub orders_executed: u64,
    /// Executions of an order already executed (must be 0).
    pub orders_executed_twice: u64,
    /// Orders acknowledged that the ROV had not executed (must be 0).
    pub orders_acknowledged_unexecuted: u64,
    /// Times the ROV lost the heartbeat.
    pub link_losses: u64,
    /// Times it came back.
    pub link_recoveries: u64,
    /// Orders or demands that could not run (absent when none): the ROV counts each refusal
    /// it reported (a GoTo or backtracking without a position estimate, an arm or a mode the
    /// vehicle refused); the operator counts each status whose WHY turned to a reason.
    #[serde(skip_serializing_if = "is_zero")]
    pub refusals: u64,
    /// Operator: statuses that said the vehicle has no position estimate (absent when none).
    #[serde(skip_serializing_if = "is_zero")]
    pub statuses_without_position: u64,
    /// Real time, operator: mean time from a slot's frame to the ROV's answer, ms.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub round_trip_ms: Option<f64>,
    /// Real time, operator: standard deviation of that time, ms.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub round_trip_jitter_ms: Option<f64>,
    /// Session length, s: the time reached when the run was interrupted.
    pub duration_s: f64,
    /// Why the run ended early (e.g. `SIGTERM`); absent when it ran its whole duration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interrupted: Option<String>,
}

fn is_zero(value: &u64) -> bool {
    *value == 0
}

/// What [`run`] says when `stop` ended it, until the caller names the cause.
pub const STOPPED: &str = "stopped";

/// One frame's row of `--events` (the data of the paper's Fig. 10).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameEvent {
    /// `operator_to_rov` or `rov_to_operator`.
    pub direction: &'static str,
    /// velocity, goto, image_settings, hold_heading (operator); image_trunk or status (ROV).
    pub kind: &'static str,
    /// Frame length.
    pub bytes: usize,
    /// When it was sent, s (none for a frame received in real time: its send time is the far
    /// end's).
    pub t_sent_s: Option<f64>,
    /// When it arrived, s (none when lost).
    pub t_received_s: Option<f64>,
    /// The link's fate for it.
    pub fate: &'static str,
}

/// What happened along the way, for outputs beyond the metrics.
pub trait Observer {
    /// A frame's fate is known.
    fn frame(&mut self, _event: &FrameEvent) {}
    /// The operator completed an image (its DEBT stream) at `t_s`.
    fn image(&mut self, _t_s: f64, _stream: &[u8]) {}
    /// The vehicle after a step (the ROV's side), or as the last status reported it (an
    /// operator in real time).
    fn pose(&mut self, _pose: &PoseSample) {}
    /// Something happened at `end`, at `t_s` (orders, images in progress, statuses, the link
    /// and the vehicle): what `--telemetry` and a live Foxglove view show.
    fn event(&mut self, _end: super::Role, _t_s: f64, _event: &Event) {}
    /// Something to tell the user at `t_s` (an order source's bad line): one line.
    fn warning(&mut self, _t_s: f64, _text: &str) {}
    /// True once the observer can record nothing more (an output failed): the run ends at the
    /// next event, as if stopped.
    fn failed(&self) -> bool {
        false
    }
}

/// An observer that observes nothing.
pub struct Quiet;

impl Observer for Quiet {}

/// One direction's running figures.
#[derive(Default)]
pub(crate) struct Direction {
    delay_ms: Running,
    iat_ms: Running,
    last_delivery: Option<SimTime>,
    sent: u64,
    delivered: u64,
    bits: u64,
}

impl Direction {
    /// A frame went out.
    pub(crate) fn sent(&mut self) {
        self.sent += 1;
    }

    /// A frame of `len` bytes arrived intact at `t_rx`, `delay_ms` after it was sent if known.
    pub(crate) fn delivered(&mut self, t_rx: SimTime, len: usize, delay_ms: Option<f64>) {
        self.delivered += 1;
        self.bits += len as u64 * 8;
        if let Some(delay) = delay_ms {
            self.delay_ms.push(delay);
        }
        if let Some(last) = self.last_delivery {
            self.iat_ms
                .push((t_rx.0.saturating_sub(last.0)) as f64 * 1e-6);
        }
        self.last_delivery = Some(t_rx);
    }

    fn record(&mut self, report: &Report) {
        if report.duplicate {
            return;
        }
        self.sent();
        if let (Fate::Delivered, Some(t_rx)) = (report.fate, report.t_rx) {
            let delay_ms = (t_rx.0 - report.t_offered.0) as f64 * 1e-6;
            self.delivered(t_rx, report.len, Some(delay_ms));
        }
    }

    pub(crate) fn metrics(&self, duration_s: f64) -> DirectionMetrics {
        let known = self.delay_ms.count() > 0;
        DirectionMetrics {
            throughput_kbps: if duration_s > 0.0 {
                self.bits as f64 / duration_s / 1000.0
            } else {
                0.0
            },
            delay_ms: known.then(|| self.delay_ms.mean()),
            jitter_ms: known.then(|| self.delay_ms.std()),
            iat_ms: self.iat_ms.mean(),
            iat_sigma_ms: self.iat_ms.std(),
            frames_sent: self.sent,
            frames_delivered: self.delivered,
        }
    }
}

/// The mean time between completed images, s.
pub(crate) fn image_period_s(image_times_s: &[f64]) -> Option<f64> {
    let n = image_times_s.len();
    (n > 1).then(|| (image_times_s[n - 1] - image_times_s[0]) / (n - 1) as f64)
}

/// What a frame is, for the events table.
pub(crate) fn kind_of(bytes: &[u8]) -> &'static str {
    let parsed = Frame::new_checked(bytes)
        .ok()
        .and_then(|f| MessageRepr::parse(&f).ok());
    match parsed.map(|r| r.message) {
        Some(Message::Operator(op)) => op.order.name(),
        Some(Message::Rov(rov)) if !rov.trunk.is_empty() => "image_trunk",
        Some(Message::Rov(_)) => "status",
        _ => "raw",
    }
}

/// Why a session could not run.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// A setting out of its range.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The link model is invalid.
    #[error(transparent)]
    Model(#[from] ModelError),
}

/// The ends a session runs beyond what its [`SessionConfig`] says: where the operator's
/// orders come from and what moves the ROV and takes its pictures.
pub struct Parts {
    /// The operator's order sources, drained in turn (the config's script comes first when
    /// built by [`Parts::from_config`]).
    pub orders: Vec<Box<dyn super::orders::OrderSource>>,
    /// What moves the vehicle.
    pub drive: Box<dyn super::drive::Drive>,
    /// The camera.
    pub camera: Box<dyn super::camera::Camera>,
}

impl Parts {
    /// The config's own: its script and waypoints, the built-in vehicle at its start, its
    /// pictures cycled.
    pub fn from_config(config: &SessionConfig) -> Parts {
        Parts {
            orders: vec![Box::new(super::orders::Script::new(
                &config.script,
                &config.waypoints,
            ))],
            drive: Box::new(super::drive::SimDrive::new(config.start_m)),
            camera: Box::new(super::camera::Cycle::new(config.images.clone())),
        }
    }

    /// The two ends these parts make for `config`.
    pub(crate) fn ends(self, config: &SessionConfig) -> (OperatorEnd, RovEnd) {
        let timeout_s = rules::link_timeout_s(config.ipg_s);
        let rov_config = RovConfig {
            settings: config.settings,
            heartbeat_timeout_s: timeout_s,
            ..RovConfig::default()
        };
        let mut operator = OperatorEnd::new(rov_config.address, config.ipg_s, self.orders);
        operator.answers_timeout_s = timeout_s;
        (
            operator,
            RovEnd::new(Rov::with(rov_config, self.drive, self.camera)),
        )
    }
}

/// Runs a session after [`SessionConfig::validate`] with the config's own [`Parts`];
/// see [`run_with`].
pub fn run(
    config: &SessionConfig,
    observer: &mut dyn Observer,
    stop: &AtomicBool,
) -> Result<Metrics, SessionError> {
    run_with(config, Parts::from_config(config), observer, stop)
}

/// Runs a session after [`SessionConfig::validate`]; `observer` sees frames, images, poses and
/// events as they happen. `stop` is checked at every event: once set, the run ends there, and
/// the metrics cover the virtual time reached, with `interrupted` set to [`STOPPED`]. The run
/// also ends early once the observer has [`failed`](Observer::failed).
pub fn run_with(
    config: &SessionConfig,
    parts: Parts,
    observer: &mut dyn Observer,
    stop: &AtomicBool,
) -> Result<Metrics, SessionError> {
    config.validate()?;
    let mut link = Link::symmetric(config.model.clone(), config.seed, Distance::Fixed(1.0))?;
    let (mut operator, mut rov) = parts.ends(config);
    link.set_distance(rov.engine.state().distance_to(config.buoy_m));
    let end = SimTime::from_secs_f64(config.duration_s);
    let mut directions = [Direction::default(), Direction::default()];
    let mut slot_orders: HashMap<u64, u64> = HashMap::new();
    let mut tally = Tally::new(true);
    // What each frame in flight is, by (sender, link sequence number): a lost frame's report
    // no longer has its bytes.
    let mut kinds: HashMap<(Side, u64), &'static str> = HashMap::new();
    let (mut interrupted_at, mut failed_at) = (None, None);

    loop {
        let candidates = [
            link.next_event_time(),
            Some(operator.next_at()),
            Some(rov.next_at()),
        ];
        let Some(t) = candidates.iter().flatten().min().copied() else {
            break;
        };
        if t > end {
            break;
        }
        if stop.load(Ordering::Relaxed) {
            interrupted_at = Some(link.now());
            break;
        }
        if observer.failed() {
            failed_at = Some(link.now());
            break;
        }
        let mut out = Out {
            tally: &mut tally,
            observer: &mut *observer,
        };
        if link.next_event_time() == Some(t) {
            link.step();
            while let Some(report) = link.pop_report() {
                let from_operator = report.from == Side::A;
                directions[usize::from(!from_operator)].record(&report);
                let kind = if report.duplicate {
                    kinds.get(&(report.from, report.seq)).copied()
                } else {
                    kinds.remove(&(report.from, report.seq))
                };
                let event = FrameEvent {
                    direction: if from_operator {
                        "operator_to_rov"
                    } else {
                        "rov_to_operator"
                    },
                    kind: kind.unwrap_or("raw"),
                    bytes: report.len,
                    t_sent_s: Some(report.t_offered.as_secs_f64()),
                    t_received_s: report.t_rx.map(SimTime::as_secs_f64),
                    fate: report.fate.as_str(),
                };
                out.observer.frame(&event);
                // The order a slot carried is forgotten at its first report, whatever its fate
                // (a lost slot's entry would otherwise stay for the whole session).
                let order = if from_operator && !report.duplicate {
                    slot_orders.remove(&report.seq)
                } else {
                    None
                };
                if report.fate != Fate::Delivered {
                    continue;
                }
                if from_operator {
                    if let Some(reply) = rov.receive(link.now(), &report.bytes, order, &mut out) {
                        let kind = kind_of(&reply);
                        let seq = link.offer(Side::B, reply);
                        kinds.insert((Side::B, seq), kind);
                    }
                } else {
                    operator.receive(link.now(), &report.bytes, &mut out);
                }
            }
            continue;
        }
        link.advance(t);
        if operator.next_at() == t {
            if let Some((frame, content)) = operator.poll(t, &mut out) {
                let kind = kind_of(&frame);
                let seq = link.offer(Side::A, frame);
                kinds.insert((Side::A, seq), kind);
                if let SlotContent::Order(index) = content {
                    slot_orders.insert(seq, index);
                }
            }
            continue;
        }
        if rov.next_at() == t {
            rov.poll(t, &mut out);
            link.set_distance(rov.engine.state().distance_to(config.buoy_m));
        }
    }
    let duration_s = interrupted_at
        .or(failed_at)
        .map_or(config.duration_s, SimTime::as_secs_f64);
    let mut metrics = tally.finish("simulation", duration_s);
    if interrupted_at.is_some() {
        metrics.interrupted = Some(STOPPED.to_string());
    }
    metrics.operator_to_rov = directions[0].metrics(duration_s);
    metrics.rov_to_operator = directions[1].metrics(duration_s);
    Ok(metrics)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::model::JitterDistribution;

    fn config(model: Model, duration_s: f64) -> SessionConfig {
        SessionConfig {
            model,
            seed: 1,
            ipg_s: 0.64,
            duration_s,
            buoy_m: [0.0; 3],
            start_m: [1.0, 0.0, 0.0],
            script: Vec::new(),
            waypoints: Vec::new(),
            settings: ImageSettings::default(),
            images: vec![super::super::test_image(160, 120, 1)],
        }
    }

    #[derive(Default)]
    struct Images(Vec<f64>);

    impl Observer for Images {
        fn image(&mut self, t_s: f64, _stream: &[u8]) {
            self.0.push(t_s);
        }
    }

    #[test]
    fn without_loss_an_image_takes_exactly_its_trunk_count_in_slots() {
        let mut model = Model::preset("s100").unwrap();
        model.jitter_distribution = JitterDistribution::None;
        let mut images = Images::default();
        let metrics = run(&config(model, 200.0), &mut images, &AtomicBool::new(false)).unwrap();
        // 2000 bytes rounded up to 52 trunks of 39 bytes, one per 0.64 s slot.
        let trunks = 2000usize.div_ceil(39);
        assert_eq!(trunks, 52);
        assert!(images.0.len() >= 4, "{:?}", images.0);
        for pair in images.0.windows(2) {
            assert!(
                (pair[1] - pair[0] - trunks as f64 * 0.64).abs() < 1e-6,
                "{pair:?}"
            );
        }
        assert_eq!(
            metrics.operator_to_rov.frames_delivered,
            metrics.operator_to_rov.frames_sent
        );
    }

    #[test]
    fn s100_session_matches_table_4_at_ber_0() {
        let metrics = run(
            &config(Model::preset("s100").unwrap(), 600.0),
            &mut Quiet,
            &AtomicBool::new(false),
        )
        .unwrap();
        let (r, o) = (&metrics.rov_to_operator, &metrics.operator_to_rov);
        assert!((r.throughput_kbps / 0.72 - 1.0).abs() < 0.05, "{r:?}");
        assert!((o.throughput_kbps / 0.2 - 1.0).abs() < 0.05, "{o:?}");
        assert!((r.delay_ms.unwrap() / 333.17 - 1.0).abs() < 0.05, "{r:?}");
        assert!((o.delay_ms.unwrap() / 158.99 - 1.0).abs() < 0.05, "{o:?}");
        assert!((r.iat_ms / 640.21 - 1.0).abs() < 0.05, "{r:?}");
        assert!((o.iat_ms / 640.36 - 1.0).abs() < 0.05, "{o:?}");
    }

    #[test]
    fn orders_survive_heavy_loss_exactly_once_and_images_complete() {
        for seed in 1..=12 {
            let mut model = Model::preset("s100").unwrap();
            model.loss_percent = 20.0;
            let mut cfg = config(model, 240.0);
            cfg.seed = seed;
            cfg.waypoints = (0..30)
                .map(|k| Waypoint {
                    t_s: 2.0 + k as f64 * 7.0,
                    position_m: [1.0 + (k % 3) as f64, (k % 2) as f64, 0.5],
                    heading_deg: (k * 40) as f64,
                })
                .collect();
            let metrics = run(&cfg, &mut Quiet, &AtomicBool::new(false)).unwrap();
            assert_eq!(metrics.orders_executed_twice, 0, "seed {seed}: {metrics:?}");
            assert_eq!(
                metrics.orders_acknowledged_unexecuted, 0,
                "seed {seed}: {metrics:?}"
            );
            assert!(
                metrics.orders_acknowledged >= 25,
                "seed {seed}: {metrics:?}"
            );
            assert!(metrics.orders_executed >= metrics.orders_acknowledged);
            // 52 trunks at 0.64 s and 36 % of exchanges failing: an image in well under a minute.
            assert!(metrics.images_completed >= 3, "seed {seed}: {metrics:?}");
        }
    }

    #[test]
    fn the_link_is_lost_past_the_range_and_regained_by_backtracking() {
        let mut cfg = config(Model::preset("s100").unwrap(), 200.0);
        cfg.start_m = [1.0, 0.0, 1.0];
        cfg.waypoints = vec![
            Waypoint {
                t_s: 5.0,
                position_m: [2.0, 0.0, 1.0],
                heading_deg: 0.0,
            },
            Waypoint {
                t_s: 40.0,
                position_m: [8.0, 0.0, 1.0],
                heading_deg: 0.0,
            },
        ];
        let metrics = run(&cfg, &mut Quiet, &AtomicBool::new(false)).unwrap();
        assert!(metrics.link_losses >= 1, "{metrics:?}");
        assert!(metrics.link_recoveries >= 1, "{metrics:?}");
    }

    /// Sets the stop flag at the `after`-th frame, as a signal handler would.
    struct StopAfter<'a> {
        frames: u64,
        after: u64,
        stop: &'a AtomicBool,
    }

    impl Observer for StopAfter<'_> {
        fn frame(&mut self, _event: &FrameEvent) {
            self.frames += 1;
            if self.frames == self.after {
                self.stop.store(true, Ordering::Relaxed);
            }
        }
    }

    #[test]
    fn a_stop_ends_the_run_at_the_next_event_with_the_figures_so_far() {
        let stop = AtomicBool::new(false);
        let mut observer = StopAfter {
            frames: 0,
            after: 100,
            stop: &stop,
        };
        let metrics = run(
            &config(Model::preset("s100").unwrap(), MAX_DURATION_S),
            &mut observer,
            &stop,
        )
        .unwrap();
        assert_eq!(metrics.interrupted.as_deref(), Some(STOPPED));
        assert_eq!(observer.frames, 100);
        // 100 frames, two a 0.64 s slot: about 32 s of a week.
        assert!((20.0..60.0).contains(&metrics.duration_s), "{metrics:?}");
        let sent = metrics.operator_to_rov.frames_sent + metrics.rov_to_operator.frames_sent;
        assert_eq!(sent, 100);
        let json = serde_json::to_value(&metrics).unwrap();
        assert_eq!(json["interrupted"], STOPPED);
        let whole = run(
            &config(Model::preset("s100").unwrap(), 5.0),
            &mut Quiet,
            &AtomicBool::new(false),
        )
        .unwrap();
        assert!(
            serde_json::to_value(&whole)
                .unwrap()
                .get("interrupted")
                .is_none()
        );
    }

    #[test]
    fn settings_out_of_range_are_refused_with_units() {
        let good = config(Model::preset("s100").unwrap(), 10.0);
        assert_eq!(good.validate(), Ok(()));
        type Change = Box<dyn Fn(&mut SessionConfig)>;
        let cases: Vec<(Change, &str)> = vec![
            (
                Box::new(|c| c.ipg_s = 1e-12),
                "IPG: expected 1 ms ..= 10 min, found 1e-9 ms",
            ),
            (Box::new(|c| c.ipg_s = f64::NAN), "IPG"),
            (
                Box::new(|c| c.duration_s = 1e300),
                "duration: expected more than 0 s",
            ),
            (Box::new(|c| c.duration_s = 0.0), "duration"),
            (
                Box::new(|c| c.buoy_m = [1e300, 0.0, 0.0]),
                "buoy position: expected X,Y,Z each in -100000 m ..= 100000 m",
            ),
            (
                Box::new(|c| c.start_m = [0.0, f64::INFINITY, 0.0]),
                "start position",
            ),
            (
                Box::new(|c| c.settings.trunk_bytes = 243),
                "trunk size: expected 1 ..= 242 bytes",
            ),
            (Box::new(|c| c.settings.trunk_bytes = 0), "trunk size"),
            (
                Box::new(|c| c.settings.size_bytes = 0),
                "image size: expected 16 ..= 65535 bytes, found 0 bytes",
            ),
            (
                Box::new(|c| {
                    c.waypoints = vec![Waypoint {
                        t_s: 1.0,
                        position_m: [400.0, 0.0, 0.0],
                        heading_deg: 0.0,
                    }]
                }),
                "waypoint 1: expected X,Y,Z each in -327.67 m ..= 327.67 m",
            ),
            (
                Box::new(|c| {
                    c.script = vec![JoystickChange {
                        t_s: f64::NAN,
                        joystick: Joystick::default(),
                    }]
                }),
                "joystick change 1: expected a time",
            ),
            (
                Box::new(|c| c.images = vec![super::super::test_image(4097, 2, 0)]),
                "camera picture 1: expected 1x1 ..= 4096x4096 pixels",
            ),
        ];
        for (change, message) in cases {
            let mut bad = good.clone();
            change(&mut bad);
            let error = bad.validate().unwrap_err().to_string();
            assert!(error.starts_with(message), "{error}");
            assert!(matches!(
                run(&bad, &mut Quiet, &AtomicBool::new(false)),
                Err(SessionError::Config(_))
            ));
        }
    }
}
