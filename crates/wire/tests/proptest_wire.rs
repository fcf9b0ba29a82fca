//! Property tests of the wire formats: random messages pack to exactly the bytes an independent
//! bit-by-bit encoder of wire.md's tables gives, read back to the same value (through bytes and
//! through JSON), and the deframer finds every intact frame in a stream of garbage and
//! corrupted frames without ever panicking.

use proptest::prelude::*;
use rovlink_wire::frame::{self, Frame};
use rovlink_wire::operator::{self, ImageOrder, Order, Roi, Velocity};
use rovlink_wire::rov::{self, BasicStatus, Status};
use rovlink_wire::{DeframeEvent, Deframer, Message, MessageRepr, Nav, json};

// ---- strategies -------------------------------------------------------------------------

fn nav() -> impl Strategy<Value = Nav> {
    (0u8..8).prop_map(Nav::from_bits)
}

fn basic_status() -> impl Strategy<Value = BasicStatus> {
    (
        (
            any::<bool>(),
            any::<bool>(),
            any::<bool>(),
            any::<bool>(),
            any::<bool>(),
            nav(),
        ),
        (any::<i16>(), any::<i16>(), any::<i16>()),
        (0u16..360, 0u16..360, 0u16..360),
        proptest::option::of((any::<bool>(), 0u8..32)),
    )
        .prop_map(
            |(
                (rd, eoid, loc, hh, arm, nav),
                (x_cm, y_cm, z_cm),
                (roll_deg, pitch_deg, yaw_deg),
                extension,
            )| BasicStatus {
                rd,
                eoid,
                loc,
                hh,
                arm,
                nav,
                x_cm,
                y_cm,
                z_cm,
                roll_deg,
                pitch_deg,
                yaw_deg,
                extension: extension.map(|(no_position, why)| rov::Extension {
                    no_position,
                    why: rov::Why::from_bits(why),
                }),
            },
        )
}

fn rov_repr() -> impl Strategy<Value = rov::Repr> {
    let basic = (
        basic_status(),
        proptest::collection::vec(any::<u8>(), 0..=rov::MAX_TRUNK_BYTES),
    )
        .prop_map(|(s, mut trunk)| {
            if s.extension.is_some() {
                trunk.truncate(rov::MAX_EXTENDED_TRUNK_BYTES);
            }
            (Status::Basic(s), trunk)
        });
    let unknown = (2u8..64, proptest::collection::vec(any::<u8>(), 0..=253))
        .prop_map(|(st, raw)| (Status::Unknown { st, raw }, Vec::new()));
    (
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
        0u8..64,
        prop_oneof![9 => basic, 1 => unknown],
    )
        .prop_map(|(ft, lt, isn, ci, itsn, (status, trunk))| rov::Repr {
            ft,
            lt,
            isn,
            ci,
            itsn,
            status,
            trunk,
        })
}

fn thrust() -> impl Strategy<Value = i8> {
    -127i8..=127
}

fn order() -> impl Strategy<Value = Order> {
    prop_oneof![
        (
            thrust(),
            thrust(),
            thrust(),
            thrust(),
            any::<bool>(),
            any::<bool>(),
            nav()
        )
            .prop_map(
                |(vx, vy, vz, vyaw, arm, disarm, nav)| Order::Velocity(Velocity {
                    vx,
                    vy,
                    vz,
                    vyaw,
                    arm,
                    disarm,
                    nav
                })
            ),
        (any::<i16>(), any::<i16>(), any::<i16>(), 0u16..360).prop_map(
            |(x_cm, y_cm, z_cm, heading_deg)| Order::GoTo {
                x_cm,
                y_cm,
                z_cm,
                heading_deg
            }
        ),
        (
            [0u16..1024, 0u16..1024, 0u16..1024, 0u16..1024],
            0u8..16,
            any::<bool>(),
            0u8..4,
            any::<u16>(),
            any::<u8>()
        )
            .prop_map(|(roi, roi_shift, gray, scale, size_bytes, trunk_bytes)| {
                Order::ImageSettings(ImageOrder {
                    roi: Roi::from_array(roi),
                    roi_shift,
                    gray,
                    scale,
                    size_bytes,
                    trunk_bytes,
                })
            }),
        (0u16..360, any::<bool>()).prop_map(|(heading_deg, enable)| Order::HoldHeading {
            heading_deg,
            enable
        }),
        (4u8..16, any::<[u8; 9]>()).prop_map(|(ot, body)| Order::Unknown { ot, body }),
    ]
}

