//! The frame printer behind `rcp-dump`: bytes in, through the [`Deframer`], out as one record
//! per frame (a line for people, a JSON object in wire.md's form, or a CSV row) plus notices
//! for people about what was not a frame (CRC failures, skipped bytes, truncated frames,
//! invalid messages), with the counters a summary reports.
//!
//! Where records and notices go is the caller's [`Sink`]; [`capture`] reads a live port until
//! it closes or a stop flag is set, giving up an incomplete frame when the line goes quiet;
//! [`read_stream`] reads a file or pipe to its end or until the flag is set.

use std::io::{self, Read};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use serde_json::{Map, Value};

use super::frame::Frame;
use super::{DeframeEvent, DeframeStats, Deframer, MessageRepr, json};
use rovlink_base::io::{IoError, StopReader};

/// The columns of a CSV of frames, in order ([`Record::csv_fields`]).
pub const CSV_COLUMNS: [&str; 48] = json::CSV_COLUMNS;

/// One frame as printed: where it started, when it arrived (live ports), its message, and why
/// the message is not valid if it is not (then the message is `raw`).
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Stream offset of the frame's first byte.
    pub offset: u64,
    /// Seconds since the capture started, on a live port.
    pub t_s: Option<f64>,
    /// The message (raw payload when it is not a valid message).
    pub repr: MessageRepr,
    /// Why the payload is not a valid message.
    pub error: Option<String>,
}

impl Record {
    /// The line for people, with its newline: `@27       rov 1->0 ...`.
    pub fn text_line(&self) -> String {
        let mut line = match self.t_s {
            Some(t) => format!("{t:>10.3}s @{:<8} {}", self.offset, self.repr),
            None => format!("@{:<8} {}", self.offset, self.repr),
        };
        if let Some(e) = &self.error {
            line.push_str(&format!("  [invalid: {e}]"));
        }
        line.push('\n');
        line
    }

    /// The JSON object of wire.md's form, with `offset` first (and `t_s`, rounded to the
    /// microsecond) and `error` last; `rcp-pack` reads it back.
    pub fn object(&self) -> Map<String, Value> {
        let mut map = Map::new();
        map.insert("offset".into(), self.offset.into());
        if let Some(t) = self.t_s {
            map.insert("t_s".into(), Value::from((t * 1e6).round() / 1e6));
        }
        json::write_fields(&self.repr, &mut map);
        if let Some(e) = &self.error {
            map.insert("error".into(), e.as_str().into());
        }
        map
    }

    /// The fields of the CSV row, one per [`CSV_COLUMNS`] entry.
    pub fn csv_fields(&self) -> Vec<String> {
        json::csv_record(&self.object())
    }
}

/// Where the printer's records and notices go.
pub trait Sink {
    /// What writing a record can fail with.
    type Error;
    /// One frame.
    fn record(&mut self, record: &Record) -> Result<(), Self::Error>;
    /// A line for people about bytes that were not a good frame (standard error, usually).
    fn notice(&mut self, text: &str);
    /// Called after each read of a live port, so what arrived is seen at once.
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// The counters of a run, as `--summary` writes them.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Summary {
    /// The input's name.
    pub input: String,
    /// The deframer's counters.
    #[serde(flatten)]
    pub stats: DeframeStats,
    /// Frames with a good CRC whose payload is not a valid message.
    pub invalid_messages: u64,
}

/// The printer: a deframer, the notices it gives, and the counters.
#[derive(Debug)]
pub struct Printer {
    name: String,
    quiet: bool,
    started: Option<Instant>,
    deframer: Deframer,
    invalid: u64,
}

impl Printer {
    /// A printer for the input `name`; `quiet` keeps notices to the summary; `timestamps`
    /// stamps each record with the seconds since now (live ports).
    pub fn new(name: &str, quiet: bool, timestamps: bool) -> Printer {
        Printer {
            name: name.to_string(),
            quiet,
            started: timestamps.then(Instant::now),
            deframer: Deframer::new(),
            invalid: 0,
        }
    }

    /// The input's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Feeds bytes and prints every event they complete.
    pub fn push<S: Sink>(&mut self, bytes: &[u8], sink: &mut S) -> Result<(), S::Error> {
        self.deframer.push(bytes);
        self.drain(sink)
    }

    /// Gives up an incomplete frame (the line went quiet) and prints what that yields.
    pub fn abandon_incomplete<S: Sink>(&mut self, sink: &mut S) -> Result<(), S::Error> {
        self.deframer.abandon_incomplete();
        self.drain(sink)
    }

    /// Ends the stream and prints what is left.
    pub fn finish<S: Sink>(&mut self, sink: &mut S) -> Result<(), S::Error> {
        self.deframer.finish();
        self.drain(sink)
    }

    /// Bytes held for a frame not yet complete.
    pub fn pending_bytes(&self) -> usize {
        self.deframer.pending_bytes()
    }

