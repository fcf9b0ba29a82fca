//! `--orders` text from any bytes: `console::parse_orders` (the simulation's reading of a whole
//! file) and `console::parse_line` (one line, as the real-time reader reads it).
//!
//! Checks: no panic; the orders come in file order with times that never go back and stay
//! within a week; every warning names the input and a line; a line `parse_orders` takes alone
//! is what `parse_line` takes, and `parse_addressed_line` too, with a vehicle in 1..=14.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_field::console::{self, MAX_WARNINGS};
use rovlink_rcp::session::MAX_DURATION_S;

fuzz_target!(|data: &[u8]| {
    let (orders, warnings) = console::parse_orders("in", data);
    assert!(warnings.len() <= MAX_WARNINGS + 1, "warnings unbounded");
    for warning in &warnings {
        assert!(warning.starts_with("in: "), "a warning without its input: {warning}");
    }
    let mut previous_s = 0.0;
    for (t, _) in &orders {
        let t_s = t.as_secs_f64();
        assert!(t_s >= previous_s, "an order overtook the one before it");
        assert!(t_s <= MAX_DURATION_S + 1e-6, "an order due after a week");
        previous_s = t_s;
    }
    if let Ok(line) = std::str::from_utf8(data)
        && !line.contains('\n')
        && !line.trim().is_empty()
        && line.len() <= console::MAX_LINE_BYTES
    {
        let alone = console::parse_line(line.strip_suffix('\r').unwrap_or(line));
        assert_eq!(alone.is_ok(), orders.len() == 1, "{line:?}");
        if let Ok((_, live)) = alone {
            assert_eq!(orders[0].1, live);
        }
        // The network form reads the same line, with the vehicle it names (1..=14, if any).
        let addressed = console::parse_addressed_line(line.strip_suffix('\r').unwrap_or(line));
        assert_eq!(addressed.is_ok(), orders.len() == 1, "{line:?}");
        if let Ok((_, vehicle, live)) = addressed {
            assert_eq!(orders[0].1, live);
            assert!(vehicle.is_none_or(|v| (1..=14).contains(&v)), "{line:?}");
        }
    }
});
