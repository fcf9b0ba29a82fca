//! The link frame: what crosses a modem, a serial line or a pipe.
//!
//! ```text
//! offset  size  field
//! 0       1     preamble, always 0x55
//! 1       1     SRC:4 (bits 7..4), DST:4 (bits 3..0)
//! 2       1     LEN: payload length, 0..=255
//! 3       LEN   payload
//! 3+LEN   2     CRC-16/XMODEM over bytes 1 .. 3+LEN, big-endian
//! ```
//!
//! Address 0 is the operator, 1..=14 are vehicles, 15 is broadcast. The overhead is
//! [`OVERHEAD_BYTES`] bytes per frame.
//!
//! No-panic contract: [`Frame::new_checked`] validates the buffer length once; after it, every
//! getter stays in bounds. Nothing here panics on any input that went through `new_checked`.

use super::{Error, Result};

/// The first byte of every frame.
pub const PREAMBLE: u8 = 0x55;
/// Bytes a frame adds around its payload: preamble, address, length, CRC.
pub const OVERHEAD_BYTES: usize = 5;
/// The largest payload a frame can carry (LEN is one byte).
pub const MAX_PAYLOAD_BYTES: usize = 255;
/// The largest frame on the wire.
pub const MAX_FRAME_BYTES: usize = MAX_PAYLOAD_BYTES + OVERHEAD_BYTES;
/// Address of the operator (the surface side, TDMA master).
pub const ADDR_OPERATOR: u8 = 0;
/// Address every node accepts.
pub const ADDR_BROADCAST: u8 = 15;

/// CRC-16/XMODEM (poly 0x1021, init 0, not reflected, no final XOR), slice-by-16 tables.
pub static CRC16: crc::Crc<u16, crc::Table<16>> =
    crc::Crc::<u16, crc::Table<16>>::new(&crc::CRC_16_XMODEM);

/// Byte ranges of the frame header; the payload and CRC follow at offsets that depend on LEN.
mod field {
    pub const PREAMBLE: usize = 0;
    pub const ADDR: usize = 1;
    pub const LEN: usize = 2;
    pub const PAYLOAD_START: usize = 3;
}

