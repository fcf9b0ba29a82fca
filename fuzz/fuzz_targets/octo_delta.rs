//! The octo-delta stream reader on arbitrary bytes: never panics; every delta message it
//! accepts re-encodes to bytes that decode to the same delta (the encoder may choose another
//! colour code parameter than the input did), and applying the stream to a receiver never
//! panics.
//!
//! Input: byte 0 even: the bytes are a whole stream. Byte 0 odd: a valid header (coarse depth
//! from byte 1) followed by one message of kind byte 2 whose payload is the rest, framed with a
//! correct CRC, so the payload parsers are reached.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_octo::delta::{self, Message, Receiver, ViewSpec};

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
            let (back, n) = delta::decode_message(&header.spec, &again, 0).expect("re-encoded delta decodes");
            assert_eq!(n, again.len());
            assert_eq!(&back, &m.message, "delta re-encodes to the same delta");
        }
        rx.apply(&m.message);
    }
});
