//! The link's text inputs: a model file (`Model::from_json`) and a distance track
//! (`Distance::from_csv`), from any bytes.
//!
//! Checks: neither parser panics; an accepted model is valid, prints to JSON that reads back
//! equal, and runs a short two-sided simulation to the end without panicking, with exactly one
//! report per frame offered (plus duplicates); an accepted track answers distances at any time.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_link::{Distance, Link, Model, Side, SimTime};

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(model) = Model::from_json(&text) {
        assert!(model.validate().is_ok(), "from_json returned an invalid model");
        let again = Model::from_json(&model.to_json()).expect("printed model reads back");
        assert_eq!(again, model);
        let distance = Distance::Track(vec![(0.0, 1.0), (1.0, 1e4), (2.0, 0.0)]);
        let mut link = Link::symmetric(model, 1, distance).expect("valid model makes a link");
        let mut offered = 0;
        for (k, byte) in data.iter().take(24).enumerate() {
            let side = if byte & 1 == 0 { Side::A } else { Side::B };
            link.advance(SimTime(k as u64 * u64::from(*byte) * 1_000_000));
            link.offer(side, vec![*byte; usize::from(*byte % 64)]);
            offered += 1;
        }
        let mut steps = 0u32;
        while link.step() {
            steps += 1;
            assert!(steps < 1_000_000, "the simulation does not end");
        }
        let mut reports = 0;
        while let Some(report) = link.pop_report() {
            reports += u32::from(!report.duplicate);
        }
        assert_eq!(reports, offered, "one report per frame");
    }
    if let Ok(track) = Distance::from_csv(data) {
        let mut link = Link::symmetric(Model::preset("s100").expect("preset"), 1, track)
            .expect("valid preset");
        for t in [0u64, 1, 1_000_000_000, u64::MAX / 2] {
            link.advance(SimTime(t));
            let distance = link.distance_m();
            assert!(distance.is_finite() && distance >= 0.0, "{distance}");
        }
    }
});
