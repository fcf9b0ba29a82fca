//! The operator's view as Foxglove plays it: an MCAP file with one `foxglove.SceneUpdate` per
//! message of a delta stream, logged when that message reached the operator, so Foxglove's 3D
//! panel shows the map growing as the operator saw it.
//!
//! # Entities
//!
//! The view ([`Receiver`](rovlink_octo::delta::Receiver)'s octree) is cut into *units*: a node at [`BLOCK_DEPTH`] (a block of
//! 8 x 8 x 8 fine voxels), or a leaf above that depth (a coarse voxel bigger than a block, a
//! pruned region). Units never overlap. Each unit with occupied space is one entity per class,
//! with id `fine/<depth>/<x>,<y>,<z>` or `coarse/<depth>/<x>,<y>,<z>` (the unit's depth and the
//! key of its first voxel), holding one `CubePrimitive` per occupied leaf of the unit: centre
//! and edge of the leaf (a box, when a leaf bigger than a coarse voxel straddles the ROI's
//! edge and is cut there), in frame [`FRAME_ID`].
//!
//! After each message, every unit the message touched is sent again whole (an entity replaces
//! the one with the same id), and the entities of units that became empty, or were split or
//! merged into other units, are deleted (`deletions`, by id). So at any time the entities are
//! exactly the occupied voxels of the view: voxels that become free disappear. A full message
//! touches everything. A unit holds at most 512 fine voxels, so what one changed voxel costs
//! is bounded.
//!
//! Fine voxels (inside the ROI, widened to whole coarse voxels, as [`ViewSpec::coarse_in_roi`](rovlink_octo::delta::ViewSpec::coarse_in_roi)
//! says) are drawn opaque in their colour, or by height (a hue that runs from red to blue and
//! back every [`HEIGHT_PERIOD_M`]) when the map has none; coarse voxels are translucent grey.
//!
//! # Times
//!
//! Message k is logged (MCAP `log_time` and `publish_time`, and the entities' `timestamp`) at
//! `k x scan_period_s`, or with `build --link ... --arrivals` rows at that scan's `t_shown_s`:
//! when it and every earlier message were complete, which is when the operator's view (which
//! applies messages in order) changed. It equals `t_complete_s` unless a later message
//! completed first; logging at `t_complete_s` then would replay an older state of a unit after
//! a newer one. The arrivals file is read strictly: its header, every field, one row per
//! message in stream order with the scan number and size of that message.
//!
//! # Encoding
//!
//! Messages are JSON (`json` message encoding) with the official JSON Schema of
//! `foxglove.SceneUpdate` (`jsonschema` schema encoding; [`SCENE_UPDATE_SCHEMA`] is
//! `schemas/jsonschema/SceneUpdate.json` of github.com/foxglove/foxglove-sdk at commit
//! 9ed45b16, MIT licence), written with the `mcap` crate, uncompressed, never seeking. Foxglove
//! plays JSON-encoded MCAP with well-known schema names natively; the official `foxglove`
//! crate's protobuf encoding would be smaller on disk but brings its generated types and
//! another MCAP writer for one message type, and the JSON is what other tools here write
//! (`rcp::mcap_log`).
//!
//! Foxglove fetches only the latest message of a topic when it seeks, so an incremental scene
//! is right when played from the start; after a seek backwards, play again from the start.
//!
//! Nothing here panics on any input: the stream and arrivals parsers return errors naming the
//! offset or the line and column, and memory is bounded by the view (which is bounded by the
//! stream) plus one message.

mod arrivals_csv;
mod foxglove_types;
mod key_box;
mod scene;
#[cfg(test)]
mod test_support;
mod timing;
pub mod voxels;

use std::collections::BTreeMap;
use std::io::Write;

use crate::pipeline::{self, ConfigError, PipelineError};
use rovlink_octo::tree::OcTree;

