//! The frame printer behind `rcp-dump`: bytes in, through the [`Deframer`], out as one record
//! per frame (a line for people, a JSON object in wire.md's form, or a CSV row) plus notices
//! for people about what was not a frame (CRC failures, skipped bytes, truncated frames,
//! invalid messages), with the counters a summary reports.
//!
//! Where records and notices go is the caller's [`Sink`]; [`capture`] reads a live port until
//! it closes or a stop flag is set, giving up an incomplete frame when the line goes quiet;
//! [`read_stream`] reads a file or pipe to its end or until the flag is set.
//!
//! Secured frames (docs/wire-extensions.md) are the business of an [`Inspector`] the caller
//! gives (`rovlink-security` has one: this crate knows no keys): it says what it found of each
//! frame ([`Security`]) and hands back the plain frame to print when it opened one. Without an
//! inspector every frame prints as version 0 reads it.

use std::collections::BTreeMap;
use std::fmt;
use std::io::Read;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use serde_json::{Map, Value};

use super::frame::Frame;
use super::{DeframeEvent, DeframeStats, Deframer, Message, MessageRepr, json};
use rovlink_base::io::{IoError, StopReader};

/// The columns of a CSV of frames, in order ([`Record::csv_fields`]).
pub const CSV_COLUMNS: [&str; 50] = json::CSV_COLUMNS;

/// The columns of a CSV of frames with their security ([`Record::csv_fields_secured`]).
pub fn csv_columns_secured() -> Vec<&'static str> {
    CSV_COLUMNS
        .iter()
        .chain(&json::CSV_SECURITY_COLUMNS)
        .copied()
        .collect()
}

/// The verdict of a frame that passed verification.
pub const VERDICT_OK: &str = "ok";
/// The verdict of a secured frame shown without a key: nothing was checked.
pub const VERDICT_UNVERIFIED: &str = "unverified";

/// True when `verdict` says verification was asked for and the frame did not pass it.
fn verdict_failed(verdict: &str) -> bool {
    verdict != VERDICT_OK && verdict != VERDICT_UNVERIFIED
}

/// What was found of one frame's security (docs/wire-extensions.md, secured frames), shown
/// beside its message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Security {
    /// The payload is marked as a secured frame's (the S bit).
    pub secured: bool,
    /// The message is encrypted (the E bit).
    pub encrypted: bool,
    /// The full counter, when the tag was verified.
    pub ctr: Option<u64>,
    /// The counter's low bits as the frame carries them, when it was not verified.
    pub ctr_low: Option<u16>,
    /// [`VERDICT_OK`], [`VERDICT_UNVERIFIED`], or why the frame was refused (`bad_tag`,
    /// `replay`, `no_key`, `malformed`, `unsecured`).
    pub verdict: &'static str,
}

impl Security {
    /// True when verification was asked for and the frame did not pass it.
    pub fn failed(&self) -> bool {
        verdict_failed(self.verdict)
    }

    /// For people: `secured, encrypted, ctr 16385: ok`.
    pub fn note(&self) -> String {
        let mut text = String::from(if self.secured { "secured" } else { "plain" });
        if self.encrypted {
            text.push_str(", encrypted");
        }
        if let Some(c) = self.ctr {
            text.push_str(&format!(", ctr {c}"));
        } else if let Some(low) = self.ctr_low {
            text.push_str(&format!(", ctr low bits {low}"));
        }
        text.push_str(&format!(": {}", self.verdict));
        text
    }

    /// Appends the fields `secured`, `encrypted`, `ctr` or `ctr_low`, `verdict`.
    fn write_fields(&self, map: &mut Map<String, Value>) {
        map.insert("secured".into(), self.secured.into());
        map.insert("encrypted".into(), self.encrypted.into());
        if let Some(c) = self.ctr {
            map.insert("ctr".into(), c.into());
        } else if let Some(low) = self.ctr_low {
            map.insert("ctr_low".into(), low.into());
        }
        map.insert("verdict".into(), self.verdict.into());
    }
}

/// What an [`Inspector`] found of a frame, and what to print of it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Inspected {
    /// What was found.
    pub security: Security,
    /// The plain link frame to print (the message inside, decrypted), or `None` to print the
    /// payload as it is, as a `raw` message.
    pub plain: Option<Vec<u8>>,
}

