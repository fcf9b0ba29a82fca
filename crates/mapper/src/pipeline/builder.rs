//! The build loop ([`build`]): the scans of every input into one [`OcTree`], one delta message
//! per scan written as soon as it is made, a [`StatsRow`] per scan to a sink, a stop flag looked
//! at between scans and inside them; what it did ([`BuildReport`], [`Built`]: figures and the
//! summary line), and when each message reached the operator over a link ([`arrival_rows`]).

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::Instant;

use serde::Serialize;

use super::inputs::{ScanSource, open_scans, with_origin};
use super::{BuildConfig, PipelineError};
use rovlink_base::io::IoError;
use rovlink_octo::Scan;
use rovlink_octo::cast::{PreparedScan, ScanCaster};
use rovlink_octo::delta::{self, Sender, ViewSpec};
use rovlink_octo::tree::OcTree;
use rovlink_octo::{files, transfer};
use rovlink_scans::recording::{Item, Recording, RecordingError};

/// One row of `--stats`: a scan's message and what sending the whole map would have cost.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatsRow {
    /// Scan number, from 0.
    pub scan: u32,
    /// Points in the scan.
    pub points: usize,
    /// The scan's message, bytes.
    pub delta_bytes: usize,
    /// Newly occupied voxels at full resolution.
    pub fine_occupied: usize,
    /// Newly free voxels at full resolution.
    pub fine_free: usize,
    /// Newly occupied coarse voxels.
    pub coarse_occupied: usize,
    /// Newly free coarse voxels.
    pub coarse_free: usize,
    /// The whole map as `.bt`, bytes.
    pub full_bt_bytes: u64,
    /// The whole map as `.ot`, bytes.
    pub full_ot_bytes: u64,
    /// Messages so far, bytes.
    pub cum_delta_bytes: u64,
    /// A `.bt` after every scan so far, bytes.
    pub cum_full_bt_bytes: u64,
    /// A `.ot` after every scan so far, bytes.
    pub cum_full_ot_bytes: u64,
    /// Points skipped (non-finite, or outside the map's key range).
    pub points_skipped: usize,
    /// Time inserting the scan and making its message, ms (to the microsecond).
    pub insert_ms: f64,
}

/// The `--stats` columns, in order.
pub const STATS_COLUMNS: [&str; 14] = [
    "scan",
    "points",
    "delta_bytes",
    "fine_occupied",
    "fine_free",
    "coarse_occupied",
    "coarse_free",
    "full_bt_bytes",
    "full_ot_bytes",
    "cum_delta_bytes",
    "cum_full_bt_bytes",
    "cum_full_ot_bytes",
    "points_skipped",
    "insert_ms",
];

/// An error a row sink returns.
pub type SinkError = Box<dyn std::error::Error + Send + Sync>;

/// Where [`build`] sends its [`StatsRow`]s.
pub type StatsSink<'a> = &'a mut dyn FnMut(&StatsRow) -> Result<(), SinkError>;

/// What [`build`] reports to and asks of its caller while it runs.
pub struct Hooks<'a> {
    /// Set (by a signal handler, say) to stop at the next scan.
    pub stop: &'a AtomicBool,
    /// Gets each scan's [`StatsRow`] (computing the full-map sizes costs a copy of the map
    /// per scan, so only when there is a sink).
    pub stats: Option<StatsSink<'a>>,
    /// Gets (scans done, scans known so far) after each scan and each input opened.
    pub progress: Option<&'a mut dyn FnMut(u64, u64)>,
}

/// What a build did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BuildReport {
    /// Scans inserted (each with its message in the stream).
    pub scans: u32,
    /// Points in them.
    pub points: usize,
    /// Points skipped: non-finite or outside the key range.
    pub points_skipped: usize,
    /// Points beyond the maximum range (their rays mark free space only).
    pub points_beyond_range: usize,
    /// Wall-clock time, s.
    pub elapsed_s: f64,
    /// Time inserting scans and making messages, s.
    pub insert_s: f64,
    /// The stream's bytes, header included.
    pub stream_bytes: u64,
    /// (scan number, message bytes) of every message, for a transfer.
    pub messages: Vec<(u32, usize)>,
    /// Whether the stop flag ended the build early.
    pub interrupted: bool,
    /// Clouds of robot logs skipped for want of a pose: (reason naming the frames, count).
    pub skipped: Vec<(String, u64)>,
    /// What a user should know about how robot logs were read (`FILE: poses from TF ...`).
    pub notes: Vec<String>,
}

