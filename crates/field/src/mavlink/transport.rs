//! The autopilot's connection: its endpoint in the one device grammar ([`DeviceSpec`]), opened
//! by the one opener ([`rovlink_link::device::open`]), MAVLink messages over what it opened (version 1
//! or 2 read, version 2 sent, numbered in the order they are written), and the receiving
//! thread that keeps what the autopilot says ([`receive`]) until the drive is dropped.

use std::io::{self, Read, Write};
use std::net::TcpListener;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::error::{MessageReadError, MessageWriteError};
use mavlink::{MavHeader, MavlinkReader, MavlinkVersion};

use super::codec::{Inbox, keep, push_bounded};
use super::{MavlinkError, READ_TIMEOUT, RECONNECT_PERIOD, TCP_CONNECT_TIMEOUT, WRITE_TIMEOUT};
use rovlink_link::device::{self, DeviceSpec, Io, OpenOptions};

/// Reads an autopilot's endpoint: a network address (`udpin:HOST:PORT`, `udpout:HOST:PORT`,
/// `udp:BIND=PEER`, `tcp:HOST:PORT`, `tcpin:HOST:PORT`, with the aliases `udp:HOST:PORT` for
/// `udpin:` and `tcpout:` for `tcp:`) or `serial:PATH:BAUD`. A bare path (no baud rate) and
/// `pty` are refused; an error names the text, what was expected and what was found.
pub fn parse_endpoint(text: &str) -> Result<DeviceSpec, MavlinkError> {
    let syntax = |reason: String| MavlinkError::Syntax {
        endpoint: text.to_string(),
        reason,
    };
    match text.parse::<DeviceSpec>() {
        Ok(DeviceSpec::Path(_)) => Err(syntax(format!(
            "expected udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT or \
             serial:PATH:BAUD (a serial autopilot needs its baud rate), found '{text}'"
        ))),
        Ok(DeviceSpec::Pty) => Err(syntax(
            "expected the autopilot's device, found 'pty' (no pseudo-terminal is made here)"
                .to_string(),
        )),
        Ok(spec) => Ok(spec),
        Err(error) => Err(syntax(error.to_string())),
    }
}

/// How the one opener opens an autopilot's device: reads wait [`READ_TIMEOUT`] at most, socket
/// writes [`WRITE_TIMEOUT`], a `tcp:` connect `connect_timeout`; `tcpin:` listens without
/// waiting for the autopilot.
fn open_options(connect_timeout: Duration) -> OpenOptions {
    OpenOptions {
        serial_timeout: READ_TIMEOUT,
        read_timeout: Some(READ_TIMEOUT),
        write_timeout: Some(WRITE_TIMEOUT),
        connect_timeout: Some(connect_timeout),
        accept: false,
        ..OpenOptions::default()
    }
}

/// A MAVLink connection over an open device. ArduPilot answers in the version it is spoken
/// to, but a port set to MAVLink 1 sends version 1 heartbeats: both are read, version 2 is
/// sent.
pub(super) struct Conn {
    reader: Mutex<MavlinkReader<Box<dyn Read + Send>>>,
    writer: Mutex<Box<dyn Write + Send>>,
    sequence: AtomicU8,
}

impl Conn {
    fn over(io: Io) -> io::Result<Conn> {
        let halves = io.split()?;
        Ok(Conn {
            reader: Mutex::new(MavlinkReader::new(halves.reader)),
            writer: Mutex::new(halves.writer),
            sequence: AtomicU8::new(0),
        })
    }

    /// The next message, waiting [`READ_TIMEOUT`] at most for bytes (a timeout is an
    /// [`io::ErrorKind::TimedOut`] or [`io::ErrorKind::WouldBlock`] error).
    pub(super) fn recv(&self) -> Result<(MavHeader, MavMessage), MessageReadError> {
        lock(&self.reader).read_any_message::<MavMessage>()
    }

    /// Sends `message` with `header`'s ids and the next sequence number (to a UDP peer that
    /// has not spoken yet, nothing goes).
    pub(super) fn send(
        &self,
        header: &MavHeader,
        message: &MavMessage,
    ) -> Result<usize, MessageWriteError> {
        let mut writer = lock(&self.writer);
        let header = MavHeader {
            sequence: self.sequence.fetch_add(1, Ordering::Relaxed),
            ..*header
        };
        let sent = mavlink::write_versioned_msg(&mut *writer, MavlinkVersion::V2, header, message)?;
        writer.flush()?;
        Ok(sent)
    }
}

