//! The ROV -> operator message: image-transfer bits, a status block and an image trunk.
//!
//! ```text
//! offset  field
//! 0       FT:1 LT:1 ST:6
//! 1       ISN:1 CI:1 ITSN:6
//! 2..=12  status block of type ST (ST = 0, 11 bytes; ST = 1, 12 bytes):
//!   2       RD:1 EOID:1 LOC:1 HH:1 ARM:1 NAV:3
//!   3..=8   X, Y, Z: i16 NED position in centimetres
//!   9..=12  orientation u32: roll bits 8..0, pitch 17..9, yaw 26..18, bits 31..27 zero
//!   13      ST = 1 only: NP:1 reserved:2 (zero) WHY:5
//! 13.. (ST = 0) or 14.. (ST = 1)  IT: image trunk, 0..=242 (0..=241) bytes
//! ```
//!
//! ST = 1 (wire.md's status version 1) is ST = 0 and one byte more, sent only when there is
//! something to say: NP, the vehicle has no position estimate (X, Y, Z are not a position),
//! and WHY, why an order cannot run ([`Why`]). A status without either goes as ST = 0, so a
//! session without trouble sends exactly the paper's frames and an ST = 0 frame decodes as
//! before. Status types 2..=63 are reserved: [`Repr::parse`] keeps them as [`Status::Unknown`]
//! with every byte after the header, since their length is not known.
//!
//! No-panic contract: after [`Packet::new_checked`] the header getters and `trunk`, and for
//! ST = 0 the status getters, stay in bounds (the status getters of a short message of a
//! reserved type do not: check `st()` first); [`Repr::parse`] never panics and rejects
//! out-of-range values (angles over 359, reserved orientation bits) with an
//! [`Error::BadField`] naming the field.

use super::{Error, Nav, Result, check_range, get_bit, with_bit, with_bits};

/// Header bytes (FT/LT/ST and ISN/CI/ITSN).
pub const HEADER_BYTES: usize = 2;
/// Bytes of the ST = 0 status block.
pub const STATUS_BYTES: usize = 11;
/// Bytes before the image trunk of an ST = 0 message.
pub const FIXED_BYTES: usize = HEADER_BYTES + STATUS_BYTES;
/// The longest trunk a frame can carry (255-byte payload minus the fixed part).
pub const MAX_TRUNK_BYTES: usize = super::frame::MAX_PAYLOAD_BYTES - FIXED_BYTES;
/// Most trunks an image may have (ITSN is 6 bits).
pub const MAX_TRUNKS: usize = 64;
/// The status type of the basic block.
pub const ST_BASIC: u8 = 0;
/// The status type of the basic block with its extension byte (status version 1).
pub const ST_EXTENDED: u8 = 1;
/// Bytes the extension adds to the status block.
pub const EXTENSION_BYTES: usize = 1;
/// The longest trunk a frame with an ST = 1 status can carry.
pub const MAX_EXTENDED_TRUNK_BYTES: usize = MAX_TRUNK_BYTES - EXTENSION_BYTES;

/// Byte ranges and bit positions of the ROV message.
mod field {
    use core::ops::Range;
    pub const FLAGS: usize = 0;
    pub const FT_BIT: u8 = 7;
    pub const LT_BIT: u8 = 6;
    pub const ST_MASK: u8 = 0x3f;
    pub const SEQ: usize = 1;
    pub const ISN_BIT: u8 = 7;
    pub const CI_BIT: u8 = 6;
    pub const ITSN_MASK: u8 = 0x3f;
    pub const STATE: usize = 2;
    pub const RD_BIT: u8 = 7;
    pub const EOID_BIT: u8 = 6;
    pub const LOC_BIT: u8 = 5;
    pub const HH_BIT: u8 = 4;
    pub const ARM_BIT: u8 = 3;
    pub const NAV_MASK: u8 = 0x07;
    pub const X: Range<usize> = 3..5;
    pub const Y: Range<usize> = 5..7;
    pub const Z: Range<usize> = 7..9;
    pub const ORIENTATION: Range<usize> = 9..13;
    pub const ROLL_SHIFT: u32 = 0;
    pub const PITCH_SHIFT: u32 = 9;
    pub const YAW_SHIFT: u32 = 18;
    pub const ANGLE_MASK: u32 = 0x1ff;
    pub const ORIENTATION_RESERVED: u32 = 0xf800_0000;
    pub const TRUNK_START: usize = 13;
    pub const EXTENSION: usize = 13;
    pub const NP_BIT: u8 = 7;
    pub const EXTENSION_RESERVED: u8 = 0x60;
    pub const WHY_MASK: u8 = 0x1f;
}

