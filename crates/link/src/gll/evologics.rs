//! The EvoLogics S2C AT dialect: the commands a host writes, the notifications a modem writes,
//! and an [`Endpoint`] that speaks it.
//!
//! Lines end in `\r\n`. The data field of `AT*SEND`, `AT*SENDIM`, `RECV` and `RECVIM` is binary
//! and may contain `\r\n` itself, so it is read by its announced length, not up to a line end.
//! Commands may carry the data-mode escape `+++` in front (`+++AT*SEND,...`); it is accepted
//! and ignored. Formats (facts.md):
//!
//! - `AT*SEND,<len>,<dst>,<data>`: a burst;
//! - `AT*SENDIM,<len>,<dst>,<ack|noack>,<data>`: an instant message (up to 64 bytes);
//! - `RECV,<len>,<src>,<dst>,<bitrate>,<rssi>,<integrity>,<ptime>,<velocity>,<data>`;
//! - `RECVIM,<len>,<src>,<dst>,<ack|noack>,<duration>,<rssi>,<integrity>,<velocity>,<data>`;
//! - `DELIVEREDIM,<dst>`, `FAILEDIM,<dst>`, `SENDSTART,...`, `SENDEND,...`, `OK`,
//!   `ERROR <reason>`, `BUSY <reason>`, and any other line.
//!
//! The parsers never panic: bytes that do not form a known item come out as `Other` lines (or
//! are skipped up to the next line end), and a buffer never holds more than one maximal item.

use std::collections::VecDeque;
use std::time::Instant;

use super::{Endpoint, GllError, Received, TimedRead};

/// Largest data field accepted in a burst, bytes.
pub const MAX_BURST_BYTES: usize = 1024;
/// Largest data field of an instant message, bytes.
pub const MAX_IM_BYTES: usize = 64;
/// Integrity below which a received packet is reported as damaged (the modem's own scale).
pub const INTEGRITY_THRESHOLD: u32 = 90;
/// The destination address every modem in range takes: the broadcast address.
pub const BROADCAST_ADDRESS: u32 = 255;

/// A command from the host.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `AT*SEND`: a burst to `dst`.
    Send {
        /// Destination address.
        dst: u32,
        /// The data.
        data: Vec<u8>,
    },
    /// `AT*SENDIM`: an instant message to `dst`, acknowledged or not.
    SendIm {
        /// Destination address.
        dst: u32,
        /// Ask for a delivery report.
        ack: bool,
        /// The data.
        data: Vec<u8>,
    },
    /// Any other line (`AT?T`, settings...), without its line end.
    Other(String),
}

/// A notification or reply from the modem.
#[derive(Debug, Clone, PartialEq)]
pub enum Notification {
    /// `RECV`: a burst arrived.
    Recv {
        /// Source address.
        src: u32,
        /// Destination address.
        dst: u32,
        /// Bit rate of the reception, bit/s.
        bitrate: u32,
        /// Signal strength, dB.
        rssi: i32,
        /// Integrity (100: clean).
        integrity: u32,
        /// Propagation time, µs.
        ptime_us: u64,
        /// Relative velocity, m/s.
        velocity: f64,
        /// The data.
        data: Vec<u8>,
    },
    /// `RECVIM`: an instant message arrived.
    RecvIm {
        /// Source address.
        src: u32,
        /// Destination address.
        dst: u32,
        /// Whether the sender asked for an acknowledgement.
        ack: bool,
        /// Duration of the reception, µs.
        duration_us: u64,
        /// Signal strength, dB.
        rssi: i32,
        /// Integrity (100: clean).
        integrity: u32,
        /// Relative velocity, m/s.
        velocity: f64,
        /// The data.
        data: Vec<u8>,
    },
    /// `DELIVEREDIM,<dst>`.
    DeliveredIm(u32),
    /// `FAILEDIM,<dst>`.
    FailedIm(u32),
    /// `OK`.
    Ok,
    /// `ERROR <reason>`.
    Error(String),
    /// `BUSY <reason>`.
    Busy(String),
    /// Any other line (`SENDSTART,...`, `SENDEND,...`, answers to queries).
    Other(String),
}

