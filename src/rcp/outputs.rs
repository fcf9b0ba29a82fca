//! What a session writes as it goes, and its summary: tdma-run's outputs as one [`Observer`].
//!
//! - `--events`: one CSV row per frame, `direction,kind,bytes,t_sent_s,t_received_s,fate`;
//! - `--track`: one CSV row per vehicle step ([`TRACK_HEADER`]; distances from the buoy);
//! - `--mcap`: the [`McapLog`];
//! - `--images-out`: every completed image as `image-NNNN.png`, each file whole (written
//!   aside and renamed), the directory created with the first; with `--preview`, the image in
//!   progress is written there too, as the file it will be, each time more of it has arrived
//!   (decoded from the trunks received without a gap), and the completed image replaces it;
//! - `--telemetry`: JSON Lines as things happen ([`Telemetry`]; docs/tdma-console.md lists
//!   every line), each line written and flushed at once so a reader of a pipe sees it live.
//!
//! Rows go through [`RowWriter`]: each one whole line in one write, so a run stopped by a
//! signal or a full disk leaves whole rows. The first write error is kept; from then on
//! [`Observer::failed`] is true (the session ends at its next event) and [`Recorder::finish`]
//! returns it.

use crate::geometry::distance_m;
use std::path::{Path, PathBuf};

use std::collections::BTreeMap;
use std::sync::{Arc, Condvar, Mutex};

use serde_json::{Map, Value};

use super::drive::DriveEvent;
use super::mcap_log::McapLog;
use super::report::{FrameEvent, Metrics, Observer};
use super::{Event, PoseSample, Role};
use crate::cli::UsageError;
use crate::cli::output::Dest;
use crate::cli::rows::{RowFormat, RowWriter};
use crate::io::{AtomicFile, Output};
use crate::wire::operator::Order;
use crate::wire::{Message, MessageRepr};

pub use super::report::EVENTS_HEADER;

/// The columns of `--track`.
pub const TRACK_HEADER: [&str; 14] = [
    "t_s",
    "x_m",
    "y_m",
    "z_m",
    "heading_deg",
    "distance_m",
    "goal_x_m",
    "goal_y_m",
    "goal_z_m",
    "goal_distance_m",
    "backtrack_x_m",
    "backtrack_y_m",
    "backtrack_z_m",
    "link_up",
];

/// Where the outputs go; each claimed by the caller before the session starts.
#[derive(Debug, Default)]
pub struct Destinations {
    /// `--events`.
    pub events: Option<Dest>,
    /// `--track`.
    pub track: Option<Dest>,
    /// `--mcap`.
    pub mcap: Option<Dest>,
    /// `--images-out`: a directory, created at the first image.
    pub images_out: Option<PathBuf>,
    /// `--telemetry`.
    pub telemetry: Option<Dest>,
    /// `--preview`: the image in progress written into `images_out` as it arrives.
    pub preview: bool,
}

/// The observer writing every output of a session.
pub struct Recorder {
    events: Option<RowWriter>,
    track: Option<RowWriter>,
    mcap: Option<McapLog>,
    images_out: Option<PathBuf>,
    images: u64,
    telemetry: Option<Telemetry>,
    preview: Option<Previewer>,
    /// The bytes of the image in progress last handed to the previewer.
    previewed: Option<usize>,
    buoy_m: [f64; 3],
    progress: indicatif::ProgressBar,
    error: Option<anyhow::Error>,
}

impl Recorder {
    /// Opens the outputs: the MCAP log starts at once (log times are `base_ns` plus the
    /// session's); CSV files appear with their first row. `progress` counts session seconds.
    pub fn new(
        dests: Destinations,
        buoy_m: [f64; 3],
        base_ns: u64,
        progress: indicatif::ProgressBar,
    ) -> anyhow::Result<Recorder> {
        let mcap = dests
            .mcap
            .as_ref()
            .map(|dest| McapLog::create(dest, base_ns))
            .transpose()?;
        let preview = (dests.preview && dests.images_out.is_some())
            .then(Previewer::start)
            .transpose()?;
        Ok(Recorder {
            events: dests
                .events
                .map(|dest| RowWriter::new(dest, RowFormat::Csv, &EVENTS_HEADER)),
            track: dests
                .track
                .map(|dest| RowWriter::new(dest, RowFormat::Csv, &TRACK_HEADER)),
            mcap,
            images_out: dests.images_out,
            images: 0,
            telemetry: dests.telemetry.map(Telemetry::new),
            preview,
            previewed: None,
            buoy_m,
            progress,
            error: None,
        })
    }

    fn keep(&mut self, outcome: Result<(), impl Into<anyhow::Error>>) {
        if let (Err(error), None) = (outcome, self.error.as_ref()) {
            self.error = Some(error.into());
        }
    }

    /// Completes every output (a CSV without rows gets its header, the MCAP its summary
    /// section); the first error wins.
    pub fn finish(mut self) -> anyhow::Result<()> {
        self.progress.finish_and_clear();
        let preview = self.preview.take().map(Previewer::finish);
        if let Some(error) = self.error.take() {
            return Err(error);
        }
        preview.transpose()?;
        let telemetry = self.telemetry.take().map(|t| t.rows);
        for rows in [self.events.take(), self.track.take(), telemetry]
            .into_iter()
            .flatten()
        {
            rows.finish()?;
        }
        if let Some(log) = self.mcap.take() {
            log.finish()?;
        }
        Ok(())
    }

