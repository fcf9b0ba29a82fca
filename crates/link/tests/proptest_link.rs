//! Property tests of the link state machine: for any valid model and any pattern of frames
//! offered from both sides, the link never panics, decides exactly one fate per frame, delivers
//! intact frames byte for byte, keeps time's order, never reorders unless asked, and ends with
//! nothing in flight. The same holds for a shared medium of N nodes, which reports every
//! frame once to each of the N - 1 other nodes.

use std::collections::HashMap;

use proptest::prelude::*;
use rovlink_link::model::{ErrorMode, GilbertElliott, JitterDistribution};
use rovlink_link::{Distance, Fate, Link, Medium, Model, Side, SimTime};

fn jitter() -> impl Strategy<Value = JitterDistribution> {
    prop_oneof![
        Just(JitterDistribution::None),
        Just(JitterDistribution::Uniform),
        Just(JitterDistribution::Normal),
        Just(JitterDistribution::Laplace),
    ]
}

prop_compose! {
    fn model()(
        bitrate_bps in 50.0..1e6f64,
        intrinsic_delay_ms in 0.0..500.0f64,
        jitter_distribution in jitter(),
        jitter_ms in 0.0..400.0f64,
        propagation_ms_per_m in 0.0..1.0f64,
        range_max_m in prop::option::of(1.0..100.0f64),
        ber in prop_oneof![Just(0.0), 0.0..0.01f64],
        corrupt in any::<bool>(),
        half_duplex in any::<bool>(),
        fifo_bytes in 1u64..4096,
        reorder in any::<bool>(),
        loss_percent in prop_oneof![Just(0.0), 0.0..50.0f64],
        burst in prop::option::of((0.0..30.0f64, 1.0..100.0f64)),
        corrupt_percent in prop_oneof![Just(0.0), 0.0..20.0f64],
        duplicate_percent in prop_oneof![Just(0.0), 0.0..20.0f64],
        rate_limit_bps in prop::option::of(50.0..1e6f64),
    ) -> Model {
        let mut model = Model::preset("s100").unwrap();
        model.bitrate_bps = bitrate_bps;
        model.intrinsic_delay_ms = intrinsic_delay_ms;
        model.jitter_distribution = jitter_distribution;
        model.jitter_ms = jitter_ms;
        model.propagation_ms_per_m = propagation_ms_per_m;
        model.range_min_m = 0.0;
        model.range_max_m = range_max_m;
        model.ber = ber;
        model.errors = if corrupt { ErrorMode::Corrupt } else { ErrorMode::Drop };
        model.half_duplex = half_duplex;
        model.fifo_bytes = fifo_bytes;
        model.reorder = reorder;
        model.loss_percent = loss_percent;
        model.gilbert_elliott = burst.map(|(p, r)| GilbertElliott {
            p_percent: p,
            r_percent: r,
            loss_bad_percent: 100.0,
            loss_good_percent: 0.0,
        });
        model.corrupt_percent = corrupt_percent;
        model.duplicate_percent = duplicate_percent;
        model.rate_limit_bps = rate_limit_bps;
        model
    }
}

/// (gap before the offer in ms, side B?, frame length)
fn offers() -> impl Strategy<Value = Vec<(u32, bool, usize)>> {
    prop::collection::vec((0u32..800, any::<bool>(), 0usize..300), 0..60)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn every_frame_gets_one_fate_and_arrivals_are_consistent(
        forward in model(),
        reverse in model(),
        seed in any::<u64>(),
        distance in 0.0..150.0f64,
        offers in offers(),
    ) {
        let mut link = Link::new(forward, reverse, seed, Distance::Fixed(distance)).unwrap();
        let mut sent: HashMap<(Side, u64), (Vec<u8>, SimTime)> = HashMap::new();
        let mut t = SimTime::ZERO;
        let mut reports = Vec::new();
        for (k, (gap_ms, from_b, len)) in offers.into_iter().enumerate() {
            t = SimTime(t.0 + u64::from(gap_ms) * 1_000_000);
            link.advance(t);
            let side = if from_b { Side::B } else { Side::A };
            let bytes: Vec<u8> = (0..len).map(|j| (k * 31 + j) as u8).collect();
            let seq = link.offer(side, bytes.clone());
            prop_assert!(sent.insert((side, seq), (bytes, link.now())).is_none());
            reports.extend(std::iter::from_fn(|| link.pop_report()));
        }
        while link.step() {}
        reports.extend(std::iter::from_fn(|| link.pop_report()));
        prop_assert_eq!(link.in_flight(), 0);

        let mut decided: HashMap<(Side, u64), Fate> = HashMap::new();
        let mut last_arrival: HashMap<Side, (SimTime, u64)> = HashMap::new();
        for report in &reports {
            let key = (report.from, report.seq);
            let (bytes, t_offered) = &sent[&key];
            prop_assert_eq!(report.t_offered, *t_offered);
            prop_assert_eq!(report.len, bytes.len());
            if report.duplicate {
                prop_assert!(report.fate.arrived());
                prop_assert_eq!(decided.get(&key), Some(&report.fate));
                continue;
            }
            prop_assert!(decided.insert(key, report.fate).is_none(), "two fates for {:?}", key);
            if let Some(tx) = report.t_tx_start {
                prop_assert!(tx >= report.t_offered);
            }
            match report.fate {
                Fate::Delivered => prop_assert_eq!(&report.bytes, bytes),
                Fate::Corrupted => prop_assert_ne!(&report.bytes, bytes),
                _ => prop_assert!(report.bytes.is_empty() && report.t_rx.is_none()),
            }
            if let Some(t_rx) = report.t_rx {
                prop_assert!(t_rx >= report.t_tx_start.unwrap());
                let model = link.model(report.from);
                if !model.reorder {
                    if let Some(&(last_t, last_seq)) = last_arrival.get(&report.from) {
                        prop_assert!(t_rx >= last_t && report.seq > last_seq, "reordered");
                    }
                    last_arrival.insert(report.from, (t_rx, report.seq));
                }
            }
        }
        prop_assert_eq!(decided.len(), sent.len());
    }
}

