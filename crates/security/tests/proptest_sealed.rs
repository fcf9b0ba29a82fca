//! Property tests: a sealed frame opens to the frame sealed, for any message, addresses,
//! counter and mode; any change to a sealed frame's bytes is refused; and opening never
//! panics, on any bytes.

use proptest::prelude::*;
use rovlink_security::counter::CounterStore;
use rovlink_security::sealed::{self, MAX_COUNTER, MAX_MESSAGE_BYTES, Sealed};
use rovlink_security::suite::Suite;
use rovlink_security::{Guard, Key, KeyRing, Refusal};
use rovlink_wire::frame::{self, CRC16, Frame};

fn ring() -> KeyRing {
    KeyRing::single(Key::from_bytes(&[0x42; 32]).unwrap())
        .with_broadcast(Key::from_bytes(&[0x24; 16]).unwrap())
}

/// Addresses with a key: the operator and a vehicle, either way, or to broadcast.
fn addresses() -> impl Strategy<Value = (u8, u8)> {
    (1u8..15, 0u8..3).prop_map(|(v, way)| match way {
        0 => (0, v),
        1 => (v, 0),
        _ => (0, 15),
    })
}

/// Rewrites a frame's CRC after its bytes were changed (the link layer's check passes; only
/// the tag can catch the change).
fn fix_crc(bytes: &mut [u8]) {
    let n = bytes.len();
    let crc = CRC16.checksum(&bytes[1..n - 2]);
    bytes[n - 2..].copy_from_slice(&crc.to_be_bytes());
}

proptest! {
    #[test]
    fn a_sealed_frame_opens_to_what_was_sealed(
        (src, dst) in addresses(),
        message in proptest::collection::vec(any::<u8>(), 0..=MAX_MESSAGE_BYTES),
        counter in 1u64..=MAX_COUNTER,
        encrypt in any::<bool>(),
    ) {
        let plain = frame::build(src, dst, &message).unwrap();
        let key = ring().for_frame(src, dst).unwrap().clone();
        let suite = Suite::new(&key);
        let secured = sealed::seal(&suite, &plain, counter, encrypt).unwrap();
        let f = Frame::new_checked(&secured[..]).unwrap();
        let p = Sealed::new_checked(f.payload()).unwrap();
        prop_assert!(p.verify(&suite, src, dst, counter));
        prop_assert!(!p.verify(&suite, src, dst, counter ^ 1));
        prop_assert_eq!(p.plain_message(&suite, src, dst, counter), message);
    }

    #[test]
    fn any_flipped_bit_is_refused(
        (src, dst) in addresses(),
        message in proptest::collection::vec(any::<u8>(), 0..64),
        encrypt in any::<bool>(),
        bit in any::<proptest::sample::Index>(),
    ) {
        let plain = frame::build(src, dst, &message).unwrap();
        let mut sender = Guard::new(ring(), encrypt, CounterStore::in_memory());
        let mut secured = sender.seal(&plain).unwrap();
        // Any bit of the address byte and of the payload (not the preamble, LEN or CRC).
        let span = 8 * (secured.len() - 5) + 8;
        let k = bit.index(span);
        let (byte, mask) = if k < 8 { (1, 1u8 << k) } else { (3 + (k - 8) / 8, 1u8 << (k % 8)) };
        secured[byte] ^= mask;
        fix_crc(&mut secured);
        let mut receiver = Guard::new(ring(), encrypt, CounterStore::in_memory());
        prop_assert!(receiver.open(&secured).is_err());
    }

    #[test]
    fn opening_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let mut receiver = Guard::new(ring(), false, CounterStore::in_memory());
        let _ = receiver.open(&bytes);
        // The same bytes as a well-formed frame's payload, marked secured.
        let mut payload = bytes.clone();
        payload.truncate(255);
        if let Some(b) = payload.first_mut() {
            *b |= 0x20;
        }
        let framed = frame::build(0, 1, &payload).unwrap();
        let verdict = receiver.open(&framed);
        prop_assert!(verdict.is_err());
        prop_assert!(verdict.err() != Some(Refusal::Unsecured) || payload.is_empty());
    }
}