/// Checks each frame's security for the [`Printer`].
pub trait Inspector: fmt::Debug {
    /// Looks at one whole link frame whose CRC checks: `None` leaves it to print as version 0
    /// reads it. Any bytes, never a panic.
    fn inspect(&mut self, frame: &[u8]) -> Option<Inspected>;
}

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
    /// What an [`Inspector`] found of its security (`None`: none looked, or a plain frame
    /// without a key).
    pub security: Option<Security>,
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
        if let Some(s) = &self.security {
            line.push_str(&format!("  [{}]", s.note()));
        }
        line.push('\n');
        line
    }

    /// The JSON object of wire.md's form, with `offset` first (and `t_s`, rounded to the
    /// microsecond), then the [`Security`] fields if any, and `error` last; `rcp-pack` reads
    /// it back.
    pub fn object(&self) -> Map<String, Value> {
        let mut map = Map::new();
        map.insert("offset".into(), self.offset.into());
        if let Some(t) = self.t_s {
            map.insert("t_s".into(), Value::from((t * 1e6).round() / 1e6));
        }
        json::write_fields(&self.repr, &mut map);
        if let Some(s) = &self.security {
            s.write_fields(&mut map);
        }
        if let Some(e) = &self.error {
            map.insert("error".into(), e.as_str().into());
        }
        map
    }

    /// The fields of the CSV row, one per [`CSV_COLUMNS`] entry; a frame's [`Security`], which
    /// has no column there, is said in the `error` column.
    pub fn csv_fields(&self) -> Vec<String> {
        let mut map = self.object();
        if let Some(s) = &self.security {
            let text = match &self.error {
                Some(e) => format!("{e}; {}", s.note()),
                None => s.note(),
            };
            map.insert("error".into(), text.into());
        }
        json::csv_record(&map)
    }

    /// The fields of the CSV row with the security columns: one per [`CSV_COLUMNS`] entry,
    /// then one per [`json::CSV_SECURITY_COLUMNS`] entry.
    pub fn csv_fields_secured(&self) -> Vec<String> {
        json::csv_record_in(&self.object(), &csv_columns_secured())
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
    /// Frames per [`Security::verdict`], when an [`Inspector`] gave any (absent otherwise).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub verdicts: BTreeMap<&'static str, u64>,
}