    /// The file image number `n` is written to, with `--images-out`.
    fn image_path(&self, n: u64) -> Option<PathBuf> {
        let dir = self.images_out.as_ref()?;
        Some(dir.join(format!("image-{n:04}.png")))
    }

    /// With `--preview`: hands the image in progress to the previewer when more of it has
    /// arrived; the file its preview goes to.
    fn write_preview(&mut self, prefix: &[u8]) -> Option<PathBuf> {
        if prefix.is_empty() || self.error.is_some() {
            return None;
        }
        let (number, previewer) = (self.images + 1, self.preview.as_ref()?);
        let path = self.image_path(number)?;
        if self.previewed != Some(prefix.len()) {
            previewer.show(number, path.clone(), prefix);
            self.previewed = Some(prefix.len());
        }
        Some(path)
    }

    fn save_image(&self, path: &std::path::Path, stream: &[u8]) -> anyhow::Result<()> {
        let image = crate::debt::decode(stream)
            .map_err(|e| anyhow::anyhow!("image {}: {e}", self.images))?;
        let png = crate::debt::picture::to_png(&image)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        write_whole(path, &png)
    }
}

/// Writes a file whole (aside, then renamed), creating its directory.
pub(crate) fn write_whole(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|source| crate::io::IoError::Open {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    AtomicFile::create(path)?.commit_with(bytes)?;
    Ok(())
}

/// `--preview`'s writer: decodes and writes the image in progress in a thread of its own, so
/// a large picture (a 1920x1080 one takes ~0.1 s to decode and compress) never holds up the
/// session. Only the latest prefix waits: one the thread had no time for is replaced by the
/// next. A preview of an image already completed is never written over its whole file.
struct Previewer {
    shared: Arc<(Mutex<PreviewState>, Condvar)>,
    worker: Option<std::thread::JoinHandle<()>>,
}

#[derive(Default)]
struct PreviewState {
    /// The latest image in progress to write: its number, its file, its bytes so far.
    pending: Option<(u64, PathBuf, Vec<u8>)>,
    /// Images completed so far: their previews are not written any more.
    completed: u64,
    /// The first write error.
    error: Option<anyhow::Error>,
    /// No more previews: the thread writes what is pending and ends.
    closing: bool,
}

impl Previewer {
    fn start() -> anyhow::Result<Previewer> {
        let shared = Arc::new((Mutex::new(PreviewState::default()), Condvar::new()));
        let theirs = Arc::clone(&shared);
        let worker = std::thread::Builder::new()
            .name("preview".into())
            .spawn(move || preview_worker(&theirs))
            .map_err(|e| anyhow::anyhow!("--preview: cannot start its thread: {e}"))?;
        Ok(Previewer {
            shared,
            worker: Some(worker),
        })
    }

    fn state(&self) -> std::sync::MutexGuard<'_, PreviewState> {
        self.shared.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Image `number` so far (`prefix`) is to be written to `path`.
    fn show(&self, number: u64, path: PathBuf, prefix: &[u8]) {
        self.state().pending = Some((number, path, prefix.to_vec()));
        self.shared.1.notify_one();
    }

    /// Image `number` is complete (its whole file is written next): waits for a preview being
    /// written, and writes none of it after.
    fn completed(&self, number: u64) {
        let mut state = self.state();
        state.completed = state.completed.max(number);
        if state.pending.as_ref().is_some_and(|(n, _, _)| *n <= number) {
            state.pending = None;
        }
    }

    fn failed(&self) -> bool {
        self.state().error.is_some()
    }

    /// Writes what is pending, ends the thread; the first write error.
    fn finish(mut self) -> anyhow::Result<()> {
        self.close();
        if let Some(worker) = self.worker.take() {
            let _ = worker.join();
        }
        self.state().error.take().map_or(Ok(()), Err)
    }

    fn close(&self) {
        self.state().closing = true;
        self.shared.1.notify_one();
    }
}

impl Drop for Previewer {
    fn drop(&mut self) {
        self.close();
    }
}

fn preview_worker(shared: &(Mutex<PreviewState>, Condvar)) {
    let (lock, wake) = shared;
    let state = || lock.lock().unwrap_or_else(|e| e.into_inner());
    loop {
        let (number, path, prefix) = {
            let mut held = state();
            while held.pending.is_none() && !held.closing {
                held = wake.wait(held).unwrap_or_else(|e| e.into_inner());
            }
            match held.pending.take() {
                Some(job) => job,
                None => return,
            }
        };
        // A prefix short of the stream's header is no picture yet.
        let Some(png) = crate::debt::decode(&prefix)
            .ok()
            .and_then(|image| crate::debt::picture::to_png(&image).ok())
        else {
            continue;
        };
        let mut held = state();
        if number > held.completed
            && held.error.is_none()
            && let Err(error) = write_whole(&path, &png)
        {
            held.error = Some(error);
        }
    }
}

/// A point's three CSV fields, empty when there is none.
fn point(p: Option<[f64; 3]>) -> [String; 3] {
    p.map_or_else(Default::default, |p| p.map(|v| format!("{v:.4}")))
}

/// A frame's `--events` fields ([`EVENTS_HEADER`]).
pub(crate) fn event_fields(e: &FrameEvent<'_>) -> [String; 12] {
    let time = |t: Option<f64>| t.map_or(String::new(), |t| format!("{t:.6}"));
    let address = |a: Option<u8>| a.map_or(String::new(), |a| a.to_string());
    [
        e.direction.to_string(),
        e.kind.to_string(),
        e.bytes.to_string(),
        time(e.t_sent_s),
        time(e.t_received_s),
        e.fate.to_string(),
        e.medium.to_string(),
        address(e.src),
        address(e.dst),
        address(e.tx),
        address(e.rx),
        e.action.to_string(),
    ]
}

impl Observer for Recorder {
    fn frame(&mut self, e: &FrameEvent<'_>) {
        let t = e.t_received_s.or(e.t_sent_s).unwrap_or(0.0);
        self.progress.set_position(t as u64);
        if let Some(log) = self.mcap.as_mut() {
            log.frame(e);
        }
        if self.error.is_some() {
            return;
        }
        if let Some(out) = self.events.as_mut() {
            let outcome = out.row(&event_fields(e));
            self.keep(outcome);
        }
    }

    fn image(&mut self, _vehicle: u8, t_s: f64, stream: &[u8]) {
        self.images += 1;
        self.previewed = None;
        if let Some(previewer) = &self.preview {
            previewer.completed(self.images);
        }
        if let Some(log) = self.mcap.as_mut() {
            log.image(t_s, stream);
        }
        let mut file = None;
        if let (Some(path), None) = (self.image_path(self.images), self.error.as_ref()) {
            let saved = self.save_image(&path, stream);
            file = saved.is_ok().then_some(path);
            self.keep(saved);
        }
        if let (Some(telemetry), None) = (self.telemetry.as_mut(), self.error.as_ref()) {
            let outcome = telemetry.image_complete(t_s, file.as_deref());
            self.keep(outcome);
        }
    }

    fn event(&mut self, _vehicle: u8, end: Role, t_s: f64, event: &Event) {
        let file = match event {
            Event::ImageProgress { prefix, .. } => self.write_preview(prefix),
            _ => None,
        };
        if let (Some(telemetry), None) = (self.telemetry.as_mut(), self.error.as_ref()) {
            let outcome = telemetry.event(end, t_s, event, file.as_deref());
            self.keep(outcome);
        }
    }

    fn warning(&mut self, t_s: f64, text: &str) {
        if let (Some(telemetry), None) = (self.telemetry.as_mut(), self.error.as_ref()) {
            let mut line = telemetry.line("warning", t_s, Role::Operator);
            line.insert("text".into(), text.into());
            let outcome = telemetry.write(line);
            self.keep(outcome);
        }
    }

    fn pose(&mut self, _vehicle: u8, pose: &PoseSample) {
        if let Some(log) = self.mcap.as_mut() {
            log.pose(pose);
        }
        let (Some(out), None) = (self.track.as_mut(), self.error.as_ref()) else {
            return;
        };
        let [x, y, z] = pose.position_m.map(|v| format!("{v:.4}"));
        let [gx, gy, gz] = point(pose.goal_m);
        let [bx, by, bz] = point(pose.backtrack_m);
        let row = [
            format!("{:.3}", pose.t_s),
            x,
            y,
            z,
            format!("{:.2}", pose.heading_deg),
            format!("{:.4}", distance_m(pose.position_m, self.buoy_m)),
            gx,
            gy,
            gz,
            pose.goal_m.map_or(String::new(), |g| {
                format!("{:.4}", distance_m(g, self.buoy_m))
            }),
            bx,
            by,
            bz,
            u8::from(pose.link_up).to_string(),
        ];
        let outcome = out.row(&row);
        self.keep(outcome);
    }

    fn failed(&self) -> bool {
        self.error.is_some()
            || self.mcap.as_ref().is_some_and(McapLog::failed)
            || self.preview.as_ref().is_some_and(Previewer::failed)
    }
}

/// Seconds between two telemetry lines for the same camera failure.
pub const CAMERA_REPEAT_S: f64 = 10.0;

/// The most orders remembered between their sending and their acknowledgement (to show the
/// order again when it is acknowledged).
const REMEMBERED_ORDERS: usize = 64;

/// `--telemetry`: one JSON object a line for each thing that happens, each with `type`,
/// `t_s` (session seconds) and `end` (`operator` or `rov`); see docs/tdma-console.md.
pub struct Telemetry {
    rows: RowWriter,
    /// Orders sent and not yet acknowledged, by number.
    sent: BTreeMap<u64, Order>,
    /// The last image progress: trunks received, trunks in all.
    progress: (usize, Option<usize>),
    /// The camera failure last written, when, and how many times it came again since.
    camera: Option<(String, f64, u64)>,
    /// In a multi-vehicle scenario: the vehicle the next lines are about.
    vehicle: Option<u8>,
    /// The other vehicles' `sent`, `progress` and `camera`, while one is current.
    others: BTreeMap<u8, VehicleLines>,
}

/// What [`Telemetry`] remembers of one vehicle's session between lines.
#[derive(Default)]
pub(crate) struct VehicleLines {
    sent: BTreeMap<u64, Order>,
    progress: (usize, Option<usize>),
    camera: Option<(String, f64, u64)>,
}

/// Session seconds as written: to the microsecond.
fn seconds(t_s: f64) -> Value {
    Value::from((t_s * 1e6).round() / 1e6)
}

/// An order in wire.md's JSON form (the `order` object of an operator message).
pub fn order_json(order: &Order) -> Value {
    let repr = MessageRepr {
        src: 0,
        dst: 0,
        message: Message::Operator(crate::wire::operator::Repr {
            oid: false,
            clo: false,
            eisn: false,
            ic: false,
            rit: 0,
            order: *order,
        }),
    };
    let mut fields = Map::new();
    crate::wire::json::write_fields(&repr, &mut fields);
    fields.remove("order").unwrap_or(Value::Null)
}

fn path_json(path: Option<&Path>) -> Value {
    path.map_or(Value::Null, |p| p.display().to_string().into())
}

impl Telemetry {
    /// Telemetry lines to `dest`; nothing is created until the first line.
    pub fn new(dest: Dest) -> Telemetry {
        Telemetry {
            rows: RowWriter::new(dest, RowFormat::Ndjson, &[]),
            sent: BTreeMap::new(),
            progress: (0, None),
            camera: None,
            vehicle: None,
            others: BTreeMap::new(),
        }
    }

    /// In a multi-vehicle scenario: every line from now on carries `"vehicle": address`, and
    /// is about that vehicle's orders and image.
    pub(crate) fn set_vehicle(&mut self, address: u8) {
        if self.vehicle == Some(address) {
            return;
        }
        let current = VehicleLines {
            sent: std::mem::take(&mut self.sent),
            progress: std::mem::take(&mut self.progress),
            camera: self.camera.take(),
        };
        if let Some(old) = self.vehicle {
            self.others.insert(old, current);
        }
        let next = self.others.remove(&address).unwrap_or_default();
        (self.sent, self.progress, self.camera) = (next.sent, next.progress, next.camera);
        self.vehicle = Some(address);
    }

    /// Completes the output (see [`RowWriter::finish`]).
    pub(crate) fn finish(self) -> Result<(), crate::io::IoError> {
        self.rows.finish()
    }

    /// A line's first fields.
    pub(crate) fn line(&self, kind: &str, t_s: f64, end: Role) -> Map<String, Value> {
        let mut line = Map::new();
        line.insert("type".into(), kind.into());
        line.insert("t_s".into(), seconds(t_s));
        line.insert("end".into(), end.name().into());
        if let Some(vehicle) = self.vehicle {
            line.insert("vehicle".into(), vehicle.into());
        }
        line
    }

    pub(crate) fn write(&mut self, line: Map<String, Value>) -> Result<(), crate::io::IoError> {
        self.rows.row(&Value::Object(line))
    }

    /// A line of `kind` with its `state` and further fields.
    fn state(
        &mut self,
        kind: &str,
        t_s: f64,
        end: Role,
        state: &str,
        fields: impl IntoIterator<Item = (&'static str, Value)>,
    ) -> Result<(), crate::io::IoError> {
        let mut line = self.line(kind, t_s, end);
        line.insert("state".into(), state.into());
        for (key, value) in fields {
            line.insert(key.into(), value);
        }
        self.write(line)
    }

    /// The image just completed, written to `file` (none without `--images-out`).
    pub(crate) fn image_complete(
        &mut self,
        t_s: f64,
        file: Option<&Path>,
    ) -> Result<(), crate::io::IoError> {
        let (trunks, of) = std::mem::take(&mut self.progress);
        let of = of
            .or((trunks > 0).then_some(trunks))
            .map_or(Value::Null, Value::from);
        let fields = [
            ("trunks", of.clone()),
            ("of", of),
            ("file", path_json(file)),
        ];
        self.state("image", t_s, Role::Operator, "complete", fields)
    }

    /// The line for `event` of `end`, if it has one; `file` is the preview written for an
    /// image in progress.
    pub(crate) fn event(
        &mut self,
        end: Role,
        t_s: f64,
        event: &Event,
        file: Option<&Path>,
    ) -> Result<(), crate::io::IoError> {
        match event {
            Event::Status(repr) => {
                let mut line = self.line("rov", t_s, end);
                crate::wire::json::write_fields(repr, &mut line);
                line.shift_remove("trunk");
                self.write(line)
            }
            Event::OrderSent { index, order } => {
                if self.sent.len() >= REMEMBERED_ORDERS {
                    self.sent.pop_first();
                }
                self.sent.insert(*index, *order);
                let fields = [("index", (*index).into()), ("order", order_json(order))];
                self.state("order", t_s, end, "sent", fields)
            }
            Event::OrderAcknowledged(index) => {
                let order = self.sent.remove(index);
                let fields = [
                    ("index", (*index).into()),
                    ("order", order.as_ref().map_or(Value::Null, order_json)),
                ];
                self.state("order", t_s, end, "acknowledged", fields)
            }
            Event::OrderExecuted(order) => self.state(
                "order",
                t_s,
                end,
                "executed",
                [("order", order_json(order))],
            ),
            Event::CancelConfirmed | Event::OrderCancelled => {
                self.state("order", t_s, end, "cancelled", [])
            }
            Event::ImageProgress { trunks, of, .. } => {
                self.progress = (*trunks, *of);
                let fields = [
                    ("trunks", (*trunks).into()),
                    ("of", of.map_or(Value::Null, Value::from)),
                    ("file", path_json(file)),
                ];
                self.state("image", t_s, end, "progress", fields)
            }
            Event::ImageStarted { trunks, bytes } => {
                self.camera = None;
                let fields = [("trunks", (*trunks).into()), ("bytes", (*bytes).into())];
                self.state("image", t_s, end, "started", fields)
            }
            Event::ImageCancelled => self.state("image", t_s, end, "cancelled", []),
            // Written by [`Observer::image`], which knows the file.
            Event::ImageCompleted(_) => Ok(()),
            Event::AnswersLost | Event::LinkLost => self.state("link", t_s, end, "lost", []),
            Event::AnswersBack | Event::LinkRecovered => {
                self.state("link", t_s, end, "recovered", [])
            }
            Event::Vehicle(drive) => self.vehicle(end, t_s, drive),
            Event::CameraFailed(error) => self.camera_failed(end, t_s, error),
        }
    }

    fn vehicle(
        &mut self,
        end: Role,
        t_s: f64,
        event: &DriveEvent,
    ) -> Result<(), crate::io::IoError> {
        match event {
            DriveEvent::Silent { silent_s } => self.state(
                "vehicle",
                t_s,
                end,
                "silent",
                [("silent_s", seconds(*silent_s))],
            ),
            DriveEvent::Heard => self.state("vehicle", t_s, end, "heard", []),
            DriveEvent::CommandAck {
                command,
                result,
                accepted,
            } => {
                let fields = [
                    ("command", command.as_str().into()),
                    ("result", result.as_str().into()),
                    ("accepted", (*accepted).into()),
                ];
                self.state("vehicle", t_s, end, "command_ack", fields)
            }
            DriveEvent::Refused { why, reason } => {
                let fields = [
                    ("why", why.to_string().into()),
                    ("reason", reason.as_str().into()),
                ];
                self.state("vehicle", t_s, end, "refused", fields)
            }
            DriveEvent::Note(text) => self.state(
                "vehicle",
                t_s,
                end,
                "note",
                [("text", text.as_str().into())],
            ),
        }
    }

    /// A camera failure: written when it is new, then at most every [`CAMERA_REPEAT_S`] with
    /// how many times it came again meanwhile (a failing camera fails at every slot).
    fn camera_failed(
        &mut self,
        end: Role,
        t_s: f64,
        error: &str,
    ) -> Result<(), crate::io::IoError> {
        let repeated = match &mut self.camera {
            Some((last, at_s, count)) if last == error => {
                *count += 1;
                if t_s - *at_s < CAMERA_REPEAT_S {
                    return Ok(());
                }
                *count
            }
            _ => 0,
        };
        self.camera = Some((error.to_string(), t_s, 0));
        let fields = [("error", error.into()), ("repeated", repeated.into())];
        self.state("camera", t_s, end, "failed", fields)
    }
}

/// Writes `metrics` as one line of JSON to `out` with the run's parameters and `seed`
/// ([`crate::cli::metrics`]) and flushes it; the caller commits it
/// ([`Output::finish`]) once every other output is complete. `out` is opened before the run
/// (a file aside, renamed on commit), so an output that cannot be created fails before any
/// work and a failed run leaves no metrics file.
pub fn write_metrics(
    out: &mut Output,
    seed: u64,
    metrics: &impl serde::Serialize,
) -> Result<(), crate::io::IoError> {
    crate::cli::metrics::write(out, "tdma-run", Some(seed), metrics)
}

/// Checks that the pictures `--images-out` would write into `dir` (`image-NNNN.png`) are none
/// of `inputs` (files, or directories standing for the files in them), through links too: an
/// input is never overwritten. A directory that does not exist yet holds no input.
pub fn check_images_out<'a>(
    dir: &Path,
    inputs: impl IntoIterator<Item = &'a Path>,
) -> Result<(), UsageError> {
    use std::os::unix::fs::MetadataExt;
    let identity = |path: &Path| std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()));
    let files_of = |path: &Path| -> Vec<PathBuf> {
        match std::fs::read_dir(path) {
            Ok(entries) => entries.flatten().map(|e| e.path()).collect(),
            Err(_) => vec![path.to_path_buf()],
        }
    };
    let mut taken = Vec::new();
    for input in inputs {
        for file in files_of(input) {
            if let Some(id) = identity(&file) {
                taken.push((id, file));
            }
        }
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    for path in entries.flatten().map(|e| e.path()) {
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        let ours = name.is_some_and(|n| n.starts_with("image-") && n.ends_with(".png"));
        let Some(id) = identity(&path).filter(|_| ours) else {
            continue;
        };
        if let Some((_, input)) = taken.iter().find(|(i, _)| *i == id) {
            return Err(UsageError(format!(
                "--images-out: {} is the input {}: refusing to overwrite an input",
                path.display(),
                input.display()
            )));
        }
    }
    Ok(())
}