/// A position within 20 m of the origin (most pairs in S100's 5 m range, some not).
fn position() -> impl Strategy<Value = [f64; 3]> {
    [-10.0..10.0f64, -10.0..10.0f64, -3.0..3.0f64]
}

/// Gap before the offer in ms, sending node (some unknown), frame length, a node moved first.
type MediumOffer = (u32, usize, usize, Option<(usize, [f64; 3])>);

fn medium_offers() -> impl Strategy<Value = Vec<MediumOffer>> {
    let moved = prop::option::of((0usize..8, position()));
    prop::collection::vec((0u32..800, 0usize..8, 0usize..300, moved), 0..60)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn a_medium_reports_every_frame_once_to_every_other_node(
        model in model(),
        seed in any::<u64>(),
        positions in prop::collection::vec(position(), 1..7),
        offers in medium_offers(),
    ) {
        let nodes = positions.len();
        let mut medium = Medium::new(model, seed, positions).unwrap();
        let mut sent: HashMap<(usize, u64), (Vec<u8>, SimTime)> = HashMap::new();
        let mut t = SimTime::ZERO;
        let mut reports = Vec::new();
        for (k, (gap_ms, from, len, moved)) in offers.into_iter().enumerate() {
            t = SimTime(t.0 + u64::from(gap_ms) * 1_000_000);
            medium.advance(t);
            if let Some((node, position)) = moved {
                medium.set_position(node, position);
            }
            let bytes: Vec<u8> = (0..len).map(|j| (k * 31 + j) as u8).collect();
            let seq = medium.offer(from, bytes.clone());
            if from < nodes {
                prop_assert!(sent.insert((from, seq), (bytes, medium.now())).is_none());
            }
            reports.extend(std::iter::from_fn(|| medium.pop_report()));
        }
        while medium.step() {}
        reports.extend(std::iter::from_fn(|| medium.pop_report()));
        prop_assert_eq!(medium.in_flight(), 0);

        let mut decided: HashMap<(usize, u64, usize), Fate> = HashMap::new();
        let mut last_arrival: HashMap<(usize, usize), (SimTime, u64)> = HashMap::new();
        for report in &reports {
            prop_assert!(report.to < nodes && report.to != report.from);
            let (bytes, t_offered) = &sent[&(report.from, report.seq)];
            let key = (report.from, report.seq, report.to);
            prop_assert_eq!(report.t_offered, *t_offered);
            prop_assert_eq!(report.len, bytes.len());
            if report.duplicate {
                prop_assert!(report.fate.arrived());
                prop_assert_eq!(decided.get(&key), Some(&report.fate));
                continue;
            }
            prop_assert!(decided.insert(key, report.fate).is_none(), "two fates for {:?}", key);
            match report.fate {
                Fate::Delivered => prop_assert_eq!(&report.bytes, bytes),
                Fate::Corrupted => prop_assert_ne!(&report.bytes, bytes),
                _ => prop_assert!(report.bytes.is_empty() && report.t_rx.is_none()),
            }
            if let Some(t_rx) = report.t_rx {
                prop_assert!(t_rx >= report.t_tx_start.unwrap());
                if !medium.model().reorder {
                    let pair = (report.from, report.to);
                    if let Some(&(last_t, last_seq)) = last_arrival.get(&pair) {
                        prop_assert!(t_rx >= last_t && report.seq > last_seq, "reordered");
                    }
                    last_arrival.insert(pair, (t_rx, report.seq));
                }
            }
        }
        // Exactly N - 1 reports (not counting duplicates) per frame offered by a known node.
        prop_assert_eq!(decided.len(), sent.len() * (nodes - 1));
    }
}
