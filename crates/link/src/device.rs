//! Devices: the one grammar of every tool's device flags ([`DeviceSpec`], parsed by its
//! `FromStr`) and the one opener ([`open`]) that turns a spec into an open [`Device`].
//!
//! | form | the device |
//! |---|---|
//! | `PATH` | a serial port or pseudo-terminal, at the tool's baud rate (`--baud`) |
//! | `serial:PATH:BAUD` | a serial port at BAUD bit/s (the path may hold colons) |
//! | `tcp:HOST:PORT` | a TCP connection to HOST:PORT (a modem's TCP console) |
//! | `tcpin:HOST:PORT` | listen on HOST:PORT; the peer is the one that connects |
//! | `udp:BIND=PEER` | a UDP socket bound to BIND that sends to PEER and takes only PEER's datagrams (both IP:PORT) |
//! | `udpin:HOST:PORT` | a UDP socket bound to HOST:PORT whose peer is the first that sends to it |
//! | `udpout:HOST:PORT` | a UDP socket on an ephemeral port that sends to HOST:PORT and takes only its datagrams |
//! | `pty` | a new pseudo-terminal pair (where a tool offers one: link-sim) |
//!
//! Aliases, the spellings of earlier versions ([`ALIASES`]): `tcpout:HOST:PORT` is
//! `tcp:HOST:PORT`, and `udp:HOST:PORT` (no `=`) is `udpin:HOST:PORT`. HOST is a name or an
//! address, an IPv6 address in brackets (`[::1]:14550`); port 0 (any free port) only where the
//! device listens. A UDP device carries one packet per datagram, and takes only its peer's:
//! a datagram from any other source address or port is dropped, counted and its source named
//! once on standard error ([`Datagrams`]).
//!
//! [`open`] does what each kind did when the tools opened it themselves: a serial port at its
//! baud rate with the caller's timeout (a path that is not a terminal is named as such), a TCP
//! stream without Nagle's delay, a pseudo-terminal in raw mode whose slave stays open while the
//! [`Pty`] lives, sockets with the caller's timeouts. What the bytes mean (frames, a modem's
//! AT dialect, MAVLink) is the caller's.

use std::fmt;
use std::fs::File;
use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs, UdpSocket};
use std::os::unix::fs::OpenOptionsExt;
use std::str::FromStr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use nix::fcntl::OFlag;
use nix::pty::{PtyMaster, grantpt, posix_openpt, ptsname_r, unlockpt};
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

/// A device as a flag names it: see the module's table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeviceSpec {
    /// A serial port or pseudo-terminal path, opened at the tool's baud rate.
    Path(String),
    /// `serial:PATH:BAUD`.
    Serial {
        /// The device path.
        path: String,
        /// Bits per second.
        baud: u32,
    },
    /// `tcp:HOST:PORT`: connect there.
    Tcp(String),
    /// `tcpin:HOST:PORT`: listen there.
    TcpIn(String),
    /// `udp:BIND=PEER`: bind BIND, send to PEER, take only PEER's datagrams.
    Udp {
        /// The local address.
        bind: SocketAddr,
        /// Where packets go.
        peer: SocketAddr,
    },
    /// `udpin:HOST:PORT`: bind there; the first sender is the peer.
    UdpIn(String),
    /// `udpout:HOST:PORT`: send there from an ephemeral port, take only its datagrams.
    UdpOut(String),
    /// `pty`: a new pseudo-terminal pair.
    Pty,
}

/// The earlier spellings still read, each with what it means.
pub const ALIASES: [(&str, &str); 2] = [
    ("tcpout:HOST:PORT", "tcp:HOST:PORT"),
    ("udp:HOST:PORT (no =)", "udpin:HOST:PORT"),
];

