//! The end of a session: its metrics line and summary, and the checks made before it starts.

use std::path::{Path, PathBuf};

use rovlink_base::UsageError;
use rovlink_base::io::Output;
use rovlink_rcp::report::Metrics;

/// Writes `metrics` as one line of JSON to `out` with the run's parameters and `seed`
/// ([`rovlink_cli::metrics`]) and flushes it; the caller commits it
/// ([`Output::finish`]) once every other output is complete. `out` is opened before the run
/// (a file aside, renamed on commit), so an output that cannot be created fails before any
/// work and a failed run leaves no metrics file.
pub fn write_metrics(
    out: &mut Output,
    seed: u64,
    metrics: &impl serde::Serialize,
) -> Result<(), rovlink_base::io::IoError> {
    rovlink_cli::metrics::write(out, "tdma-run", Some(seed), metrics)
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
