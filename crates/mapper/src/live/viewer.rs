//! The operator's side of the live map (`octo-delta view`): segments in, the view applied
//! record by record, and what changed out for the screen (scene updates, the vehicle's pose, a
//! log); requests out until answered, each answer timed.
//!
//! Records (docs/octo-delta-format.md, "Live transport"): a sync record starts a new view with
//! its header (the scene is cleared), a spec record moves the ROI (same resolution and coarse
//! depth), a message record is applied, a pose record says where the vehicle was and when its
//! scan came to the mapper (the next message is that scan's: the time from the cloud's arrival
//! to its voxels shown is measured there). A record that does not parse is counted, never
//! applied, and the view asks for a resync.

use std::collections::VecDeque;
use std::time::Duration;

use rovlink_maplink::outbox::{RECORD_MESSAGE, RECORD_POSE, RECORD_SPEC, RECORD_SYNC};
use rovlink_maplink::{Inbox, InboxEvent, Request};
use rovlink_octo::delta::{self, Message, Receiver, ViewSpec};
use rovlink_octo::tree::OcTree;
use serde::Serialize;

use super::map_state::POSE_RECORD_BYTES;
use crate::view::{Deletion, SceneBuilder, SceneUpdate, Time};

/// What the view has for the screen.
#[derive(Debug, Clone, PartialEq)]
pub enum ViewOutput {
    /// The scene changed (incremental: a client that subscribes later needs a snapshot).
    Scene(SceneUpdate),
    /// Where the vehicle was after a scan: position (m) and orientation x, y, z, w.
    Pose([f64; 3], [f64; 4]),
    /// Something to tell the operator.
    Log(LogKind, String),
}

/// How much a log line matters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogKind {
    /// News.
    Info,
    /// Something went wrong and was dealt with.
    Warning,
}

/// One message as the view applied it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShownRow {
    /// Scan number the message is after.
    pub scan: u32,
    /// Its kind: delta, full or region.
    pub kind: &'static str,
    /// Message bytes.
    pub bytes: usize,
    /// When its scan came to the mapper, s from the first scan the view heard of (none for
    /// a message no pose record announced: an answer to a request).
    pub t_ready_s: Option<f64>,
    /// When it was applied, s on the same clock.
    pub t_shown_s: f64,
    /// From its scan's arrival at the mapper to applied here, s.
    pub latency_s: Option<f64>,
}

/// A request as the view saw it answered.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RequestOutcome {
    /// Its id.
    pub id: u32,
    /// What it asked.
    pub request: serde_json::Value,
    /// When it was asked, s from the view's start.
    pub asked_s: f64,
    /// When its reply came.
    pub replied_s: Option<f64>,
    /// Whether the mapper refused it.
    pub refused: bool,
    /// When its answer (a full or region message, or the resync's) was applied.
    pub applied_s: Option<f64>,
    /// The answer's bytes.
    pub answer_bytes: Option<usize>,
}

/// What the view has counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct ViewCounters {
    /// Messages applied.
    pub messages: u64,
    /// Records that did not parse (never applied).
    pub bad_records: u64,
    /// Times the view started again from a sync record.
    pub syncs: u64,
    /// Times the mapper was seen to restart.
    pub mapper_restarts: u64,
}

/// The view and its transport.
pub struct Viewer {
    inbox: Inbox,
    scene: Option<SceneBuilder>,
    plain: Option<Receiver>,
    with_scene: bool,
    outputs: VecDeque<ViewOutput>,
    /// The pose record waiting for its message: scan, arrival (Unix s).
    announced: Option<(u32, f64)>,
    /// The first arrival heard of (Unix s): the origin of the rows' times.
    origin_unix_s: Option<f64>,
    start_unix_s: f64,
    rows: Vec<ShownRow>,
    requests: Vec<RequestOutcome>,
    counters: ViewCounters,
}

impl Viewer {
    /// A view with no map yet; `rto` is the transport's resend timeout, `first_id` the first
    /// request id (random), `start_unix_s` the wall clock at `now = 0`; `with_scene` builds
    /// scene updates (a Foxglove view), else only the map.
    pub fn new(rto: Duration, first_id: u32, start_unix_s: f64, with_scene: bool) -> Viewer {
        Viewer {
            inbox: Inbox::new(rto, first_id),
            scene: None,
            plain: None,
            with_scene,
            outputs: VecDeque::new(),
            announced: None,
            origin_unix_s: None,
            start_unix_s,
            rows: Vec::new(),
            requests: Vec::new(),
            counters: ViewCounters::default(),
        }
    }

    /// Asks for the stream from the start of what the mapper has (a view starting late).
    pub fn want_resync(&mut self, now: Duration) {
        self.request(Request::Resync, now);
    }

    /// The view so far (none before the first sync).
    pub fn view(&self) -> Option<&OcTree> {
        match (&self.scene, &self.plain) {
            (Some(s), _) => Some(s.view()),
            (_, Some(p)) => Some(p.view()),
            _ => None,
        }
    }