/// A read/write view of a ROV message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Packet<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Packet<T> {
    /// Wraps a buffer without checking it.
    pub const fn new_unchecked(buffer: T) -> Packet<T> {
        Packet { buffer }
    }

    /// Wraps a buffer after [`check_len`](Self::check_len).
    pub fn new_checked(buffer: T) -> Result<Packet<T>> {
        let packet = Self::new_unchecked(buffer);
        packet.check_len()?;
        Ok(packet)
    }

    /// Checks that the header is there and, for ST = 0 and 1, the whole status block.
    pub fn check_len(&self) -> Result<()> {
        let len = self.buffer.as_ref().len();
        if len < HEADER_BYTES {
            return Err(Error::Truncated {
                what: "rov message header",
                expected: HEADER_BYTES,
                found: len,
            });
        }
        let needed = self.trunk_start();
        if self.st() <= ST_EXTENDED && len < needed {
            return Err(Error::Truncated {
                what: "rov message status",
                expected: needed,
                found: len,
            });
        }
        Ok(())
    }

    /// Returns the underlying buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    fn byte(&self, at: usize) -> u8 {
        self.buffer.as_ref()[at]
    }

    fn i16_at(&self, range: core::ops::Range<usize>) -> i16 {
        let b = &self.buffer.as_ref()[range];
        i16::from_be_bytes([b[0], b[1]])
    }

    /// FT: this trunk is the first of an image.
    pub fn ft(&self) -> bool {
        get_bit(self.byte(field::FLAGS), field::FT_BIT)
    }

    /// LT: this trunk is the last of an image.
    pub fn lt(&self) -> bool {
        get_bit(self.byte(field::FLAGS), field::LT_BIT)
    }

    /// ST: status block type, 0..=63 (0 is the only one defined).
    pub fn st(&self) -> u8 {
        self.byte(field::FLAGS) & field::ST_MASK
    }

    /// ISN: one-bit sequence number of the image in flight.
    pub fn isn(&self) -> bool {
        get_bit(self.byte(field::SEQ), field::ISN_BIT)
    }

    /// CI: the image in flight was cancelled.
    pub fn ci(&self) -> bool {
        get_bit(self.byte(field::SEQ), field::CI_BIT)
    }

    /// ITSN: index of the trunk carried, 0..=63.
    pub fn itsn(&self) -> u8 {
        self.byte(field::SEQ) & field::ITSN_MASK
    }

    /// RD: the ROV is ready (executes no high-level order).
    pub fn rd(&self) -> bool {
        get_bit(self.byte(field::STATE), field::RD_BIT)
    }

    /// EOID: one-bit id of the next high-level order the ROV expects.
    pub fn eoid(&self) -> bool {
        get_bit(self.byte(field::STATE), field::EOID_BIT)
    }

    /// LOC: the last order was cancelled.
    pub fn loc(&self) -> bool {
        get_bit(self.byte(field::STATE), field::LOC_BIT)
    }

    /// HH: heading hold is on.
    pub fn hh(&self) -> bool {
        get_bit(self.byte(field::STATE), field::HH_BIT)
    }

    /// ARM: the thrusters are armed.
    pub fn arm(&self) -> bool {
        get_bit(self.byte(field::STATE), field::ARM_BIT)
    }

    /// NAV: navigation mode.
    pub fn nav(&self) -> Nav {
        Nav::from_bits(self.byte(field::STATE) & field::NAV_MASK)
    }

    /// X: north position in centimetres.
    pub fn x_cm(&self) -> i16 {
        self.i16_at(field::X)
    }

    /// Y: east position in centimetres.
    pub fn y_cm(&self) -> i16 {
        self.i16_at(field::Y)
    }

    /// Z: down position in centimetres.
    pub fn z_cm(&self) -> i16 {
        self.i16_at(field::Z)
    }

    /// Where the trunk starts: after the status block of ST = 0, one byte later for ST = 1.
    fn trunk_start(&self) -> usize {
        if self.st() == ST_EXTENDED {
            field::TRUNK_START + EXTENSION_BYTES
        } else {
            field::TRUNK_START
        }
    }

    /// NP (ST = 1): the vehicle has no position estimate; X, Y, Z are not a position.
    pub fn np(&self) -> bool {
        get_bit(self.byte(field::EXTENSION), field::NP_BIT)
    }

    /// WHY (ST = 1): why an order cannot run, 5 bits.
    pub fn why(&self) -> Why {
        Why::from_bits(self.byte(field::EXTENSION) & field::WHY_MASK)
    }

    /// The extension byte's reserved bits (ST = 1; zero when valid).
    pub fn extension_reserved(&self) -> u8 {
        self.byte(field::EXTENSION) & field::EXTENSION_RESERVED
    }

    /// The raw orientation word (roll, pitch, yaw packed).
    pub fn orientation(&self) -> u32 {
        let b = &self.buffer.as_ref()[field::ORIENTATION];
        u32::from_be_bytes([b[0], b[1], b[2], b[3]])
    }

    /// Roll in whole degrees (9 bits; 0..=359 when valid).
    pub fn roll_deg(&self) -> u16 {
        ((self.orientation() >> field::ROLL_SHIFT) & field::ANGLE_MASK) as u16
    }

    /// Pitch in whole degrees (9 bits; 0..=359 when valid).
    pub fn pitch_deg(&self) -> u16 {
        ((self.orientation() >> field::PITCH_SHIFT) & field::ANGLE_MASK) as u16
    }

    /// Yaw in whole degrees (9 bits; 0..=359 when valid).
    pub fn yaw_deg(&self) -> u16 {
        ((self.orientation() >> field::YAW_SHIFT) & field::ANGLE_MASK) as u16
    }

    /// The image trunk (ST = 0 and 1): every byte after the status block (empty when the
    /// buffer ends before it, as a short message of a reserved status type may).
    pub fn trunk(&self) -> &[u8] {
        self.buffer
            .as_ref()
            .get(self.trunk_start()..)
            .unwrap_or(&[])
    }

    /// Every byte after the two header bytes (the status block of an unknown type, and more).
    pub fn after_header(&self) -> &[u8] {
        &self.buffer.as_ref()[HEADER_BYTES..]
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Packet<T> {
    fn update(&mut self, at: usize, f: impl FnOnce(u8) -> u8) {
        let b = &mut self.buffer.as_mut()[at];
        *b = f(*b);
    }

    fn set_i16_at(&mut self, range: core::ops::Range<usize>, value: i16) {
        self.buffer.as_mut()[range].copy_from_slice(&value.to_be_bytes());
    }

    fn set_angle(&mut self, shift: u32, value: u16) {
        let word = self.orientation() & !(field::ANGLE_MASK << shift);
        self.set_orientation(word | ((u32::from(value) & field::ANGLE_MASK) << shift));
    }

    /// Sets FT.
    pub fn set_ft(&mut self, value: bool) {
        self.update(field::FLAGS, |b| with_bit(b, field::FT_BIT, value));
    }

    /// Sets LT.
    pub fn set_lt(&mut self, value: bool) {
        self.update(field::FLAGS, |b| with_bit(b, field::LT_BIT, value));
    }

    /// Sets ST (low 6 bits).
    pub fn set_st(&mut self, value: u8) {
        self.update(field::FLAGS, |b| with_bits(b, field::ST_MASK, 0, value));
    }

    /// Sets ISN.
    pub fn set_isn(&mut self, value: bool) {
        self.update(field::SEQ, |b| with_bit(b, field::ISN_BIT, value));
    }

    /// Sets CI.
    pub fn set_ci(&mut self, value: bool) {
        self.update(field::SEQ, |b| with_bit(b, field::CI_BIT, value));
    }

    /// Sets ITSN (low 6 bits).
    pub fn set_itsn(&mut self, value: u8) {
        self.update(field::SEQ, |b| with_bits(b, field::ITSN_MASK, 0, value));
    }

    /// Sets RD.
    pub fn set_rd(&mut self, value: bool) {
        self.update(field::STATE, |b| with_bit(b, field::RD_BIT, value));
    }

    /// Sets EOID.
    pub fn set_eoid(&mut self, value: bool) {
        self.update(field::STATE, |b| with_bit(b, field::EOID_BIT, value));
    }

    /// Sets LOC.
    pub fn set_loc(&mut self, value: bool) {
        self.update(field::STATE, |b| with_bit(b, field::LOC_BIT, value));
    }

    /// Sets HH.
    pub fn set_hh(&mut self, value: bool) {
        self.update(field::STATE, |b| with_bit(b, field::HH_BIT, value));
    }

    /// Sets ARM.
    pub fn set_arm(&mut self, value: bool) {
        self.update(field::STATE, |b| with_bit(b, field::ARM_BIT, value));
    }

    /// Sets NAV.
    pub fn set_nav(&mut self, value: Nav) {
        self.update(field::STATE, |b| {
            with_bits(b, field::NAV_MASK, 0, value.bits())
        });
    }

    /// Sets X in centimetres.
    pub fn set_x_cm(&mut self, value: i16) {
        self.set_i16_at(field::X, value);
    }

    /// Sets Y in centimetres.
    pub fn set_y_cm(&mut self, value: i16) {
        self.set_i16_at(field::Y, value);
    }

    /// Sets Z in centimetres.
    pub fn set_z_cm(&mut self, value: i16) {
        self.set_i16_at(field::Z, value);
    }

    /// Sets the raw orientation word.
    pub fn set_orientation(&mut self, value: u32) {
        self.buffer.as_mut()[field::ORIENTATION].copy_from_slice(&value.to_be_bytes());
    }

    /// Sets roll (low 9 bits).
    pub fn set_roll_deg(&mut self, value: u16) {
        self.set_angle(field::ROLL_SHIFT, value);
    }

    /// Sets pitch (low 9 bits).
    pub fn set_pitch_deg(&mut self, value: u16) {
        self.set_angle(field::PITCH_SHIFT, value);
    }

    /// Sets yaw (low 9 bits).
    pub fn set_yaw_deg(&mut self, value: u16) {
        self.set_angle(field::YAW_SHIFT, value);
    }

    /// Sets NP (ST = 1).
    pub fn set_np(&mut self, value: bool) {
        self.update(field::EXTENSION, |b| with_bit(b, field::NP_BIT, value));
    }

    /// Sets WHY (ST = 1) and clears the extension's reserved bits.
    pub fn set_why(&mut self, value: Why) {
        self.update(field::EXTENSION, |b| {
            with_bits(
                b & !field::EXTENSION_RESERVED,
                field::WHY_MASK,
                0,
                value.bits(),
            )
        });
    }

    /// The trunk bytes (after the status block of the packet's ST), writable.
    pub fn trunk_mut(&mut self) -> &mut [u8] {
        let start = self.trunk_start();
        &mut self.buffer.as_mut()[start..]
    }

    /// Every byte after the header, writable.
    pub fn after_header_mut(&mut self) -> &mut [u8] {
        &mut self.buffer.as_mut()[HEADER_BYTES..]
    }
}

/// The ST = 0 status block as a value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BasicStatus {
    /// Ready: no high-level order in execution.
    pub rd: bool,
    /// Expected order id (one bit).
    pub eoid: bool,
    /// Last order cancelled.
    pub loc: bool,
    /// Heading hold on.
    pub hh: bool,
    /// Thrusters armed.
    pub arm: bool,
    /// Navigation mode.
    pub nav: Nav,
    /// North, centimetres.
    pub x_cm: i16,
    /// East, centimetres.
    pub y_cm: i16,
    /// Down, centimetres.
    pub z_cm: i16,
    /// Roll, whole degrees 0..=359.
    pub roll_deg: u16,
    /// Pitch, whole degrees 0..=359.
    pub pitch_deg: u16,
    /// Yaw, whole degrees 0..=359.
    pub yaw_deg: u16,
    /// The extension byte: `Some` makes the block ST = 1, `None` ST = 0.
    pub extension: Option<Extension>,
}

