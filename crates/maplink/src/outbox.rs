//! The vehicle's side of the transport: records in, segments out.
//!
//! A record (one byte of kind, then its body: [`RECORD_SYNC`], [`RECORD_SPEC`],
//! [`RECORD_MESSAGE`], [`RECORD_POSE`]) waits in the backlog until the window has room; then it
//! is cut into data segments of at most [`MAX_CHUNK_BYTES`], each with the next sequence number.
//! A segment not acknowledged within the timeout is sent again; resends go before new segments,
//! replies before both. Every segment waits for the shaper: the link's bytes (the carrier's
//! framing included) at most at the configured rate.
//!
//! Memory is bounded: at most [`OutboxConfig::window_bytes`] of unacknowledged segments, and the
//! caller keeps the backlog within its bound with [`Outbox::replace_backlog`] (the mapper
//! replaces waiting records by one full map: a change is never lost, it is sent inside the full
//! map). A resync ([`Outbox::restart`]) drops everything in flight and starts the stream again
//! at a sequence number the reply carries.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap, VecDeque};
use std::time::Duration;

use crate::segment::{MAX_CHUNK_BYTES, Repr};

/// Record kind: an `.odl` stream header; the receiver starts a new view with it.
pub const RECORD_SYNC: u8 = 1;
/// Record kind: an `.odl` stream header whose ROI replaces the receiver's (same resolution and
/// coarse depth); the view is kept.
pub const RECORD_SPEC: u8 = 2;
/// Record kind: an `.odl` message (delta, full or region).
pub const RECORD_MESSAGE: u8 = 3;
/// Record kind: the vehicle's pose after a scan: scan u32, x, y, z, qx, qy, qz, qw as f32.
pub const RECORD_POSE: u8 = 4;

/// How the outbox sends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutboxConfig {
    /// The shaped rate, bit/s: every segment's bytes plus `frame_overhead_bytes`.
    pub rate_bps: f64,
    /// Bytes the carrier adds to each segment (a wire.md frame: 5).
    pub frame_overhead_bytes: usize,
    /// Time after which an unacknowledged segment is sent again.
    pub rto: Duration,
    /// The most bytes of unacknowledged segments.
    pub window_bytes: usize,
}

/// What the outbox has done.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OutboxStats {
    /// Data segments sent for the first time.
    pub segments: u64,
    /// Data segments sent again.
    pub resends: u64,
    /// Replies sent.
    pub replies: u64,
    /// Bytes on the link, the carrier's framing included.
    pub link_bytes: u64,
    /// Records taken.
    pub records: u64,
    /// Acknowledgements taken (of this epoch).
    pub acks: u64,
    /// Acknowledgements of another epoch, ignored.
    pub stale_acks: u64,
    /// Times the stream was started again ([`Outbox::restart`]).
    pub restarts: u64,
}

/// Where the backlog stands.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Backlog {
    /// Records waiting to be cut.
    pub records: usize,
    /// Their bytes (and what is left of the record being cut).
    pub bytes: usize,
    /// Bytes of segments sent and not yet acknowledged.
    pub unacked_bytes: usize,
}

#[derive(Debug)]
struct Seg {
    bytes: Vec<u8>,
    sent_at: Option<Duration>,
    /// Times sent: the timeout doubles with each resend (at most [`MAX_BACKOFF`] times the
    /// first), so that a link that is down is probed, not flooded.
    sends: u32,
}

/// The most a segment's timeout grows by backing off: 8 times (a link back up is noticed
/// within 8 timeouts).
pub const MAX_BACKOFF: u32 = 8;

/// The sender.
#[derive(Debug)]
pub struct Outbox {
    cfg: OutboxConfig,
    epoch: u32,
    next_seq: u32,
    waiting: VecDeque<Vec<u8>>,
    waiting_bytes: usize,
    /// The record being cut and how much of it is cut.
    cutting: Option<(Vec<u8>, usize)>,
    unacked: BTreeMap<u32, Seg>,
    unacked_bytes: usize,
    resend: VecDeque<u32>,
    /// (deadline, sequence number, when sent), earliest first.
    timers: BinaryHeap<Reverse<(Duration, u32, Duration)>>,
    replies: VecDeque<Vec<u8>>,
    /// Segments due for a resend held back while the link looks down (no acknowledgement for
    /// two timeouts): only the oldest probes it; they go again once an acknowledgement comes.
    parked: Vec<u32>,
    /// When the last acknowledgement that acknowledged something came.
    last_progress: Duration,
    next_slot: Duration,
    stats: OutboxStats,
}