/// A read/write view of a link frame in a byte buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Frame<T> {
    /// Wraps a buffer without checking it; getters may panic if it is too short.
    pub const fn new_unchecked(buffer: T) -> Frame<T> {
        Frame { buffer }
    }

    /// Wraps a buffer after [`check_len`](Self::check_len).
    pub fn new_checked(buffer: T) -> Result<Frame<T>> {
        let frame = Self::new_unchecked(buffer);
        frame.check_len()?;
        Ok(frame)
    }

    /// Checks that the buffer holds the header and the whole frame its LEN field announces.
    /// Bytes after the frame are allowed and ignored.
    pub fn check_len(&self) -> Result<()> {
        let len = self.buffer.as_ref().len();
        if len < field::PAYLOAD_START {
            return Err(Error::Truncated {
                what: "frame header",
                expected: field::PAYLOAD_START,
                found: len,
            });
        }
        let total = self.total_len();
        if len < total {
            return Err(Error::Truncated {
                what: "frame",
                expected: total,
                found: len,
            });
        }
        Ok(())
    }

    /// Returns the underlying buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    /// The preamble byte (0x55 in a valid frame).
    pub fn preamble(&self) -> u8 {
        self.buffer.as_ref()[field::PREAMBLE]
    }

    /// Source address, 0..=15.
    pub fn src(&self) -> u8 {
        self.buffer.as_ref()[field::ADDR] >> 4
    }

    /// Destination address, 0..=15.
    pub fn dst(&self) -> u8 {
        self.buffer.as_ref()[field::ADDR] & 0x0f
    }

    /// Payload length in bytes (the LEN field).
    pub fn payload_len(&self) -> usize {
        usize::from(self.buffer.as_ref()[field::LEN])
    }

    /// Length of the whole frame, header to CRC, as LEN announces it.
    pub fn total_len(&self) -> usize {
        self.payload_len() + OVERHEAD_BYTES
    }

    /// The payload bytes.
    pub fn payload(&self) -> &[u8] {
        let end = field::PAYLOAD_START + self.payload_len();
        &self.buffer.as_ref()[field::PAYLOAD_START..end]
    }

    /// The CRC the frame carries.
    pub fn crc(&self) -> u16 {
        let at = field::PAYLOAD_START + self.payload_len();
        let data = self.buffer.as_ref();
        u16::from_be_bytes([data[at], data[at + 1]])
    }

    /// The CRC of the frame's address, length and payload bytes.
    pub fn compute_crc(&self) -> u16 {
        let end = field::PAYLOAD_START + self.payload_len();
        CRC16.checksum(&self.buffer.as_ref()[field::ADDR..end])
    }

    /// Checks the preamble and the CRC.
    pub fn check(&self) -> Result<()> {
        if self.preamble() != PREAMBLE {
            return Err(Error::BadPreamble {
                found: self.preamble(),
            });
        }
        let (computed, carried) = (self.compute_crc(), self.crc());
        if computed != carried {
            return Err(Error::BadCrc { computed, carried });
        }
        Ok(())
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Frame<T> {
    /// Sets the preamble byte.
    pub fn set_preamble(&mut self, value: u8) {
        self.buffer.as_mut()[field::PREAMBLE] = value;
    }

    /// Sets the source address (low 4 bits of `value`).
    pub fn set_src(&mut self, value: u8) {
        let b = &mut self.buffer.as_mut()[field::ADDR];
        *b = (*b & 0x0f) | (value << 4);
    }

    /// Sets the destination address (low 4 bits of `value`).
    pub fn set_dst(&mut self, value: u8) {
        let b = &mut self.buffer.as_mut()[field::ADDR];
        *b = (*b & 0xf0) | (value & 0x0f);
    }

    /// Sets the LEN field.
    pub fn set_payload_len(&mut self, value: u8) {
        self.buffer.as_mut()[field::LEN] = value;
    }

    /// The payload bytes, writable (LEN must be set first).
    pub fn payload_mut(&mut self) -> &mut [u8] {
        let end = field::PAYLOAD_START + self.payload_len();
        &mut self.buffer.as_mut()[field::PAYLOAD_START..end]
    }

    /// Sets the CRC field to a given value.
    pub fn set_crc(&mut self, value: u16) {
        let at = field::PAYLOAD_START + self.payload_len();
        self.buffer.as_mut()[at..at + 2].copy_from_slice(&value.to_be_bytes());
    }

    /// Computes the CRC over the current contents and stores it.
    pub fn fill_crc(&mut self) {
        let crc = self.compute_crc();
        self.set_crc(crc);
    }
}

/// The header of a frame as a value: addresses and payload length.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Repr {
    /// Source address, 0..=15.
    pub src: u8,
    /// Destination address, 0..=15.
    pub dst: u8,
    /// Payload length in bytes, 0..=255.
    pub payload_len: usize,
}

impl Repr {
    /// Reads the header of a frame after checking its preamble and CRC.
    pub fn parse<T: AsRef<[u8]>>(frame: &Frame<T>) -> Result<Repr> {
        frame.check_len()?;
        frame.check()?;
        Ok(Repr {
            src: frame.src(),
            dst: frame.dst(),
            payload_len: frame.payload_len(),
        })
    }

    /// Bytes the whole frame takes.
    pub const fn buffer_len(&self) -> usize {
        self.payload_len + OVERHEAD_BYTES
    }

    /// Checks that the addresses fit in 4 bits and the payload in 255 bytes.
    pub fn validate(&self) -> Result<()> {
        super::check_range("src", self.src.into(), 0, 15, "0..=15")?;
        super::check_range("dst", self.dst.into(), 0, 15, "0..=15")?;
        if self.payload_len > MAX_PAYLOAD_BYTES {
            return Err(Error::BadLength {
                what: "frame payload",
                expected: "0..=255",
                found: self.payload_len,
            });
        }
        Ok(())
    }

    /// Writes preamble, addresses and LEN. The caller writes the payload, then calls
    /// [`Frame::fill_crc`].
    pub fn emit<T: AsRef<[u8]> + AsMut<[u8]>>(&self, frame: &mut Frame<T>) {
        debug_assert!(self.validate().is_ok(), "invalid frame repr {self:?}");
        frame.set_preamble(PREAMBLE);
        frame.set_src(self.src);
        frame.set_dst(self.dst);
        frame.set_payload_len(self.payload_len as u8);
    }
}

