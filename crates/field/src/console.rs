//! The live operator console's orders: `--orders PATH`, JSON Lines, one order a line.
//!
//! Each line is an order in wire.md's JSON form (the `order` object of an operator message:
//! `velocity`, `goto`, `image_settings`, `hold_heading`) or `{"type":"cancel"}`, read by
//! [`Live::parse`]; an optional `"t_s"` field (session seconds, finite, 0 ..= a week) says when
//! it is due. An order never overtakes the line before it: a line is due at its `t_s` or at the
//! previous line's time, whichever is later; a line without `t_s` is due with the previous one
//! (in simulation: at 0 for the first) or, in real time, as soon as it is read. In a
//! multi-vehicle network an optional `"vehicle"` field (an address 1..=14) names the vehicle
//! it is for ([`OrderSource::poll_addressed`]; without it, the first vehicle); a single-vehicle
//! session ignores it.
//!
//! Two ways of reading, chosen by the caller:
//! - simulation (`live = false`): the whole input (at most [`MAX_ORDERS_BYTES`]) is read when it
//!   is opened, and each order is due at its time, so virtual time jumps to it
//!   ([`OrderSource::next_at`]);
//! - real time (`live = true`): a reader thread hands lines over as they come, so a pipe, a
//!   FIFO or a terminal is read while the session runs. A regular file is read to its end once;
//!   standard input and pipes until they close; a FIFO never ends (it is opened for reading
//!   and writing, so writers come and go: `echo '{...}' > fifo` can be repeated).
//!
//! No-panic, no-hang contract: any bytes give orders or warnings, never a panic. A bad line
//! (not UTF-8, longer than [`MAX_LINE_BYTES`], not an order) is skipped with a warning
//! `PATH: line N: <error>` ([`OrderSource::take_warnings`]); at most [`MAX_WARNINGS`] wait
//! between two takes, the rest are counted in one line. The session never waits for the
//! reader thread; the thread holds at most a few lines, and orders read but not yet due are at
//! most [`MAX_PENDING`] (then the thread waits). Only a path that cannot be opened is an error
//! ([`ConsoleError`]), at start.
//!
//! Whoever can write to the orders commands the vehicle: a path (a file or a FIFO) owned by
//! another user, or writable by group or others, is refused before a byte of it is read
//! ([`rovlink_base::secret::open_command_source`]: checked on the open handle, opened without
//! waiting for a FIFO's writer). Standard input (`-`) is what the user gave the tool.

use std::collections::VecDeque;
use std::fs::File;
use std::io::{self, BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, sync_channel};

use rovlink_base::secret::SecretFileError;
use rovlink_link::SimTime;
use rovlink_rcp::config::MAX_DURATION_S;
use rovlink_rcp::orders::{Live, LiveError, OrderSource, Script, object_of};
use rovlink_wire::json::JsonError;

/// The most bytes of orders read in simulation (the whole input is read at start).
pub const MAX_ORDERS_BYTES: u64 = 64 << 20;

/// The longest line taken, bytes; a longer one is skipped with a warning.
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// The most orders read in real time but not yet due (their `t_s` ahead); the reader thread
/// waits while there are this many.
pub const MAX_PENDING: usize = 4096;

/// The most warnings kept between two [`OrderSource::take_warnings`]; more are counted.
pub const MAX_WARNINGS: usize = 1000;

/// Lines the reader thread may have read ahead of the session.
const CHANNEL_LINES: usize = 64;

/// Why the orders cannot be read at all.
#[derive(Debug, thiserror::Error)]
pub enum ConsoleError {
    /// The path cannot be opened (missing, no permission).
    #[error("{}: cannot open the orders: {source}", path.display())]
    Open {
        /// The path.
        path: PathBuf,
        /// The reason.
        source: io::Error,
    },
    /// The path is owned by another user or writable by group or others: whoever can write
    /// to it could command the vehicle.
    #[error("{0}")]
    Refused(SecretFileError),
    /// The path is a directory.
    #[error(
        "{}: a directory: --orders reads a file, a FIFO or - (standard input)",
        path.display()
    )]
    Directory {
        /// The path.
        path: PathBuf,
    },
    /// More than [`MAX_ORDERS_BYTES`] (simulation reads everything at start).
    #[error("{name}: more than {} MiB of orders", MAX_ORDERS_BYTES >> 20)]
    TooBig {
        /// The path, or `<stdin>`.
        name: String,
    },
    /// Reading failed (simulation reads everything at start).
    #[error("{name}: cannot read the orders: {source}")]
    Read {
        /// The path, or `<stdin>`.
        name: String,
        /// The reason.
        source: io::Error,
    },
}