/// A build's outcome: the map and the report.
#[derive(Debug)]
pub struct Built {
    /// The map after the last scan inserted.
    pub tree: OcTree,
    /// What was done.
    pub report: BuildReport,
}

impl Built {
    /// The build's figures as JSON (`octo-delta build --metrics`): scans, points, times, the
    /// map's nodes and .ot size, the stream's and the largest message's bytes.
    pub fn figures(&self) -> serde_json::Value {
        let r = &self.report;
        let message_bytes = r.messages.iter().map(|&(_, bytes)| bytes);
        serde_json::json!({
            "scans": r.scans,
            "points": r.points,
            "points_skipped": r.points_skipped,
            "points_beyond_range": r.points_beyond_range,
            "elapsed_s": r.elapsed_s,
            "insert_s": r.insert_s,
            "map_nodes": self.tree.num_nodes(),
            "ot_bytes": files::ot_size(&self.tree),
            "stream_bytes": r.stream_bytes,
            "message_bytes_max": message_bytes.clone().max().unwrap_or(0),
            "message_bytes_total": message_bytes.sum::<usize>(),
            "interrupted": r.interrupted,
        })
    }

    /// The one-line summary: scans, points, times, map and stream sizes; `interrupted` says by
    /// what when the build was stopped.
    pub fn summary(&self, interrupted: &str) -> String {
        let r = &self.report;
        let mut s = format!(
            "{} scans, {} points ({} outside the map's key range skipped, {} beyond max range) in {:.3} s ({:.3} s inserting); map {} nodes ({} bytes as .ot); stream {} bytes",
            r.scans,
            r.points,
            r.points_skipped,
            r.points_beyond_range,
            r.elapsed_s,
            r.insert_s,
            self.tree.num_nodes(),
            files::ot_size(&self.tree),
            r.stream_bytes
        );
        if r.interrupted {
            s.push_str(&format!("; {interrupted} after {} scans", r.scans));
        }
        s
    }

    /// What the build tells its user, in order: a warning per reason clouds were skipped (also
    /// when `quiet`: the map lacks them), the notes on how robot logs were read (unless
    /// `quiet`), and the [summary](Built::summary) (unless `quiet`, or when interrupted:
    /// `interrupted` says by what, else it says `interrupted`).
    pub fn messages(&self, quiet: bool, interrupted: Option<&str>) -> Vec<String> {
        let r = &self.report;
        let skipped = r.skipped.iter();
        let mut lines: Vec<String> = skipped
            .map(|(reason, n)| format!("warning: {n} cloud(s) skipped: {reason}"))
            .collect();
        if !quiet {
            lines.extend(r.notes.iter().cloned());
        }
        if !quiet || r.interrupted {
            lines.push(self.summary(interrupted.unwrap_or("interrupted")));
        }
        lines
    }
}

/// Where each scan's message goes once the scan is in the map: the delta stream, the stats sink
/// and the progress hook.
struct Emitter<'w> {
    spec: ViewSpec,
    sender: Sender,
    stream: &'w mut dyn Write,
    stream_name: &'w str,
    header_bytes: u64,
    cum_bt_bytes: u64,
    cum_ot_bytes: u64,
}

