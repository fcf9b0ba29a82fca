//! The vehicle's side of the live map: the map, the delta sender, and a mirror of the
//! operator's view (every message sent is applied to it), from which the mapper answers what
//! the operator asks:
//!
//! - a scan becomes the delta message `build` writes for it, byte for byte;
//! - a resync, or a backlog too long to keep, is the mirror as one full message after a sync
//!   record: the view it gives is exactly the one the deltas would have built;
//! - a full map is the map's view now (colours as they are now), whole or inside a box (a
//!   region message, or the whole map when the box names too many coarse voxels);
//! - a moved ROI is a spec record and a region message of the coarse voxels that change sides
//!   (the newly fine ones sent fine once, with colour); a new coarse depth, or a ROI from or to
//!   "everywhere", is a new stream: a sync record and the full view under the new spec.

use rovlink_maplink::outbox::{RECORD_MESSAGE, RECORD_POSE, RECORD_SPEC, RECORD_SYNC};
use rovlink_maplink::request::BoxM;
use rovlink_octo::delta::{self, Message, Receiver, Roi, Sender, ViewSpec};
use rovlink_octo::region::{self, Selection};
use rovlink_octo::tree::{OcTree, ScanUpdate};
use rovlink_octo::{Pose, Scan};

use crate::pipeline::{BuildConfig, PipelineError, check_roi};

/// Bytes of a pose record: kind, scan, arrival time (f64 s since the Unix epoch), x, y, z and
/// the quaternion w, x, y, z (f32).
pub const POSE_RECORD_BYTES: usize = 1 + 4 + 8 + 7 * 4;

/// The map and what the operator has of it.
pub struct MapState {
    cfg: BuildConfig,
    spec: ViewSpec,
    tree: Option<OcTree>,
    sender: Sender,
    mirror: Receiver,
    /// Scans inserted.
    pub scans: u32,
}

/// What inserting one scan made.
pub struct Inserted {
    /// The scan's delta message (as `build` writes it).
    pub message: Vec<u8>,
    /// The map's update.
    pub update: ScanUpdate,
}

/// A record: kind byte, then body.
fn record(kind: u8, body: &[u8]) -> Vec<u8> {
    let mut r = Vec::with_capacity(body.len() + 1);
    r.push(kind);
    r.extend_from_slice(body);
    r
}

/// The pose record of scan `scan`, which arrived at `t_unix_s`.
pub fn pose_record(scan: u32, t_unix_s: f64, pose: &Pose) -> Vec<u8> {
    let mut r = Vec::with_capacity(POSE_RECORD_BYTES);
    r.push(RECORD_POSE);
    r.extend_from_slice(&scan.to_le_bytes());
    r.extend_from_slice(&t_unix_s.to_le_bytes());
    for v in pose.translation_m.iter().chain(&pose.rotation) {
        r.extend_from_slice(&v.to_le_bytes());
    }
    r
}

/// What the mapper does for a request: the records to queue, or a restart of the stream.
#[derive(Debug, PartialEq)]
pub enum Answer {
    /// Queue these records after what is waiting.
    Queue(Vec<Vec<u8>>),
    /// Drop everything in flight and start the stream again with these records.
    Restart(Vec<Vec<u8>>),
    /// Refused: why.
    Refused(String),
}

fn to_roi(b: &BoxM) -> Roi {
    Roi {
        min_m: b.min_m,
        max_m: b.max_m,
    }
}

impl MapState {
    /// An empty map for `cfg` (checked).
    pub fn new(cfg: &BuildConfig) -> Result<MapState, rovlink_octo::checks::ConfigError> {
        let spec = cfg.validate()?;
        let mut sender = Sender::new(spec);
        sender.set_color_updates(cfg.color_updates);
        Ok(MapState {
            cfg: cfg.clone(),
            spec,
            tree: None,
            sender,
            mirror: Receiver::new(spec),
            scans: 0,
        })
    }