/// Why an order cannot run (WHY, 5 bits, in an ST = 1 status). Values 5..=31 are reserved;
/// they are kept, not rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Why {
    /// 0: nothing stands in the way.
    Nothing,
    /// 1: the vehicle refused to arm (e.g. ArduSub's pre-arm checks).
    ArmRefused,
    /// 2: the vehicle refused the navigation mode asked for.
    ModeRefused,
    /// 3: a GoTo (or recovery's backtracking) was refused: the vehicle has no position
    /// estimate.
    NoPosition,
    /// 4: the vehicle (its autopilot) does not answer.
    VehicleSilent,
    /// 5..=31: reserved values, kept as they came.
    Unknown(u8),
}

impl Why {
    /// Decodes the 5-bit field (bits above the fifth are ignored).
    pub const fn from_bits(bits: u8) -> Why {
        match bits & 0x1f {
            0 => Why::Nothing,
            1 => Why::ArmRefused,
            2 => Why::ModeRefused,
            3 => Why::NoPosition,
            4 => Why::VehicleSilent,
            other => Why::Unknown(other),
        }
    }

    /// Encodes the reason as its 5-bit value.
    pub const fn bits(self) -> u8 {
        match self {
            Why::Nothing => 0,
            Why::ArmRefused => 1,
            Why::ModeRefused => 2,
            Why::NoPosition => 3,
            Why::VehicleSilent => 4,
            Why::Unknown(v) => v & 0x1f,
        }
    }

