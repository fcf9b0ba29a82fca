//! What a session writes as it goes, and its summary: tdma-run's outputs as one [`Observer`],
//! the [`Recorder`], for every kind of session: a single vehicle's or a network's
//! ([`Layout`]).
//!
//! - `--events`: one CSV row per frame and receiver ([`EVENTS_HEADER`], the same in every
//!   session): the medium, the frame's SRC and DST, the node that transmitted this copy and the
//!   node that heard it, the fate there and what that node's router did;
//! - `--track`: one CSV row per vehicle step: a single session's [`TRACK_HEADER`] (distances
//!   from the buoy, goal, backtrack point), a network's [`NET_TRACK_HEADER`] (the vehicle's
//!   address first);
//! - `--mcap`: a single session's [`McapLog`], a network's [`NetMcapLog`] (each vehicle's
//!   channels, every frame at every receiver);
//! - `--images-out DIR`: every completed image as `DIR/image-NNNN.png` (a network's as
//!   `DIR/vehicle-N/image-NNNN.png`), each file whole (written aside and renamed), the
//!   directory created with the first; with `--preview` (a single session), the image in
//!   progress is written there too, as the file it will be, each time more of it has arrived
//!   (decoded from the trunks received without a gap), and the completed image replaces it;
//! - `--telemetry`: JSON Lines as things happen ([`Telemetry`]; docs/tdma-console.md lists
//!   every line; a network's each with `"vehicle": N`), each line written and flushed at once
//!   so a reader of a pipe sees it live.
//!
//! Rows go through [`RowWriter`]: each one whole line in one write, so a run stopped by a
//! signal or a full disk leaves whole rows. The first write error is kept; from then on
//! [`Observer::failed`] is true (the session ends at its next event) and [`Recorder::finish`]
//! returns it.

mod preview;
mod summary;
mod telemetry;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use preview::Previewer;
use rovlink_base::geometry::distance_m;
use rovlink_base::io::AtomicFile;
use rovlink_base::output::Dest;
use rovlink_cli::rows::{RowFormat, RowWriter};
use rovlink_field::mcap_log::McapLog;
use rovlink_field::net_mcap::NetMcapLog;
use rovlink_rcp::report::{FrameEvent, Observer};
use rovlink_rcp::{Event, PoseSample, Role};

pub use rovlink_rcp::report::EVENTS_HEADER;
pub use summary::{check_images_out, summary, wall_clock_ns, write_metrics};
pub use telemetry::Telemetry;

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

/// The columns of `--track` in a network.
pub const NET_TRACK_HEADER: [&str; 7] = [
    "vehicle",
    "t_s",
    "x_m",
    "y_m",
    "z_m",
    "heading_deg",
    "link_up",
];

/// The shape of a session's outputs.
#[derive(Debug, Clone, PartialEq)]
pub enum Layout {
    /// One vehicle: [`TRACK_HEADER`] with distances from the buoy at `buoy_m`, images as
    /// `image-NNNN.png`, the [`McapLog`] with log times `base_ns` plus the session's, telemetry
    /// lines without a vehicle, `--preview` honoured.
    Single {
        /// The buoy (the operator's modem), NED m.
        buoy_m: [f64; 3],
        /// The MCAP log's time base, ns (0 in simulation, the wall clock in real time).
        base_ns: u64,
    },
    /// A network of these vehicles: [`NET_TRACK_HEADER`], images as
    /// `vehicle-N/image-NNNN.png`, the [`NetMcapLog`], telemetry lines with `"vehicle": N`.
    Network {
        /// The vehicles' addresses.
        vehicles: Vec<u8>,
    },
}

/// The MCAP log of the layout.
enum Log {
    Single(McapLog),
    Network(NetMcapLog),
}

impl Log {
    fn failed(&self) -> bool {
        match self {
            Log::Single(log) => log.failed(),
            Log::Network(log) => log.failed(),
        }
    }

    fn finish(self) -> anyhow::Result<()> {
        match self {
            Log::Single(log) => log.finish()?,
            Log::Network(log) => log.finish()?,
        }
        Ok(())
    }
}

/// The observer writing every output of a session.
pub struct Recorder {
    events: Option<RowWriter>,
    track: Option<RowWriter>,
    mcap: Option<Log>,
    images_out: Option<PathBuf>,
    /// Images completed, per vehicle.
    images: BTreeMap<u8, u64>,
    telemetry: Option<Telemetry>,
    preview: Option<Previewer>,
    /// The bytes of the image in progress last handed to the previewer.
    previewed: Option<usize>,
    /// The buoy, in a single session (its track's distances).
    buoy_m: Option<[f64; 3]>,
    progress: indicatif::ProgressBar,
    error: Option<anyhow::Error>,
}

