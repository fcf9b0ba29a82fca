//! The remote-control protocol's engines: the operator (TDMA master) and the ROV (slave), as
//! state machines given the time and the frames that arrived, returning the frames to send.
//!
//! The semantics are wire.md's: orders with one-bit ids acknowledged by the ROV's EOID toggle
//! (so an order is never executed twice), images sent trunk by trunk with a received-trunk
//! bitmap and RIT resends, EISN/ISN toggles, CI/IC cancellation, heartbeats and the recovery
//! algorithm. [`harness`] holds the two ends around the engines (order sources, the vehicle, the
//! counters), which [`session`] runs with a link in virtual time and [`realtime`] one at a time
//! over a port; [`drive`] is what moves the vehicle, [`camera`] what takes its pictures,
//! [`orders`] and [`script`] what the operator plays; [`outputs`] writes a session's CSV rows,
//! images and [`mcap_log`] (Foxglove) as it goes; [`foxglove`] serves the same view live and
//! takes orders from Foxglove.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod camera;
pub mod config;
pub mod drive;
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
pub mod session;
pub mod vehicle;

use rovlink_debt as debt;
use rovlink_wire::operator::{Order, Roi};
use rovlink_wire::rov::{MAX_TRUNKS, cut_trunks};
use rovlink_wire::{Message, MessageRepr};

/// A file's bytes through [`rovlink_base::io::read_bounded`]: `None` when it holds more than
/// `max_bytes`.
pub(crate) fn read_at_most(
    path: &std::path::Path,
    max_bytes: u64,
) -> std::io::Result<Option<Vec<u8>>> {
    rovlink_base::io::read_bounded(std::fs::File::open(path)?, max_bytes)
}

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
    Vehicle(drive::DriveEvent),
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

/// The most picture bytes a [`TrunkCache`] keeps (the four built-in 320x240 pictures take
/// 0.9 MB); a larger picture is encoded every time.
pub const TRUNK_CACHE_BYTES: usize = 8 << 20;

/// The trunks of the pictures last encoded, by picture and settings: a camera that cycles
/// through a few pictures (`--images`, the built-in ones) has each encoded once per setting
/// instead of at every capture. The encoder is a function of the picture and the settings, so
/// a hit is the same trunks [`trunks_of`] would return. Holds at most [`TRUNK_CACHE_BYTES`]
/// of pictures (by default), the least recently used dropped first.
#[derive(Debug)]
pub struct TrunkCache {
    /// Least recently used first.
    entries: std::collections::VecDeque<(ImageSettings, debt::Image, Vec<Vec<u8>>)>,
    picture_bytes: usize,
    budget_bytes: usize,
}

impl Default for TrunkCache {
    fn default() -> Self {
        TrunkCache::with_budget(TRUNK_CACHE_BYTES)
    }
}

impl TrunkCache {
    /// An empty cache holding at most `budget_bytes` of pictures.
    pub fn with_budget(budget_bytes: usize) -> TrunkCache {
        TrunkCache {
            entries: std::collections::VecDeque::new(),
            picture_bytes: 0,
            budget_bytes,
        }
    }

    /// [`trunks_of`] `image` with `settings`, encoded only when not already held.
    pub fn trunks(&mut self, image: &debt::Image, settings: &ImageSettings) -> Vec<Vec<u8>> {
        let held = self
            .entries
            .iter()
            .position(|(s, i, _)| s == settings && i == image);
        if let Some(entry) = held.and_then(|k| self.entries.remove(k)) {
            let trunks = entry.2.clone();
            self.entries.push_back(entry);
            return trunks;
        }
        let trunks = trunks_of(image, settings);
        let bytes = image.data.len();
        if bytes <= self.budget_bytes {
            while self.picture_bytes + bytes > self.budget_bytes {
                let Some((_, dropped, _)) = self.entries.pop_front() else {
                    break;
                };
                self.picture_bytes -= dropped.data.len();
            }
            self.picture_bytes += bytes;
            self.entries
                .push_back((*settings, image.clone(), trunks.clone()));
        }
        trunks
    }

    /// The number of (picture, settings) pairs held.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when nothing is held.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

/// A built-in camera picture: `width` x `height` RGB, a seabed-like texture with a few
/// objects, different for each `seed`.
pub fn test_image(width: usize, height: usize, seed: u64) -> debt::Image {
    let mut data = Vec::with_capacity(width * height * 3);
    let s = seed as f64;
    for y in 0..height {
        for x in 0..width {
            let (fx, fy) = (x as f64 / width as f64, y as f64 / height as f64);
            let sand = 0.5
                + 0.15 * ((fx * 23.0 + s).sin() * (fy * 17.0 - s).cos())
                + 0.1 * ((fx * 71.0 + fy * 43.0 + s * 3.0).sin());
            let rock = ((fx - 0.3 - 0.05 * s.sin()).powi(2) + (fy - 0.6).powi(2)).sqrt() < 0.15;
            let pipe = (fy - 0.35 - 0.1 * fx).abs() < 0.03;
            let (r, g, b) = if rock {
                (0.25, 0.3, 0.3)
            } else if pipe {
                (0.8, 0.6, 0.1)
            } else {
                (0.3 * sand, 0.6 * sand, 0.7 * sand + 0.1)
            };
            for c in [r, g, b] {
                data.push((c * 255.0).clamp(0.0, 255.0) as u8);
            }
        }
    }
    debt::Image {
        width,
        height,
        channels: 3,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_trunk_cache_gives_what_trunks_of_gives_and_stays_bounded() {
        let picture_bytes = 64 * 48 * 3;
        let mut cache = TrunkCache::with_budget(4 * picture_bytes);
        let pictures: Vec<debt::Image> = (0..3).map(|k| test_image(64, 48, k)).collect();
        let small = ImageSettings {
            size_bytes: 400,
            ..ImageSettings::default()
        };
        for _ in 0..2 {
            for picture in &pictures[..2] {
                for settings in [ImageSettings::default(), small] {
                    assert_eq!(
                        cache.trunks(picture, &settings),
                        trunks_of(picture, &settings)
                    );
                }
            }
        }
        assert_eq!(cache.len(), 4);
        // A picture above the budget is encoded, not held.
        let large = test_image(64, 48 * 5, 0);
        assert_eq!(cache.trunks(&large, &small), trunks_of(&large, &small));
        assert_eq!(cache.len(), 4);
        // One more pushes out the least recently used: the first picture at the default
        // settings.
        assert_eq!(
            cache.trunks(&pictures[2], &small),
            trunks_of(&pictures[2], &small)
        );
        assert_eq!(cache.len(), 4);
        assert!(cache.picture_bytes <= 4 * picture_bytes);
        let first = (ImageSettings::default(), &pictures[0]);
        assert!(!cache.entries.iter().any(|(s, i, _)| (*s, i) == first));
    }
}
