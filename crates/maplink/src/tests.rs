//! The two sides over a simulated link in virtual time: a delay, seeded losses, and the
//! faults the transport must survive.

use std::collections::VecDeque;
use std::time::Duration;

use crate::outbox::{RECORD_MESSAGE, RECORD_SYNC};
use crate::{Inbox, InboxEvent, Outbox, OutboxConfig, Request};

/// A one-way link: a fixed delay, a loss rate from a seeded generator, and a switch.
struct Wire {
    delay: Duration,
    loss: f64,
    rng: u64,
    up: bool,
    flight: VecDeque<(Duration, Vec<u8>)>,
    sent: usize,
}

impl Wire {
    fn new(delay_ms: u64, loss: f64, seed: u64) -> Wire {
        Wire {
            delay: Duration::from_millis(delay_ms),
            loss,
            rng: seed.wrapping_mul(6364136223846793005).wrapping_add(1),
            up: true,
            flight: VecDeque::new(),
            sent: 0,
        }
    }
    fn send(&mut self, now: Duration, b: Vec<u8>) {
        self.rng = self
            .rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let u = (self.rng >> 11) as f64 / (1u64 << 53) as f64;
        self.sent += 1;
        if self.up && u >= self.loss {
            self.flight.push_back((now + self.delay, b));
        }
    }
    fn due(&mut self, now: Duration) -> Option<Vec<u8>> {
        (self.flight.front()?.0 <= now).then(|| self.flight.pop_front().unwrap().1)
    }
    fn next(&self) -> Option<Duration> {
        self.flight.front().map(|f| f.0)
    }
}

fn cfg() -> OutboxConfig {
    OutboxConfig {
        rate_bps: 653_000.0,
        frame_overhead_bytes: 5,
        rto: Duration::from_millis(1400),
        window_bytes: 400_000,
    }
}

fn record(kind: u8, n: usize, tag: u8) -> Vec<u8> {
    let mut r = vec![kind];
    r.extend((0..n).map(|i| (i as u8).wrapping_mul(31) ^ tag));
    r
}

/// Both sides and the two directions of the link.
struct Run {
    now: Duration,
    tx: Outbox,
    rx: Inbox,
    up: Wire,
    down: Wire,
    got: Vec<Vec<u8>>,
    events: Vec<InboxEvent>,
}

impl Run {
    fn new(loss: f64, seed: u64) -> Run {
        Run {
            now: Duration::ZERO,
            tx: Outbox::new(cfg(), 7),
            rx: Inbox::new(Duration::from_millis(1400), 100),
            up: Wire::new(310, loss, seed),
            down: Wire::new(310, loss, seed + 1),
            got: Vec::new(),
            events: Vec::new(),
        }
    }

    /// Runs until `until`, the mapper answering requests with `answer`.
    fn run_until(&mut self, until: Duration, answer: &mut dyn FnMut(&mut Outbox, u32, Request)) {
        while self.now < until {
            while let Some(b) = self.up.due(self.now) {
                let _ = self.rx.on_segment(&b, self.now);
            }
            while let Some(e) = self.rx.next_event() {
                match e {
                    InboxEvent::Record(r) => self.got.push(r),
                    InboxEvent::Synced { .. } => self.got.clear(),
                    other => self.events.push(other),
                }
            }
            while let Some(b) = self.down.due(self.now) {
                match crate::Repr::parse(&b).unwrap() {
                    crate::Repr::Ack { epoch, cum, sack } => {
                        self.tx.on_ack(epoch, cum, sack, self.now)
                    }
                    crate::Repr::Request { id, request } => answer(&mut self.tx, id, request),
                    _ => panic!("not for the mapper"),
                }
            }
            while let Some(b) = self.tx.poll(self.now) {
                self.up.send(self.now, b);
            }
            while let Some(b) = self.rx.poll(self.now) {
                self.down.send(self.now, b);
            }
            let next = [
                self.tx.next_deadline(),
                self.rx.next_deadline(),
                self.up.next(),
                self.down.next(),
                Some(until),
            ]
            .into_iter()
            .flatten()
            .filter(|&t| t > self.now)
            .min()
            .unwrap();
            self.now = next;
        }
    }
}

/// Resyncs as the mapper does: the stream again from a sync record.
fn resync_with(state: Vec<Vec<u8>>) -> impl FnMut(&mut Outbox, u32, Request) {
    move |tx: &mut Outbox, id, req| {
        assert_eq!(req, Request::Resync);
        let seq = tx.restart(state.clone());
        tx.reply(id, false, seq);
    }
}

#[test]
fn records_arrive_whole_and_in_order_over_a_lossy_link() {
    for (loss, seed) in [(0.0, 1), (0.05, 2), (0.2, 3)] {
        let mut run = Run::new(loss, seed);
        let sync = record(RECORD_SYNC, 20, 0);
        let mut want = vec![sync.clone()];
        run.tx.push(sync);
        for k in 0..60u8 {
            let r = record(RECORD_MESSAGE, 37 * k as usize * k as usize + 1, k);
            run.tx.push(r.clone());
            want.push(r);
        }
        run.run_until(Duration::from_secs(600), &mut resync_with(Vec::new()));
        assert!(
            run.got == want,
            "loss {loss}: {} records of {}",
            run.got.len(),
            want.len()
        );
        assert!(run.tx.idle());
        let s = run.tx.stats();
        if loss > 0.0 {
            assert!(s.resends > 0);
        } else {
            assert_eq!(s.resends, 0);
        }
    }
}

