//! The remote-control protocol's engines: the operator (TDMA master) and the ROV (slave), as
//! state machines given the time and the frames that arrived, returning the frames to send.
//!
//! The semantics are wire.md's: orders with one-bit ids acknowledged by the ROV's EOID toggle
//! (so an order is never executed twice), images sent trunk by trunk with a received-trunk
//! bitmap and RIT resends, EISN/ISN toggles, CI/IC cancellation, heartbeats and the recovery
//! algorithm. [`harness`] holds the two ends around the engines (order sources, the vehicle, the
//! counters), which [`session`] runs with a link in virtual time and [`realtime`] one at a time
//! over a port; [`autopilot`] is what moves the vehicle (its autopilot, or the built-in model),
//! [`camera`] what takes its pictures, [`orders`] and [`script`] what the operator plays. What
//! a session writes and shows (CSV rows, images, the MCAP log, the live Foxglove view) lives
//! above this crate, in tdma-run's `outputs` and in `rovlink-field`.
//!
//! This file holds, besides the module list, only the protocol's shared vocabulary: what an
//! engine did ([`Event`]), which end is which ([`Role`]), the vehicle at one instant
//! ([`PoseSample`]), how images are encoded and cut ([`ImageSettings`]), a frame out of a
//! message ([`emit`]) and an image into its trunks ([`trunks_of`]). Nearly every module and
//! every caller of the crate names them; at the crate root they read as what they are, the
//! words of the protocol (`rovlink_rcp::Event`), where a `vocabulary` module would only add a
//! path segment and a re-export for each. Everything with a subject of its own has its module
//! ([`trunk_cache`], the built-in pictures in [`camera`]).
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod autopilot;
pub mod camera;
pub mod config;
pub mod driver;
pub mod harness;
pub mod network;
pub mod operator;
pub mod orders;
pub mod realnet;
pub mod realtime;
pub mod report;
pub mod routing;
pub mod rov;
pub mod rules;
pub mod scenario;
pub mod script;
pub mod secure;
pub mod session;
pub mod trunk_cache;
pub mod vehicle;

use rovlink_debt as debt;
use rovlink_wire::operator::{Order, Roi};
use rovlink_wire::rov::{MAX_TRUNKS, cut_trunks};
use rovlink_wire::{Message, MessageRepr};

/// Something an engine did that a report or a test wants to know.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// ROV: a high-level order was executed.
    OrderExecuted(Order),
    /// ROV: the order in execution was cancelled (CLO).
    OrderCancelled,
    /// Operator: high-level order number `index` was acknowledged (EOID toggled).
    OrderAcknowledged(u64),
    /// ROV: a new image went into the pipe.
    ImageStarted {
        /// Its trunks.
        trunks: usize,
        /// Its bytes.
        bytes: usize,
    },
    /// ROV: the image in flight was cancelled by new settings.
    ImageCancelled,
    /// Operator: every trunk of an image arrived; the DEBT stream.
    ImageCompleted(Vec<u8>),
    /// ROV: no heartbeat for the timeout.
    LinkLost,
    /// ROV: heartbeats again.
    LinkRecovered,
    /// Operator: high-level order number `index` went out in a slot for the first time.
    OrderSent {
        /// Its number, in the order orders were queued.
        index: u64,
        /// The order.
        order: Order,
    },
    /// Operator: the ROV answered a cancel request with LOC: the order in execution was
    /// cancelled.
    CancelConfirmed,
    /// Operator: a ROV frame with a status arrived: the frame as parsed, its trunk emptied.
    Status(MessageRepr),
    /// Operator: a trunk of the image in progress arrived.
    ImageProgress {
        /// Trunks received so far.
        trunks: usize,
        /// Trunks in the image, once its last trunk (LT) has arrived.
        of: Option<usize>,
        /// The trunks received from the first on without a gap, concatenated: a DEBT prefix
        /// that decodes to the image so far.
        prefix: Vec<u8>,
    },
    /// Operator: no ROV frame for the heartbeat timeout (5 s).
    AnswersLost,
    /// Operator: ROV frames arrive again.
    AnswersBack,
    /// ROV: the vehicle (autopilot) reported something.
    Vehicle(autopilot::DriveEvent),
    /// ROV: the camera gave no picture; why.
    CameraFailed(String),
}

/// Which end of the session an event or a process is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// The TDMA master at the surface.
    Operator,
    /// The vehicle.
    Rov,
}

impl Role {
    /// `operator` or `rov`.
    pub fn name(self) -> &'static str {
        match self {
            Role::Operator => "operator",
            Role::Rov => "rov",
        }
    }
}