/// The base of real-time log times: the wall clock now, ns since the Unix epoch.
pub fn wall_clock_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(0))
}

/// Table 4's rows for both directions, then the counters: the lines of the summary on stderr
/// (one end's half in real time).
pub fn summary(metrics: &Metrics) -> Vec<String> {
    let mut lines = Vec::new();
    if metrics.measured_by == "simulation" {
        let (r, o) = (&metrics.rov_to_operator, &metrics.operator_to_rov);
        let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
        let mut row = |name: &str, a: String, b: String| {
            lines.push(format!("{name:<18} {a:>10} {b:>10}"));
        };
        row("", "ROV->op".into(), "op->ROV".into());
        row(
            "throughput kbit/s",
            format!("{:.3}", r.throughput_kbps),
            format!("{:.3}", o.throughput_kbps),
        );
        row("delay ms", ms(r.delay_ms), ms(o.delay_ms));
        row("jitter ms", ms(r.jitter_ms), ms(o.jitter_ms));
        row(
            "IAT ms",
            format!("{:.2}", r.iat_ms),
            format!("{:.2}", o.iat_ms),
        );
        row(
            "IAT sigma ms",
            format!("{:.2}", r.iat_sigma_ms),
            format!("{:.2}", o.iat_sigma_ms),
        );
        row(
            "frames sent",
            r.frames_sent.to_string(),
            o.frames_sent.to_string(),
        );
        row(
            "frames delivered",
            r.frames_delivered.to_string(),
            o.frames_delivered.to_string(),
        );
    } else {
        half(metrics, &mut lines);
    }
    lines.push(counters(metrics));
    lines
}

