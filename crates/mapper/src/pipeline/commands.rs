//! The commands besides `build`, each a call on bytes: [`apply`] a stream (the operator's
//! view), [`dump`] its messages, send a whole map as a one-message stream ([`full`]), and make
//! a synthetic survey ([`synth`]).

use std::io::Write;

use super::{Coarse, ConfigError, PipelineError, RESOLUTION_MAX_M, RESOLUTION_MIN_M};
use super::{check_range, view_spec};
use rovlink_base::io::IoError;
use rovlink_octo::delta::{self, Message, Receiver, Roi, ViewSpec};
use rovlink_octo::tree::{OcTree, TREE_DEPTH, unmorton};
use rovlink_octo::{files, graph, synth};
use rovlink_scans::cloud;

/// A stream's header and messages, or where `bytes` (named `name`) stop being one.
pub fn read_stream(
    bytes: &[u8],
    name: &str,
) -> Result<(delta::StreamHeader, Vec<delta::Framed>), PipelineError> {
    delta::decode_stream(bytes).map_err(|source| PipelineError::Input {
        name: name.to_string(),
        source,
    })
}

/// The operator's view after the first `messages` messages of a stream (all: `usize::MAX`).
pub fn apply(bytes: &[u8], name: &str, messages: usize) -> Result<OcTree, PipelineError> {
    let (h, msgs) = read_stream(bytes, name)?;
    let mut rx = Receiver::new(h.spec);
    for m in msgs.iter().take(messages) {
        rx.apply(&m.message);
    }
    Ok(rx.view().clone())
}

/// A whole map (`.ot` or `.bt` bytes, named `name`) as a one-message stream with this view.
pub fn full(
    bytes: &[u8],
    name: &str,
    coarse: Coarse,
    roi: Option<Roi>,
) -> Result<Vec<u8>, PipelineError> {
    let tree = files::read_map(bytes).map_err(|source| PipelineError::Input {
        name: name.to_string(),
        source,
    })?;
    let res = tree.resolution_m();
    check_range("resolution", res, RESOLUTION_MIN_M, RESOLUTION_MAX_M, "m").map_err(|source| {
        PipelineError::OutOfRange {
            name: name.to_string(),
            source,
        }
    })?;
    let spec = view_spec(res, coarse, roi)?;
    let view = delta::view_of(&tree, &spec);
    let mut out = delta::encode_header(&spec);
    out.extend_from_slice(&delta::encode_full(0, &view));
    Ok(out)
}

/// How [`dump`] lists a stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DumpFormat {
    /// A line for the stream, one per message (and per voxel with `voxels`).
    Text,
    /// One JSON object per message.
    Ndjson,
    /// One CSV row per message.
    Csv,
}

impl std::str::FromStr for DumpFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "text" => Ok(DumpFormat::Text),
            "ndjson" => Ok(DumpFormat::Ndjson),
            "csv" => Ok(DumpFormat::Csv),
            _ => Err(format!("unknown format {s:?} (text, ndjson or csv)")),
        }
    }
}

/// Lists a stream's messages to `out` (the voxels too with `voxels`, text and ndjson), each
/// line written whole.
pub fn dump(
    bytes: &[u8],
    name: &str,
    format: DumpFormat,
    voxels: bool,
    out: &mut dyn Write,
) -> Result<(), PipelineError> {
    let (h, msgs) = read_stream(bytes, name)?;
    let spec = h.spec;
    let mut lines = Vec::new();
    match format {
        DumpFormat::Text => {
            let roi = spec.roi.map_or("everywhere".to_string(), |r| {
                format!("{:?}..{:?}", r.min_m, r.max_m)
            });
            lines.push(format!(
                "stream: resolution {} m, coarse depth {} ({} m voxels), ROI {roi}",
                spec.resolution_m,
                spec.coarse_depth,
                spec.resolution_m * (1u64 << (TREE_DEPTH - spec.coarse_depth)) as f64
            ));
        }
        DumpFormat::Csv => lines.push(
            "offset,bytes,kind,scan,fine_occupied,fine_free,coarse_occupied,coarse_free,leaves"
                .into(),
        ),
        DumpFormat::Ndjson => {}
    }
    let emit = |out: &mut dyn Write, lines: &mut Vec<String>| -> Result<(), PipelineError> {
        let mut text = String::new();
        for l in lines.drain(..) {
            text.push_str(&l);
            text.push('\n');
        }
        out.write_all(text.as_bytes())
            .map_err(|source| IoError::Write {
                name: "<stdout>".into(),
                source,
            })
            .map_err(PipelineError::from)
    };
    for f in &msgs {
        dump_message(&spec, f, format, voxels, &mut lines);
        emit(out, &mut lines)?;
    }
    emit(out, &mut lines)
}

