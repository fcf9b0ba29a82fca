//! The operator -> ROV message: always 11 bytes, so the operator's frame is always 16 bytes and
//! its TDMA slot constant.
//!
//! ```text
//! offset  field
//! 0       OID:1 CLO:1 OT:4 reserved:2 (zero)
//! 1       EISN:1 IC:1 RIT:6
//! 2..=10  order body, 9 bytes, zero after the order's own fields
//! ```
//!
//! | OT | order | body |
//! |---|---|---|
//! | 0 | Velocity | vx, vy, vz, vyaw: i8 (-127..=127); byte 4: ARM:1 DISARM:1 reserved:3 NAV:3 |
//! | 1 | GoTo | x, y, z: i16 cm NED; heading: u16 whole degrees |
//! | 2 | ImageSettings | ROI x0, y0, x1, y1: 10 bits each MSB-first in 5 bytes; byte 5: ROI_SHIFT:4 GRAY:1 reserved:1 SCALE:2; bytes 6..=7 target size u16; byte 8 trunk size |
//! | 3 | HoldHeading | heading u16; byte 2: ENABLE:1 reserved:7 |
//! | 4..=15 | reserved | kept as [`Order::Unknown`] with the raw body |
//!
//! No-panic contract: after [`Packet::new_checked`] every getter is in bounds; [`Repr::parse`]
//! never panics and rejects reserved bits that are set, padding that is not zero and values out
//! of range, naming the field, so that every message it accepts is emitted back to the same
//! bytes.

use super::{Error, Nav, Result, check_range, get_bit, with_bit, with_bits};

/// Length of every operator message.
pub const MESSAGE_BYTES: usize = 11;
/// Length of the order body.
pub const BODY_BYTES: usize = 9;

/// Byte ranges and bit positions of the operator message. Body offsets are absolute.
mod field {
    use core::ops::Range;
    pub const FLAGS: usize = 0;
    pub const OID_BIT: u8 = 7;
    pub const CLO_BIT: u8 = 6;
    pub const OT_MASK: u8 = 0x3c;
    pub const OT_SHIFT: u8 = 2;
    pub const FLAGS_RESERVED: u8 = 0x03;
    pub const SEQ: usize = 1;
    pub const EISN_BIT: u8 = 7;
    pub const IC_BIT: u8 = 6;
    pub const RIT_MASK: u8 = 0x3f;
    pub const BODY: Range<usize> = 2..11;
    // Velocity
    pub const VX: usize = 2;
    pub const VY: usize = 3;
    pub const VZ: usize = 4;
    pub const VYAW: usize = 5;
    pub const VEL_MODE: usize = 6;
    pub const ARM_BIT: u8 = 7;
    pub const DISARM_BIT: u8 = 6;
    pub const VEL_MODE_RESERVED: u8 = 0x38;
    pub const NAV_MASK: u8 = 0x07;
    pub const VEL_END: usize = 7;
    // GoTo
    pub const GOTO_X: Range<usize> = 2..4;
    pub const GOTO_Y: Range<usize> = 4..6;
    pub const GOTO_Z: Range<usize> = 6..8;
    pub const GOTO_HEADING: Range<usize> = 8..10;
    pub const GOTO_END: usize = 10;
    // ImageSettings
    pub const ROI: Range<usize> = 2..7;
    pub const IMG_MODE: usize = 7;
    pub const ROI_SHIFT_MASK: u8 = 0xf0;
    pub const ROI_SHIFT_SHIFT: u8 = 4;
    pub const GRAY_BIT: u8 = 3;
    pub const IMG_MODE_RESERVED: u8 = 0x04;
    pub const SCALE_MASK: u8 = 0x03;
    pub const SIZE: Range<usize> = 8..10;
    pub const TRUNK: usize = 10;
    pub const IMG_END: usize = 11;
    // HoldHeading
    pub const HH_HEADING: Range<usize> = 2..4;
    pub const HH_MODE: usize = 4;
    pub const ENABLE_BIT: u8 = 7;
    pub const HH_MODE_RESERVED: u8 = 0x7f;
    pub const HH_END: usize = 5;
}

/// Order type codes (OT).
pub mod order_type {
    /// Velocity (low level, joystick).
    pub const VELOCITY: u8 = 0;
    /// GoTo a NED position and heading.
    pub const GOTO: u8 = 1;
    /// Image capture and coding settings.
    pub const IMAGE_SETTINGS: u8 = 2;
    /// Hold a heading.
    pub const HOLD_HEADING: u8 = 3;
}

