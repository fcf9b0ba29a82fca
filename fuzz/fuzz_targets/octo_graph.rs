//! OctoMap `.graph` files from any bytes: `octo::graph::read` never panics; a rejected input's
//! error offset lies within the input; an accepted one is exactly the format's size and
//! re-writes (`write_graph`) to bytes that read back to the same graph (values bit for bit,
//! every NaN counted equal) and that, NaNs aside, are the input itself with its unchecked
//! record tags set to 3 and 4 and its `f64` coordinates rounded to `f32`; `read_scans` agrees
//! with `read`, and so does `ScanStream` (the same scans, or the same error); and `write` of
//! its scans reads back with ids `0..n` and no edges.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_octo::graph::{
    self, EDGE_BYTES, EMPTY_NODE_BYTES, Graph, QUATERNION_RECORD_BYTES, VECTOR_RECORD_BYTES,
};
use rovlink_octo::{ParseError, Pose, Scan};

/// An `f32` as bits, every NaN one value (Rust's casts keep NaNs NaN, not their payloads).
fn key(v: f32) -> u32 {
    if v.is_nan() { u32::MAX } else { v.to_bits() }
}

fn pose_keys(p: &Pose, out: &mut Vec<u32>) {
    out.extend(p.translation_m.iter().chain(&p.rotation).map(|&v| key(v)));
}

/// Everything of a graph as comparable bits (lengths included, so that nothing shifts).
fn keys(g: &Graph) -> Vec<u64> {
    let mut f = Vec::new();
    let mut out = vec![
        g.scans.len() as u64,
        g.ids.len() as u64,
        g.edges.len() as u64,
    ];
    for s in &g.scans {
        out.push(s.points.len() as u64);
        f.clear();
        f.extend(s.points.iter().flatten().map(|&v| key(v)));
        pose_keys(&s.pose, &mut f);
        out.extend(f.iter().map(|&k| u64::from(k)));
        assert!(s.colors.is_none(), "a .graph scan has no colours");
    }
    out.extend(g.ids.iter().map(|&id| u64::from(id)));
    for e in &g.edges {
        out.extend([
            u64::from(e.first_id),
            u64::from(e.second_id),
            e.weight.to_bits(),
        ]);
        f.clear();
        pose_keys(&e.constraint, &mut f);
        out.extend(f.iter().map(|&k| u64::from(k)));
    }
    out
}

fn has_nan(g: &Graph) -> bool {
    let nan = |p: &Pose| {
        p.translation_m
            .iter()
            .chain(&p.rotation)
            .any(|v| v.is_nan())
    };
    g.scans
        .iter()
        .any(|s| nan(&s.pose) || s.points.iter().flatten().any(|v| v.is_nan()))
        || g.edges.iter().any(|e| nan(&e.constraint))
}

/// The input as the writer would write what was read from it: every record tag (the `i32`
/// before each vector and quaternion) set to 3 or 4 (the reader does not check them) and every
/// coordinate replaced by its `f32` value widened back (`f64` -> `f32` rounds); counts, ids
/// and edge weights unchanged.
fn as_rewritten(data: &[u8], g: &Graph) -> Vec<u8> {
    let mut b = data.to_vec();
    let record = |b: &mut Vec<u8>, at: usize, tag: i32, values: usize| {
        b[at..at + 4].copy_from_slice(&tag.to_le_bytes());
        for k in 0..values {
            let o = at + 4 + 8 * k;
            let mut v = [0u8; 8];
            v.copy_from_slice(&b[o..o + 8]);
            let narrowed = f64::from(f64::from_le_bytes(v) as f32);
            b[o..o + 8].copy_from_slice(&narrowed.to_le_bytes());
        }
    };
    let pose = |b: &mut Vec<u8>, at: usize| {
        record(b, at, 3, 3);
        record(b, at + VECTOR_RECORD_BYTES, 4, 4);
    };
    let mut at = 4;
    for s in &g.scans {
        at += 4;
        for _ in &s.points {
            record(&mut b, at, 3, 3);
            at += VECTOR_RECORD_BYTES;
        }
        pose(&mut b, at);
        at += VECTOR_RECORD_BYTES + QUATERNION_RECORD_BYTES + 4;
    }
    at += 4;
    for _ in &g.edges {
        pose(&mut b, at + 8);
        at += EDGE_BYTES;
    }
    assert_eq!(at, b.len());
    b
}

/// The scans as `ScanStream` reads them from a stream of the input's length.
fn streamed(data: &[u8]) -> Result<Vec<Scan>, ParseError> {
    graph::ScanStream::new(data, data.len() as u64)?.collect()
}

fuzz_target!(|data: &[u8]| {
    let g = match graph::read(data) {
        Ok(g) => g,
        Err(err) => {
            assert!(err.offset <= data.len() as u64, "{err}");
            assert_eq!(graph::read_scans(data), Err(err.clone()));
            assert_eq!(
                streamed(data),
                Err(err),
                "the stream fails where read fails"
            );
            return;
        }
    };
    let stream = streamed(data).expect("the stream accepts what read accepts");
    let same = Graph {
        scans: stream,
        ..g.clone()
    };
    assert_eq!(keys(&same), keys(&g), "the stream reads what read reads");
    let points: usize = g.scans.iter().map(|s| s.points.len()).sum();
    let size = 4
        + g.scans.len() * EMPTY_NODE_BYTES
        + points * VECTOR_RECORD_BYTES
        + 4
        + g.edges.len() * EDGE_BYTES;
    assert_eq!(size, data.len(), "accepted bytes are exactly the format");
    assert_eq!(g.ids.len(), g.scans.len());

    let bytes = graph::write_graph(&g);
    assert_eq!(bytes.len(), data.len());
    let back = graph::read(&bytes).expect("a re-written graph reads");
    assert_eq!(
        keys(&back),
        keys(&g),
        "re-written graph reads back different"
    );
    if !has_nan(&g) {
        // Byte for byte: the input with its tags and values as the writer writes them.
        assert_eq!(
            bytes,
            as_rewritten(data, &g),
            "re-written bytes differ from the input"
        );
    }

    let scans = graph::read_scans(data).expect("read_scans agrees with read");
    let same_scans = Graph {
        scans: scans.clone(),
        ..g.clone()
    };
    assert_eq!(keys(&same_scans), keys(&g), "read_scans differs from read");
    let plain = graph::read(&graph::write(&scans)).expect("written scans read");
    assert!(plain.edges.is_empty());
    assert!(
        plain
            .ids
            .iter()
            .enumerate()
            .all(|(i, &id)| id as usize == i)
    );
    assert_eq!(
        keys(&Graph {
            ids: g.ids.clone(),
            edges: g.edges.clone(),
            ..plain
        }),
        keys(&g)
    );
});