/// Builds a whole frame (header, payload, CRC) into a new vector.
pub fn build(src: u8, dst: u8, payload: &[u8]) -> Result<Vec<u8>> {
    let repr = Repr {
        src,
        dst,
        payload_len: payload.len(),
    };
    repr.validate()?;
    let mut out = vec![0u8; repr.buffer_len()];
    let mut frame = Frame::new_unchecked(&mut out[..]);
    repr.emit(&mut frame);
    frame.payload_mut().copy_from_slice(payload);
    frame.fill_crc();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_check_value() {
        assert_eq!(CRC16.checksum(b"123456789"), 0x31c3);
    }

    #[test]
    fn build_and_read_back() {
        let bytes = build(1, 0, &[0xde, 0xad]).unwrap();
        assert_eq!(bytes[..5], [0x55, 0x10, 0x02, 0xde, 0xad]);
        let frame = Frame::new_checked(&bytes[..]).unwrap();
        assert_eq!(
            Repr::parse(&frame).unwrap(),
            Repr {
                src: 1,
                dst: 0,
                payload_len: 2
            }
        );
        assert_eq!(frame.payload(), &[0xde, 0xad]);
    }

    #[test]
    fn empty_payload() {
        let bytes = build(15, 15, &[]).unwrap();
        assert_eq!(bytes.len(), OVERHEAD_BYTES);
        let frame = Frame::new_checked(&bytes[..]).unwrap();
        assert!(frame.check().is_ok());
    }

    #[test]
    fn truncated_header_and_body() {
        assert_eq!(
            Frame::new_checked(&[0x55u8, 0x10][..]).unwrap_err(),
            Error::Truncated {
                what: "frame header",
                expected: 3,
                found: 2
            }
        );
        assert_eq!(
            Frame::new_checked(&[0x55u8, 0x10, 0x04, 1, 2][..]).unwrap_err(),
            Error::Truncated {
                what: "frame",
                expected: 9,
                found: 5
            }
        );
    }

    #[test]
    fn bad_crc_and_preamble() {
        let mut bytes = build(1, 0, &[1, 2, 3]).unwrap();
        bytes[4] ^= 0x01;
        let frame = Frame::new_checked(&bytes[..]).unwrap();
        assert!(matches!(frame.check(), Err(Error::BadCrc { .. })));
        bytes[4] ^= 0x01;
        bytes[0] = 0x54;
        let frame = Frame::new_checked(&bytes[..]).unwrap();
        assert_eq!(frame.check(), Err(Error::BadPreamble { found: 0x54 }));
    }

    #[test]
    fn validate_rejects_wide_address_and_long_payload() {
        assert!(build(16, 0, &[]).is_err());
        assert!(build(0, 0, &[0u8; 256]).is_err());
        assert!(build(0, 0, &[0u8; 255]).is_ok());
    }

    fn a5_frame() -> [u8; 8] {
        let mut buf = [0xa5u8; 8];
        buf[2] = 3;
        buf
    }

    #[test]
    fn field_src() {
        let mut buf = a5_frame();
        Frame::new_unchecked(&mut buf[..]).set_src(0x3);
        assert_eq!(buf, [0xa5, 0x35, 0x03, 0xa5, 0xa5, 0xa5, 0xa5, 0xa5]);
    }

    #[test]
    fn field_dst() {
        let mut buf = a5_frame();
        Frame::new_unchecked(&mut buf[..]).set_dst(0xc);
        assert_eq!(buf, [0xa5, 0xac, 0x03, 0xa5, 0xa5, 0xa5, 0xa5, 0xa5]);
    }

    #[test]
    fn field_preamble_len_crc() {
        let mut buf = a5_frame();
        let mut frame = Frame::new_unchecked(&mut buf[..]);
        frame.set_preamble(PREAMBLE);
        frame.set_crc(0x1234);
        assert_eq!(buf, [0x55, 0xa5, 0x03, 0xa5, 0xa5, 0xa5, 0x12, 0x34]);
        let mut buf = [0xa5u8; 8];
        Frame::new_unchecked(&mut buf[..]).set_payload_len(0);
        assert_eq!(buf, [0xa5, 0xa5, 0x00, 0xa5, 0xa5, 0xa5, 0xa5, 0xa5]);
    }
}