fn dump_message(
    spec: &ViewSpec,
    f: &delta::Framed,
    format: DumpFormat,
    voxels: bool,
    lines: &mut Vec<String>,
) {
    let (offset, bytes) = (f.offset, f.bytes);
    match (&f.message, format) {
        (Message::Delta { scan, delta: d }, DumpFormat::Text) => {
            lines.push(format!(
                "offset {offset} ({bytes} bytes): delta of scan {scan}: fine +{} occupied, +{} free; coarse +{} occupied, +{} free",
                d.fine_occupied.len(),
                d.fine_free.len(),
                d.coarse_occupied.len(),
                d.coarse_free.len()
            ));
            if voxels {
                for (c, col) in &d.fine_occupied {
                    lines.push(format!(
                        "  fine occupied key {:?} colour {col:?}",
                        unmorton(*c)
                    ));
                }
                for c in &d.fine_free {
                    lines.push(format!("  fine free key {:?}", unmorton(*c)));
                }
                let depth = spec.coarse_depth;
                for c in &d.coarse_occupied {
                    let k = spec.coarse_key(*c);
                    lines.push(format!("  coarse occupied key {k:?} (depth {depth})"));
                }
                for c in &d.coarse_free {
                    let k = spec.coarse_key(*c);
                    lines.push(format!("  coarse free key {k:?} (depth {depth})"));
                }
            }
        }
        (Message::Full { scan, leaves }, DumpFormat::Text) => lines.push(format!(
            "offset {offset} ({bytes} bytes): full view after scan {scan}: {} leaves ({} occupied)",
            leaves.len(),
            leaves.iter().filter(|l| l.2).count()
        )),
        (Message::Region { scan, coarse, leaves }, DumpFormat::Text) => lines.push(format!(
            "offset {offset} ({bytes} bytes): region after scan {scan}: {} coarse voxels, {} leaves ({} occupied)",
            coarse.len(),
            leaves.len(),
            leaves.iter().filter(|l| l.2).count()
        )),
        (Message::Delta { scan, delta: d }, DumpFormat::Csv) => lines.push(format!(
            "{offset},{bytes},delta,{scan},{},{},{},{},",
            d.fine_occupied.len(),
            d.fine_free.len(),
            d.coarse_occupied.len(),
            d.coarse_free.len()
        )),
        (Message::Full { scan, leaves }, DumpFormat::Csv) => {
            lines.push(format!("{offset},{bytes},full,{scan},,,,,{}", leaves.len()))
        }
        (Message::Region { scan, leaves, .. }, DumpFormat::Csv) => {
            lines.push(format!("{offset},{bytes},region,{scan},,,,,{}", leaves.len()))
        }
        (Message::Delta { scan, delta: d }, DumpFormat::Ndjson) => {
            let mut v = serde_json::json!({
                "offset": offset, "bytes": bytes, "kind": "delta", "scan": scan,
                "fine_occupied": d.fine_occupied.len(), "fine_free": d.fine_free.len(),
                "coarse_occupied": d.coarse_occupied.len(), "coarse_free": d.coarse_free.len(),
            });
            if voxels {
                v["voxels"] = serde_json::json!({
                    "fine_occupied": d.fine_occupied.iter()
                        .map(|(c, col)| serde_json::json!({"key": unmorton(*c), "rgb": col}))
                        .collect::<Vec<_>>(),
                    "fine_free": d.fine_free.iter().map(|c| unmorton(*c)).collect::<Vec<_>>(),
                    "coarse_occupied": d.coarse_occupied.iter()
                        .map(|c| spec.coarse_key(*c)).collect::<Vec<_>>(),
                    "coarse_free": d.coarse_free.iter()
                        .map(|c| spec.coarse_key(*c)).collect::<Vec<_>>(),
                });
            }
            lines.push(v.to_string());
        }
        (Message::Full { scan, leaves }, DumpFormat::Ndjson) => lines.push(
            serde_json::json!({"offset": offset, "bytes": bytes, "kind": "full", "scan": scan,
                "leaves": leaves.len(), "occupied": leaves.iter().filter(|l| l.2).count()})
            .to_string(),
        ),
        (Message::Region { scan, coarse, leaves }, DumpFormat::Ndjson) => lines.push(
            serde_json::json!({"offset": offset, "bytes": bytes, "kind": "region", "scan": scan,
                "coarse": coarse.len(), "leaves": leaves.len(),
                "occupied": leaves.iter().filter(|l| l.2).count()})
            .to_string(),
        ),
    }
}

/// A synthetic survey's file: `.graph` bytes, or with `mcap` an MCAP of coloured scans.
pub fn synth(params: &synth::SurveyParams, mcap: bool) -> Result<Vec<u8>, ConfigError> {
    params.validate()?;
    let scans = synth::survey(params);
    Ok(if mcap {
        cloud::write_clouds_mcap(&scans)
    } else {
        graph::write(&scans)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_map_of_an_unusable_resolution_is_named() {
        let map = b"# Octomap OcTree file\nid OcTree\nsize 0\nres 1e-10\ndata\n";
        let err = full(map, "m.ot", Coarse::default(), None).unwrap_err();
        assert_eq!(
            err.to_string(),
            "m.ot: resolution: expected 0.0001 m ..= 1000 m, found 1e-10"
        );
    }
}