impl Emitter<'_> {
    fn write(&mut self, bytes: &[u8]) -> Result<(), PipelineError> {
        self.stream
            .write_all(bytes)
            .and_then(|()| self.stream.flush())
            .map_err(|source| {
                IoError::Write {
                    name: self.stream_name.to_string(),
                    source,
                }
                .into()
            })
    }

    /// Applies a cast scan to `tree` (`None`: the stop flag ended its casting, and the build),
    /// writes its message and reports it; `started` is when the caller began waiting for it.
    fn emit(
        &mut self,
        tree: &mut OcTree,
        prepared: Option<PreparedScan>,
        started: Instant,
        report: &mut BuildReport,
        hooks: &mut Hooks<'_>,
        known: u64,
    ) -> Result<bool, PipelineError> {
        let Some(prepared) = prepared else {
            report.interrupted = true;
            return Ok(false);
        };
        let up = tree.apply_scan(&prepared);
        let d = self.sender.delta(tree, &up.changes);
        let msg = delta::encode_delta(&self.spec, report.scans, &d);
        let dt = started.elapsed().as_secs_f64();
        report.insert_s += dt;
        self.write(&msg)?;
        report.points += up.points;
        report.points_skipped += up.points_skipped;
        report.points_beyond_range += up.points_beyond_range;
        report.stream_bytes += msg.len() as u64;
        report.messages.push((report.scans, msg.len()));
        if let Some(sink) = hooks.stats.as_mut() {
            let full_bt_bytes = files::write_bt(tree).len() as u64;
            let full_ot_bytes = files::ot_size(tree) as u64;
            self.cum_bt_bytes += full_bt_bytes;
            self.cum_ot_bytes += full_ot_bytes;
            sink(&StatsRow {
                scan: report.scans,
                points: up.points,
                delta_bytes: msg.len(),
                fine_occupied: d.fine_occupied.len(),
                fine_free: d.fine_free.len(),
                coarse_occupied: d.coarse_occupied.len(),
                coarse_free: d.coarse_free.len(),
                full_bt_bytes,
                full_ot_bytes,
                cum_delta_bytes: report.stream_bytes - self.header_bytes,
                cum_full_bt_bytes: self.cum_bt_bytes,
                cum_full_ot_bytes: self.cum_ot_bytes,
                points_skipped: up.points_skipped,
                insert_ms: (dt * 1e6).round() / 1e3,
            })
            .map_err(PipelineError::Sink)?;
        }
        report.scans += 1;
        if let Some(p) = hooks.progress.as_mut() {
            p(report.scans as u64, known);
        }
        Ok(true)
    }
}

/// Scans queued or being cast per casting thread, at most (see [`CastThreads::window`]).
const SCANS_AHEAD_PER_THREAD: usize = 4;

/// The threads that cast the next scans while the caller applies the last one: scans in, each
/// taken by the first thread free, cast scans out in the order they went in.
struct CastThreads {
    /// The scans to cast, numbered.
    scans: mpsc::Sender<(usize, Scan)>,
    /// The scans cast, numbered, in the order they were done.
    cast: mpsc::Receiver<(usize, Option<PreparedScan>)>,
    /// Scans cast before an earlier one, by number.
    early: BTreeMap<usize, Option<PreparedScan>>,
    /// Scans in flight (sent, not yet applied) beyond which the oldest is applied before the
    /// next is sent: a few per thread, so that a thread done with a quick scan finds another
    /// queued while the main thread waits for a slow one.
    window: usize,
    /// Scans sent so far.
    sent: usize,
    /// Cast scans received so far.
    received: usize,
}

