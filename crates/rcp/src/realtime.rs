//! The real-time driver: one end of a session, the operator or the ROV, over a modem endpoint
//! (a serial port, a pseudo-terminal such as `link-sim --pty`'s, a TCP modem console or UDP),
//! with the host's monotonic clock.
//!
//! The session is the one-vehicle network of [`crate::session::scenario`], this process one of
//! its two nodes, run by the one driver ([`crate::driver::run`]) over a [`PortAir`]: the
//! engines and the loop are the simulation's; only the clock and the transport change. Time zero is when [`run`] starts; the engines see the time elapsed since,
//! and a received frame is stamped when its last byte was read. The operator sends its slot's
//! frame when the slot is due and listens until the next slot (or script event); the ROV steps
//! its vehicle every 0.1 s and answers a frame the moment it arrives.
//!
//! Each end knows only its half of the figures: what it sent, and when what it received
//! arrived. One-way delays need both ends' clocks, so they are left out
//! ([`DirectionMetrics::delay_ms`] is `None`); the operator measures the round trip from a
//! slot's frame to the ROV's answer instead.
//!
//! [`DirectionMetrics::delay_ms`]: crate::report::DirectionMetrics::delay_ms

use std::collections::BTreeMap;
use std::sync::atomic::AtomicBool;

use crate::driver::{self, PortAir, Setup};
use crate::report::{Metrics, Observer};
use crate::session::{self, Parts, SessionConfig};
use rovlink_link::gll::Endpoint;

pub use crate::Role;
pub use crate::driver::Ended;

/// Runs one end of `config`'s session over `endpoint` until its duration has passed, `stop`
/// is set, or the endpoint fails. The link model, seed and buoy of `config` are not used (the
/// link is real); the operator takes its orders from `parts.orders`, the ROV is moved by
/// `parts.drive` and takes pictures with `parts.camera` (the other end's parts are unused).
pub fn run(
    role: Role,
    config: &SessionConfig,
    mut parts: Parts,
    endpoint: &mut dyn Endpoint,
    stop: &AtomicBool,
    observer: &mut dyn Observer,
) -> (Metrics, Ended) {
    let scenario = session::scenario(config);
    let vehicle = session::rov_address();
    let guards = std::mem::take(&mut parts.guards);
    let mut ends = parts.ends(&scenario, vehicle, Some(role));
    if let Some(operator) = ends.operator.as_mut() {
        operator.status_poses = true;
    }
    let address = match role {
        Role::Operator => 0,
        Role::Rov => vehicle,
    };
    let mut air = PortAir::new(&scenario, address, vec![endpoint]);
    let setup = Setup {
        scenario: &scenario,
        nodes: vec![address],
        vehicles: BTreeMap::from([(vehicle, ends)]),
        measured_by: role.name(),
        duration_s: config.duration_s,
        // A single session has no relays, and the ROV does not know the operator's IPG.
        duplicate_window_s: 0.0,
        guards,
    };
    let (metrics, ended) = driver::run(setup, &mut air, stop, observer);
    drop(air);
    let mut metrics = session::single(metrics);
    metrics.foreign_datagrams_dropped = endpoint.foreign_datagrams_dropped();
    (metrics, ended)
}
