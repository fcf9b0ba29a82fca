//! The link under the transport: a device of the toolkit's one grammar (serial port, PTY,
//! `tcp:`, `udp:` ...) carrying each segment as the payload of one wire.md link frame, from
//! the vehicle's address to the operator's or back.
//!
//! A reader thread deframes what comes in and hands over the payloads of good frames addressed
//! from the peer to this end; everything else is counted, never handed over: bytes that belong
//! to no good frame (noise, garbage, a corrupted frame), frames whose CRC fails, frames from or
//! to another address (a third modem).

use std::io::{self, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use rovlink_link::device::{self, DeviceSpec, OpenOptions};
use rovlink_wire::deframe::{DeframeEvent, Deframer};

/// What the reader hands over.
#[derive(Debug)]
pub enum Carried {
    /// A segment: the payload of a good frame from the peer.
    Segment(Vec<u8>),
    /// The device closed or failed.
    Closed(String),
}

/// What came in that was not a segment, and what went out.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct CarrierCounters {
    /// Bytes read.
    pub bytes_in: u64,
    /// Bytes written (frames).
    pub bytes_out: u64,
    /// Good frames from the peer to this end.
    pub frames_in: u64,
    /// Frames written.
    pub frames_out: u64,
    /// Frames whose CRC failed.
    pub crc_failures: u64,
    /// Bytes that belong to no good frame.
    pub bytes_skipped: u64,
    /// Good frames from or to another address, dropped.
    pub foreign_frames: u64,
}

/// One end of the link: the device's writer and the addresses.
pub struct Carrier {
    writer: Box<dyn Write + Send>,
    /// A pseudo-terminal's slave, kept open while the carrier lives.
    _keep: Option<std::fs::File>,
    local: u8,
    peer: u8,
    counters: Arc<Mutex<CarrierCounters>>,
    /// The device's name for messages.
    pub name: String,
}

impl Carrier {
    /// Opens `spec` (serial ports at `baud`) as the end at address `local` talking to `peer`;
    /// the reader thread hands what it reads to `hand` until `hand` returns false, the device
    /// closes, or `stop` is set.
    pub fn open(
        spec: &DeviceSpec,
        baud: u32,
        local: u8,
        peer: u8,
        stop: Arc<AtomicBool>,
        hand: Box<dyn Fn(Carried) -> bool + Send>,
    ) -> Result<Carrier, String> {
        let options = OpenOptions {
            baud,
            serial_timeout: Duration::from_millis(100),
            read_timeout: Some(Duration::from_millis(100)),
            ..OpenOptions::default()
        };
        let dev = device::open(spec, &options).map_err(|e| e.to_string())?;
        let name = dev.name.clone();
        let halves = dev.io.split().map_err(|e| format!("{name}: {e}"))?;
        let counters = Arc::new(Mutex::new(CarrierCounters::default()));
        let shared = Arc::clone(&counters);
        let mut reader = halves.reader;
        let datagrams = halves.datagrams;
        std::thread::spawn(move || {
            let mut deframer = Deframer::new();
            let mut buf = vec![0u8; 64 * 1024];
            let closed = loop {
                if stop.load(Ordering::Relaxed) {
                    break None;
                }
                let n = match reader.read(&mut buf) {
                    Ok(0) => break Some("end of stream".to_string()),
                    Ok(n) => n,
                    Err(e) if rovlink_base::io::nothing_yet(&e) => {
                        if deframer.pending_bytes() > 0 {
                            deframer.abandon_incomplete();
                            if !drain(&mut deframer, local, peer, &shared, &hand) {
                                break None;
                            }
                        }
                        continue;
                    }
                    Err(e) => break Some(e.to_string()),
                };
                deframer.push(&buf[..n]);
                if datagrams {
                    // A datagram is whole: a frame it started cannot go on in the next.
                    deframer.abandon_incomplete();
                }
                lock(&shared).bytes_in += n as u64;
                if !drain(&mut deframer, local, peer, &shared, &hand) {
                    break None;
                }
            };
            if let Some(reason) = closed {
                hand(Carried::Closed(reason));
            }
        });
        Ok(Carrier {
            writer: halves.writer,
            _keep: halves.keep,
            local,
            peer,
            counters,
            name,
        })
    }

    /// Sends a segment in one frame.
    pub fn send(&mut self, segment: &[u8]) -> io::Result<()> {
        let frame = rovlink_wire::frame::build(self.local, self.peer, segment)
            .map_err(|e| io::Error::other(e.to_string()))?;
        self.writer.write_all(&frame)?;
        self.writer.flush()?;
        let mut c = lock(&self.counters);
        c.bytes_out += frame.len() as u64;
        c.frames_out += 1;
        Ok(())
    }

    /// The counters so far.
    pub fn counters(&self) -> CarrierCounters {
        *lock(&self.counters)
    }
}

fn lock(m: &Mutex<CarrierCounters>) -> std::sync::MutexGuard<'_, CarrierCounters> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Hands over the good frames' payloads; false when the receiver is gone.
fn drain(
    deframer: &mut Deframer,
    local: u8,
    peer: u8,
    counters: &Mutex<CarrierCounters>,
    hand: &dyn Fn(Carried) -> bool,
) -> bool {
    while let Some(event) = deframer.next_event() {
        match event {
            DeframeEvent::Frame { frame, .. } => {
                if frame.src() != peer || frame.dst() != local {
                    lock(counters).foreign_frames += 1;
                    continue;
                }
                lock(counters).frames_in += 1;
                if !hand(Carried::Segment(frame.payload().to_vec())) {
                    return false;
                }
            }
            DeframeEvent::BadCrc { .. } => lock(counters).crc_failures += 1,
            DeframeEvent::Skipped { .. } | DeframeEvent::Truncated { .. } => {}
        }
    }
    lock(counters).bytes_skipped = deframer.stats().bytes_skipped;
    true
}
