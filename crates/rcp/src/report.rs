//! The vocabulary every session driver and output shares: the figures of a session
//! ([`Metrics`], [`DirectionMetrics`]), what happened along the way ([`FrameEvent`], seen by an
//! [`Observer`]), and the per-direction tallies the drivers keep. A leaf of [`crate`]'s
//! drivers: it uses the engines' types, never a driver or an output.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::{Event, PoseSample};
use rovlink_base::stats::Running;
use rovlink_link::SimTime;
use rovlink_wire::frame::Frame;
use rovlink_wire::{Message, MessageRepr};

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
    /// ROV with a MAVLink autopilot: messages from the link not used, by reason (`unsigned`,
    /// `bad_signature`, `replayed`, `other_address`, `other_system`; absent when none).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub mavlink_refused: BTreeMap<&'static str, u64>,
    /// Operator: statuses that said the vehicle has no position estimate (absent when none).
    #[serde(skip_serializing_if = "is_zero")]
    pub statuses_without_position: u64,
    /// Frames a secured end refused (absent when none), by the source address they claimed,
    /// then by reason (`unsecured`, `malformed`, `no_key`, `bad_tag`, `replay`).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub frames_refused: BTreeMap<String, BTreeMap<&'static str, u64>>,
    /// Real time over UDP: datagrams dropped because they came from someone other than the
    /// endpoint's peer (absent when none).
    #[serde(skip_serializing_if = "is_zero")]
    pub foreign_datagrams_dropped: u64,
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

/// What one node's router did.
#[derive(Debug, Clone, Default, Serialize, PartialEq, Eq)]
pub struct NodeMetrics {
    /// Frames it heard intact.
    pub frames_heard: u64,
    /// Of those, taken by its own engine.
    pub frames_delivered: u64,
    /// Frames it forwarded (each onto one interface counts once).
    pub frames_forwarded: u64,
    /// Copies dropped as duplicates (overheard again, or its own forward coming back).
    pub duplicates_dropped: u64,
    /// Frames for others, not on its routed path.
    pub off_path_dropped: u64,
    /// Its own frames relayed back to it.
    pub own_dropped: u64,
    /// Forwards towards the node the frame was heard from (must be 0).
    pub forwarded_back: u64,
    /// Frames for this node its guard refused (absent when none), by the source address they
    /// claimed, then by reason (see [`Metrics::frames_refused`]).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub refused: BTreeMap<String, BTreeMap<&'static str, u64>>,
}

/// What crossed one medium.
#[derive(Debug, Clone, Default, Serialize, PartialEq, Eq)]
pub struct MediumMetrics {
    /// Transmissions (origins and forwards).
    pub transmissions: u64,
    /// Receptions that arrived intact.
    pub receptions_delivered: u64,
    /// Receptions lost in a collision at their receiver.
    pub receptions_collided: u64,
    /// Receptions out of range.
    pub receptions_out_of_range: u64,
    /// Receptions lost otherwise (loss, bit errors, overflow, corruption).
    pub receptions_lost: u64,
}

/// A scenario's figures (`--metrics`).
#[derive(Debug, Clone, Default, Serialize)]
pub struct NetworkMetrics {
    /// `simulation`.
    pub measured_by: &'static str,
    /// Session length, s: the time reached when the run was interrupted.
    pub duration_s: f64,
    /// Why the run ended early; absent when it ran its whole duration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interrupted: Option<String>,
    /// The seed.
    pub seed: u64,
    /// The TDMA cycle, s.
    pub cycle_s: f64,
    /// Each vehicle's slot, s, by address.
    pub slots_s: BTreeMap<String, f64>,
    /// Each vehicle's session figures, by address (the single-vehicle session's fields, end to
    /// end over its routed path).
    pub vehicles: BTreeMap<String, Metrics>,
    /// Each node's routing figures, by address.
    pub nodes: BTreeMap<String, NodeMetrics>,
    /// Each medium's figures, by name.
    pub media: BTreeMap<String, MediumMetrics>,
}

fn is_zero(value: &u64) -> bool {
    *value == 0
}

/// What the driver (`rcp::driver::run`, under every kind of session) says when `stop` ended it,
/// until the caller names the cause.
pub const STOPPED: &str = "stopped";

/// The columns of `--events`, in every kind of session: the frame's direction, what it is, its
/// length, when it was sent and received, the medium's fate for it, then where: the medium, the
/// frame's SRC and DST, the node that transmitted this copy, the node this row is about, and what
/// that node's router did. A simulation writes one row per frame and receiver; a real-time node
/// one per frame it sent (fate `sent`) or heard (fate `received`).
pub const EVENTS_HEADER: [&str; 12] = [
    "direction",
    "kind",
    "bytes",
    "t_sent_s",
    "t_received_s",
    "fate",
    "medium",
    "src",
    "dst",
    "tx",
    "rx",
    "action",
];

