//! Device adapters: "a modem endpoint" behind one trait, whatever the modem is.
//!
//! An [`Endpoint`] sends a packet and receives packets stamped with the host's monotonic clock
//! at the moment their last byte was read. Adapters:
//!
//! - [`Transparent`]: a modem in transparent mode on a serial port or pseudo-terminal (the WFS
//!   S100, or `link-sim --pty`): bytes in, bytes out; packets are wire.md frames found by the
//!   deframer; writes can be cut into chunks paced at the air rate, as the S100 driver does;
//! - [`evologics::EvoLogics`]: the EvoLogics AT dialect (burst `AT*SEND`, instant messages
//!   `AT*SENDIM`) over a serial port or TCP;
//! - [`Udp`]: a UDP socket, one datagram per packet.
//!
//! Devices are named and opened by [`crate::device`] (the one grammar and the one opener);
//! [`PortOptions::open`] puts the adapter the dialect says on what it opened.
//!
//! The simulated link needs no adapter: in virtual time the tools drive a [`crate::Link`]
//! directly.

pub mod device;
pub mod evologics;

pub use crate::device::TimedRead;
pub use device::{Dialect, PortError, PortOptions};

use std::io;
use std::time::{Duration, Instant};

use crate::device::Datagrams;
use rovlink_wire::{DeframeEvent, Deframer};

/// A packet that arrived.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Received {
    /// When its last byte was read.
    pub at: Instant,
    /// Its bytes.
    pub bytes: Vec<u8>,
    /// True when the modem said it arrived with errors (EvoLogics' integrity), if it says.
    pub damaged: bool,
}

/// What went wrong with an endpoint.
#[derive(Debug, thiserror::Error)]
pub enum GllError {
    /// The device could not be opened.
    #[error("{name}: cannot open: {reason}")]
    Open {
        /// The device or address.
        name: String,
        /// Why.
        reason: String,
    },
    /// The device closed or failed while in use.
    #[error("{name}: {reason}")]
    Closed {
        /// The device or address.
        name: String,
        /// What happened.
        reason: String,
    },
    /// The modem answered a command with an error.
    #[error("{name}: modem refused: {reply}")]
    Refused {
        /// The device.
        name: String,
        /// Its reply.
        reply: String,
    },
}

/// A modem endpoint: send packets, receive packets with host timestamps.
pub trait Endpoint {
    /// The device or address, for messages.
    fn name(&self) -> &str;
    /// Sends one packet.
    fn send(&mut self, packet: &[u8]) -> Result<(), GllError>;
    /// Waits until `deadline` at most for a packet; `None` when none came.
    fn receive(&mut self, deadline: Instant) -> Result<Option<Received>, GllError>;
    /// Commands the modem refused so far (`ERROR ...`, `BUSY ...`), for the report.
    fn refusals(&self) -> &[String] {
        &[]
    }
    /// Datagrams dropped because they came from someone other than the peer (UDP only).
    fn foreign_datagrams_dropped(&self) -> u64 {
        0
    }
}

/// Reads once from `port`, waiting until `deadline` at most: `Ok(None)` on timeout.
fn read_until(
    port: &mut dyn TimedRead,
    name: &str,
    deadline: Instant,
    buf: &mut [u8],
) -> Result<Option<usize>, GllError> {
    let wait = deadline.saturating_duration_since(Instant::now());
    if wait.is_zero() {
        return Ok(None);
    }
    port.set_read_timeout(wait)
        .map_err(|e| closed(name, "set timeout", e))?;
    match port.read(buf) {
        Ok(0) => Err(GllError::Closed {
            name: name.to_string(),
            reason: "closed (end of file)".into(),
        }),
        Ok(n) => Ok(Some(n)),
        Err(e) if rovlink_base::io::nothing_yet(&e) => Ok(None),
        Err(e) => Err(closed(name, "read failed", e)),
    }
}

fn closed(name: &str, what: &str, err: io::Error) -> GllError {
    GllError::Closed {
        name: name.to_string(),
        reason: format!("{what}: {err}"),
    }
}

/// Write pacing of a transparent modem: chunks of `chunk_bytes`, each followed by its air time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pacing {
    /// Bytes per chunk.
    pub chunk_bytes: usize,
    /// The air rate the pause is computed from, bit/s.
    pub rate_bps: f64,
}

/// A transparent modem on a byte stream: wire.md frames in both directions.
pub struct Transparent<P: TimedRead> {
    name: String,
    port: P,
    pacing: Option<Pacing>,
    deframer: Deframer,
    ready: std::collections::VecDeque<Received>,
}

