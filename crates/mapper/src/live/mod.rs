//! The live map (octo-delta `map` and `view`): a mapper on the vehicle that inserts clouds as
//! they come and streams the map's changes over a link with the transport of
//! [`rovlink_maplink`], and the operator's view that applies them as they arrive and sends the
//! operator's requests back.
//!
//! - [`input`]: clouds as they come (a `.graph` on a pipe or followed as it is written);
//! - [`carrier`]: the device under the transport, one wire.md frame per segment;
//! - [`map_state`]: the vehicle's map, its sender and a mirror of the operator's view, and the
//!   answers to requests;
//! - [`ros2_out`]: the operator's view published on a ROS 2 graph (Octomap and voxel cloud).
pub mod carrier;
pub mod input;
pub mod map_state;
pub mod mapper;
pub mod ros2_out;
pub mod viewer;

use std::time::Duration;

use rovlink_link::Model;
use rovlink_maplink::OutboxConfig;
use rovlink_maplink::segment::{ACK_BYTES, MAX_SEGMENT_BYTES};

/// Bytes a wire.md link frame adds to each segment.
pub const FRAME_OVERHEAD_BYTES: usize = rovlink_wire::frame::OVERHEAD_BYTES;

/// The resend timeout for a link model: twice the round trip of a full segment and its
/// acknowledgement (delays with three standard deviations of jitter, both frames' air time),
/// plus 50 ms; the same rule as `build --link`'s simulated transfer.
pub fn rto_of(model: &Model) -> Duration {
    let frames = (MAX_SEGMENT_BYTES + ACK_BYTES + 2 * FRAME_OVERHEAD_BYTES) as f64;
    let rtt_s = 2.0 * (model.intrinsic_delay_ms + 3.0 * model.jitter_ms) / 1e3
        + frames * 8.0 / model.bitrate_bps;
    Duration::from_secs_f64((2.0 * rtt_s + 0.05).min(3600.0))
}

/// The transport over a link model: shaped to `rate_bps` (default 85% of the model's bit
/// rate, [`rovlink_octo::transfer::SHAPING`]), resent after `rto` (default [`rto_of`]), a
/// window of four timeouts of the shaped rate (at least 64 KiB).
pub fn outbox_config(model: &Model, rate_bps: Option<f64>, rto: Option<Duration>) -> OutboxConfig {
    let rate_bps = rate_bps.unwrap_or(model.bitrate_bps * rovlink_octo::transfer::SHAPING);
    let rto = rto.unwrap_or_else(|| rto_of(model));
    let window = (4.0 * rate_bps / 8.0 * rto.as_secs_f64()).min(64e6) as usize;
    OutboxConfig {
        rate_bps,
        frame_overhead_bytes: FRAME_OVERHEAD_BYTES,
        rto,
        window_bytes: window.max(64 << 10),
    }
}

/// The default bound of the mapper's backlog: 30 s of the shaped rate, at least 256 KiB.
pub fn default_backlog_bytes(cfg: &OutboxConfig) -> usize {
    ((cfg.rate_bps / 8.0 * 30.0) as usize).max(256 << 10)
}
