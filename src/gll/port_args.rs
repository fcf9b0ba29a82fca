//! The flags every tool that talks to a real modem shares (`modem-bench`, `tdma-run`), and the
//! one function that turns a device name into an [`Endpoint`].
//!
//! A device is a serial port or pseudo-terminal path, `tcp:HOST:PORT` (a modem's TCP console,
//! EvoLogics' usual interface) or `udp:BIND_ADDR=PEER_ADDR` (one datagram per packet).

use std::net::SocketAddr;

use super::evologics::{EvoLogics, SendMode};
use super::{Endpoint, GllError, Pacing, Transparent, Udp, open_serial};

/// How a modem is spoken to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Dialect {
    /// Bytes in, bytes out (S100-like, or link-sim --pty): packets are wire.md frames.
    Transparent,
    /// EvoLogics AT commands: AT*SEND bursts (or --instant for AT*SENDIM), RECV notifications.
    Evologics,
}

/// The modem flags, flattened into a tool's arguments.
#[derive(clap::Args, Debug, Clone, PartialEq)]
pub struct PortArgs {
    /// How the modems are spoken to.
    #[arg(long, value_enum, default_value_t = Dialect::Transparent, help_heading = "Real modems")]
    pub dialect: Dialect,

    /// EvoLogics: send instant messages (AT*SENDIM, up to 64 bytes) instead of bursts.
    #[arg(long, help_heading = "Real modems")]
    pub instant: bool,

    /// EvoLogics: the destination address of the packets.
    #[arg(
        long,
        value_name = "ADDR",
        default_value_t = 2,
        help_heading = "Real modems"
    )]
    pub address: u32,

    /// Baud rate of the serial ports.
    #[arg(long, default_value_t = 9600, value_parser = clap::value_parser!(u32).range(1..), help_heading = "Real modems")]
    pub baud: u32,

    /// Transparent modems: write each packet in chunks of this many bytes, paced at --chunk-rate-bps
    /// (the S100 driver sends 45-byte chunks at the air rate, without flow control).
    #[arg(long, value_name = "BYTES", value_parser = clap::value_parser!(u64).range(1..), help_heading = "Real modems")]
    pub chunk_bytes: Option<u64>,

    /// The rate chunk pauses are computed from, bit/s.
    #[arg(
        long,
        value_name = "BPS",
        default_value_t = 1900.0,
        help_heading = "Real modems"
    )]
    pub chunk_rate_bps: f64,
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

impl PortArgs {
    /// True when any flag differs from its default (they only mean something with a device).
    pub fn any_set(&self) -> bool {
        self.dialect != Dialect::Transparent || self.instant || self.chunk_bytes.is_some()
    }

    /// Opens `device` as these flags say.
    pub fn open(&self, device: &str) -> Result<Box<dyn Endpoint>, PortError> {
        if let Some(spec) = device.strip_prefix("udp:") {
            let Some((bind, peer)) = spec.split_once('=') else {
                return Err(PortError::Usage(format!(
                    "{device}: expected udp:BIND_ADDR=PEER_ADDR"
                )));
            };
            let parse = |text: &str| {
                text.parse::<SocketAddr>()
                    .map_err(|e| PortError::Usage(format!("{device}: `{text}`: {e}")))
            };
            if self.dialect != Dialect::Transparent {
                return Err(PortError::Usage(format!(
                    "{device}: UDP carries bare datagrams: use --dialect transparent"
                )));
            }
            return Ok(Box::new(Udp::open(parse(bind)?, parse(peer)?)?));
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
            let stream = std::net::TcpStream::connect(address).map_err(|e| GllError::Open {
                name: device.to_string(),
                reason: e.to_string(),
            })?;
            let _ = stream.set_nodelay(true);
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