/// One console line read: the order and its `t_s`, if it has one.
pub fn parse_line(line: &str) -> Result<(Option<f64>, Live), LiveError> {
    parse_addressed_line(line).map(|(t_s, _, live)| (t_s, live))
}

/// One console line read: its `t_s` and its `vehicle` (an address 1..=14), each if it has
/// one, and the order.
pub fn parse_addressed_line(line: &str) -> Result<(Option<f64>, Option<u8>, Live), LiveError> {
    let map = object_of(line)?;
    let vehicle = match map.get("vehicle") {
        None => None,
        Some(value) => match value.as_u64() {
            Some(v @ 1..=14) => u8::try_from(v).ok(),
            _ => {
                return Err(JsonError::BadValue {
                    field: "vehicle".into(),
                    expected: "a vehicle address 1..=14".into(),
                    found: rovlink_wire::json::show(value),
                }
                .into());
            }
        },
    };
    let t_s = match map.get("t_s") {
        None => None,
        Some(value) => match value.as_f64() {
            Some(t) if t.is_finite() && (0.0..=MAX_DURATION_S).contains(&t) => Some(t),
            _ => {
                return Err(JsonError::BadValue {
                    field: "t_s".into(),
                    expected: format!("session seconds, 0 ..= {MAX_DURATION_S}"),
                    found: rovlink_wire::json::show(value),
                }
                .into());
            }
        },
    };
    Ok((t_s, vehicle, Live::from_object(&map)?))
}

/// A console line's order: when it is due (if it says), the vehicle it names, the order.
type Parsed = (Option<f64>, Option<u8>, Live);

/// A line's bytes as an order, or the warning's text (without the `PATH: line N: ` prefix).
fn read_order(bytes: &[u8], too_long: bool) -> Option<Result<Parsed, String>> {
    if too_long {
        return Some(Err(format!(
            "longer than {MAX_LINE_BYTES} bytes: not an order"
        )));
    }
    let bytes = bytes.strip_suffix(b"\r").unwrap_or(bytes);
    let Ok(text) = std::str::from_utf8(bytes) else {
        return Some(Err("not UTF-8 text".into()));
    };
    if text.trim().is_empty() {
        return None;
    }
    Some(parse_addressed_line(text).map_err(|e| e.to_string()))
}

/// Warnings, at most [`MAX_WARNINGS`] kept; the rest counted.
#[derive(Default)]
struct Warnings {
    lines: Vec<String>,
    dropped: u64,
}

impl Warnings {
    fn push(&mut self, line: String) {
        if self.lines.len() < MAX_WARNINGS {
            self.lines.push(line);
        } else {
            self.dropped += 1;
        }
    }

    fn take(&mut self, name: &str) -> Vec<String> {
        let mut lines = std::mem::take(&mut self.lines);
        if self.dropped > 0 {
            lines.push(format!(
                "{name}: {} more bad lines skipped",
                std::mem::take(&mut self.dropped)
            ));
        }
        lines
    }
}

/// Orders of a whole text, each at its time (see the module doc), and the warnings for the
/// lines skipped. `name` starts each warning.
pub fn parse_orders(name: &str, text: &[u8]) -> (Vec<(SimTime, Live)>, Vec<String>) {
    let mut warnings = Warnings::default();
    let orders = parse_text(name, text, &mut warnings)
        .into_iter()
        .map(|(t, _, live)| (t, live))
        .collect();
    (orders, warnings.take(name))
}

fn parse_text(
    name: &str,
    text: &[u8],
    warnings: &mut Warnings,
) -> Vec<(SimTime, Option<u8>, Live)> {
    let mut orders = Vec::new();
    let mut due_s = 0.0f64;
    for (k, line) in text.split(|&b| b == b'\n').enumerate() {
        match read_order(line, line.len() > MAX_LINE_BYTES) {
            None => {}
            Some(Ok((t_s, vehicle, live))) => {
                due_s = due_s.max(t_s.unwrap_or(due_s));
                orders.push((SimTime::from_secs_f64(due_s), vehicle, live));
            }
            Some(Err(error)) => warnings.push(format!("{name}: line {}: {error}", k + 1)),
        }
    }
    orders
}

