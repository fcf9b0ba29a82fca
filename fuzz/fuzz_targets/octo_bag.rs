//! `octo::bag`'s MCAP walk on arbitrary bytes, and on valid frames around a zstd or lz4 chunk
//! of arbitrary bytes (so the decompressing path sees more than bad magic).
//!
//! Checks: opening and iterating every message never panics; each message's topic is a valid
//! index into the topics; reading the bag's scans (two passes, and one pass) never panics.

#![no_main]

use std::sync::atomic::AtomicBool;

use libfuzzer_sys::fuzz_target;
use rovlink_scans::bag::Bag;
use rovlink_scans::recording::{Recording, RecordingOptions};

const MAGIC: &[u8] = b"\x89MCAP0\r\n";

fn record(out: &mut Vec<u8>, opcode: u8, body: &[u8]) {
    out.push(opcode);
    out.extend((body.len() as u64).to_le_bytes());
    out.extend_from_slice(body);
}

/// A file whose one chunk holds `data` as its compressed records (size field from the input).
fn framed(compression: &str, size: u64, data: &[u8]) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    record(&mut out, 0x01, &[0; 8]);
    let mut b = Vec::new();
    b.extend([0u8; 16]);
    b.extend(size.to_le_bytes());
    b.extend(0u32.to_le_bytes());
    b.extend((compression.len() as u32).to_le_bytes());
    b.extend(compression.as_bytes());
    b.extend((data.len() as u64).to_le_bytes());
    b.extend_from_slice(data);
    record(&mut out, 0x06, &b);
    record(&mut out, 0x02, &[0; 20]);
    out.extend_from_slice(MAGIC);
    out
}

fn read_all(bytes: Vec<u8>) {
    let stop = AtomicBool::new(false);
    for one_pass in [false, true] {
        let options = RecordingOptions {
            origin_given: true,
            one_pass,
            ..RecordingOptions::default()
        };
        if let Ok(mut rec) = Recording::from_mcap_bytes("fuzz", bytes.clone(), &options, &stop)
            && let Ok(scans) = rec.scans(&stop)
        {
            scans.for_each(drop);
        }
    }
    let Ok(mut bag) = Bag::from_mcap_bytes("fuzz", bytes) else {
        return;
    };
    let n = bag.topics().len();
    let all: Vec<usize> = (0..n).collect();
    if let Ok(messages) = bag.messages(&all, &stop) {
        for m in messages.flatten() {
            assert!(m.topic < n, "topic index {} of {n}", m.topic);
        }
    }
}

fuzz_target!(|data: &[u8]| {
    read_all(data.to_vec());
    if let Some((&[a, b], rest)) = data.split_first_chunk::<2>() {
        // Sizes up to 64 KiB from the input, so a real decompression is attempted.
        let size = u64::from(u16::from_le_bytes([a, b]));
        read_all(framed("zstd", size, rest));
        read_all(framed("lz4", size, rest));
    }
});