/// The printer: a deframer, the notices it gives, and the counters.
#[derive(Debug)]
pub struct Printer {
    name: String,
    quiet: bool,
    started: Option<Instant>,
    deframer: Deframer,
    invalid: u64,
    inspector: Option<Box<dyn Inspector>>,
    verdicts: BTreeMap<&'static str, u64>,
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
            inspector: None,
            verdicts: BTreeMap::new(),
        }
    }

    /// The same printer, with `inspector` looking at every frame's security.
    pub fn with_inspector(mut self, inspector: Box<dyn Inspector>) -> Printer {
        self.inspector = Some(inspector);
        self
    }

    /// Frames that did not pass verification ([`Security::failed`]).
    pub fn failed_verification(&self) -> u64 {
        self.verdicts
            .iter()
            .filter(|(v, _)| verdict_failed(v))
            .map(|(_, n)| n)
            .sum()
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
            verdicts: self.verdicts.clone(),
        }
    }

    /// The summary as one line for people.
    pub fn summary_line(&self) -> String {
        let s = self.deframer.stats();
        let mut line = format!(
            "{}: {} frames ok ({} invalid messages), {} CRC failures, {} truncated, {} of {} bytes skipped",
            self.name,
            s.frames,
            self.invalid,
            s.crc_failures,
            s.truncated,
            s.bytes_skipped,
            s.bytes_in
        );
        if !self.verdicts.is_empty() {
            let counts: Vec<String> = self
                .verdicts
                .iter()
                .map(|(v, n)| format!("{n} {v}"))
                .collect();
            line.push_str(&format!("; verdicts: {}", counts.join(", ")));
        }
        line
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
                    let bytes = frame.into_inner();
                    let inspected = self.inspector.as_mut().and_then(|i| i.inspect(bytes));
                    let (repr, error, security) = match inspected {
                        None => {
                            let (repr, error) =
                                MessageRepr::parse_lenient(&Frame::new_unchecked(bytes));
                            (repr, error, None)
                        }
                        Some(Inspected {
                            security,
                            plain: Some(plain),
                        }) => {
                            let (repr, error) =
                                MessageRepr::parse_lenient(&Frame::new_unchecked(&plain[..]));
                            (repr, error, Some(security))
                        }
                        Some(Inspected {
                            security,
                            plain: None,
                        }) => {
                            let f = Frame::new_unchecked(bytes);
                            let repr = MessageRepr {
                                src: f.src(),
                                dst: f.dst(),
                                message: Message::Raw(f.payload().to_vec()),
                            };
                            (repr, None, Some(security))
                        }
                    };
                    let error = error.map(|e| e.to_string());
                    if let Some(e) = &error {
                        self.invalid += 1;
                        say(
                            sink,
                            format!("offset {offset}: invalid message from {}: {e}", repr.src),
                        );
                    }
                    if let Some(s) = &security {
                        *self.verdicts.entry(s.verdict).or_default() += 1;
                        if s.failed() {
                            say(
                                sink,
                                format!(
                                    "offset {offset}: frame {}->{} refused: {}",
                                    repr.src, repr.dst, s.verdict
                                ),
                            );
                        }
                    }
                    sink.record(&Record {
                        offset,
                        t_s,
                        repr,
                        error,
                        security,
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
            Err(e) if rovlink_base::io::nothing_yet(&e) => {
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
        assert!(json::parse_object(&raw.object()).is_ok(), "{raw:?}");
        let summary = printer.summary();
        assert_eq!((summary.stats.frames, summary.invalid_messages), (2, 1));
        assert!(!printer.clean());
        assert!(
            printer
                .summary_line()
                .starts_with("in.bin: 2 frames ok (1 invalid messages), 1 CRC failures")
        );
    }

    /// Names every frame with a payload of 3 bytes or more secured, opening those 0->1.
    #[derive(Debug)]
    struct Marks;

    impl Inspector for Marks {
        fn inspect(&mut self, frame: &[u8]) -> Option<Inspected> {
            let f = Frame::new_checked(frame).ok()?;
            (f.payload_len() >= 3).then(|| {
                let open = f.dst() == 1;
                Inspected {
                    security: Security {
                        secured: true,
                        encrypted: open,
                        ctr: open.then_some(7),
                        ctr_low: (!open).then_some(7),
                        verdict: if open { VERDICT_OK } else { "bad_tag" },
                    },
                    plain: open.then(|| frame.to_vec()),
                }
            })
        }
    }

    #[test]
    fn an_inspector_adds_the_verdict_and_failures_are_counted() {
        let good = frame(0x01, &[0x80, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
        let refused = frame(0x02, &[0x20, 7, 1, 2, 3, 4]);
        let plain = frame(0x10, &[0x80, 0]);
        let mut printer = Printer::new("s", false, false).with_inspector(Box::new(Marks));
        let mut sink = Collect::default();
        printer
            .push(&[good, refused, plain].concat(), &mut sink)
            .unwrap();
        let [ok, bad, other] = &sink.records[..] else {
            panic!("{:?}", sink.records)
        };
        assert!(
            ok.text_line()
                .ends_with("  [secured, encrypted, ctr 7: ok]\n"),
            "{}",
            ok.text_line()
        );
        let json = Value::Object(bad.object()).to_string();
        assert!(
            json.ends_with(
                r#""payload":"200701020304","secured":true,"encrypted":false,"ctr_low":7,"verdict":"bad_tag"}"#
            ),
            "{json}"
        );
        assert_eq!(other.security, None);
        let csv = bad.csv_fields();
        assert_eq!(
            csv.last().unwrap(),
            "secured, ctr low bits 7: bad_tag",
            "no security columns: the note is in the error column"
        );
        let secured = ok.csv_fields_secured();
        assert_eq!(secured.len(), csv_columns_secured().len());
        assert_eq!(
            &secured[secured.len() - 5..],
            ["true", "true", "7", "", "ok"]
        );
        assert_eq!(printer.failed_verification(), 1);
        // rcp-pack reads each record back: what a dump adds is known to it.
        for record in &sink.records {
            assert!(json::parse_object(&record.object()).is_ok(), "{record:?}");
        }
        assert_eq!(sink.notices[0], "s: offset 16: frame 0->2 refused: bad_tag");
        let summary = serde_json::to_value(printer.summary()).unwrap();
        assert_eq!(
            summary["verdicts"],
            serde_json::json!({"bad_tag": 1, "ok": 1})
        );
        assert!(
            printer
                .summary_line()
                .ends_with("; verdicts: 1 bad_tag, 1 ok"),
            "{}",
            printer.summary_line()
        );
        let quiet = Printer::new("q", true, false);
        assert!(
            serde_json::to_value(quiet.summary())
                .unwrap()
                .get("verdicts")
                .is_none()
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
        assert!(json::parse_object(&sink.records[0].object()).is_ok());
        let set = AtomicBool::new(true);
        let end = capture(&mut &good[..], &mut printer, &mut sink, &set, None).unwrap();
        assert_eq!(end, CaptureEnd::Stopped);
        assert!(sink.notices.is_empty());
    }
}