impl<P: TimedRead> Transparent<P> {
    /// An adapter over an open port.
    pub fn new(name: &str, port: P, pacing: Option<Pacing>) -> Transparent<P> {
        Transparent {
            name: name.to_string(),
            port,
            pacing,
            deframer: Deframer::new(),
            ready: std::collections::VecDeque::new(),
        }
    }
}

impl<P: TimedRead> Endpoint for Transparent<P> {
    fn name(&self) -> &str {
        &self.name
    }

    fn send(&mut self, packet: &[u8]) -> Result<(), GllError> {
        let chunk = self
            .pacing
            .map_or(packet.len().max(1), |p| p.chunk_bytes.max(1));
        for (k, part) in packet.chunks(chunk).enumerate() {
            if k > 0
                && let Some(pacing) = self.pacing
            {
                let pause = chunk as f64 * 8.0 / pacing.rate_bps;
                std::thread::sleep(Duration::from_secs_f64(pause.clamp(0.0, 10.0)));
            }
            self.port
                .write_all(part)
                .and_then(|()| self.port.flush())
                .map_err(|e| closed(&self.name, "write failed", e))?;
        }
        Ok(())
    }

    fn receive(&mut self, deadline: Instant) -> Result<Option<Received>, GllError> {
        let mut buf = [0u8; 4096];
        loop {
            if let Some(packet) = self.ready.pop_front() {
                return Ok(Some(packet));
            }
            let Some(n) = read_until(&mut self.port, &self.name, deadline, &mut buf)? else {
                return Ok(None);
            };
            let at = Instant::now();
            self.deframer.push(&buf[..n]);
            while let Some(event) = self.deframer.next_event() {
                if let DeframeEvent::Frame { frame, .. } = event {
                    self.ready.push_back(Received {
                        at,
                        bytes: frame.into_inner().to_vec(),
                        damaged: false,
                    });
                }
            }
        }
    }
}

/// A UDP device: one datagram per packet, sent to its peer.
pub struct Udp {
    name: String,
    socket: Datagrams,
}

impl Udp {
    /// An adapter over an open UDP device.
    pub fn new(socket: Datagrams) -> Udp {
        let local = socket
            .local_addr()
            .map_or_else(|_| "?".to_string(), |a| a.to_string());
        let peer = socket
            .peer()
            .map_or_else(|| "the first sender".to_string(), |a| a.to_string());
        Udp {
            name: format!("udp {local} -> {peer}"),
            socket,
        }
    }
}

impl Endpoint for Udp {
    fn name(&self) -> &str {
        &self.name
    }

    fn send(&mut self, packet: &[u8]) -> Result<(), GllError> {
        self.socket
            .send(packet)
            .map(|_| ())
            .map_err(|e| closed(&self.name, "send failed", e))
    }

    fn receive(&mut self, deadline: Instant) -> Result<Option<Received>, GllError> {
        let mut buf = vec![0u8; 65_536];
        loop {
            let wait = deadline.saturating_duration_since(Instant::now());
            if wait.is_zero() {
                return Ok(None);
            }
            self.socket
                .set_timeout(Some(wait))
                .map_err(|e| closed(&self.name, "set timeout", e))?;
            match self.socket.recv(&mut buf) {
                Ok(Some(n)) => {
                    buf.truncate(n);
                    return Ok(Some(Received {
                        at: Instant::now(),
                        bytes: buf,
                        damaged: false,
                    }));
                }
                // Not the peer's: dropped (and counted); wait for the rest of the time.
                Ok(None) => {}
                // A signal interrupts a receive with a timeout whatever SA_RESTART says: the
                // caller looks at its stop flag.
                Err(e) if rovlink_base::io::nothing_yet(&e) => return Ok(None),
                Err(e) => return Err(closed(&self.name, "receive failed", e)),
            }
        }
    }

    fn foreign_datagrams_dropped(&self) -> u64 {
        self.socket.foreign_drops().count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_udp_endpoint_receives_its_peers_packets_and_counts_the_others() {
        let peer = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let spec = format!("udp:127.0.0.1:0={}", peer.local_addr().unwrap());
        let opened = crate::device::open(&spec.parse().unwrap(), &Default::default()).unwrap();
        let crate::device::Io::Udp(socket) = opened.io else {
            panic!("{spec}: not UDP");
        };
        let at = socket.local_addr().unwrap();
        let mut endpoint = Udp::new(socket);
        let foreign = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        foreign.send_to(b"forged", at).unwrap();
        peer.send_to(b"frame", at).unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        let received = endpoint
            .receive(deadline)
            .unwrap()
            .expect("the peer's packet");
        assert_eq!(received.bytes, b"frame");
        assert_eq!(endpoint.foreign_datagrams_dropped(), 1);
    }
}
