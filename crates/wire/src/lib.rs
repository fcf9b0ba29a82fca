//! Wire formats of the remote-control protocol (RCP): the link frame and the two messages it
//! carries, as the contract in `shared/design/wire.md` fixes them.
//!
//! The layout follows smoltcp: for each format a zero-copy view `Packet<T: AsRef<[u8]>>` whose
//! getters and setters read and write fields in place (byte ranges in a private `field` module),
//! a checked constructor `new_checked` that validates the length once so the getters cannot go
//! out of bounds, and a plain `Repr` value with `parse` (bytes to value), `emit` (value to bytes)
//! and `buffer_len`. Code fields are enums that keep values the contract reserves, so nothing a
//! newer peer sends is lost on the way through.
//!
//! - [`frame`]: the link frame (preamble, addresses, length, payload, CRC-16/XMODEM).
//! - [`rov`]: the ROV -> operator message (status, image trunk).
//! - [`operator`]: the operator -> ROV message (sequence bits and one order).
//! - [`message`]: a whole frame as a value: addresses plus the message its source implies.
//! - [`deframe`]: a streaming deframer that finds frames in any byte stream and resynchronises.
//! - [`json`]: the JSON Lines text form that `rcp-pack` reads and `rcp-dump` writes.
//! - [`pack`]: `rcp-pack`'s packer: JSON Lines to frames, a file cut into image trunks.
//! - [`print`]: `rcp-dump`'s printer: frames in a byte stream or from a live port as text,
//!   JSON or CSV records, notices about what was not a frame, and the run's counters.
//!
//! # No-panic contract
//! Every function here that reads untrusted bytes or text (`new_checked`, `parse`, the deframer,
//! the JSON reader) returns an [`Error`] on bad input and never panics, on any input. The
//! fuzz targets in `fuzz/` and the property tests hold the code to that.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod deframe;
pub mod frame;
pub mod json;
pub mod message;
pub mod operator;
pub mod pack;
pub mod print;
pub mod rov;

pub use deframe::{DeframeEvent, DeframeStats, Deframer};
pub use message::{Message, MessageRepr};

/// What went wrong while reading or writing a wire format. Every variant carries the numbers a
/// person needs to find the problem: the field, what was expected and what was found.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Error {
    /// The buffer is shorter than the format needs.
    #[error("{what}: need {expected} bytes, found {found}")]
    Truncated {
        /// Which structure was being read.
        what: &'static str,
        /// Bytes needed.
        expected: usize,
        /// Bytes available.
        found: usize,
    },
    /// The buffer has a length the format does not allow (too long, or not the fixed size).
    #[error("{what}: length must be {expected}, found {found} bytes")]
    BadLength {
        /// Which structure was being read.
        what: &'static str,
        /// The allowed length(s), in words.
        expected: &'static str,
        /// The length found.
        found: usize,
    },
    /// A frame does not start with the preamble byte 0x55.
    #[error("preamble: expected 0x55, found 0x{found:02x}")]
    BadPreamble {
        /// The byte found instead.
        found: u8,
    },
    /// The frame's CRC does not match its contents.
    #[error("crc: computed 0x{computed:04x}, frame carries 0x{carried:04x}")]
    BadCrc {
        /// CRC computed over the frame's bytes.
        computed: u16,
        /// CRC stored in the frame.
        carried: u16,
    },
    /// A field holds a value outside its range (or a reserved bit is set).
    #[error("field {field}: expected {expected}, found {found}")]
    BadField {
        /// The field's name, as in wire.md and the JSON form.
        field: &'static str,
        /// The allowed values, in words.
        expected: &'static str,
        /// The value found.
        found: i64,
    },
    /// The message type does not fit the frame's source address.
    #[error("address: {message} messages need src {expected}, found src {found}")]
    WrongSource {
        /// The message type.
        message: &'static str,
        /// The allowed sources.
        expected: &'static str,
        /// The source address found.
        found: u8,
    },
}

/// Result of reading or writing a wire format.
pub type Result<T> = core::result::Result<T, Error>;

/// Checks that `value` lies in `min..=max`, naming the field otherwise.
pub(crate) fn check_range(
    field: &'static str,
    value: i64,
    min: i64,
    max: i64,
    expected: &'static str,
) -> Result<()> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(Error::BadField {
            field,
            expected,
            found: value,
        })
    }
}

/// Navigation mode of the vehicle (3 bits): reported in the ROV status, requested in a
/// Velocity order. Values 5..=7 are reserved; they are kept, not rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Nav {
    /// 0: thrusters follow the joystick directly.
    Manual,
    /// 1: attitude stabilised.
    Stabilize,
    /// 2: depth held.
    DepthHold,
    /// 3: position held.
    HoldPosition,
    /// 4: following high-level orders.
    Guided,
    /// 5..=7: reserved values, kept as they came.
    Unknown(u8),
}

impl Nav {
    /// Decodes the 3-bit field (bits above the third are ignored).
    pub const fn from_bits(bits: u8) -> Nav {
        match bits & 0x07 {
            0 => Nav::Manual,
            1 => Nav::Stabilize,
            2 => Nav::DepthHold,
            3 => Nav::HoldPosition,
            4 => Nav::Guided,
            other => Nav::Unknown(other),
        }
    }

    /// Encodes the mode as its 3-bit value.
    pub const fn bits(self) -> u8 {
        match self {
            Nav::Manual => 0,
            Nav::Stabilize => 1,
            Nav::DepthHold => 2,
            Nav::HoldPosition => 3,
            Nav::Guided => 4,
            Nav::Unknown(v) => v & 0x07,
        }
    }

    /// The name used in the JSON form, or `None` for a reserved value (written as its number).
    pub const fn name(self) -> Option<&'static str> {
        match self {
            Nav::Manual => Some("manual"),
            Nav::Stabilize => Some("stabilize"),
            Nav::DepthHold => Some("depth_hold"),
            Nav::HoldPosition => Some("hold_position"),
            Nav::Guided => Some("guided"),
            Nav::Unknown(_) => None,
        }
    }

    /// Looks a mode up by its JSON name.
    pub fn from_name(name: &str) -> Option<Nav> {
        (0..5).map(Nav::from_bits).find(|n| n.name() == Some(name))
    }
}

impl core::fmt::Display for Nav {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.name() {
            Some(name) => f.write_str(name),
            None => write!(f, "{}", self.bits()),
        }
    }
}

/// Reads bit `bit` (7 = most significant) of a byte.
pub(crate) const fn get_bit(byte: u8, bit: u8) -> bool {
    byte & (1 << bit) != 0
}

/// Returns `byte` with bit `bit` set to `value`.
pub(crate) const fn with_bit(byte: u8, bit: u8, value: bool) -> u8 {
    if value {
        byte | (1 << bit)
    } else {
        byte & !(1 << bit)
    }
}

/// Returns `byte` with the bits in `mask` replaced by `value << shift`.
pub(crate) const fn with_bits(byte: u8, mask: u8, shift: u8, value: u8) -> u8 {
    (byte & !mask) | ((value << shift) & mask)
}

/// Helpers of the per-field tests: apply one setter to a buffer of 0xa5 bytes and compare
/// with the 0xa5 buffer changed at the expected bytes only.
#[cfg(test)]
pub(crate) mod field_test {
    /// `N` bytes of 0xa5 with the given (offset, value) changes.
    pub fn a5_with<const N: usize>(changes: &[(usize, u8)]) -> [u8; N] {
        let mut buf = [0xa5u8; N];
        for &(at, value) in changes {
            buf[at] = value;
        }
        buf
    }
}