    /// The view the operator gets.
    pub fn spec(&self) -> &ViewSpec {
        &self.spec
    }

    /// The map so far.
    pub fn tree(&self) -> OcTree {
        self.tree
            .clone()
            .unwrap_or_else(|| OcTree::new(self.cfg.resolution_m))
    }

    /// The map so far, without a copy (none before the first scan).
    pub fn tree_ref(&self) -> Option<&OcTree> {
        self.tree.as_ref()
    }

    /// The operator's view as the mapper knows it.
    pub fn mirror(&self) -> &OcTree {
        self.mirror.view()
    }

    /// The first records of a stream: its sync record.
    pub fn start_records(&self) -> Vec<Vec<u8>> {
        vec![record(RECORD_SYNC, &delta::encode_header(&self.spec))]
    }

    /// Inserts a scan as `build` does and makes its delta message (applied to the mirror);
    /// `None` when `stop` ended its casting; an error, the map unchanged, when its rays may
    /// cross more cells than [`BuildConfig::max_cells_per_scan`].
    pub fn insert(
        &mut self,
        scan: &Scan,
        stop: &std::sync::atomic::AtomicBool,
    ) -> Result<Option<Inserted>, PipelineError> {
        let tree = self.tree.get_or_insert_with(|| self.cfg.new_tree(scan));
        let prepared = tree.caster_mut().prepare(scan, self.cfg.max_range_m, stop);
        let Some(prepared) = self.cfg.cells_checked(self.scans, prepared)? else {
            return Ok(None);
        };
        let update = tree.apply_scan(&prepared);
        let d = self.sender.delta(tree, &update.changes);
        let message = delta::encode_delta(&self.spec, self.scans, &d);
        self.mirror.apply(&Message::Delta {
            scan: self.scans,
            delta: d,
        });
        self.scans += 1;
        Ok(Some(Inserted { message, update }))
    }

    /// The scan number messages made now carry: the last scan inserted.
    fn last_scan(&self) -> u32 {
        self.scans.saturating_sub(1)
    }

    /// The mirror as a new stream: a sync record and one full message (a resync, or the
    /// backlog replaced).
    pub fn resync_records(&self) -> Vec<Vec<u8>> {
        let full = delta::encode_full(self.last_scan(), self.mirror.view());
        vec![
            record(RECORD_SYNC, &delta::encode_header(&self.spec)),
            record(RECORD_MESSAGE, &full),
        ]
    }

    /// Bytes of [`MapState::resync_records`], without making them twice.
    pub fn resync_bytes(records: &[Vec<u8>]) -> usize {
        records.iter().map(Vec::len).sum()
    }

    /// Applies a message the mapper sends to the mirror (the bytes it made itself).
    fn mirror_apply(&mut self, bytes: &[u8]) {
        if let Ok((m, _)) = delta::decode_message(&self.spec, bytes, 0) {
            self.mirror.apply(&m);
        }
    }

    /// The map's view now, whole.
    fn current_view(&self, spec: &ViewSpec) -> OcTree {
        match &self.tree {
            Some(t) => delta::view_of(t, spec),
            None => OcTree::new(spec.resolution_m),
        }
    }

    /// The full map now, as one full message (queued after what waits).
    pub fn full(&mut self) -> Answer {
        let view = self.current_view(&self.spec);
        let msg = delta::encode_full(self.last_scan(), &view);
        self.mirror_apply(&msg);
        Answer::Queue(vec![record(RECORD_MESSAGE, &msg)])
    }

    /// The map inside a box now: a region message (the whole map when the box names more
    /// than [`region::MAX_REGION_COARSE`] coarse voxels).
    pub fn full_box(&mut self, b: &BoxM) -> Answer {
        let view = self.current_view(&self.spec);
        let sel = Selection::Box(to_roi(b));
        let Some(coarse) = region::select(&view, &self.spec, &sel) else {
            return self.full();
        };
        let msg = delta::encode_region(&self.spec, self.last_scan(), &view, &coarse);
        self.mirror_apply(&msg);
        Answer::Queue(vec![record(RECORD_MESSAGE, &msg)])
    }

