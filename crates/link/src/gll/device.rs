//! Opening a modem: the options the command line's port flags give ([`PortOptions`]), and the
//! adapter they put on a device that [`crate::device::open`] opened (named in the one grammar,
//! [`DeviceSpec`]: a serial port or pseudo-terminal path, `serial:PATH:BAUD`, `tcp:`, `tcpin:`,
//! `udp:BIND=PEER`, `udpin:`, `udpout:`).

use std::time::Duration;

use super::evologics::{EvoLogics, SendMode};
use super::{Endpoint, GllError, Pacing, TimedRead, Transparent, Udp};
use crate::device::{self, DeviceSpec, Io, OpenError, OpenOptions};

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
    /// Every dialect, in the order `--help` lists them.
    pub const ALL: [Dialect; 2] = [Dialect::Transparent, Dialect::Evologics];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Dialect::Transparent => "transparent",
            Dialect::Evologics => "evologics",
        }
    }

    /// What the dialect is, for `--help`.
    pub fn help(self) -> &'static str {
        match self {
            Dialect::Transparent => "bytes in, bytes out: packets are wire.md frames",
            Dialect::Evologics => "EvoLogics AT commands (AT*SEND / AT*SENDIM, RECV)",
        }
    }

    /// The destination address every modem in range takes, for a dialect whose packets carry
    /// a destination; none for bare packets. A node of a routed network sends every packet
    /// there (tdma-run `--routes`): its neighbours' routers decide who takes a frame.
    pub fn broadcast_address(self) -> Option<u32> {
        match self {
            Dialect::Transparent => None,
            Dialect::Evologics => Some(super::evologics::BROADCAST_ADDRESS),
        }
    }

    /// True when link-sim emulates the dialect only between the two sides of a link (an
    /// emulated modem has its side's address, 1 or 2), not on a shared medium of more ports
    /// (`link-sim --pty N`, N > 2). Bare packets go anywhere.
    pub fn two_sides_only(self) -> bool {
        match self {
            Dialect::Transparent => false,
            Dialect::Evologics => true,
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

impl From<OpenError> for PortError {
    fn from(error: OpenError) -> PortError {
        PortError::Open(GllError::Open {
            name: error.device,
            reason: error.error.to_string(),
        })
    }
}

/// Parses a device flag's text: a usage error naming it when it is not a device.
fn parse(device: &str) -> Result<DeviceSpec, PortError> {
    device
        .parse()
        .map_err(|e| PortError::Usage(format!("{device}: {e}")))
}

impl PortOptions {
    /// True when any flag differs from its default (they only mean something with a device).
    pub fn any_set(&self) -> bool {
        self.dialect != Dialect::Transparent || self.instant || self.chunk_bytes.is_some()
    }

    /// How the one opener opens a modem's device: at the baud rate, serial reads waiting
    /// 50 ms at most (each receive sets its own wait).
    fn open_options(&self) -> OpenOptions {
        OpenOptions {
            baud: self.baud,
            ..OpenOptions::default()
        }
    }

    /// Opens `device` (in the grammar of [`DeviceSpec`]) as these flags say.
    pub fn open(&self, device: &str) -> Result<Box<dyn Endpoint>, PortError> {
        self.open_spec(&parse(device)?)
    }

    /// Opens `spec` as these flags say: the dialect's adapter on the device (UDP carries bare
    /// datagrams: transparent only).
    pub fn open_spec(&self, spec: &DeviceSpec) -> Result<Box<dyn Endpoint>, PortError> {
        if spec.is_datagram() && self.dialect != Dialect::Transparent {
            return Err(PortError::Usage(format!(
                "{spec}: UDP carries bare datagrams: use --dialect transparent"
            )));
        }
        if !(self.chunk_rate_bps.is_finite() && self.chunk_rate_bps > 0.0) {
            return Err(PortError::Usage(format!(
                "--chunk-rate-bps: expected bit/s > 0, found {}",
                self.chunk_rate_bps
            )));
        }
        let opened = device::open(spec, &self.open_options())?;
        let name = opened.name;
        if let Io::Udp(socket) = opened.io {
            return Ok(Box::new(Udp::new(socket)));
        }
        let Some(stream) = opened.io.into_stream() else {
            return Err(PortError::Usage(format!("{spec}: not a modem's device")));
        };
        let pacing = self.chunk_bytes.map(|chunk_bytes| Pacing {
            chunk_bytes: usize::try_from(chunk_bytes).unwrap_or(usize::MAX),
            rate_bps: self.chunk_rate_bps,
        });
        let mode = if self.instant {
            SendMode::Instant { ack: false }
        } else {
            SendMode::Burst
        };
        Ok(match self.dialect {
            Dialect::Transparent => Box::new(Transparent::new(&name, stream, pacing)),
            Dialect::Evologics => Box::new(EvoLogics::new(&name, stream, self.address, mode)),
        })
    }

    /// Opens `device` as a bare byte stream whose reads time out after `timeout`, for tools
    /// that watch a line's bytes as they come (`rcp-dump --port`): a serial port or
    /// pseudo-terminal at the baud rate, a TCP connection, or UDP datagrams back to back. No
    /// dialect is spoken.
    pub fn open_bytes(
        &self,
        device: &str,
        timeout: Duration,
    ) -> Result<Box<dyn TimedRead>, PortError> {
        let spec = parse(device)?;
        let opened = device::open(&spec, &self.open_options())?;
        let Some(mut port) = opened.io.into_stream() else {
            return Err(PortError::Usage(format!("{spec}: not a byte stream")));
        };
        port.set_read_timeout(timeout).map_err(|e| GllError::Open {
            name: opened.name,
            reason: e.to_string(),
        })?;
        Ok(port)
    }
}