    /// The spec of the view (none before the first sync).
    pub fn spec(&self) -> Option<&ViewSpec> {
        match (&self.scene, &self.plain) {
            (Some(s), _) => Some(s.spec()),
            (_, Some(p)) => Some(p.spec()),
            _ => None,
        }
    }

    /// The whole scene now (for a client that just subscribed).
    pub fn snapshot(&self, time_ns: u64) -> Option<SceneUpdate> {
        self.scene.as_ref().map(|s| s.snapshot(time_ns))
    }

    /// One row per message applied.
    pub fn rows(&self) -> &[ShownRow] {
        &self.rows
    }

    /// Every request and how it was answered.
    pub fn requests(&self) -> &[RequestOutcome] {
        &self.requests
    }

    /// The counts.
    pub fn counters(&self) -> ViewCounters {
        self.counters
    }

    /// The transport's counts.
    pub fn transport(&self) -> rovlink_maplink::inbox::InboxStats {
        self.inbox.stats()
    }

    /// Whether the view follows the mapper's stream.
    pub fn synced(&self) -> bool {
        self.inbox.synced()
    }

    /// Queues a request; its id, or `None` when too many wait.
    pub fn request(&mut self, request: Request, now: Duration) -> Option<u32> {
        let id = self.inbox.request(request, now)?;
        self.requests.push(RequestOutcome {
            id,
            request: request.to_json(),
            asked_s: now.as_secs_f64(),
            replied_s: None,
            refused: false,
            applied_s: None,
            answer_bytes: None,
        });
        Some(id)
    }

    /// The next segment to send.
    pub fn poll(&mut self, now: Duration) -> Option<Vec<u8>> {
        self.inbox.poll(now)
    }

    /// An acknowledgement of everything applied, now (at exit).
    pub fn final_ack(&mut self) -> Option<Vec<u8>> {
        self.inbox.ack_now()
    }

    /// When [`Viewer::poll`] may next give something.
    pub fn next_deadline(&self) -> Option<Duration> {
        self.inbox.next_deadline()
    }

    /// What changed for the screen since the last call.
    pub fn take_outputs(&mut self) -> Vec<ViewOutput> {
        self.outputs.drain(..).collect()
    }

    fn log(&mut self, kind: LogKind, text: String) {
        self.outputs.push_back(ViewOutput::Log(kind, text));
    }

    /// Takes a segment from the link at `now`; what it completes is applied at once.
    pub fn on_segment(&mut self, bytes: &[u8], now: Duration) {
        if let Err(e) = self.inbox.on_segment(bytes, now)
            && self.inbox.stats().malformed == 1
        {
            self.log(
                LogKind::Warning,
                format!("a segment that does not parse was dropped ({e}); all such are counted"),
            );
        }
        while let Some(e) = self.inbox.next_event() {
            match e {
                InboxEvent::Record(r) => self.record(&r, now),
                InboxEvent::Synced { epoch, seq } => {
                    self.log(
                        LogKind::Info,
                        format!("following the mapper's stream {epoch:08x} from segment {seq}"),
                    );
                }
                InboxEvent::NewEpoch(epoch) => {
                    self.counters.mapper_restarts += 1;
                    self.log(
                        LogKind::Info,
                        format!("the mapper's stream {epoch:08x} began: resynchronising"),
                    );
                }
                InboxEvent::Reply { id, refused, .. } => {
                    if let Some(r) = self.requests.iter_mut().find(|r| r.id == id) {
                        r.replied_s = Some(now.as_secs_f64());
                        r.refused = refused;
                    }
                    let what = if refused { "refused" } else { "accepted" };
                    self.log(LogKind::Info, format!("request {id} {what} by the mapper"));
                }
            }
        }
    }

    fn unix(&self, now: Duration) -> f64 {
        self.start_unix_s + now.as_secs_f64()
    }

    fn bad(&mut self, what: String, now: Duration) {
        self.counters.bad_records += 1;
        self.log(
            LogKind::Warning,
            format!("{what}: dropped, never applied; resynchronising"),
        );
        self.want_resync(now);
    }

