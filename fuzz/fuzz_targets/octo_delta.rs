//! The octo-delta stream reader on arbitrary bytes: never panics; a stream it accepts re-encodes
//! (every delta message) to the same bytes, and applying it to a receiver never panics.
//!
//! Input: byte 0 even: the bytes are a whole stream. Byte 0 odd: a valid header (coarse depth
//! from byte 1) followed by one message of kind byte 2 whose payload is the rest, framed with a
//! correct CRC, so the payload parsers are reached.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink::octo::delta::{self, Message, Receiver, ViewSpec};

fuzz_target!(|data: &[u8]| {
    let owned;
    let stream = match data {
        [mode, depth, kind, payload @ ..] if mode & 1 == 1 => {
            let spec = ViewSpec {
                resolution_m: 0.1,
                coarse_depth: 1 + u32::from(*depth % 16),
                roi: None,
            };
            let mut s = delta::encode_header(&spec);
            s.extend(delta::frame_message(kind % 3, 7, payload));
            owned = s;
            &owned[..]
        }
        _ => data,
    };
    let Ok((header, messages)) = delta::decode_stream(stream) else {
        return;
    };
    let mut rx = Receiver::new(header.spec);
    for m in &messages {
        if let Message::Delta { scan, delta: d } = &m.message {
            let again = delta::encode_delta(&header.spec, *scan, d);
            let start = m.offset as usize;
            assert_eq!(&again[..], &stream[start..start + m.bytes], "delta re-encodes");
        }
        rx.apply(&m.message);
    }
});