/// A region of interest in pixels, each coordinate 10 bits (0..=1023). All zero means none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Roi {
    /// Left column.
    pub x0: u16,
    /// Top row.
    pub y0: u16,
    /// Right column.
    pub x1: u16,
    /// Bottom row.
    pub y1: u16,
}

impl Roi {
    /// The coordinates in wire order.
    pub const fn to_array(self) -> [u16; 4] {
        [self.x0, self.y0, self.x1, self.y1]
    }

    /// Builds a ROI from coordinates in wire order.
    pub const fn from_array(c: [u16; 4]) -> Roi {
        Roi {
            x0: c[0],
            y0: c[1],
            x1: c[2],
            y1: c[3],
        }
    }

    /// True for the all-zero rectangle, which means "no ROI".
    pub const fn is_none(self) -> bool {
        self.x0 == 0 && self.y0 == 0 && self.x1 == 0 && self.y1 == 0
    }
}

/// A read/write view of an operator message.
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

    /// Checks that the buffer is exactly [`MESSAGE_BYTES`] long.
    pub fn check_len(&self) -> Result<()> {
        let len = self.buffer.as_ref().len();
        if len != MESSAGE_BYTES {
            return Err(Error::BadLength {
                what: "operator message",
                expected: "11 bytes",
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

    fn u16_at(&self, range: core::ops::Range<usize>) -> u16 {
        let b = &self.buffer.as_ref()[range];
        u16::from_be_bytes([b[0], b[1]])
    }

    /// OID: one-bit id of the high-level order carried.
    pub fn oid(&self) -> bool {
        get_bit(self.byte(field::FLAGS), field::OID_BIT)
    }

    /// CLO: cancel the order in execution.
    pub fn clo(&self) -> bool {
        get_bit(self.byte(field::FLAGS), field::CLO_BIT)
    }

    /// OT: order type, 0..=15.
    pub fn ot(&self) -> u8 {
        (self.byte(field::FLAGS) & field::OT_MASK) >> field::OT_SHIFT
    }

    /// The two reserved bits of byte 0 (zero in a valid message).
    pub fn flags_reserved(&self) -> u8 {
        self.byte(field::FLAGS) & field::FLAGS_RESERVED
    }

    /// EISN: one-bit sequence number of the image the operator expects.
    pub fn eisn(&self) -> bool {
        get_bit(self.byte(field::SEQ), field::EISN_BIT)
    }

    /// IC: the operator confirms an image cancellation.
    pub fn ic(&self) -> bool {
        get_bit(self.byte(field::SEQ), field::IC_BIT)
    }

    /// RIT: the lowest image trunk still missing, 0..=63.
    pub fn rit(&self) -> u8 {
        self.byte(field::SEQ) & field::RIT_MASK
    }

    /// The 9-byte order body.
    pub fn body(&self) -> &[u8] {
        &self.buffer.as_ref()[field::BODY]
    }

    /// Velocity: surge thrust, -127..=127 = -100..=100 %.
    pub fn velocity_vx(&self) -> i8 {
        self.byte(field::VX) as i8
    }

    /// Velocity: sway thrust.
    pub fn velocity_vy(&self) -> i8 {
        self.byte(field::VY) as i8
    }

    /// Velocity: heave thrust.
    pub fn velocity_vz(&self) -> i8 {
        self.byte(field::VZ) as i8
    }

    /// Velocity: yaw thrust.
    pub fn velocity_vyaw(&self) -> i8 {
        self.byte(field::VYAW) as i8
    }

    /// Velocity: ARM request.
    pub fn velocity_arm(&self) -> bool {
        get_bit(self.byte(field::VEL_MODE), field::ARM_BIT)
    }

    /// Velocity: DISARM request.
    pub fn velocity_disarm(&self) -> bool {
        get_bit(self.byte(field::VEL_MODE), field::DISARM_BIT)
    }

    /// Velocity: requested navigation mode.
    pub fn velocity_nav(&self) -> Nav {
        Nav::from_bits(self.byte(field::VEL_MODE) & field::NAV_MASK)
    }

    /// GoTo: north in centimetres.
    pub fn goto_x_cm(&self) -> i16 {
        self.u16_at(field::GOTO_X) as i16
    }

    /// GoTo: east in centimetres.
    pub fn goto_y_cm(&self) -> i16 {
        self.u16_at(field::GOTO_Y) as i16
    }

    /// GoTo: down in centimetres.
    pub fn goto_z_cm(&self) -> i16 {
        self.u16_at(field::GOTO_Z) as i16
    }

    /// GoTo: heading in whole degrees.
    pub fn goto_heading_deg(&self) -> u16 {
        self.u16_at(field::GOTO_HEADING)
    }

    /// ImageSettings: the region of interest (four 10-bit fields, MSB first).
    pub fn image_roi(&self) -> Roi {
        let b = &self.buffer.as_ref()[field::ROI];
        let bits = b.iter().fold(0u64, |acc, &x| (acc << 8) | u64::from(x));
        let at = |i: u32| ((bits >> (30 - 10 * i)) & 0x3ff) as u16;
        Roi::from_array([at(0), at(1), at(2), at(3)])
    }

    /// ImageSettings: ROI up-shift in bit-planes, 0..=15.
    pub fn image_roi_shift(&self) -> u8 {
        (self.byte(field::IMG_MODE) & field::ROI_SHIFT_MASK) >> field::ROI_SHIFT_SHIFT
    }

    /// ImageSettings: capture in grey.
    pub fn image_gray(&self) -> bool {
        get_bit(self.byte(field::IMG_MODE), field::GRAY_BIT)
    }

    /// ImageSettings: capture downscale exponent (size / 2^scale), 0..=3.
    pub fn image_scale(&self) -> u8 {
        self.byte(field::IMG_MODE) & field::SCALE_MASK
    }

    /// ImageSettings: target encoded image size in bytes.
    pub fn image_size_bytes(&self) -> u16 {
        self.u16_at(field::SIZE)
    }

    /// ImageSettings: trunk size in bytes.
    pub fn image_trunk_bytes(&self) -> u8 {
        self.byte(field::TRUNK)
    }

    /// HoldHeading: heading in whole degrees.
    pub fn hold_heading_deg(&self) -> u16 {
        self.u16_at(field::HH_HEADING)
    }

    /// HoldHeading: enable (true) or release (false).
    pub fn hold_enable(&self) -> bool {
        get_bit(self.byte(field::HH_MODE), field::ENABLE_BIT)
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Packet<T> {
    fn update(&mut self, at: usize, f: impl FnOnce(u8) -> u8) {
        let b = &mut self.buffer.as_mut()[at];
        *b = f(*b);
    }

    fn set_u16_at(&mut self, range: core::ops::Range<usize>, value: u16) {
        self.buffer.as_mut()[range].copy_from_slice(&value.to_be_bytes());
    }

    /// Sets OID.
    pub fn set_oid(&mut self, value: bool) {
        self.update(field::FLAGS, |b| with_bit(b, field::OID_BIT, value));
    }

    /// Sets CLO.
    pub fn set_clo(&mut self, value: bool) {
        self.update(field::FLAGS, |b| with_bit(b, field::CLO_BIT, value));
    }

    /// Sets OT (low 4 bits).
    pub fn set_ot(&mut self, value: u8) {
        self.update(field::FLAGS, |b| {
            with_bits(b, field::OT_MASK, field::OT_SHIFT, value)
        });
    }

    /// Sets the two reserved bits of byte 0.
    pub fn set_flags_reserved(&mut self, value: u8) {
        self.update(field::FLAGS, |b| {
            with_bits(b, field::FLAGS_RESERVED, 0, value)
        });
    }

    /// Sets EISN.
    pub fn set_eisn(&mut self, value: bool) {
        self.update(field::SEQ, |b| with_bit(b, field::EISN_BIT, value));
    }

    /// Sets IC.
    pub fn set_ic(&mut self, value: bool) {
        self.update(field::SEQ, |b| with_bit(b, field::IC_BIT, value));
    }

    /// Sets RIT (low 6 bits).
    pub fn set_rit(&mut self, value: u8) {
        self.update(field::SEQ, |b| with_bits(b, field::RIT_MASK, 0, value));
    }

    /// The order body, writable.
    pub fn body_mut(&mut self) -> &mut [u8] {
        &mut self.buffer.as_mut()[field::BODY]
    }

    /// Sets Velocity vx.
    pub fn set_velocity_vx(&mut self, value: i8) {
        self.buffer.as_mut()[field::VX] = value as u8;
    }

    /// Sets Velocity vy.
    pub fn set_velocity_vy(&mut self, value: i8) {
        self.buffer.as_mut()[field::VY] = value as u8;
    }

    /// Sets Velocity vz.
    pub fn set_velocity_vz(&mut self, value: i8) {
        self.buffer.as_mut()[field::VZ] = value as u8;
    }

    /// Sets Velocity vyaw.
    pub fn set_velocity_vyaw(&mut self, value: i8) {
        self.buffer.as_mut()[field::VYAW] = value as u8;
    }

    /// Sets Velocity ARM.
    pub fn set_velocity_arm(&mut self, value: bool) {
        self.update(field::VEL_MODE, |b| with_bit(b, field::ARM_BIT, value));
    }

    /// Sets Velocity DISARM.
    pub fn set_velocity_disarm(&mut self, value: bool) {
        self.update(field::VEL_MODE, |b| with_bit(b, field::DISARM_BIT, value));
    }

    /// Sets Velocity NAV.
    pub fn set_velocity_nav(&mut self, value: Nav) {
        self.update(field::VEL_MODE, |b| {
            with_bits(b, field::NAV_MASK, 0, value.bits())
        });
    }

    /// Sets GoTo x.
    pub fn set_goto_x_cm(&mut self, value: i16) {
        self.set_u16_at(field::GOTO_X, value as u16);
    }

    /// Sets GoTo y.
    pub fn set_goto_y_cm(&mut self, value: i16) {
        self.set_u16_at(field::GOTO_Y, value as u16);
    }

    /// Sets GoTo z.
    pub fn set_goto_z_cm(&mut self, value: i16) {
        self.set_u16_at(field::GOTO_Z, value as u16);
    }

    /// Sets GoTo heading.
    pub fn set_goto_heading_deg(&mut self, value: u16) {
        self.set_u16_at(field::GOTO_HEADING, value);
    }

    /// Sets the ImageSettings ROI (each coordinate's low 10 bits).
    pub fn set_image_roi(&mut self, roi: Roi) {
        let bits = roi
            .to_array()
            .iter()
            .fold(0u64, |acc, &c| (acc << 10) | u64::from(c & 0x3ff));
        self.buffer.as_mut()[field::ROI].copy_from_slice(&bits.to_be_bytes()[3..]);
    }

    /// Sets the ImageSettings ROI shift (low 4 bits).
    pub fn set_image_roi_shift(&mut self, value: u8) {
        self.update(field::IMG_MODE, |b| {
            with_bits(b, field::ROI_SHIFT_MASK, field::ROI_SHIFT_SHIFT, value)
        });
    }

    /// Sets ImageSettings GRAY.
    pub fn set_image_gray(&mut self, value: bool) {
        self.update(field::IMG_MODE, |b| with_bit(b, field::GRAY_BIT, value));
    }

    /// Sets the ImageSettings scale exponent (low 2 bits).
    pub fn set_image_scale(&mut self, value: u8) {
        self.update(field::IMG_MODE, |b| {
            with_bits(b, field::SCALE_MASK, 0, value)
        });
    }

    /// Sets the ImageSettings target size.
    pub fn set_image_size_bytes(&mut self, value: u16) {
        self.set_u16_at(field::SIZE, value);
    }

    /// Sets the ImageSettings trunk size.
    pub fn set_image_trunk_bytes(&mut self, value: u8) {
        self.buffer.as_mut()[field::TRUNK] = value;
    }

    /// Sets the HoldHeading heading.
    pub fn set_hold_heading_deg(&mut self, value: u16) {
        self.set_u16_at(field::HH_HEADING, value);
    }

    /// Sets HoldHeading ENABLE.
    pub fn set_hold_enable(&mut self, value: bool) {
        self.update(field::HH_MODE, |b| with_bit(b, field::ENABLE_BIT, value));
    }
}

/// A Velocity order: the joystick's four axes and the arm and navigation demands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Velocity {
    /// Surge, -127..=127 (= -100..=100 % of full thrust).
    pub vx: i8,
    /// Sway, -127..=127.
    pub vy: i8,
    /// Heave, -127..=127.
    pub vz: i8,
    /// Yaw, -127..=127.
    pub vyaw: i8,
    /// Arm the thrusters.
    pub arm: bool,
    /// Disarm the thrusters.
    pub disarm: bool,
    /// Requested navigation mode.
    pub nav: Nav,
}

impl Velocity {
    /// The four axes: surge, sway, heave, yaw.
    pub const fn axes(&self) -> [i8; 4] {
        [self.vx, self.vy, self.vz, self.vyaw]
    }
}

/// An ImageSettings order: how the next images are taken, encoded and cut.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ImageOrder {
    /// Region of interest in pixels (all zero: none).
    pub roi: Roi,
    /// ROI up-shift in bit-planes, 0..=15.
    pub roi_shift: u8,
    /// Capture in grey.
    pub gray: bool,
    /// Capture downscale exponent, 0..=3 (size / 2^scale).
    pub scale: u8,
    /// Target encoded size in bytes.
    pub size_bytes: u16,
    /// Trunk size in bytes.
    pub trunk_bytes: u8,
}

/// One order, the body of an operator message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Order {
    /// Low-level joystick state; sent in every slot that carries no high-level order.
    Velocity(Velocity),
    /// Go to a NED position and heading.
    GoTo {
        /// North, centimetres.
        x_cm: i16,
        /// East, centimetres.
        y_cm: i16,
        /// Down, centimetres.
        z_cm: i16,
        /// Heading, whole degrees 0..=359.
        heading_deg: u16,
    },
    /// Settings for the next images; cancels the image in flight.
    ImageSettings(ImageOrder),
    /// Hold (or release) a heading.
    HoldHeading {
        /// Heading, whole degrees 0..=359.
        heading_deg: u16,
        /// Enable (true) or release (false).
        enable: bool,
    },
    /// A reserved order type (4..=15), kept with its raw body.
    Unknown {
        /// The OT value.
        ot: u8,
        /// The 9 body bytes.
        body: [u8; BODY_BYTES],
    },
}

impl Order {
    /// The OT code of this order.
    pub const fn ot(&self) -> u8 {
        match self {
            Order::Velocity(_) => order_type::VELOCITY,
            Order::GoTo { .. } => order_type::GOTO,
            Order::ImageSettings(_) => order_type::IMAGE_SETTINGS,
            Order::HoldHeading { .. } => order_type::HOLD_HEADING,
            Order::Unknown { ot, .. } => *ot,
        }
    }

    /// True for orders the ROV acknowledges through EOID (everything but Velocity).
    pub const fn is_high_level(&self) -> bool {
        !matches!(self, Order::Velocity(_))
    }

    /// The name used in the JSON form.
    pub const fn name(&self) -> &'static str {
        match self {
            Order::Velocity(_) => "velocity",
            Order::GoTo { .. } => "goto",
            Order::ImageSettings(_) => "image_settings",
            Order::HoldHeading { .. } => "hold_heading",
            Order::Unknown { .. } => "unknown",
        }
    }

    /// Offset (absolute, in the message) where the order's own fields end and padding begins.
    const fn fields_end(&self) -> usize {
        match self {
            Order::Velocity(_) => field::VEL_END,
            Order::GoTo { .. } => field::GOTO_END,
            Order::ImageSettings(_) => field::IMG_END,
            Order::HoldHeading { .. } => field::HH_END,
            Order::Unknown { .. } => MESSAGE_BYTES,
        }
    }
}

/// An operator -> ROV message as a value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Repr {
    /// Order id (one bit), equal to the ROV's last EOID for a new high-level order.
    pub oid: bool,
    /// Cancel the order in execution.
    pub clo: bool,
    /// Expected image sequence number (one bit).
    pub eisn: bool,
    /// Image cancellation confirmed.
    pub ic: bool,
    /// Requested image trunk, 0..=63.
    pub rit: u8,
    /// The order carried.
    pub order: Order,
}