impl CastThreads {
    /// `n` casting threads in `scope`, each with a copy of `caster` (casting a scan on one
    /// thread), stopping inside a scan when `stop` is set.
    fn spawn<'scope>(
        n: usize,
        caster: &ScanCaster,
        max_range_m: Option<f64>,
        stop: &'scope AtomicBool,
        scope: &'scope std::thread::Scope<'scope, '_>,
    ) -> Self {
        let (scans, scans_in) = mpsc::channel::<(usize, Scan)>();
        let (cast_out, cast) = mpsc::channel();
        let scans_in = Arc::new(Mutex::new(scans_in));
        for _ in 0..n.max(1) {
            let mut c = caster.clone();
            c.set_threads(1);
            let (scans_in, cast_out) = (Arc::clone(&scans_in), cast_out.clone());
            scope.spawn(move || {
                loop {
                    // Another thread panicking while it waited leaves the lock poisoned: the
                    // queue is still whole.
                    let next = match scans_in.lock() {
                        Ok(q) => q.recv(),
                        Err(poisoned) => poisoned.into_inner().recv(),
                    };
                    let Ok((i, scan)) = next else { break };
                    if cast_out
                        .send((i, c.prepare(&scan, max_range_m, stop)))
                        .is_err()
                    {
                        break;
                    }
                }
            });
        }
        CastThreads {
            scans,
            cast,
            early: BTreeMap::new(),
            window: n.max(1) * SCANS_AHEAD_PER_THREAD,
            sent: 0,
            received: 0,
        }
    }

    /// Scans sent and not yet received.
    fn in_flight(&self) -> usize {
        self.sent - self.received
    }

    /// Sends the next scan to be cast; false if the threads are gone (they panicked).
    fn send(&mut self, scan: Scan) -> bool {
        let ok = self.scans.send((self.sent, scan)).is_ok();
        self.sent += ok as usize;
        ok
    }

    /// The next scan cast, in the order sent (`None`: stopped inside it, or the threads are
    /// gone).
    fn recv(&mut self) -> Option<PreparedScan> {
        let want = self.received;
        self.received += 1;
        if let Some(p) = self.early.remove(&want) {
            return p;
        }
        loop {
            match self.cast.recv() {
                Ok((i, p)) if i == want => return p,
                Ok((i, p)) => {
                    self.early.insert(i, p);
                }
                Err(_) => return None,
            }
        }
    }
}

/// Builds the map from the scans of `inputs` (in order; `-` is standard input) and writes the
/// delta stream to `stream` (named `stream_name` in errors): the header, then one message per
/// scan as soon as it is made. The map keeps colours when the first scan has them, unless
/// [`BuildConfig::no_color`].
///
/// With more than one thread ([`BuildConfig::threads`]), the next scans are cast on that many
/// threads, a scan each, while the previous scan goes into the map: the map and the stream are
/// the same as with one thread, byte for byte.
///
/// When `hooks.stop` is set the build ends before the next scan (or inside a scan, before it
/// changes the map): the stream then holds whole messages for every scan in the map, and
/// [`BuildReport::interrupted`] says so. An input that does not parse fails the build, as does
/// a write error; the caller should then drop its outputs.
pub fn build(
    cfg: &BuildConfig,
    inputs: &[PathBuf],
    stream: &mut dyn Write,
    stream_name: &str,
    hooks: &mut Hooks<'_>,
) -> Result<Built, PipelineError> {
    let spec = cfg.validate()?;
    let started = Instant::now();
    let threads = cfg
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get().min(8)));
    // A live topic is cast on one thread: with more, the last scans cast would wait for the
    // next cloud to come before going into the map (issue 48 moves the reading off this
    // thread to lift this).
    let threads = match inputs
        .iter()
        .any(|p| super::ros2_input::topic_of(p).is_some())
    {
        true => 1,
        false => threads,
    };
    let mut sender = Sender::new(spec);
    sender.set_color_updates(cfg.color_updates);
    let header = delta::encode_header(&spec);
    let mut out = Emitter {
        spec,
        sender,
        stream,
        stream_name,
        header_bytes: header.len() as u64,
        cum_bt_bytes: 0,
        cum_ot_bytes: 0,
    };
    out.write(&header)?;
    let mut report = BuildReport {
        stream_bytes: header.len() as u64,
        ..BuildReport::default()
    };
    let mut tree: Option<OcTree> = None;
    std::thread::scope(|scope| {
        build_in(
            cfg,
            inputs,
            threads,
            &mut out,
            &mut tree,
            &mut report,
            hooks,
            scope,
        )
    })?;
    report.elapsed_s = started.elapsed().as_secs_f64();
    let tree = tree.unwrap_or_else(|| OcTree::new(cfg.resolution_m));
    Ok(Built { tree, report })
}

