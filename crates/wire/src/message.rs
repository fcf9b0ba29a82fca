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

/// The one-line human form `rcp-dump --format text` prints: addresses, type, the flags that
/// are set, then the fields (positions in metres, angles in degrees).
impl core::fmt::Display for MessageRepr {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{:>2}->{:<2} {:<8}",
            self.src,
            self.dst,
            self.message.type_name()
        )?;
        let flag = |f: &mut core::fmt::Formatter<'_>, on: bool, name: &str| {
            if on { write!(f, " {name}") } else { Ok(()) }
        };
        match &self.message {
            Message::Rov(r) => {
                write!(f, " isn={} itsn={:<2}", u8::from(r.isn), r.itsn)?;
                flag(f, r.ft, "FT")?;
                flag(f, r.lt, "LT")?;
                flag(f, r.ci, "CI")?;
                match &r.status {
                    rov::Status::Basic(s) => {
                        write!(f, " | eoid={} nav={}", u8::from(s.eoid), s.nav)?;
                        flag(f, s.rd, "RD")?;
                        flag(f, s.loc, "LOC")?;
                        flag(f, s.hh, "HH")?;
                        flag(f, s.arm, "ARM")?;
                        flag(f, !s.position_known(), "NP")?;
                        if s.why() != rov::Why::Nothing {
                            write!(f, " why={}", s.why())?;
                        }
                        write!(
                            f,
                            " ned=({:.2},{:.2},{:.2})m rpy=({},{},{})deg | trunk {} B",
                            f64::from(s.x_cm) / 100.0,
                            f64::from(s.y_cm) / 100.0,
                            f64::from(s.z_cm) / 100.0,
                            s.roll_deg,
                            s.pitch_deg,
                            s.yaw_deg,
                            r.trunk.len()
                        )
                    }
                    rov::Status::Unknown { st, raw } => {
                        write!(f, " | status type {st} ({} B raw)", raw.len())
                    }
                }
            }
            Message::Operator(o) => {
                write!(
                    f,
                    " oid={} eisn={} rit={:<2}",
                    u8::from(o.oid),
                    u8::from(o.eisn),
                    o.rit
                )?;
                flag(f, o.clo, "CLO")?;
                flag(f, o.ic, "IC")?;
                write!(f, " | {}", o.order.name())?;
                match o.order {
                    operator::Order::Velocity(v) => {
                        let [vx, vy, vz, vyaw] = v.axes();
                        write!(f, " vx={vx} vy={vy} vz={vz} vyaw={vyaw} nav={}", v.nav)?;
                        flag(f, v.arm, "ARM")?;
                        flag(f, v.disarm, "DISARM")
                    }
                    operator::Order::GoTo {
                        x_cm,
                        y_cm,
                        z_cm,
                        heading_deg,
                    } => write!(
                        f,
                        " ned=({:.2},{:.2},{:.2})m heading={heading_deg}deg",
                        f64::from(x_cm) / 100.0,
                        f64::from(y_cm) / 100.0,
                        f64::from(z_cm) / 100.0
                    ),
                    operator::Order::ImageSettings(operator::ImageOrder {
                        roi,
                        roi_shift,
                        gray,
                        scale,
                        size_bytes,
                        trunk_bytes,
                    }) => {
                        if roi.is_none() {
                            write!(f, " roi=none")?;
                        } else {
                            write!(
                                f,
                                " roi=({},{})-({},{}) shift={roi_shift}",
                                roi.x0, roi.y0, roi.x1, roi.y1
                            )?;
                        }
                        write!(
                            f,
                            " scale=1/{} size={size_bytes}B trunk={trunk_bytes}B",
                            1u8 << scale
                        )?;
                        flag(f, gray, "GRAY")
                    }
                    operator::Order::HoldHeading {
                        heading_deg,
                        enable,
                    } => {
                        write!(
                            f,
                            " heading={heading_deg}deg {}",
                            if enable { "on" } else { "off" }
                        )
                    }
                    operator::Order::Unknown { ot, body } => {
                        write!(f, " ot={ot} body={}", super::json::encode_hex(&body))
                    }
                }
            }
            Message::Raw(p) => write!(f, " {} B: {}", p.len(), super::json::encode_hex(p)),
        }
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
