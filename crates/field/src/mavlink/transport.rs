//! The autopilot's connection: its endpoint in the one device grammar ([`DeviceSpec`]), opened
//! by the one opener ([`rovlink_link::device::open`]), MAVLink messages over what it opened (version 1
//! or 2 read, version 2 sent, numbered in the order they are written, signed with a key), and
//! the receiving thread that keeps what the autopilot says ([`receive`]) until the drive is
//! dropped, behind the [`Gate`]: with a key only frames signed with it and new for their
//! stream pass; over UDP only the first autopilot's address and system.

use std::collections::BTreeSet;
use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::error::{MessageReadError, MessageWriteError};
use mavlink::{MAVLinkMessageRaw, MavHeader, MavlinkReader, MavlinkVersion, Message};

use super::codec::{Inbox, keep, push_bounded};
use super::signing::{Refusal, Signing};
use super::{MavlinkError, READ_TIMEOUT, RECONNECT_PERIOD, TCP_CONNECT_TIMEOUT, WRITE_TIMEOUT};
use rovlink_link::device::{self, Datagrams, DeviceSpec, Io, OpenOptions};

/// The most sources whose refusal is said (on stderr and as a note); later ones are counted
/// only.
pub const MAX_SOURCES_SAID: usize = 32;

/// The largest datagram read, bytes (a UDP datagram's limit).
const DATAGRAM_BYTES: usize = 65_536;

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
    link: Link,
    sequence: AtomicU8,
}

/// How the frames travel.
enum Link {
    /// A byte stream (TCP, serial): frames as they come.
    Stream {
        reader: Mutex<MavlinkReader<Box<dyn Read + Send>>>,
        writer: Mutex<Box<dyn Write + Send>>,
    },
    /// UDP: each datagram read whole, with its sender, and its frames parsed on their own (a
    /// frame never spans two senders' datagrams).
    Datagrams {
        socket: Datagrams,
        buffer: Mutex<Vec<u8>>,
    },
}

/// What one read brought: the sender (UDP) and the frames, checksums verified.
pub(super) struct Heard {
    pub(super) from: Option<SocketAddr>,
    pub(super) frames: Vec<MAVLinkMessageRaw>,
}

impl Conn {
    fn over(io: Io) -> io::Result<Conn> {
        let link = match io {
            Io::Udp(socket) => Link::Datagrams {
                socket,
                buffer: Mutex::new(vec![0; DATAGRAM_BYTES]),
            },
            io => {
                let halves = io.split()?;
                Link::Stream {
                    reader: Mutex::new(MavlinkReader::new(halves.reader)),
                    writer: Mutex::new(halves.writer),
                }
            }
        };
        Ok(Conn {
            link,
            sequence: AtomicU8::new(0),
        })
    }

    /// The next frames, waiting [`READ_TIMEOUT`] at most for bytes (a timeout is an
    /// [`io::ErrorKind::TimedOut`] or [`io::ErrorKind::WouldBlock`] error).
    pub(super) fn recv(&self) -> Result<Heard, MessageReadError> {
        match &self.link {
            Link::Stream { reader, .. } => {
                let frame = lock(reader).read_any_raw_message::<MavMessage>()?;
                Ok(Heard {
                    from: None,
                    frames: vec![frame],
                })
            }
            Link::Datagrams { socket, buffer } => {
                let mut buffer = lock(buffer);
                let (len, from) = socket.recv_from(&mut buffer)?;
                let mut reader = MavlinkReader::new(&buffer[..len]);
                // The raw reader skips what does not check out and ends at the datagram's end.
                let frames =
                    std::iter::from_fn(|| reader.read_any_raw_message::<MavMessage>().ok())
                        .collect();
                Ok(Heard {
                    from: Some(from),
                    frames,
                })
            }
        }
    }

    /// UDP that learns its peer (`udpin:`): answer `addr` from now on.
    pub(super) fn answer(&self, addr: SocketAddr) {
        if let Link::Datagrams { socket, .. } = &self.link {
            socket.set_peer(addr);
        }
    }

    /// Sends `message` with `header`'s ids and the next sequence number, signed when
    /// `signing` is given (to a UDP peer that has not spoken yet, nothing goes).
    pub(super) fn send(
        &self,
        header: &MavHeader,
        message: &MavMessage,
        signing: Option<&Signing>,
    ) -> Result<usize, MessageWriteError> {
        let header = MavHeader {
            sequence: self.sequence.fetch_add(1, Ordering::Relaxed),
            ..*header
        };
        let bytes = match signing {
            Some(signing) => signing.frame(header, message),
            None => {
                let mut bytes = Vec::new();
                mavlink::write_versioned_msg(&mut bytes, MavlinkVersion::V2, header, message)?;
                bytes
            }
        };
        match &self.link {
            Link::Stream { writer, .. } => {
                let mut writer = lock(writer);
                writer.write_all(&bytes)?;
                writer.flush()?;
            }
            Link::Datagrams { socket, .. } => {
                socket.send(&bytes)?;
            }
        }
        Ok(bytes.len())
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
    /// The key everything sent is signed with and everything heard must be signed with.
    pub(super) signing: Option<Arc<Signing>>,
}

/// Locks `mutex`, also when a panicking thread poisoned it.
pub(super) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// What passes from the link to the inbox, and what is refused (counted in the inbox, said
/// once per reason and source).
pub(super) struct Gate {
    /// Our own system id (our echo is not the autopilot).
    pub(super) our_system: u8,
    /// Where refusals are said besides the notes: `tool: text` on stderr.
    pub(super) tool: Option<&'static str>,
    /// UDP: the address and system of the first autopilot heard, the only ones heard since.
    pin: Option<(SocketAddr, u8)>,
    said: BTreeSet<(Refusal, String)>,
}

impl Gate {
    /// A gate for our system `our_system`, saying refusals on stderr as `tool` when given.
    pub(super) fn new(our_system: u8, tool: Option<&'static str>) -> Gate {
        Gate {
            our_system,
            tool,
            pin: None,
            said: BTreeSet::new(),
        }
    }

