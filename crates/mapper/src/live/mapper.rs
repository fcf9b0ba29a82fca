//! The mapper's loop (`octo-delta map`): scans in as they come, each inserted and its delta
//! queued at once with the vehicle's pose; segments out as the transport's shaper allows;
//! acknowledgements and requests in from the carrier; everything from one channel, woken by
//! the transport's next deadline.
//!
//! The backlog is bounded: when the records waiting exceed [`MapperSetup::backlog_bytes`] and a
//! full map of the mirror is smaller, they are replaced by it (sync record and full message):
//! no change is lost, the operator gets them all at once. Requests are answered once per id
//! (a resent request gets the same reply) and each kind at most once per resend timeout
//! (more are refused as busy): a flood of requests costs the link nothing but replies.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender};
use std::time::{Duration, Instant, SystemTime};

use rovlink_maplink::outbox::{OutboxStats, RECORD_MESSAGE};
use rovlink_maplink::segment::{DATA_HEADER_BYTES, MAX_CHUNK_BYTES};
use rovlink_maplink::{Outbox, OutboxConfig, Repr, Request};
use rovlink_octo::Scan;
use serde::Serialize;

use super::carrier::{Carried, Carrier, CarrierCounters};
use super::input::{FeedReport, feed};
use super::map_state::{Answer, MapState, pose_record};
use crate::pipeline::{BuildConfig, PipelineError};

/// What the mapper's loop waits on.
pub enum MapperEvent {
    /// A scan, whole, and when it was.
    Scan(Box<Scan>, SystemTime),
    /// The inputs are all read (or failed).
    InputEnded(Result<FeedReport, PipelineError>),
    /// Something from the carrier.
    Carried(Carried),
}

/// How the mapper runs.
pub struct MapperSetup {
    /// The build's configuration (the same flags as `build`).
    pub cfg: BuildConfig,
    /// The inputs.
    pub inputs: Vec<PathBuf>,
    /// Follow files as they are written.
    pub follow: bool,
    /// The transport.
    pub outbox: OutboxConfig,
    /// The stream's epoch (random at each start).
    pub epoch: u32,
    /// The most bytes of records waiting before they are replaced by a full map.
    pub backlog_bytes: usize,
    /// End once the inputs are read and the operator has everything (else serve requests
    /// until stopped).
    pub exit_when_done: bool,
    /// With `exit_when_done`: end anyway once the inputs are read and nothing has been
    /// acknowledged for this long (the view has gone).
    pub linger: Duration,
}

/// One scan as the mapper sent it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScanRow {
    /// Scan number.
    pub scan: u32,
    /// When the scan came, s from the first scan.
    pub t_arrival_s: f64,
    /// Points in it.
    pub points: usize,
    /// Its delta message, bytes.
    pub message_bytes: usize,
    /// Its records (message and pose) on the link: data segments with the carrier's framing.
    pub link_bytes: usize,
    /// The map as `.bt` after it, bytes (0 unless asked for).
    pub full_bt_bytes: usize,
}

/// The `--stats` columns of `map`, in order.
pub const SCAN_COLUMNS: [&str; 6] = [
    "scan",
    "t_arrival_s",
    "points",
    "message_bytes",
    "link_bytes",
    "full_bt_bytes",
];

/// A request as the mapper answered it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RequestRow {
    /// Its id.
    pub id: u32,
    /// What it asked (JSON form).
    pub request: serde_json::Value,
    /// When it came, s from the start.
    pub t_s: f64,
    /// Why it was refused, if it was.
    pub refused: Option<String>,
    /// Bytes of the records that answer it.
    pub answer_bytes: usize,
}

/// What the loop reports to and asks of its caller.
pub struct MapperHooks<'a> {
    /// Set to stop (after the current scan).
    pub stop: &'a AtomicBool,
    /// Something the user should know (said once per kind by the caller's choice).
    pub say: &'a mut dyn FnMut(String),
    /// After each scan.
    pub scan: &'a mut dyn FnMut(&ScanRow),
    /// Whether to compute each scan's full `.bt` size (a copy of the map per scan).
    pub full_sizes: bool,
}