/// The grammar for `--help` (every tool with a device flag shows it).
pub const HELP: &str = "\
Devices (every device flag):
  PATH                a serial port or pseudo-terminal, at --baud
  serial:PATH:BAUD    a serial port at BAUD bit/s (PATH may hold colons)
  tcp:HOST:PORT       connect there (a modem's TCP console)
  tcpin:HOST:PORT     listen there; the peer is the one that connects
  udp:BIND=PEER       bind BIND, send to PEER (both IP:PORT); one datagram per packet
  udpin:HOST:PORT     bind there; the first sender is the peer, kept until the end
  udpout:HOST:PORT    send there, from an ephemeral port
  pty                 a new pseudo-terminal (link-sim; its path is printed)
Aliases (earlier spellings): tcpout:HOST:PORT = tcp:HOST:PORT; udp:HOST:PORT (no =) =
udpin:HOST:PORT. An IPv6 host goes in brackets ([::1]:14550). A UDP device takes only its
peer's datagrams: others are dropped and their source named once on stderr.";

/// The forms, for error messages.
const FORMS: &str = "a path, serial:PATH:BAUD, tcp:HOST:PORT, tcpin:HOST:PORT, udp:BIND=PEER, \
                     udpin:HOST:PORT, udpout:HOST:PORT or pty";

/// Why a text is not a device: what was expected and what was found.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("expected {expected}, found {found}")]
pub struct DeviceSpecError {
    /// What the text should have been.
    pub expected: String,
    /// What it was (quoted).
    pub found: String,
}

fn wrong(expected: impl Into<String>, found: impl Into<String>) -> DeviceSpecError {
    DeviceSpecError {
        expected: expected.into(),
        found: found.into(),
    }
}

impl FromStr for DeviceSpec {
    type Err = DeviceSpecError;

    fn from_str(text: &str) -> Result<DeviceSpec, DeviceSpecError> {
        if text.is_empty() {
            return Err(wrong(FORMS, "nothing"));
        }
        if text == "pty" {
            return Ok(DeviceSpec::Pty);
        }
        let Some((kind, rest)) = text.split_once(':') else {
            return Ok(DeviceSpec::Path(text.to_string()));
        };
        match kind {
            "serial" => serial(rest),
            "tcp" | "tcpout" => Ok(DeviceSpec::Tcp(host_port(rest, false)?)),
            "tcpin" => Ok(DeviceSpec::TcpIn(host_port(rest, true)?)),
            "udp" => match rest.split_once('=') {
                Some((bind, peer)) => Ok(DeviceSpec::Udp {
                    bind: socket_addr(bind)?,
                    peer: socket_addr(peer)?,
                }),
                None => Ok(DeviceSpec::UdpIn(host_port(rest, true)?)),
            },
            "udpin" => Ok(DeviceSpec::UdpIn(host_port(rest, true)?)),
            "udpout" => Ok(DeviceSpec::UdpOut(host_port(rest, false)?)),
            _ if text.starts_with(['/', '.']) => Ok(DeviceSpec::Path(text.to_string())),
            _ => Err(wrong(
                FORMS,
                format!("'{text}' (no device kind '{kind}'; a relative path starts with ./)"),
            )),
        }
    }
}

/// `PATH:BAUD` after `serial:`.
fn serial(rest: &str) -> Result<DeviceSpec, DeviceSpecError> {
    let Some((path, baud)) = rest.rsplit_once(':') else {
        return Err(wrong("serial:PATH:BAUD", format!("'serial:{rest}'")));
    };
    if path.is_empty() {
        return Err(wrong(
            "a device path before the baud rate",
            format!("nothing in 'serial:{rest}'"),
        ));
    }
    match baud.parse::<u32>() {
        Ok(baud) if baud > 0 => Ok(DeviceSpec::Serial {
            path: path.to_string(),
            baud,
        }),
        _ => Err(wrong(
            "a baud rate (bits per second) after the device",
            format!("'{baud}'"),
        )),
    }
}

/// Checks `HOST:PORT` (an IPv6 host in brackets); port 0 only where the device listens.
fn host_port(text: &str, listening: bool) -> Result<String, DeviceSpecError> {
    let Some((host, port)) = text.rsplit_once(':') else {
        return Err(wrong("HOST:PORT", format!("'{text}'")));
    };
    if host.is_empty() {
        return Err(wrong("HOST:PORT", format!("no host in '{text}'")));
    }
    let bracketed = host.starts_with('[') && host.ends_with(']') && host.len() > 2;
    if host.contains(':') && !bracketed {
        return Err(wrong(
            "an IPv6 host in brackets ([::1]:14550)",
            format!("'{text}'"),
        ));
    }
    let digits = !port.is_empty() && port.bytes().all(|b| b.is_ascii_digit());
    match port.parse::<u16>().ok().filter(|_| digits).ok_or(()) {
        Ok(0) if !listening => Err(wrong(
            "a port to connect to (port 0 only where the device listens)",
            format!("0 in '{text}'"),
        )),
        Ok(_) => Ok(text.to_string()),
        Err(_) => Err(wrong(
            "a port number 0..=65535 after the host",
            format!("'{port}'"),
        )),
    }
}

/// An `IP:PORT` of `udp:BIND=PEER`.
fn socket_addr(text: &str) -> Result<SocketAddr, DeviceSpecError> {
    text.parse::<SocketAddr>().map_err(|e| {
        wrong(
            "udp:BIND=PEER, both IP:PORT (127.0.0.1:9001, [::1]:9001)",
            format!("'{text}' ({e})"),
        )
    })
}

impl fmt::Display for DeviceSpec {
    /// The canonical spelling, which parses back to the same spec.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DeviceSpec::Path(path) => write!(f, "{path}"),
            DeviceSpec::Serial { path, baud } => write!(f, "serial:{path}:{baud}"),
            DeviceSpec::Tcp(address) => write!(f, "tcp:{address}"),
            DeviceSpec::TcpIn(address) => write!(f, "tcpin:{address}"),
            DeviceSpec::Udp { bind, peer } => write!(f, "udp:{bind}={peer}"),
            DeviceSpec::UdpIn(address) => write!(f, "udpin:{address}"),
            DeviceSpec::UdpOut(address) => write!(f, "udpout:{address}"),
            DeviceSpec::Pty => write!(f, "pty"),
        }
    }
}

impl DeviceSpec {
    /// True for a serial port or pseudo-terminal (a path, `serial:` or `pty`): a line with a
    /// baud rate.
    pub fn is_serial(&self) -> bool {
        matches!(
            self,
            DeviceSpec::Path(_) | DeviceSpec::Serial { .. } | DeviceSpec::Pty
        )
    }

    /// True for a UDP device (one datagram per packet).
    pub fn is_datagram(&self) -> bool {
        matches!(
            self,
            DeviceSpec::Udp { .. } | DeviceSpec::UdpIn(_) | DeviceSpec::UdpOut(_)
        )
    }
}

/// How [`open`] opens: what each tool did at open before there was one opener.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OpenOptions {
    /// The baud rate of a bare path (`serial:` carries its own).
    pub baud: u32,
    /// How long a serial port's reads and writes may wait.
    pub serial_timeout: Duration,
    /// A socket's read timeout (none: reads wait).
    pub read_timeout: Option<Duration>,
    /// A socket's write timeout (none: writes wait).
    pub write_timeout: Option<Duration>,
    /// How long a `tcp:` connect may wait (none: as long as the system lets it).
    pub connect_timeout: Option<Duration>,
    /// `tcpin:`: wait for the one peer and return the connection; else return the listener,
    /// non-blocking, for the caller to accept from.
    pub accept: bool,
    /// Whether `pty` is offered (the caller runs pseudo-terminals).
    pub pty: bool,
}

