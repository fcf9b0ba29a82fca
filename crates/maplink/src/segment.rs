//! Segment layouts: the payload of one link frame (wire.md) of the live transport. All
//! integers little-endian, as the rest of the `.odl` format.
//!
//! ```text
//! byte 0: V:4 (version, 1) T:4 (type)
//! T=1 data      1..5 epoch u32 | 5..9 seq u32 | 9 flags (bit 0 first, bit 1 last) | 10.. chunk (1..=245 B)
//! T=2 ack       1..5 epoch u32 | 5..9 cum u32 (every seq below received) | 9..17 sack u64 (bit i: seq cum+1+i)
//! T=3 request   1..5 id u32    | 5.. request (see [`crate::request`])
//! T=4 reply     1..5 epoch u32 | 5..9 id u32 | 9 status (0 done, 1 refused) | 10..14 sync seq u32
//! ```
//!
//! No-panic contract: [`Packet::new_checked`] checks the length for the type once; every getter
//! after it stays in bounds, and [`Repr::parse`] never panics on any input.

use crate::request::{Request, RequestError};

/// The transport's version (the high nibble of byte 0).
pub const VERSION: u8 = 1;
/// Type of a data segment (vehicle to operator).
pub const TYPE_DATA: u8 = 1;
/// Type of an acknowledgement (operator to vehicle).
pub const TYPE_ACK: u8 = 2;
/// Type of a request (operator to vehicle).
pub const TYPE_REQUEST: u8 = 3;
/// Type of a reply to a request (vehicle to operator).
pub const TYPE_REPLY: u8 = 4;
/// The largest segment: a link frame's payload.
pub const MAX_SEGMENT_BYTES: usize = 255;
/// Bytes of a data segment before its chunk.
pub const DATA_HEADER_BYTES: usize = 10;
/// The largest chunk of a record one data segment carries.
pub const MAX_CHUNK_BYTES: usize = MAX_SEGMENT_BYTES - DATA_HEADER_BYTES;
/// Bytes of an acknowledgement.
pub const ACK_BYTES: usize = 17;
/// Bytes of a reply.
pub const REPLY_BYTES: usize = 14;
/// Data flag: the segment starts a record.
pub const FLAG_FIRST: u8 = 1;
/// Data flag: the segment ends a record.
pub const FLAG_LAST: u8 = 2;

/// Byte ranges of the fields.
mod field {
    use std::ops::Range;
    pub const VT: usize = 0;
    pub const EPOCH: Range<usize> = 1..5;
    pub const SEQ: Range<usize> = 5..9;
    pub const FLAGS: usize = 9;
    pub const CHUNK: usize = 10;
    pub const CUM: Range<usize> = 5..9;
    pub const SACK: Range<usize> = 9..17;
    pub const REQ_ID: Range<usize> = 1..5;
    pub const REQ_BODY: usize = 5;
    pub const REPLY_ID: Range<usize> = 5..9;
    pub const STATUS: usize = 9;
    pub const SYNC_SEQ: Range<usize> = 10..14;
}

/// Why a segment was not understood.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SegmentError {
    /// Empty, or shorter than its type needs.
    #[error("segment of {found} bytes: type {kind} needs {expected}")]
    Length {
        /// The type byte's type.
        kind: u8,
        /// Bytes needed.
        expected: String,
        /// Bytes found.
        found: usize,
    },
    /// Another version of the transport.
    #[error("segment version {0}: expected {VERSION}")]
    Version(u8),
    /// A type this version does not have.
    #[error("segment type {0}: expected 1 (data), 2 (ack), 3 (request) or 4 (reply)")]
    Type(u8),
    /// A data segment's flags have bits this version does not use.
    #[error("data flags {0:#04x}: unknown bits")]
    Flags(u8),
    /// A reply's status is not 0 or 1.
    #[error("reply status {0}: expected 0 (done) or 1 (refused)")]
    Status(u8),
    /// A request's body is wrong.
    #[error("request: {0}")]
    Request(#[from] RequestError),
}

/// A view of a segment in a buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Packet<T: AsRef<[u8]>> {
    buffer: T,
}

fn u32_at(b: &[u8], r: std::ops::Range<usize>) -> u32 {
    let mut a = [0u8; 4];
    a.copy_from_slice(&b[r]);
    u32::from_le_bytes(a)
}

