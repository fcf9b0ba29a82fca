//! A ROV -> operator message payload from any bytes: `rov::Packet::new_checked` and
//! `rov::Repr::parse`.
//!
//! Checks, for every payload `parse` accepts:
//! - the value passes `validate()` and `buffer_len()` equals the payload length;
//! - `emit` into a buffer of `buffer_len()` bytes gives back the payload exactly, whatever the
//!   buffer held before (all-zero and all-one buffers), and the result parses to the same value;
//! - inside a frame from a vehicle (src 1) the value survives the JSON Lines form unchanged.

#![no_main]

#[path = "common/payload.rs"]
mod payload;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    payload::check(1, 0, data);
});
