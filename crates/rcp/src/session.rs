//! A whole single-vehicle teleoperation session in virtual time: operator, link and ROV in one
//! process, as a one-vehicle network ([`SessionConfig`] as a [`Scenario`]: the operator at the
//! buoy, the vehicle at its start, one medium with the session's model, the IPG as the
//! vehicle's slot) run by the one driver ([`crate::driver`]). The vehicle's distance to the
//! buoy sets the medium's range at every vehicle step, so the range model cuts the link when
//! the vehicle strays; the ROV answers a delivered operator frame at the instant it arrives.

use std::collections::BTreeMap;
use std::sync::atomic::AtomicBool;

use crate::Role;
use crate::driver::{self, VehicleEnds};
use crate::network::{self, NetworkError, NetworkMetrics};
use crate::report::{Metrics, Observer, SINGLE_MEDIUM};
use crate::routing::Routes;
use crate::scenario::{MediumSpec, Node, Scenario};
use rovlink_link::ModelError;

pub use crate::config::{
    BoundedIpg, ConfigError, JoystickChange, MAX_DURATION_S, MAX_IPG_S, MAX_POSITION_M,
    MAX_WAYPOINT_M, MIN_IMAGE_BYTES, MIN_IPG_S, SessionConfig, Waypoint, auto_ipg_for, bound_ipg,
};

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
    pub orders: Vec<Box<dyn crate::orders::OrderSource>>,
    /// What moves the vehicle.
    pub drive: Box<dyn crate::autopilot::Drive>,
    /// The camera.
    pub camera: Box<dyn crate::camera::Camera>,
    /// The guards of the nodes this process runs, by address ([`crate::secure`]); empty for
    /// the paper's plain frames.
    pub guards: BTreeMap<u8, rovlink_security::Guard>,
}

impl Parts {
    /// The config's own: its script and waypoints, the built-in vehicle at its start, its
    /// pictures cycled.
    pub fn from_config(config: &SessionConfig) -> Parts {
        Parts {
            orders: vec![Box::new(crate::orders::Script::new(
                &config.script,
                &config.waypoints,
            ))],
            drive: Box::new(crate::autopilot::SimDrive::new(config.start_m)),
            camera: Box::new(crate::camera::Cycle::new(config.images.clone())),
            guards: BTreeMap::new(),
        }
    }

    /// The ends these parts make in `scenario` for `vehicle`: the operator's (unless `role`
    /// is the ROV's), the vehicle's (unless it is the operator's); both when `role` is none
    /// (a simulation).
    pub fn ends(self, scenario: &Scenario, vehicle: u8, role: Option<Role>) -> VehicleEnds {
        VehicleEnds {
            operator: (role != Some(Role::Rov))
                .then(|| driver::operator_end(scenario, vehicle, self.orders)),
            rov: (role != Some(Role::Operator))
                .then(|| driver::rov_end(scenario, vehicle, self.drive, self.camera)),
        }
    }
}

/// The address of a single session's vehicle.
pub fn rov_address() -> u8 {
    crate::rov::RovConfig::default().address
}

/// `config` as a one-vehicle network: the operator at the buoy and the vehicle at its start,
/// one medium ([`SINGLE_MEDIUM`]) with the session's model, no routes, and the vehicle's slot
/// the IPG (so the cycle is the IPG).
pub fn scenario(config: &SessionConfig) -> Scenario {
    let rov = rov_address();
    Scenario {
        duration_s: config.duration_s,
        seed: config.seed,
        nodes: vec![
            Node {
                address: 0,
                role: Role::Operator,
                position_m: config.buoy_m,
                waypoints: Vec::new(),
                slot_s: None,
            },
            Node {
                address: rov,
                role: Role::Rov,
                position_m: config.start_m,
                waypoints: Vec::new(),
                slot_s: Some(config.ipg_s),
            },
        ],
        media: vec![MediumSpec {
            name: SINGLE_MEDIUM.to_string(),
            model: config.model.clone(),
            nodes: vec![0, rov],
        }],
        routes: Routes::default(),
        settings: config.settings,
        frame_overhead_bytes: 0,
    }
}

/// The single vehicle's figures of a one-vehicle network's.
pub fn single(mut metrics: NetworkMetrics) -> Metrics {
    let mut m = metrics
        .vehicles
        .remove(&rov_address().to_string())
        .unwrap_or_default();
    m.measured_by = metrics.measured_by;
    m.duration_s = metrics.duration_s;
    m.interrupted = metrics.interrupted;
    m
}

/// Runs a session after [`SessionConfig::validate`] with the config's own [`Parts`];
/// see [`run_with`].
pub fn run(
    config: &SessionConfig,
    observer: &mut dyn Observer,
    stop: &AtomicBool,
) -> Result<Metrics, SessionError> {
    run_with(config, Parts::from_config(config), observer, stop, None)
}

/// Runs a session after [`SessionConfig::validate`]; `observer` sees frames, images, poses and
/// events as they happen. `stop` is checked at every event: once set, the run ends there, and
/// the metrics cover the virtual time reached, with `interrupted` set to
/// [`crate::report::STOPPED`]. The run also ends early once the observer has
/// [`failed`](Observer::failed). With a `pace`, virtual time is held to `pace` times real
/// time ([`crate::driver::Pace`]).
pub fn run_with(
    config: &SessionConfig,
    mut parts: Parts,
    observer: &mut dyn Observer,
    stop: &AtomicBool,
    pace: Option<f64>,
) -> Result<Metrics, SessionError> {
    config.validate()?;
    let scenario = scenario(config);
    let vehicle = rov_address();
    let guards = std::mem::take(&mut parts.guards);
    let ends = BTreeMap::from([(vehicle, parts.ends(&scenario, vehicle, None))]);
    match network::simulate(&scenario, ends, guards, observer, stop, pace) {
        Ok(metrics) => Ok(single(metrics)),
        Err(NetworkError::Model { error, .. }) => Err(SessionError::Model(error)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ImageSettings;
    use crate::operator::Joystick;
    use crate::report::Quiet;
    use crate::report::{FrameEvent, STOPPED};
    use rovlink_link::Model;
    use rovlink_link::model::JitterDistribution;
    use std::sync::atomic::Ordering;

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
            images: vec![crate::camera::builtin_picture(160, 120, 1)],
        }
    }

    #[derive(Default)]
    struct Images(Vec<f64>);

    impl Observer for Images {
        fn image(&mut self, _vehicle: u8, t_s: f64, _stream: &[u8]) {
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
        fn frame(&mut self, _event: &FrameEvent<'_>) {
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
                Box::new(|c| c.images = vec![crate::camera::builtin_picture(4097, 2, 0)]),
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
