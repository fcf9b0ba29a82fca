//! What a multi-vehicle scenario writes as it goes: tdma-run `--scenario`'s outputs as one
//! [`Observer`].
//!
//! - `--events`: one CSV row per frame and receiver ([`EVENTS_HEADER`]): the medium, the
//!   frame's SRC and DST, the node that transmitted this copy and the node that heard it, the
//!   medium's fate there and what that node's router did (delivered, forwarded, or why it
//!   dropped it);
//! - `--track`: one CSV row per vehicle step, with the vehicle's address first;
//! - `--images-out DIR`: every completed image as `DIR/vehicle-N/image-NNNN.png`, each file
//!   whole;
//! - `--telemetry`: the single-vehicle JSON Lines, each with `"vehicle": N`;
//! - `--mcap`: the [`NetMcapLog`] (each vehicle's channels, every frame at every receiver).
//!
//! Rows are whole lines, flushed as they go; the first write error is kept, from then on
//! [`Observer::failed`] is true and [`NetRecorder::finish`] returns it.

use std::path::PathBuf;

use super::net_mcap::NetMcapLog;
use super::outputs::{Destinations, Telemetry, event_fields, write_whole};
use super::report::{EVENTS_HEADER, FrameEvent, Observer};
use super::{Event, PoseSample, Role};
use crate::cli::rows::{RowFormat, RowWriter};

/// The columns of `--track` in a scenario.
pub const NET_TRACK_HEADER: [&str; 7] = [
    "vehicle",
    "t_s",
    "x_m",
    "y_m",
    "z_m",
    "heading_deg",
    "link_up",
];

/// The observer writing every output of a scenario.
pub struct NetRecorder {
    events: Option<RowWriter>,
    track: Option<RowWriter>,
    images_out: Option<PathBuf>,
    /// Images completed per vehicle.
    images: std::collections::BTreeMap<u8, u64>,
    telemetry: Option<Telemetry>,
    mcap: Option<NetMcapLog>,
    progress: indicatif::ProgressBar,
    error: Option<anyhow::Error>,
}

impl NetRecorder {
    /// The outputs of a scenario with `vehicles` (`dests.preview` is a single session's); the
    /// MCAP log starts at once, CSV files appear with their first row. `progress` counts session seconds.
    pub fn new(
        dests: Destinations,
        vehicles: &[u8],
        progress: indicatif::ProgressBar,
    ) -> anyhow::Result<NetRecorder> {
        let mcap = dests
            .mcap
            .as_ref()
            .map(|dest| NetMcapLog::create(dest, vehicles))
            .transpose()?;
        Ok(NetRecorder {
            events: dests
                .events
                .map(|dest| RowWriter::new(dest, RowFormat::Csv, &EVENTS_HEADER)),
            track: dests
                .track
                .map(|dest| RowWriter::new(dest, RowFormat::Csv, &NET_TRACK_HEADER)),
            images_out: dests.images_out,
            images: Default::default(),
            telemetry: dests.telemetry.map(Telemetry::new),
            mcap,
            progress,
            error: None,
        })
    }

    fn keep(&mut self, outcome: Result<(), impl Into<anyhow::Error>>) {
        if let (Err(error), None) = (outcome, self.error.as_ref()) {
            self.error = Some(error.into());
        }
    }

    /// Completes every output; the first error wins.
    pub fn finish(mut self) -> anyhow::Result<()> {
        self.progress.finish_and_clear();
        if let Some(error) = self.error.take() {
            return Err(error);
        }
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
}

impl Observer for NetRecorder {
    fn frame(&mut self, e: &FrameEvent<'_>) {
        let t = e.t_received_s.or(e.t_sent_s).unwrap_or(0.0);
        self.progress.set_position(t as u64);
        if let Some(log) = self.mcap.as_mut() {
            log.hop(e);
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
        if let Some(log) = self.mcap.as_mut() {
            log.image(vehicle, t_s, stream);
        }
        let mut file = None;
        if let (Some(dir), None) = (self.images_out.as_ref(), self.error.as_ref()) {
            let path = dir
                .join(format!("vehicle-{vehicle}"))
                .join(format!("image-{number:04}.png"));
            let saved = crate::debt::decode(stream)
                .map_err(|e| anyhow::anyhow!("vehicle {vehicle} image {number}: {e}"))
                .and_then(|image| {
                    crate::debt::picture::to_png(&image)
                        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
                })
                .and_then(|png| write_whole(&path, &png));
            file = saved.is_ok().then_some(path);
            self.keep(saved);
        }
        if let (Some(telemetry), None) = (self.telemetry.as_mut(), self.error.as_ref()) {
            telemetry.set_vehicle(vehicle);
            let outcome = telemetry.image_complete(t_s, file.as_deref());
            self.keep(outcome);
        }
    }

    fn pose(&mut self, vehicle: u8, pose: &PoseSample) {
        if let Some(log) = self.mcap.as_mut() {
            log.pose(vehicle, pose);
        }
        let (Some(out), None) = (self.track.as_mut(), self.error.as_ref()) else {
            return;
        };
        let [x, y, z] = pose.position_m.map(|v| format!("{v:.4}"));
        let row = [
            vehicle.to_string(),
            format!("{:.3}", pose.t_s),
            x,
            y,
            z,
            format!("{:.2}", pose.heading_deg),
            u8::from(pose.link_up).to_string(),
        ];
        let outcome = out.row(&row);
        self.keep(outcome);
    }

    fn event(&mut self, vehicle: u8, end: Role, t_s: f64, event: &Event) {
        if let Some(log) = self.mcap.as_mut() {
            log.event(vehicle, end, t_s, event);
        }
        if let (Some(telemetry), None) = (self.telemetry.as_mut(), self.error.as_ref()) {
            telemetry.set_vehicle(vehicle);
            let outcome = telemetry.event(end, t_s, event, None);
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

    fn failed(&self) -> bool {
        self.error.is_some() || self.mcap.as_ref().is_some_and(NetMcapLog::failed)
    }
}
