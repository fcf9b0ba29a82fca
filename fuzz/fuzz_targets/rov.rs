//! A ROV -> operator message payload from any bytes: `rov::Packet::new_checked` and
//! `rov::Repr::parse`.
//!
//! Checks, for every payload `parse` accepts:
//! - the value passes `validate()` and `buffer_len()` equals the payload length;
//! - `emit` into a buffer of `buffer_len()` bytes gives back the payload exactly, whatever the
//!   buffer held before (all-zero and all-one buffers), and the result parses to the same value;
//! - inside a frame from a vehicle (src 1) the value survives the JSON Lines form unchanged.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink::wire::message::Message;
use rovlink::wire::{MessageRepr, json, rov};

fuzz_target!(|data: &[u8]| {
    let Ok(packet) = rov::Packet::new_checked(data) else {
        return;
    };
    let Ok(repr) = rov::Repr::parse(&packet) else {
        return;
    };
    assert_eq!(
        repr.validate(),
        Ok(()),
        "parse returned a value validate() rejects"
    );
    assert_eq!(
        repr.buffer_len(),
        data.len(),
        "buffer_len differs from the payload length"
    );

    for fill in [0x00u8, 0xff] {
        let mut buf = vec![fill; repr.buffer_len()];
        repr.emit(&mut rov::Packet::new_unchecked(&mut buf[..]));
        assert_eq!(
            buf, data,
            "parse then emit (buffer of 0x{fill:02x}) changes the payload"
        );
    }
    let again = rov::Repr::parse(&rov::Packet::new_checked(data).unwrap()).unwrap();
    assert_eq!(again, repr);

    let msg = MessageRepr {
        src: 1,
        dst: 0,
        message: Message::Rov(repr),
    };
    let line = json::to_line(&msg);
    match json::parse_line(&line) {
        Ok(back) => assert_eq!(back, msg, "JSON round trip changes the value: {line}"),
        Err(e) => panic!("parse_line rejects to_line's output: {e}\n{line}"),
    }
});
