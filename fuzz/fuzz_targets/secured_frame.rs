//! Secured frames from any bytes: `Guard::open` (in-memory counters, a fixed key) and
//! `Sealed::new_checked` with every getter.
//!
//! Input: byte 0 is a mode (bit 0: wrap the rest in a good link frame, byte 1 its address
//! byte, so that the payload checks are reached past the CRC; bit 1: encrypt in the round
//! trip); the rest is a link frame (or, wrapped, an address byte and a payload).
//!
//! Checks:
//! - `Sealed::new_checked` on the bytes as a payload never panics; a payload it takes has the
//!   S bit, a counter of at most 14 bits, and its header, message and tag tile it; `verify`
//!   and `plain_message` never panic;
//! - `Guard::open` never panics; a frame it takes opens to a link frame of the same SRC and
//!   DST, 6 bytes shorter, whose counter has the low bits the frame carries, and the same
//!   frame a second time is refused as a replay; a plain payload is refused as `Unsecured`;
//! - the frame's payload, sealed by one guard, opens in another to the same plain frame with
//!   counter 1 (or sealing is refused for the reasons it may be: no key for the pair, a message
//!   too long).

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_security::counter::CounterStore;
use rovlink_security::guard::{Guard, Refusal, SealError};
use rovlink_security::key::{Key, KeyRing};
use rovlink_security::sealed::{
    MAX_COUNTER, MAX_MESSAGE_BYTES, OVERHEAD_BYTES, Sealed, SealedError, is_sealed,
};
use rovlink_security::suite::Suite;
use rovlink_wire::frame::{self, Frame, MAX_PAYLOAD_BYTES};

/// RFC 4493's key, the key of the secured-frame test vectors (so their seeds open).
const KEY: [u8; 16] = [
    0x2b, 0x7e, 0x15, 0x16, 0x28, 0xae, 0xd2, 0xa6, 0xab, 0xf7, 0x15, 0x88, 0x09, 0xcf, 0x4f, 0x3c,
];

fn ring() -> KeyRing {
    let key = Key::from_bytes(&KEY).expect("16 bytes");
    KeyRing::single(key.clone()).with_broadcast(key)
}

fn guard(encrypt: bool) -> Guard {
    Guard::new(ring(), encrypt, CounterStore::in_memory())
}

/// `Sealed::new_checked` and its getters on `payload`.
fn view(payload: &[u8]) {
    let Ok(p) = Sealed::new_checked(payload) else {
        assert!(payload.len() < OVERHEAD_BYTES || !is_sealed(payload));
        return;
    };
    assert!(is_sealed(payload));
    assert!(p.counter_low() < 1 << 14);
    assert_eq!(p.message().len() + OVERHEAD_BYTES, payload.len());
    assert_eq!(p.tag(), &payload[payload.len() - 4..]);
    let _ = p.encrypted();
    let suite = Suite::new(&Key::from_bytes(&KEY).expect("16 bytes"));
    let counter = u64::from(p.counter_low()).max(1);
    let _ = p.verify(&suite, 0, 1, counter);
    assert_eq!(
        p.plain_message(&suite, 0, 1, counter).len(),
        p.message().len()
    );
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    view(rest);
    let bytes = if mode & 1 == 1 {
        let Some((&address, payload)) = rest.split_first() else {
            return;
        };
        let payload = &payload[..payload.len().min(MAX_PAYLOAD_BYTES)];
        frame::build(address >> 4, address & 0x0f, payload).expect("a payload that fits")
    } else {
        rest.to_vec()
    };

    let mut rx = guard(false);
    let opened = rx.open(&bytes);
    let Ok(f) = Frame::new_checked(&bytes[..]) else {
        assert_eq!(opened.err(), Some(Refusal::Malformed));
        return;
    };
    view(f.payload());
    match opened {
        Ok((opened, stored)) => {
            assert!(stored.is_none(), "an in-memory store cannot fail");
            let plain = Frame::new_checked(&opened.frame[..]).expect("an opened frame is a frame");
            assert!(plain.check().is_ok());
            assert_eq!((plain.src(), plain.dst()), (f.src(), f.dst()));
            assert_eq!(plain.payload_len() + OVERHEAD_BYTES, f.payload_len());
            assert!((1..=MAX_COUNTER).contains(&opened.counter));
            let carried = Sealed::new_checked(f.payload()).expect("an opened frame is sealed");
            assert_eq!(opened.counter & 0x3fff, u64::from(carried.counter_low()));
            assert_eq!(opened.encrypted, carried.encrypted());
            assert_eq!(rx.open(&bytes).err(), Some(Refusal::Replay), "taken twice");
        }
        Err(Refusal::Unsecured) => assert!(!is_sealed(f.payload())),
        Err(Refusal::Malformed) => assert!(f.payload_len() < OVERHEAD_BYTES),
        Err(_) => assert!(is_sealed(f.payload())),
    }

    // The payload as a message: sealed, then opened by another node.
    let Ok(plain) = frame::build(f.src(), f.dst(), f.payload()) else {
        return;
    };
    match guard(mode & 2 != 0).seal(&plain) {
        Ok(sealed) => {
            assert_eq!(sealed.len(), plain.len() + OVERHEAD_BYTES);
            let (back, _) = guard(false)
                .open(&sealed)
                .expect("a sealed frame opens under the same key");
            assert_eq!(back.frame, plain);
            assert_eq!((back.counter, back.encrypted), (1, mode & 2 != 0));
        }
        Err(SealError::NoKey { src, dst }) => {
            assert!(
                ring().for_frame(src, dst).is_none(),
                "{src}->{dst} has a key"
            )
        }
        Err(SealError::Frame(SealedError::TooLong(n))) => assert!(n > MAX_MESSAGE_BYTES),
        Err(e) => panic!("sealing {} bytes: {e}", plain.len()),
    }
});