/// The `--orders` source: a file read at start (simulation) or lines as they come (real
/// time). See the module doc.
pub struct JsonOrders {
    name: String,
    mode: Mode,
    warnings: Warnings,
}

enum Mode {
    /// Everything read at start.
    Timed(Script),
    /// A reader thread's lines.
    Live(LiveLines),
}

/// What the reader thread hands over.
enum FromReader {
    /// A line that is an order, or a warning for one that is not.
    Line {
        number: u64,
        parsed: Result<Parsed, String>,
    },
    /// Nothing more: why, if it is worth saying.
    End(Option<String>),
}

struct LiveLines {
    lines: Receiver<FromReader>,
    /// Orders read, not yet due: (due time, vehicle named, order) in the order read.
    pending: VecDeque<(Option<SimTime>, Option<u8>, Live)>,
    /// The latest due time given so far (an order never overtakes the one before).
    last_due: SimTime,
    ended: bool,
}

/// Opens `--orders PATH` (`-` is standard input); `live` chooses how it is read (see the
/// module doc). A path that does not exist, cannot be opened, is a directory, is owned by
/// another user or is writable by group or others is an error;
/// in simulation so is input that cannot be read or is over [`MAX_ORDERS_BYTES`]. Bad lines
/// are warnings, never errors.
pub fn open_orders(path: &Path, live: bool) -> Result<JsonOrders, ConsoleError> {
    let stdin = rovlink_base::io::is_std(Some(path));
    let name = rovlink_base::io::display_name(Some(path), "<stdin>");
    let source = if stdin {
        Source::Stdin
    } else {
        // Checked on the open handle before a byte is read (see the module doc); a live
        // FIFO is kept open for writing too, so writers may come and go (Linux's fifo(7))
        // without a line written between one writer's close and a reopen being lost.
        let (file, meta) =
            rovlink_base::secret::open_command_source(path, live).map_err(|e| match e {
                SecretFileError::Read { source, .. } => ConsoleError::Open {
                    path: path.to_path_buf(),
                    source,
                },
                refused => ConsoleError::Refused(refused),
            })?;
        if meta.is_dir() {
            return Err(ConsoleError::Directory {
                path: path.to_path_buf(),
            });
        }
        Source::File(file)
    };
    let mut warnings = Warnings::default();
    let mode = if live {
        let (tx, rx) = sync_channel(CHANNEL_LINES);
        let thread_name = name.clone();
        std::thread::Builder::new()
            .name("orders".into())
            .spawn(move || read_lines(&thread_name, source, &tx))
            .map_err(|e| ConsoleError::Read {
                name: name.clone(),
                source: e,
            })?;
        Mode::Live(LiveLines {
            lines: rx,
            pending: VecDeque::new(),
            last_due: SimTime::ZERO,
            ended: false,
        })
    } else {
        let read = match source {
            Source::Stdin => rovlink_base::io::read_bounded(io::stdin().lock(), MAX_ORDERS_BYTES),
            Source::File(file) => rovlink_base::io::read_bounded(file, MAX_ORDERS_BYTES),
        };
        let text = read
            .map_err(|source| ConsoleError::Read {
                name: name.clone(),
                source,
            })?
            .ok_or_else(|| ConsoleError::TooBig { name: name.clone() })?;
        let orders = parse_text(&name, &text, &mut warnings);
        Mode::Timed(Script::addressed(orders))
    };
    Ok(JsonOrders {
        name,
        mode,
        warnings,
    })
}

/// Where the reader thread reads.
enum Source {
    Stdin,
    /// A regular file, a pipe, a device, a FIFO: read until it ends (a FIFO opened for
    /// reading and writing never does).
    File(File),
}

