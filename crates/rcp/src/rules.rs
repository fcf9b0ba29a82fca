//! The protocol's derived rules, each written once: the timeouts, the duplicate window, the
//! frame sizes a slot is sized for, and a hop's share of the slot time. A single-vehicle session is the
//! one-vehicle case of a network, so both use these; a leaf module (it uses nothing else of
//! [`crate`]).

use rovlink_link::Model;

/// The link timeout of wire.md, s: a vehicle counts the link as lost after this long without a
/// heartbeat, and the operator counts the vehicle's answers as lost after this long without one.
pub const LINK_TIMEOUT_S: f64 = 5.0;

/// The multiple of the cycle after which the link counts as lost, where that is longer than
/// [`LINK_TIMEOUT_S`]: a vehicle is polled once a cycle, so a long cycle needs more.
pub const TIMEOUT_CYCLES: f64 = 3.0;

/// The heartbeat and answers timeout of a session whose cycle (its IPG, for one vehicle) is
/// `cycle_s`: the longer of [`LINK_TIMEOUT_S`] and [`TIMEOUT_CYCLES`] cycles.
pub fn link_timeout_s(cycle_s: f64) -> f64 {
    (TIMEOUT_CYCLES * cycle_s).max(LINK_TIMEOUT_S)
}

/// How long a router remembers a frame it took, to drop the copies of it it hears again, s:
/// half the cycle (a copy relayed back arrives within the cycle; the next frame of the same
/// sender comes a cycle later).
pub fn duplicate_window_s(cycle_s: f64) -> f64 {
    cycle_s / 2.0
}

/// The operator's frame a slot is sized for, bytes: a GoTo order's frame, the longest the
/// operator sends.
pub const OPERATOR_FRAME_BYTES: usize = 16;

/// The ROV's frame a slot is sized for, bytes: a status with one image trunk of `trunk_bytes`,
/// in a link frame.
pub fn rov_frame_bytes(trunk_bytes: u8) -> usize {
    rovlink_wire::frame::OVERHEAD_BYTES + rovlink_wire::rov::FIXED_BYTES + usize::from(trunk_bytes)
}

/// One hop's share of a slot, s: a frame of `frame_bytes` on the air, the modem's intrinsic
/// delay and the propagation over `distance_m`. A slot is the hops of the operator's frame to
/// the vehicle, each followed by its [`guard_s`], then the hops of the answer back, summed in
/// that order.
pub fn hop_s(model: &Model, frame_bytes: usize, distance_m: f64) -> f64 {
    model.air_time_s(frame_bytes)
        + model.intrinsic_delay_ms * 1e-3
        + model.propagation_s(distance_m)
}

/// The guard after each hop of the operator's frame, s: three jitter standard deviations.
pub fn guard_s(model: &Model) -> f64 {
    3.0 * model.jitter_ms * 1e-3
}

/// One hop of a slot: its medium's model and its length, m.
#[derive(Debug, Clone, Copy)]
pub struct Hop<'a> {
    /// The model of the medium the hop is on.
    pub model: &'a Model,
    /// Its length, m.
    pub distance_m: f64,
}

/// The TDMA slot rule, the one place it is written: a vehicle's slot, s, is the operator's
/// frame ([`OPERATOR_FRAME_BYTES`]) over each hop of `out`, each followed by its [`guard_s`],
/// then the answer (a status with a trunk of `trunk_bytes`) over each hop of `back`; every
/// frame is `overhead_bytes` longer when frames are secured (6, docs/wire-extensions.md; 0
/// for the paper's plain frames). A single session's automatic IPG is the one-hop case.
pub fn slot_s(out: &[Hop<'_>], back: &[Hop<'_>], trunk_bytes: u8, overhead_bytes: usize) -> f64 {
    let mut slot_s = 0.0;
    for hop in out {
        slot_s += hop_s(
            hop.model,
            OPERATOR_FRAME_BYTES + overhead_bytes,
            hop.distance_m,
        );
        slot_s += guard_s(hop.model);
    }
    let answer_bytes = rov_frame_bytes(trunk_bytes) + overhead_bytes;
    for hop in back {
        slot_s += hop_s(hop.model, answer_bytes, hop.distance_m);
    }
    slot_s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_cycle_lengthens_the_timeout() {
        assert_eq!(link_timeout_s(0.5), 5.0);
        assert_eq!(link_timeout_s(2.0), 6.0);
        assert_eq!(duplicate_window_s(0.8), 0.4);
    }

    #[test]
    fn a_slot_is_both_hops_and_one_guard() {
        let model = Model::preset("s100").unwrap();
        let out = hop_s(&model, OPERATOR_FRAME_BYTES, 3.0);
        let back = hop_s(&model, rov_frame_bytes(39), 3.0);
        let air = model.air_time_s(OPERATOR_FRAME_BYTES) - model.air_time_s(rov_frame_bytes(39));
        assert!((out - back - air).abs() < 1e-12);
        assert_eq!(guard_s(&model), 3.0 * model.jitter_ms * 1e-3);
    }
}
