//! The virtual-time driver: frames from one side, offered back to back or at a fixed interval,
//! through a [`Link`] as fast as the CPU allows.
//!
//! Back to back means each frame is offered when the previous one's air time is over (the
//! transmitter is free), which is how a modem is fed at its own pace: no frame waits in the
//! FIFO, so its delay is exactly the intrinsic delay, its jitter, its air time and the
//! propagation. With an interval, frame `k` is offered at `k x interval` whatever the link is
//! doing, and the FIFO absorbs (or drops) what the link cannot keep up with.
//!
//! Frames are pulled from the source only when they are offered, and reports are pushed to the
//! sink as soon as they are decided, so memory holds only the frames in flight.
//!
//! [`FrameReader`] is the source of link-sim's pipe: the wire.md frames of a byte stream, read
//! on a thread of their own so that a stop request is seen even while the input is silent.

use std::collections::VecDeque;
use std::io::{self, Read};
use std::os::unix::fs::FileTypeExt;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::Duration;

use rovlink_base::io::IoError;
use rovlink_wire::{DeframeEvent, DeframeStats, Deframer};

use super::channel::{Link, Report, Side};
use super::sched::SimTime;

/// The latest time a frame is offered at: 100 years of virtual time. With a model's figures in
/// their ranges a fate is decided within about 20 years of its offer, so every time of a run
/// stays well inside [`SimTime`]'s 584 years and nothing saturates.
pub const HORIZON: SimTime = SimTime(100 * 365 * 24 * 3600 * 1_000_000_000);

/// When frames are offered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pace {
    /// Each frame when the transmitter is free.
    BackToBack,
    /// Frame `k` at `k x` this many nanoseconds.
    IntervalNs(u64),
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// The source ran out and every frame's fate was reported.
    Done,
    /// The stop flag was set: the run ended at the next event, with the reports decided so far
    /// handed over; frames still in flight ([`Link::in_flight`]) were not reported.
    Stopped,
    /// The next offer would have come after [`HORIZON`]: no more frames were taken from the
    /// source, and every frame offered was reported.
    Horizon,
}

/// A run that reached [`HORIZON`]: bad input for a tool (exit 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "the input holds more frames than 100 years of virtual time at this pace (the rest was not read)"
)]
pub struct PastHorizon;

impl Ended {
    /// The outcome, or [`PastHorizon`] for [`Ended::Horizon`].
    pub fn within_horizon(self) -> Result<Ended, PastHorizon> {
        match self {
            Ended::Horizon => Err(PastHorizon),
            other => Ok(other),
        }
    }
}

/// Offers every frame `source` yields from side A of `link`, in virtual time at `pace`, and
/// hands each report to `sink` (in the order fates are decided) until the last frame's fate is
/// known. `source` is called at each offer time, with that time, and returns the frame to offer
/// (`None` ends the input). `stop` is checked at every event and every offer. Errors from the
/// source or the sink stop the run and are returned.
pub fn run<E>(
    link: &mut Link,
    pace: Pace,
    stop: &AtomicBool,
    mut source: impl FnMut(SimTime) -> Result<Option<Vec<u8>>, E>,
    mut sink: impl FnMut(Report) -> Result<(), E>,
) -> Result<Ended, E> {
    let mut exhausted = false;
    let mut past_horizon = false;
    let mut offered: u64 = 0;
    loop {
        if stop.load(Ordering::Relaxed) {
            while let Some(report) = link.pop_report() {
                sink(report)?;
            }
            return Ok(Ended::Stopped);
        }
        if !exhausted {
            let offer_at = match pace {
                Pace::BackToBack => link.tx_idle(Side::A).then(|| link.now()),
                Pace::IntervalNs(interval) => Some(
                    offered
                        .checked_mul(interval)
                        .map_or(SimTime(u64::MAX), SimTime),
                ),
            };
            match offer_at {
                Some(t) if t > HORIZON => {
                    exhausted = true;
                    past_horizon = true;
                }
                // Events due at the offer time come first: a transmitter freed at t takes a
                // frame offered at t. (Back to back with nothing pending: the link is idle.)
                Some(t) if link.next_event_time().is_none_or(|due| due > t) => {
                    link.advance(t);
                    match source(link.now())? {
                        Some(frame) => {
                            link.offer(Side::A, frame);
                            offered += 1;
                        }
                        None => exhausted = true,
                    }
                }
                _ => {
                    link.step();
                }
            }
        } else if !link.step() {
            while let Some(report) = link.pop_report() {
                sink(report)?;
            }
            return Ok(if past_horizon {
                Ended::Horizon
            } else {
                Ended::Done
            });
        }
        while let Some(report) = link.pop_report() {
            sink(report)?;
        }
    }
}

