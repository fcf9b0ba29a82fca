//! The build loop ([`build`]): the scans of every input into one [`OcTree`], one delta message
//! per scan written as soon as it is made, a [`StatsRow`] per scan to a sink, a stop flag looked
//! at between scans and inside them; what it did ([`BuildReport`], [`Built`]: figures and the
//! summary line), and when each message reached the operator over a link ([`arrival_rows`]).

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

use serde::Serialize;

use super::reading::{Reading, count_skipped, read_inputs};
use super::{BuildConfig, PipelineError};
use rovlink_base::io::IoError;
use rovlink_octo::Scan;
use rovlink_octo::cast::{PreparedScan, ScanCaster, TooManyCells};
use rovlink_octo::delta::{self, Sender, ViewSpec};
use rovlink_octo::tree::OcTree;
use rovlink_octo::{files, transfer};

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
    /// writes its message and reports it; casting it took `cast_s`.
    fn emit(
        &mut self,
        tree: &mut OcTree,
        prepared: Option<PreparedScan>,
        cast_s: f64,
        report: &mut BuildReport,
        hooks: &mut Hooks<'_>,
        known: u64,
    ) -> Result<bool, PipelineError> {
        let Some(prepared) = prepared else {
            report.interrupted = true;
            return Ok(false);
        };
        let started = Instant::now();
        let up = tree.apply_scan(&prepared);
        let d = self.sender.delta(tree, &up.changes);
        let msg = delta::encode_delta(&self.spec, report.scans, &d);
        let dt = cast_s + started.elapsed().as_secs_f64();
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

/// Scans read and not yet in the map per casting thread, at most: a few per thread, so that a
/// thread done with a quick scan finds another queued while the map waits for a slow one.
const SCANS_AHEAD_PER_THREAD: usize = 4;

/// How often the build's loop looks at the stop flag while it waits for the reading or the
/// casting threads.
const STOP_POLL: Duration = Duration::from_millis(20);

/// What the build's loop waits for: something read, a scan cast, or the reading's end.
enum Event {
    /// From the reading thread, in the order read (scans go to the [`ScanQueue`]).
    Read(Reading),
    /// The reading thread put scan number `i` into the [`ScanQueue`]. A thread may take the
    /// scan, and its cast may come, before this does.
    Queued(usize),
    /// A scan cast (by its number; `None`: the stop flag ended its casting, or its thread
    /// failed; an error: it would cross too many cells), and how long casting it took, s.
    Cast(usize, Casting, f64),
    /// The reading ended: stopped (true) or done (false), or an input failed.
    Ended(Result<bool, PipelineError>),
}

/// What casting a scan gave ([`ScanCaster::prepare`]).
type Casting = Result<Option<PreparedScan>, TooManyCells>;

/// The scans read and not yet cast, numbered in the order read. The reading thread puts them
/// in; the first thread free takes each: a casting thread, or the build's loop when no cast
/// scan waits to go into the map ([`Run::cast_here`]).
type ScanQueue = Arc<Mutex<mpsc::Receiver<(usize, Scan)>>>;

/// The scans between the reading and the map: queued, cast (in any order) and applied (in
/// the order read).
struct InFlight {
    /// The scans read and not yet taken by a thread.
    queue: ScanQueue,
    /// Scans cast before an earlier one, by number.
    early: BTreeMap<usize, (Casting, f64)>,
    /// Scans known to be queued so far: one more than the highest number seen, in an
    /// [`Event::Queued`] or in a cast, whichever came first.
    queued: usize,
    /// Cast scans applied (or dropped) so far: the number of the next one to apply.
    applied: usize,
}

impl InFlight {
    /// Scans queued and not yet applied.
    fn count(&self) -> usize {
        self.queued - self.applied
    }

    /// Scan `i` is queued (it may have been seen already).
    fn seen(&mut self, i: usize) {
        self.queued = self.queued.max(i + 1);
    }

    /// The next scan queued that no casting thread has taken, if there is one and the queue
    /// is not in a casting thread's hands (one waiting there for a scan holds it while the
    /// queue is empty).
    fn take(&self) -> Option<(usize, Scan)> {
        match self.queue.try_lock() {
            Ok(q) => q.try_recv().ok(),
            Err(std::sync::TryLockError::Poisoned(q)) => q.into_inner().try_recv().ok(),
            Err(std::sync::TryLockError::WouldBlock) => None,
        }
    }

    /// Keeps a scan cast (by any thread) until it is next to apply.
    fn cast(&mut self, i: usize, cast: Casting, cast_s: f64) {
        // Cast, hence queued, though its `Event::Queued` may still be on its way.
        self.seen(i);
        self.early.insert(i, (cast, cast_s));
    }

    /// The next scan to apply, in the order read, if it is cast.
    fn next_ready(&mut self) -> Option<(Casting, f64)> {
        let next = self.early.remove(&self.applied)?;
        self.applied += 1;
        Some(next)
    }
}

/// Casts `scan` with `c`, and how long that took, s. A failure inside casting (a bug: casting
/// does not panic on any input) is an `Err`: that scan is lost, and the build ends as stopped.
fn cast_caught(
    c: &mut ScanCaster,
    scan: &Scan,
    max_range_m: Option<f64>,
    stop: &AtomicBool,
) -> (std::thread::Result<Casting>, f64) {
    let t0 = Instant::now();
    let cast = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        c.prepare(scan, max_range_m, stop)
    }));
    (cast, t0.elapsed().as_secs_f64())
}