fn check_heading(field: &'static str, value: u16) -> Result<()> {
    check_range(field, value.into(), 0, 359, "whole degrees 0..=359")
}

fn check_thrust(field: &'static str, value: i8) -> Result<()> {
    check_range(field, value.into(), -127, 127, "-127..=127")
}

fn check_reserved(field: &'static str, bits: u8) -> Result<()> {
    check_range(field, bits.into(), 0, 0, "0 (reserved)")
}

impl Repr {
    /// Reads a message, rejecting set reserved bits, non-zero padding and out-of-range values.
    pub fn parse<T: AsRef<[u8]>>(packet: &Packet<T>) -> Result<Repr> {
        packet.check_len()?;
        check_reserved("reserved bits of byte 0", packet.flags_reserved())?;
        let order = match packet.ot() {
            order_type::VELOCITY => {
                let mode = packet.byte(field::VEL_MODE);
                check_reserved("velocity reserved bits", mode & field::VEL_MODE_RESERVED)?;
                Order::Velocity(Velocity {
                    vx: packet.velocity_vx(),
                    vy: packet.velocity_vy(),
                    vz: packet.velocity_vz(),
                    vyaw: packet.velocity_vyaw(),
                    arm: packet.velocity_arm(),
                    disarm: packet.velocity_disarm(),
                    nav: packet.velocity_nav(),
                })
            }
            order_type::GOTO => Order::GoTo {
                x_cm: packet.goto_x_cm(),
                y_cm: packet.goto_y_cm(),
                z_cm: packet.goto_z_cm(),
                heading_deg: packet.goto_heading_deg(),
            },
            order_type::IMAGE_SETTINGS => {
                let mode = packet.byte(field::IMG_MODE);
                check_reserved(
                    "image_settings reserved bit",
                    mode & field::IMG_MODE_RESERVED,
                )?;
                Order::ImageSettings(ImageOrder {
                    roi: packet.image_roi(),
                    roi_shift: packet.image_roi_shift(),
                    gray: packet.image_gray(),
                    scale: packet.image_scale(),
                    size_bytes: packet.image_size_bytes(),
                    trunk_bytes: packet.image_trunk_bytes(),
                })
            }
            order_type::HOLD_HEADING => {
                let mode = packet.byte(field::HH_MODE);
                check_reserved("hold_heading reserved bits", mode & field::HH_MODE_RESERVED)?;
                Order::HoldHeading {
                    heading_deg: packet.hold_heading_deg(),
                    enable: packet.hold_enable(),
                }
            }
            ot => {
                let mut body = [0u8; BODY_BYTES];
                body.copy_from_slice(packet.body());
                Order::Unknown { ot, body }
            }
        };
        let padding = &packet.buffer.as_ref()[order.fields_end()..];
        if let Some(&nonzero) = padding.iter().find(|&&b| b != 0) {
            return Err(Error::BadField {
                field: "order padding",
                expected: "0",
                found: nonzero.into(),
            });
        }
        let repr = Repr {
            oid: packet.oid(),
            clo: packet.clo(),
            eisn: packet.eisn(),
            ic: packet.ic(),
            rit: packet.rit(),
            order,
        };
        repr.validate()?;
        Ok(repr)
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<()> {
        check_range("rit", self.rit.into(), 0, 63, "0..=63")?;
        match self.order {
            Order::Velocity(velocity) => {
                for (name, axis) in ["vx", "vy", "vz", "vyaw"].into_iter().zip(velocity.axes()) {
                    check_thrust(name, axis)?;
                }
                if let Nav::Unknown(v) = velocity.nav {
                    check_range("nav", v.into(), 5, 7, "a mode name or 5..=7")?;
                }
            }
            Order::GoTo { heading_deg, .. } => check_heading("heading_deg", heading_deg)?,
            Order::ImageSettings(image) => {
                for c in image.roi.to_array() {
                    check_range("roi", c.into(), 0, 1023, "pixel coordinates 0..=1023")?;
                }
                check_range("roi_shift", image.roi_shift.into(), 0, 15, "0..=15")?;
                check_range("scale", image.scale.into(), 0, 3, "0..=3")?;
            }
            Order::HoldHeading { heading_deg, .. } => check_heading("heading_deg", heading_deg)?,
            Order::Unknown { ot, .. } => {
                check_range("ot", ot.into(), 4, 15, "4..=15 for an unknown order")?;
            }
        }
        Ok(())
    }

    /// Bytes the message takes: always [`MESSAGE_BYTES`].
    pub const fn buffer_len(&self) -> usize {
        MESSAGE_BYTES
    }

    /// Writes the message into an 11-byte packet, zeroing reserved bits and padding.
    pub fn emit<T: AsRef<[u8]> + AsMut<[u8]>>(&self, packet: &mut Packet<T>) {
        debug_assert!(self.validate().is_ok(), "invalid operator repr {self:?}");
        packet.set_oid(self.oid);
        packet.set_clo(self.clo);
        packet.set_ot(self.order.ot());
        packet.set_flags_reserved(0);
        packet.set_eisn(self.eisn);
        packet.set_ic(self.ic);
        packet.set_rit(self.rit);
        packet.body_mut().fill(0);
        match self.order {
            Order::Velocity(v) => {
                packet.set_velocity_vx(v.vx);
                packet.set_velocity_vy(v.vy);
                packet.set_velocity_vz(v.vz);
                packet.set_velocity_vyaw(v.vyaw);
                packet.set_velocity_arm(v.arm);
                packet.set_velocity_disarm(v.disarm);
                packet.set_velocity_nav(v.nav);
            }
            Order::GoTo {
                x_cm,
                y_cm,
                z_cm,
                heading_deg,
            } => {
                packet.set_goto_x_cm(x_cm);
                packet.set_goto_y_cm(y_cm);
                packet.set_goto_z_cm(z_cm);
                packet.set_goto_heading_deg(heading_deg);
            }
            Order::ImageSettings(image) => {
                packet.set_image_roi(image.roi);
                packet.set_image_roi_shift(image.roi_shift);
                packet.set_image_gray(image.gray);
                packet.set_image_scale(image.scale);
                packet.set_image_size_bytes(image.size_bytes);
                packet.set_image_trunk_bytes(image.trunk_bytes);
            }
            Order::HoldHeading {
                heading_deg,
                enable,
            } => {
                packet.set_hold_heading_deg(heading_deg);
                packet.set_hold_enable(enable);
            }
            Order::Unknown { body, .. } => packet.body_mut().copy_from_slice(&body),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(bytes: &[u8]) -> Result<Repr> {
        Repr::parse(&Packet::new_checked(bytes)?)
    }

    fn emit(repr: &Repr) -> [u8; MESSAGE_BYTES] {
        let mut buf = [0xa5u8; MESSAGE_BYTES];
        repr.emit(&mut Packet::new_unchecked(&mut buf[..]));
        buf
    }

    #[test]
    fn vectors_parse_and_emit() {
        let cases: [(&[u8; 11], Repr); 4] = [
            (
                &[0x80, 0x05, 0x64, 0xec, 0x00, 0x81, 0x81, 0, 0, 0, 0],
                Repr {
                    oid: true,
                    clo: false,
                    eisn: false,
                    ic: false,
                    rit: 5,
                    order: Order::Velocity(Velocity {
                        vx: 100,
                        vy: -20,
                        vz: 0,
                        vyaw: -127,
                        arm: true,
                        disarm: false,
                        nav: Nav::Stabilize,
                    }),
                },
            ),
            (
                &[
                    0x44, 0xff, 0xff, 0x06, 0x04, 0xb0, 0x01, 0x36, 0x01, 0x67, 0x00,
                ],
                Repr {
                    oid: false,
                    clo: true,
                    eisn: true,
                    ic: true,
                    rit: 63,
                    order: Order::GoTo {
                        x_cm: -250,
                        y_cm: 1200,
                        z_cm: 310,
                        heading_deg: 359,
                    },
                },
            ),
            (
                &[
                    0x88, 0x80, 0x19, 0x05, 0x06, 0x91, 0x2c, 0x39, 0x07, 0xd0, 0x27,
                ],
                Repr {
                    oid: true,
                    clo: false,
                    eisn: true,
                    ic: false,
                    rit: 0,
                    order: Order::ImageSettings(ImageOrder {
                        roi: Roi::from_array([100, 80, 420, 300]),
                        roi_shift: 3,
                        gray: true,
                        scale: 1,
                        size_bytes: 2000,
                        trunk_bytes: 39,
                    }),
                },
            ),
            (
                &[0x0c, 0x0c, 0x01, 0x0e, 0x80, 0, 0, 0, 0, 0, 0],
                Repr {
                    oid: false,
                    clo: false,
                    eisn: false,
                    ic: false,
                    rit: 12,
                    order: Order::HoldHeading {
                        heading_deg: 270,
                        enable: true,
                    },
                },
            ),
        ];
        for (bytes, repr) in cases {
            assert_eq!(parse(bytes).unwrap(), repr);
            assert_eq!(&emit(&repr), bytes);
        }
    }

    #[test]
    fn unknown_order_is_kept() {
        let bytes = [0x3c, 0x01, 1, 2, 3, 4, 5, 6, 7, 8, 9];
        let repr = parse(&bytes).unwrap();
        assert_eq!(
            repr.order,
            Order::Unknown {
                ot: 15,
                body: [1, 2, 3, 4, 5, 6, 7, 8, 9]
            }
        );
        assert_eq!(emit(&repr), bytes);
    }

    #[test]
    fn strictness() {
        let velocity = [0x80u8, 0x05, 0x64, 0xec, 0x00, 0x81, 0x81, 0, 0, 0, 0];
        let mut b = velocity;
        b[0] |= 0x01;
        assert!(matches!(
            parse(&b),
            Err(Error::BadField {
                field: "reserved bits of byte 0",
                found: 1,
                ..
            })
        ));
        let mut b = velocity;
        b[10] = 7;
        assert_eq!(
            parse(&b).unwrap_err(),
            Error::BadField {
                field: "order padding",
                expected: "0",
                found: 7
            }
        );
        let mut b = velocity;
        b[2] = 0x80;
        assert!(matches!(
            parse(&b),
            Err(Error::BadField {
                field: "vx",
                found: -128,
                ..
            })
        ));
        let mut b = velocity;
        b[6] |= 0x08;
        assert!(matches!(
            parse(&b),
            Err(Error::BadField {
                field: "velocity reserved bits",
                ..
            })
        ));
        assert_eq!(
            parse(&velocity[..10]).unwrap_err(),
            Error::BadLength {
                what: "operator message",
                expected: "11 bytes",
                found: 10
            }
        );
        let goto = [
            0x44u8, 0xff, 0xff, 0x06, 0x04, 0xb0, 0x01, 0x36, 0x01, 0x68, 0x00,
        ];
        assert!(matches!(
            parse(&goto),
            Err(Error::BadField {
                field: "heading_deg",
                found: 360,
                ..
            })
        ));
    }

    /// Applies one setter to an 11-byte buffer of 0xa5 and returns the bytes.
    fn set(f: impl FnOnce(&mut Packet<&mut [u8]>)) -> [u8; 11] {
        let mut buf = [0xa5u8; 11];
        f(&mut Packet::new_unchecked(&mut buf[..]));
        buf
    }

    fn a5_with(changes: &[(usize, u8)]) -> [u8; 11] {
        crate::field_test::a5_with(changes)
    }

    #[test]
    fn field_oid() {
        assert_eq!(set(|p| p.set_oid(false)), a5_with(&[(0, 0x25)]));
    }
    #[test]
    fn field_clo() {
        assert_eq!(set(|p| p.set_clo(true)), a5_with(&[(0, 0xe5)]));
    }
    #[test]
    fn field_ot() {
        assert_eq!(set(|p| p.set_ot(0xf)), a5_with(&[(0, 0xbd)]));
    }
    #[test]
    fn field_reserved() {
        assert_eq!(set(|p| p.set_flags_reserved(0)), a5_with(&[(0, 0xa4)]));
    }
    #[test]
    fn field_eisn() {
        assert_eq!(set(|p| p.set_eisn(false)), a5_with(&[(1, 0x25)]));
    }
    #[test]
    fn field_ic() {
        assert_eq!(set(|p| p.set_ic(true)), a5_with(&[(1, 0xe5)]));
    }
    #[test]
    fn field_rit() {
        assert_eq!(set(|p| p.set_rit(0)), a5_with(&[(1, 0x80)]));
    }
    #[test]
    fn field_velocity_axes() {
        assert_eq!(set(|p| p.set_velocity_vx(-1)), a5_with(&[(2, 0xff)]));
        assert_eq!(set(|p| p.set_velocity_vy(127)), a5_with(&[(3, 0x7f)]));
        assert_eq!(set(|p| p.set_velocity_vz(-127)), a5_with(&[(4, 0x81)]));
        assert_eq!(set(|p| p.set_velocity_vyaw(0)), a5_with(&[(5, 0x00)]));
    }
    #[test]
    fn field_velocity_arm() {
        assert_eq!(set(|p| p.set_velocity_arm(false)), a5_with(&[(6, 0x25)]));
    }
    #[test]
    fn field_velocity_disarm() {
        assert_eq!(set(|p| p.set_velocity_disarm(true)), a5_with(&[(6, 0xe5)]));
    }
    #[test]
    fn field_velocity_nav() {
        assert_eq!(
            set(|p| p.set_velocity_nav(Nav::Guided)),
            a5_with(&[(6, 0xa4)])
        );
    }
    #[test]
    fn field_goto() {
        assert_eq!(
            set(|p| p.set_goto_x_cm(-250)),
            a5_with(&[(2, 0xff), (3, 0x06)])
        );
        assert_eq!(
            set(|p| p.set_goto_y_cm(1200)),
            a5_with(&[(4, 0x04), (5, 0xb0)])
        );
        assert_eq!(
            set(|p| p.set_goto_z_cm(310)),
            a5_with(&[(6, 0x01), (7, 0x36)])
        );
        assert_eq!(
            set(|p| p.set_goto_heading_deg(359)),
            a5_with(&[(8, 0x01), (9, 0x67)])
        );
    }
    #[test]
    fn field_image_roi() {
        let roi = Roi::from_array([100, 80, 420, 300]);
        let expected = a5_with(&[(2, 0x19), (3, 0x05), (4, 0x06), (5, 0x91), (6, 0x2c)]);
        assert_eq!(set(|p| p.set_image_roi(roi)), expected);
        assert_eq!(Packet::new_unchecked(&expected[..]).image_roi(), roi);
    }
    #[test]
    fn field_image_roi_shift() {
        assert_eq!(set(|p| p.set_image_roi_shift(3)), a5_with(&[(7, 0x35)]));
    }
    #[test]
    fn field_image_gray() {
        assert_eq!(set(|p| p.set_image_gray(true)), a5_with(&[(7, 0xad)]));
    }
    #[test]
    fn field_image_scale() {
        assert_eq!(set(|p| p.set_image_scale(2)), a5_with(&[(7, 0xa6)]));
    }
    #[test]
    fn field_image_size_and_trunk() {
        assert_eq!(
            set(|p| p.set_image_size_bytes(2000)),
            a5_with(&[(8, 0x07), (9, 0xd0)])
        );
        assert_eq!(set(|p| p.set_image_trunk_bytes(39)), a5_with(&[(10, 0x27)]));
    }
    #[test]
    fn field_hold_heading() {
        assert_eq!(
            set(|p| p.set_hold_heading_deg(270)),
            a5_with(&[(2, 0x01), (3, 0x0e)])
        );
        assert_eq!(set(|p| p.set_hold_enable(false)), a5_with(&[(4, 0x25)]));
    }
}