pub use arrivals_csv::{ArrivalTime, ArrivalsError, read_arrivals};
pub use foxglove_types::{
    Color, Cube, Deletion, Entity, PoseJson, Quaternion, SCENE_UPDATE_SCHEMA, SCHEMA_NAME,
    SceneUpdate, Time, Vector3,
};
pub use scene::{BLOCK_DEPTH, FRAME_ID, HEIGHT_PERIOD_M, SceneBuilder};
pub use timing::{Timing, log_times_ns};

/// The topic of the scene updates.
pub const TOPIC: &str = "/octo_delta/view";
/// Latest log time, s (about 32 years: a log time in ns stays far inside 64 bits).
pub const MAX_TIME_S: f64 = 1e9;

/// Why a view could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The stream does not parse, or a number is out of range.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// A time beyond [`MAX_TIME_S`].
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The arrivals file is wrong, or does not go with the stream.
    #[error("{name}: {source}")]
    Arrivals {
        /// The file.
        name: String,
        /// Where and what.
        source: ArrivalsError,
    },
    /// A scene update did not encode as JSON (it holds only finite numbers and strings).
    #[error("scene update: {0}")]
    Json(serde_json::Error),
    /// The MCAP writer failed (usually the disk).
    #[error("{name}: MCAP: {source}")]
    Mcap {
        /// The output.
        name: String,
        /// The writer's error.
        source: mcap::McapError,
    },
}

/// What writing a view did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ViewReport {
    /// Scene updates written (one per message applied).
    pub messages: usize,
    /// Entities sent, replacements included.
    pub entities_sent: u64,
    /// Deletions sent.
    pub deletions: u64,
    /// Cubes sent.
    pub cubes_sent: u64,
    /// Entities in the scene at the end.
    pub entities_at_end: usize,
    /// The largest scene update, bytes of JSON.
    pub largest_message_bytes: usize,
}