    /// The counters so far.
    pub fn summary(&self) -> Summary {
        Summary {
            input: self.name.clone(),
            stats: self.deframer.stats(),
            invalid_messages: self.invalid,
        }
    }

    /// The summary as one line for people.
    pub fn summary_line(&self) -> String {
        let s = self.deframer.stats();
        format!(
            "{}: {} frames ok ({} invalid messages), {} CRC failures, {} truncated, {} of {} bytes skipped",
            self.name,
            s.frames,
            self.invalid,
            s.crc_failures,
            s.truncated,
            s.bytes_skipped,
            s.bytes_in
        )
    }

    /// True when every byte so far was part of a valid message.
    pub fn clean(&self) -> bool {
        self.deframer.stats().bytes_skipped == 0 && self.invalid == 0
    }

    fn drain<S: Sink>(&mut self, sink: &mut S) -> Result<(), S::Error> {
        let t_s = self.started.map(|t| t.elapsed().as_secs_f64());
        let name = &self.name;
        let say = |sink: &mut S, text: String| {
            if !self.quiet {
                sink.notice(&format!("{name}: {text}"));
            }
        };
        while let Some(event) = self.deframer.next_event() {
            match event {
                DeframeEvent::Frame { offset, frame } => {
                    let (repr, error) =
                        MessageRepr::parse_lenient(&Frame::new_unchecked(frame.into_inner()));
                    let error = error.map(|e| e.to_string());
                    if let Some(e) = &error {
                        self.invalid += 1;
                        say(
                            sink,
                            format!("offset {offset}: invalid message from {}: {e}", repr.src),
                        );
                    }
                    sink.record(&Record {
                        offset,
                        t_s,
                        repr,
                        error,
                    })?;
                }
                DeframeEvent::BadCrc {
                    offset,
                    payload_len,
                    computed,
                    carried,
                } => say(
                    sink,
                    format!(
                        "offset {offset}: CRC failure (LEN {payload_len}, computed 0x{computed:04x}, carried 0x{carried:04x}), resyncing"
                    ),
                ),
                DeframeEvent::Skipped { offset, len } => {
                    say(sink, format!("offset {offset}: skipped {len} bytes"))
                }
                DeframeEvent::Truncated {
                    offset,
                    expected,
                    found,
                    at_end,
                } => {
                    let when = if at_end {
                        "at end of stream"
                    } else {
                        "after the line went idle"
                    };
                    say(
                        sink,
                        format!(
                            "offset {offset}: incomplete frame given up {when} (needs {expected} bytes, {found} there)"
                        ),
                    )
                }
            }
        }
        Ok(())
    }
}

/// How a live capture ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CaptureEnd {
    /// The stop flag was set (Ctrl-C): the normal end of a capture.
    Stopped,
    /// The port closed or failed (end of file, a pseudo-terminal hung up, an adapter
    /// unplugged): why.
    Closed(String),
}

/// What a capture can fail with: the sink's error (a closed pipe, a full disk).
pub type CaptureResult<E> = Result<CaptureEnd, E>;

/// Reads a live port until it closes or `stop` is set, printing as it goes and flushing the
/// sink after each read. `port` must time out its reads (`TimedOut`/`WouldBlock`), so that the
/// flag is polled and, after `idle` of silence with an incomplete frame held, that frame is
/// given up (`None`: wait forever). The end of the stream is printed either way.
pub fn capture<S: Sink>(
    port: &mut dyn Read,
    printer: &mut Printer,
    sink: &mut S,
    stop: &AtomicBool,
    idle: Option<Duration>,
) -> CaptureResult<S::Error> {
    let mut buf = [0u8; 4096];
    let mut last_rx = Instant::now();
    let end = loop {
        if stop.load(Ordering::SeqCst) {
            break CaptureEnd::Stopped;
        }
        match port.read(&mut buf) {
            Ok(0) => break CaptureEnd::Closed("end of file".into()),
            Ok(n) => {
                last_rx = Instant::now();
                printer.push(&buf[..n], sink)?;
                sink.flush()?;
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::TimedOut
                        | io::ErrorKind::WouldBlock
                        | io::ErrorKind::Interrupted
                ) =>
            {
                if let Some(idle) = idle
                    && printer.pending_bytes() > 0
                    && last_rx.elapsed() >= idle
                {
                    printer.abandon_incomplete(sink)?;
                    sink.flush()?;
                }
            }
            // A pseudo-terminal whose other side closed reports EIO; a USB adapter unplugged
            // reports an error too.
            Err(e) => break CaptureEnd::Closed(e.to_string()),
        }
    };
    printer.finish(sink)?;
    sink.flush()?;
    Ok(end)
}

/// What reading a file or pipe through the printer ([`read_stream`]) can fail with.
#[derive(Debug, thiserror::Error)]
pub enum StreamError<E: std::error::Error + 'static> {
    /// Opening or reading the stream failed.
    #[error(transparent)]
    Read(IoError),
    /// The sink failed (a closed pipe, a full disk).
    #[error(transparent)]
    Sink(E),
}

