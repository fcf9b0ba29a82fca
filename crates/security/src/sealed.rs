//! The secured frame (docs/wire-extensions.md, "Secured frames, version 1"): a link frame of
//! wire.md whose payload is
//!
//! ```text
//! offset     size   field
//! 0          1      E:1 C13:1 S:1 (always 1) C12..C8:5
//! 1          1      C7..C0
//! 2          n      the message (wire.md's operator or ROV message), AES-CTR encrypted when E
//! 2+n        4      TAG: AES-CMAC truncated to 4 bytes
//! ```
//!
//! C is the low [`COUNTER_LOW_BITS`] bits of the sender's 48-bit frame counter for this
//! (SRC, DST); the receiver restores the rest ([`crate::counter`]). S marks the frame as
//! secured: a version-0 parser reads the byte as a ROV status type of 32..=63 or an operator
//! order type of 8..=15, both reserved, so it reports an unknown type, never something else;
//! no plain message has S set.
//!
//! TAG = the first 4 bytes of AES-CMAC(K_mac, V D A C48 LEN P), where V is the version (1), D
//! the direction (0 from the operator, 1 from a vehicle), A the frame's address byte
//! (SRC:4 DST:4), C48 the full counter (6 bytes, big-endian), LEN the payload length and P
//! the payload before the tag, as sent (ciphertext when E): encrypt-then-MAC. The keystream's
//! first counter block is V D A C48 followed by 7 zero bytes. K_mac and K_enc are derived from
//! the frame key ([`crate::suite`]).
//!
//! No-panic contract: [`Sealed::new_checked`] checks the length once; every getter after it
//! stays in bounds, on any input.

use rovlink_wire::frame::{self, Frame, MAX_PAYLOAD_BYTES};

use crate::suite::{Suite, TAG_BYTES};
use rovlink_base::secret::constant_time_eq;

/// The version of the construction, the first byte of what the tag covers.
pub const VERSION: u8 = 1;
/// Bytes before the message: the flags and the counter's low bits.
pub const HEADER_BYTES: usize = 2;
/// Bytes a secured frame adds to the plain one.
pub const OVERHEAD_BYTES: usize = HEADER_BYTES + TAG_BYTES;
/// The longest message a secured frame carries.
pub const MAX_MESSAGE_BYTES: usize = MAX_PAYLOAD_BYTES - OVERHEAD_BYTES;
/// How many low bits of the counter a frame carries.
pub const COUNTER_LOW_BITS: u32 = 14;
/// The highest counter a sender may use (48 bits).
pub const MAX_COUNTER: u64 = (1 << 48) - 1;

/// The S bit: the payload is a secured frame's.
const SECURED: u8 = 0x20;
/// The E bit: the message is encrypted.
const ENCRYPTED: u8 = 0x80;
/// The counter's bit 13, in the flags byte.
const C13: u8 = 0x40;

/// Byte ranges of the secured payload; the tag is the last [`TAG_BYTES`].
mod field {
    pub const FLAGS: usize = 0;
    pub const COUNTER_LOW: usize = 1;
    pub const MESSAGE_START: usize = 2;
}

/// A read view of a secured frame's payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sealed<T: AsRef<[u8]>> {
    buffer: T,
}

/// What is wrong with a payload that should be a secured one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SealedError {
    /// Shorter than the header and the tag.
    #[error("secured payload: need at least {OVERHEAD_BYTES} bytes, found {0}")]
    Truncated(usize),
    /// The S bit is clear: a plain message.
    #[error("not a secured frame (byte 0 = {0:#04x}: S bit clear)")]
    Plain(u8),
    /// [`seal`]: the message does not fit with the overhead.
    #[error("message of {0} bytes: a secured frame carries at most {MAX_MESSAGE_BYTES}")]
    TooLong(usize),
    /// [`seal`]: the input is not a whole link frame.
    #[error("not a link frame: {0}")]
    NotAFrame(String),
}

/// True when `payload` is marked as a secured frame's (the S bit), whatever else it holds.
pub fn is_sealed(payload: &[u8]) -> bool {
    payload.first().is_some_and(|b| b & SECURED != 0)
}

impl<T: AsRef<[u8]>> Sealed<T> {
    /// Wraps a payload after checking its length and the S bit.
    pub fn new_checked(buffer: T) -> Result<Sealed<T>, SealedError> {
        let bytes = buffer.as_ref();
        if bytes.len() < OVERHEAD_BYTES {
            return Err(SealedError::Truncated(bytes.len()));
        }
        if !is_sealed(bytes) {
            return Err(SealedError::Plain(bytes[field::FLAGS]));
        }
        Ok(Sealed { buffer })
    }

    /// True when the message is encrypted.
    pub fn encrypted(&self) -> bool {
        self.buffer.as_ref()[field::FLAGS] & ENCRYPTED != 0
    }

    /// The counter's low [`COUNTER_LOW_BITS`] bits.
    pub fn counter_low(&self) -> u16 {
        let b = self.buffer.as_ref();
        let flags = b[field::FLAGS];
        (u16::from(flags & C13 != 0) << 13)
            | (u16::from(flags & 0x1f) << 8)
            | u16::from(b[field::COUNTER_LOW])
    }

    /// The message as sent (ciphertext when encrypted).
    pub fn message(&self) -> &[u8] {
        let b = self.buffer.as_ref();
        &b[field::MESSAGE_START..b.len() - TAG_BYTES]
    }

    /// The tag.
    pub fn tag(&self) -> &[u8] {
        let b = self.buffer.as_ref();
        &b[b.len() - TAG_BYTES..]
    }

    /// What the tag covers of the payload: everything before it.
    fn covered(&self) -> &[u8] {
        let b = self.buffer.as_ref();
        &b[..b.len() - TAG_BYTES]
    }