/// What a run did.
pub struct MapperRun {
    /// The map and the view state at the end.
    pub state: MapState,
    /// One row per scan.
    pub rows: Vec<ScanRow>,
    /// Requests answered.
    pub requests: Vec<RequestRow>,
    /// The transport's counters.
    pub outbox: OutboxStats,
    /// The carrier's counters.
    pub carrier: CarrierCounters,
    /// Segments from the operator that did not parse or were not for the mapper.
    pub malformed: u64,
    /// Times the backlog was replaced by a full map.
    pub backlog_replacements: u64,
    /// How reading ended (none: still reading when stopped).
    pub feed: Option<Result<FeedReport, PipelineError>>,
    /// The carrier closed: why.
    pub closed: Option<String>,
    /// Whether the stop flag ended the run.
    pub interrupted: bool,
    /// Seconds from start to end.
    pub elapsed_s: f64,
    /// Whether everything sent was acknowledged at the end.
    pub all_acknowledged: bool,
}

/// Link bytes of a record's data segments.
fn link_bytes(record_len: usize, overhead: usize) -> usize {
    record_len + record_len.div_ceil(MAX_CHUNK_BYTES) * (DATA_HEADER_BYTES + overhead)
}

/// Answers remembered for resent requests.
const REMEMBERED: usize = 64;

/// Runs the mapper until the inputs are done and acknowledged (with `exit_when_done`), the
/// stop flag, or the carrier closing. `events` is the channel `to_loop` feeds (the carrier's
/// reader sends there too).
pub fn run(
    setup: MapperSetup,
    carrier: &mut Carrier,
    to_loop: SyncSender<MapperEvent>,
    events: Receiver<MapperEvent>,
    hooks: &mut MapperHooks<'_>,
) -> Result<MapperRun, PipelineError> {
    let mut state = MapState::new(&setup.cfg)?;
    let start = Instant::now();
    let mut outbox = Outbox::new(setup.outbox, setup.epoch);
    for r in state.start_records() {
        outbox.push(r);
    }
    let mut run = MapperRun {
        state: MapState::new(&setup.cfg)?,
        rows: Vec::new(),
        requests: Vec::new(),
        outbox: OutboxStats::default(),
        carrier: CarrierCounters::default(),
        malformed: 0,
        backlog_replacements: 0,
        feed: None,
        closed: None,
        interrupted: false,
        elapsed_s: 0.0,
        all_acknowledged: false,
    };
    // The reading ends when the loop does, whyever it does.
    let quit = AtomicBool::new(false);
    let quit = &quit;
    std::thread::scope(|scope| -> Result<(), PipelineError> {
        let events = events;
        let (inputs, cfg, follow) = (&setup.inputs, &setup.cfg, setup.follow);
        let tx = to_loop.clone();
        scope.spawn(move || {
            let mut send = |scan: Scan| {
                tx.send(MapperEvent::Scan(Box::new(scan), SystemTime::now()))
                    .is_ok()
            };
            let ended = feed(inputs, cfg, follow, quit, &mut send);
            let _ = tx.send(MapperEvent::InputEnded(ended));
        });
        drop(to_loop);
        let outcome = serve(
            &setup,
            &mut state,
            &mut outbox,
            carrier,
            &events,
            hooks,
            &mut run,
            start,
        );
        quit.store(true, Ordering::Relaxed);
        outcome
    })?;
    run.all_acknowledged = outbox.idle();
    run.outbox = outbox.stats();
    run.carrier = carrier.counters();
    run.elapsed_s = start.elapsed().as_secs_f64();
    run.state = state;
    Ok(run)
}