/// The reader thread: lines to `tx` until the input ends or the receiver is gone.
fn read_lines(name: &str, source: Source, tx: &SyncSender<FromReader>) {
    let mut number = 0u64;
    let mut line = Vec::new();
    let end = match source {
        Source::Stdin => pump(&mut io::stdin().lock(), &mut number, &mut line, tx),
        Source::File(file) => {
            let regular = file.metadata().is_ok_and(|m| m.is_file());
            match pump(&mut BufReader::new(file), &mut number, &mut line, tx) {
                Pumped::Ended if regular => Pumped::Quiet,
                other => other,
            }
        }
    };
    let said = match end {
        Pumped::Gone => return,
        Pumped::Quiet => None,
        Pumped::Ended => Some(format!(
            "{name}: closed after {number} lines: no more orders"
        )),
        Pumped::Failed(e) => Some(format!(
            "{name}: cannot read the orders after line {number}: {e}; no more orders"
        )),
    };
    let _ = tx.send(FromReader::End(said));
}

/// How a [`pump`] ended.
enum Pumped {
    /// End of input.
    Ended,
    /// End of input not worth a word (a regular file read through).
    Quiet,
    /// A read error.
    Failed(io::Error),
    /// Nobody listens any more.
    Gone,
}

/// Reads lines from `reader` to `tx`, numbering them from `number` on.
fn pump(
    reader: &mut impl BufRead,
    number: &mut u64,
    line: &mut Vec<u8>,
    tx: &SyncSender<FromReader>,
) -> Pumped {
    loop {
        let too_long = match read_line_bounded(reader, line, MAX_LINE_BYTES) {
            Ok(Some(too_long)) => too_long,
            Ok(None) => return Pumped::Ended,
            Err(e) => return Pumped::Failed(e),
        };
        *number += 1;
        if let Some(parsed) = read_order(line, too_long) {
            let sent = tx.send(FromReader::Line {
                number: *number,
                parsed,
            });
            if sent.is_err() {
                return Pumped::Gone;
            }
        }
    }
}

