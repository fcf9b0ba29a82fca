//! The mapper's clouds as they come: each input read in turn, its scans handed over one by one
//! as soon as each is whole. A `.graph` is streamed (node by node) from a pipe, a FIFO, or,
//! with `follow`, a file still being written, read as `tail -f` reads one (at its end, it waits
//! for more); any other input is read as `build` reads it.

use std::fs::File;
use std::io::{self, Read};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::pipeline::inputs::{InputFormat, ScanSource, open_scans, with_origin};
use crate::pipeline::{BuildConfig, PipelineError};
use rovlink_base::io::{IoError, StopReader};
use rovlink_octo::{Scan, graph};
use rovlink_scans::recording::Item;

/// How often a followed file is looked at again once its end is reached.
pub const FOLLOW_POLL: Duration = Duration::from_millis(50);

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

/// A file read as `tail -f` reads it: at its end, wait for more until `stop` is set.
struct Follow<'a> {
    file: File,
    stop: &'a AtomicBool,
}

impl Read for Follow<'_> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        loop {
            match self.file.read(buf) {
                Ok(0) if !buf.is_empty() => {
                    if self.stop.load(Ordering::Relaxed) {
                        return Err(io::Error::other("stopped"));
                    }
                    std::thread::sleep(FOLLOW_POLL);
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                other => return other,
            }
        }
    }
}

/// Whether `path` is a `.graph` stream: standard input or a FIFO of that format, or a file
/// followed.
fn graph_stream(path: &Path, cfg: &BuildConfig, follow: bool) -> bool {
    let format = cfg.format.or_else(|| InputFormat::from_path(path));
    if format != Some(InputFormat::Graph) {
        return false;
    }
    follow || rovlink_base::io::is_std(Some(path)) || !path.is_file()
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
    let origin = cfg.origin_m.map(|o| o.map(|c| c as f32));
    for path in inputs {
        if stop.load(Ordering::Relaxed) {
            report.interrupted = true;
            break;
        }
        let name = path.display().to_string();
        let bad = |source| PipelineError::Input {
            name: name.clone(),
            source,
        };
        let stopped = |report: &mut FeedReport| {
            report.interrupted = stop.load(Ordering::Relaxed);
            report.interrupted
        };
        if graph_stream(path, cfg, follow) {
            let reader: Box<dyn Read + '_> = if follow && !rovlink_base::io::is_std(Some(path)) {
                // As tail -F: a file not there yet is waited for.
                let file = loop {
                    match File::open(path) {
                        Err(e) if e.kind() == io::ErrorKind::NotFound => {
                            if stop.load(Ordering::Relaxed) {
                                report.interrupted = true;
                                return Ok(report);
                            }
                            std::thread::sleep(FOLLOW_POLL);
                        }
                        opened => {
                            break opened.map_err(|source| IoError::Open {
                                path: path.clone(),
                                source,
                            })?;
                        }
                    }
                };
                Box::new(Follow { file, stop })
            } else {
                Box::new(StopReader::open(Some(path), stop))
            };
            let stream = match graph::ScanStream::new(reader, u64::MAX) {
                Err(_) if stopped(&mut report) => break,
                s => s.map_err(bad)?,
            };
            let n = stream.node_count() as usize;
            for scan in stream.take(n) {
                let scan = match scan {
                    Err(_) if stopped(&mut report) => return Ok(report),
                    s => s.map_err(bad)?,
                };
                report.scans += 1;
                if !send(scan) {
                    report.interrupted = true;
                    return Ok(report);
                }
            }
            continue;
        }
        let source = match open_scans(path, cfg, stop) {
            Err(_) if stopped(&mut report) => break,
            s => s?,
        };
        let mut recording = None;
        let (items, needs_origin): (Box<dyn Iterator<Item = Result<Item, PipelineError>>>, bool) =
            match source {
                ScanSource::Scans(scans, _, format) => {
                    let name = name.clone();
                    let items = scans.map(move |r| {
                        r.map(Item::Scan).map_err(|source| PipelineError::Input {
                            name: name.clone(),
                            source,
                        })
                    });
                    (Box::new(items), !format.has_poses())
                }
                ScanSource::Bag(rec) => {
                    let rec = recording.insert(rec);
                    let needs_origin = !rec.has_poses();
                    let items = rec.scans(stop)?.map(|r| r.map_err(PipelineError::from));
                    (Box::new(items), needs_origin)
                }
                ScanSource::Live(scans) => (scans, false),
            };
        let origin = origin.filter(|_| needs_origin);
        for item in items {
            match item {
                Err(_) if stopped(&mut report) => return Ok(report),
                Err(e) => return Err(e),
                Ok(Item::Skipped(reason)) => {
                    let reason = format!("{name}: {reason}");
                    match report.skipped.iter_mut().find(|(r, _)| *r == reason) {
                        Some((_, n)) => *n += 1,
                        None => report.skipped.push((reason, 1)),
                    }
                }
                Ok(Item::Scan(scan)) => {
                    report.scans += 1;
                    if !send(with_origin(scan, origin)) {
                        report.interrupted = true;
                        return Ok(report);
                    }
                }
            }
        }
        // A live input ends only when stopped.
        if stopped(&mut report) {
            return Ok(report);
        }
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rovlink_octo::Pose;
    use std::io::Write;

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