/// Starts `n` casting threads in `scope`, each with a copy of `caster` (casting a scan on one
/// thread): each takes scans from `queue`, stops inside a scan when `stop` is set, and sends
/// each cast scan to `events` as soon as it is done.
fn spawn_casters<'scope>(
    n: usize,
    caster: &ScanCaster,
    max_range_m: Option<f64>,
    queue: &ScanQueue,
    stop: &'scope AtomicBool,
    events: &mpsc::Sender<Event>,
    scope: &'scope std::thread::Scope<'scope, '_>,
) {
    for _ in 0..n {
        let mut c = caster.clone();
        c.set_threads(1);
        let (queue, events) = (Arc::clone(queue), events.clone());
        scope.spawn(move || {
            loop {
                // Another thread failing while it waited leaves the lock poisoned: the queue
                // is still whole.
                let next = match queue.lock() {
                    Ok(q) => q.recv(),
                    Err(poisoned) => poisoned.into_inner().recv(),
                };
                let Ok((i, scan)) = next else { break };
                let (cast, cast_s) = cast_caught(&mut c, &scan, max_range_m, stop);
                let failed = cast.is_err();
                if events
                    .send(Event::Cast(i, cast.unwrap_or(Ok(None)), cast_s))
                    .is_err()
                    || failed
                {
                    break;
                }
            }
        });
    }
}