fn operator_repr() -> impl Strategy<Value = operator::Repr> {
    (
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
        0u8..64,
        order(),
    )
        .prop_map(|(oid, clo, eisn, ic, rit, order)| operator::Repr {
            oid,
            clo,
            eisn,
            ic,
            rit,
            order,
        })
}

fn message_repr() -> impl Strategy<Value = MessageRepr> {
    prop_oneof![
        4 => (1u8..16, 0u8..16, rov_repr()).prop_map(|(src, dst, r)| MessageRepr { src, dst, message: Message::Rov(r) }),
        4 => (0u8..16, operator_repr()).prop_map(|(dst, o)| MessageRepr { src: 0, dst, message: Message::Operator(o) }),
        1 => (0u8..16, 0u8..16, proptest::collection::vec(any::<u8>(), 0..=255))
            .prop_map(|(src, dst, p)| MessageRepr { src, dst, message: Message::Raw(p) }),
    ]
}

// ---- an independent encoder, bit by bit from wire.md's tables -------------------------------

#[derive(Default)]
struct Bits {
    bytes: Vec<u8>,
    used: u32,
}

impl Bits {
    fn push(&mut self, value: u64, width: u32) {
        for i in (0..width).rev() {
            if self.used.is_multiple_of(8) {
                self.bytes.push(0);
            }
            let bit = ((value >> i) & 1) as u8;
            *self.bytes.last_mut().unwrap() |= bit << (7 - self.used % 8);
            self.used += 1;
        }
    }
    fn flag(&mut self, b: bool) {
        self.push(u64::from(b), 1);
    }
    fn bytes(&mut self, data: &[u8]) {
        for &b in data {
            self.push(b.into(), 8);
        }
    }
}

fn reference_payload(message: &Message) -> Vec<u8> {
    let mut w = Bits::default();
    match message {
        Message::Rov(r) => {
            w.flag(r.ft);
            w.flag(r.lt);
            w.push(r.status.st().into(), 6);
            w.flag(r.isn);
            w.flag(r.ci);
            w.push(r.itsn.into(), 6);
            match &r.status {
                Status::Basic(s) => {
                    for f in [s.rd, s.eoid, s.loc, s.hh, s.arm] {
                        w.flag(f);
                    }
                    w.push(s.nav.bits().into(), 3);
                    for v in [s.x_cm, s.y_cm, s.z_cm] {
                        w.push(u64::from(v as u16), 16);
                    }
                    w.push(0, 5);
                    w.push(s.yaw_deg.into(), 9);
                    w.push(s.pitch_deg.into(), 9);
                    w.push(s.roll_deg.into(), 9);
                    if let Some(e) = s.extension {
                        w.flag(e.no_position);
                        w.push(0, 2);
                        w.push(e.why.bits().into(), 5);
                    }
                    w.bytes(&r.trunk);
                }
                Status::Unknown { raw, .. } => w.bytes(raw),
            }
        }
        Message::Operator(o) => {
            w.flag(o.oid);
            w.flag(o.clo);
            w.push(o.order.ot().into(), 4);
            w.push(0, 2);
            w.flag(o.eisn);
            w.flag(o.ic);
            w.push(o.rit.into(), 6);
            match o.order {
                Order::Velocity(velocity) => {
                    for v in velocity.axes() {
                        w.push(u64::from(v as u8), 8);
                    }
                    w.flag(velocity.arm);
                    w.flag(velocity.disarm);
                    w.push(0, 3);
                    w.push(velocity.nav.bits().into(), 3);
                }
                Order::GoTo {
                    x_cm,
                    y_cm,
                    z_cm,
                    heading_deg,
                } => {
                    for v in [x_cm, y_cm, z_cm] {
                        w.push(u64::from(v as u16), 16);
                    }
                    w.push(heading_deg.into(), 16);
                }
                Order::ImageSettings(ImageOrder {
                    roi,
                    roi_shift,
                    gray,
                    scale,
                    size_bytes,
                    trunk_bytes,
                }) => {
                    for c in roi.to_array() {
                        w.push(c.into(), 10);
                    }
                    w.push(roi_shift.into(), 4);
                    w.flag(gray);
                    w.push(0, 1);
                    w.push(scale.into(), 2);
                    w.push(size_bytes.into(), 16);
                    w.push(trunk_bytes.into(), 8);
                }
                Order::HoldHeading {
                    heading_deg,
                    enable,
                } => {
                    w.push(heading_deg.into(), 16);
                    w.flag(enable);
                    w.push(0, 7);
                }
                Order::Unknown { body, .. } => w.bytes(&body),
            }
            while w.bytes.len() < 11 {
                w.push(0, 8);
            }
        }
        Message::Raw(p) => w.bytes(p),
    }
    w.bytes
}

