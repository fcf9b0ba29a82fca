//! The DEBT decoder on arbitrary bytes: never panics; a stream it accepts decodes to an image of
//! the size its header states, and every prefix of it decodes too, and so does the stream with
//! a byte range after the header lost (segmented streams drop that range's segments).
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_debt::{Header, decode, decode_with_loss};

fuzz_target!(|data: &[u8]| {
    // Keep each run fast: images up to 64 x 64 (the decoder's cost grows with the area).
    let Ok(header) = Header::read(data) else {
        // Only a version 5 stream cut inside its features decodes without its whole header
        // (to the flat picture of the size its base header states).
        assert!(decode(data).is_err() || data[0] == 0xd5);
        return;
    };
    if header.width * header.height > 64 * 64 {
        return;
    }
    let img = decode(data).expect("a stream with a valid header decodes");
    assert_eq!((img.width, img.height), (header.width, header.height));
    assert_eq!(img.channels, if header.gray { 1 } else { 3 });
    assert_eq!(img.data.len(), img.width * img.height * img.channels);
    for cut in [header.len(), (header.len() + data.len()) / 2] {
        if cut <= data.len() {
            assert!(decode(&data[..cut]).is_ok());
        }
    }
    // A lost range chosen by the data itself, after the header.
    let start = header.len() + usize::from(data[data.len() - 1]);
    let lost = [start..start + 1 + usize::from(data[0] & 0x3f)];
    assert!(decode_with_loss(data, &lost).is_ok());
});