/// The scans cast and not yet in the map, in order, each applied; false if the build stopped
/// (the rest dropped).
fn drain(
    out: &mut Emitter<'_>,
    caster: &mut Option<CastThreads>,
    tree: &mut Option<OcTree>,
    report: &mut BuildReport,
    hooks: &mut Hooks<'_>,
    known: u64,
) -> Result<bool, PipelineError> {
    let (Some(c), Some(tree)) = (caster.as_mut(), tree.as_mut()) else {
        return Ok(true);
    };
    while c.in_flight() > 0 {
        if !apply_next(out, c, tree, report, hooks, known)? {
            return Ok(false);
        }
    }
    Ok(true)
}

/// The next scan cast into the map, its message written; false if the build stopped (the
/// stop flag was set, before or while it was cast).
fn apply_next(
    out: &mut Emitter<'_>,
    c: &mut CastThreads,
    tree: &mut OcTree,
    report: &mut BuildReport,
    hooks: &mut Hooks<'_>,
    known: u64,
) -> Result<bool, PipelineError> {
    if hooks.stop.load(Ordering::Relaxed) {
        report.interrupted = true;
        return Ok(false);
    }
    let t0 = Instant::now();
    let prepared = c.recv();
    out.emit(tree, prepared, t0, report, hooks, known)
}

/// [`build`]'s loop over the inputs and their scans; the casting threads, if any, in `scope`.
#[allow(clippy::too_many_arguments)]
fn build_in<'scope, 'h: 'scope>(
    cfg: &BuildConfig,
    inputs: &[PathBuf],
    threads: usize,
    out: &mut Emitter<'_>,
    tree_slot: &mut Option<OcTree>,
    report: &mut BuildReport,
    hooks: &mut Hooks<'h>,
    scope: &'scope std::thread::Scope<'scope, '_>,
) -> Result<(), PipelineError> {
    let origin = cfg.origin_m.map(|o| o.map(|c| c as f32));
    let max_range_m = cfg.max_range_m;
    let mut known = 0u64;
    let mut caster: Option<CastThreads> = None;
    'inputs: for path in inputs {
        if hooks.stop.load(Ordering::Relaxed) {
            report.interrupted = true;
            break;
        }
        // A read that gave up because the flag was set is a stop, not a bad input.
        let stop = hooks.stop;
        let name = path.display().to_string();
        let source = match open_scans(path, cfg, stop) {
            Err(_) if stop.load(Ordering::Relaxed) => {
                report.interrupted = true;
                break;
            }
            opened => opened?,
        };
        // A bag's clouds borrow it: it lives here, beside the loop over them.
        let mut recording: Option<Box<Recording>> = None;
        type Items<'s> = Box<dyn Iterator<Item = Result<Item, PipelineError>> + 's>;
        let (items, count, needs_origin): (Items<'_>, u64, bool) = match source {
            ScanSource::Scans(scans, n, format) => {
                let name = name.clone();
                let items = scans.map(move |r| {
                    r.map(Item::Scan).map_err(|source| PipelineError::Input {
                        name: name.clone(),
                        source,
                    })
                });
                (Box::new(items), n as u64, !format.has_poses())
            }
            ScanSource::Bag(rec) => {
                let rec = recording.insert(rec);
                let n = rec.cloud_count().unwrap_or(0);
                let needs_origin = !rec.has_poses();
                let items = rec.scans(stop)?.map(|r| r.map_err(PipelineError::from));
                (Box::new(items), n, needs_origin)
            }
            ScanSource::Live(scans) => (scans, 0, false),
        };
        known += count;
        if let Some(p) = hooks.progress.as_mut() {
            p(report.scans as u64, known);
        }
        let origin = origin.filter(|_| needs_origin);
        let (mut posed, mut skipped, mut first_reason) = (0u64, 0u64, None);
        for item in items {
            if stop.load(Ordering::Relaxed) {
                report.interrupted = true;
                break 'inputs;
            }
            let scan = match item {
                Err(_) if stop.load(Ordering::Relaxed) => {
                    report.interrupted = true;
                    break 'inputs;
                }
                Ok(Item::Skipped(reason)) => {
                    let reason = format!("{name}: {reason}");
                    skipped += 1;
                    match report.skipped.iter_mut().find(|(r, _)| *r == reason) {
                        Some((_, n)) => *n += 1,
                        None => report.skipped.push((reason.clone(), 1)),
                    }
                    first_reason.get_or_insert(reason);
                    continue;
                }
                Ok(Item::Scan(scan)) => scan,
                Err(e) => {
                    // The scans before the bad one go into the map and the stream first.
                    drain(out, &mut caster, tree_slot, report, hooks, known)?;
                    return Err(e);
                }
            };
            posed += 1;
            let scan = with_origin(scan, origin);
            let tree = tree_slot.get_or_insert_with(|| {
                // Its own caster casts only on one thread: more threads cast scans apart.
                let mut t = OcTree::new(cfg.resolution_m);
                if scan.colors.is_some() && !cfg.no_color {
                    t.enable_color();
                }
                t
            });
            if threads > 1 && caster.is_none() {
                caster = Some(CastThreads::spawn(
                    threads,
                    &tree.caster(),
                    max_range_m,
                    stop,
                    scope,
                ));
            }
            let Some(c) = caster.as_mut() else {
                let t0 = Instant::now();
                let prepared = tree.caster_mut().prepare(&scan, max_range_m, stop);
                if !out.emit(tree, prepared, t0, report, hooks, known)? {
                    break 'inputs;
                }
                continue;
            };
            if !c.send(scan) {
                // A casting thread is gone (it panicked): the scan is lost, the build stops.
                report.interrupted = true;
                break 'inputs;
            }
            // Scans being cast on every thread, and a few queued, while the oldest goes into
            // the map.
            if c.in_flight() > c.window && !apply_next(out, c, tree, report, hooks, known)? {
                break 'inputs;
            }
        }
        // An input's scans are all in the map before the next input is opened.
        if !drain(out, &mut caster, tree_slot, report, hooks, known)? {
            break 'inputs;
        }
        // A live input ends only when stopped.
        if stop.load(Ordering::Relaxed) {
            report.interrupted = true;
            break 'inputs;
        }
        if let Some(rec) = &recording {
            // A bag that says it has clouds but gives none (its metadata.yaml lists a topic its
            // .db3 lacks) is not an empty survey.
            if posed == 0
                && skipped == 0
                && let Some(n) = rec.cloud_count().filter(|&n| n > 0)
            {
                return Err(PipelineError::Recording(RecordingError::Unusable {
                    file: name,
                    message: format!(
                        "cloud topic {:?}: expected {n} messages (as the bag says), found none",
                        rec.cloud_topic()
                    ),
                }));
            }
            if posed == 0
                && let Some(reason) = first_reason
            {
                return Err(PipelineError::NoPosedCloud {
                    name,
                    skipped,
                    reason,
                });
            }
            report
                .notes
                .extend(rec.notes.iter().map(|n| format!("{name}: {n}")));
        }
    }
    Ok(())
}