/// One end's figures in real time: what it sent, what it received.
fn half(metrics: &Metrics, lines: &mut Vec<String>) {
    let (sent, received, sent_name, received_name) = if metrics.measured_by == "operator" {
        (
            &metrics.operator_to_rov,
            &metrics.rov_to_operator,
            "op->ROV",
            "ROV->op",
        )
    } else {
        (
            &metrics.rov_to_operator,
            &metrics.operator_to_rov,
            "ROV->op",
            "op->ROV",
        )
    };
    lines.push(format!(
        "sent {sent_name}: {} frames; received {received_name}: {} frames, {:.3} kbit/s, IAT {:.2} ms (sigma {:.2} ms)",
        sent.frames_sent,
        received.frames_delivered,
        received.throughput_kbps,
        received.iat_ms,
        received.iat_sigma_ms
    ));
    if let (Some(rtt), Some(jitter)) = (metrics.round_trip_ms, metrics.round_trip_jitter_ms) {
        lines.push(format!(
            "round trip slot -> answer {rtt:.2} ms (sigma {jitter:.2} ms)"
        ));
    }
}

/// Images, orders and link recovery.
fn counters(metrics: &Metrics) -> String {
    let period = metrics
        .image_period_s
        .map_or("-".into(), |p| format!("{p:.1} s"));
    match metrics.measured_by {
        "operator" => format!(
            "images completed {} (one every {period}); orders sent {}, acknowledged {}",
            metrics.images_completed, metrics.orders_sent, metrics.orders_acknowledged
        ),
        "rov" => format!(
            "images started {}; orders executed {}; link lost {} times, recovered {}",
            metrics.images_started,
            metrics.orders_executed,
            metrics.link_losses,
            metrics.link_recoveries
        ),
        _ => format!(
            "images completed {} of {} started (one every {period}); orders sent {}, acknowledged {}, executed {}, executed twice {}; link lost {} times, recovered {}",
            metrics.images_completed,
            metrics.images_started,
            metrics.orders_sent,
            metrics.orders_acknowledged,
            metrics.orders_executed,
            metrics.orders_executed_twice,
            metrics.link_losses,
            metrics.link_recoveries
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rcp::drive::DriveEvent;
    use crate::rcp::{ImageSettings, test_image, trunks_of};

    const STATUS: &str = r#"{"type":"rov","src":1,"dst":0,"ft":true,"lt":false,"st":0,"isn":1,"ci":false,"itsn":0,"rd":true,"eoid":1,"loc":false,"hh":true,"arm":true,"nav":"guided","x_cm":-250,"y_cm":1200,"z_cm":455,"roll_deg":359,"pitch_deg":1,"yaw_deg":180,"trunk":"00010203"}"#;

    const GOTO: Order = Order::GoTo {
        x_cm: 300,
        y_cm: 0,
        z_cm: 50,
        heading_deg: 90,
    };

    fn recorder(dests: Destinations) -> Recorder {
        Recorder::new(dests, [0.0; 3], 0, indicatif::ProgressBar::hidden()).unwrap()
    }

    fn lines(path: &Path) -> Vec<Value> {
        std::fs::read_to_string(path)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    }

    /// An image's DEBT stream, as the ROV cuts it into trunks.
    fn trunks() -> Vec<Vec<u8>> {
        trunks_of(&test_image(64, 48, 1), &ImageSettings::default())
    }

    #[test]
    fn telemetry_has_a_line_for_each_thing_as_it_happens() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.jsonl");
        let mut rec = recorder(Destinations {
            telemetry: Some(Dest::File(path.clone())),
            ..Destinations::default()
        });
        let (op, rov) = (Role::Operator, Role::Rov);
        let status = crate::wire::json::parse_line(STATUS).unwrap();
        rec.event(1, op, 1.5, &Event::Status(status));
        // Each line is in the file as soon as it happened.
        assert_eq!(lines(&path).len(), 1);
        rec.event(
            1,
            op,
            2.0,
            &Event::OrderSent {
                index: 3,
                order: GOTO,
            },
        );
        rec.event(1, op, 2.5, &Event::OrderAcknowledged(3));
        rec.event(1, op, 3.0, &Event::CancelConfirmed);
        rec.event(1, rov, 3.0, &Event::OrderExecuted(GOTO));
        let stream: Vec<u8> = trunks().concat();
        let progress = Event::ImageProgress {
            trunks: 2,
            of: None,
            prefix: stream[..78].to_vec(),
        };
        rec.event(1, op, 4.0, &progress);
        rec.event(1, op, 5.0, &Event::ImageCompleted(stream.clone()));
        rec.image(1, 5.0, &stream);
        rec.event(1, op, 6.0, &Event::AnswersLost);
        rec.event(1, rov, 6.5, &Event::LinkLost);
        rec.event(1, rov, 7.0, &Event::LinkRecovered);
        rec.event(
            1,
            rov,
            7.0,
            &Event::Vehicle(DriveEvent::Silent { silent_s: 3.0 }),
        );
        let ack = DriveEvent::CommandAck {
            command: "MAV_CMD_COMPONENT_ARM_DISARM".into(),
            result: "MAV_RESULT_DENIED".into(),
            accepted: false,
        };
        rec.event(1, rov, 7.5, &Event::Vehicle(ack));
        for k in 0..5 {
            rec.event(
                1,
                rov,
                8.0 + f64::from(k),
                &Event::CameraFailed("no picture".into()),
            );
        }
        rec.event(1, rov, 18.5, &Event::CameraFailed("no picture".into()));
        rec.warning(19.0, "o.jsonl: line 2: not valid JSON at column 1: x");
        assert!(!rec.failed());
        rec.finish().unwrap();

        let got = lines(&path);
        let expected = [
            r#"{"type":"rov","t_s":1.5,"end":"operator","src":1,"dst":0,"ft":true,"lt":false,"st":0,"isn":1,"ci":false,"itsn":0,"rd":true,"eoid":1,"loc":false,"hh":true,"arm":true,"nav":"guided","x_cm":-250,"y_cm":1200,"z_cm":455,"roll_deg":359,"pitch_deg":1,"yaw_deg":180}"#,
            r#"{"type":"order","t_s":2.0,"end":"operator","state":"sent","index":3,"order":{"type":"goto","x_cm":300,"y_cm":0,"z_cm":50,"heading_deg":90}}"#,
            r#"{"type":"order","t_s":2.5,"end":"operator","state":"acknowledged","index":3,"order":{"type":"goto","x_cm":300,"y_cm":0,"z_cm":50,"heading_deg":90}}"#,
            r#"{"type":"order","t_s":3.0,"end":"operator","state":"cancelled"}"#,
            r#"{"type":"order","t_s":3.0,"end":"rov","state":"executed","order":{"type":"goto","x_cm":300,"y_cm":0,"z_cm":50,"heading_deg":90}}"#,
            r#"{"type":"image","t_s":4.0,"end":"operator","state":"progress","trunks":2,"of":null,"file":null}"#,
            r#"{"type":"image","t_s":5.0,"end":"operator","state":"complete","trunks":2,"of":2,"file":null}"#,
            r#"{"type":"link","t_s":6.0,"end":"operator","state":"lost"}"#,
            r#"{"type":"link","t_s":6.5,"end":"rov","state":"lost"}"#,
            r#"{"type":"link","t_s":7.0,"end":"rov","state":"recovered"}"#,
            r#"{"type":"vehicle","t_s":7.0,"end":"rov","state":"silent","silent_s":3.0}"#,
            r#"{"type":"vehicle","t_s":7.5,"end":"rov","state":"command_ack","command":"MAV_CMD_COMPONENT_ARM_DISARM","result":"MAV_RESULT_DENIED","accepted":false}"#,
            r#"{"type":"camera","t_s":8.0,"end":"rov","state":"failed","error":"no picture","repeated":0}"#,
            r#"{"type":"camera","t_s":18.5,"end":"rov","state":"failed","error":"no picture","repeated":5}"#,
            r#"{"type":"warning","t_s":19.0,"end":"operator","text":"o.jsonl: line 2: not valid JSON at column 1: x"}"#,
        ];
        let text = std::fs::read_to_string(&path).unwrap();
        for (line, want) in text.lines().zip(expected) {
            assert_eq!(line, want);
        }
        assert_eq!(got.len(), expected.len(), "{text}");
    }

    /// Waits until `path` holds `bytes` (the previewer writes in its own thread), or 10 s.
    fn wait_for(path: &Path, bytes: &[u8]) -> bool {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while std::time::Instant::now() < deadline {
            if std::fs::read(path).is_ok_and(|b| b == bytes) {
                return true;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        false
    }

    fn png_of(stream: &[u8]) -> Vec<u8> {
        crate::debt::picture::to_png(&crate::debt::decode(stream).unwrap()).unwrap()
    }

    #[test]
    fn preview_writes_the_image_in_progress_as_the_file_it_will_be() {
        let dir = tempfile::tempdir().unwrap();
        let (out, telemetry) = (dir.path().join("rx"), dir.path().join("t.jsonl"));
        let mut rec = recorder(Destinations {
            images_out: Some(out.clone()),
            preview: true,
            telemetry: Some(Dest::File(telemetry.clone())),
            ..Destinations::default()
        });
        let trunks = trunks();
        let stream = trunks.concat();
        let first = out.join("image-0001.png");
        let mut prefix = Vec::new();
        let mut previews = Vec::new();
        for (k, trunk) in trunks.iter().enumerate() {
            prefix.extend_from_slice(trunk);
            let of = (k + 1 == trunks.len()).then_some(trunks.len());
            let event = Event::ImageProgress {
                trunks: k + 1,
                of,
                prefix: prefix.clone(),
            };
            rec.event(1, Role::Operator, k as f64, &event);
            let expected = png_of(&prefix);
            assert!(wait_for(&first, &expected), "preview {k} not written");
            previews.push(expected);
        }
        // The picture changed as trunks arrived (it sharpened).
        assert!(previews.windows(2).filter(|w| w[0] != w[1]).count() >= previews.len() / 2);
        rec.image(1, 21.0, &stream);
        assert_eq!(std::fs::read(&first).unwrap(), png_of(&stream));
        let gap = Event::ImageProgress {
            trunks: 1,
            of: None,
            prefix: Vec::new(),
        };
        rec.event(1, Role::Operator, 22.0, &gap);
        let next = Event::ImageProgress {
            trunks: 1,
            of: None,
            prefix: trunks[0].clone(),
        };
        rec.event(1, Role::Operator, 23.0, &next);
        rec.finish().unwrap();
        // Finishing writes the preview still pending: the image in flight stays as it was.
        assert_eq!(
            std::fs::read(out.join("image-0002.png")).unwrap(),
            png_of(&trunks[0])
        );
        let got = lines(&telemetry);
        let file = |v: &Value| v["file"].as_str().map(str::to_string);
        assert_eq!(file(&got[0]), Some(first.display().to_string()));
        let complete = got.iter().find(|l| l["state"] == "complete").unwrap();
        assert_eq!(file(complete), Some(first.display().to_string()));
        assert_eq!(complete["of"], trunks.len());
        assert_eq!(
            got.last().unwrap()["file"],
            out.join("image-0002.png").display().to_string()
        );
        assert_eq!(got[got.len() - 2]["file"], Value::Null);
    }

    #[test]
    fn a_preview_never_overwrites_the_completed_image() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("rx");
        let mut rec = recorder(Destinations {
            images_out: Some(out.clone()),
            preview: true,
            ..Destinations::default()
        });
        // A picture large enough that its preview takes a while to decode and compress.
        let trunks = trunks_of(&test_image(320, 240, 1), &ImageSettings::default());
        let stream = trunks.concat();
        for n in 1..=5u32 {
            // The last trunks arrive and the image completes at once, while its preview may
            // still be in the writer's hands.
            for k in [trunks.len() - 2, trunks.len() - 1] {
                let event = Event::ImageProgress {
                    trunks: k,
                    of: None,
                    prefix: trunks[..k].concat(),
                };
                rec.event(1, Role::Operator, f64::from(n), &event);
            }
            // The writer has taken the last preview and is at work on it.
            std::thread::sleep(std::time::Duration::from_millis(2));
            rec.image(1, f64::from(n), &stream);
        }
        rec.finish().unwrap();
        let whole = png_of(&stream);
        for n in 1..=5 {
            let file = out.join(format!("image-{n:04}.png"));
            assert_eq!(std::fs::read(&file).unwrap(), whole, "{}", file.display());
        }
        assert_eq!(std::fs::read_dir(&out).unwrap().count(), 5);
    }

    #[test]
    fn a_telemetry_write_error_is_kept_and_fails_the_run() {
        let mut rec = recorder(Destinations {
            telemetry: Some(Dest::File("/dev/full".into())),
            ..Destinations::default()
        });
        rec.event(1, Role::Operator, 1.0, &Event::AnswersLost);
        assert!(rec.failed());
        let error = rec.finish().unwrap_err().to_string();
        assert!(error.starts_with("/dev/full"), "{error}");
    }
}