/// CRC-16/XMODEM, one bit at a time (independent of the crc crate the library uses).
fn reference_crc(data: &[u8]) -> u16 {
    let mut crc = 0u16;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

fn reference_frame(repr: &MessageRepr) -> Vec<u8> {
    let payload = reference_payload(&repr.message);
    let mut out = vec![0x55, repr.src << 4 | repr.dst, payload.len() as u8];
    out.extend(&payload);
    let crc = reference_crc(&out[1..]);
    out.extend(crc.to_be_bytes());
    out
}

fn emit(repr: &MessageRepr) -> Vec<u8> {
    let mut out = Vec::new();
    repr.emit_to_vec(&mut out).expect("valid repr emits");
    out
}

#[test]
fn reference_crc_check_value() {
    assert_eq!(reference_crc(b"123456789"), 0x31c3);
    assert_eq!(frame::CRC16.checksum(b"123456789"), 0x31c3);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn message_packs_to_the_spec_bytes(repr in message_repr()) {
        prop_assert_eq!(emit(&repr), reference_frame(&repr));
    }

    #[test]
    fn rov_repr_round_trips(repr in rov_repr()) {
        let mut buf = vec![0xa5u8; repr.buffer_len()];
        repr.emit(&mut rov::Packet::new_unchecked(&mut buf[..]));
        let back = rov::Repr::parse(&rov::Packet::new_checked(&buf[..]).unwrap()).unwrap();
        prop_assert_eq!(back, repr);
    }

    #[test]
    fn operator_repr_round_trips(repr in operator_repr()) {
        let mut buf = [0xa5u8; operator::MESSAGE_BYTES];
        repr.emit(&mut operator::Packet::new_unchecked(&mut buf[..]));
        let back = operator::Repr::parse(&operator::Packet::new_checked(&buf[..]).unwrap()).unwrap();
        prop_assert_eq!(back, repr);
    }

    #[test]
    fn frame_round_trips_through_bytes_and_json(repr in message_repr()) {
        let bytes = emit(&repr);
        let frame = Frame::new_checked(&bytes[..]).unwrap();
        let (parsed, error) = MessageRepr::parse_lenient(&frame);
        match &repr.message {
            // A random raw payload may happen to be a valid message: then it must re-emit the same.
            Message::Raw(_) => prop_assert_eq!(emit(&parsed), bytes.clone()),
            _ => {
                prop_assert!(error.is_none(), "{:?}", error);
                prop_assert_eq!(&parsed, &repr);
            }
        }
        let line = json::to_line(&repr);
        let from_json = json::parse_line(&line).unwrap();
        prop_assert_eq!(&from_json, &repr);
        prop_assert_eq!(json::to_line(&from_json), line);
    }
}

// ---- the deframer ----------------------------------------------------------------------

#[derive(Debug, Clone)]
enum Piece {
    Intact(MessageRepr),
    Garbage(Vec<u8>),
    /// A frame with bits flipped at these positions (byte index, bit), preamble excluded.
    Corrupted(MessageRepr, Vec<(usize, u8)>),
    /// The first bytes of a frame, cut short.
    Cut(MessageRepr, usize),
}

fn garbage() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 1..40),
        // Preamble-heavy garbage, the worst case for resynchronisation.
        proptest::collection::vec(prop_oneof![Just(0x55u8), any::<u8>()], 1..40),
    ]
}