/// One frame's row of `--events` ([`EVENTS_HEADER`]; the data of the paper's Fig. 10).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameEvent<'a> {
    /// `operator_to_rov` or `rov_to_operator`.
    pub direction: &'static str,
    /// velocity, goto, image_settings, hold_heading (operator); image_trunk or status (ROV);
    /// raw when it does not parse.
    pub kind: &'static str,
    /// Frame length.
    pub bytes: usize,
    /// When it was sent, s (none for a frame received in real time: its send time is the far
    /// end's).
    pub t_sent_s: Option<f64>,
    /// When it arrived, s (none when lost, or for a row of a frame sent in real time).
    pub t_received_s: Option<f64>,
    /// The medium's fate for it at `rx` (`delivered`, `lost`, `range`, ...); in real time
    /// `sent` or `received` (the medium is outside).
    pub fate: &'static str,
    /// The medium (a single session's is [`SINGLE_MEDIUM`]).
    pub medium: &'a str,
    /// The frame's SRC (none when its bytes are unknown or do not parse).
    pub src: Option<u8>,
    /// The frame's DST.
    pub dst: Option<u8>,
    /// The node that transmitted this copy (none for a frame heard in real time).
    pub tx: Option<u8>,
    /// The node this row is about: the receiver (none for a frame sent in real time).
    pub rx: Option<u8>,
    /// What `rx`'s router did: `delivered`, `forwarded`, `delivered+forwarded`, or why it
    /// dropped it (`duplicate`, `off_path`, `own`, `malformed`); empty when it did not arrive
    /// intact, or for a frame sent.
    pub action: &'static str,
}

/// The name of a single-vehicle session's one medium in `--events`.
pub const SINGLE_MEDIUM: &str = "link";

/// The direction of a frame from `src` to `dst`: towards the operator or away from it.
pub fn direction_of(src: u8, dst: u8) -> &'static str {
    if dst == 0 && src != 0 {
        "rov_to_operator"
    } else {
        "operator_to_rov"
    }
}

/// What happened along the way, for outputs beyond the metrics: the one interface every
/// session (single or network, simulated or real) reports through. `vehicle` is the address
/// of the vehicle whose session it is (a single session's is its ROV's).
pub trait Observer {
    /// A frame's fate is known (a row of `--events`).
    fn frame(&mut self, _event: &FrameEvent<'_>) {}
    /// The operator completed an image of `vehicle` (its DEBT stream) at `t_s`.
    fn image(&mut self, _vehicle: u8, _t_s: f64, _stream: &[u8]) {}
    /// `vehicle` after a step (the ROV's side), or as the last status reported it (an
    /// operator in real time).
    fn pose(&mut self, _vehicle: u8, _pose: &PoseSample) {}
    /// Something happened at `end` of `vehicle`'s session, at `t_s` (orders, images in
    /// progress, statuses, the link and the vehicle): what `--telemetry` and a live Foxglove
    /// view show.
    fn event(&mut self, _vehicle: u8, _end: crate::Role, _t_s: f64, _event: &Event) {}
    /// Something to tell the user at `t_s` (an order source's bad line): one line.
    fn warning(&mut self, _t_s: f64, _text: &str) {}
    /// True once the observer can record nothing more (an output failed): the run ends at the
    /// next event, as if stopped.
    fn failed(&self) -> bool {
        false
    }
    /// True when [`Observer::pose`] must come at every vehicle step as it happens (a track,
    /// a log, a live view); false lets a simulation sleep through the steps of a still
    /// vehicle, running them late (the same results) without showing each one's pose.
    fn wants_poses(&self) -> bool {
        true
    }
}

/// Several observers as one: each sees everything, in turn; it has failed when one has.
pub struct Tee<'a>(pub Vec<&'a mut dyn Observer>);

impl Observer for Tee<'_> {
    fn frame(&mut self, event: &FrameEvent<'_>) {
        self.0.iter_mut().for_each(|o| o.frame(event));
    }

    fn image(&mut self, vehicle: u8, t_s: f64, stream: &[u8]) {
        self.0
            .iter_mut()
            .for_each(|o| o.image(vehicle, t_s, stream));
    }

    fn pose(&mut self, vehicle: u8, pose: &PoseSample) {
        self.0.iter_mut().for_each(|o| o.pose(vehicle, pose));
    }

    fn event(&mut self, vehicle: u8, end: crate::Role, t_s: f64, event: &Event) {
        self.0
            .iter_mut()
            .for_each(|o| o.event(vehicle, end, t_s, event));
    }

    fn warning(&mut self, t_s: f64, text: &str) {
        self.0.iter_mut().for_each(|o| o.warning(t_s, text));
    }

    fn failed(&self) -> bool {
        self.0.iter().any(|o| o.failed())
    }

    fn wants_poses(&self) -> bool {
        self.0.iter().any(|o| o.wants_poses())
    }
}

/// An observer that observes nothing.
pub struct Quiet;

impl Observer for Quiet {
    fn wants_poses(&self) -> bool {
        false
    }
}

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

/// What a frame is, for the events table: a secured frame's message when it is not
/// encrypted, `encrypted` when it is.
pub(crate) fn kind_of(bytes: &[u8]) -> &'static str {
    use rovlink_security::sealed::{Sealed, is_sealed};
    let Ok(frame) = Frame::new_checked(bytes) else {
        return "raw";
    };
    let message = if is_sealed(frame.payload()) {
        match Sealed::new_checked(frame.payload()) {
            Ok(p) if p.encrypted() => return "encrypted",
            Ok(p) => Message::parse_payload(frame.src(), p.message()).ok(),
            Err(_) => None,
        }
    } else {
        MessageRepr::parse(&frame).ok().map(|r| r.message)
    };
    match message {
        Some(Message::Operator(op)) => op.order.name(),
        Some(Message::Rov(rov)) if !rov.trunk.is_empty() => "image_trunk",
        Some(Message::Rov(_)) => "status",
        _ => "raw",
    }
}
