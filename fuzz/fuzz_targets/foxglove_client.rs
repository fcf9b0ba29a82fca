//! One message a Foxglove client publishes, on the order channel and on a Twist channel:
//! `rcp::foxglove::ClientTopic::parse` on any bytes.
//!
//! Checks that it never panics and, for every message it accepts, that a Twist gives a
//! joystick with every axis finite and within -100..=100 %, armed, in manual; and that an order
//! is a joystick, a high-level order or a cancel, never an unknown order.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_field::foxglove::ClientTopic;
use rovlink_rcp::orders::Live;
use rovlink_wire::Nav;
use rovlink_wire::operator::Order;

fuzz_target!(|data: &[u8]| {
    if let Ok(live) = ClientTopic::Twist.parse(data) {
        let Live::Joystick {
            joystick,
            arm,
            disarm,
            nav,
        } = live
        else {
            panic!("a Twist gave {live:?}");
        };
        for v in [joystick.vx, joystick.vy, joystick.vz, joystick.vyaw] {
            assert!(v.is_finite() && (-100.0..=100.0).contains(&v), "{joystick:?}");
        }
        assert!(arm && !disarm && nav == Nav::Manual);
    }
    if let Ok(Live::Order(order)) = ClientTopic::Orders.parse(data) {
        assert!(
            !matches!(order, Order::Unknown { .. } | Order::Velocity(_)),
            "{order:?}"
        );
    }
});