    /// Moves the ROI (`None`: everything fine).
    pub fn set_roi(&mut self, roi: Option<BoxM>) -> Answer {
        let roi = roi.as_ref().map(to_roi);
        if let Some(r) = &roi
            && let Err(e) = check_roi(r)
        {
            return Answer::Refused(format!("roi: expected {}, found {}", e.expected, e.found));
        }
        let new = ViewSpec { roi, ..self.spec };
        let view = self.current_view(&new);
        let sel = Selection::RoiChange {
            old: self.spec.roi,
            new: roi,
        };
        let Some(coarse) = region::select(&view, &new, &sel) else {
            return self.new_stream(new, view);
        };
        let msg = delta::encode_region(&new, self.last_scan(), &view, &coarse);
        self.spec = new;
        self.sender.set_roi(roi);
        self.mirror.set_roi(roi);
        let shift = new.coarse_shift();
        for &c in &coarse {
            let occ = (!new.coarse_in_roi(c)).then(|| {
                view.search(c << shift, new.coarse_depth)
                    .is_some_and(|(n, _)| view.node(n).log_odds >= 0.0)
            });
            self.sender.note_coarse(c, occ);
        }
        self.mirror_apply(&msg);
        Answer::Queue(vec![
            record(RECORD_SPEC, &delta::encode_header(&new)),
            record(RECORD_MESSAGE, &msg),
        ])
    }

    /// Changes the coarse depth (1..=16).
    pub fn set_coarse_depth(&mut self, depth: u8) -> Answer {
        let new = ViewSpec {
            coarse_depth: depth as u32,
            ..self.spec
        };
        let view = self.current_view(&new);
        self.new_stream(new, view)
    }

