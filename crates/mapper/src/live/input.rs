//! The mapper's clouds as they come: each input read in turn
//! ([`crate::pipeline::read_inputs`]), its scans handed over one by one as soon as each is
//! whole. A `.graph` is streamed (node by node) from a pipe, a FIFO, or, with `follow`, a file
//! still being written, read as `tail -f` reads one (at its end, it waits for more); any other
//! input is read as `build` reads it.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use crate::pipeline::{BuildConfig, PipelineError, Reading, count_skipped, read_inputs};
use rovlink_octo::Scan;

pub use crate::pipeline::FOLLOW_POLL;

/// What reading the inputs came to.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FeedReport {
    /// Scans handed over.
    pub scans: u64,
    /// Clouds skipped for want of a pose: (reason, count).
    pub skipped: Vec<(String, u64)>,
    /// Whether the stop flag ended the reading.
    pub interrupted: bool,
}

/// Reads `inputs` in turn and hands each scan to `send` (false: stop reading); a bad input is
/// an error naming it, after the scans before it were handed over.
pub fn feed(
    inputs: &[PathBuf],
    cfg: &BuildConfig,
    follow: bool,
    stop: &AtomicBool,
    send: &mut dyn FnMut(Scan) -> bool,
) -> Result<FeedReport, PipelineError> {
    let mut report = FeedReport::default();
    let mut take = |r: Reading| match r {
        Reading::Scan(scan) => {
            report.scans += 1;
            send(scan)
        }
        Reading::Skipped(reason) => {
            count_skipped(&mut report.skipped, reason);
            true
        }
        Reading::Opened { .. } | Reading::Notes(_) => true,
    };
    let interrupted = read_inputs(inputs, cfg, follow, stop, &mut take)?;
    report.interrupted = interrupted;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rovlink_octo::{Pose, graph};
    use std::io::Write;
    use std::sync::atomic::Ordering;
    use std::time::Duration;

    fn scans(n: usize) -> Vec<Scan> {
        (0..n)
            .map(|k| Scan {
                points: vec![[k as f32, 1.0, -2.0], [0.5, k as f32, -2.0]],
                colors: None,
                pose: Pose::IDENTITY,
            })
            .collect()
    }

    #[test]
    fn a_graph_being_written_is_followed_scan_by_scan() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("live.graph");
        let bytes = graph::write(&scans(3));
        // The node count and the first scan only, for now (a one-scan graph less its edge
        // count).
        let first_end = graph::write(&scans(1)).len() - 4;
        std::fs::write(&path, &bytes[..first_end]).unwrap();
        let stop = AtomicBool::new(false);
        let (tx, rx) = std::sync::mpsc::channel();
        let cfg = BuildConfig::default();
        std::thread::scope(|s| {
            let reader = s.spawn(|| {
                let mut send = |scan: Scan| tx.send(scan).is_ok();
                feed(std::slice::from_ref(&path), &cfg, true, &stop, &mut send)
            });
            // The first scan comes while the file is still short.
            let first = rx.recv_timeout(Duration::from_secs(60));
            if first.is_err() {
                stop.store(true, Ordering::Relaxed);
            }
            let first = first.unwrap();
            assert_eq!(first.points[0], [0.0, 1.0, -2.0]);
            let mut f = std::fs::OpenOptions::new()
                .append(true)
                .open(&path)
                .unwrap();
            f.write_all(&bytes[first_end..]).unwrap();
            drop(f);
            let report = reader.join().unwrap().unwrap();
            assert_eq!(report.scans, 3);
            assert_eq!(rx.try_iter().count(), 2);
        });
    }

    #[test]
    fn a_stopped_follow_ends_without_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("live.graph");
        std::fs::write(&path, 5u32.to_le_bytes()).unwrap();
        let stop = AtomicBool::new(true);
        let cfg = BuildConfig::default();
        let r = feed(&[path], &cfg, true, &stop, &mut |_| true).unwrap();
        assert!(r.interrupted);
        assert_eq!(r.scans, 0);
    }
}
