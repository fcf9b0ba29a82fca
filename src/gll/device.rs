//! Opening a device: the one function every tool uses to turn a device name into an
//! [`Endpoint`], with the options the command line's port flags give.
//!
//! A device is a serial port or pseudo-terminal path, `tcp:HOST:PORT` (a modem's TCP console,
//! EvoLogics' usual interface) or `udp:BIND_ADDR=PEER_ADDR` (one datagram per packet).

use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::time::Duration;

use super::evologics::{EvoLogics, SendMode};
use super::{Endpoint, GllError, Pacing, TimedRead, Transparent, Udp, open_serial};

/// How a modem is spoken to: the one dialect enum of every tool that opens a port.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Dialect {
    /// Bytes in, bytes out (S100-like, or link-sim --pty): packets are wire.md frames.
    #[default]
    Transparent,
    /// EvoLogics AT commands: AT*SEND bursts (or instant AT*SENDIM), RECV notifications.
    Evologics,
}

impl Dialect {
    /// Every dialect with its command-line name.
    pub const ALL: [(Dialect, &'static str); 2] = [
        (Dialect::Transparent, "transparent"),
        (Dialect::Evologics, "evologics"),
    ];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Dialect::Transparent => "transparent",
            Dialect::Evologics => "evologics",
        }
    }
}

/// How a device is opened and spoken to (the command line's `cli::port::PortArgs`).
#[derive(Debug, Clone, PartialEq)]
pub struct PortOptions {
    /// How the modem is spoken to.
    pub dialect: Dialect,
    /// EvoLogics: send instant messages (AT*SENDIM) instead of bursts.
    pub instant: bool,
    /// EvoLogics: the destination address of the packets.
    pub address: u32,
    /// Baud rate of serial ports.
    pub baud: u32,
    /// Transparent modems: write each packet in chunks of this many bytes.
    pub chunk_bytes: Option<u64>,
    /// The rate chunk pauses are computed from, bit/s.
    pub chunk_rate_bps: f64,
}

impl Default for PortOptions {
    fn default() -> PortOptions {
        PortOptions {
            dialect: Dialect::Transparent,
            instant: false,
            address: 2,
            baud: 9600,
            chunk_bytes: None,
            chunk_rate_bps: 1900.0,
        }
    }
}

/// Why a device could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum PortError {
    /// The device name or the flags are wrong (bad usage).
    #[error("{0}")]
    Usage(String),
    /// The device did not open.
    #[error(transparent)]
    Open(#[from] GllError),
}

impl PortOptions {
    /// True when any flag differs from its default (they only mean something with a device).
    pub fn any_set(&self) -> bool {
        self.dialect != Dialect::Transparent || self.instant || self.chunk_bytes.is_some()
    }

    /// Opens `device` as these flags say.
    pub fn open(&self, device: &str) -> Result<Box<dyn Endpoint>, PortError> {
        if let Some((bind, peer)) = udp_addresses(device)? {
            if self.dialect != Dialect::Transparent {
                return Err(PortError::Usage(format!(
                    "{device}: UDP carries bare datagrams: use --dialect transparent"
                )));
            }
            return Ok(Box::new(Udp::open(bind, peer)?));
        }
        if !(self.chunk_rate_bps.is_finite() && self.chunk_rate_bps > 0.0) {
            return Err(PortError::Usage(format!(
                "--chunk-rate-bps: expected bit/s > 0, found {}",
                self.chunk_rate_bps
            )));
        }
        let pacing = self.chunk_bytes.map(|chunk_bytes| Pacing {
            chunk_bytes: usize::try_from(chunk_bytes).unwrap_or(usize::MAX),
            rate_bps: self.chunk_rate_bps,
        });
        let mode = if self.instant {
            SendMode::Instant { ack: false }
        } else {
            SendMode::Burst
        };
        if let Some(address) = device.strip_prefix("tcp:") {
            let stream = connect_tcp(device, address)?;
            return Ok(match self.dialect {
                Dialect::Transparent => Box::new(Transparent::new(device, stream, pacing)),
                Dialect::Evologics => Box::new(EvoLogics::new(device, stream, self.address, mode)),
            });
        }
        let port = open_serial(device, self.baud)?;
        Ok(match self.dialect {
            Dialect::Transparent => Box::new(Transparent::new(device, port, pacing)),
            Dialect::Evologics => Box::new(EvoLogics::new(device, port, self.address, mode)),
        })
    }
}

impl PortOptions {
    /// Opens `device` as a bare byte stream whose reads time out after `timeout`, for tools
    /// that watch a line's bytes as they come (`rcp-dump --port`): a serial port or
    /// pseudo-terminal at the baud rate, a TCP console, or UDP datagrams back to back. No
    /// dialect is spoken.
    pub fn open_bytes(
        &self,
        device: &str,
        timeout: Duration,
    ) -> Result<Box<dyn TimedRead>, PortError> {
        let mut port: Box<dyn TimedRead> = if let Some((bind, peer)) = udp_addresses(device)? {
            let socket = UdpSocket::bind(bind).map_err(|e| GllError::Open {
                name: device.to_string(),
                reason: e.to_string(),
            })?;
            Box::new(UdpBytes { socket, peer })
        } else if let Some(address) = device.strip_prefix("tcp:") {
            Box::new(connect_tcp(device, address)?)
        } else {
            Box::new(open_serial(device, self.baud)?)
        };
        port.set_read_timeout(timeout).map_err(|e| GllError::Open {
            name: device.to_string(),
            reason: e.to_string(),
        })?;
        Ok(port)
    }
}

/// The addresses of a `udp:BIND_ADDR=PEER_ADDR` device; `None` for another device.
fn udp_addresses(device: &str) -> Result<Option<(SocketAddr, SocketAddr)>, PortError> {
    let Some(spec) = device.strip_prefix("udp:") else {
        return Ok(None);
    };
    let Some((bind, peer)) = spec.split_once('=') else {
        return Err(PortError::Usage(format!(
            "{device}: expected udp:BIND_ADDR=PEER_ADDR"
        )));
    };
    let parse = |text: &str| {
        text.parse::<SocketAddr>()
            .map_err(|e| PortError::Usage(format!("{device}: `{text}`: {e}")))
    };
    Ok(Some((parse(bind)?, parse(peer)?)))
}

/// Connects a `tcp:HOST:PORT` device.
fn connect_tcp(device: &str, address: &str) -> Result<TcpStream, GllError> {
    let stream = TcpStream::connect(address).map_err(|e| GllError::Open {
        name: device.to_string(),
        reason: e.to_string(),
    })?;
    let _ = stream.set_nodelay(true);
    Ok(stream)
}

/// A UDP socket read as a byte stream: each datagram's bytes in turn (empty ones skipped);
/// writes go to the peer.
struct UdpBytes {
    socket: UdpSocket,
    peer: SocketAddr,
}

impl Read for UdpBytes {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self.socket.recv(buf)? {
            0 => Err(io::ErrorKind::WouldBlock.into()),
            n => Ok(n),
        }
    }
}

impl Write for UdpBytes {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.socket.send_to(buf, self.peer)
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl TimedRead for UdpBytes {
    fn set_read_timeout(&mut self, timeout: Duration) -> io::Result<()> {
        self.socket
            .set_read_timeout(Some(timeout.max(Duration::from_micros(1))))
    }
}