impl Default for OpenOptions {
    fn default() -> OpenOptions {
        OpenOptions {
            baud: 9600,
            serial_timeout: Duration::from_millis(50),
            read_timeout: None,
            write_timeout: None,
            connect_timeout: None,
            accept: true,
            pty: false,
        }
    }
}

/// Why a device did not open.
#[derive(Debug, thiserror::Error)]
#[error("{device}: cannot {action}: {error}")]
pub struct OpenError {
    /// The device (a path, or the spec's canonical text).
    pub device: String,
    /// What was tried: `open`, `connect`, `listen`, `accept`, `bind`, `resolve`, `create`.
    pub action: &'static str,
    /// Why it failed.
    pub error: io::Error,
}

/// An open device: its name for messages and what it is.
#[derive(Debug)]
pub struct Device {
    /// The path of a serial port (of a new pseudo-terminal: the path programs open), the bound
    /// address of a UDP socket, or the spec's canonical text.
    pub name: String,
    /// The open device.
    pub io: Io,
}

/// What an open device is.
pub enum Io {
    /// A serial port or someone's pseudo-terminal.
    Serial(Box<dyn serialport::SerialPort>),
    /// A new pseudo-terminal pair.
    Pty(Pty),
    /// A TCP connection.
    Tcp(TcpStream),
    /// A listening TCP socket (`tcpin:` without [`OpenOptions::accept`]).
    Listener(TcpListener),
    /// A UDP socket with its peer.
    Udp(Datagrams),
}

impl fmt::Debug for Io {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kind = match self {
            Io::Serial(_) => "Serial",
            Io::Pty(_) => "Pty",
            Io::Tcp(_) => "Tcp",
            Io::Listener(_) => "Listener",
            Io::Udp(_) => "Udp",
        };
        f.write_str(kind)
    }
}

/// The one opener: opens `spec` as `options` say. A spec the options do not offer (`pty`) is
/// an error like any device that does not open.
pub fn open(spec: &DeviceSpec, options: &OpenOptions) -> Result<Device, OpenError> {
    let device = spec.to_string();
    let fail = |action: &'static str| {
        let device = device.clone();
        move |error: io::Error| OpenError {
            device,
            action,
            error,
        }
    };
    let io = match spec {
        DeviceSpec::Path(path) | DeviceSpec::Serial { path, .. } => {
            let baud = match spec {
                DeviceSpec::Serial { baud, .. } => *baud,
                _ => options.baud,
            };
            let port = open_serial(path, baud, options.serial_timeout)?;
            return Ok(Device {
                name: path.clone(),
                io: Io::Serial(port),
            });
        }
        DeviceSpec::Pty if !options.pty => {
            let why = "this tool does not create pseudo-terminals (link-sim does): give a device";
            return Err(fail("create")(io::Error::other(why)));
        }
        DeviceSpec::Pty => {
            let pty = Pty::create().map_err(|e| fail("create")(e.into()))?;
            return Ok(Device {
                name: pty.path().to_string(),
                io: Io::Pty(pty),
            });
        }
        DeviceSpec::Tcp(address) => {
            let stream = match options.connect_timeout {
                Some(timeout) => {
                    let to = resolve(address).map_err(fail("resolve"))?;
                    TcpStream::connect_timeout(&to, timeout)
                }
                None => TcpStream::connect(address.as_str()),
            }
            .map_err(fail("connect"))?;
            Io::Tcp(tcp_stream(stream, options).map_err(fail("connect"))?)
        }
        DeviceSpec::TcpIn(address) => {
            let at = resolve(address).map_err(fail("resolve"))?;
            let listener = TcpListener::bind(at).map_err(fail("listen"))?;
            if options.accept {
                let (stream, _) = listener.accept().map_err(fail("accept"))?;
                Io::Tcp(tcp_stream(stream, options).map_err(fail("accept"))?)
            } else {
                listener.set_nonblocking(true).map_err(fail("listen"))?;
                Io::Listener(listener)
            }
        }
        DeviceSpec::Udp { bind, peer } => {
            let socket = UdpSocket::bind(bind).map_err(fail("bind"))?;
            let peer = Peer::Fixed {
                to: *peer,
                from: vec![*peer],
            };
            Io::Udp(Datagrams::new(spec, socket, peer, options).map_err(fail("bind"))?)
        }
        DeviceSpec::UdpIn(address) => {
            let at = resolve(address).map_err(fail("resolve"))?;
            let socket = UdpSocket::bind(at).map_err(fail("bind"))?;
            let peer = Peer::Learned(Arc::default());
            Io::Udp(Datagrams::new(spec, socket, peer, options).map_err(fail("bind"))?)
        }
        DeviceSpec::UdpOut(address) => {
            // Every address of the host may answer: the one sent to is the first.
            let from: Vec<SocketAddr> = address
                .as_str()
                .to_socket_addrs()
                .map_err(fail("resolve"))?
                .collect();
            let to = *from.first().ok_or_else(|| fail("resolve")(no_address()))?;
            let any: SocketAddr = match to {
                SocketAddr::V4(_) => (std::net::Ipv4Addr::UNSPECIFIED, 0).into(),
                SocketAddr::V6(_) => (std::net::Ipv6Addr::UNSPECIFIED, 0).into(),
            };
            let socket = UdpSocket::bind(any).map_err(fail("bind"))?;
            let peer = Peer::Fixed { to, from };
            Io::Udp(Datagrams::new(spec, socket, peer, options).map_err(fail("bind"))?)
        }
    };
    let name = match &io {
        Io::Udp(datagrams) => datagrams
            .local_addr()
            .map_or_else(|_| device.clone(), |a| a.to_string()),
        _ => device,
    };
    Ok(Device { name, io })
}