/// How far behind the shaper may fall and catch up (a loop woken late sends a little burst).
const SHAPER_SLACK: Duration = Duration::from_millis(10);

impl Outbox {
    /// An outbox of a new stream of `epoch`.
    pub fn new(cfg: OutboxConfig, epoch: u32) -> Outbox {
        Outbox {
            cfg,
            epoch,
            next_seq: 0,
            waiting: VecDeque::new(),
            waiting_bytes: 0,
            cutting: None,
            unacked: BTreeMap::new(),
            unacked_bytes: 0,
            resend: VecDeque::new(),
            timers: BinaryHeap::new(),
            replies: VecDeque::new(),
            parked: Vec::new(),
            last_progress: Duration::ZERO,
            next_slot: Duration::ZERO,
            stats: OutboxStats::default(),
        }
    }

    /// The stream's epoch.
    pub fn epoch(&self) -> u32 {
        self.epoch
    }

    /// What it has done.
    pub fn stats(&self) -> OutboxStats {
        self.stats
    }

    /// Where the backlog stands.
    pub fn backlog(&self) -> Backlog {
        let cut_left = self.cutting.as_ref().map_or(0, |(r, at)| r.len() - at);
        Backlog {
            records: self.waiting.len(),
            bytes: self.waiting_bytes + cut_left,
            unacked_bytes: self.unacked_bytes,
        }
    }

    /// When an acknowledgement last acknowledged something (or the outbox began).
    pub fn last_progress(&self) -> Duration {
        self.last_progress
    }

    /// Whether everything taken has been sent and acknowledged.
    pub fn idle(&self) -> bool {
        self.waiting.is_empty() && self.cutting.is_none() && self.unacked.is_empty()
    }

    /// Queues a record (kind byte, then body).
    pub fn push(&mut self, record: Vec<u8>) {
        if record.is_empty() {
            return;
        }
        self.stats.records += 1;
        self.waiting_bytes += record.len();
        self.waiting.push_back(record);
    }

    /// Drops every record still waiting (not the one being cut) and queues `records` instead:
    /// the mapper's way of keeping its backlog bounded (a full map in place of the deltas).
    pub fn replace_backlog(&mut self, records: Vec<Vec<u8>>) {
        self.waiting.clear();
        self.waiting_bytes = 0;
        for r in records {
            self.push(r);
        }
    }

    /// Starts the stream again: drops everything waiting, being cut or unacknowledged, and
    /// queues `records`; returns the sequence number where they start (a resync's reply).
    pub fn restart(&mut self, records: Vec<Vec<u8>>) -> u32 {
        self.stats.restarts += 1;
        self.cutting = None;
        self.unacked.clear();
        self.unacked_bytes = 0;
        self.resend.clear();
        self.parked.clear();
        self.timers.clear();
        self.replace_backlog(records);
        self.next_seq
    }

    /// Queues a reply to request `id`.
    pub fn reply(&mut self, id: u32, refused: bool, sync_seq: u32) {
        let r = Repr::Reply {
            epoch: self.epoch,
            id,
            refused,
            sync_seq,
        };
        self.replies.push_back(r.emit());
    }

    /// Takes an acknowledgement at `now`.
    pub fn on_ack(&mut self, epoch: u32, cum: u32, sack: u64, now: Duration) {
        if epoch != self.epoch {
            self.stats.stale_acks += 1;
            return;
        }
        self.stats.acks += 1;
        let below: Vec<u32> = self.unacked.range(..cum).map(|(&s, _)| s).collect();
        let mut progress = false;
        for s in below {
            progress |= self.acked(s);
        }
        for i in 0..64u32 {
            if sack & (1 << i) != 0
                && let Some(s) = cum.checked_add(1 + i)
            {
                progress |= self.acked(s);
            }
        }
        // Fast resend: a segment sent once, before one the operator has now, was lost (the
        // link keeps order); it goes again without waiting for its timeout.
        if let Some(high) = (0..64u32).rev().find(|i| sack & (1 << i) != 0) {
            let high = cum.saturating_add(1 + high);
            for (&seq, seg) in self.unacked.range_mut(..high) {
                if seg.sends == 1 && seg.sent_at.is_some() {
                    seg.sent_at = None;
                    self.resend.push_back(seq);
                }
            }
        }
        if progress {
            self.last_progress = now;
            // The link is back: segments held back or whose timeouts grew are due now.
            self.resend.extend(self.parked.drain(..));
            for (&seq, seg) in self.unacked.iter_mut() {
                if seg.sends > 1 && seg.sent_at.is_some() {
                    seg.sent_at = None;
                    self.resend.push_back(seq);
                }
            }
        }
    }