#[test]
fn the_shaper_keeps_the_link_within_its_rate() {
    let mut run = Run::new(0.0, 4);
    run.tx.push(record(RECORD_SYNC, 20, 0));
    run.tx.push(record(RECORD_MESSAGE, 300_000, 1));
    run.run_until(Duration::from_secs(2), &mut resync_with(Vec::new()));
    let bits = run.tx.stats().link_bytes as f64 * 8.0;
    // 2 s at 653 kbit/s, plus the shaper's slack of one segment.
    assert!(bits <= 653_000.0 * 2.0 + 2600.0, "{bits}");
    assert!(bits >= 653_000.0 * 1.9, "{bits}");
}

#[test]
fn a_restarted_view_resyncs_by_itself() {
    let mut run = Run::new(0.05, 5);
    let sync = record(RECORD_SYNC, 20, 0);
    run.tx.push(sync.clone());
    for k in 0..10u8 {
        run.tx.push(record(RECORD_MESSAGE, 5000, k));
    }
    run.run_until(Duration::from_secs(1), &mut resync_with(Vec::new()));
    // The view restarts mid-stream: a new inbox, no state.
    run.rx = Inbox::new(Duration::from_millis(1400), 900);
    let state = vec![sync.clone(), record(RECORD_MESSAGE, 9000, 99)];
    let mut answer = resync_with(state.clone());
    run.run_until(Duration::from_secs(300), &mut answer);
    assert!(run.got == state, "{} records", run.got.len());
    assert!(run.tx.idle());
    assert!(run.events.iter().any(|e| matches!(
        e,
        InboxEvent::Reply {
            request: Request::Resync,
            refused: false,
            ..
        }
    )));
}

#[test]
fn a_restarted_mapper_is_a_new_epoch_the_view_follows() {
    let mut run = Run::new(0.0, 6);
    run.tx.push(record(RECORD_SYNC, 20, 0));
    run.tx.push(record(RECORD_MESSAGE, 3000, 1));
    run.run_until(Duration::from_secs(5), &mut resync_with(Vec::new()));
    assert_eq!(run.got.len(), 2);
    run.tx = Outbox::new(cfg(), 8);
    let fresh = vec![record(RECORD_SYNC, 20, 2), record(RECORD_MESSAGE, 100, 3)];
    for r in &fresh {
        run.tx.push(r.clone());
    }
    run.run_until(Duration::from_secs(10), &mut resync_with(Vec::new()));
    assert!(run.got == fresh, "{} records", run.got.len());
    assert!(run.events.contains(&InboxEvent::NewEpoch(8)));
}

#[test]
fn an_outage_is_probed_not_flooded_and_caught_up_when_the_link_returns() {
    let mut run = Run::new(0.0, 8);
    run.tx.push(record(RECORD_SYNC, 20, 0));
    run.run_until(Duration::from_secs(2), &mut resync_with(Vec::new()));
    run.up.up = false;
    let mut want = Vec::new();
    for k in 0..40u8 {
        let r = record(RECORD_MESSAGE, 2000, k);
        run.tx.push(r.clone());
        want.push(r);
        run.run_until(
            run.now + Duration::from_millis(500),
            &mut resync_with(Vec::new()),
        );
    }
    // 20 s down: each of the ~330 segments sent once and resent a few times, backing off,
    // not every 1.4 s.
    let during = run.tx.stats().resends;
    assert!(during < 60, "{during} resends while the link was down");
    run.up.up = true;
    let back = run.now;
    run.run_until(back + Duration::from_secs(60), &mut resync_with(Vec::new()));
    assert!(run.got.ends_with(&want), "{} records", run.got.len());
    assert!(run.tx.idle());
}

#[test]
fn a_link_that_never_acknowledges_holds_at_most_a_window() {
    let mut run = Run::new(0.0, 7);
    run.down.up = false;
    run.tx.push(record(RECORD_SYNC, 20, 0));
    for k in 0..200u8 {
        run.tx.push(record(RECORD_MESSAGE, 20_000, k));
        run.run_until(
            run.now + Duration::from_millis(500),
            &mut resync_with(Vec::new()),
        );
        let b = run.tx.backlog();
        assert!(b.unacked_bytes <= cfg().window_bytes, "{b:?}");
        if b.bytes > 1_000_000 {
            run.tx
                .replace_backlog(vec![record(RECORD_MESSAGE, 50_000, 0xff)]);
        }
        assert!(run.tx.backlog().bytes <= 1_100_000);
    }
    assert!(run.tx.stats().resends > 0);
}

#[test]
fn garbage_is_counted_never_applied() {
    let mut rx = Inbox::new(Duration::from_secs(1), 0);
    for bad in [&[][..], &[0x55, 1, 2], &[0x11; 5], &[0x12; 17], &[0x1f; 40]] {
        let _ = rx.on_segment(bad, Duration::ZERO);
    }
    assert_eq!(rx.stats().malformed, 5);
    assert!(rx.next_event().is_none());
}
