//! The operator's side of the transport: segments in, records out, in order.
//!
//! Synchronised on a stream (an epoch and the sequence number it expects next), the inbox
//! buffers segments that come early (at most [`MAX_AHEAD`] ahead), hands out each record once
//! every segment before it has come, and acknowledges: at once when a segment comes out of
//! order or again, else after [`ACK_EVERY`] segments or [`ACK_DELAY`].
//!
//! Not synchronised (at start, after a restart of the view, or when a new epoch shows that the
//! mapper restarted), it takes the first segment of an epoch's stream if it comes (sequence 0,
//! a sync record), and otherwise asks for a resync and waits for the reply, which says where the
//! new stream starts; until then data is dropped unacknowledged. Requests are sent again every
//! timeout until their reply comes.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use crate::outbox::RECORD_SYNC;
use crate::request::Request;
use crate::segment::{Repr, SegmentError};

/// Segments buffered at most beyond the one expected.
pub const MAX_AHEAD: u32 = 8192;
/// In-order segments acknowledged together at most.
pub const ACK_EVERY: u32 = 8;
/// The longest an in-order segment waits for its acknowledgement.
pub const ACK_DELAY: Duration = Duration::from_millis(20);
/// The largest record taken (a full map of a large survey is a few MB).
pub const MAX_RECORD_BYTES: usize = 256 << 20;
/// Requests waiting for their reply, at most.
pub const MAX_PENDING_REQUESTS: usize = 16;

/// What the inbox has for its caller.
#[derive(Debug, Clone, PartialEq)]
pub enum InboxEvent {
    /// A whole record, in stream order.
    Record(Vec<u8>),
    /// The inbox follows a stream from this point (a resync or an epoch's start): the next
    /// record is a sync record.
    Synced {
        /// The mapper's epoch.
        epoch: u32,
        /// Where the stream was taken up.
        seq: u32,
    },
    /// A new epoch was seen: the mapper restarted.
    NewEpoch(u32),
    /// A request was answered.
    Reply {
        /// Its identifier.
        id: u32,
        /// What it asked.
        request: Request,
        /// Whether the mapper refused it.
        refused: bool,
        /// When it was first sent.
        asked_at: Duration,
    },
}

/// What the inbox has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InboxStats {
    /// Data segments taken (first copies).
    pub segments: u64,
    /// Copies of segments already taken.
    pub duplicates: u64,
    /// Data segments dropped: not synchronised, too far ahead, or of an old epoch.
    pub dropped: u64,
    /// Segments that did not parse, or of a type the operator does not take.
    pub malformed: u64,
    /// Records handed out.
    pub records: u64,
    /// Acknowledgements sent.
    pub acks: u64,
    /// Requests sent, resends included.
    pub requests_sent: u64,
    /// Records cut short by a broken stream (a chunk out of place): the view resyncs.
    pub broken_records: u64,
}

#[derive(Debug)]
struct Pending {
    id: u32,
    request: Request,
    asked_at: Duration,
    sent_at: Option<Duration>,
}

#[derive(Debug)]
enum State {
    /// Waiting for a stream's start or a resync's reply (of this epoch, when one was seen).
    Unsynced { epoch: Option<u32> },
    Synced {
        epoch: u32,
        expected: u32,
        early: BTreeMap<u32, (bool, bool, Vec<u8>)>,
        record: Option<Vec<u8>>,
    },
}

/// The receiver.
#[derive(Debug)]
pub struct Inbox {
    state: State,
    rto: Duration,
    next_id: u32,
    pending: VecDeque<Pending>,
    events: VecDeque<InboxEvent>,
    unacked: u32,
    ack_at: Option<Duration>,
    stats: InboxStats,
}

impl Inbox {
    /// An inbox that is not synchronised; `rto` is the time after which a request is sent
    /// again; request ids start at `first_id` (random: a restarted view's do not repeat).
    pub fn new(rto: Duration, first_id: u32) -> Inbox {
        Inbox {
            state: State::Unsynced { epoch: None },
            rto,
            next_id: first_id,
            pending: VecDeque::new(),
            events: VecDeque::new(),
            unacked: 0,
            ack_at: None,
            stats: InboxStats::default(),
        }
    }

