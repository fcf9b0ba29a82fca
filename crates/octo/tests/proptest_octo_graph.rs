//! Property tests of the `.graph` reader and writer: random graphs (any `f32` bit patterns,
//! ids, edges) write and read back equal, bit for bit; the writer's size is the format's; and
//! random bytes, every truncation and random mutations of valid files never panic (a truncated
//! file is always an error, an accepted mutated one re-writes to bytes that read back equal);
//! `ScanStream` reads the same scans or fails with the same error as `read`.

use proptest::prelude::*;
use rovlink_octo::graph::{self, EDGE_BYTES, EMPTY_NODE_BYTES, Edge, Graph, VECTOR_RECORD_BYTES};
use rovlink_octo::{Pose, Scan};

// ---- strategies -------------------------------------------------------------------------

/// Any `f32`, NaNs, infinities, subnormals and signed zeros included, weighted towards the
/// special ones.
fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => any::<u32>().prop_map(f32::from_bits),
        2 => -1e4f32..1e4,
        1 => prop::sample::select(vec![
            0.0,
            -0.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            f32::MAX,
            f32::MIN,
            f32::NAN,
        ]),
    ]
}

fn pose() -> impl Strategy<Value = Pose> {
    (
        prop::array::uniform3(any_f32()),
        prop::array::uniform4(any_f32()),
    )
        .prop_map(|(translation_m, rotation)| Pose {
            translation_m,
            rotation,
        })
}

fn scan() -> impl Strategy<Value = Scan> {
    (
        prop::collection::vec(prop::array::uniform3(any_f32()), 0..40),
        pose(),
    )
        .prop_map(|(points, pose)| Scan {
            points,
            colors: None,
            pose,
        })
}

fn edge() -> impl Strategy<Value = Edge> {
    (any::<u32>(), any::<u32>(), pose(), any::<u64>()).prop_map(
        |(first_id, second_id, constraint, weight)| Edge {
            first_id,
            second_id,
            constraint,
            weight: f64::from_bits(weight),
        },
    )
}

fn graph() -> impl Strategy<Value = Graph> {
    prop::collection::vec(scan(), 0..5).prop_flat_map(|scans| {
        let n = scans.len();
        (
            Just(scans),
            prop::collection::vec(any::<u32>(), n..=n),
            prop::collection::vec(edge(), 0..4),
        )
            .prop_map(|(scans, ids, edges)| Graph { scans, ids, edges })
    })
}

// ---- comparison -------------------------------------------------------------------------

/// Bits of an `f32` for equality: exact, except that every NaN is one value (the `f32` ->
/// `f64` -> `f32` casts keep a NaN a NaN but Rust does not promise its payload).
fn key(v: f32) -> u32 {
    if v.is_nan() { u32::MAX } else { v.to_bits() }
}

fn pose_bits(p: &Pose) -> Vec<u32> {
    p.translation_m
        .iter()
        .chain(&p.rotation)
        .map(|&v| key(v))
        .collect()
}

/// A graph as bits: nodes (points, pose), ids, edges (ids, constraint, weight).
type GraphBits = (
    Vec<(Vec<u32>, Vec<u32>)>,
    Vec<u32>,
    Vec<(u32, u32, Vec<u32>, u64)>,
);

/// Everything of a graph as bits: equal keys mean bit-for-bit equal values (NaNs aside).
fn graph_bits(g: &Graph) -> GraphBits {
    let scans = g
        .scans
        .iter()
        .map(|s| {
            (
                s.points.iter().flatten().map(|&v| key(v)).collect(),
                pose_bits(&s.pose),
            )
        })
        .collect();
    let edges = g
        .edges
        .iter()
        .map(|e| {
            (
                e.first_id,
                e.second_id,
                pose_bits(&e.constraint),
                e.weight.to_bits(),
            )
        })
        .collect();
    (scans, g.ids.clone(), edges)
}

fn has_nan(g: &Graph) -> bool {
    let (scans, _, edges) = graph_bits(g);
    let nan = u32::MAX;
    scans
        .iter()
        .any(|(p, q)| p.contains(&nan) || q.contains(&nan))
        || edges.iter().any(|(_, _, c, _)| c.contains(&nan))
}

fn expected_len(g: &Graph) -> usize {
    let points: usize = g.scans.iter().map(|s| s.points.len()).sum();
    4 + g.scans.len() * EMPTY_NODE_BYTES
        + points * VECTOR_RECORD_BYTES
        + 4
        + g.edges.len() * EDGE_BYTES
}

