//! One JSON Lines line from any UTF-8 text: `json::parse_line` (input that is not UTF-8 is
//! skipped).
//!
//! Checks, for every line `parse_line` accepts:
//! - the value passes `validate()` and `emit_to_vec` succeeds, giving a frame of `buffer_len()`
//!   bytes that passes `Frame::new_checked` and `check()`;
//! - the bytes parse back with `MessageRepr::parse` to an equal value. The one exception is
//!   inherent in the format: a `raw` payload that happens to be a valid message parses back as
//!   that message; then re-emitting it must give the same bytes. A `raw` payload that is not a
//!   valid message comes back equal through `parse_lenient`, with `parse`'s error;
//! - `to_line` of the value parses to the same value again, and `to_line` is stable on it.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_wire::frame::Frame;
use rovlink_wire::message::Message;
use rovlink_wire::{MessageRepr, json};

fuzz_target!(|data: &[u8]| {
    let Ok(line) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(repr) = json::parse_line(line) else {
        return;
    };
    assert_eq!(
        repr.validate(),
        Ok(()),
        "parse_line returned a value validate() rejects"
    );

    let mut bytes = Vec::new();
    repr.emit_to_vec(&mut bytes)
        .expect("emit_to_vec refuses a value parse_line accepted");
    assert_eq!(bytes.len(), repr.buffer_len());
    let frame = Frame::new_checked(&bytes[..]).expect("emitted frame fails new_checked");
    assert_eq!(
        frame.total_len(),
        bytes.len(),
        "emitted frame's LEN is wrong"
    );
    frame.check().expect("emitted frame fails check()");

    match (&repr.message, MessageRepr::parse(&frame)) {
        (Message::Raw(_), Ok(typed)) => {
            // A raw payload that is a valid message: the bytes are what matter.
            assert_eq!((typed.src, typed.dst), (repr.src, repr.dst));
            let mut again = Vec::new();
            typed.emit_to_vec(&mut again).unwrap();
            assert_eq!(again, bytes, "raw payload re-emitted as a message changes");
        }
        (Message::Raw(_), Err(e)) => {
            let (lenient, err) = MessageRepr::parse_lenient(&frame);
            assert_eq!(lenient, repr, "raw payload does not come back as itself");
            assert_eq!(err, Some(e));
        }
        (_, Ok(back)) => assert_eq!(back, repr, "JSON -> bytes -> parse changes the value"),
        (_, Err(e)) => panic!("bytes emitted from {line:?} do not parse back: {e}"),
    }

    let text = json::to_line(&repr);
    let back = json::parse_line(&text)
        .unwrap_or_else(|e| panic!("parse_line rejects to_line's output: {e}\n{text}"));
    assert_eq!(
        back, repr,
        "to_line then parse_line changes the value: {text}"
    );
    assert_eq!(json::to_line(&back), text, "to_line is not stable");
});