impl<T: AsRef<[u8]>> Packet<T> {
    /// Wraps a buffer after checking its version, type and length for the type.
    pub fn new_checked(buffer: T) -> Result<Packet<T>, SegmentError> {
        let b = buffer.as_ref();
        let Some(&vt) = b.first() else {
            return Err(SegmentError::Length {
                kind: 0,
                expected: "at least 1".into(),
                found: 0,
            });
        };
        if vt >> 4 != VERSION {
            return Err(SegmentError::Version(vt >> 4));
        }
        let kind = vt & 0x0f;
        let (ok, expected) = match kind {
            TYPE_DATA => (
                (DATA_HEADER_BYTES + 1..=MAX_SEGMENT_BYTES).contains(&b.len()),
                format!("{} ..= {MAX_SEGMENT_BYTES}", DATA_HEADER_BYTES + 1),
            ),
            TYPE_ACK => (b.len() == ACK_BYTES, ACK_BYTES.to_string()),
            TYPE_REQUEST => (
                (field::REQ_BODY + 1..=MAX_SEGMENT_BYTES).contains(&b.len()),
                format!("{} ..= {MAX_SEGMENT_BYTES}", field::REQ_BODY + 1),
            ),
            TYPE_REPLY => (b.len() == REPLY_BYTES, REPLY_BYTES.to_string()),
            other => return Err(SegmentError::Type(other)),
        };
        if !ok {
            return Err(SegmentError::Length {
                kind,
                expected,
                found: b.len(),
            });
        }
        Ok(Packet { buffer })
    }

    /// The segment's type.
    pub fn kind(&self) -> u8 {
        self.buffer.as_ref()[field::VT] & 0x0f
    }

    /// The sender's epoch (data, ack, reply).
    pub fn epoch(&self) -> u32 {
        u32_at(self.buffer.as_ref(), field::EPOCH)
    }
}

/// A segment, parsed.
#[derive(Debug, Clone, PartialEq)]
pub enum Repr<'a> {
    /// A chunk of the record stream.
    Data {
        /// The mapper's epoch (a new one at each start).
        epoch: u32,
        /// Sequence number.
        seq: u32,
        /// The segment starts a record.
        first: bool,
        /// The segment ends a record.
        last: bool,
        /// The chunk.
        chunk: &'a [u8],
    },
    /// What the operator has received.
    Ack {
        /// The epoch acknowledged.
        epoch: u32,
        /// Every sequence number below this was received.
        cum: u32,
        /// Bit i: `cum + 1 + i` was received.
        sack: u64,
    },
    /// An operator's request.
    Request {
        /// Its identifier (the same on every resend).
        id: u32,
        /// What it asks.
        request: Request,
    },
    /// The mapper's answer to a request.
    Reply {
        /// The mapper's epoch.
        epoch: u32,
        /// The request's identifier.
        id: u32,
        /// Whether it was done.
        refused: bool,
        /// For a resync: the sequence number where the new stream starts.
        sync_seq: u32,
    },
}