// ---- properties -------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn graphs_round_trip_bit_for_bit(g in graph()) {
        let bytes = graph::write_graph(&g);
        prop_assert_eq!(bytes.len(), expected_len(&g));
        let back = graph::read(&bytes).expect("a written graph reads");
        prop_assert_eq!(graph_bits(&back), graph_bits(&g));
        prop_assert!(back.scans.iter().all(|s| s.colors.is_none()));
        // Re-writing what was read gives the same bytes (the tags are always 3 and 4; NaN
        // payloads aside, which Rust's casts do not promise to keep).
        if !has_nan(&g) {
            prop_assert_eq!(graph::write_graph(&back), bytes);
        }
    }

    #[test]
    fn scans_round_trip_with_ids_and_no_edges(scans in prop::collection::vec(scan(), 0..5)) {
        let bytes = graph::write(&scans);
        let back = graph::read(&bytes).expect("written scans read");
        let ids: Vec<u32> = (0..scans.len() as u32).collect();
        let g = Graph { scans: scans.clone(), ids, edges: Vec::new() };
        prop_assert_eq!(graph_bits(&back), graph_bits(&g));
        prop_assert_eq!(graph::read_scans(&bytes).expect("reads").len(), scans.len());
        if !has_nan(&g) {
            prop_assert_eq!(graph::write_graph(&g), bytes);
        }
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        if let Ok(g) = graph::read(&bytes) {
            // Accepted means exactly the format: it re-writes to the same values and size.
            prop_assert_eq!(expected_len(&g), bytes.len());
            let again = graph::read(&graph::write_graph(&g)).expect("re-written graph reads");
            prop_assert_eq!(graph_bits(&again), graph_bits(&g));
        }
    }

    #[test]
    fn every_truncation_is_an_error(g in graph()) {
        let bytes = graph::write_graph(&g);
        for cut in 0..bytes.len() {
            let err = graph::read(&bytes[..cut]).expect_err("a truncated file is an error");
            let part = &bytes[..cut];
            let streamed: Result<Vec<Scan>, _> =
                graph::ScanStream::new(part, cut as u64).and_then(|s| s.collect());
            prop_assert_eq!(streamed, Err(err.clone()));
            prop_assert!(err.offset <= cut as u64, "offset {} beyond the cut {}", err.offset, cut);
            prop_assert!(err.message.contains("expected"), "{}", err.message);
        }
    }

    #[test]
    fn mutations_never_panic(
        g in graph(),
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        extra in prop::collection::vec(any::<u8>(), 0..8),
    ) {
        let mut bytes = graph::write_graph(&g);
        if !bytes.is_empty() {
            for (at, value) in &edits {
                let i = at.index(bytes.len());
                bytes[i] = *value;
            }
        }
        bytes.extend_from_slice(&extra);
        let streamed: Result<Vec<Scan>, _> = graph::ScanStream::new(&bytes[..], bytes.len() as u64)
            .and_then(|s| s.collect());
        match graph::read(&bytes) {
            Ok(back) => {
                let streamed = Graph { scans: streamed.expect("the stream reads it"), ..back.clone() };
                prop_assert_eq!(graph_bits(&streamed), graph_bits(&back));
                prop_assert_eq!(expected_len(&back), bytes.len());
                let again = graph::read(&graph::write_graph(&back)).expect("re-written graph reads");
                prop_assert_eq!(graph_bits(&again), graph_bits(&back));
            }
            Err(err) => {
                prop_assert!(err.offset <= bytes.len() as u64);
                prop_assert_eq!(streamed, Err(err), "the stream fails where read fails");
            }
        }
    }
}

#[test]
fn claimed_huge_counts_in_tiny_files_fail_fast() {
    // 4e9 nodes of 4e9 points each, then nothing: fails at the first missing point.
    let mut bytes = u32::MAX.to_le_bytes().to_vec();
    bytes.extend_from_slice(&u32::MAX.to_le_bytes());
    let err = graph::read(&bytes).unwrap_err();
    assert_eq!(err.offset, 8);
    assert!(
        err.message.contains("point 1 of 4294967295"),
        "{}",
        err.message
    );
    // A file of 1 node with a claimed huge point count and a few real points.
    let mut bytes = 1u32.to_le_bytes().to_vec();
    bytes.extend_from_slice(&3_000_000_000u32.to_le_bytes());
    bytes.extend_from_slice(&[0; 3 * VECTOR_RECORD_BYTES + 1]);
    let err = graph::read(&bytes).unwrap_err();
    assert_eq!(err.offset, (8 + 3 * VECTOR_RECORD_BYTES) as u64);
    assert_eq!(
        err.message,
        "node 1 of 1, point 4 of 3000000000: expected 28 bytes, 1 left"
    );
}