/// Formats a command as the bytes a host writes.
pub fn format_command(command: &Command) -> Vec<u8> {
    let mut out = Vec::new();
    match command {
        Command::Send { dst, data } => {
            out.extend(format!("AT*SEND,{},{dst},", data.len()).bytes());
            out.extend(data);
        }
        Command::SendIm { dst, ack, data } => {
            let ack = if *ack { "ack" } else { "noack" };
            out.extend(format!("AT*SENDIM,{},{dst},{ack},", data.len()).bytes());
            out.extend(data);
        }
        Command::Other(line) => out.extend(line.bytes()),
    }
    out.extend(b"\r\n");
    out
}

/// Formats a notification as the bytes a modem writes.
pub fn format_notification(notification: &Notification) -> Vec<u8> {
    let mut out = Vec::new();
    match notification {
        Notification::Recv {
            src,
            dst,
            bitrate,
            rssi,
            integrity,
            ptime_us,
            velocity,
            data,
        } => {
            out.extend(
                format!(
                    "RECV,{},{src},{dst},{bitrate},{rssi},{integrity},{ptime_us},{velocity:.2},",
                    data.len()
                )
                .bytes(),
            );
            out.extend(data);
        }
        Notification::RecvIm {
            src,
            dst,
            ack,
            duration_us,
            rssi,
            integrity,
            velocity,
            data,
        } => {
            let ack = if *ack { "ack" } else { "noack" };
            out.extend(
                format!(
                    "RECVIM,{},{src},{dst},{ack},{duration_us},{rssi},{integrity},{velocity:.2},",
                    data.len()
                )
                .bytes(),
            );
            out.extend(data);
        }
        Notification::DeliveredIm(dst) => out.extend(format!("DELIVEREDIM,{dst}").bytes()),
        Notification::FailedIm(dst) => out.extend(format!("FAILEDIM,{dst}").bytes()),
        Notification::Ok => out.extend(b"OK"),
        Notification::Error(reason) => out.extend(format!("ERROR {reason}").bytes()),
        Notification::Busy(reason) => out.extend(format!("BUSY {reason}").bytes()),
        Notification::Other(line) => out.extend(line.bytes()),
    }
    out.extend(b"\r\n");
    out
}

/// The outcome of looking at the front of a buffer.
enum Step<T> {
    /// More bytes are needed.
    Incomplete,
    /// An item, and how many bytes it took.
    Item(T, usize),
}

/// Position of the first `\r\n` at or after `from`.
fn line_end(buf: &[u8], from: usize) -> Option<usize> {
    buf.get(from..)?
        .windows(2)
        .position(|w| w == b"\r\n")
        .map(|p| p + from)
}

/// Splits `count` comma-terminated fields after `prefix`; returns them and where the data starts.
/// `None` when a field is not complete yet; `Some(Err)` when the header is malformed.
fn header_fields(
    buf: &[u8],
    prefix: usize,
    count: usize,
) -> Option<Result<(Vec<String>, usize), ()>> {
    let mut fields = Vec::with_capacity(count);
    let mut at = prefix;
    for _ in 0..count {
        let rest = buf.get(at..)?;
        let limit = rest.len().min(32);
        match rest[..limit].iter().position(|&b| b == b',') {
            Some(p) => {
                let field = std::str::from_utf8(&rest[..p]).ok();
                match field {
                    Some(f) if !f.contains('\r') => fields.push(f.to_string()),
                    _ => return Some(Err(())),
                }
                at += p + 1;
            }
            None if limit == 32 || rest[..limit].contains(&b'\n') => return Some(Err(())),
            None => return None,
        }
    }
    Some(Ok((fields, at)))
}

/// Reads a data item: `prefix` then `fields` header fields (the first is the length), the data,
/// and `\r\n`. `build` makes the item from the fields and data (None: malformed).
fn data_item<T>(
    buf: &[u8],
    prefix: usize,
    fields: usize,
    max_len: usize,
    build: impl FnOnce(&[String], Vec<u8>) -> Option<T>,
) -> Option<Step<Option<T>>> {
    let (header, data_start) = match header_fields(buf, prefix, fields)? {
        Ok(parsed) => parsed,
        Err(()) => return Some(Step::Item(None, 0)),
    };
    let Some(len) = header[0]
        .parse::<usize>()
        .ok()
        .filter(|&len| len <= max_len)
    else {
        return Some(Step::Item(None, 0));
    };
    let end = data_start + len;
    if buf.len() < end + 2 {
        return Some(Step::Incomplete);
    }
    if &buf[end..end + 2] != b"\r\n" {
        return Some(Step::Item(None, 0));
    }
    let item = build(&header, buf[data_start..end].to_vec());
    Some(Step::Item(item, end + 2))
}