    /// What it has seen.
    pub fn stats(&self) -> InboxStats {
        self.stats
    }

    /// Whether it follows a stream.
    pub fn synced(&self) -> bool {
        matches!(self.state, State::Synced { .. })
    }

    /// The epoch it follows or waits for.
    pub fn epoch(&self) -> Option<u32> {
        match self.state {
            State::Unsynced { epoch } => epoch,
            State::Synced { epoch, .. } => Some(epoch),
        }
    }

    /// Requests waiting for their reply.
    pub fn pending_requests(&self) -> usize {
        self.pending.len()
    }

    /// Queues a request at `now`; its id, or `None` when [`MAX_PENDING_REQUESTS`] wait already.
    pub fn request(&mut self, request: Request, now: Duration) -> Option<u32> {
        if self.pending.len() >= MAX_PENDING_REQUESTS {
            return None;
        }
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1);
        self.pending.push_back(Pending {
            id,
            request,
            asked_at: now,
            sent_at: None,
        });
        Some(id)
    }

    fn want_resync(&mut self, now: Duration) {
        if !self.pending.iter().any(|p| p.request == Request::Resync) {
            self.request(Request::Resync, now);
        }
    }

    /// The next event, if any.
    pub fn next_event(&mut self) -> Option<InboxEvent> {
        self.events.pop_front()
    }

    /// Takes a segment at `now`; a segment that does not parse is counted and its error
    /// returned (never applied).
    pub fn on_segment(&mut self, bytes: &[u8], now: Duration) -> Result<(), SegmentError> {
        let repr = match Repr::parse(bytes) {
            Ok(r) => r,
            Err(e) => {
                self.stats.malformed += 1;
                return Err(e);
            }
        };
        match repr {
            Repr::Data {
                epoch,
                seq,
                first,
                last,
                chunk,
            } => self.on_data(epoch, seq, first, last, chunk, now),
            Repr::Reply {
                epoch,
                id,
                refused,
                sync_seq,
            } => self.on_reply(epoch, id, refused, sync_seq),
            Repr::Ack { .. } | Repr::Request { .. } => self.stats.malformed += 1,
        }
        Ok(())
    }

    fn on_reply(&mut self, epoch: u32, id: u32, refused: bool, sync_seq: u32) {
        let Some(i) = self.pending.iter().position(|p| p.id == id) else {
            return;
        };
        let Some(p) = self.pending.remove(i) else {
            return;
        };
        if p.request == Request::Resync && !refused {
            if self.epoch() != Some(epoch) {
                self.events.push_back(InboxEvent::NewEpoch(epoch));
            }
            self.sync(epoch, sync_seq);
            // The mapper learns at once where this view stands.
            self.ack_at = Some(Duration::ZERO);
        }
        self.events.push_back(InboxEvent::Reply {
            id,
            request: p.request,
            refused,
            asked_at: p.asked_at,
        });
    }

    fn sync(&mut self, epoch: u32, seq: u32) {
        self.state = State::Synced {
            epoch,
            expected: seq,
            early: BTreeMap::new(),
            record: None,
        };
        self.events.push_back(InboxEvent::Synced { epoch, seq });
    }

    fn on_data(
        &mut self,
        epoch: u32,
        seq: u32,
        first: bool,
        last: bool,
        chunk: &[u8],
        now: Duration,
    ) {
        let starts_epoch = seq == 0 && first && chunk.first() == Some(&RECORD_SYNC);
        match self.state {
            State::Synced { epoch: e, .. } if e == epoch => {}
            _ if starts_epoch => {
                if self.epoch() != Some(epoch) {
                    self.events.push_back(InboxEvent::NewEpoch(epoch));
                }
                self.sync(epoch, 0);
            }
            State::Unsynced { epoch: Some(e) } if e == epoch => {
                self.stats.dropped += 1;
                self.want_resync(now);
                return;
            }
            _ => {
                // A new epoch (or the first one seen): follow it once a resync says where.
                self.events.push_back(InboxEvent::NewEpoch(epoch));
                self.state = State::Unsynced { epoch: Some(epoch) };
                self.stats.dropped += 1;
                self.want_resync(now);
                return;
            }
        }
        let State::Synced {
            expected, early, ..
        } = &mut self.state
        else {
            return;
        };
        let ahead = seq.wrapping_sub(*expected);
        if ahead >= u32::MAX / 2 || early.contains_key(&seq) {
            // Already taken: its acknowledgement was lost.
            self.stats.duplicates += 1;
            self.ack_at = Some(Duration::ZERO);
            return;
        }
        if ahead >= MAX_AHEAD {
            self.stats.dropped += 1;
            return;
        }
        self.stats.segments += 1;
        early.insert(seq, (first, last, chunk.to_vec()));
        if ahead != 0 {
            self.ack_at = Some(Duration::ZERO);
        }
        self.deliver(now);
        self.unacked += 1;
        if self.unacked >= ACK_EVERY {
            self.ack_at = Some(Duration::ZERO);
        } else if self.ack_at.is_none() {
            self.ack_at = Some(now + ACK_DELAY);
        }
    }

    /// Hands out the records whose segments have all come.
    fn deliver(&mut self, now: Duration) {
        let mut broken = false;
        if let State::Synced {
            expected,
            early,
            record,
            ..
        } = &mut self.state
        {
            while let Some((first, last, chunk)) = early.remove(expected) {
                *expected = expected.wrapping_add(1);
                if first {
                    if record.is_some() {
                        broken = true;
                    }
                    *record = Some(Vec::new());
                }
                let Some(r) = record.as_mut() else {
                    // A chunk with no record started: the stream is broken.
                    broken = true;
                    continue;
                };
                if r.len() + chunk.len() > MAX_RECORD_BYTES {
                    *record = None;
                    broken = true;
                    continue;
                }
                r.extend_from_slice(&chunk);
                if last && let Some(r) = record.take() {
                    self.stats.records += 1;
                    self.events.push_back(InboxEvent::Record(r));
                }
            }
        }
        if broken {
            self.stats.broken_records += 1;
            self.want_resync(now);
        }
    }

    /// An acknowledgement of everything taken, now (the last thing a view sends as it ends, so
    /// that the mapper does not resend what it has); none when not synchronised.
    pub fn ack_now(&mut self) -> Option<Vec<u8>> {
        if !self.synced() {
            return None;
        }
        self.ack_at = Some(Duration::ZERO);
        self.poll(Duration::ZERO)
    }

    /// The next segment to send at `now`: an acknowledgement when one is due, else a request
    /// never sent or sent a timeout ago.
    pub fn poll(&mut self, now: Duration) -> Option<Vec<u8>> {
        if self.ack_at.is_some_and(|t| t <= now)
            && let State::Synced {
                epoch,
                expected,
                early,
                ..
            } = &self.state
        {
            let mut sack = 0u64;
            for &s in early.keys() {
                let i = s.wrapping_sub(expected.wrapping_add(1));
                if i < 64 {
                    sack |= 1 << i;
                }
            }
            let ack = Repr::Ack {
                epoch: *epoch,
                cum: *expected,
                sack,
            };
            self.ack_at = None;
            self.unacked = 0;
            self.stats.acks += 1;
            return Some(ack.emit());
        }
        let rto = self.rto;
        let p = self
            .pending
            .iter_mut()
            .find(|p| p.sent_at.is_none_or(|t| now >= t + rto))?;
        p.sent_at = Some(now);
        self.stats.requests_sent += 1;
        Some(
            Repr::Request {
                id: p.id,
                request: p.request,
            }
            .emit(),
        )
    }

    /// The earliest time [`Inbox::poll`] may give something.
    pub fn next_deadline(&self) -> Option<Duration> {
        let ack = self.ack_at.filter(|_| self.synced());
        let req = self
            .pending
            .iter()
            .map(|p| p.sent_at.map_or(Duration::ZERO, |t| t + self.rto))
            .min();
        match (ack, req) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}
