//! The checks the `rov` and `operator` targets share, written once over the message a frame
//! from `src` carries (`Message::parse_payload` is `Packet::new_checked` + `Repr::parse` of the
//! type the source implies).

use rovlink_wire::message::Message;
use rovlink_wire::{MessageRepr, json};

/// For every payload the parser accepts: the value validates, `buffer_len` is the payload
/// length, `emit` gives back the payload exactly whatever the buffer held before (all-zero and
/// all-one buffers), the bytes parse to the same value again, and the JSON Lines form keeps it.
pub fn check(src: u8, dst: u8, data: &[u8]) {
    let Ok(message) = Message::parse_payload(src, data) else {
        return;
    };
    let msg = MessageRepr { src, dst, message };
    assert_eq!(
        msg.validate(),
        Ok(()),
        "parse returned a value validate() rejects"
    );
    assert_eq!(
        msg.message.buffer_len(),
        data.len(),
        "buffer_len differs from the payload length"
    );
    for fill in [0x00u8, 0xff] {
        let mut buf = vec![fill; msg.message.buffer_len()];
        msg.message.emit(&mut buf);
        assert_eq!(
            buf, data,
            "parse then emit (buffer of 0x{fill:02x}) changes the payload"
        );
    }
    let again = Message::parse_payload(src, data).expect("parses twice");
    assert_eq!(again, msg.message);
    let line = json::to_line(&msg);
    match json::parse_line(&line) {
        Ok(back) => assert_eq!(back, msg, "JSON round trip changes the value: {line}"),
        Err(e) => panic!("parse_line rejects to_line's output: {e}\n{line}"),
    }
}
