//! The one device grammar: `DeviceSpec`'s `FromStr` and the MAVLink endpoint reader, from any
//! text (bytes that are not UTF-8 are read lossily).
//!
//! Checks: neither panics; an accepted spec prints (`Display`) to its canonical spelling, which
//! parses back to the same spec and prints the same again; an error is one line that says what
//! was expected and what was found; every endpoint the MAVLink reader accepts is a spec of the
//! grammar, and the reader's errors name the text.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_link::device::DeviceSpec;
use rovlink_field::mavlink::parse_endpoint;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    match text.parse::<DeviceSpec>() {
        Ok(spec) => {
            let canonical = spec.to_string();
            let again: DeviceSpec = canonical.parse().expect("the canonical spelling parses");
            assert_eq!(again, spec, "the canonical spelling reads back differently");
            assert_eq!(again.to_string(), canonical, "the canonical spelling is not stable");
        }
        Err(error) => {
            let message = error.to_string();
            assert!(message.starts_with("expected "), "{message}");
            assert!(message.contains(", found "), "{message}");
            assert!(!message.contains('\n'), "{message}");
        }
    }
    match parse_endpoint(&text) {
        Ok(spec) => assert_eq!(text.parse::<DeviceSpec>().ok(), Some(spec)),
        Err(error) => {
            let message = error.to_string();
            assert!(message.starts_with("mavlink endpoint '"), "{message}");
        }
    }
});
