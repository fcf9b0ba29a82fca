//! The octo-delta stream reader on arbitrary bytes: never panics; a stream it accepts re-encodes
//! (every delta message) to the same bytes, and applying it to a receiver never panics.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink::octo::delta::{self, Message, Receiver};

fuzz_target!(|data: &[u8]| {
    let Ok((header, messages)) = delta::decode_stream(data) else {
        return;
    };
    let mut rx = Receiver::new(header.spec);
    for m in &messages {
        if let Message::Delta { scan, delta: d } = &m.message {
            let again = delta::encode_delta(&header.spec, *scan, d);
            let start = m.offset as usize;
            assert_eq!(
                &again[..],
                &data[start..start + m.bytes],
                "delta re-encodes"
            );
        }
        rx.apply(&m.message);
    }
});
