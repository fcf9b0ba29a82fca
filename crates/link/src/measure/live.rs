//! A characterisation campaign in real time, over device adapters.
//!
//! Probes are sent one every `interval` (sizes interleaved: probe `k` has size
//! `sizes[k % sizes.len()]`), each stamped with its send time; what arrives is matched by sequence
//! number. A probe that has not arrived `timeout` after it was sent is recorded as lost. Rows are
//! handed over as soon as they are known (arrival or timeout), so a caller that writes them as
//! they come loses nothing when the run is cut short.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::{Row, probe, read_probe};
use crate::gll::{Endpoint, GllError};

/// What to send.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Probe sizes, bytes (each a whole link frame), interleaved.
    pub sizes: Vec<usize>,
    /// Probes per size.
    pub count_per_size: u32,
    /// Time between sends.
    pub interval: Duration,
    /// How long after its send a probe that has not arrived counts as lost.
    pub timeout: Duration,
}

impl Plan {
    /// Probes in all.
    pub fn total(&self) -> u64 {
        self.sizes.len() as u64 * u64::from(self.count_per_size)
    }

    /// What the campaign will do, for people: probes, pace and about how long it takes.
    pub fn describe(&self) -> String {
        let interval_s = self.interval.as_secs_f64();
        let length_s = self.total() as f64 * interval_s + self.timeout.as_secs_f64().min(5.0);
        format!(
            "sending {} packets, one every {:.0} ms (about {length_s:.0} s)",
            self.total(),
            interval_s * 1e3
        )
    }
}

/// The endpoints of a campaign.
pub enum Ports<'a> {
    /// Probes go out on `tx` and come back on `rx` (both modems on this host: one clock).
    Pair {
        /// The sending modem.
        tx: &'a mut dyn Endpoint,
        /// The receiving modem.
        rx: &'a mut dyn Endpoint,
    },
    /// Probes go out and their echoes come back on the same modem: delays are round trips.
    Echo(&'a mut dyn Endpoint),
}

/// How a campaign ended.
#[derive(Debug)]
pub enum Ended {
    /// Every probe was sent and accounted for.
    Done,
    /// Stopped from outside (Ctrl-C); `unresolved` probes were still on their way.
    Stopped {
        /// Probes sent whose fate was not known yet.
        unresolved: u64,
    },
    /// A port failed; `unresolved` probes were still on their way.
    Failed {
        /// What happened.
        error: GllError,
        /// Probes sent whose fate was not known yet.
        unresolved: u64,
    },
}

/// Counters beyond the rows.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Extras {
    /// Packets received that were not an intact probe of this campaign.
    pub foreign: u64,
    /// Probes received a second time.
    pub duplicates: u64,
}

impl Extras {
    /// A line for the summary when anything unexpected arrived.
    pub fn note(&self) -> Option<String> {
        (self.foreign > 0 || self.duplicates > 0).then(|| {
            format!(
                "{} packets received that were not this run's probes, {} probes received twice",
                self.foreign, self.duplicates
            )
        })
    }
}

/// Runs the campaign; `on_row` gets each row when known, `on_progress` the number of probes
/// resolved so far. An error from `on_row` stops the run and is returned.
pub fn run<E>(
    mut ports: Ports<'_>,
    plan: &Plan,
    stop: &AtomicBool,
    mut on_row: impl FnMut(Row) -> Result<(), E>,
    mut on_progress: impl FnMut(u64),
) -> Result<(Ended, Extras), E> {
    let start = Instant::now();
    let since_start = |at: Instant| at.saturating_duration_since(start).as_secs_f64();
    let total = plan.total();
    let mut outstanding: BTreeMap<u32, (usize, Instant)> = BTreeMap::new();
    let mut next_seq: u64 = 0;
    let mut resolved: u64 = 0;
    let mut extras = Extras::default();
    loop {
        if stop.load(Ordering::SeqCst) {
            let unresolved = outstanding.len() as u64;
            return Ok((Ended::Stopped { unresolved }, extras));
        }
        let now = Instant::now();
        let next_send = start + plan.interval.mul_f64(next_seq as f64);
        if next_seq < total && now >= next_send {
            let size = plan.sizes[(next_seq % plan.sizes.len() as u64) as usize];
            let seq = next_seq as u32;
            let sent_at = Instant::now();
            let t_us = sent_at.saturating_duration_since(start).as_micros() as u64;
            let bytes = probe(seq, size, t_us).unwrap_or_default();
            let tx = match &mut ports {
                Ports::Pair { tx, .. } => &mut **tx,
                Ports::Echo(port) => &mut **port,
            };
            if let Err(error) = tx.send(&bytes) {
                let unresolved = outstanding.len() as u64;
                return Ok((Ended::Failed { error, unresolved }, extras));
            }
            outstanding.insert(seq, (size, sent_at));
            next_seq += 1;
            continue;
        }
        // Probes past their timeout are lost.
        while let Some((&seq, &(size, sent_at))) = outstanding.first_key_value() {
            if now.saturating_duration_since(sent_at) < plan.timeout {
                break;
            }
            outstanding.remove(&seq);
            resolved += 1;
            on_row(Row {
                seq,
                size_bytes: size,
                t_tx_s: since_start(sent_at),
                t_rx_s: None,
                delay_ms: None,
                delivered: false,
                corrupted: false,
            })?;
            on_progress(resolved);
        }
        if next_seq == total && outstanding.is_empty() {
            return Ok((Ended::Done, extras));
        }
        let mut deadline = now + Duration::from_millis(100);
        if next_seq < total {
            deadline = deadline.min(start + plan.interval.mul_f64(next_seq as f64));
        }
        if let Some((_, &(_, sent_at))) = outstanding.first_key_value() {
            deadline = deadline.min(sent_at + plan.timeout);
        }
        let rx = match &mut ports {
            Ports::Pair { rx, .. } => &mut **rx,
            Ports::Echo(port) => &mut **port,
        };
        let received = match rx.receive(deadline) {
            Ok(received) => received,
            Err(error) => {
                let unresolved = outstanding.len() as u64;
                return Ok((Ended::Failed { error, unresolved }, extras));
            }
        };
        let Some(packet) = received else {
            continue;
        };
        let Some(info) = read_probe(&packet.bytes) else {
            extras.foreign += 1;
            continue;
        };
        let Some((size, sent_at)) = outstanding.remove(&info.seq) else {
            if u64::from(info.seq) < next_seq {
                extras.duplicates += 1;
            } else {
                extras.foreign += 1;
            }
            continue;
        };
        resolved += 1;
        let delay_ms = packet.at.saturating_duration_since(sent_at).as_secs_f64() * 1e3;
        on_row(Row {
            seq: info.seq,
            size_bytes: size,
            t_tx_s: since_start(sent_at),
            t_rx_s: Some(since_start(packet.at)),
            delay_ms: Some(delay_ms),
            delivered: true,
            corrupted: packet.damaged || info.size != size,
        })?;
        on_progress(resolved);
    }
}
