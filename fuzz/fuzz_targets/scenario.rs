//! A scenario from any bytes: `Scenario::parse`, then, if it is accepted, `Scenario::cycle`.
//!
//! Input: the bytes as the text of a scenario file (not UTF-8: nothing to parse). Model files
//! are looked up in a folder that does not exist, so only preset names and model objects give
//! a model.
//!
//! Checks:
//! - an accepted scenario has one operator (address 0), at least one vehicle, every node on a
//!   medium, every medium with at least two nodes of the scenario;
//! - its cycle has one slot per vehicle, in address order, each starting where the previous
//!   one ended, each of a finite length within the slot bounds, and the cycle's length is
//!   their sum.

#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use rovlink_rcp::Role;
use rovlink_rcp::scenario::Scenario;
use rovlink_rcp::session::{MAX_IPG_S, MIN_IPG_S};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(scenario) = Scenario::parse(text, Path::new("/nonexistent-rovlink-fuzz")) else {
        return;
    };
    let operators = scenario.nodes.iter().filter(|n| n.role == Role::Operator);
    assert_eq!(operators.map(|n| n.address).collect::<Vec<_>>(), [0]);
    let vehicles = scenario.vehicles();
    assert!(!vehicles.is_empty());
    for node in &scenario.nodes {
        assert!(!scenario.interfaces(node.address).is_empty());
    }
    for medium in &scenario.media {
        assert!(medium.nodes.len() >= 2);
        assert!(medium.nodes.iter().all(|&a| scenario.node(a).is_some()));
    }
    let cycle = scenario.cycle();
    let addresses: Vec<u8> = cycle.iter().map(|s| s.address).collect();
    assert_eq!(addresses, vehicles);
    let mut start_s = 0.0;
    for slot in &cycle {
        assert_eq!(slot.start_s, start_s);
        assert!(slot.length_s.is_finite());
        assert!((MIN_IPG_S..=MAX_IPG_S).contains(&slot.length_s), "{slot:?}");
        start_s += slot.length_s;
    }
    assert_eq!(scenario.cycle_s(), cycle.iter().map(|s| s.length_s).sum::<f64>());
});
