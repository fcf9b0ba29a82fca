//! Deframe + parse throughput of link-frame streams, on one core.
//!
//! Run: `cargo bench -p rovlink-wire --bench deframe` (add `-- --quick` for fewer repetitions). Prints one row
//! per case: the median throughput over the repetitions, the spread, and the ratio to the anchor
//! measured in the same run: a bare CRC-16 over every frame at known boundaries, the least work
//! any deframer must do. The bar is 100 MB/s of 57-byte frames.

use std::hint::black_box;
use std::time::Instant;

use rovlink_wire::frame::{CRC16, Frame};
use rovlink_wire::{DeframeEvent, Deframer, Message, MessageRepr, Nav, operator, rov};

/// A small deterministic generator so every run measures the same bytes.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
}

fn rov_frame(rng: &mut Lcg, seq: usize) -> Vec<u8> {
    let trunk: Vec<u8> = (0..39).map(|_| rng.next() as u8).collect();
    let repr = MessageRepr {
        src: 1,
        dst: 0,
        message: Message::Rov(rov::Repr {
            ft: seq.is_multiple_of(64),
            lt: seq % 64 == 63,
            isn: (seq / 64) % 2 == 1,
            ci: false,
            itsn: (seq % 64) as u8,
            status: rov::Status::Basic(rov::BasicStatus {
                rd: true,
                eoid: seq.is_multiple_of(2),
                loc: false,
                hh: true,
                arm: true,
                nav: Nav::Guided,
                x_cm: rng.next() as i16,
                y_cm: rng.next() as i16,
                z_cm: rng.next() as i16,
                roll_deg: (rng.next() % 360) as u16,
                pitch_deg: (rng.next() % 360) as u16,
                yaw_deg: (rng.next() % 360) as u16,
                extension: None,
            }),
            trunk,
        }),
    };
    let mut out = Vec::new();
    repr.emit_to_vec(&mut out).unwrap();
    out
}

fn operator_frame(rng: &mut Lcg) -> Vec<u8> {
    let repr = MessageRepr {
        src: 0,
        dst: 1,
        message: Message::Operator(operator::Repr {
            oid: false,
            clo: false,
            eisn: true,
            ic: false,
            rit: (rng.next() % 64) as u8,
            order: operator::Order::Velocity(operator::Velocity {
                vx: (rng.next() % 255) as i16 as i8 / 2,
                vy: (rng.next() % 255) as i16 as i8 / 2,
                vz: 0,
                vyaw: (rng.next() % 255) as i16 as i8 / 2,
                arm: true,
                disarm: false,
                nav: Nav::Stabilize,
            }),
        }),
    };
    let mut out = Vec::new();
    repr.emit_to_vec(&mut out).unwrap();
    out
}

const CHUNK_BYTES: usize = 64 * 1024;

/// Pushes the stream in chunks and hands every good frame to `per_frame`.
fn deframe_with(stream: &[u8], mut per_frame: impl FnMut(&Frame<&[u8]>)) -> u64 {
    let mut d = Deframer::new();
    for chunk in stream.chunks(CHUNK_BYTES) {
        d.push(chunk);
        while let Some(ev) = d.next_event() {
            if let DeframeEvent::Frame { frame, .. } = ev {
                per_frame(&frame);
            }
        }
    }
    d.finish();
    while d.next_event().is_some() {}
    d.stats().frames
}

struct Case<'a> {
    name: &'static str,
    stream: &'a [u8],
    run: Box<dyn Fn() -> u64 + 'a>,
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let reps = if quick { 3 } else { 11 };
    let mut rng = Lcg(0x5eed);
    let frame_count = 600_000;
    let rov_frames: Vec<Vec<u8>> = (0..frame_count).map(|i| rov_frame(&mut rng, i)).collect();
    let rov_stream: Vec<u8> = rov_frames.concat();
    let op_stream: Vec<u8> = (0..frame_count)
        .map(|_| operator_frame(&mut rng))
        .collect::<Vec<_>>()
        .concat();
    let bounds: Vec<(usize, usize)> = {
        let mut at = 0;
        rov_frames
            .iter()
            .map(|f| {
                let b = (at, at + f.len());
                at += f.len();
                b
            })
            .collect()
    };
    assert!(rov_frames.iter().all(|f| f.len() == 57));

    let cases = vec![
        Case {
            name: "anchor: CRC-16 at known boundaries (57 B)",
            stream: &rov_stream,
            run: Box::new(|| {
                let mut n = 0u64;
                for &(a, b) in &bounds {
                    let f = &rov_stream[a..b];
                    n += u64::from(
                        CRC16.checksum(&f[1..f.len() - 2])
                            == u16::from_be_bytes([f[b - a - 2], f[b - a - 1]]),
                    );
                }
                n
            }),
        },
        Case {
            name: "deframe only (57 B ROV frames)",
            stream: &rov_stream,
            run: Box::new(|| {
                deframe_with(&rov_stream, |f| {
                    black_box(f);
                })
            }),
        },
        Case {
            name: "deframe + zero-copy view (57 B)",
            stream: &rov_stream,
            run: Box::new(|| {
                let mut acc = 0i64;
                let n = deframe_with(&rov_stream, |f| {
                    if let Ok(p) = rov::Packet::new_checked(f.payload()) {
                        acc += i64::from(p.x_cm())
                            + i64::from(p.yaw_deg())
                            + i64::from(p.itsn())
                            + p.trunk().len() as i64;
                    }
                });
                black_box(acc);
                n
            }),
        },
        Case {
            name: "deframe + parse to Repr (57 B)",
            stream: &rov_stream,
            run: Box::new(|| {
                let mut ok = 0u64;
                deframe_with(&rov_stream, |f| {
                    let (repr, err) = MessageRepr::parse_lenient(f);
                    ok += u64::from(err.is_none());
                    black_box(repr);
                });
                ok
            }),
        },
        Case {
            name: "deframe + parse to Repr (16 B operator)",
            stream: &op_stream,
            run: Box::new(|| {
                let mut ok = 0u64;
                deframe_with(&op_stream, |f| {
                    let (repr, err) = MessageRepr::parse_lenient(f);
                    ok += u64::from(err.is_none());
                    black_box(repr);
                });
                ok
            }),
        },
    ];

    println!(
        "deframe+parse throughput, one core, {reps} repetitions, {} frames per stream (median; min..max)",
        frame_count
    );
    println!(
        "{:<44} {:>10} {:>17} {:>11} {:>8}",
        "case", "MB/s", "min..max MB/s", "Mframes/s", "x anchor"
    );
    let mut anchor = None;
    for case in &cases {
        let expected = (case.run)();
        assert_eq!(
            expected, frame_count as u64,
            "{}: every frame must be found and valid",
            case.name
        );
        let mut rates: Vec<f64> = (0..reps)
            .map(|_| {
                let t = Instant::now();
                black_box((case.run)());
                case.stream.len() as f64 / t.elapsed().as_secs_f64() / 1e6
            })
            .collect();
        let med = median(&mut rates);
        let (lo, hi) = (rates[0], rates[rates.len() - 1]);
        let frames_per_s = med * 1e6 / (case.stream.len() as f64 / frame_count as f64) / 1e6;
        let anchor_rate = *anchor.get_or_insert(med);
        println!(
            "{:<44} {:>10.1} {:>8.1}..{:<8.1} {:>11.2} {:>8.2}",
            case.name,
            med,
            lo,
            hi,
            frames_per_s,
            med / anchor_rate
        );
    }
}