/// The first address of `HOST:PORT`.
pub fn resolve(address: &str) -> io::Result<SocketAddr> {
    address.to_socket_addrs()?.next().ok_or_else(no_address)
}

/// A host that resolved to no address.
fn no_address() -> io::Error {
    io::Error::new(io::ErrorKind::NotFound, "the host has no address")
}

/// A TCP stream set up as `options` say: blocking, without Nagle's delay, with its timeouts.
pub fn tcp_stream(stream: TcpStream, options: &OpenOptions) -> io::Result<TcpStream> {
    stream.set_nonblocking(false)?;
    stream.set_read_timeout(options.read_timeout)?;
    stream.set_write_timeout(options.write_timeout)?;
    stream.set_nodelay(true)?;
    Ok(stream)
}

/// Opens a serial port (or pseudo-terminal) whose reads and writes wait `timeout` at most. A
/// path that is not a terminal (a regular file, a directory, `/dev/null`) is named as such, not
/// as "Not a typewriter".
pub fn open_serial(
    path: &str,
    baud: u32,
    timeout: Duration,
) -> Result<Box<dyn serialport::SerialPort>, OpenError> {
    serialport::new(path, baud)
        .timeout(timeout)
        .open()
        .map_err(|e| OpenError {
            device: path.to_string(),
            action: "open",
            error: io::Error::other(not_a_terminal(path).unwrap_or_else(|| e.to_string())),
        })
}

/// Why `path`, which exists, cannot be a serial port: `None` when it may be one (or is gone).
fn not_a_terminal(path: &str) -> Option<String> {
    let kind = std::fs::metadata(path).ok()?.file_type();
    let what = if let Some(what) = rovlink_base::io::kind_name(kind) {
        what
    } else {
        // Non-blocking: a serial line waiting for carrier must not hold the error up.
        let nonblocking = OFlag::O_NONBLOCK.bits();
        let mut options = std::fs::OpenOptions::new();
        let file = options
            .read(true)
            .custom_flags(nonblocking)
            .open(path)
            .ok()?;
        if nix::unistd::isatty(&file).unwrap_or(true) {
            return None;
        }
        "a device that is not a terminal"
    };
    Some(format!("{what}, not a serial port or pseudo-terminal"))
}

/// Reads with a timeout: the common shape of serial ports and sockets.
pub trait TimedRead: Read + Write + Send {
    /// Sets how long a read may wait.
    fn set_read_timeout(&mut self, timeout: Duration) -> io::Result<()>;
}

impl TimedRead for dyn serialport::SerialPort {
    fn set_read_timeout(&mut self, timeout: Duration) -> io::Result<()> {
        self.set_timeout(timeout).map_err(io::Error::other)
    }
}

impl<T: TimedRead + ?Sized> TimedRead for Box<T> {
    fn set_read_timeout(&mut self, timeout: Duration) -> io::Result<()> {
        (**self).set_read_timeout(timeout)
    }
}

impl TimedRead for TcpStream {
    fn set_read_timeout(&mut self, timeout: Duration) -> io::Result<()> {
        TcpStream::set_read_timeout(self, Some(timeout.max(Duration::from_micros(1))))
    }
}

impl TimedRead for Datagrams {
    fn set_read_timeout(&mut self, timeout: Duration) -> io::Result<()> {
        self.socket
            .set_read_timeout(Some(timeout.max(Duration::from_micros(1))))
    }
}

/// Where a UDP device's packets go, and whose datagrams it takes.
#[derive(Debug, Clone)]
enum Peer {
    /// Always there: `to` gets the packets; datagrams are taken only from one of `from` (the
    /// addresses PEER or HOST resolved to when the device opened).
    Fixed {
        /// Where packets go.
        to: SocketAddr,
        /// The sources whose datagrams are taken.
        from: Vec<SocketAddr>,
    },
    /// The first sender, kept for the life of the device (nobody yet: packets are dropped).
    Learned(Arc<Mutex<Option<SocketAddr>>>),
}

/// The most foreign sources a UDP device names on standard error; later ones are counted.
const MAX_FOREIGN_SOURCES_SAID: usize = 64;

/// Datagrams a UDP device dropped because they came from someone other than its peer,
/// shared by every handle on the device.
#[derive(Debug, Default)]
struct Foreign {
    /// The device as given (`udp:BIND=PEER`), for messages.
    device: String,
    /// How many were dropped.
    dropped: AtomicU64,
    /// The sources already named on standard error (at most [`MAX_FOREIGN_SOURCES_SAID`]).
    said: Mutex<Vec<SocketAddr>>,
}

/// How many datagrams a UDP device dropped because they were not its peer's (a handle that
/// stays valid after the device is split into a reader and a writer).
#[derive(Debug, Clone, Default)]
pub struct ForeignDrops(Arc<Foreign>);

impl ForeignDrops {
    /// The count so far.
    pub fn count(&self) -> u64 {
        self.0.dropped.load(Ordering::Relaxed)
    }
}

/// The same host and port (an IPv4 address mapped into IPv6 is the IPv4 address; an IPv6
/// scope or flow label does not make another source).
fn same_source(a: SocketAddr, b: SocketAddr) -> bool {
    a.ip().to_canonical() == b.ip().to_canonical() && a.port() == b.port()
}