    fn record(&mut self, r: &[u8], now: Duration) {
        let (&kind, body) = match r.split_first() {
            Some(x) => x,
            None => return self.bad("an empty record".into(), now),
        };
        match kind {
            RECORD_SYNC | RECORD_SPEC => {
                let spec = match delta::decode_header(body) {
                    Ok((h, n)) if n == body.len() => h.spec,
                    Ok(_) => return self.bad("a header record with bytes after it".into(), now),
                    Err(e) => return self.bad(format!("a header record: {e}"), now),
                };
                if kind == RECORD_SYNC {
                    self.start(spec, now);
                } else {
                    self.move_roi(spec, now);
                }
            }
            RECORD_MESSAGE => self.message(body, now),
            RECORD_POSE => {
                if r.len() != POSE_RECORD_BYTES {
                    return self.bad(format!("a pose record of {} bytes", r.len()), now);
                }
                let f = |i: usize| f32::from_le_bytes([r[i], r[i + 1], r[i + 2], r[i + 3]]) as f64;
                let scan = u32::from_le_bytes([r[1], r[2], r[3], r[4]]);
                let mut t = [0u8; 8];
                t.copy_from_slice(&r[5..13]);
                let t = f64::from_le_bytes(t);
                let p = [f(13), f(17), f(21)];
                let q = [f(29), f(33), f(37), f(25)];
                if !(t.is_finite() && p.iter().chain(&q).all(|v| v.is_finite())) {
                    return self.bad("a pose record with a number that is not finite".into(), now);
                }
                self.origin_unix_s.get_or_insert(t);
                self.announced = Some((scan, t));
                self.outputs.push_back(ViewOutput::Pose(p, q));
            }
            other => self.bad(format!("a record of kind {other}"), now),
        }
    }

    fn start(&mut self, spec: ViewSpec, now: Duration) {
        self.counters.syncs += 1;
        if self.with_scene {
            if self.scene.is_some() {
                // The old view's entities go: the next message brings the new view.
                let t = Time::from_ns((self.unix(now) * 1e9) as u64);
                self.outputs.push_back(ViewOutput::Scene(SceneUpdate {
                    deletions: vec![Deletion {
                        timestamp: t,
                        kind: 1,
                        id: String::new(),
                    }],
                    entities: Vec::new(),
                }));
            }
            self.scene = Some(SceneBuilder::new(spec));
        } else {
            self.plain = Some(Receiver::new(spec));
        }
        // A resync's answer is the full message that follows.
        self.announced = None;
    }

    fn move_roi(&mut self, spec: ViewSpec, now: Duration) {
        let Some(old) = self.spec().copied() else {
            return self.bad("a spec record before any sync".into(), now);
        };
        if old.coarse_depth != spec.coarse_depth || old.resolution_m != spec.resolution_m {
            return self.bad(
                "a spec record that changes the resolution or coarse depth".into(),
                now,
            );
        }
        if let Some(s) = self.scene.as_mut() {
            s.set_roi(spec.roi);
        }
        if let Some(p) = self.plain.as_mut() {
            p.set_roi(spec.roi);
        }
    }

    fn message(&mut self, body: &[u8], now: Duration) {
        let Some(spec) = self.spec().copied() else {
            return self.bad("a message before any sync".into(), now);
        };
        let m = match delta::decode_message(&spec, body, 0) {
            Ok((m, n)) if n == body.len() => m,
            Ok(_) => return self.bad("a message record with bytes after it".into(), now),
            Err(e) => return self.bad(format!("a message record: {e}"), now),
        };
        let unix = self.unix(now);
        if let Some(s) = self.scene.as_mut() {
            let update = s.apply(&m, (unix * 1e9) as u64);
            self.outputs.push_back(ViewOutput::Scene(update));
        } else if let Some(p) = self.plain.as_mut() {
            p.apply(&m);
        }
        self.counters.messages += 1;
        let (scan, kind) = match &m {
            Message::Delta { scan, .. } => (*scan, "delta"),
            Message::Full { scan, .. } => (*scan, "full"),
            Message::Region { scan, .. } => (*scan, "region"),
        };
        let ready = match (kind, self.announced.take()) {
            ("delta", Some((s, t))) if s == scan => Some(t),
            _ => None,
        };
        let origin = self.origin_unix_s.unwrap_or(unix);
        let latency = ready.map_or(String::new(), |t| {
            format!(", shown {:.3} s after its cloud came", unix - t)
        });
        self.log(
            LogKind::Info,
            format!(
                "scan {scan}: {kind} of {} bytes applied{latency}",
                body.len()
            ),
        );
        self.rows.push(ShownRow {
            scan,
            kind,
            bytes: body.len(),
            t_ready_s: ready.map(|t| t - origin),
            t_shown_s: unix - origin,
            latency_s: ready.map(|t| unix - t),
        });
        if kind != "delta" {
            // The oldest request still waiting for such an answer has it now.
            let answers = |r: &RequestOutcome| {
                let t = r.request["type"].as_str().unwrap_or("");
                r.applied_s.is_none()
                    && r.replied_s.is_some()
                    && !r.refused
                    && (t == "full" || t == "roi" || t == "coarse_depth" || t == "resync")
            };
            if let Some(r) = self.requests.iter_mut().find(|r| answers(r)) {
                r.applied_s = Some(now.as_secs_f64());
                r.answer_bytes = Some(body.len());
                let id = r.id;
                self.log(
                    LogKind::Info,
                    format!("request {id} answered: its {kind} message applied"),
                );
            }
        }
    }
}
