//! An operator -> ROV message payload from any bytes: `operator::Packet::new_checked` and
//! `operator::Repr::parse`.
//!
//! Checks, for every payload `parse` accepts:
//! - the value passes `validate()` and `buffer_len()` equals the payload length (11);
//! - `emit` into a buffer of `buffer_len()` bytes gives back the payload exactly, whatever the
//!   buffer held before (all-zero and all-one buffers), and the result parses to the same value;
//! - inside a frame from the operator (src 0) the value survives the JSON Lines form unchanged.

#![no_main]

#[path = "common/payload.rs"]
mod payload;

use libfuzzer_sys::fuzz_target;
use rovlink_wire::operator;

fuzz_target!(|data: &[u8]| {
    if operator::Packet::new_checked(data).is_err() {
        assert_ne!(data.len(), operator::MESSAGE_BYTES);
    }
    payload::check(0, 1, data);
});