/// The name this program was started as, for its own lines on standard error.
fn program_name() -> String {
    std::env::args_os()
        .next()
        .map(std::path::PathBuf::from)
        .and_then(|path| path.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "rovlink".to_string())
}

/// A UDP socket and its peer: one datagram per packet. Only the peer's datagrams are taken:
/// those from any other source are dropped, counted ([`Datagrams::foreign_drops`]) and each
/// source is named once on standard error. A fixed peer (`udp:BIND=PEER`, `udpout:`) is known
/// at open; a learned one (`udpin:`) is the first source heard, kept until the device closes.
///
/// The socket is not `connect()`ed, although the kernel would then filter by source too: a
/// connected UDP socket reports an ICMP "port unreachable" as `ECONNREFUSED` on its next
/// receive, so a peer that is not up yet (the other end is started second) would end the
/// run; the kernel would also drop foreign datagrams without a word. The filter here is one
/// comparison per datagram.
///
/// As a byte stream ([`Read`], [`Write`]) each read is one datagram's bytes (an empty or a
/// dropped datagram reads as [`io::ErrorKind::Interrupted`], not as an end of file) and each
/// write one datagram; a write before a learned peer has spoken is dropped.
#[derive(Debug)]
pub struct Datagrams {
    socket: UdpSocket,
    peer: Peer,
    foreign: ForeignDrops,
}

impl Datagrams {
    fn new(
        device: &DeviceSpec,
        socket: UdpSocket,
        peer: Peer,
        options: &OpenOptions,
    ) -> io::Result<Self> {
        socket.set_read_timeout(options.read_timeout)?;
        socket.set_write_timeout(options.write_timeout)?;
        let foreign = ForeignDrops(Arc::new(Foreign {
            device: device.to_string(),
            ..Foreign::default()
        }));
        Ok(Datagrams {
            socket,
            peer,
            foreign,
        })
    }

    /// A second handle on the same socket and peer (a learned peer and the count of dropped
    /// datagrams are shared).
    pub fn try_clone(&self) -> io::Result<Datagrams> {
        Ok(Datagrams {
            socket: self.socket.try_clone()?,
            peer: self.peer.clone(),
            foreign: self.foreign.clone(),
        })
    }

    /// The address the socket is bound to.
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// Where packets go now (none before a learned peer has spoken).
    pub fn peer(&self) -> Option<SocketAddr> {
        match &self.peer {
            Peer::Fixed { to, .. } => Some(*to),
            Peer::Learned(learned) => *learned.lock().unwrap_or_else(PoisonError::into_inner),
        }
    }

    /// The datagrams dropped so far because they were not the peer's.
    pub fn foreign_drops(&self) -> ForeignDrops {
        self.foreign.clone()
    }

    /// Receives one datagram: its length (maybe 0) when it is the peer's (the first sender
    /// becomes a learned peer), `None` when it came from someone else and was dropped.
    pub fn recv(&self, buf: &mut [u8]) -> io::Result<Option<usize>> {
        let (n, from) = self.socket.recv_from(buf)?;
        let (peer, which) = match &self.peer {
            Peer::Fixed { to, from: sources } => {
                if sources.iter().any(|&source| same_source(source, from)) {
                    return Ok(Some(n));
                }
                (*to, "")
            }
            Peer::Learned(learned) => {
                let mut learned = learned.lock().unwrap_or_else(PoisonError::into_inner);
                match *learned {
                    Some(peer) if !same_source(peer, from) => (peer, " (its first sender)"),
                    Some(_) => return Ok(Some(n)),
                    None => {
                        *learned = Some(from);
                        return Ok(Some(n));
                    }
                }
            }
        };
        self.drop_foreign(from, peer, which);
        Ok(None)
    }

    /// Counts a datagram from `from`, not the peer (`which` says how the peer was chosen),
    /// and names its source once.
    fn drop_foreign(&self, from: SocketAddr, peer: SocketAddr, which: &str) {
        let foreign = &self.foreign.0;
        foreign.dropped.fetch_add(1, Ordering::Relaxed);
        let mut said = foreign.said.lock().unwrap_or_else(PoisonError::into_inner);
        if said.iter().any(|&source| same_source(source, from)) {
            return;
        }
        let line = match said.len() {
            n if n < MAX_FOREIGN_SOURCES_SAID => format!(
                "{}: dropped datagrams from {from}, not the peer {peer}{which}",
                foreign.device
            ),
            MAX_FOREIGN_SOURCES_SAID => format!(
                "{}: dropped datagrams from more than {MAX_FOREIGN_SOURCES_SAID} sources, \
                 not the peer {peer}{which}; further sources are counted, not named",
                foreign.device
            ),
            _ => return,
        };
        said.push(from);
        rovlink_base::io::warn(&program_name(), &line);
    }

    /// Receives one datagram and says who sent it, without learning the sender as the peer:
    /// the caller decides whom to answer ([`Datagrams::set_peer`]).
    pub fn recv_from(&self, buf: &mut [u8]) -> io::Result<(usize, SocketAddr)> {
        self.socket.recv_from(buf)
    }

    /// Makes `addr` the peer of a socket that learns its peer (`udpin:`); a fixed peer stays.
    pub fn set_peer(&self, addr: SocketAddr) {
        if let Peer::Learned(learned) = &self.peer {
            *learned.lock().unwrap_or_else(PoisonError::into_inner) = Some(addr);
        }
    }

    /// Sends one datagram to the peer; false when there is no peer yet (the packet is lost).
    pub fn send(&self, packet: &[u8]) -> io::Result<bool> {
        match self.peer() {
            Some(to) => self.socket.send_to(packet, to).map(|_| true),
            None => Ok(false),
        }
    }

