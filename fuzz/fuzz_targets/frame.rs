//! One link frame from any bytes: `Frame::new_checked`, `frame::Repr::parse`,
//! `MessageRepr::parse` and `MessageRepr::parse_lenient`.
//!
//! Checks:
//! - `frame::Repr::parse` and `MessageRepr::parse` fail whenever `check()` (preamble + CRC) does;
//! - a frame `MessageRepr::parse` accepts is emitted back by `emit_to_vec` to exactly its bytes
//!   (the first `total_len()` of the input);
//! - `parse_lenient` never panics on a length-checked frame; it keeps the addresses and payload
//!   and re-emits to the same bytes with the preamble and CRC made good (to exactly the input
//!   when `check()` passes); on a checked frame it agrees with `parse` (same value, or `Raw` with
//!   `parse`'s error);
//! - the lenient value survives the JSON Lines form (`to_line` then `parse_line`) unchanged and
//!   its one-line text form (`Display`) does not panic.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_wire::frame::{self, CRC16, Frame, PREAMBLE};
use rovlink_wire::message::Message;
use rovlink_wire::{MessageRepr, json};

fuzz_target!(|data: &[u8]| {
    let Ok(frame) = Frame::new_checked(data) else {
        assert!(
            data.len() < 3 || data.len() < usize::from(data[2]) + frame::OVERHEAD_BYTES,
            "new_checked rejects a buffer that holds the whole frame"
        );
        return;
    };
    let total = frame.total_len();
    assert!(total <= data.len());
    let bytes = &data[..total];
    assert_eq!(frame.payload(), &bytes[3..total - 2]);

    let checked = frame.check();
    assert_eq!(
        checked.is_ok(),
        bytes[0] == PREAMBLE && CRC16.checksum(&bytes[1..total - 2]) == frame.crc()
    );
    assert_eq!(frame::Repr::parse(&frame).is_ok(), checked.is_ok());

    let strict = MessageRepr::parse(&frame);
    if let Ok(repr) = &strict {
        assert!(checked.is_ok(), "parse accepted a frame that fails check()");
        assert_eq!(
            repr.validate(),
            Ok(()),
            "parse returned a value validate() rejects"
        );
        assert_eq!(repr.buffer_len(), total);
        let mut out = Vec::new();
        repr.emit_to_vec(&mut out)
            .expect("emit_to_vec refuses a parsed value");
        assert_eq!(out, bytes, "parse then emit_to_vec changes the frame");
    }

    let (lenient, err) = MessageRepr::parse_lenient(&frame);
    assert_eq!((lenient.src, lenient.dst), (frame.src(), frame.dst()));
    let mut out = Vec::new();
    lenient
        .emit_to_vec(&mut out)
        .expect("emit_to_vec refuses a leniently parsed value");
    assert_eq!(out.len(), total);
    assert_eq!(out[0], PREAMBLE);
    assert_eq!(
        &out[1..total - 2],
        &bytes[1..total - 2],
        "parse_lenient then emit changes addresses, LEN or payload"
    );
    if checked.is_ok() {
        assert_eq!(
            out, bytes,
            "parse_lenient then emit_to_vec changes a good frame"
        );
        match &strict {
            Ok(repr) => {
                assert_eq!(&lenient, repr, "parse_lenient and parse disagree");
                assert_eq!(err, None);
            }
            Err(e) => {
                assert_eq!(lenient.message, Message::Raw(frame.payload().to_vec()));
                assert_eq!(err.as_ref(), Some(e), "parse_lenient and parse disagree");
            }
        }
    }

    let line = json::to_line(&lenient);
    match json::parse_line(&line) {
        Ok(back) => assert_eq!(back, lenient, "JSON round trip changes the value: {line}"),
        Err(e) => panic!("parse_line rejects to_line's output: {e}\n{line}"),
    }
    let _ = lenient.to_string();
});
