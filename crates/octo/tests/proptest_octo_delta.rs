//! Properties of the map-delta stream: applying every delta gives the operator exactly the view
//! of the final map (for any ROI and coarse depth), messages decode to what was encoded, and no
//! input, however damaged, makes a reader panic.

use proptest::prelude::*;
use rovlink_base::rng::Rng;
use rovlink_octo::delta::{self, Message, Receiver, Roi, Sender, ViewSpec};
use rovlink_octo::files;
use rovlink_octo::tree::OcTree;
use rovlink_octo::{Pose, Scan};

fn scan(rng: &mut Rng, colored: bool) -> Scan {
    let c = [
        (rng.uniform() * 4.0 - 2.0) as f32,
        (rng.uniform() * 4.0 - 2.0) as f32,
        1.0,
    ];
    let n = 400 + (rng.next_u32() % 800) as usize;
    let points: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            [
                (rng.uniform() * 5.0 - 2.5) as f32,
                (rng.uniform() * 5.0 - 2.5) as f32,
                (-1.0 - rng.uniform() * 1.5) as f32,
            ]
        })
        .collect();
    let colors = colored.then(|| {
        (0..n)
            .map(|_| {
                [
                    rng.next_u32() as u8,
                    rng.next_u32() as u8,
                    rng.next_u32() as u8,
                ]
            })
            .collect()
    });
    Scan {
        points,
        colors,
        pose: Pose {
            translation_m: c,
            rotation: [1.0, 0.0, 0.0, 0.0],
        },
    }
}

fn leaves(t: &OcTree) -> Vec<(u64, u32, bool, Option<[u8; 3]>)> {
    let mut v = Vec::new();
    t.for_each_leaf(|c, d, n| {
        v.push((
            c,
            d,
            n.log_odds >= 0.0,
            if n.log_odds >= 0.0 { n.color } else { None },
        ))
    });
    v
}