    /// The name used in the JSON form, or `None` for a reserved value (written as its number).
    pub const fn name(self) -> Option<&'static str> {
        match self {
            Why::Nothing => Some("none"),
            Why::ArmRefused => Some("arm_refused"),
            Why::ModeRefused => Some("mode_refused"),
            Why::NoPosition => Some("no_position"),
            Why::VehicleSilent => Some("vehicle_silent"),
            Why::Unknown(_) => None,
        }
    }

    /// Looks a reason up by its JSON name.
    pub fn from_name(name: &str) -> Option<Why> {
        (0..5).map(Why::from_bits).find(|w| w.name() == Some(name))
    }
}

impl core::fmt::Display for Why {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.name() {
            Some(name) => f.write_str(name),
            None => write!(f, "{}", self.bits()),
        }
    }
}

/// The ST = 1 extension byte as a value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Extension {
    /// NP: no position estimate (X, Y, Z are not a position).
    pub no_position: bool,
    /// WHY: why an order cannot run.
    pub why: Why,
}

impl BasicStatus {
    /// False when an ST = 1 block says the vehicle has no position estimate.
    pub fn position_known(&self) -> bool {
        !self.extension.is_some_and(|e| e.no_position)
    }

    /// WHY of an ST = 1 block ([`Why::Nothing`] for ST = 0).
    pub fn why(&self) -> Why {
        self.extension.map_or(Why::Nothing, |e| e.why)
    }
}

