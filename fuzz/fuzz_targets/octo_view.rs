//! The Foxglove view of a delta stream on arbitrary bytes: the arrivals reader and the scene
//! builder never panic, and no scene update sends an empty entity.
//!
//! Input: byte 0 even: the rest is an arrivals CSV, read and matched against an empty stream's
//! messages. Byte 0 odd: a valid header (coarse depth from byte 1, an ROI or none from byte 2)
//! followed by one message of kind byte 3 whose payload is the rest, framed with a correct CRC,
//! applied to a scene twice (a second message over the first).
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_octo::delta::{self, Roi, ViewSpec};
use rovlink_mapper::view::{self, SceneBuilder, Timing};

fuzz_target!(|data: &[u8]| {
    match data {
        [mode, depth, roi, kind, payload @ ..] if mode & 1 == 1 => {
            let spec = ViewSpec {
                resolution_m: 0.1,
                coarse_depth: 1 + u32::from(*depth % 16),
                roi: (roi & 1 == 1).then(|| Roi {
                    min_m: [-f64::from(*roi), -1.0, -0.5],
                    max_m: [0.3, f64::from(*roi) / 8.0, 2.0],
                }),
            };
            let mut stream = delta::encode_header(&spec);
            stream.extend(delta::frame_message(kind % 3, 7, payload));
            let Ok((_, messages)) = delta::decode_stream(&stream) else {
                return;
            };
            let mut scene = SceneBuilder::new(spec);
            for (k, m) in messages.iter().chain(&messages).enumerate() {
                let update = scene.apply(&m.message, k as u64);
                assert!(update.entities.iter().all(|e| !e.cubes.is_empty()), "no empty entity");
            }
        }
        [_, text @ ..] => {
            let _ = view::read_arrivals(text);
            let _ = view::log_times_ns(&[], usize::MAX, Timing::Arrivals { text, name: "a.csv" });
        }
        [] => {}
    }
});