/// The vehicle's state at one instant: what logs, plots and the MCAP file show.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSample {
    /// When, s since the session started.
    pub t_s: f64,
    /// Position, NED m.
    pub position_m: [f64; 3],
    /// Heading, degrees from north.
    pub heading_deg: f64,
    /// Body velocities: surge, sway, heave (m/s), yaw rate (degrees/s).
    pub velocity: [f64; 4],
    /// The velocities the command in force asks for (same frame and units).
    pub commanded_velocity: [f64; 4],
    /// The GoTo order being executed: its target, NED m.
    pub goal_m: Option<[f64; 3]>,
    /// While the link is lost: the stacked position the ROV is backtracking to, NED m.
    pub backtrack_m: Option<[f64; 3]>,
    /// True while heartbeats arrive.
    pub link_up: bool,
}

/// How the ROV encodes and cuts its images.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageSettings {
    /// Region of interest, if any.
    pub roi: Option<Roi>,
    /// Bit-planes the ROI is raised by.
    pub roi_shift: u8,
    /// Luma only.
    pub gray: bool,
    /// Capture downscale exponent (size / 2^scale).
    pub scale: u8,
    /// Encoded size, bytes.
    pub size_bytes: u16,
    /// Trunk size, bytes.
    pub trunk_bytes: u8,
    /// Parity trunks after the image's data trunks, percent of its trunks (0: none;
    /// `tdma-run --fec`, [`debt::fec`]). A session setting both ends share: ImageSettings
    /// orders do not carry it.
    pub fec_percent: u8,
}

impl From<rovlink_wire::operator::ImageOrder> for ImageSettings {
    /// The settings an ImageSettings order asks for (an all-zero ROI is none).
    fn from(order: rovlink_wire::operator::ImageOrder) -> Self {
        ImageSettings {
            roi: (order.roi.to_array() != [0; 4]).then_some(order.roi),
            roi_shift: order.roi_shift,
            gray: order.gray,
            scale: order.scale,
            size_bytes: order.size_bytes,
            trunk_bytes: order.trunk_bytes,
            fec_percent: 0,
        }
    }
}

impl Default for ImageSettings {
    fn default() -> Self {
        ImageSettings {
            roi: None,
            roi_shift: 3,
            gray: false,
            scale: 0,
            size_bytes: 2000,
            trunk_bytes: 39,
            fec_percent: 0,
        }
    }
}

/// A frame carrying `message` from `src` to `dst`.
pub fn emit(src: u8, dst: u8, message: Message) -> Vec<u8> {
    let repr = MessageRepr { src, dst, message };
    let mut out = Vec::with_capacity(repr.buffer_len());
    // Engines build only valid messages; an emit failure would leave the frame empty.
    let _ = repr.emit_to_vec(&mut out);
    out
}

/// Encodes `image` with `settings` and cuts the stream into trunks. The size is rounded up to a
/// whole number of trunks, so every slot carries a full trunk (the paper's constant 57-byte ROV
/// frame with 39-byte trunks), and capped at [`MAX_TRUNKS`] trunks. With parity
/// (`fec_percent`), the last trunks are the parity, inside the size.
pub fn trunks_of(image: &debt::Image, settings: &ImageSettings) -> Vec<Vec<u8>> {
    let trunk = usize::from(settings.trunk_bytes.max(1));
    let bytes = usize::from(settings.size_bytes)
        .div_ceil(trunk)
        .clamp(1, MAX_TRUNKS)
        * trunk;
    let bytes = bytes.max(16);
    let roi = settings.roi.map(|r| debt::Rect {
        x0: usize::from(r.x0),
        y0: usize::from(r.y0),
        x1: usize::from(r.x1),
        y1: usize::from(r.y1),
    });
    let options = debt::EncodeOptions {
        bytes,
        gray: settings.gray,
        scale: u32::from(settings.scale.min(3)),
        roi,
        roi_shift: u32::from(settings.roi_shift.clamp(1, 15)),
        fec: (settings.fec_percent > 0).then_some(debt::FecOptions {
            percent: u32::from(settings.fec_percent).min(debt::fec::MAX_PERCENT),
            trunk_bytes: trunk,
        }),
        ..debt::EncodeOptions::default()
    };
    let stream = debt::encode(image, &options)
        .or_else(|_| {
            // A ROI outside the picture: encode without it rather than send nothing.
            debt::encode(
                image,
                &debt::EncodeOptions {
                    roi: None,
                    ..options.clone()
                },
            )
        })
        .unwrap_or_default();
    cut_trunks(&stream, trunk)
        .map(|trunks| trunks.into_iter().map(<[u8]>::to_vec).collect())
        .unwrap_or_default()
}