/// Reads a file (`None` or `-`: standard input) to its end, printing as it goes, or until
/// `stop` is set; true if the flag ended it. The stream is read through a [`StopReader`], so
/// a pipe from a live process that stays silent cannot keep a signal from being seen (the flag
/// is polled every 100 ms). The end of the stream is printed either way.
pub fn read_stream<S: Sink>(
    path: Option<&Path>,
    printer: &mut Printer,
    sink: &mut S,
    stop: &AtomicBool,
) -> Result<bool, StreamError<S::Error>>
where
    S::Error: std::error::Error + 'static,
{
    let mut reader = StopReader::open(path, stop);
    let stopped = loop {
        match reader.next_chunk() {
            Ok(Some(chunk)) => printer.push(&chunk, sink).map_err(StreamError::Sink)?,
            Ok(None) => break false,
            Err(_) if stop.load(Ordering::SeqCst) => break true,
            Err(e) => return Err(StreamError::Read(e)),
        }
    };
    printer.finish(sink).map_err(StreamError::Sink)?;
    Ok(stopped)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Default)]
    struct Collect {
        records: Vec<Record>,
        notices: Vec<String>,
    }

    impl Sink for Collect {
        type Error = std::convert::Infallible;
        fn record(&mut self, record: &Record) -> Result<(), Self::Error> {
            self.records.push(record.clone());
            Ok(())
        }
        fn notice(&mut self, text: &str) {
            self.notices.push(text.to_string());
        }
    }

    fn frame(src_dst: u8, payload: &[u8]) -> Vec<u8> {
        let mut out = vec![0x55, src_dst, payload.len() as u8];
        out.extend_from_slice(payload);
        let crc = crc::Crc::<u16>::new(&crc::CRC_16_XMODEM).checksum(&out[1..]);
        out.extend_from_slice(&crc.to_be_bytes());
        out
    }

    #[test]
    fn frames_garbage_and_bad_messages_are_records_and_notices() {
        let good = frame(0x01, &[0x80, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
        let mut stream = vec![0xaa, 0xbb];
        stream.extend_from_slice(&good);
        let mut bad = good.clone();
        bad[4] ^= 0x40;
        stream.extend_from_slice(&bad);
        stream.extend_from_slice(&frame(0x01, &[1, 2]));
        let mut printer = Printer::new("in.bin", false, false);
        let mut sink = Collect::default();
        for piece in stream.chunks(5) {
            printer.push(piece, &mut sink).unwrap();
        }
        printer.finish(&mut sink).unwrap();
        assert_eq!(sink.records.len(), 2);
        assert_eq!(sink.records[0].offset, 2);
        let line = sink.records[0].text_line();
        assert!(
            line.starts_with("@2         0->1  operator oid=1"),
            "{line}"
        );
        let json = Value::Object(sink.records[0].object()).to_string();
        assert!(
            json.starts_with(r#"{"offset":2,"type":"operator","src":0,"dst":1"#),
            "{json}"
        );
        assert_eq!(sink.records[0].csv_fields().len(), CSV_COLUMNS.len());
        // A 2-byte operator payload: a raw message, with its reason.
        let raw = &sink.records[1];
        assert!(
            raw.error.is_some() && raw.text_line().contains("[invalid: "),
            "{raw:?}"
        );
        assert!(
            sink.notices
                .iter()
                .any(|n| n.starts_with("in.bin: offset 0: skipped 2 bytes")),
            "{:?}",
            sink.notices
        );
        assert!(
            sink.notices.iter().any(|n| n.contains("CRC failure")),
            "{:?}",
            sink.notices
        );
        let summary = printer.summary();
        assert_eq!((summary.stats.frames, summary.invalid_messages), (2, 1));
        assert!(!printer.clean());
        assert!(
            printer
                .summary_line()
                .starts_with("in.bin: 2 frames ok (1 invalid messages), 1 CRC failures")
        );
    }

    #[test]
    fn a_capture_ends_when_the_port_closes_or_the_flag_is_set() {
        let good = frame(0x01, &[0x80, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
        let mut printer = Printer::new("port", true, true);
        let mut sink = Collect::default();
        let never = AtomicBool::new(false);
        let end = capture(&mut &good[..], &mut printer, &mut sink, &never, None).unwrap();
        assert_eq!(end, CaptureEnd::Closed("end of file".into()));
        assert_eq!(sink.records.len(), 1);
        assert!(sink.records[0].t_s.is_some());
        let set = AtomicBool::new(true);
        let end = capture(&mut &good[..], &mut printer, &mut sink, &set, None).unwrap();
        assert_eq!(end, CaptureEnd::Stopped);
        assert!(sink.notices.is_empty());
    }
}