/// Reads one line (without its newline) into `line`, keeping at most `max_bytes` of it:
/// `Some(true)` when it was longer (the rest is read and dropped), `None` at the end of input
/// with nothing read. Interrupted reads are retried.
fn read_line_bounded(
    reader: &mut impl BufRead,
    line: &mut Vec<u8>,
    max_bytes: usize,
) -> io::Result<Option<bool>> {
    line.clear();
    let (mut too_long, mut any) = (false, false);
    loop {
        let available = match reader.fill_buf() {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if available.is_empty() {
            return Ok(any.then_some(too_long));
        }
        any = true;
        let newline = available.iter().position(|&b| b == b'\n');
        let take = newline.unwrap_or(available.len());
        let room = max_bytes.saturating_sub(line.len());
        too_long |= take > room;
        line.extend_from_slice(&available[..take.min(room)]);
        reader.consume(newline.map_or(take, |n| n + 1));
        if newline.is_some() {
            return Ok(Some(too_long));
        }
    }
}

impl JsonOrders {
    /// The name warnings carry: the path, or `<stdin>`.
    pub fn name(&self) -> &str {
        &self.name
    }
}

impl OrderSource for JsonOrders {
    fn poll(&mut self, now: SimTime) -> Vec<Live> {
        self.poll_addressed(now)
            .into_iter()
            .map(|(_, live)| live)
            .collect()
    }

    fn poll_addressed(&mut self, now: SimTime) -> Vec<(Option<u8>, Live)> {
        let live = match &mut self.mode {
            Mode::Timed(script) => return script.poll_addressed(now),
            Mode::Live(live) => live,
        };
        while !live.ended && live.pending.len() < MAX_PENDING {
            match live.lines.try_recv() {
                Ok(FromReader::Line {
                    parsed: Ok((t_s, vehicle, order)),
                    ..
                }) => {
                    let due = t_s.map(SimTime::from_secs_f64);
                    live.pending.push_back((due, vehicle, order));
                }
                Ok(FromReader::Line {
                    number,
                    parsed: Err(error),
                }) => self
                    .warnings
                    .push(format!("{}: line {number}: {error}", self.name)),
                Ok(FromReader::End(said)) => {
                    live.ended = true;
                    said.into_iter().for_each(|line| self.warnings.push(line));
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => live.ended = true,
            }
        }
        let mut due = Vec::new();
        while let Some((t, _, _)) = live.pending.front() {
            let at = t.unwrap_or(now).max(live.last_due);
            if at > now {
                break;
            }
            live.last_due = at;
            if let Some((_, vehicle, order)) = live.pending.pop_front() {
                due.push((vehicle, order));
            }
        }
        due
    }

    fn next_at(&self) -> Option<SimTime> {
        match &self.mode {
            Mode::Timed(script) => script.next_at(),
            Mode::Live(live) => live
                .pending
                .front()
                .and_then(|(t, _, _)| *t)
                .map(|t| t.max(live.last_due)),
        }
    }

    fn take_warnings(&mut self) -> Vec<String> {
        self.warnings.take(&self.name)
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;
    use std::time::{Duration, Instant};

    use super::*;
    use proptest::strategy::Strategy;
    use rovlink_wire::operator::Order;

    const GOTO: &str = r#"{"type":"goto","x_cm":300,"y_cm":0,"z_cm":50,"heading_deg":90"#;

    fn at(t_s: f64) -> SimTime {
        SimTime::from_secs_f64(t_s)
    }

    fn goto_x(live: &Live) -> Option<i16> {
        match live {
            Live::Order(Order::GoTo { x_cm, .. }) => Some(*x_cm),
            _ => None,
        }
    }

    #[test]
    fn a_line_may_name_its_vehicle() {
        let line = format!("{GOTO},\"vehicle\":2,\"t_s\":1}}");
        let (t_s, vehicle, live) = parse_addressed_line(&line).unwrap();
        assert_eq!(
            (t_s, vehicle, goto_x(&live)),
            (Some(1.0), Some(2), Some(300))
        );
        assert_eq!(parse_line(&line).unwrap().1, live);
        for bad in ["0", "15", "2.5", "\"2\"", "-1"] {
            let error = parse_addressed_line(&format!("{GOTO},\"vehicle\":{bad}}}")).unwrap_err();
            assert_eq!(
                error.to_string(),
                format!("field vehicle: expected a vehicle address 1..=14, found {bad}")
            );
        }
        let (mut orders, _) = (
            open_orders_text(&format!("{GOTO},\"vehicle\":3}}\n{GOTO}}}")),
            (),
        );
        let got = orders.poll_addressed(at(0.0));
        assert_eq!(
            got.iter().map(|(v, _)| *v).collect::<Vec<_>>(),
            [Some(3), None]
        );
    }

    /// A simulation's `--orders` source over `text`.
    fn open_orders_text(text: &str) -> JsonOrders {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("orders.jsonl");
        std::fs::write(&path, text).unwrap();
        open_orders(&path, false).unwrap()
    }

    #[test]
    fn a_file_gives_each_order_at_its_time_and_warns_of_bad_lines_by_number() {
        let text = format!(
            "{GOTO},\"t_s\":2}}\r\n\n{{\"type\":\"cancel\"}}\nnot json\n{GOTO},\"t_s\":-1}}\n\
             {GOTO},\"t_s\":1}}\n\u{1}\n{{\"type\":\"hold_heading\",\"heading_deg\":10,\"enable\":true,\"t_s\":5.5}}"
        );
        let mut bytes = text.into_bytes();
        for b in bytes.iter_mut().filter(|b| **b == 1) {
            *b = 0xff;
        }
        let (orders, warnings) = parse_orders("o.jsonl", &bytes);
        let times: Vec<f64> = orders.iter().map(|(t, _)| t.as_secs_f64()).collect();
        // The cancel goes with the line before it, and the line at 1 s does not overtake 2 s.
        assert_eq!(times, [2.0, 2.0, 2.0, 5.5]);
        assert_eq!(orders[1].1, Live::Cancel);
        assert_eq!(warnings.len(), 3, "{warnings:?}");
        assert!(
            warnings[0].starts_with("o.jsonl: line 4: not valid JSON at column 2"),
            "{}",
            warnings[0]
        );
        assert_eq!(
            warnings[1],
            "o.jsonl: line 5: field t_s: expected session seconds, 0 ..= 604800, found -1"
        );
        assert_eq!(warnings[2], "o.jsonl: line 7: not UTF-8 text");
    }

    #[test]
    fn a_line_too_long_and_a_flood_of_bad_lines_are_bounded() {
        let mut text = format!("{GOTO},\"pad\":\"{}\"}}\n", "x".repeat(MAX_LINE_BYTES));
        text.push_str(&"?\n".repeat(MAX_WARNINGS + 5));
        let (orders, warnings) = parse_orders("f", text.as_bytes());
        assert!(orders.is_empty());
        assert_eq!(warnings.len(), MAX_WARNINGS + 1);
        assert_eq!(
            warnings[0],
            format!("f: line 1: longer than {MAX_LINE_BYTES} bytes: not an order")
        );
        assert_eq!(warnings[MAX_WARNINGS], "f: 6 more bad lines skipped");
    }

    #[test]
    fn in_simulation_the_file_is_read_at_start_and_virtual_time_jumps_to_each_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("orders.jsonl");
        std::fs::write(
            &path,
            format!("{GOTO},\"t_s\":3}}\nbad\n{{\"type\":\"cancel\",\"t_s\":7}}\n"),
        )
        .unwrap();
        let mut orders = open_orders(&path, false).unwrap();
        let warnings = orders.take_warnings();
        assert_eq!(warnings.len(), 1);
        assert!(warnings[0].starts_with(&format!("{}: line 2: ", path.display())));
        assert!(orders.take_warnings().is_empty());
        assert_eq!(orders.next_at(), Some(at(3.0)));
        assert!(orders.poll(at(2.9)).is_empty());
        assert_eq!(goto_x(&orders.poll(at(3.0))[0]), Some(300));
        assert_eq!(orders.next_at(), Some(at(7.0)));
        assert_eq!(orders.poll(at(100.0)), [Live::Cancel]);
        assert_eq!(orders.next_at(), None);
    }

    #[test]
    fn a_path_that_cannot_be_read_is_an_error_at_start() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("none.jsonl");
        for live in [false, true] {
            let error = open_orders(&missing, live).err().unwrap();
            assert!(
                error.to_string().starts_with(&format!(
                    "{}: cannot open the orders: No such file",
                    missing.display()
                )),
                "{error}"
            );
            let error = open_orders(dir.path(), live).err().unwrap();
            assert!(matches!(error, ConsoleError::Directory { .. }), "{error}");
        }
    }

    #[test]
    fn orders_someone_else_could_write_are_refused_before_a_byte_is_read() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("shared.fifo");
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        std::fs::set_permissions(&fifo, std::fs::Permissions::from_mode(0o666)).unwrap();
        let file = dir.path().join("group.jsonl");
        std::fs::write(&file, format!("{GOTO}}}\n")).unwrap();
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o664)).unwrap();
        // Refused, in simulation too, without waiting for the FIFO's writer.
        for live in [false, true] {
            for (path, mode) in [(&fifo, "0666"), (&file, "0664")] {
                let error = open_orders(path, live).err().unwrap();
                assert!(matches!(error, ConsoleError::Refused(_)), "{error}");
                let text = error.to_string();
                assert!(
                    text.contains(&format!("permissions {mode} are too open")),
                    "{text}"
                );
            }
        }
        if !nix::unistd::geteuid().is_root() {
            eprintln!("skipped: a file owned by another user needs root to make");
            return;
        }
        let theirs = dir.path().join("theirs.jsonl");
        std::fs::write(&theirs, format!("{GOTO}}}\n")).unwrap();
        std::os::unix::fs::chown(&theirs, Some(65534), Some(65534)).unwrap();
        for live in [false, true] {
            let text = open_orders(&theirs, live).err().unwrap().to_string();
            assert!(
                text.contains("owned by uid 65534, not by this user"),
                "{text}"
            );
        }
    }

    /// Polls `orders` until `n` orders came or 5 s passed.
    fn poll_for(orders: &mut JsonOrders, now: SimTime, n: usize) -> Vec<Live> {
        let deadline = Instant::now() + Duration::from_secs(5);
        let mut got = Vec::new();
        while got.len() < n && Instant::now() < deadline {
            got.extend(orders.poll(now));
            std::thread::sleep(Duration::from_millis(5));
        }
        got
    }

    #[test]
    fn live_a_regular_file_holds_orders_until_their_time_in_file_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("orders.jsonl");
        std::fs::write(
            &path,
            format!(
                "{GOTO},\"t_s\":4}}\n{{\"type\":\"cancel\"}}\n{{\"type\":\"cancel\",\"t_s\":1}}"
            ),
        )
        .unwrap();
        let mut orders = open_orders(&path, true).unwrap();
        let deadline = Instant::now() + Duration::from_secs(5);
        while orders.next_at().is_none() && Instant::now() < deadline {
            assert!(orders.poll(at(1.0)).is_empty());
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(orders.next_at(), Some(at(4.0)));
        let got = poll_for(&mut orders, at(4.0), 3);
        assert_eq!(got.len(), 3);
        assert_eq!(goto_x(&got[0]), Some(300));
        assert!(
            orders.take_warnings().is_empty(),
            "a file read through is no news"
        );
    }

    #[test]
    fn live_a_fifo_is_read_as_written_by_one_writer_after_another() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("orders.fifo");
        nix::unistd::mkfifo(&path, nix::sys::stat::Mode::S_IRWXU).unwrap();
        // Opening does not wait for a writer.
        let started = Instant::now();
        let mut orders = open_orders(&path, true).unwrap();
        assert!(started.elapsed() < Duration::from_secs(1));
        assert!(orders.poll(at(0.0)).is_empty());
        let mut fifo = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
        writeln!(fifo, "oops").unwrap();
        writeln!(fifo, "{GOTO}}}").unwrap();
        let got = poll_for(&mut orders, at(10.0), 1);
        assert_eq!(goto_x(&got[0]), Some(300));
        drop(fifo);
        // Writers one after another, as `echo ... > fifo` in a loop: no line is lost between
        // one writer's close and the next one's open.
        for x_cm in 1..=40 {
            let mut fifo = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
            writeln!(
                fifo,
                r#"{{"type":"goto","x_cm":{x_cm},"y_cm":0,"z_cm":0,"heading_deg":0}}"#
            )
            .unwrap();
        }
        let got = poll_for(&mut orders, at(10.0), 40);
        let xs: Vec<i16> = got.iter().filter_map(goto_x).collect();
        assert_eq!(xs, (1..=40).collect::<Vec<_>>());
        let warnings = orders.take_warnings();
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(
            warnings[0].contains(": line 1: not valid JSON"),
            "{warnings:?}"
        );
    }

    #[test]
    fn line_reading_keeps_lines_whole_and_bounded() {
        let mut reader = BufReader::with_capacity(4, &b"abcdefgh\nxy\n\nlast"[..]);
        let mut line = Vec::new();
        assert_eq!(
            read_line_bounded(&mut reader, &mut line, 5).unwrap(),
            Some(true)
        );
        assert_eq!(line, b"abcde");
        assert_eq!(
            read_line_bounded(&mut reader, &mut line, 5).unwrap(),
            Some(false)
        );
        assert_eq!(line, b"xy");
        assert_eq!(
            read_line_bounded(&mut reader, &mut line, 5).unwrap(),
            Some(false)
        );
        assert!(line.is_empty());
        assert_eq!(
            read_line_bounded(&mut reader, &mut line, 5).unwrap(),
            Some(false)
        );
        assert_eq!(line, b"last");
        assert_eq!(read_line_bounded(&mut reader, &mut line, 5).unwrap(), None);
    }

    proptest::proptest! {
        #[test]
        fn any_bytes_give_orders_in_time_order_or_numbered_warnings(
            lines in proptest::collection::vec(
                proptest::prop_oneof![
                    proptest::collection::vec(proptest::num::u8::ANY, 0..40),
                    (0.0f64..100.0).prop_map(|t| format!("{GOTO},\"t_s\":{t}}}").into_bytes()),
                    proptest::strategy::Just(br#"{"type":"cancel"}"#.to_vec()),
                ],
                0..30,
            )
        ) {
            let text = lines.join(&b'\n');
            let (orders, warnings) = parse_orders("p", &text);
            proptest::prop_assert!(orders.windows(2).all(|w| w[0].0 <= w[1].0));
            let count = text.split(|&b| b == b'\n').count();
            proptest::prop_assert!(orders.len() + warnings.len() <= count);
            for warning in &warnings {
                proptest::prop_assert!(warning.starts_with("p: line "), "{}", warning);
            }
        }
    }
}
