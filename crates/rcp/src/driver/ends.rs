//! The ends a node holds and how a scenario builds them: the operator's end for a vehicle,
//! the vehicle's end, and a node's router.

use crate::autopilot::Drive;
use crate::camera::Camera;
use crate::harness::{OperatorEnd, RovEnd};
use crate::orders::OrderSource;
use crate::routing::Router;
use crate::rov::{Rov, RovConfig};
use crate::rules;
use crate::scenario::Scenario;
use rovlink_link::SimTime;

/// One vehicle's session as this process runs it: the ends it holds (both in a simulation,
/// the operator's or the vehicle's in real time).
pub struct VehicleEnds {
    /// The operator's end for this vehicle, when the operator runs here.
    pub operator: Option<OperatorEnd>,
    /// The vehicle's end, when the vehicle runs here.
    pub rov: Option<RovEnd>,
}

/// The operator's end for `vehicle` of `scenario`: polling it once a cycle at its slot
/// ([`Scenario::cycle`]), its answers timeout [`rules::link_timeout_s`] of the cycle, its
/// orders from `sources`.
pub fn operator_end(
    scenario: &Scenario,
    vehicle: u8,
    sources: Vec<Box<dyn OrderSource>>,
) -> OperatorEnd {
    let cycle_s = scenario.cycle_s();
    let start_s = scenario
        .cycle()
        .iter()
        .find(|s| s.address == vehicle)
        .map_or(0.0, |s| s.start_s);
    let mut end = OperatorEnd::new(vehicle, cycle_s, sources)
        .first_slot_at(SimTime::from_secs_f64(start_s))
        .with_parity(scenario.settings.fec_percent > 0);
    end.answers_timeout_s = rules::link_timeout_s(cycle_s);
    end
}

/// `vehicle`'s end: at its address, with the scenario's image settings, a heartbeat timeout of
/// [`rules::link_timeout_s`] of the cycle, moved by `drive`, taking pictures with `camera`.
pub fn rov_end(
    scenario: &Scenario,
    vehicle: u8,
    drive: Box<dyn Drive>,
    camera: Box<dyn Camera>,
) -> RovEnd {
    let config = RovConfig {
        address: vehicle,
        heartbeat_timeout_s: rules::link_timeout_s(scenario.cycle_s()),
        settings: scenario.settings,
        ..RovConfig::default()
    };
    RovEnd::new(Rov::with(config, drive, camera))
}

/// Node `address`'s router in `scenario`: the scenario's routes, the node's neighbours per
/// interface, a duplicate window of `duplicate_window_s`.
pub fn router(scenario: &Scenario, address: u8, duplicate_window_s: f64) -> Router {
    Router::new(
        address,
        scenario.routes.clone(),
        scenario.neighbours(address),
        duplicate_window_s,
    )
}