/// Bytes read from the input per chunk.
const CHUNK_BYTES: usize = 64 * 1024;

/// How often a reader waiting for input looks at the stop flag.
const STOP_POLL: Duration = Duration::from_millis(50);

/// The wire.md frames of a byte stream, in order; bytes that are not part of a good frame are
/// skipped and counted ([`FrameReader::stats`], [`FrameReader::skipped_note`]).
pub struct FrameReader {
    name: String,
    chunks: Receiver<Result<Vec<u8>, IoError>>,
    deframer: Deframer,
    frames: VecDeque<Vec<u8>>,
    eof: bool,
}

/// Input the pipe cannot use.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// The input could not be opened or read.
    #[error(transparent)]
    Io(#[from] IoError),
    /// Bytes, but not one good frame among them.
    #[error(
        "{name}: no link frame in {bytes} bytes (expected wire.md frames starting with 0x55 and a valid CRC)"
    )]
    NoFrames {
        /// The input's name.
        name: String,
        /// Bytes read.
        bytes: u64,
    },
}

impl FrameReader {
    /// Opens a file, or standard input for `None` or `-`, and reads it ([`FrameReader::new`]).
    /// A named pipe is opened on the reading thread, so that waiting for its writer does not
    /// hold up a stop either (a failure to open it then comes with the first frame).
    pub fn open(path: Option<&Path>) -> Result<FrameReader, IoError> {
        let Some(path) = path.filter(|p| !rovlink_base::io::is_std(Some(p))) else {
            return Ok(FrameReader::new("<stdin>".into(), io::stdin()));
        };
        let owned = path.to_path_buf();
        let open = move || {
            std::fs::File::open(&owned).map_err(|source| IoError::Open {
                path: owned.clone(),
                source,
            })
        };
        let name = path.display().to_string();
        let fifo = std::fs::metadata(path).is_ok_and(|m| m.file_type().is_fifo());
        if fifo {
            Ok(FrameReader::spawn(name, open))
        } else {
            let file = open()?;
            Ok(FrameReader::new(name, file))
        }
    }

    /// Reads `input`, called `name` in messages, on a thread of its own (interrupted reads are
    /// retried; the thread ends at the end of the input or at the first error).
    pub fn new(name: String, input: impl Read + Send + 'static) -> FrameReader {
        FrameReader::spawn(name, move || Ok(input))
    }

    /// Opens the input with `open` on the reading thread, then reads it as [`FrameReader::new`].
    fn spawn<R: Read>(
        name: String,
        open: impl FnOnce() -> Result<R, IoError> + Send + 'static,
    ) -> FrameReader {
        let (sender, chunks) = mpsc::sync_channel(4);
        let thread_name = name.clone();
        std::thread::spawn(move || {
            let mut input = match open() {
                Ok(input) => input,
                Err(error) => {
                    let _ = sender.send(Err(error));
                    return;
                }
            };
            let mut buf = vec![0u8; CHUNK_BYTES];
            loop {
                let chunk = match input.read(&mut buf) {
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                    Err(source) => Err(IoError::Read {
                        name: thread_name.clone(),
                        source,
                    }),
                    Ok(n) => Ok(buf[..n].to_vec()),
                };
                let last = !matches!(&chunk, Ok(bytes) if !bytes.is_empty());
                if sender.send(chunk).is_err() || last {
                    return;
                }
            }
        });
        FrameReader {
            name,
            chunks,
            deframer: Deframer::new(),
            frames: VecDeque::new(),
            eof: false,
        }
    }

    /// The next frame; `None` at the end of the input, or as soon as `stop` is set (within
    /// 50 ms, even while the input is silent). A read (or open) error names the input.
    pub fn next_frame(&mut self, stop: &AtomicBool) -> Result<Option<Vec<u8>>, IoError> {
        while self.frames.is_empty() && !self.eof {
            if stop.load(Ordering::Relaxed) {
                return Ok(None);
            }
            match self.chunks.recv_timeout(STOP_POLL) {
                Ok(Ok(bytes)) if !bytes.is_empty() => self.deframer.push(&bytes),
                Ok(Ok(_)) | Err(RecvTimeoutError::Disconnected) => {
                    self.deframer.finish();
                    self.eof = true;
                }
                Ok(Err(error)) => return Err(error),
                Err(RecvTimeoutError::Timeout) => continue,
            }
            while let Some(event) = self.deframer.next_event() {
                if let DeframeEvent::Frame { frame, .. } = event {
                    self.frames.push_back(frame.into_inner().to_vec());
                }
            }
        }
        Ok(self.frames.pop_front())
    }

