//! What a session writes as it goes, and its summary: tdma-run's outputs as one [`Observer`].
//!
//! - `--events`: one CSV row per frame, `direction,kind,bytes,t_sent_s,t_received_s,fate`;
//! - `--track`: one CSV row per vehicle step ([`TRACK_HEADER`]; distances from the buoy);
//! - `--mcap`: the [`McapLog`];
//! - `--images-out`: every completed image as `image-NNNN.png`, each file whole (written
//!   aside and renamed), the directory created with the first.
//!
//! Rows go through [`RowWriter`]: each one whole line in one write, so a run stopped by a
//! signal or a full disk leaves whole rows. The first write error is kept; from then on
//! [`Observer::failed`] is true (the session ends at its next event) and [`Recorder::finish`]
//! returns it.

use std::path::{Path, PathBuf};

use super::PoseSample;
use super::mcap_log::McapLog;
use super::session::{FrameEvent, Metrics, Observer};
use crate::cli::UsageError;
use crate::cli::output::Dest;
use crate::cli::rows::{RowFormat, RowWriter};
use crate::io::{AtomicFile, Output};

/// The columns of `--events`.
pub const EVENTS_HEADER: [&str; 6] = [
    "direction",
    "kind",
    "bytes",
    "t_sent_s",
    "t_received_s",
    "fate",
];

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
}

/// The observer writing every output of a session.
pub struct Recorder {
    events: Option<RowWriter>,
    track: Option<RowWriter>,
    mcap: Option<McapLog>,
    images_out: Option<PathBuf>,
    images: u64,
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
        if let Some(error) = self.error.take() {
            return Err(error);
        }
        for rows in [self.events.take(), self.track.take()]
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

    fn save_image(&self, path: &std::path::Path, stream: &[u8]) -> anyhow::Result<()> {
        let image = crate::debt::decode(stream)
            .map_err(|e| anyhow::anyhow!("image {}: {e}", self.images))?;
        let png = crate::debt::picture::to_png(&image)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|source| crate::io::IoError::Open {
                path: dir.to_path_buf(),
                source,
            })?;
        }
        AtomicFile::create(path)?.commit_with(&png)?;
        Ok(())
    }
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

/// A point's three CSV fields, empty when there is none.
fn point(p: Option<[f64; 3]>) -> [String; 3] {
    p.map_or_else(Default::default, |p| p.map(|v| format!("{v:.4}")))
}

impl Observer for Recorder {
    fn frame(&mut self, e: &FrameEvent) {
        let t = e.t_received_s.or(e.t_sent_s).unwrap_or(0.0);
        self.progress.set_position(t as u64);
        if let Some(log) = self.mcap.as_mut() {
            log.frame(e);
        }
        if self.error.is_some() {
            return;
        }
        if let Some(out) = self.events.as_mut() {
            let time = |t: Option<f64>| t.map_or(String::new(), |t| format!("{t:.6}"));
            let row = [
                e.direction.to_string(),
                e.kind.to_string(),
                e.bytes.to_string(),
                time(e.t_sent_s),
                time(e.t_received_s),
                e.fate.to_string(),
            ];
            let outcome = out.row(&row);
            self.keep(outcome);
        }
    }

    fn image(&mut self, t_s: f64, stream: &[u8]) {
        self.images += 1;
        if let Some(log) = self.mcap.as_mut() {
            log.image(t_s, stream);
        }
        let (Some(dir), None) = (self.images_out.as_ref(), self.error.as_ref()) else {
            return;
        };
        let path = dir.join(format!("image-{:04}.png", self.images));
        let saved = self.save_image(&path, stream);
        self.keep(saved);
    }

    fn pose(&mut self, pose: &PoseSample) {
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
            format!("{:.4}", distance(pose.position_m, self.buoy_m)),
            gx,
            gy,
            gz,
            pose.goal_m.map_or(String::new(), |g| {
                format!("{:.4}", distance(g, self.buoy_m))
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
        self.error.is_some() || self.mcap.as_ref().is_some_and(Observer::failed)
    }
}

/// Writes `metrics` as pretty JSON to `out` and flushes it; the caller commits it
/// ([`Output::finish`]) once every other output is complete. `out` is opened before the run
/// (a file aside, renamed on commit), so an output that cannot be created fails before any
/// work and a failed run leaves no metrics file.
pub fn write_metrics(out: &mut Output, metrics: &Metrics) -> Result<(), crate::io::IoError> {
    let mut text =
        serde_json::to_string_pretty(metrics).map_err(|e| crate::io::IoError::Write {
            name: out.name(),
            source: std::io::Error::other(e),
        })?;
    text.push('\n');
    out.write_bytes(text.as_bytes())?;
    out.flush_named()
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
