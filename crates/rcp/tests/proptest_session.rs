//! Property tests of whole simulated sessions under heavy loss: for any seed, any schedule of
//! GoTo orders and joystick changes, and 20 % of frames lost in each direction (plus, sometimes,
//! bit errors and duplicates), no order is executed twice, every acknowledged order was
//! executed, and every image the ROV starts is completed by the operator (except the one still
//! in flight when the session ends).

use std::sync::atomic::AtomicBool;

use proptest::prelude::*;
use rovlink_link::Model;
use rovlink_rcp::ImageSettings;
use rovlink_rcp::camera::builtin_picture;
use rovlink_rcp::operator::Joystick;
use rovlink_rcp::report::Quiet;
use rovlink_rcp::session::{self, JoystickChange, SessionConfig, Waypoint};

prop_compose! {
    fn waypoint()(t_s in 0.0..150.0f64, x in -3.0..3.0f64, y in -3.0..3.0f64, z in 0.0..2.0f64,
                  heading_deg in 0.0..360.0f64) -> Waypoint {
        Waypoint { t_s, position_m: [x, y, z], heading_deg }
    }
}

prop_compose! {
    fn joystick()(t_s in 0.0..150.0f64, v in prop::array::uniform4(-100.0..100.0f64))
                 -> JoystickChange {
        JoystickChange { t_s, joystick: Joystick { vx: v[0], vy: v[1], vz: v[2], vyaw: v[3] } }
    }
}

prop_compose! {
    fn session()(
        seed in any::<u64>(),
        mut waypoints in prop::collection::vec(waypoint(), 1..25),
        mut script in prop::collection::vec(joystick(), 0..6),
        ber in prop_oneof![Just(0.0), 1e-4..1e-3f64],
        duplicate_percent in prop_oneof![Just(0.0), 0.0..10.0f64],
        size_bytes in 300u16..1500,
    ) -> SessionConfig {
        waypoints.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        script.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        let mut model = Model::preset("s100").unwrap();
        model.loss_percent = 20.0;
        model.ber = ber;
        model.duplicate_percent = duplicate_percent;
        // The vehicle stays within 5 m of the buoy: the range model never cuts the link, so
        // loss is the only cause of missing frames.
        model.range_max_m = None;
        SessionConfig {
            model,
            seed,
            ipg_s: 0.64,
            duration_s: 180.0,
            buoy_m: [0.0; 3],
            start_m: [1.0, 0.0, 0.0],
            script,
            waypoints,
            settings: ImageSettings { size_bytes, ..ImageSettings::default() },
            images: vec![builtin_picture(96, 64, seed % 7)],
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn orders_run_exactly_once_and_images_complete_under_20_percent_loss(config in session()) {
        let metrics = session::run(&config, &mut Quiet, &AtomicBool::new(false)).unwrap();
        prop_assert_eq!(metrics.orders_executed_twice, 0, "{:?}", metrics);
        prop_assert_eq!(metrics.orders_acknowledged_unexecuted, 0, "{:?}", metrics);
        prop_assert!(metrics.orders_acknowledged <= metrics.orders_sent);
        prop_assert!(metrics.orders_executed <= metrics.orders_sent);
        prop_assert!(metrics.images_completed >= 1, "{:?}", metrics);
        prop_assert!(
            metrics.images_completed + 1 >= metrics.images_started
                && metrics.images_completed <= metrics.images_started,
            "started {}, completed {}",
            metrics.images_started,
            metrics.images_completed
        );
        // Orders queued early enough are all acknowledged: with 36 % of exchanges failing, the
        // chance that one order's exchanges all fail for 30 s is about 0.36^47.
        let early = config.waypoints.iter().filter(|w| w.t_s < 150.0).count() as u64;
        prop_assert_eq!(metrics.orders_acknowledged, early.min(metrics.orders_sent), "{:?}", metrics);
    }
}