/// One row of `--arrivals`: when a scan's message reached the operator over the link.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ArrivalRow {
    /// Scan number.
    pub scan: u32,
    /// Message bytes.
    pub bytes: usize,
    /// When it was ready to send, s.
    pub t_ready_s: f64,
    /// When its last segment arrived, s.
    pub t_complete_s: f64,
    /// When it could be shown (it and every earlier message complete), s.
    pub t_shown_s: f64,
    /// From ready to shown, s.
    pub latency_s: f64,
}

/// The `--arrivals` columns, in order.
pub const ARRIVAL_COLUMNS: [&str; 6] = [
    "scan",
    "bytes",
    "t_ready_s",
    "t_complete_s",
    "t_shown_s",
    "latency_s",
];

/// `v` rounded to the microsecond (what the arrival columns carry).
fn micro(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// The arrival rows of a transfer.
pub fn arrival_rows(report: &transfer::TransferReport) -> Vec<ArrivalRow> {
    report
        .arrivals
        .iter()
        .map(|a| ArrivalRow {
            scan: a.scan,
            bytes: a.bytes,
            t_ready_s: micro(a.t_ready_s),
            t_complete_s: micro(a.t_complete_s),
            t_shown_s: micro(a.t_applied_s),
            latency_s: micro(a.t_applied_s - a.t_ready_s),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn xyz_file(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn a_set_stop_flag_ends_the_build_before_the_next_scan() {
        let dir = tempfile::tempdir().unwrap();
        let a = xyz_file(dir.path(), "a.xyz", "1 0 0\n0 1 0\n");
        let b = xyz_file(dir.path(), "b.xyz", "0 0 1\n");
        let stop = AtomicBool::new(false);
        let mut rows = Vec::new();
        let mut sink = |r: &StatsRow| -> Result<(), SinkError> {
            rows.push(r.clone());
            // Stopped while the first scan is done: the second is not inserted.
            stop.store(true, Ordering::Relaxed);
            Ok(())
        };
        let mut out = Vec::new();
        let built = build(
            &BuildConfig::default(),
            &[a, b],
            &mut out,
            "mem",
            &mut Hooks {
                stop: &stop,
                stats: Some(&mut sink),
                progress: None,
            },
        )
        .unwrap();
        assert!(built.report.interrupted);
        assert_eq!(built.report.scans, 1);
        assert_eq!(rows.len(), 1);
        // The stream holds the header and one whole message.
        let (_, msgs) = delta::decode_stream(&out).unwrap();
        assert_eq!(msgs.len(), 1);
        assert!(
            built
                .summary("interrupted by SIGTERM")
                .ends_with("; interrupted by SIGTERM after 1 scans")
        );
    }

    #[test]
    fn the_issue_point_builds_at_once() {
        // Issue 14: "-1e-30 -1e-30 -1e-30" with --origin 0,0,0 hung forever.
        let dir = tempfile::tempdir().unwrap();
        let t = xyz_file(dir.path(), "t.xyz", "-1e-30 -1e-30 -1e-30\n");
        let cfg = BuildConfig {
            origin_m: Some([0.0; 3]),
            ..BuildConfig::default()
        };
        let (built, _) = build_uninterrupted(&cfg, &t);
        assert_eq!((built.report.scans, built.report.points), (1, 1));
        assert!(!built.report.interrupted);
    }

    /// A build of `input` with no stop, no sink, no progress: the map and the stream.
    fn build_uninterrupted(cfg: &BuildConfig, input: &Path) -> (Built, Vec<u8>) {
        let never = AtomicBool::new(false);
        let mut out = Vec::new();
        let mut hooks = Hooks {
            stop: &never,
            stats: None,
            progress: None,
        };
        let built = build(cfg, &[input.to_path_buf()], &mut out, "mem", &mut hooks).unwrap();
        (built, out)
    }

    /// The stream, .bt and .ot of a build of `input` on `threads` threads.
    fn built_bytes(input: &Path, threads: usize) -> (Vec<u8>, Vec<u8>, Vec<u8>) {
        let cfg = BuildConfig {
            resolution_m: 0.1,
            threads: Some(threads),
            ..BuildConfig::default()
        };
        let (built, out) = build_uninterrupted(&cfg, input);
        assert_eq!(built.report.scans, 6);
        (
            out,
            files::write_bt(&built.tree),
            files::write_ot(&built.tree),
        )
    }

    #[test]
    fn two_threads_build_the_same_bytes_as_one() {
        let dir = tempfile::tempdir().unwrap();
        let params = rovlink_octo::synth::SurveyParams {
            scans: 6,
            ..Default::default()
        };
        for (name, mcap) in [("s.graph", false), ("s.mcap", true)] {
            let path = dir.path().join(name);
            let bytes = crate::pipeline::commands::synth(&params, mcap).unwrap();
            std::fs::write(&path, bytes).unwrap();
            let one = built_bytes(&path, 1);
            // The coloured map is a ColorOcTree, the plain one an OcTree.
            assert_eq!(
                String::from_utf8_lossy(&one.2[..200]).contains("id ColorOcTree"),
                mcap
            );
            for threads in [2, 3] {
                let more = built_bytes(&path, threads);
                assert!(
                    one.0 == more.0,
                    "{name}: streams differ at {threads} threads"
                );
                assert!(one.1 == more.1, "{name}: .bt differ at {threads} threads");
                assert!(one.2 == more.2, "{name}: .ot differ at {threads} threads");
            }
        }
    }
}