    /// Sets how long a receive may wait (none: it waits).
    pub fn set_timeout(&self, timeout: Option<Duration>) -> io::Result<()> {
        self.socket.set_read_timeout(timeout)
    }
}

impl Read for Datagrams {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self.recv(buf)? {
            Some(0) | None => Err(io::ErrorKind::Interrupted.into()),
            Some(n) => Ok(n),
        }
    }
}

impl Write for Datagrams {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.send(buf).map(|_| buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// A pseudo-terminal pair this process created, in raw mode: programs open [`Pty::path`] as if
/// it were a serial port; the slave is kept open so the pair lives while they come and go.
pub struct Pty {
    master: PtyMaster,
    slave: File,
    path: String,
}

impl fmt::Debug for Pty {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Pty").field("path", &self.path).finish()
    }
}

impl Pty {
    /// A new pair, raw.
    pub fn create() -> nix::Result<Pty> {
        let master = posix_openpt(OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_CLOEXEC)?;
        grantpt(&master)?;
        unlockpt(&master)?;
        let path = ptsname_r(&master)?;
        let slave = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(OFlag::O_NOCTTY.bits())
            .open(&path)
            .map_err(|e| nix::Error::from_raw(e.raw_os_error().unwrap_or(0)))?;
        let mut termios = tcgetattr(&slave)?;
        cfmakeraw(&mut termios);
        tcsetattr(&slave, SetArg::TCSANOW, &termios)?;
        Ok(Pty {
            master,
            slave,
            path,
        })
    }

    /// The slave's path, which programs open.
    pub fn path(&self) -> &str {
        &self.path
    }
}

/// An open device cut in two for a reader thread and a writer thread.
pub struct Halves {
    /// Reads the device.
    pub reader: Box<dyn Read + Send>,
    /// Writes it (flushed by the caller).
    pub writer: Box<dyn Write + Send>,
    /// True for a UDP device: each read is one packet.
    pub datagrams: bool,
    /// A pseudo-terminal's slave, to keep open as long as the halves are used.
    pub keep: Option<File>,
    /// A UDP device's count of datagrams dropped because they were not its peer's.
    pub foreign: Option<ForeignDrops>,
}

/// A pseudo-terminal's master, shared by its reader and its writer.
struct Master(Arc<PtyMaster>);

impl Read for Master {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        (&*self.0).read(buf)
    }
}

impl Write for Master {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        (&*self.0).write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        (&*self.0).flush()
    }
}

impl Io {
    /// A reader and a writer of the same device (a listener has none: accept first).
    pub fn split(self) -> io::Result<Halves> {
        let halves = |reader: Box<dyn Read + Send>, writer: Box<dyn Write + Send>| Halves {
            reader,
            writer,
            datagrams: false,
            keep: None,
            foreign: None,
        };
        Ok(match self {
            Io::Serial(port) => {
                let writer = port.try_clone().map_err(io::Error::other)?;
                halves(Box::new(port), Box::new(writer))
            }
            Io::Pty(Pty { master, slave, .. }) => {
                let master = Arc::new(master);
                Halves {
                    keep: Some(slave),
                    ..halves(
                        Box::new(Master(Arc::clone(&master))),
                        Box::new(Master(master)),
                    )
                }
            }
            Io::Tcp(stream) => {
                let writer = stream.try_clone()?;
                halves(Box::new(stream), Box::new(writer))
            }
            Io::Udp(datagrams) => {
                let writer = datagrams.try_clone()?;
                Halves {
                    datagrams: true,
                    foreign: Some(datagrams.foreign_drops()),
                    ..halves(Box::new(datagrams), Box::new(writer))
                }
            }
            Io::Listener(_) => {
                return Err(io::Error::other(
                    "a listening socket: accept a connection first",
                ));
            }
        })
    }