/// Takes the first item off `buf`: a data item, or a line. Malformed data items are returned as
/// `Other` lines up to the next line end.
fn take<T>(
    buf: &mut Vec<u8>,
    data: impl FnOnce(&[u8]) -> Option<Step<Option<T>>>,
    line: impl FnOnce(&str) -> T,
) -> Option<T> {
    if let Some(step) = data(buf) {
        match step {
            Step::Incomplete => return None,
            Step::Item(Some(item), used) => {
                buf.drain(..used);
                return Some(item);
            }
            Step::Item(None, _) => {} // malformed: fall through to a plain line
        }
    }
    let end = line_end(buf, 0)?;
    let text = String::from_utf8_lossy(&buf[..end]).into_owned();
    buf.drain(..end + 2);
    Some(line(&text))
}

/// Reads host commands from a byte stream (what a modem, or `link-sim --dialect evologics`, hears).
#[derive(Debug, Default)]
pub struct CommandReader {
    buf: Vec<u8>,
}

impl CommandReader {
    /// An empty reader.
    pub fn new() -> CommandReader {
        CommandReader::default()
    }

    /// Adds bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
        // Bound memory: a buffer with no line end in a maximal item's length is garbage.
        let limit = MAX_BURST_BYTES + 64;
        if self.buf.len() > 2 * limit && line_end(&self.buf, 0).is_none() {
            let drop = self.buf.len() - limit;
            self.buf.drain(..drop);
        }
    }

    /// The next complete command, if any.
    pub fn next_command(&mut self) -> Option<Command> {
        loop {
            // Skip line ends left between commands and the data-mode escape.
            while self.buf.starts_with(b"\r\n") {
                self.buf.drain(..2);
            }
            // The data-mode escape, only in front of a command (so the answer never depends
            // on how the bytes were chunked).
            if self.buf.starts_with(b"+++AT") {
                self.buf.drain(..3);
            } else if !self.buf.is_empty() && b"+++AT".starts_with(&self.buf) {
                return None;
            }
            let command = take(
                &mut self.buf,
                |buf| {
                    if buf.starts_with(b"AT*SENDIM,") {
                        data_item(buf, 10, 3, MAX_IM_BYTES, |f, data| {
                            let ack = match f[2].as_str() {
                                "ack" => true,
                                "noack" => false,
                                _ => return None,
                            };
                            Some(Command::SendIm {
                                dst: f[1].parse().ok()?,
                                ack,
                                data,
                            })
                        })
                    } else if buf.starts_with(b"AT*SEND,") {
                        data_item(buf, 8, 2, MAX_BURST_BYTES, |f, data| {
                            Some(Command::Send {
                                dst: f[1].parse().ok()?,
                                data,
                            })
                        })
                    } else if b"AT*SENDIM,".starts_with(buf) || b"AT*SEND,".starts_with(buf) {
                        Some(Step::Incomplete)
                    } else {
                        None
                    }
                },
                |text| Command::Other(text.to_string()),
            )?;
            if matches!(&command, Command::Other(text) if text.is_empty()) {
                continue;
            }
            return Some(command);
        }
    }
}

/// Reads modem notifications from a byte stream (what a host hears).
#[derive(Debug, Default)]
pub struct NotificationReader {
    buf: Vec<u8>,
}

impl NotificationReader {
    /// An empty reader.
    pub fn new() -> NotificationReader {
        NotificationReader::default()
    }