impl Default for BasicStatus {
    fn default() -> Self {
        BasicStatus {
            rd: true,
            eoid: false,
            loc: false,
            hh: false,
            arm: false,
            nav: Nav::Manual,
            x_cm: 0,
            y_cm: 0,
            z_cm: 0,
            roll_deg: 0,
            pitch_deg: 0,
            yaw_deg: 0,
            extension: None,
        }
    }
}

/// The status block of a ROV message.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Status {
    /// ST = 0: state bits, position and orientation; ST = 1: the same and the extension byte.
    Basic(BasicStatus),
    /// A reserved status type (2..=63), kept with every byte after the header (the block's length is not
    /// known, so no trunk is split off).
    Unknown {
        /// The ST value, 1..=63.
        st: u8,
        /// Bytes 2.. of the message.
        raw: Vec<u8>,
    },
}

impl Status {
    /// The ST code of this block.
    pub fn st(&self) -> u8 {
        match self {
            Status::Basic(s) if s.extension.is_some() => ST_EXTENDED,
            Status::Basic(_) => ST_BASIC,
            Status::Unknown { st, .. } => *st,
        }
    }
}

/// A ROV -> operator message as a value.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Repr {
    /// First trunk of an image.
    pub ft: bool,
    /// Last trunk of an image.
    pub lt: bool,
    /// Image sequence number (one bit).
    pub isn: bool,
    /// Image cancelled.
    pub ci: bool,
    /// Trunk sequence number, 0..=63.
    pub itsn: u8,
    /// The status block.
    pub status: Status,
    /// The image trunk (empty when no image is in flight, and for an unknown status type).
    pub trunk: Vec<u8>,
}

fn check_angle(field: &'static str, value: u16) -> Result<()> {
    check_range(field, value.into(), 0, 359, "whole degrees 0..=359")
}

impl Repr {
    /// Reads a message, rejecting out-of-range values.
    pub fn parse<T: AsRef<[u8]>>(packet: &Packet<T>) -> Result<Repr> {
        packet.check_len()?;
        let len = packet.buffer.as_ref().len();
        if len > super::frame::MAX_PAYLOAD_BYTES {
            return Err(Error::BadLength {
                what: "rov message",
                expected: "at most 255 bytes",
                found: len,
            });
        }
        let (status, trunk) = if packet.st() <= ST_EXTENDED {
            let reserved = packet.orientation() & field::ORIENTATION_RESERVED;
            if reserved != 0 {
                return Err(Error::BadField {
                    field: "orientation bits 31..27",
                    expected: "0",
                    found: i64::from(reserved >> 27),
                });
            }
            let status = BasicStatus {
                rd: packet.rd(),
                eoid: packet.eoid(),
                loc: packet.loc(),
                hh: packet.hh(),
                arm: packet.arm(),
                nav: packet.nav(),
                x_cm: packet.x_cm(),
                y_cm: packet.y_cm(),
                z_cm: packet.z_cm(),
                roll_deg: packet.roll_deg(),
                pitch_deg: packet.pitch_deg(),
                yaw_deg: packet.yaw_deg(),
                extension: None,
            };
            let status = if packet.st() == ST_EXTENDED {
                let reserved = packet.extension_reserved();
                if reserved != 0 {
                    return Err(Error::BadField {
                        field: "status extension bits 6..5",
                        expected: "0",
                        found: i64::from(reserved >> 5),
                    });
                }
                BasicStatus {
                    extension: Some(Extension {
                        no_position: packet.np(),
                        why: packet.why(),
                    }),
                    ..status
                }
            } else {
                status
            };
            check_angle("roll_deg", status.roll_deg)?;
            check_angle("pitch_deg", status.pitch_deg)?;
            check_angle("yaw_deg", status.yaw_deg)?;
            (Status::Basic(status), packet.trunk().to_vec())
        } else {
            let raw = packet.after_header().to_vec();
            (
                Status::Unknown {
                    st: packet.st(),
                    raw,
                },
                Vec::new(),
            )
        };
        Ok(Repr {
            ft: packet.ft(),
            lt: packet.lt(),
            isn: packet.isn(),
            ci: packet.ci(),
            itsn: packet.itsn(),
            status,
            trunk,
        })
    }