impl Recorder {
    /// Opens the outputs of a session of this `layout`: the MCAP log starts at once; CSV files
    /// appear with their first row. `progress` counts session seconds.
    pub fn new(
        dests: Destinations,
        layout: &Layout,
        progress: indicatif::ProgressBar,
    ) -> anyhow::Result<Recorder> {
        let (mcap, header, buoy_m, preview): (_, &[&str], _, _) = match layout {
            Layout::Single { buoy_m, base_ns } => (
                dests
                    .mcap
                    .as_ref()
                    .map(|dest| McapLog::create(dest, *base_ns).map(Log::Single))
                    .transpose()?,
                &TRACK_HEADER,
                Some(*buoy_m),
                dests.preview && dests.images_out.is_some(),
            ),
            Layout::Network { vehicles } => (
                dests
                    .mcap
                    .as_ref()
                    .map(|dest| NetMcapLog::create(dest, vehicles).map(Log::Network))
                    .transpose()?,
                &NET_TRACK_HEADER,
                None,
                false,
            ),
        };
        Ok(Recorder {
            events: dests
                .events
                .map(|dest| RowWriter::new(dest, RowFormat::Csv, &EVENTS_HEADER)),
            track: dests
                .track
                .map(|dest| RowWriter::new(dest, RowFormat::Csv, header)),
            mcap,
            images_out: dests.images_out,
            images: BTreeMap::new(),
            telemetry: dests.telemetry.map(Telemetry::new),
            preview: preview.then(Previewer::start).transpose()?,
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
        for rows in [self.events.take(), self.track.take()]
            .into_iter()
            .flatten()
        {
            rows.finish()?;
        }
        if let Some(telemetry) = self.telemetry.take() {
            telemetry.finish()?;
        }
        if let Some(log) = self.mcap.take() {
            log.finish()?;
        }
        Ok(())
    }

    /// The file image number `n` of `vehicle` is written to, with `--images-out`.
    fn image_path(&self, vehicle: u8, n: u64) -> Option<PathBuf> {
        let dir = self.images_out.as_ref()?;
        let file = format!("image-{n:04}.png");
        Some(match self.buoy_m {
            Some(_) => dir.join(file),
            None => dir.join(format!("vehicle-{vehicle}")).join(file),
        })
    }

    /// With `--preview`: hands the image in progress to the previewer when more of it has
    /// arrived; the file its preview goes to.
    fn write_preview(&mut self, vehicle: u8, prefix: &[u8]) -> Option<PathBuf> {
        if prefix.is_empty() || self.error.is_some() {
            return None;
        }
        let number = self.images.get(&vehicle).copied().unwrap_or(0) + 1;
        let previewer = self.preview.as_ref()?;
        let path = self.image_path(vehicle, number)?;
        if self.previewed != Some(prefix.len()) {
            previewer.show(number, path.clone(), prefix);
            self.previewed = Some(prefix.len());
        }
        Some(path)
    }

    /// Decodes image `number` of `vehicle` and writes it whole at `path` as PNG.
    fn save_image(
        &self,
        vehicle: u8,
        number: u64,
        path: &Path,
        stream: &[u8],
    ) -> anyhow::Result<()> {
        let image = rovlink_debt::decode(stream).map_err(|e| match self.buoy_m {
            Some(_) => anyhow::anyhow!("image {number}: {e}"),
            None => anyhow::anyhow!("vehicle {vehicle} image {number}: {e}"),
        })?;
        let png = rovlink_debt::picture::to_png(&image)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        write_whole(path, &png)
    }

    /// The telemetry writer, about `vehicle` in a network; none once an output failed.
    fn telemetry_of(&mut self, vehicle: u8) -> Option<&mut Telemetry> {
        if self.error.is_some() {
            return None;
        }
        let network = self.buoy_m.is_none();
        let telemetry = self.telemetry.as_mut()?;
        if network {
            telemetry.set_vehicle(vehicle);
        }
        Some(telemetry)
    }

    /// A step's `--track` row.
    fn track_row(&self, vehicle: u8, pose: &PoseSample) -> Vec<String> {
        let [x, y, z] = pose.position_m.map(|v| format!("{v:.4}"));
        let (t_s, heading_deg) = (
            format!("{:.3}", pose.t_s),
            format!("{:.2}", pose.heading_deg),
        );
        let link_up = u8::from(pose.link_up).to_string();
        let Some(buoy_m) = self.buoy_m else {
            return vec![vehicle.to_string(), t_s, x, y, z, heading_deg, link_up];
        };
        let [gx, gy, gz] = point(pose.goal_m);
        let [bx, by, bz] = point(pose.backtrack_m);
        let goal_distance = pose
            .goal_m
            .map_or(String::new(), |g| format!("{:.4}", distance_m(g, buoy_m)));
        vec![
            t_s,
            x,
            y,
            z,
            heading_deg,
            format!("{:.4}", distance_m(pose.position_m, buoy_m)),
            gx,
            gy,
            gz,
            goal_distance,
            bx,
            by,
            bz,
            link_up,
        ]
    }
}

/// Writes a file whole (aside, then renamed), creating its directory.
pub(crate) fn write_whole(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|source| rovlink_base::io::IoError::Open {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    AtomicFile::create(path)?.commit_with(bytes)?;
    Ok(())
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
        match self.mcap.as_mut() {
            Some(Log::Single(log)) => log.frame(e),
            Some(Log::Network(log)) => log.hop(e),
            None => {}
        }
        let (Some(out), None) = (self.events.as_mut(), self.error.as_ref()) else {
            return;
        };
        let outcome = out.row(&event_fields(e));
        self.keep(outcome);
    }

    fn image(&mut self, vehicle: u8, t_s: f64, stream: &[u8]) {
        let count = self.images.entry(vehicle).or_insert(0);
        *count += 1;
        let number = *count;
        self.previewed = None;
        if let Some(previewer) = &self.preview {
            previewer.completed(number);
        }
        match self.mcap.as_mut() {
            Some(Log::Single(log)) => log.image(t_s, stream),
            Some(Log::Network(log)) => log.image(vehicle, t_s, stream),
            None => {}
        }
        let mut file = None;
        if let (Some(path), None) = (self.image_path(vehicle, number), self.error.as_ref()) {
            let saved = self.save_image(vehicle, number, &path, stream);
            file = saved.is_ok().then_some(path);
            self.keep(saved);
        }
        if let Some(telemetry) = self.telemetry_of(vehicle) {
            let outcome = telemetry.image_complete(t_s, file.as_deref());
            self.keep(outcome);
        }
    }

    fn event(&mut self, vehicle: u8, end: Role, t_s: f64, event: &Event) {
        if let Some(Log::Network(log)) = self.mcap.as_mut() {
            log.event(vehicle, end, t_s, event);
        }
        let file = match event {
            Event::ImageProgress { prefix, .. } => self.write_preview(vehicle, prefix),
            _ => None,
        };
        if let Some(telemetry) = self.telemetry_of(vehicle) {
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

    fn pose(&mut self, vehicle: u8, pose: &PoseSample) {
        match self.mcap.as_mut() {
            Some(Log::Single(log)) => log.pose(pose),
            Some(Log::Network(log)) => log.pose(vehicle, pose),
            None => {}
        }
        if self.error.is_some() || self.track.is_none() {
            return;
        }
        let row = self.track_row(vehicle, pose);
        if let Some(out) = self.track.as_mut() {
            let outcome = out.row(&row);
            self.keep(outcome);
        }
    }

    fn wants_poses(&self) -> bool {
        self.mcap.is_some() || self.track.is_some()
    }

    fn failed(&self) -> bool {
        self.error.is_some()
            || self.mcap.as_ref().is_some_and(Log::failed)
            || self.preview.as_ref().is_some_and(Previewer::failed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rovlink_rcp::autopilot::DriveEvent;
    use rovlink_rcp::camera::builtin_picture;
    use rovlink_rcp::{ImageSettings, trunks_of};
    use rovlink_wire::operator::Order;
    use serde_json::Value;

    const STATUS: &str = r#"{"type":"rov","src":1,"dst":0,"ft":true,"lt":false,"st":0,"isn":1,"ci":false,"itsn":0,"rd":true,"eoid":1,"loc":false,"hh":true,"arm":true,"nav":"guided","x_cm":-250,"y_cm":1200,"z_cm":455,"roll_deg":359,"pitch_deg":1,"yaw_deg":180,"trunk":"00010203"}"#;

    const GOTO: Order = Order::GoTo {
        x_cm: 300,
        y_cm: 0,
        z_cm: 50,
        heading_deg: 90,
    };

    fn recorder(dests: Destinations) -> Recorder {
        let layout = Layout::Single {
            buoy_m: [0.0; 3],
            base_ns: 0,
        };
        Recorder::new(dests, &layout, indicatif::ProgressBar::hidden()).unwrap()
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
        trunks_of(&builtin_picture(64, 48, 1), &ImageSettings::default())
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
        let status = rovlink_wire::json::parse_line(STATUS).unwrap();
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
        rovlink_debt::picture::to_png(&rovlink_debt::decode(stream).unwrap()).unwrap()
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
        let trunks = trunks_of(&builtin_picture(320, 240, 1), &ImageSettings::default());
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