    /// The device as one byte stream whose reads time out (a serial port, a TCP connection or
    /// a UDP socket); none for a pseudo-terminal pair or a listener.
    pub fn into_stream(self) -> Option<Box<dyn TimedRead>> {
        match self {
            Io::Serial(port) => Some(Box::new(port)),
            Io::Tcp(stream) => Some(Box::new(stream)),
            Io::Udp(datagrams) => Some(Box::new(datagrams)),
            Io::Pty(_) | Io::Listener(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<DeviceSpec, DeviceSpecError> {
        text.parse()
    }

    #[test]
    fn every_form_parses_and_prints_back() {
        let v4 = |text: &str| text.parse::<SocketAddr>().unwrap();
        let cases = [
            ("/dev/ttyUSB0", DeviceSpec::Path("/dev/ttyUSB0".into())),
            ("ttyUSB0", DeviceSpec::Path("ttyUSB0".into())),
            (
                "/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0",
                DeviceSpec::Path("/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0".into()),
            ),
            ("./odd:name", DeviceSpec::Path("./odd:name".into())),
            (
                "serial:/dev/ttyACM0:115200",
                DeviceSpec::Serial {
                    path: "/dev/ttyACM0".into(),
                    baud: 115200,
                },
            ),
            (
                "serial:/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0:57600",
                DeviceSpec::Serial {
                    path: "/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0".into(),
                    baud: 57600,
                },
            ),
            (
                "tcp:192.168.0.209:9200",
                DeviceSpec::Tcp("192.168.0.209:9200".into()),
            ),
            ("tcpin:[::1]:5761", DeviceSpec::TcpIn("[::1]:5761".into())),
            ("tcpin:0.0.0.0:0", DeviceSpec::TcpIn("0.0.0.0:0".into())),
            (
                "udp:0.0.0.0:5000=127.0.0.1:5001",
                DeviceSpec::Udp {
                    bind: v4("0.0.0.0:5000"),
                    peer: v4("127.0.0.1:5001"),
                },
            ),
            (
                "udp:[::1]:5000=[::1]:5001",
                DeviceSpec::Udp {
                    bind: v4("[::1]:5000"),
                    peer: v4("[::1]:5001"),
                },
            ),
            (
                "udpin:0.0.0.0:14550",
                DeviceSpec::UdpIn("0.0.0.0:14550".into()),
            ),
            (
                "udpout:localhost:14551",
                DeviceSpec::UdpOut("localhost:14551".into()),
            ),
            ("pty", DeviceSpec::Pty),
        ];
        for (text, expected) in cases {
            let parsed = parse(text).unwrap();
            assert_eq!(parsed, expected, "{text}");
            assert_eq!(parsed.to_string(), text, "canonical spelling");
            assert_eq!(parse(&parsed.to_string()).unwrap(), parsed);
        }
    }

    #[test]
    fn every_alias_reads_as_its_canonical_form() {
        for (alias, canonical) in [
            ("tcpout:localhost:5760", "tcp:localhost:5760"),
            ("udp:0.0.0.0:14550", "udpin:0.0.0.0:14550"),
            ("udp:[::]:14550", "udpin:[::]:14550"),
        ] {
            assert_eq!(parse(alias).unwrap(), parse(canonical).unwrap(), "{alias}");
            assert_eq!(parse(alias).unwrap().to_string(), canonical);
        }
        // Each alias of the table is one of these.
        assert_eq!(ALIASES.len(), 2);
        assert!(HELP.contains("tcpout:HOST:PORT = tcp:HOST:PORT"));
    }

    #[test]
    fn malformed_devices_say_what_was_expected_and_what_was_found() {
        let cases = [
            ("", "expected a path, serial:PATH:BAUD", "found nothing"),
            (
                "file:log.tlog",
                "expected a path, serial:",
                "no device kind 'file'",
            ),
            ("udpin:14550", "expected HOST:PORT", "found '14550'"),
            (
                "udpin::14550",
                "expected HOST:PORT",
                "found no host in ':14550'",
            ),
            (
                "udpout:host:port",
                "expected a port number 0..=65535 after the host",
                "found 'port'",
            ),
            ("udpout:host:70000", "0..=65535", "found '70000'"),
            (
                "tcp:127.0.0.1:0",
                "expected a port to connect to",
                "found 0 in '127.0.0.1:0'",
            ),
            ("tcpout:h:0", "expected a port to connect to", "found 0"),
            (
                "tcp:::1:5760",
                "expected an IPv6 host in brackets",
                "'::1:5760'",
            ),
            (
                "serial:/dev/ttyACM0",
                "expected serial:PATH:BAUD",
                "found 'serial:/dev/ttyACM0'",
            ),
            (
                "serial::",
                "expected a device path",
                "found nothing in 'serial::'",
            ),
            (
                "serial:/dev/ttyACM0:fast",
                "expected a baud rate (bits per second) after the device",
                "found 'fast'",
            ),
            ("serial:/dev/ttyACM0:0", "baud rate", "found '0'"),
            ("udp:nonsense", "expected HOST:PORT", "found 'nonsense'"),
            (
                "udp:127.0.0.1:0=x",
                "expected udp:BIND=PEER, both IP:PORT",
                "found 'x' (",
            ),
            ("udp:=127.0.0.1:1", "expected udp:BIND=PEER", "found '' ("),
        ];
        for (text, expected, found) in cases {
            let error = parse(text).unwrap_err().to_string();
            assert!(error.starts_with("expected "), "{text}: {error}");
            assert!(error.contains(expected), "{text}: {error}");
            assert!(error.contains(found), "{text}: {error}");
            assert!(!error.contains('\n'), "{error}");
        }
        // Listening on port 0 is allowed (an ephemeral port).
        assert!(parse("udpin:127.0.0.1:0").is_ok());
    }

    #[test]
    fn a_path_that_is_not_a_terminal_is_named_as_such() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("frames.bin");
        std::fs::write(&file, b"x").unwrap();
        let timeout = Duration::from_millis(50);
        for (path, what) in [
            (file.to_str().unwrap(), "a regular file, not a serial port"),
            (
                dir.path().to_str().unwrap(),
                "a directory, not a serial port",
            ),
            (
                "/dev/null",
                "a device that is not a terminal, not a serial port",
            ),
        ] {
            let Err(err) = open_serial(path, 9600, timeout) else {
                panic!("{path} opened");
            };
            let err = err.to_string();
            assert!(err.contains(what), "{err}");
            assert!(!err.contains("typewriter"), "{err}");
        }
        let Err(err) = open_serial("/no/such/tty", 9600, timeout) else {
            panic!("/no/such/tty opened");
        };
        let err = err.to_string();
        assert!(err.contains("No such file"), "{err}");
    }

    #[test]
    fn a_pty_opens_only_where_it_is_offered() {
        let Err(err) = open(&DeviceSpec::Pty, &OpenOptions::default()) else {
            panic!("a pty opened where none is offered");
        };
        assert!(err.to_string().starts_with("pty: cannot create: "), "{err}");
        let options = OpenOptions {
            pty: true,
            ..OpenOptions::default()
        };
        let device = open(&DeviceSpec::Pty, &options).unwrap();
        assert!(device.name.starts_with("/dev/"), "{}", device.name);
        let halves = device.io.split().unwrap();
        assert!(halves.keep.is_some() && !halves.datagrams);
    }

    /// A UDP device opened with reads that wait 5 s at most.
    fn open_udp(spec: &str) -> Datagrams {
        let options = OpenOptions {
            read_timeout: Some(Duration::from_secs(5)),
            ..OpenOptions::default()
        };
        let Io::Udp(datagrams) = open(&spec.parse().unwrap(), &options).unwrap().io else {
            panic!("{spec}: not UDP");
        };
        datagrams
    }

    /// The next datagram the device takes, with how many it dropped before it.
    fn next_taken(device: &Datagrams) -> (Vec<u8>, u64) {
        let mut buf = [0u8; 64];
        let before = device.foreign_drops().count();
        loop {
            if let Some(n) = device.recv(&mut buf).unwrap() {
                return (buf[..n].to_vec(), device.foreign_drops().count() - before);
            }
        }
    }

    #[test]
    fn udpin_keeps_its_first_sender_and_udpout_sends_to_its_host() {
        let mut listening = open_udp("udpin:127.0.0.1:0");
        // Nobody has spoken: a packet is dropped, not an error.
        assert!(!listening.send(b"lost").unwrap());
        let at = listening.local_addr().unwrap();
        let mut sending = open_udp(&format!("udpout:{at}"));
        sending.write_all(b"hello").unwrap();
        let mut buf = [0u8; 16];
        assert_eq!(listening.read(&mut buf).unwrap(), 5);
        let learned = listening.peer().map(|peer| peer.port());
        assert_eq!(learned, Some(sending.local_addr().unwrap().port()));
        // Someone else speaks next: dropped, and the peer stays the first sender.
        let intruder = UdpSocket::bind("127.0.0.1:0").unwrap();
        intruder.send_to(b"mine now", at).unwrap();
        sending.write_all(b"again").unwrap();
        assert_eq!(next_taken(&listening), (b"again".to_vec(), 1));
        assert_eq!(listening.peer().map(|peer| peer.port()), learned);
        listening.write_all(b"back").unwrap();
        assert_eq!(sending.read(&mut buf).unwrap(), 4);
        // The answer goes to the first sender, not to the intruder.
        assert_eq!(&buf[..4], b"back");
    }

    #[test]
    fn udp_bind_peer_takes_only_datagrams_from_its_peer() {
        let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
        let device = open_udp(&format!("udp:127.0.0.1:0={}", peer.local_addr().unwrap()));
        let at = device.local_addr().unwrap();
        let foreign = UdpSocket::bind("127.0.0.1:0").unwrap();
        foreign.send_to(b"forged", at).unwrap();
        foreign.send_to(b"forged again", at).unwrap();
        peer.send_to(b"frame", at).unwrap();
        assert_eq!(next_taken(&device), (b"frame".to_vec(), 2));
        // A split device still counts (the reader half's drops are the device's).
        let Halves {
            foreign: Some(count),
            ..
        } = Io::Udp(device).split().unwrap()
        else {
            panic!("a UDP device's halves carry its count");
        };
        assert_eq!(count.count(), 2);
    }

    #[test]
    fn a_source_is_its_address_and_port_whatever_its_family() {
        let v4: SocketAddr = "127.0.0.1:9001".parse().unwrap();
        let mapped: SocketAddr = "[::ffff:127.0.0.1]:9001".parse().unwrap();
        assert!(same_source(v4, mapped));
        assert!(!same_source(v4, "127.0.0.1:9002".parse().unwrap()));
        assert!(!same_source(v4, "127.0.0.2:9001".parse().unwrap()));
        assert!(!same_source(
            "[::1]:9001".parse().unwrap(),
            "[::2]:9001".parse().unwrap()
        ));
    }

    #[test]
    fn tcpin_accepts_one_peer_or_hands_over_its_listener() {
        let free = TcpListener::bind("127.0.0.1:0").unwrap();
        let at = free.local_addr().unwrap();
        drop(free);
        let spec: DeviceSpec = format!("tcpin:{at}").parse().unwrap();
        let keep = OpenOptions {
            accept: false,
            ..OpenOptions::default()
        };
        let device = open(&spec, &keep).unwrap();
        assert!(matches!(device.io, Io::Listener(_)), "{:?}", device.io);
        drop(device);
        let server = std::thread::spawn(move || open(&spec, &OpenOptions::default()));
        let connect: DeviceSpec = format!("tcp:{at}").parse().unwrap();
        let patient = OpenOptions {
            connect_timeout: Some(Duration::from_secs(5)),
            ..OpenOptions::default()
        };
        let client = (0..250)
            .find_map(|_| {
                let opened = open(&connect, &patient).ok();
                if opened.is_none() {
                    std::thread::sleep(Duration::from_millis(20));
                }
                opened
            })
            .expect("the listener accepts");
        let Io::Tcp(mut client) = client.io else {
            panic!("not TCP");
        };
        let Io::Tcp(mut accepted) = server.join().unwrap().unwrap().io else {
            panic!("not TCP");
        };
        client.write_all(b"x").unwrap();
        let mut buf = [0u8; 1];
        accepted.read_exact(&mut buf).unwrap();
        assert_eq!(&buf, b"x");
    }

    proptest::proptest! {
        #[test]
        fn parsing_never_panics(text in "\\PC{0,40}") {
            let _ = parse(&text);
        }

        #[test]
        fn device_like_text_parses_back_from_its_spelling(
            kind in "(udpin|udpout|tcpin|tcpout|serial|udp|tcp|pty|x|/dev/tty)",
            rest in "[\\[\\]:=0-9a-z./]{0,24}",
        ) {
            let text = format!("{kind}:{rest}");
            if let Ok(parsed) = parse(&text) {
                proptest::prop_assert_eq!(parse(&parsed.to_string()).unwrap(), parsed);
            }
        }
    }
}