    /// Checks every field's range and the total length.
    pub fn validate(&self) -> Result<()> {
        check_range("itsn", self.itsn.into(), 0, 63, "0..=63")?;
        match &self.status {
            Status::Basic(s) => {
                if let Nav::Unknown(v) = s.nav {
                    check_range("nav", v.into(), 5, 7, "a mode name or 5..=7")?;
                }
                check_angle("roll_deg", s.roll_deg)?;
                check_angle("pitch_deg", s.pitch_deg)?;
                check_angle("yaw_deg", s.yaw_deg)?;
                if let Some(Extension {
                    why: Why::Unknown(v),
                    ..
                }) = s.extension
                {
                    check_range("why", v.into(), 5, 31, "a reason name or 5..=31")?;
                }
            }
            Status::Unknown { st, .. } => {
                check_range("st", (*st).into(), 2, 63, "2..=63 for an unknown status")?;
                if !self.trunk.is_empty() {
                    return Err(Error::BadLength {
                        what: "trunk of an unknown status type",
                        expected: "0 (the raw status holds every byte)",
                        found: self.trunk.len(),
                    });
                }
            }
        }
        let len = self.buffer_len();
        if len > super::frame::MAX_PAYLOAD_BYTES {
            return Err(Error::BadLength {
                what: "rov message",
                expected: "at most 255 bytes (a trunk of at most 242, 241 with ST 1)",
                found: len,
            });
        }
        Ok(())
    }

    /// Bytes the message takes.
    pub fn buffer_len(&self) -> usize {
        match &self.status {
            Status::Basic(s) if s.extension.is_some() => {
                FIXED_BYTES + EXTENSION_BYTES + self.trunk.len()
            }
            Status::Basic(_) => FIXED_BYTES + self.trunk.len(),
            Status::Unknown { raw, .. } => HEADER_BYTES + raw.len(),
        }
    }

    /// Writes the message into a packet of exactly [`buffer_len`](Self::buffer_len) bytes.
    pub fn emit<T: AsRef<[u8]> + AsMut<[u8]>>(&self, packet: &mut Packet<T>) {
        debug_assert!(self.validate().is_ok(), "invalid rov repr {self:?}");
        packet.set_ft(self.ft);
        packet.set_lt(self.lt);
        packet.set_st(self.status.st());
        packet.set_isn(self.isn);
        packet.set_ci(self.ci);
        packet.set_itsn(self.itsn);
        match &self.status {
            Status::Basic(s) => {
                packet.set_rd(s.rd);
                packet.set_eoid(s.eoid);
                packet.set_loc(s.loc);
                packet.set_hh(s.hh);
                packet.set_arm(s.arm);
                packet.set_nav(s.nav);
                packet.set_x_cm(s.x_cm);
                packet.set_y_cm(s.y_cm);
                packet.set_z_cm(s.z_cm);
                packet.set_orientation(0);
                packet.set_roll_deg(s.roll_deg);
                packet.set_pitch_deg(s.pitch_deg);
                packet.set_yaw_deg(s.yaw_deg);
                if let Some(extension) = s.extension {
                    packet.set_np(extension.no_position);
                    packet.set_why(extension.why);
                }
                packet.trunk_mut().copy_from_slice(&self.trunk);
            }
            Status::Unknown { raw, .. } => packet.after_header_mut().copy_from_slice(raw),
        }
    }
}

