//! CPU per frame: sealing and opening a frame (plain tag, and encrypted) against the anchor
//! measured in the same run, building a plain frame with its CRC (what every frame costs
//! without keys). Medians of 9 runs of 20,000 frames; the 16-byte operator frame and the
//! 57-byte ROV frame of the paper. Run: `cargo bench -p rovlink-security --bench seal`.

use std::hint::black_box;
use std::time::Instant;

use rovlink_security::counter::CounterStore;
use rovlink_security::{Guard, Key, KeyRing};
use rovlink_wire::frame;

const FRAMES: u64 = 20_000;
const RUNS: usize = 9;

/// Median ns per frame of `work` run [`FRAMES`] times, over [`RUNS`] runs.
fn median_ns(mut work: impl FnMut(u64)) -> f64 {
    let mut runs: Vec<f64> = (0..RUNS)
        .map(|_| {
            let t = Instant::now();
            for i in 0..FRAMES {
                work(i);
            }
            t.elapsed().as_nanos() as f64 / FRAMES as f64
        })
        .collect();
    runs.sort_by(f64::total_cmp);
    runs[RUNS / 2]
}

fn main() {
    let ring = KeyRing::single(Key::from_bytes(&[7u8; 16]).unwrap());
    println!("frame_bytes,what,ns_per_frame,x_anchor");
    for (src, dst, len) in [(0u8, 1u8, 11usize), (1, 0, 52)] {
        let message = vec![0x11u8; len];
        let plain = frame::build(src, dst, &message).unwrap();
        let anchor = median_ns(|_| {
            black_box(frame::build(src, dst, black_box(&message)).unwrap());
        });
        println!("{},plain build+crc (anchor),{anchor:.0},1.00", plain.len());
        for encrypt in [false, true] {
            let mut sender = Guard::new(ring.clone(), encrypt, CounterStore::in_memory());
            let seal = median_ns(|_| {
                black_box(sender.seal(black_box(&plain)).unwrap());
            });
            let mut sender = Guard::new(ring.clone(), encrypt, CounterStore::in_memory());
            let sealed: Vec<Vec<u8>> = (0..FRAMES * RUNS as u64)
                .map(|_| sender.seal(&plain).unwrap())
                .collect();
            let mut receiver = Guard::new(ring.clone(), encrypt, CounterStore::in_memory());
            let mut next = 0usize;
            let open = median_ns(|_| {
                black_box(receiver.open(black_box(&sealed[next])).unwrap());
                next += 1;
            });
            let what = if encrypt { "encrypted" } else { "tag" };
            println!("{},seal {what},{seal:.0},{:.2}", plain.len(), seal / anchor);
            println!("{},open {what},{open:.0},{:.2}", plain.len(), open / anchor);
        }
    }
}