impl<'a> Repr<'a> {
    /// Parses a segment.
    pub fn parse(bytes: &'a [u8]) -> Result<Repr<'a>, SegmentError> {
        let p = Packet::new_checked(bytes)?;
        let b = bytes;
        Ok(match p.kind() {
            TYPE_DATA => {
                let flags = b[field::FLAGS];
                if flags & !(FLAG_FIRST | FLAG_LAST) != 0 {
                    return Err(SegmentError::Flags(flags));
                }
                Repr::Data {
                    epoch: p.epoch(),
                    seq: u32_at(b, field::SEQ),
                    first: flags & FLAG_FIRST != 0,
                    last: flags & FLAG_LAST != 0,
                    chunk: &b[field::CHUNK..],
                }
            }
            TYPE_ACK => {
                let mut s = [0u8; 8];
                s.copy_from_slice(&b[field::SACK]);
                Repr::Ack {
                    epoch: p.epoch(),
                    cum: u32_at(b, field::CUM),
                    sack: u64::from_le_bytes(s),
                }
            }
            TYPE_REQUEST => Repr::Request {
                id: u32_at(b, field::REQ_ID),
                request: Request::parse(&b[field::REQ_BODY..])?,
            },
            _ => {
                let status = b[field::STATUS];
                if status > 1 {
                    return Err(SegmentError::Status(status));
                }
                Repr::Reply {
                    epoch: p.epoch(),
                    id: u32_at(b, field::REPLY_ID),
                    refused: status == 1,
                    sync_seq: u32_at(b, field::SYNC_SEQ),
                }
            }
        })
    }

    /// The segment's bytes.
    pub fn emit(&self) -> Vec<u8> {
        let vt = |t: u8| VERSION << 4 | t;
        let mut out = Vec::with_capacity(MAX_SEGMENT_BYTES);
        match self {
            Repr::Data {
                epoch,
                seq,
                first,
                last,
                chunk,
            } => {
                out.push(vt(TYPE_DATA));
                out.extend_from_slice(&epoch.to_le_bytes());
                out.extend_from_slice(&seq.to_le_bytes());
                out.push(if *first { FLAG_FIRST } else { 0 } | if *last { FLAG_LAST } else { 0 });
                out.extend_from_slice(chunk);
            }
            Repr::Ack { epoch, cum, sack } => {
                out.push(vt(TYPE_ACK));
                out.extend_from_slice(&epoch.to_le_bytes());
                out.extend_from_slice(&cum.to_le_bytes());
                out.extend_from_slice(&sack.to_le_bytes());
            }
            Repr::Request { id, request } => {
                out.push(vt(TYPE_REQUEST));
                out.extend_from_slice(&id.to_le_bytes());
                request.emit(&mut out);
            }
            Repr::Reply {
                epoch,
                id,
                refused,
                sync_seq,
            } => {
                out.push(vt(TYPE_REPLY));
                out.extend_from_slice(&epoch.to_le_bytes());
                out.extend_from_slice(&id.to_le_bytes());
                out.push(*refused as u8);
                out.extend_from_slice(&sync_seq.to_le_bytes());
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Test vectors: one of each type, as bytes on the wire.
    #[test]
    fn vectors() {
        let data = Repr::Data {
            epoch: 0x0403_0201,
            seq: 7,
            first: true,
            last: false,
            chunk: &[3, 0xaa],
        };
        let bytes = data.emit();
        assert_eq!(
            bytes,
            [
                0x11, 0x01, 0x02, 0x03, 0x04, 0x07, 0x00, 0x00, 0x00, 0x01, 0x03, 0xaa
            ]
        );
        assert_eq!(Repr::parse(&bytes).unwrap(), data);
        let ack = Repr::Ack {
            epoch: 1,
            cum: 0x100,
            sack: 0b101,
        };
        let bytes = ack.emit();
        assert_eq!(
            bytes,
            [
                0x12, 1, 0, 0, 0, 0x00, 0x01, 0, 0, 0b101, 0, 0, 0, 0, 0, 0, 0
            ]
        );
        assert_eq!(Repr::parse(&bytes).unwrap(), ack);
        let req = Repr::Request {
            id: 9,
            request: Request::CoarseDepth(12),
        };
        let bytes = req.emit();
        assert_eq!(bytes, [0x13, 9, 0, 0, 0, 6, 12]);
        assert_eq!(Repr::parse(&bytes).unwrap(), req);
        let reply = Repr::Reply {
            epoch: 2,
            id: 9,
            refused: true,
            sync_seq: 5,
        };
        let bytes = reply.emit();
        assert_eq!(bytes, [0x14, 2, 0, 0, 0, 9, 0, 0, 0, 1, 5, 0, 0, 0]);
        assert_eq!(Repr::parse(&bytes).unwrap(), reply);
    }

    #[test]
    fn bad_segments_name_what_is_wrong() {
        let err = |b: &[u8]| Repr::parse(b).unwrap_err().to_string();
        assert_eq!(err(&[]), "segment of 0 bytes: type 0 needs at least 1");
        assert_eq!(err(&[0x21]), "segment version 2: expected 1");
        assert_eq!(
            err(&[0x17]),
            "segment type 7: expected 1 (data), 2 (ack), 3 (request) or 4 (reply)"
        );
        assert_eq!(
            err(&[0x11, 0, 0, 0, 0, 0, 0, 0, 0, 1]),
            "segment of 10 bytes: type 1 needs 11 ..= 255"
        );
        assert_eq!(
            err(&[0x11, 0, 0, 0, 0, 0, 0, 0, 0, 4, 1]),
            "data flags 0x04: unknown bits"
        );
        assert_eq!(
            err(&[0x14, 2, 0, 0, 0, 9, 0, 0, 0, 2, 5, 0, 0, 0]),
            "reply status 2: expected 0 (done) or 1 (refused)"
        );
        assert_eq!(err(&[0x12; 16]), "segment of 16 bytes: type 2 needs 17");
    }

    proptest::proptest! {
        /// Any bytes: parsed or refused, never a panic; what parses emits the same bytes.
        #[test]
        fn never_panics_and_round_trips(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..300)) {
            if let Ok(r) = Repr::parse(&bytes) {
                proptest::prop_assert_eq!(r.emit(), bytes);
            }
        }
    }
}
