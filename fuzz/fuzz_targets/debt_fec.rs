//! The erasure-code repair and the trunk-loss decoder on arbitrary bytes: never panic; the
//! repaired data never claims more than the stream or its stated code holds, a stream the
//! repair calls whole decodes, and with nothing lost a stream with parity repairs to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_debt::{Header, decode_trunks, fec};

fuzz_target!(|data: &[u8]| {
    // The first two bytes choose the trunk size (16..=79) and which trunks are lost.
    let [t, mask, stream @ ..] = data else {
        return;
    };
    let trunk = 16 + usize::from(t % 64);
    let lost: Vec<usize> = (0..8).filter(|i| mask & (1 << i) != 0).map(|i| i * 3).collect();
    let repaired = fec::repair(stream, trunk, &lost);
    let stated = repaired.fec.map_or(0, |f| f.data_bytes);
    assert!(repaired.data.len() <= stream.len().max(stated));
    assert!(repaired.lost.iter().all(|r| r.start < r.end));
    if let Some(whole) = repaired.whole() {
        assert_eq!(whole.len() % trunk, 0);
    }
    // Decoding costs the picture's area: only small ones.
    let small = Header::read(stream).map_or(true, |h| h.width * h.height <= 64 * 64);
    if small {
        let _ = decode_trunks(stream, trunk, &lost);
    }
    if let Ok(h) = Header::read(stream)
        && let Some(code) = h.fec
        && code.trunk_bytes == trunk
        && code.total_bytes() == stream.len()
        && h.width * h.height <= 64 * 64
    {
        let none = fec::repair(stream, trunk, &[]);
        assert!(none.lost.is_empty());
    }
});