/// Applies the first `messages` messages of a stream (`stream`, named `name`) and writes the
/// scene as it grew to `out` (named `out_name`) as MCAP; returns the view at the end and what
/// was written. The stream and the arrivals are checked whole before anything is written.
pub fn apply_with_view(
    stream: &[u8],
    name: &str,
    messages: usize,
    timing: Timing<'_>,
    out: &mut dyn Write,
    out_name: &str,
) -> Result<(OcTree, ViewReport), ViewError> {
    let (header, msgs) = pipeline::read_stream(stream, name)?;
    let times = log_times_ns(&msgs, messages, timing)?;
    let wrap = |source| ViewError::Mcap {
        name: out_name.to_string(),
        source,
    };
    let mut writer = rovlink_base::io::json_mcap_writer(out).map_err(wrap)?;
    let spec = header.spec;
    let mut about = BTreeMap::new();
    about.insert("resolution_m".to_string(), spec.resolution_m.to_string());
    about.insert("coarse_depth".to_string(), spec.coarse_depth.to_string());
    let channel = rovlink_base::io::json_mcap_channel(
        &mut writer,
        SCHEMA_NAME,
        SCENE_UPDATE_SCHEMA,
        TOPIC,
        &about,
    )
    .map_err(wrap)?;
    let mut scene = SceneBuilder::new(spec);
    let mut report = ViewReport::default();
    for (k, (m, &t_ns)) in msgs.iter().zip(&times).enumerate() {
        let update = scene.apply(&m.message, t_ns);
        report.entities_sent += update.entities.len() as u64;
        report.deletions += update.deletions.len() as u64;
        report.cubes_sent += update
            .entities
            .iter()
            .map(|e| e.cubes.len() as u64)
            .sum::<u64>();
        let json = serde_json::to_vec(&update).map_err(ViewError::Json)?;
        report.largest_message_bytes = report.largest_message_bytes.max(json.len());
        let h = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: k as u32,
            log_time: t_ns,
            publish_time: t_ns,
        };
        writer.write_to_known_channel(&h, &json).map_err(wrap)?;
        report.messages += 1;
    }
    writer.finish().map_err(wrap)?;
    report.entities_at_end = scene.entities();
    Ok((scene.view().clone(), report))
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::test_support::{assert_same, messages, replay};
    use super::*;
    use rovlink_octo::delta::{self, Message, Roi, ViewSpec};

    #[test]
    fn the_mcap_holds_one_valid_update_per_message() {
        let spec = ViewSpec {
            resolution_m: 0.2,
            coarse_depth: 13,
            roi: None,
        };
        let mut stream = delta::encode_header(&spec);
        for m in messages(&spec).iter().take(2) {
            if let Message::Delta { scan, delta: d } = m {
                stream.extend(delta::encode_delta(&spec, *scan, d));
            }
        }
        let mut out = Vec::new();
        let (view, report) = apply_with_view(
            &stream,
            "s.odl",
            usize::MAX,
            Timing::Period(2.0),
            &mut out,
            "v.mcap",
        )
        .unwrap();
        assert_eq!(report.messages, 2);
        assert!(report.cubes_sent > 0 && report.largest_message_bytes > 0);
        let mut scene = HashMap::new();
        let stream_msgs = mcap::MessageStream::new(&out).unwrap();
        for (k, m) in stream_msgs.enumerate() {
            let m = m.unwrap();
            assert_eq!(m.channel.topic, TOPIC);
            let schema = m.channel.schema.as_ref().unwrap();
            assert_eq!(
                (schema.name.as_str(), schema.encoding.as_str()),
                (SCHEMA_NAME, "jsonschema")
            );
            assert_eq!(m.channel.message_encoding, "json");
            assert_eq!(m.log_time, k as u64 * 2_000_000_000);
            assert_eq!(m.publish_time, m.log_time);
            let u: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            for e in u["entities"].as_array().unwrap() {
                let cubes: Vec<Cube> = e["cubes"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|c| Cube {
                        pose: PoseJson {
                            position: Vector3 {
                                x: c["pose"]["position"]["x"].as_f64().unwrap(),
                                y: c["pose"]["position"]["y"].as_f64().unwrap(),
                                z: c["pose"]["position"]["z"].as_f64().unwrap(),
                            },
                            orientation: Quaternion {
                                x: 0.0,
                                y: 0.0,
                                z: 0.0,
                                w: 1.0,
                            },
                        },
                        size: Vector3 {
                            x: c["size"]["x"].as_f64().unwrap(),
                            y: c["size"]["y"].as_f64().unwrap(),
                            z: c["size"]["z"].as_f64().unwrap(),
                        },
                        color: Color {
                            r: c["color"]["r"].as_f64().unwrap(),
                            g: c["color"]["g"].as_f64().unwrap(),
                            b: c["color"]["b"].as_f64().unwrap(),
                            a: c["color"]["a"].as_f64().unwrap(),
                        },
                    })
                    .collect();
                scene.insert(e["id"].as_str().unwrap().to_string(), cubes);
            }
        }
        assert_same(&scene, &view, &spec);
        // A bad stream writes nothing.
        let mut none = Vec::new();
        let err = apply_with_view(
            b"ODL1",
            "s.odl",
            9,
            Timing::Period(1.0),
            &mut none,
            "v.mcap",
        )
        .unwrap_err();
        assert!(err.to_string().starts_with("s.odl: offset"), "{err}");
        assert!(none.is_empty());
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]

        #[test]
        fn arbitrary_arrivals_and_messages_never_panic(
            text in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..200),
            depth in 1u32..=16,
            kind in 0u8..3,
        ) {
            let _ = read_arrivals(&text);
            let spec = ViewSpec {
                resolution_m: 0.1,
                coarse_depth: depth,
                roi: Some(Roi { min_m: [-0.3, -1.0, -0.5], max_m: [0.3, 2.0, 2.0] }),
            };
            let mut stream = delta::encode_header(&spec);
            stream.extend(delta::frame_message(kind, 7, &text));
            if let Ok((_, msgs)) = delta::decode_stream(&stream) {
                let mut b = SceneBuilder::new(spec);
                let mut scene = HashMap::new();
                for (k, m) in msgs.iter().chain(&msgs).enumerate() {
                    replay(&mut scene, &b.apply(&m.message, k as u64));
                }
                proptest::prop_assert_eq!(b.entities(), scene.len());
            }
        }
    }
}