    /// A new stream under `spec`: a sync record and the map's `view` under it; the sender
    /// starts again knowing the coarse voxels the view has.
    fn new_stream(&mut self, spec: ViewSpec, view: OcTree) -> Answer {
        let msg = delta::encode_full(self.last_scan(), &view);
        self.spec = spec;
        self.sender = Sender::new(spec);
        self.sender.set_color_updates(self.cfg.color_updates);
        let shift = spec.coarse_shift();
        view.for_each_leaf(|code, depth, v| {
            if depth == spec.coarse_depth && !spec.coarse_in_roi(code >> shift) {
                self.sender
                    .note_coarse(code >> shift, Some(v.log_odds >= 0.0));
            }
        });
        self.mirror = Receiver::new(spec);
        self.mirror_apply(&msg);
        Answer::Queue(vec![
            record(RECORD_SYNC, &delta::encode_header(&spec)),
            record(RECORD_MESSAGE, &msg),
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rovlink_octo::files;
    use rovlink_octo::synth::{SurveyParams, survey};
    use std::sync::atomic::AtomicBool;

    /// The records' messages applied in order, as the view applies them.
    fn view_of_records(records: &[Vec<u8>], mut rx: Option<Receiver>) -> Receiver {
        for r in records {
            match r[0] {
                RECORD_SYNC => {
                    let (h, _) = delta::decode_header(&r[1..]).unwrap();
                    rx = Some(Receiver::new(h.spec));
                }
                RECORD_SPEC => {
                    let (h, _) = delta::decode_header(&r[1..]).unwrap();
                    rx.as_mut().unwrap().set_roi(h.spec.roi);
                }
                RECORD_MESSAGE => {
                    let rx = rx.as_mut().unwrap();
                    let (m, _) = delta::decode_message(rx.spec(), &r[1..], 0).unwrap();
                    rx.apply(&m);
                }
                _ => {}
            }
        }
        rx.unwrap()
    }

    /// The live mapper refuses a scan over the cell budget as `build` does, before casting it:
    /// an error naming the scan, the map and the scan count as they were.
    #[test]
    fn a_scan_over_the_cell_budget_is_an_error_and_leaves_the_map_as_it_was() {
        let scans = survey(&SurveyParams {
            scans: 1,
            ..SurveyParams::default()
        });
        let stop = AtomicBool::new(false);
        let cfg = BuildConfig {
            max_cells_per_scan: 1000,
            ..BuildConfig::default()
        };
        let mut m = MapState::new(&cfg).unwrap();
        match m.insert(&scans[0], &stop) {
            Err(PipelineError::TooManyCells {
                scan: 0, source, ..
            }) => {
                assert_eq!(source.max, 1000);
                assert!(source.cells > 1000, "{source:?}");
            }
            other => panic!("{:?}", other.map(|o| o.is_some())),
        }
        assert_eq!(m.scans, 0);
        assert_eq!(m.tree().num_nodes(), 0);
        let mut fine = MapState::new(&BuildConfig::default()).unwrap();
        assert!(fine.insert(&scans[0], &stop).unwrap().is_some());
    }

    #[test]
    fn every_answer_keeps_the_view_and_the_mirror_equal() {
        let params = SurveyParams {
            scans: 12,
            ..SurveyParams::default()
        };
        let scans = survey(&params);
        let cfg = BuildConfig {
            resolution_m: 0.2,
            ..BuildConfig::default()
        };
        let stop = AtomicBool::new(false);
        let mut m = MapState::new(&cfg).unwrap();
        let mut records = m.start_records();
        let answers: [&dyn Fn(&mut MapState) -> Answer; 5] = [
            &|m| m.set_roi(Some(BoxM::new([-5.0, -5.0, -30.0, 5.0, 5.0, 0.0]).unwrap())),
            &|m| m.full_box(&BoxM::new([-3.0, -3.0, -30.0, 3.0, 3.0, 0.0]).unwrap()),
            &|m| m.set_roi(Some(BoxM::new([0.0, -8.0, -30.0, 9.0, 2.0, 0.0]).unwrap())),
            &|m| m.set_coarse_depth(12),
            &|m| m.full(),
        ];
        for (k, scan) in scans.iter().enumerate() {
            let done = m.insert(scan, &stop).unwrap().unwrap();
            records.push(record(RECORD_MESSAGE, &done.message));
            if k % 2 == 1 {
                match answers[k / 2 % answers.len()](&mut m) {
                    Answer::Queue(r) => records.extend(r),
                    other => panic!("{other:?}"),
                }
            }
            let rx = view_of_records(&records, None);
            assert_eq!(
                files::write_ot(rx.view()),
                files::write_ot(m.mirror()),
                "scan {k}"
            );
        }
        // A resync alone gives the same view.
        let rx = view_of_records(&m.resync_records(), None);
        assert_eq!(files::write_ot(rx.view()), files::write_ot(m.mirror()));
        // And after a full map request, the view is the map's view.
        let Answer::Queue(r) = m.full() else { panic!() };
        records.extend(r);
        let rx = view_of_records(&records, None);
        let want = delta::view_of(&m.tree(), m.spec());
        assert_eq!(files::write_ot(rx.view()), files::write_ot(&want));
    }

    #[test]
    fn a_roi_out_of_range_is_refused_and_changes_nothing() {
        let mut m = MapState::new(&BuildConfig::default()).unwrap();
        let before = *m.spec();
        let a = m.set_roi(Some(
            BoxM::new([-1e300, 0.0, 0.0, 1e300, 1.0, 1.0]).unwrap(),
        ));
        assert!(
            matches!(a, Answer::Refused(ref why) if why.contains("corners within")),
            "{a:?}"
        );
        assert_eq!(*m.spec(), before);
    }
}