    fn acked(&mut self, seq: u32) -> bool {
        match self.unacked.remove(&seq) {
            Some(seg) => {
                self.unacked_bytes -= seg.bytes.len();
                true
            }
            None => false,
        }
    }

    /// The next segment to send at `now`, if the shaper allows one and there is one.
    pub fn poll(&mut self, now: Duration) -> Option<Vec<u8>> {
        self.expire(now);
        if now < self.next_slot {
            return None;
        }
        let bytes = if let Some(r) = self.replies.pop_front() {
            self.stats.replies += 1;
            r
        } else if let Some(seq) = self.next_resend(now) {
            self.stats.resends += 1;
            self.send_seg(seq, now)
        } else if let Some(seq) = self.cut() {
            self.stats.segments += 1;
            self.send_seg(seq, now)
        } else {
            return None;
        };
        let cost = (bytes.len() + self.cfg.frame_overhead_bytes) as f64 * 8.0 / self.cfg.rate_bps;
        self.next_slot = self.next_slot.max(now.saturating_sub(SHAPER_SLACK))
            + Duration::from_secs_f64(cost.min(3600.0));
        self.stats.link_bytes += (bytes.len() + self.cfg.frame_overhead_bytes) as u64;
        Some(bytes)
    }

    /// The earliest time [`Outbox::poll`] may give something (None: nothing to send until a
    /// record, an acknowledgement or a request comes).
    pub fn next_deadline(&self) -> Option<Duration> {
        let sendable = !self.replies.is_empty()
            || !self.resend.is_empty()
            || ((self.cutting.is_some() || !self.waiting.is_empty()) && self.room());
        let timer = self.timers.peek().map(|Reverse((t, _, _))| *t);
        let slot = sendable.then_some(self.next_slot);
        match (slot, timer) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Unacknowledged segments whose timeout has passed go to the resend queue.
    fn expire(&mut self, now: Duration) {
        while let Some(&Reverse((deadline, seq, sent))) = self.timers.peek() {
            let live = self
                .unacked
                .get(&seq)
                .is_some_and(|s| s.sent_at == Some(sent));
            if !live {
                self.timers.pop();
            } else if now >= deadline {
                self.timers.pop();
                if let Some(s) = self.unacked.get_mut(&seq) {
                    s.sent_at = None;
                }
                self.resend.push_back(seq);
            } else {
                break;
            }
        }
    }

    fn next_resend(&mut self, now: Duration) -> Option<u32> {
        let down = now > self.last_progress + self.cfg.rto * 2;
        let oldest = self.unacked.keys().next().copied();
        while let Some(seq) = self.resend.pop_front() {
            if !self.unacked.contains_key(&seq) {
                continue;
            }
            if down && Some(seq) != oldest {
                self.parked.push(seq);
                continue;
            }
            return Some(seq);
        }
        None
    }

    fn send_seg(&mut self, seq: u32, now: Duration) -> Vec<u8> {
        let Some(seg) = self.unacked.get_mut(&seq) else {
            return Vec::new();
        };
        seg.sent_at = Some(now);
        seg.sends += 1;
        let backoff = (1u32 << (seg.sends - 1).min(3)).min(MAX_BACKOFF);
        self.timers
            .push(Reverse((now + self.cfg.rto * backoff, seq, now)));
        seg.bytes.clone()
    }

    fn room(&self) -> bool {
        self.unacked_bytes + MAX_CHUNK_BYTES + 10 <= self.cfg.window_bytes.max(MAX_CHUNK_BYTES + 10)
    }

    /// Cuts the next segment of the record stream, if the window has room; its sequence number.
    fn cut(&mut self) -> Option<u32> {
        if !self.room() {
            return None;
        }
        if self.cutting.is_none() {
            let r = self.waiting.pop_front()?;
            self.waiting_bytes -= r.len();
            self.cutting = Some((r, 0));
        }
        let (record, at) = self.cutting.as_mut()?;
        let end = (*at + MAX_CHUNK_BYTES).min(record.len());
        let seq = self.next_seq;
        let bytes = Repr::Data {
            epoch: self.epoch,
            seq,
            first: *at == 0,
            last: end == record.len(),
            chunk: &record[*at..end],
        }
        .emit();
        *at = end;
        if end == record.len() {
            self.cutting = None;
        }
        self.next_seq = self.next_seq.wrapping_add(1);
        self.unacked_bytes += bytes.len();
        self.unacked.insert(
            seq,
            Seg {
                bytes,
                sent_at: None,
                sends: 0,
            },
        );
        Some(seq)
    }
}