fn piece() -> impl Strategy<Value = Piece> {
    prop_oneof![
        4 => message_repr().prop_map(Piece::Intact),
        2 => garbage().prop_map(Piece::Garbage),
        2 => (message_repr(), proptest::collection::vec((1usize..300, 0u8..8), 1..4)).prop_map(|(m, f)| Piece::Corrupted(m, f)),
        1 => (message_repr(), 1usize..300).prop_map(|(m, n)| Piece::Cut(m, n)),
    ]
}

/// Deframes `stream` pushed in chunks of the given sizes (cycled); returns the good frames.
fn deframe(stream: &[u8], chunks: &[usize]) -> (Vec<(u64, Vec<u8>)>, rovlink_wire::DeframeStats) {
    let mut d = Deframer::new();
    let mut found = Vec::new();
    let mut collect = |d: &mut Deframer| {
        while let Some(ev) = d.next_event() {
            if let DeframeEvent::Frame { offset, frame } = ev {
                found.push((offset, frame.into_inner().to_vec()));
            }
        }
    };
    let (mut at, mut i) = (0, 0);
    while at < stream.len() {
        let n = chunks[i % chunks.len()].max(1).min(stream.len() - at);
        d.push(&stream[at..at + n]);
        collect(&mut d);
        at += n;
        i += 1;
    }
    d.finish();
    collect(&mut d);
    (found, d.stats())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn deframer_finds_every_intact_frame(pieces in proptest::collection::vec(piece(), 1..30),
                                          chunks in proptest::collection::vec(1usize..200, 1..8)) {
        let mut stream = Vec::new();
        let mut intact = Vec::new();
        for p in &pieces {
            match p {
                Piece::Intact(m) => {
                    intact.push((stream.len() as u64, emit(m)));
                    stream.extend(emit(m));
                }
                Piece::Garbage(g) => stream.extend(g),
                Piece::Corrupted(m, flips) => {
                    let mut f = emit(m);
                    for &(at, bit) in flips {
                        let i = 1 + at % (f.len() - 1);
                        f[i] ^= 1 << bit;
                    }
                    stream.extend(f);
                }
                Piece::Cut(m, n) => {
                    let f = emit(m);
                    stream.extend(&f[..n % f.len()]);
                }
            }
        }
        let (found, stats) = deframe(&stream, &chunks);
        // Every frame found is a real frame (CRC checks) at the place it was found.
        for (offset, bytes) in &found {
            let o = *offset as usize;
            prop_assert_eq!(&stream[o..o + bytes.len()], &bytes[..]);
            prop_assert!(Frame::new_checked(&bytes[..]).unwrap().check().is_ok());
        }
        // Every intact frame is found, unless a frame that really checks (a CRC collision in
        // garbage, about 1 in 65536 per false preamble) covers its first byte.
        for (offset, bytes) in &intact {
            let hit = found.iter().any(|(o, b)| o == offset && b == bytes);
            let covered = found.iter().any(|(o, b)| o < offset && o + b.len() as u64 > *offset);
            prop_assert!(hit || covered, "intact frame at {} not found", offset);
        }
        // Accounting: every byte is in exactly one good frame or skipped.
        let in_frames: u64 = found.iter().map(|(_, b)| b.len() as u64).sum();
        prop_assert_eq!(in_frames + stats.bytes_skipped, stream.len() as u64);
        prop_assert_eq!(stats.frames, found.len() as u64);
        // Chunking never changes the result.
        let (whole, _) = deframe(&stream, &[stream.len().max(1)]);
        prop_assert_eq!(whole, found);
    }

    #[test]
    fn deframer_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..3000),
                             chunks in proptest::collection::vec(1usize..300, 1..8)) {
        let (found, stats) = deframe(&bytes, &chunks);
        let in_frames: u64 = found.iter().map(|(_, b)| b.len() as u64).sum();
        prop_assert_eq!(in_frames + stats.bytes_skipped, bytes.len() as u64);
        prop_assert_eq!(stats.bytes_in, bytes.len() as u64);
    }

    #[test]
    fn parsers_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        if let Ok(frame) = Frame::new_checked(&bytes[..]) {
            let _ = MessageRepr::parse(&frame);
            let _ = MessageRepr::parse_lenient(&frame);
        }
        let _ = Message::parse_payload(0, &bytes);
        let _ = Message::parse_payload(1, &bytes);
        let _ = json::parse_line(&String::from_utf8_lossy(&bytes));
    }
}