    /// Adds bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
        let limit = MAX_BURST_BYTES + 128;
        if self.buf.len() > 2 * limit && line_end(&self.buf, 0).is_none() {
            let drop = self.buf.len() - limit;
            self.buf.drain(..drop);
        }
    }

    /// The next complete notification, if any.
    pub fn next_notification(&mut self) -> Option<Notification> {
        loop {
            while self.buf.starts_with(b"\r\n") {
                self.buf.drain(..2);
            }
            let item = take(
                &mut self.buf,
                |buf| {
                    if buf.starts_with(b"RECVIM,") {
                        data_item(buf, 7, 8, MAX_IM_BYTES, |f, data| {
                            Some(Notification::RecvIm {
                                src: f[1].parse().ok()?,
                                dst: f[2].parse().ok()?,
                                ack: f[3] == "ack",
                                duration_us: f[4].parse().ok()?,
                                rssi: f[5].parse().ok()?,
                                integrity: f[6].parse().ok()?,
                                velocity: f[7].parse().ok()?,
                                data,
                            })
                        })
                    } else if buf.starts_with(b"RECV,") {
                        data_item(buf, 5, 8, MAX_BURST_BYTES, |f, data| {
                            Some(Notification::Recv {
                                src: f[1].parse().ok()?,
                                dst: f[2].parse().ok()?,
                                bitrate: f[3].parse().ok()?,
                                rssi: f[4].parse().ok()?,
                                integrity: f[5].parse().ok()?,
                                ptime_us: f[6].parse().ok()?,
                                velocity: f[7].parse().ok()?,
                                data,
                            })
                        })
                    } else if b"RECVIM,".starts_with(buf) || b"RECV,".starts_with(buf) {
                        Some(Step::Incomplete)
                    } else {
                        None
                    }
                },
                |text| {
                    let number = |rest: &str| rest.trim().parse::<u32>().ok();
                    if text == "OK" {
                        Notification::Ok
                    } else if let Some(dst) = text.strip_prefix("DELIVEREDIM,").and_then(number) {
                        Notification::DeliveredIm(dst)
                    } else if let Some(dst) = text.strip_prefix("FAILEDIM,").and_then(number) {
                        Notification::FailedIm(dst)
                    } else if let Some(reason) = text.strip_prefix("ERROR") {
                        Notification::Error(reason.trim().to_string())
                    } else if let Some(reason) = text.strip_prefix("BUSY") {
                        Notification::Busy(reason.trim().to_string())
                    } else {
                        Notification::Other(text.to_string())
                    }
                },
            )?;
            if matches!(&item, Notification::Other(text) if text.is_empty()) {
                continue;
            }
            return Some(item);
        }
    }
}

/// How an [`EvoLogics`] endpoint sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SendMode {
    /// `AT*SEND` bursts.
    Burst,
    /// `AT*SENDIM` instant messages, with or without acknowledgement.
    Instant {
        /// Ask for `DELIVEREDIM` / `FAILEDIM`.
        ack: bool,
    },
}

/// An EvoLogics modem (or `link-sim --dialect evologics`) on a serial port or TCP stream.
pub struct EvoLogics<P: TimedRead> {
    name: String,
    port: P,
    dst: u32,
    mode: SendMode,
    reader: NotificationReader,
    /// Replies that were not packets: `ERROR` and `BUSY` lines seen, in order.
    pub refusals: Vec<String>,
    /// `DELIVEREDIM` and `FAILEDIM` counts.
    pub delivery_reports: (u64, u64),
    pending: VecDeque<Received>,
}

impl<P: TimedRead> EvoLogics<P> {
    /// An endpoint that sends to address `dst` in `mode`.
    pub fn new(name: &str, port: P, dst: u32, mode: SendMode) -> EvoLogics<P> {
        EvoLogics {
            name: name.to_string(),
            port,
            dst,
            mode,
            reader: NotificationReader::new(),
            refusals: Vec::new(),
            delivery_reports: (0, 0),
            pending: VecDeque::new(),
        }
    }
}

impl<P: TimedRead> Endpoint for EvoLogics<P> {
    fn name(&self) -> &str {
        &self.name
    }

    fn refusals(&self) -> &[String] {
        &self.refusals
    }

    fn send(&mut self, packet: &[u8]) -> Result<(), GllError> {
        let command = match self.mode {
            SendMode::Burst => Command::Send {
                dst: self.dst,
                data: packet.to_vec(),
            },
            SendMode::Instant { ack } => Command::SendIm {
                dst: self.dst,
                ack,
                data: packet.to_vec(),
            },
        };
        self.port
            .write_all(&format_command(&command))
            .and_then(|()| self.port.flush())
            .map_err(|e| super::closed(&self.name, "write failed", e))
    }