/// The loop itself: until done, stopped or the carrier closes.
#[allow(clippy::too_many_arguments)]
fn serve(
    setup: &MapperSetup,
    state: &mut MapState,
    outbox: &mut Outbox,
    carrier: &mut Carrier,
    events: &Receiver<MapperEvent>,
    hooks: &mut MapperHooks<'_>,
    run: &mut MapperRun,
    start: Instant,
) -> Result<(), PipelineError> {
    let overhead = setup.outbox.frame_overhead_bytes;
    let rto = setup.outbox.rto;
    let stop = hooks.stop;
    let mut answered: VecDeque<(u32, bool, u32)> = VecDeque::new();
    let mut last_of_kind: [Option<Duration>; 7] = [None; 7];
    let mut first_arrival: Option<SystemTime> = None;
    loop {
        let now = start.elapsed();
        while let Some(seg) = outbox.poll(now) {
            if let Err(e) = carrier.send(&seg) {
                run.closed = Some(format!("{}: write failed: {e}", carrier.name));
                return Ok(());
            }
        }
        if stop.load(Ordering::Relaxed) {
            run.interrupted = true;
            return Ok(());
        }
        if setup.exit_when_done && run.feed.is_some() && outbox.idle() {
            return Ok(());
        }
        let wait = outbox
            .next_deadline()
            .map_or(Duration::from_millis(200), |t| t.saturating_sub(now))
            .min(Duration::from_millis(200));
        let event = match events.recv_timeout(wait) {
            Ok(e) => e,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => return Ok(()),
        };
        match event {
            MapperEvent::Scan(scan, at) => {
                let first = *first_arrival.get_or_insert(at);
                let Some(done) = state.insert(&scan, stop)? else {
                    run.interrupted = true;
                    return Ok(());
                };
                let scan_no = state.scans - 1;
                let unix = at
                    .duration_since(SystemTime::UNIX_EPOCH)
                    .map_or(0.0, |d| d.as_secs_f64());
                let pose = pose_record(scan_no, unix, &scan.pose);
                let mut message = vec![RECORD_MESSAGE];
                message.extend_from_slice(&done.message);
                let row = ScanRow {
                    scan: scan_no,
                    t_arrival_s: at.duration_since(first).map_or(0.0, |d| d.as_secs_f64()),
                    points: done.update.points,
                    message_bytes: done.message.len(),
                    link_bytes: link_bytes(pose.len(), overhead)
                        + link_bytes(message.len(), overhead),
                    full_bt_bytes: if hooks.full_sizes {
                        state
                            .tree_ref()
                            .map_or(0, |t| rovlink_octo::files::write_bt(t).len())
                    } else {
                        0
                    },
                };
                outbox.push(pose);
                outbox.push(message);
                (hooks.scan)(&row);
                run.rows.push(row);
                let backlog = outbox.backlog();
                if backlog.bytes > setup.backlog_bytes {
                    let records = state.resync_records();
                    let bytes = MapState::resync_bytes(&records);
                    if bytes < backlog.bytes {
                        outbox.replace_backlog(records);
                        run.backlog_replacements += 1;
                        (hooks.say)(format!(
                            "backlog of {} bytes ({} records) replaced by the full map ({bytes} bytes): the link is slower than the map grows, or down",
                            backlog.bytes, backlog.records
                        ));
                    }
                }
            }
            MapperEvent::InputEnded(ended) => run.feed = Some(ended),
            MapperEvent::Carried(Carried::Closed(why)) => {
                run.closed = Some(format!("{}: {why}", carrier.name));
                return Ok(());
            }
            MapperEvent::Carried(Carried::Segment(bytes)) => match Repr::parse(&bytes) {
                Ok(Repr::Ack { epoch, cum, sack }) => {
                    outbox.on_ack(epoch, cum, sack, start.elapsed())
                }
                Ok(Repr::Request { id, request }) => {
                    if let Some(&(_, refused, seq)) = answered.iter().find(|(i, _, _)| *i == id) {
                        outbox.reply(id, refused, seq);
                        continue;
                    }
                    let now = start.elapsed();
                    let kind = request.kind() as usize;
                    let busy = last_of_kind[kind].is_some_and(|t| now < t + rto);
                    let answer = if busy {
                        Answer::Refused(format!(
                            "busy: one {} request per {:.1} s",
                            request.name(),
                            rto.as_secs_f64()
                        ))
                    } else {
                        match request {
                            Request::Resync => Answer::Restart(state.resync_records()),
                            Request::Full => state.full(),
                            Request::FullBox(b) => state.full_box(&b),
                            Request::Roi(b) => state.set_roi(b),
                            Request::CoarseDepth(d) => state.set_coarse_depth(d),
                        }
                    };
                    let mut row = RequestRow {
                        id,
                        request: request.to_json(),
                        t_s: now.as_secs_f64(),
                        refused: None,
                        answer_bytes: 0,
                    };
                    if !matches!(answer, Answer::Refused(_)) {
                        last_of_kind[kind] = Some(now);
                    }
                    let (refused, seq) = match answer {
                        Answer::Refused(why) => {
                            (hooks.say)(format!("request {id} refused: {why}"));
                            row.refused = Some(why);
                            (true, 0)
                        }
                        Answer::Queue(records) => {
                            row.answer_bytes = records.iter().map(Vec::len).sum();
                            for r in records {
                                outbox.push(r);
                            }
                            (false, 0)
                        }
                        Answer::Restart(records) => {
                            row.answer_bytes = records.iter().map(Vec::len).sum();
                            (false, outbox.restart(records))
                        }
                    };
                    outbox.reply(id, refused, seq);
                    answered.push_back((id, refused, seq));
                    if answered.len() > REMEMBERED {
                        answered.pop_front();
                    }
                    run.requests.push(row);
                }
                Ok(_) | Err(_) => run.malformed += 1,
            },
        }
    }
}
