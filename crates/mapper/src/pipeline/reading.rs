//! Reading the inputs of a build or a live mapper, in order, on whichever thread calls
//! [`read_inputs`]: each input opened, its scans handed over one by one as soon as each is
//! whole, and what the caller should know (clouds skipped, notes on how a robot log was read).
//!
//! A `.graph` on standard input or a FIFO is streamed node by node, and with `follow` a file
//! still being written is read as `tail -f` reads one (at its end, it waits for more); any other
//! input is read as [`open_scans`] reads it. Every read waiting on a silent pipe gives up once
//! the stop flag is set.

use std::fs::File;
use std::io::{self, Read};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use super::inputs::{InputFormat, ScanSource, open_scans, with_origin};
use super::{BuildConfig, PipelineError};
use rovlink_base::io::{IoError, StopReader};
use rovlink_octo::{Scan, graph};
use rovlink_scans::recording::{Item, RecordingError};

/// How often a followed file is looked at again once its end is reached.
pub const FOLLOW_POLL: Duration = Duration::from_millis(50);

/// What [`read_inputs`] hands over, in the order it reads it.
#[derive(Debug)]
pub enum Reading {
    /// An input was opened; it says it has this many scans (0: it does not say).
    Opened {
        /// Scans the input says it has.
        scans: u64,
    },
    /// A whole scan, posed (`--origin` applied to inputs without poses).
    Scan(Scan),
    /// A cloud skipped for want of a pose: why, naming the input.
    Skipped(String),
    /// What a user should know about how a robot log was read (`FILE: poses from TF ...`),
    /// once the log is read to its end.
    Notes(Vec<String>),
}

/// Counts one more cloud skipped for `reason` in `skipped` ((reason, count), in the order the
/// reasons first came).
pub fn count_skipped(skipped: &mut Vec<(String, u64)>, reason: String) {
    match skipped.iter_mut().find(|(r, _)| *r == reason) {
        Some((_, n)) => *n += 1,
        None => skipped.push((reason, 1)),
    }
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

/// Reads `inputs` in turn and hands what it reads to `send` (false: stop reading); returns
/// whether the reading was stopped (by `stop` or by `send`) rather than ending with the last
/// input. A bad input is an error naming it, after everything before it was handed over; an
/// error while `stop` is set is a stop.
pub fn read_inputs(
    inputs: &[PathBuf],
    cfg: &BuildConfig,
    follow: bool,
    stop: &AtomicBool,
    send: &mut dyn FnMut(Reading) -> bool,
) -> Result<bool, PipelineError> {
    let stopped = || stop.load(Ordering::Relaxed);
    for path in inputs {
        if stopped() {
            return Ok(true);
        }
        match read_one(path, cfg, follow, stop, send) {
            Err(_) if stopped() => return Ok(true),
            Err(e) => return Err(e),
            Ok(true) => return Ok(true),
            Ok(false) => {}
        }
        // A live input ends only when stopped.
        if stopped() {
            return Ok(true);
        }
    }
    Ok(false)
}

/// [`read_inputs`] of one input; true if `send` asked to stop.
fn read_one(
    path: &Path,
    cfg: &BuildConfig,
    follow: bool,
    stop: &AtomicBool,
    send: &mut dyn FnMut(Reading) -> bool,
) -> Result<bool, PipelineError> {
    let name = path.display().to_string();
    let bad = |source| PipelineError::Input {
        name: name.clone(),
        source,
    };
    let origin = cfg.origin_m.map(|o| o.map(|c| c as f32));
    if graph_stream(path, cfg, follow) {
        let reader: Box<dyn Read + '_> = if follow && !rovlink_base::io::is_std(Some(path)) {
            // As tail -F: a file not there yet is waited for.
            let file = loop {
                match File::open(path) {
                    Err(e) if e.kind() == io::ErrorKind::NotFound => {
                        if stop.load(Ordering::Relaxed) {
                            return Ok(true);
                        }
                        std::thread::sleep(FOLLOW_POLL);
                    }
                    opened => {
                        break opened.map_err(|source| IoError::Open {
                            path: path.to_path_buf(),
                            source,
                        })?;
                    }
                }
            };
            Box::new(Follow { file, stop })
        } else {
            Box::new(StopReader::open(Some(path), stop))
        };
        let stream = graph::ScanStream::new(reader, u64::MAX).map_err(bad)?;
        let n = stream.node_count() as usize;
        if !send(Reading::Opened { scans: n as u64 }) {
            return Ok(true);
        }
        for scan in stream.take(n) {
            if !send(Reading::Scan(with_origin(scan.map_err(bad)?, origin))) {
                return Ok(true);
            }
        }
        return Ok(false);
    }
    let source = open_scans(path, cfg, stop)?;
    let mut recording = None;
    type Items<'s> = Box<dyn Iterator<Item = Result<Item, PipelineError>> + 's>;
    let (items, count, needs_origin): (Items<'_>, u64, bool) = match source {
        ScanSource::Scans(scans, n, format) => {
            let name = name.clone();
            let items = scans.map(move |r| {
                r.map(Item::Scan).map_err(|source| PipelineError::Input {
                    name: name.clone(),
                    source,
                })
            });
            (Box::new(items), n as u64, !format.has_poses())
        }
        ScanSource::Bag(rec) => {
            // A bag's clouds borrow it: it lives here, beside the loop over them.
            let rec = recording.insert(rec);
            let n = rec.cloud_count().unwrap_or(0);
            let needs_origin = !rec.has_poses();
            let items = rec.scans(stop)?.map(|r| r.map_err(PipelineError::from));
            (Box::new(items), n, needs_origin)
        }
        ScanSource::Live(scans) => (scans, 0, false),
    };
    if !send(Reading::Opened { scans: count }) {
        return Ok(true);
    }
    let origin = origin.filter(|_| needs_origin);
    let (mut posed, mut skipped, mut first_reason) = (0u64, 0u64, None);
    for item in items {
        match item? {
            Item::Skipped(reason) => {
                let reason = format!("{name}: {reason}");
                skipped += 1;
                first_reason.get_or_insert_with(|| reason.clone());
                if !send(Reading::Skipped(reason)) {
                    return Ok(true);
                }
            }
            Item::Scan(scan) => {
                posed += 1;
                if !send(Reading::Scan(with_origin(scan, origin))) {
                    return Ok(true);
                }
            }
        }
        if stop.load(Ordering::Relaxed) {
            return Ok(true);
        }
    }
    let Some(rec) = &recording else {
        return Ok(false);
    };
    // A bag that says it has clouds but gives none (its metadata.yaml lists a topic its .db3
    // lacks) is not an empty survey.
    if posed == 0
        && skipped == 0
        && let Some(n) = rec.cloud_count().filter(|&n| n > 0)
    {
        return Err(PipelineError::Recording(RecordingError::Unusable {
            file: name,
            message: format!(
                "cloud topic {:?}: expected {n} messages (as the bag says), found none",
                rec.cloud_topic()
            ),
        }));
    }
    if posed == 0
        && let Some(reason) = first_reason
    {
        return Err(PipelineError::NoPosedCloud {
            name,
            skipped,
            reason,
        });
    }
    let notes = rec.notes.iter().map(|n| format!("{name}: {n}")).collect();
    Ok(!send(Reading::Notes(notes)))
}