/// Builds the map from the scans of `inputs` (in order; `-` is standard input) and writes the
/// delta stream to `stream` (named `stream_name` in errors): the header, then one message per
/// scan as soon as it is made. The map keeps colours when the first scan has them, unless
/// [`BuildConfig::no_color`].
///
/// The inputs are read on a thread of their own ([`super::read_inputs`]), a few scans ahead of
/// the map, so that reading, decompressing and decoding overlap the map's work. With more than
/// one thread ([`BuildConfig::threads`]), the scans are cast on that many threads, a scan each:
/// this one (when no cast scan waits to go into the map) and one fewer of their own; the last
/// scan, once the reading has ended, on all of them, its rays shared. The map
/// and the stream are the same as with one thread, byte for byte, and each scan goes into the
/// map and the stream as soon as it is read and cast, whatever comes after it (a live input
/// may be quiet for a long time).
///
/// When `hooks.stop` is set the build ends before the next scan (or inside a scan, before it
/// changes the map): the stream then holds whole messages for every scan in the map, and
/// [`BuildReport::interrupted`] says so. An input that does not parse fails the build (after
/// the scans before it went into the map and the stream), as does a write error; the caller
/// should then drop its outputs.
pub fn build(
    cfg: &BuildConfig,
    inputs: &[PathBuf],
    stream: &mut dyn Write,
    stream_name: &str,
    hooks: &mut Hooks<'_>,
) -> Result<Built, PipelineError> {
    let spec = cfg.validate()?;
    let started = Instant::now();
    let threads = cfg.thread_count();
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
    // The reading ends when the build's loop does, whyever it does.
    let quit = AtomicBool::new(false);
    let quit = &quit;
    std::thread::scope(|scope| {
        let (events_tx, events) = mpsc::channel::<Event>();
        let (scans_tx, scans) = mpsc::channel::<(usize, Scan)>();
        // A token per scan read ahead of the map, given back as each goes in.
        let ahead = threads.max(1) * SCANS_AHEAD_PER_THREAD;
        let (tokens_back, tokens) = mpsc::sync_channel::<()>(ahead);
        for _ in 0..ahead {
            let _ = tokens_back.try_send(());
        }
        let tx = events_tx.clone();
        scope.spawn(move || {
            let mut read = 0;
            let mut send = |r: Reading| {
                let Reading::Scan(scan) = r else {
                    return tx.send(Event::Read(r)).is_ok();
                };
                let i = read;
                if tokens.recv().is_err() || scans_tx.send((i, scan)).is_err() {
                    return false;
                }
                read += 1;
                tx.send(Event::Queued(i)).is_ok()
            };
            let ended = read_inputs(inputs, cfg, false, quit, &mut send);
            let _ = tx.send(Event::Ended(ended));
        });
        let mut run = Run {
            cfg,
            threads,
            out: &mut out,
            tree: &mut tree,
            report: &mut report,
            scans: InFlight {
                queue: Arc::new(Mutex::new(scans)),
                early: BTreeMap::new(),
                queued: 0,
                applied: 0,
            },
            known: 0,
            tokens_back,
        };
        let stop = hooks.stop;
        let outcome = run.serve(&events, &events_tx, stop, hooks, scope);
        quit.store(true, Ordering::Relaxed);
        outcome
    })?;
    report.elapsed_s = started.elapsed().as_secs_f64();
    let tree = tree.unwrap_or_else(|| OcTree::new(cfg.resolution_m));
    Ok(Built { tree, report })
}

/// The build's loop and what it keeps: scans read are cast by the first thread free (this
/// one among them), cast scans go into the map in the order read.
struct Run<'r, 'w> {
    cfg: &'r BuildConfig,
    threads: usize,
    out: &'r mut Emitter<'w>,
    tree: &'r mut Option<OcTree>,
    report: &'r mut BuildReport,
    scans: InFlight,
    /// Scans the inputs opened so far say they have.
    known: u64,
    /// Gives the reading a token back for each scan that went into the map.
    tokens_back: mpsc::SyncSender<()>,
}