    /// Lets what `heard` brought on `conn` through to the inbox, or refuses it.
    fn pass(&mut self, shared: &Shared, conn: &Conn, heard: Heard) {
        let mut inbox = lock(&shared.inbox);
        if let (Some((pinned, _)), Some(from)) = (self.pin, heard.from)
            && from != pinned
        {
            self.refuse(&mut inbox, Refusal::OtherAddress, from.to_string(), None);
            return;
        }
        for raw in heard.frames {
            let system = raw.system_id();
            let source = match heard.from {
                Some(from) => format!("{from} system {system} component {}", raw.component_id()),
                None => format!("system {system} component {}", raw.component_id()),
            };
            let version = match raw {
                MAVLinkMessageRaw::V1(_) => MavlinkVersion::V1,
                MAVLinkMessageRaw::V2(_) => MavlinkVersion::V2,
            };
            let parsed = MavMessage::parse(version, raw.message_id(), raw.payload());
            let name = parsed.as_ref().ok().map(Message::message_name);
            if let Some(signing) = &shared.signing {
                let checked = signing.check(&raw);
                // Before the autopilot is known, our heartbeat goes to whoever holds the key:
                // also to one whose clock is behind ours (refused as old), so that it hears
                // our newer timestamps and catches up, as signing peers do.
                if let (None, Some(from), Ok(()) | Err(Refusal::Replayed)) =
                    (self.pin, heard.from, checked)
                {
                    conn.answer(from);
                }
                if let Err(reason) = checked {
                    self.refuse(&mut inbox, reason, source, name);
                    continue;
                }
            } else if let (None, Some(from)) = (self.pin, heard.from) {
                conn.answer(from);
            }
            if let Some((_, pinned_system)) = self.pin
                && system != u32::from(pinned_system)
            {
                self.refuse(&mut inbox, Refusal::OtherSystem, source, name);
                continue;
            }
            let Ok(message) = parsed else {
                continue;
            };
            let header = MavHeader {
                system_id: system,
                component_id: raw.component_id(),
                sequence: raw.sequence(),
            };
            keep(&mut inbox, &header, message, self.our_system);
            if let (None, Some(from), Some(autopilot)) = (self.pin, heard.from, inbox.autopilot) {
                self.pin = Some((from, autopilot.system));
                conn.answer(from);
                let text = format!(
                    "mavlink: UDP: the autopilot is system {} at {from}: datagrams from other \
                     addresses and messages of other systems are dropped from now on",
                    autopilot.system
                );
                self.say(&mut inbox, text);
            }
        }
    }

    /// Counts a refusal; says it the first time for its reason and source.
    fn refuse(&mut self, inbox: &mut Inbox, reason: Refusal, source: String, name: Option<&str>) {
        inbox.refused[reason as usize] += 1;
        if self.said.len() >= MAX_SOURCES_SAID || !self.said.insert((reason, source.clone())) {
            return;
        }
        let what = match reason {
            Refusal::Unsigned => "an unsigned message",
            Refusal::BadSignature => "a message signed with another key",
            Refusal::Replayed => "a replayed or too old signed message",
            Refusal::OtherAddress => "a datagram",
            Refusal::OtherSystem => "a message of another system",
        };
        let name = name.map_or_else(String::new, |n| format!(" ({n})"));
        let text = format!(
            "mavlink: refused {what}{name} from {source}: {}; later ones from there are only \
             counted (mavlink_refused.{} in --metrics)",
            match reason {
                Refusal::Unsigned | Refusal::BadSignature | Refusal::Replayed =>
                    "only messages signed with --mavlink-key-file, each newer than the last, are used",
                Refusal::OtherAddress | Refusal::OtherSystem =>
                    "only the autopilot first heard is listened to",
            },
            reason.name()
        );
        self.say(inbox, text);
    }

    /// A note for the next step, and a line on stderr when the gate has a tool's name.
    fn say(&self, inbox: &mut Inbox, text: String) {
        if let Some(tool) = self.tool {
            rovlink_base::io::warn(tool, &text);
        }
        push_bounded(&mut inbox.notes, text);
    }
}

/// The receiving thread: reads messages until told to stop, keeping what `step` needs of what
/// passes the `gate`.
pub(super) fn receive(shared: &Shared, reopen: Reopen, mut gate: Gate) {
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
            Ok(heard) => {
                failed = None;
                gate.pass(shared, &conn, heard);
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