/// How the receiving thread gets a connection back when TCP closes.
pub(super) enum Reopen {
    /// UDP and serial: the connection stays.
    Never,
    /// `tcp:`: connect again.
    Connect(DeviceSpec),
    /// `tcpin:`: accept the next connection.
    Accept(TcpListener),
}

/// Opens `spec` (`text` as given, for errors): the connection (none yet for `tcpin:`, whose
/// autopilot connects later) and how to get it back.
pub(super) fn open(spec: &DeviceSpec, text: &str) -> Result<(Option<Conn>, Reopen), MavlinkError> {
    let failed = |action: &'static str, source: io::Error| MavlinkError::Open {
        endpoint: text.to_string(),
        action,
        source,
    };
    let opened = device::open(spec, &open_options(TCP_CONNECT_TIMEOUT))
        .map_err(|e| failed(e.action, e.error))?;
    let reopen = match opened.io {
        Io::Listener(listener) => return Ok((None, Reopen::Accept(listener))),
        Io::Tcp(_) => Reopen::Connect(spec.clone()),
        _ => Reopen::Never,
    };
    let conn = Conn::over(opened.io).map_err(|e| failed("open", e))?;
    Ok((Some(conn), reopen))
}

impl Reopen {
    /// A new TCP connection, or none yet (or ever, for [`Reopen::Never`]): `tcp:` tries again
    /// after [`RECONNECT_PERIOD`] (watching `stop`), `tcpin:` takes a pending connection.
    pub(super) fn again(&self, stop: &AtomicBool) -> Option<Conn> {
        match self {
            Reopen::Never => None,
            Reopen::Connect(spec) => {
                let again = Instant::now() + RECONNECT_PERIOD;
                while Instant::now() < again && !stop.load(Ordering::Relaxed) {
                    std::thread::sleep(READ_TIMEOUT);
                }
                let options = open_options(READ_TIMEOUT * 5);
                let opened = device::open(spec, &options).ok()?;
                Conn::over(opened.io).ok()
            }
            Reopen::Accept(listener) => match listener.accept() {
                Ok((stream, _)) => {
                    let stream = device::tcp_stream(stream, &open_options(READ_TIMEOUT)).ok()?;
                    Conn::over(Io::Tcp(stream)).ok()
                }
                Err(_) => {
                    std::thread::sleep(READ_TIMEOUT / 2);
                    None
                }
            },
        }
    }

    /// True when a closed connection can come back (TCP).
    pub(super) fn reconnects(&self) -> bool {
        !matches!(self, Reopen::Never)
    }
}

/// The connection and the inbox, shared by `step` and the receiving thread.
pub(super) struct Shared {
    /// `None` while a TCP connection is (re)established.
    pub(super) conn: Mutex<Option<Arc<Conn>>>,
    /// What the autopilot said since the last step.
    pub(super) inbox: Mutex<Inbox>,
    /// Set when the drive is dropped.
    pub(super) stop: AtomicBool,
}

/// Locks `mutex`, also when a panicking thread poisoned it.
pub(super) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The receiving thread: reads messages until told to stop, keeping what `step` needs.
pub(super) fn receive(shared: &Shared, reopen: Reopen, our_system: u8) {
    let mut failed: Option<String> = None;
    while !shared.stop.load(Ordering::Relaxed) {
        let conn = lock(&shared.conn).clone();
        let Some(conn) = conn else {
            if !reopen.reconnects() {
                return;
            }
            if let Some(fresh) = reopen.again(&shared.stop) {
                *lock(&shared.conn) = Some(Arc::new(fresh));
                note(shared, "mavlink: TCP connection established".to_string());
            }
            continue;
        };
        let result = conn.recv();
        match result {
            Ok((header, message)) => {
                failed = None;
                keep(&mut lock(&shared.inbox), &header, message, our_system);
            }
            Err(MessageReadError::Parse(_)) => {}
            Err(MessageReadError::Io(error)) => match error.kind() {
                io::ErrorKind::WouldBlock
                | io::ErrorKind::TimedOut
                | io::ErrorKind::Interrupted => {}
                _ if reopen.reconnects() => {
                    *lock(&shared.conn) = None;
                    note(shared, format!("mavlink: TCP connection closed: {error}"));
                }
                _ => {
                    let text = format!("mavlink: receive failed: {error}");
                    if failed.as_deref() != Some(text.as_str()) {
                        note(shared, text.clone());
                        failed = Some(text);
                    }
                    std::thread::sleep(READ_TIMEOUT);
                }
            },
        }
    }
}

/// Keeps a note for the next step.
fn note(shared: &Shared, text: String) {
    push_bounded(&mut lock(&shared.inbox).notes, text);
}
