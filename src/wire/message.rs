//! A whole frame as a value: its addresses and the message its source address implies
//! (address 0 sends operator messages, every other address sends ROV messages).
//!
//! A frame whose CRC is good but whose payload is not a valid message is still data: it can be
//! kept as [`Message::Raw`], so tools pass it through byte for byte and say what was wrong.
//!
//! No-panic contract: [`MessageRepr::parse`] and [`Message::parse_payload`] return errors on
//! any bad input and never panic.

use super::frame::{self, Frame};
use super::{Error, Result, operator, rov};

/// The message inside a frame.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Message {
    /// ROV -> operator.
    Rov(rov::Repr),
    /// Operator -> ROV.
    Operator(operator::Repr),
    /// Payload bytes kept as they are: a frame whose payload is not a valid message, or one
    /// crafted on purpose.
    Raw(Vec<u8>),
}

impl Message {
    /// Parses a payload as the message its source address implies.
    pub fn parse_payload(src: u8, payload: &[u8]) -> Result<Message> {
        if src == frame::ADDR_OPERATOR {
            let packet = operator::Packet::new_checked(payload)?;
            Ok(Message::Operator(operator::Repr::parse(&packet)?))
        } else {
            let packet = rov::Packet::new_checked(payload)?;
            Ok(Message::Rov(rov::Repr::parse(&packet)?))
        }
    }

    /// The name used in the JSON form's `type` field.
    pub const fn type_name(&self) -> &'static str {
        match self {
            Message::Rov(_) => "rov",
            Message::Operator(_) => "operator",
            Message::Raw(_) => "raw",
        }
    }

    /// Bytes of the payload.
    pub fn buffer_len(&self) -> usize {
        match self {
            Message::Rov(r) => r.buffer_len(),
            Message::Operator(o) => o.buffer_len(),
            Message::Raw(p) => p.len(),
        }
    }

    /// Writes the payload into a buffer of exactly [`buffer_len`](Self::buffer_len) bytes.
    pub fn emit(&self, buf: &mut [u8]) {
        match self {
            Message::Rov(r) => r.emit(&mut rov::Packet::new_unchecked(buf)),
            Message::Operator(o) => o.emit(&mut operator::Packet::new_unchecked(buf)),
            Message::Raw(p) => buf.copy_from_slice(p),
        }
    }
}

/// A frame as a value: addresses plus message.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct MessageRepr {
    /// Source address, 0..=15.
    pub src: u8,
    /// Destination address, 0..=15.
    pub dst: u8,
    /// The message.
    pub message: Message,
}

impl MessageRepr {
    /// Parses a checked frame: preamble, CRC, then the message its source implies.
    pub fn parse<T: AsRef<[u8]>>(frame: &Frame<T>) -> Result<MessageRepr> {
        let header = frame::Repr::parse(frame)?;
        Ok(MessageRepr {
            src: header.src,
            dst: header.dst,
            message: Message::parse_payload(header.src, frame.payload())?,
        })
    }

    /// Parses a frame whose preamble and CRC were already checked (as the deframer's output
    /// is), keeping a payload that is not a valid message as [`Message::Raw`] together with the
    /// reason.
    pub fn parse_lenient<T: AsRef<[u8]>>(frame: &Frame<T>) -> (MessageRepr, Option<Error>) {
        let (src, dst) = (frame.src(), frame.dst());
        match Message::parse_payload(src, frame.payload()) {
            Ok(message) => (MessageRepr { src, dst, message }, None),
            Err(e) => {
                let message = Message::Raw(frame.payload().to_vec());
                (MessageRepr { src, dst, message }, Some(e))
            }
        }
    }

    /// Checks addresses, that the message type fits the source, and the message's fields.
    pub fn validate(&self) -> Result<()> {
        let header = frame::Repr {
            src: self.src,
            dst: self.dst,
            payload_len: self.message.buffer_len(),
        };
        match &self.message {
            Message::Rov(r) => {
                if self.src == frame::ADDR_OPERATOR {
                    return Err(Error::WrongSource {
                        message: "rov",
                        expected: "1..=15",
                        found: self.src,
                    });
                }
                r.validate()?;
            }
            Message::Operator(o) => {
                if self.src != frame::ADDR_OPERATOR {
                    return Err(Error::WrongSource {
                        message: "operator",
                        expected: "0",
                        found: self.src,
                    });
                }
                o.validate()?;
            }
            Message::Raw(_) => {}
        }
        header.validate()
    }

    /// Bytes the whole frame takes.
    pub fn buffer_len(&self) -> usize {
        self.message.buffer_len() + frame::OVERHEAD_BYTES
    }

    /// Writes the whole frame (header, payload, CRC) into a buffer of exactly
    /// [`buffer_len`](Self::buffer_len) bytes. Call [`validate`](Self::validate) first on
    /// values that did not come from [`parse`](Self::parse).
    pub fn emit(&self, buf: &mut [u8]) {
        let mut frame = Frame::new_unchecked(buf);
        frame::Repr {
            src: self.src,
            dst: self.dst,
            payload_len: self.message.buffer_len(),
        }
        .emit(&mut frame);
        self.message.emit(frame.payload_mut());
        frame.fill_crc();
    }

    /// Validates and appends the whole frame to `out`.
    pub fn emit_to_vec(&self, out: &mut Vec<u8>) -> Result<()> {
        self.validate()?;
        let start = out.len();
        out.resize(start + self.buffer_len(), 0);
        self.emit(&mut out[start..]);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn source_decides_the_message_type() {
        let op_payload = [0x80u8, 0x05, 0x64, 0xec, 0x00, 0x81, 0x81, 0, 0, 0, 0];
        assert!(matches!(
            Message::parse_payload(0, &op_payload),
            Ok(Message::Operator(_))
        ));
        // The same 11 bytes from a vehicle are a ROV message too short for its status block.
        assert!(matches!(
            Message::parse_payload(1, &op_payload),
            Err(Error::Truncated {
                what: "rov message status",
                ..
            })
        ));
    }

    #[test]
    fn wrong_source_is_rejected() {
        let repr = MessageRepr {
            src: 3,
            dst: 0,
            message: Message::Operator(operator::Repr {
                oid: false,
                clo: false,
                eisn: false,
                ic: false,
                rit: 0,
                order: operator::Order::HoldHeading {
                    heading_deg: 0,
                    enable: false,
                },
            }),
        };
        assert_eq!(
            repr.validate(),
            Err(Error::WrongSource {
                message: "operator",
                expected: "0",
                found: 3
            })
        );
    }

    #[test]
    fn lenient_parse_keeps_bad_payload() {
        let bytes = frame::build(0, 1, &[1, 2, 3]).unwrap();
        let (repr, err) = MessageRepr::parse_lenient(&Frame::new_checked(&bytes[..]).unwrap());
        assert_eq!(repr.message, Message::Raw(vec![1, 2, 3]));
        assert!(matches!(err, Some(Error::BadLength { .. })));
        let mut out = Vec::new();
        repr.emit_to_vec(&mut out).unwrap();
        assert_eq!(out, bytes);
    }
}
