//! An operator -> ROV message payload from any bytes: `operator::Packet::new_checked` and
//! `operator::Repr::parse`.
//!
//! Checks, for every payload `parse` accepts:
//! - the value passes `validate()` and `buffer_len()` equals the payload length (11);
//! - `emit` into a buffer of `buffer_len()` bytes gives back the payload exactly, whatever the
//!   buffer held before (all-zero and all-one buffers), and the result parses to the same value;
//! - inside a frame from the operator (src 0) the value survives the JSON Lines form unchanged.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink::wire::message::Message;
use rovlink::wire::{MessageRepr, json, operator};

fuzz_target!(|data: &[u8]| {
    let Ok(packet) = operator::Packet::new_checked(data) else {
        assert_ne!(data.len(), operator::MESSAGE_BYTES);
        return;
    };
    let Ok(repr) = operator::Repr::parse(&packet) else {
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
        repr.emit(&mut operator::Packet::new_unchecked(&mut buf[..]));
        assert_eq!(
            buf, data,
            "parse then emit (buffer of 0x{fill:02x}) changes the payload"
        );
    }
    let again = operator::Repr::parse(&operator::Packet::new_checked(data).unwrap()).unwrap();
    assert_eq!(again, repr);

    let msg = MessageRepr {
        src: 0,
        dst: 1,
        message: Message::Operator(repr),
    };
    let line = json::to_line(&msg);
    match json::parse_line(&line) {
        Ok(back) => assert_eq!(back, msg, "JSON round trip changes the value: {line}"),
        Err(e) => panic!("parse_line rejects to_line's output: {e}\n{line}"),
    }
});