/// The occupancy of `leaves` (key, depth, occupied) with every 8 sibling leaves of one state
/// merged into their parent, as far up as that goes: two trees with the same occupancy at
/// every finest voxel give the same list, however they are split. (A coloured tree prunes 8
/// children once their colours agree; a receiver without colour updates keeps the colours
/// they had when they became occupied, so it may keep the 8.) Keys are the finest-depth
/// Morton codes of a node's first voxel.
fn canonical(leaves: Vec<(u64, u32, bool)>) -> Vec<(u64, u32, bool)> {
    use std::collections::BTreeMap;
    const FINEST: u32 = 16;
    let mut by_depth: BTreeMap<u32, BTreeMap<u64, bool>> = BTreeMap::new();
    for (code, depth, occupied) in leaves {
        by_depth.entry(depth).or_default().insert(code, occupied);
    }
    for depth in (1..=FINEST).rev() {
        let Some(level) = by_depth.remove(&depth) else {
            continue;
        };
        let span = 3 * (FINEST + 1 - depth);
        let mut groups: BTreeMap<u64, Vec<(u64, bool)>> = BTreeMap::new();
        for (code, occupied) in level {
            groups
                .entry(code & !((1u64 << span) - 1))
                .or_default()
                .push((code, occupied));
        }
        let mut kept = BTreeMap::new();
        for (parent, children) in groups {
            let same = children.len() == 8 && children.iter().all(|c| c.1 == children[0].1);
            if same {
                by_depth
                    .entry(depth - 1)
                    .or_default()
                    .insert(parent, children[0].1);
            } else {
                kept.extend(children);
            }
        }
        by_depth.insert(depth, kept);
    }
    let mut out: Vec<(u64, u32, bool)> = by_depth
        .into_iter()
        .flat_map(|(d, level)| level.into_iter().map(move |(c, o)| (c, d, o)))
        .collect();
    out.sort_unstable();
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(40))]

    #[test]
    fn applied_deltas_are_the_view_of_the_map(
        seed in 0u64..10_000,
        scans in 1usize..5,
        coarse_depth in 11u32..=16,
        roi in proptest::option::of((-3.0f64..3.0, -3.0f64..3.0, 0.1f64..3.0)),
        colored in any::<bool>(),
        color_updates in any::<bool>(),
    ) {
        let mut rng = Rng::new(seed, 7);
        let roi = roi.map(|(x, y, w)| Roi { min_m: [x, y, -5.0], max_m: [x + w, y + w, 5.0] });
        let spec = ViewSpec { resolution_m: 0.2, coarse_depth, roi };
        let mut tree = OcTree::new(0.2);
        if colored {
            tree.enable_color();
        }
        let mut tx = Sender::new(spec);
        tx.set_color_updates(color_updates);
        let mut stream = delta::encode_header(&spec);
        let mut sent = Vec::new();
        for k in 0..scans {
            let up = tree.insert_scan(&scan(&mut rng, colored), None);
            let d = tx.delta(&tree, &up.changes);
            stream.extend(delta::encode_delta(&spec, k as u32, &d));
            sent.push(d);
        }
        let (h, msgs) = delta::decode_stream(&stream).unwrap();
        prop_assert_eq!(h.spec, spec);
        let mut rx = Receiver::new(spec);
        for (m, d) in msgs.iter().zip(&sent) {
            match &m.message {
                Message::Delta { delta, .. } => prop_assert_eq!(delta, d),
                other => prop_assert!(false, "unexpected {:?}", other),
            }
            rx.apply(&m.message);
        }
        let want = delta::view_of(&tree, &spec);
        if color_updates {
            prop_assert_eq!(leaves(rx.view()), leaves(&want));
        } else {
            // Colours are those the voxels had when they became occupied; the states are exact
            // at every voxel (the split may differ: see `canonical`).
            let states = |t: &OcTree| {
                canonical(leaves(t).into_iter().map(|l| (l.0, l.1, l.2)).collect())
            };
            prop_assert_eq!(states(rx.view()), states(&want));
        }
        // The same view through a full message.
        let full = delta::encode_full(0, &want);
        let (m, _) = delta::decode_message(&spec, &full, 0).unwrap();
        let mut rx2 = Receiver::new(spec);
        rx2.apply(&m);
        prop_assert_eq!(leaves(rx2.view()), leaves(&want));
    }

    #[test]
    fn damaged_streams_and_maps_never_panic(
        seed in 0u64..10_000,
        cut in 0usize..4000,
        flips in proptest::collection::vec((0usize..4000, any::<u8>()), 0..6),
        junk in proptest::collection::vec(any::<u8>(), 0..300),
    ) {
        let mut rng = Rng::new(seed, 9);
        let spec = ViewSpec { resolution_m: 0.2, coarse_depth: 13, roi: None };
        let mut tree = OcTree::new(0.2);
        tree.enable_color();
        let up = tree.insert_scan(&scan(&mut rng, true), None);
        let mut tx = Sender::new(spec);
        let mut stream = delta::encode_header(&spec);
        stream.extend(delta::encode_delta(&spec, 0, &tx.delta(&tree, &up.changes)));
        stream.extend(delta::encode_full(1, &delta::view_of(&tree, &spec)));
        for bytes in [stream, files::write_ot(&tree), files::write_bt(&tree)] {
            let mut b = bytes.clone();
            for &(at, v) in &flips {
                if !b.is_empty() {
                    let i = at % b.len();
                    b[i] ^= v;
                }
            }
            b.truncate(cut.min(b.len()).max(b.len().saturating_sub(cut)));
            for input in [&b[..], &junk[..], &bytes[..bytes.len().min(cut)]] {
                if let Ok((h, msgs)) = delta::decode_stream(input) {
                    let mut rx = Receiver::new(h.spec);
                    for m in &msgs {
                        rx.apply(&m.message);
                    }
                }
                let _ = files::read_map(input);
            }
        }
    }
}