/// A stream cut into trunks of `trunk_bytes` (the last one shorter), as ITSN 0, 1, ... carry
/// them; `Err` with the smallest trunk size that would do when it takes more than
/// [`MAX_TRUNKS`].
pub fn cut_trunks(stream: &[u8], trunk_bytes: usize) -> core::result::Result<Vec<&[u8]>, usize> {
    let trunk = trunk_bytes.max(1);
    if stream.len().div_ceil(trunk) > MAX_TRUNKS {
        return Err(stream.len().div_ceil(MAX_TRUNKS));
    }
    Ok(stream.chunks(trunk).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Payload of wire.md's first vector.
    const VECTOR: [u8; 17] = [
        0x80, 0x80, 0xdc, 0xff, 0x06, 0x04, 0xb0, 0x01, 0xc7, 0x02, 0xd0, 0x03, 0x67, 0x00, 0x01,
        0x02, 0x03,
    ];

    fn vector_repr() -> Repr {
        Repr {
            ft: true,
            lt: false,
            isn: true,
            ci: false,
            itsn: 0,
            status: Status::Basic(BasicStatus {
                rd: true,
                eoid: true,
                loc: false,
                hh: true,
                arm: true,
                nav: Nav::Guided,
                x_cm: -250,
                y_cm: 1200,
                z_cm: 455,
                roll_deg: 359,
                pitch_deg: 1,
                yaw_deg: 180,
                extension: None,
            }),
            trunk: vec![0, 1, 2, 3],
        }
    }

    #[test]
    fn extended_status_carries_np_and_why_before_the_trunk() {
        let mut repr = vector_repr();
        let Status::Basic(ref mut status) = repr.status else {
            unreachable!()
        };
        status.extension = Some(Extension {
            no_position: true,
            why: Why::NoPosition,
        });
        assert_eq!(repr.status.st(), ST_EXTENDED);
        let mut bytes = vec![0xa5u8; repr.buffer_len()];
        repr.emit(&mut Packet::new_unchecked(&mut bytes[..]));
        // ST 1 in byte 0; bytes 2..=12 as ST 0; byte 13: NP 1, reserved 0, WHY 3; the trunk.
        let mut expected = VECTOR.to_vec();
        expected[0] = 0x81;
        expected.insert(13, 0x83);
        assert_eq!(bytes, expected);
        let parsed = Repr::parse(&Packet::new_checked(&bytes[..]).unwrap()).unwrap();
        assert_eq!(parsed, repr);
        let Status::Basic(status) = parsed.status else {
            unreachable!()
        };
        assert!(!status.position_known());
        assert_eq!(status.why(), Why::NoPosition);
        // Reserved bits of the extension are refused; a short ST 1 block is truncated.
        let mut bad = expected.clone();
        bad[13] |= 0x20;
        assert!(matches!(
            Repr::parse(&Packet::new_checked(&bad[..]).unwrap()),
            Err(Error::BadField {
                field: "status extension bits 6..5",
                ..
            })
        ));
        assert_eq!(
            Packet::new_checked(&expected[..13]).unwrap_err(),
            Error::Truncated {
                what: "rov message status",
                expected: 14,
                found: 13
            }
        );
        // A reserved reason is kept.
        let mut reserved = expected.clone();
        reserved[13] = 0x1f;
        let parsed = Repr::parse(&Packet::new_checked(&reserved[..]).unwrap()).unwrap();
        let Status::Basic(status) = parsed.status else {
            unreachable!()
        };
        assert_eq!(status.why(), Why::Unknown(31));
        assert!(status.position_known());
        for k in 0..32 {
            let why = Why::from_bits(k);
            assert_eq!(why.bits(), k);
            if let Some(name) = why.name() {
                assert_eq!(Why::from_name(name), Some(why));
            }
        }
    }

    #[test]
    fn parse_vector() {
        let packet = Packet::new_checked(&VECTOR[..]).unwrap();
        assert_eq!(Repr::parse(&packet).unwrap(), vector_repr());
    }

    #[test]
    fn emit_vector() {
        let repr = vector_repr();
        let mut buf = vec![0xa5u8; repr.buffer_len()];
        repr.emit(&mut Packet::new_unchecked(&mut buf[..]));
        assert_eq!(buf, VECTOR);
    }

    #[test]
    fn unknown_status_is_kept() {
        let bytes = [0x05u8, 0x00, 1, 2, 3];
        let repr = Repr::parse(&Packet::new_checked(&bytes[..]).unwrap()).unwrap();
        assert_eq!(
            repr.status,
            Status::Unknown {
                st: 5,
                raw: vec![1, 2, 3]
            }
        );
        let mut out = vec![0u8; repr.buffer_len()];
        repr.emit(&mut Packet::new_unchecked(&mut out[..]));
        assert_eq!(out, bytes);
    }

    #[test]
    fn short_status_is_truncated() {
        assert_eq!(
            Packet::new_checked(&VECTOR[..12]).unwrap_err(),
            Error::Truncated {
                what: "rov message status",
                expected: 13,
                found: 12
            }
        );
        assert!(Packet::new_checked(&VECTOR[..1]).is_err());
    }

    #[test]
    fn out_of_range_angle_and_reserved_bits_are_rejected() {
        let mut bytes = VECTOR;
        Packet::new_unchecked(&mut bytes[..]).set_yaw_deg(360);
        assert_eq!(
            Repr::parse(&Packet::new_checked(&bytes[..]).unwrap()).unwrap_err(),
            Error::BadField {
                field: "yaw_deg",
                expected: "whole degrees 0..=359",
                found: 360
            }
        );
        let mut bytes = VECTOR;
        bytes[9] |= 0x80;
        assert!(matches!(
            Repr::parse(&Packet::new_checked(&bytes[..]).unwrap()),
            Err(Error::BadField {
                field: "orientation bits 31..27",
                ..
            })
        ));
    }

    /// Applies one setter to a 13-byte buffer of 0xa5 and returns the bytes.
    fn set(f: impl FnOnce(&mut Packet<&mut [u8]>)) -> [u8; 13] {
        let mut buf = [0xa5u8; 13];
        f(&mut Packet::new_unchecked(&mut buf[..]));
        buf
    }

    fn a5_with(changes: &[(usize, u8)]) -> [u8; 13] {
        crate::field_test::a5_with(changes)
    }

    #[test]
    fn field_ft() {
        assert_eq!(set(|p| p.set_ft(false)), a5_with(&[(0, 0x25)]));
    }
    #[test]
    fn field_lt() {
        assert_eq!(set(|p| p.set_lt(true)), a5_with(&[(0, 0xe5)]));
    }
    #[test]
    fn field_st() {
        assert_eq!(set(|p| p.set_st(0)), a5_with(&[(0, 0x80)]));
    }
    #[test]
    fn field_isn() {
        assert_eq!(set(|p| p.set_isn(false)), a5_with(&[(1, 0x25)]));
    }
    #[test]
    fn field_ci() {
        assert_eq!(set(|p| p.set_ci(true)), a5_with(&[(1, 0xe5)]));
    }
    #[test]
    fn field_itsn() {
        assert_eq!(set(|p| p.set_itsn(63)), a5_with(&[(1, 0xbf)]));
    }
    #[test]
    fn field_rd() {
        assert_eq!(set(|p| p.set_rd(false)), a5_with(&[(2, 0x25)]));
    }
    #[test]
    fn field_eoid() {
        assert_eq!(set(|p| p.set_eoid(true)), a5_with(&[(2, 0xe5)]));
    }
    #[test]
    fn field_loc() {
        assert_eq!(set(|p| p.set_loc(false)), a5_with(&[(2, 0x85)]));
    }
    #[test]
    fn field_hh() {
        assert_eq!(set(|p| p.set_hh(true)), a5_with(&[(2, 0xb5)]));
    }
    #[test]
    fn field_arm() {
        assert_eq!(set(|p| p.set_arm(true)), a5_with(&[(2, 0xad)]));
    }
    #[test]
    fn field_nav() {
        assert_eq!(set(|p| p.set_nav(Nav::HoldPosition)), a5_with(&[(2, 0xa3)]));
        assert_eq!(set(|p| p.set_nav(Nav::Unknown(7))), a5_with(&[(2, 0xa7)]));
    }
    #[test]
    fn field_x() {
        assert_eq!(set(|p| p.set_x_cm(-2)), a5_with(&[(3, 0xff), (4, 0xfe)]));
    }
    #[test]
    fn field_y() {
        assert_eq!(
            set(|p| p.set_y_cm(0x0102)),
            a5_with(&[(5, 0x01), (6, 0x02)])
        );
    }
    #[test]
    fn field_z() {
        assert_eq!(
            set(|p| p.set_z_cm(i16::MIN)),
            a5_with(&[(7, 0x80), (8, 0x00)])
        );
    }
    #[test]
    fn field_roll() {
        // 0xa5a5a5a5 with bits 8..0 replaced by 0: 0xa5a5a400.
        assert_eq!(
            set(|p| p.set_roll_deg(0)),
            a5_with(&[(11, 0xa4), (12, 0x00)])
        );
    }
    #[test]
    fn field_pitch() {
        // bits 17..9 replaced by 0x1ff: 0xa5a5a5a5 | 0x0003fe00 = 0xa5a7ffa5.
        assert_eq!(
            set(|p| p.set_pitch_deg(0x1ff)),
            a5_with(&[(10, 0xa7), (11, 0xff)])
        );
    }
    #[test]
    fn field_yaw() {
        // bits 26..18 replaced by 0: 0xa5a5a5a5 & !0x07fc0000 = 0xa001a5a5.
        assert_eq!(set(|p| p.set_yaw_deg(0)), a5_with(&[(9, 0xa0), (10, 0x01)]));
    }
    #[test]
    fn field_trunk() {
        let mut buf = [0xa5u8; 15];
        Packet::new_unchecked(&mut buf[..])
            .trunk_mut()
            .copy_from_slice(&[1, 2]);
        assert_eq!(buf[..13], [0xa5; 13]);
        assert_eq!(buf[13..], [1, 2]);
    }
}