    fn receive(&mut self, deadline: Instant) -> Result<Option<Received>, GllError> {
        let mut buf = [0u8; 4096];
        loop {
            if let Some(packet) = self.pending.pop_front() {
                return Ok(Some(packet));
            }
            let Some(n) = super::read_until(&mut self.port, &self.name, deadline, &mut buf)? else {
                return Ok(None);
            };
            let at = Instant::now();
            self.reader.push(&buf[..n]);
            while let Some(notification) = self.reader.next_notification() {
                match notification {
                    Notification::Recv {
                        integrity, data, ..
                    }
                    | Notification::RecvIm {
                        integrity, data, ..
                    } => {
                        self.pending.push_back(Received {
                            at,
                            bytes: data,
                            damaged: integrity < INTEGRITY_THRESHOLD,
                        });
                    }
                    Notification::Error(reason) => self.refusals.push(format!("ERROR {reason}")),
                    Notification::Busy(reason) => self.refusals.push(format!("BUSY {reason}")),
                    Notification::DeliveredIm(_) => self.delivery_reports.0 += 1,
                    Notification::FailedIm(_) => self.delivery_reports.1 += 1,
                    Notification::Ok | Notification::Other(_) => {}
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_round_trip_with_binary_data_in_any_chunking() {
        let commands = vec![
            Command::Send {
                dst: 2,
                data: b"a\r\nb,c\r\n".to_vec(),
            },
            Command::SendIm {
                dst: 7,
                ack: true,
                data: vec![0x55, 0x0d, 0x0a, 0xff],
            },
            Command::Other("AT?T".into()),
            Command::SendIm {
                dst: 1,
                ack: false,
                data: Vec::new(),
            },
        ];
        let stream: Vec<u8> = commands.iter().flat_map(format_command).collect();
        for chunk in [1, 2, 3, 7, stream.len()] {
            let mut reader = CommandReader::new();
            let mut got = Vec::new();
            for part in stream.chunks(chunk) {
                reader.push(part);
                while let Some(c) = reader.next_command() {
                    got.push(c);
                }
            }
            assert_eq!(got, commands, "chunks of {chunk}");
        }
        let mut reader = CommandReader::new();
        reader.push(b"+++AT*SEND,2,3,hi\r\n");
        assert_eq!(
            reader.next_command(),
            Some(Command::Send {
                dst: 3,
                data: b"hi".to_vec()
            })
        );
    }

    #[test]
    fn notifications_round_trip() {
        let notes = vec![
            Notification::Recv {
                src: 1,
                dst: 2,
                bitrate: 1620,
                rssi: -40,
                integrity: 100,
                ptime_us: 670_000,
                velocity: 0.0,
                data: b"x\r\ny".to_vec(),
            },
            Notification::RecvIm {
                src: 2,
                dst: 1,
                ack: true,
                duration_us: 5000,
                rssi: -45,
                integrity: 80,
                velocity: 0.25,
                data: vec![1, 2, 3],
            },
            Notification::DeliveredIm(2),
            Notification::FailedIm(3),
            Notification::Ok,
            Notification::Error("WRONG FORMAT".into()),
            Notification::Busy("BACKOFF STATE".into()),
            Notification::Other("SENDEND,2,im,1234,5000".into()),
        ];
        let stream: Vec<u8> = notes.iter().flat_map(format_notification).collect();
        for chunk in [1, 5, stream.len()] {
            let mut reader = NotificationReader::new();
            let mut got = Vec::new();
            for part in stream.chunks(chunk) {
                reader.push(part);
                while let Some(n) = reader.next_notification() {
                    got.push(n);
                }
            }
            assert_eq!(got, notes, "chunks of {chunk}");
        }
    }

    #[test]
    fn malformed_input_becomes_lines_and_never_sticks() {
        let mut reader = CommandReader::new();
        reader.push(b"AT*SEND,abc,2,xyz\r\nAT*SEND,99999,1,\r\nAT*SEND,1,2,zz\r\nAT\r\n");
        let got: Vec<Command> = std::iter::from_fn(|| reader.next_command()).collect();
        assert_eq!(
            got,
            vec![
                Command::Other("AT*SEND,abc,2,xyz".into()),
                Command::Other("AT*SEND,99999,1,".into()),
                Command::Other("AT*SEND,1,2,zz".into()),
                Command::Other("AT".into()),
            ]
        );
        let mut reader = CommandReader::new();
        reader.push(&vec![b'x'; 10_000]);
        assert!(reader.next_command().is_none());
        assert!(reader.buf.len() < 3000);
    }
}