    /// True when the tag is right for a frame from `src` to `dst` with full counter
    /// `counter`.
    pub fn verify(&self, suite: &Suite, src: u8, dst: u8, counter: u64) -> bool {
        let len = self.buffer.as_ref().len();
        let expected = suite.tag(&[&prefix(src, dst, counter), &[len as u8], self.covered()]);
        constant_time_eq(&expected, self.tag())
    }

    /// The plain message (decrypted when encrypted); call after [`Sealed::verify`].
    pub fn plain_message(&self, suite: &Suite, src: u8, dst: u8, counter: u64) -> Vec<u8> {
        let mut message = self.message().to_vec();
        if self.encrypted() {
            suite.apply_keystream(iv(src, dst, counter), &mut message);
        }
        message
    }
}

/// The direction byte: 0 from the operator, 1 from a vehicle.
fn direction(src: u8) -> u8 {
    u8::from(src != frame::ADDR_OPERATOR)
}

/// V D A C48: what both the tag and the keystream start from.
fn prefix(src: u8, dst: u8, counter: u64) -> [u8; 9] {
    let mut p = [0u8; 9];
    p[0] = VERSION;
    p[1] = direction(src);
    p[2] = (src << 4) | (dst & 0x0f);
    p[3..9].copy_from_slice(&counter.to_be_bytes()[2..8]);
    p
}

/// The keystream's first counter block.
fn iv(src: u8, dst: u8, counter: u64) -> [u8; 16] {
    let mut iv = [0u8; 16];
    iv[..9].copy_from_slice(&prefix(src, dst, counter));
    iv
}

/// Seals the plain link frame `plain` with `suite` and counter `counter` (at most
/// [`MAX_COUNTER`]; the caller never reuses one under a key): the secured frame's bytes.
pub fn seal(
    suite: &Suite,
    plain: &[u8],
    counter: u64,
    encrypt: bool,
) -> Result<Vec<u8>, SealedError> {
    let frame = Frame::new_checked(plain).map_err(|e| SealedError::NotAFrame(e.to_string()))?;
    let (src, dst) = (frame.src(), frame.dst());
    let message = frame.payload();
    if message.len() > MAX_MESSAGE_BYTES {
        return Err(SealedError::TooLong(message.len()));
    }
    let low = (counter & ((1 << COUNTER_LOW_BITS) - 1)) as u16;
    let mut flags = SECURED | ((low >> 8) as u8 & 0x1f);
    if low & (1 << 13) != 0 {
        flags |= C13;
    }
    if encrypt {
        flags |= ENCRYPTED;
    }
    let mut payload = Vec::with_capacity(message.len() + OVERHEAD_BYTES);
    payload.push(flags);
    payload.push(low as u8);
    payload.extend_from_slice(message);
    if encrypt {
        suite.apply_keystream(iv(src, dst, counter), &mut payload[field::MESSAGE_START..]);
    }
    let len = payload.len() + TAG_BYTES;
    let tag = suite.tag(&[&prefix(src, dst, counter), &[len as u8], &payload]);
    payload.extend_from_slice(&tag);
    frame::build(src, dst, &payload).map_err(|e| SealedError::NotAFrame(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::key::Key;

    fn suite() -> Suite {
        Suite::new(&Key::from_bytes(&[0x2bu8; 16]).unwrap())
    }

    #[test]
    fn the_counter_low_bits_round_trip_through_the_flags() {
        let s = suite();
        let plain = frame::build(0, 1, &[0u8; 11]).unwrap();
        for counter in [
            0u64,
            1,
            255,
            256,
            8191,
            8192,
            16383,
            16384,
            0x1234_5678_9abc,
        ] {
            let sealed = seal(&s, &plain, counter, false).unwrap();
            let f = Frame::new_checked(&sealed[..]).unwrap();
            let p = Sealed::new_checked(f.payload()).unwrap();
            assert_eq!(u64::from(p.counter_low()), counter & 0x3fff);
            assert!(p.verify(&s, 0, 1, counter));
            assert!(!p.verify(&s, 0, 1, counter + 1));
            assert!(!p.verify(&s, 0, 2, counter));
            assert!(!p.encrypted());
        }
    }

    #[test]
    fn encryption_hides_the_message_and_decrypts() {
        let s = suite();
        let message: Vec<u8> = (0..57).collect();
        let plain = frame::build(3, 0, &message).unwrap();
        let sealed = seal(&s, &plain, 77, true).unwrap();
        assert_eq!(sealed.len(), plain.len() + OVERHEAD_BYTES);
        let f = Frame::new_checked(&sealed[..]).unwrap();
        let p = Sealed::new_checked(f.payload()).unwrap();
        assert!(p.encrypted());
        assert_ne!(p.message(), &message[..]);
        assert!(p.verify(&s, 3, 0, 77));
        assert_eq!(p.plain_message(&s, 3, 0, 77), message);
    }

    #[test]
    fn plain_messages_never_look_sealed_and_short_payloads_are_refused() {
        // Every ROV status type of wire.md (0) and the extension (1), every order type 0..=3.
        for b in [0x00u8, 0x01, 0xc1, 0x80, 0x84, 0x88, 0x8c, 0x4c] {
            assert!(!is_sealed(&[b]));
        }
        assert_eq!(
            Sealed::new_checked(&[0x20u8; 5][..]),
            Err(SealedError::Truncated(5))
        );
        assert_eq!(
            Sealed::new_checked(&[0u8; 9][..]),
            Err(SealedError::Plain(0))
        );
        let long = frame::build(0, 1, &[0u8; 250]).unwrap();
        assert_eq!(
            seal(&suite(), &long, 1, false),
            Err(SealedError::TooLong(250))
        );
    }
}