impl Run<'_, '_> {
    /// Takes events until the reading ended and every scan read is in the map, the stop flag
    /// is set, or something fails. With nothing to take in, a queued scan is cast here.
    fn serve<'scope>(
        &mut self,
        events: &mpsc::Receiver<Event>,
        events_tx: &mpsc::Sender<Event>,
        stop: &'scope AtomicBool,
        hooks: &mut Hooks<'_>,
        scope: &'scope std::thread::Scope<'scope, '_>,
    ) -> Result<(), PipelineError> {
        let mut ended: Option<Result<bool, PipelineError>> = None;
        loop {
            if stop.load(Ordering::Relaxed) {
                self.report.interrupted = true;
                return Ok(());
            }
            if self.scans.count() == 0
                && let Some(end) = ended.take()
            {
                // A live input ends only when stopped.
                self.report.interrupted |= end? || stop.load(Ordering::Relaxed);
                return Ok(());
            }
            let event = match events.try_recv() {
                Ok(event) => event,
                Err(_) => match self.cast_here(events_tx, stop, hooks, scope, ended.is_some())? {
                    Some(true) => continue,
                    Some(false) => return Ok(()),
                    None => match events.recv_timeout(STOP_POLL) {
                        Ok(event) => event,
                        Err(mpsc::RecvTimeoutError::Timeout) => continue,
                        Err(mpsc::RecvTimeoutError::Disconnected) => {
                            self.report.interrupted = true;
                            return Ok(());
                        }
                    },
                },
            };
            let go_on = match event {
                Event::Ended(end) => {
                    ended = Some(end);
                    true
                }
                Event::Read(Reading::Opened { scans }) => {
                    self.known += scans;
                    if let Some(p) = hooks.progress.as_mut() {
                        p(self.report.scans as u64, self.known);
                    }
                    true
                }
                Event::Read(Reading::Skipped(reason)) => {
                    count_skipped(&mut self.report.skipped, reason);
                    true
                }
                Event::Read(Reading::Notes(notes)) => {
                    self.report.notes.extend(notes);
                    true
                }
                // Scans come through the queue.
                Event::Read(Reading::Scan(_)) => true,
                Event::Queued(i) => {
                    self.scans.seen(i);
                    true
                }
                Event::Cast(i, prepared, cast_s) => {
                    self.scans.cast(i, prepared, cast_s);
                    self.apply_ready(hooks)?
                }
            };
            if !go_on {
                return Ok(());
            }
        }
    }

    /// Casts here the next queued scan that no casting thread has taken, then puts every cast
    /// scan next in order into the map: `None` when there was none to cast, else false if the
    /// build stopped. The first scan makes the map (coloured or not) and starts the casting
    /// threads, one fewer than the build's threads. The last scan, once the reading has
    /// ended, is cast on all the build's threads: no scan is left for the casting threads.
    fn cast_here<'scope>(
        &mut self,
        events_tx: &mpsc::Sender<Event>,
        stop: &'scope AtomicBool,
        hooks: &mut Hooks<'_>,
        scope: &'scope std::thread::Scope<'scope, '_>,
        reading_ended: bool,
    ) -> Result<Option<bool>, PipelineError> {
        let Some((i, scan)) = self.scans.take() else {
            return Ok(None);
        };
        let cfg = self.cfg;
        let first = self.tree.is_none();
        let tree = self.tree.get_or_insert_with(|| cfg.new_tree(&scan));
        if first {
            spawn_casters(
                self.threads.saturating_sub(1),
                &tree.caster(),
                cfg.max_range_m,
                &self.scans.queue,
                stop,
                events_tx,
                scope,
            );
        }
        // Its own caster casts on one thread, the others casting scans apart; the last scan
        // read, the reading over, has its rays shared by all of them (the same cells, in the
        // same order: the casting threads are idle or finishing the scan before it). A failed
        // scan (`None`) ends the build as stopped when its turn comes, with every scan before
        // it in the map.
        let last = reading_ended && i + 1 == self.scans.queued;
        let caster = tree.caster_mut();
        caster.set_threads(if last { self.threads } else { 1 });
        let (cast, cast_s) = cast_caught(caster, &scan, cfg.max_range_m, stop);
        caster.set_threads(1);
        self.scans.cast(i, cast.unwrap_or(Ok(None)), cast_s);
        self.apply_ready(hooks).map(Some)
    }

    /// Every cast scan next in order goes into the map, its message written; false if the
    /// build stopped.
    fn apply_ready(&mut self, hooks: &mut Hooks<'_>) -> Result<bool, PipelineError> {
        let Some(tree) = self.tree.as_mut() else {
            return Ok(true);
        };
        while let Some((prepared, cast_s)) = self.scans.next_ready() {
            if hooks.stop.load(Ordering::Relaxed) {
                self.report.interrupted = true;
                return Ok(false);
            }
            let prepared = self.cfg.cells_checked(self.report.scans, prepared)?;
            if !self
                .out
                .emit(tree, prepared, cast_s, self.report, hooks, self.known)?
            {
                return Ok(false);
            }
            let _ = self.tokens_back.try_send(());
        }
        Ok(true)
    }
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

    /// A scan taken from the queue and cast before the reading's `Event::Queued` for it
    /// arrives (the loop casts between the reading's two sends) counts as queued: the scans in
    /// flight never go below zero (a panic in a debug build before), and the late event
    /// changes nothing.
    #[test]
    fn a_scan_cast_before_its_queued_event_is_counted_once() {
        let (_tx, rx) = mpsc::channel::<(usize, Scan)>();
        let mut f = InFlight {
            queue: Arc::new(Mutex::new(rx)),
            early: BTreeMap::new(),
            queued: 0,
            applied: 0,
        };
        f.cast(0, Ok(None), 0.0);
        assert_eq!(f.count(), 1);
        assert!(f.next_ready().is_some());
        assert_eq!(f.count(), 0);
        f.seen(0);
        assert_eq!(f.count(), 0);
        // Scan 2 cast before scan 1: both in flight, and nothing to apply yet.
        f.cast(2, Ok(None), 0.0);
        f.seen(1);
        assert_eq!(f.count(), 2);
        assert!(f.next_ready().is_none());
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