    /// What the deframer has seen so far: bytes read, good frames, bytes skipped.
    pub fn stats(&self) -> DeframeStats {
        self.deframer.stats()
    }

    /// The input's verdict once read: an error when it held bytes but no good frame, a line
    /// for the summary when some bytes were skipped, nothing when every byte was a frame.
    pub fn skipped_note(&self) -> Result<Option<String>, InputError> {
        let stats = self.stats();
        if stats.bytes_skipped == 0 {
            return Ok(None);
        }
        if stats.frames == 0 {
            return Err(InputError::NoFrames {
                name: self.name.clone(),
                bytes: stats.bytes_in,
            });
        }
        Ok(Some(format!(
            "{}: skipped {} bytes that were not good frames ({} CRC failures, {} truncated)",
            self.name, stats.bytes_skipped, stats.crc_failures, stats.truncated
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Distance, Model};

    fn link() -> Link {
        Link::symmetric(Model::preset("s100").unwrap(), 1, Distance::Fixed(1.0)).unwrap()
    }

    #[test]
    fn frames_come_out_of_a_byte_stream_with_the_junk_counted() {
        let frame = rovlink_wire::frame::build(1, 2, b"hello").unwrap();
        let mut bytes = b"junk".to_vec();
        bytes.extend_from_slice(&frame);
        bytes.extend_from_slice(&frame);
        let mut reader = FrameReader::new("t.bin".into(), io::Cursor::new(bytes));
        let stop = AtomicBool::new(false);
        assert_eq!(reader.next_frame(&stop).unwrap(), Some(frame.clone()));
        assert_eq!(reader.next_frame(&stop).unwrap(), Some(frame));
        assert_eq!(reader.next_frame(&stop).unwrap(), None);
        let stats = reader.stats();
        assert_eq!((stats.frames, stats.bytes_skipped), (2, 4));
        let note = reader.skipped_note().unwrap().unwrap();
        assert!(note.starts_with("t.bin: skipped 4 bytes"), "{note}");
        let mut junk = FrameReader::new("j.bin".into(), io::Cursor::new(vec![0x55; 27]));
        assert_eq!(junk.next_frame(&stop).unwrap(), None);
        let message = junk.skipped_note().unwrap_err().to_string();
        assert!(
            message.starts_with("j.bin: no link frame in 27 bytes"),
            "{message}"
        );
    }

    #[test]
    fn a_silent_input_does_not_hold_up_a_stop() {
        let (_keep_open, silent) = std::os::unix::net::UnixStream::pair().unwrap();
        let mut reader = FrameReader::new("silent".into(), silent);
        let stop = AtomicBool::new(false);
        let start = std::time::Instant::now();
        std::thread::scope(|scope| {
            scope.spawn(|| {
                std::thread::sleep(Duration::from_millis(100));
                stop.store(true, Ordering::Relaxed);
            });
            assert_eq!(reader.next_frame(&stop).unwrap(), None);
        });
        assert!(start.elapsed() < Duration::from_secs(1));
    }

    #[test]
    fn a_set_stop_flag_ends_the_run_at_the_next_event() {
        let stop = AtomicBool::new(false);
        let mut link = link();
        let mut offered = 0u64;
        let mut reports = 0u64;
        let ended = run::<()>(
            &mut link,
            Pace::BackToBack,
            &stop,
            |_| {
                offered += 1;
                Ok(Some(vec![0; 57])) // an endless source
            },
            |_| {
                reports += 1;
                if reports == 10 {
                    stop.store(true, Ordering::Relaxed);
                }
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(ended, Ended::Stopped);
        assert_eq!(reports, 10);
        assert!(offered <= 12, "{offered} offered");
    }

    #[test]
    fn offers_end_at_the_horizon_instead_of_saturating_time() {
        let stop = AtomicBool::new(false);
        let mut link = link();
        let mut offered = 0u64;
        let mut last_rx = SimTime::ZERO;
        // Ten minutes between frames: the horizon comes after 5 256 000 offers; a year apart,
        // after 101.
        let year_ns = 365 * 24 * 3600 * 1_000_000_000;
        let ended = run::<()>(
            &mut link,
            Pace::IntervalNs(year_ns),
            &stop,
            |_| {
                offered += 1;
                Ok(Some(vec![0; 57]))
            },
            |report| {
                last_rx = last_rx.max(report.t_rx.unwrap_or(SimTime::ZERO));
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(ended, Ended::Horizon);
        assert_eq!(offered, 101);
        assert!(last_rx > SimTime(100 * year_ns) && last_rx < SimTime(101 * year_ns));
        assert_eq!(link.in_flight(), 0);
    }
}
