//! The discrete-event scheduler: virtual time and a queue of future events.
//!
//! Events are kept in a binary heap keyed by (due time, sequence number). The sequence number
//! grows with every event scheduled, so events due at the same time leave in the order they
//! were scheduled: runs are reproducible whatever the heap does with ties. Memory holds only the
//! pending events, so a streaming simulation that schedules as it consumes stays bounded.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;
use std::fmt;

/// A point in virtual time, in nanoseconds since the start of the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct SimTime(pub u64);

impl SimTime {
    /// The start of a run.
    pub const ZERO: SimTime = SimTime(0);

    /// A time `seconds` after the start (negative or not-a-number: the start; saturating).
    pub fn from_secs_f64(seconds: f64) -> SimTime {
        SimTime(secs_to_ns(seconds))
    }

    /// Seconds since the start.
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }

    /// This time plus `seconds` (a negative delay counts as none; saturating).
    pub fn after_secs(self, seconds: f64) -> SimTime {
        SimTime(self.0.saturating_add(secs_to_ns(seconds)))
    }
}

fn secs_to_ns(seconds: f64) -> u64 {
    // `as` saturates: NaN and negatives give 0, huge values u64::MAX.
    (seconds * 1e9).round() as u64
}

impl fmt::Display for SimTime {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.9} s", self.as_secs_f64())
    }
}

struct Entry<E> {
    due: SimTime,
    seq: u64,
    event: E,
}

impl<E> PartialEq for Entry<E> {
    fn eq(&self, other: &Self) -> bool {
        (self.due, self.seq) == (other.due, other.seq)
    }
}

impl<E> Eq for Entry<E> {}

impl<E> PartialOrd for Entry<E> {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl<E> Ord for Entry<E> {
    fn cmp(&self, other: &Self) -> Ordering {
        (self.due, self.seq).cmp(&(other.due, other.seq))
    }
}

/// Virtual time and the events waiting for it.
pub struct Scheduler<E> {
    now: SimTime,
    next_seq: u64,
    queue: BinaryHeap<Reverse<Entry<E>>>,
}

impl<E> Default for Scheduler<E> {
    fn default() -> Self {
        Scheduler::new()
    }
}

impl<E> Scheduler<E> {
    /// An empty scheduler at time zero.
    pub fn new() -> Scheduler<E> {
        Scheduler {
            now: SimTime::ZERO,
            next_seq: 0,
            queue: BinaryHeap::new(),
        }
    }

    /// The current virtual time: the due time of the last event taken.
    pub fn now(&self) -> SimTime {
        self.now
    }

    /// Schedules `event` at `due`. Time never runs backwards: an event due in the past is due
    /// now (after the events already due now).
    pub fn schedule(&mut self, due: SimTime, event: E) {
        let due = due.max(self.now);
        self.queue.push(Reverse(Entry {
            due,
            seq: self.next_seq,
            event,
        }));
        self.next_seq += 1;
    }

    /// Schedules `event` `seconds` from now.
    pub fn schedule_in_secs(&mut self, seconds: f64, event: E) {
        self.schedule(self.now.after_secs(seconds), event);
    }

    /// When the next event is due, if any.
    pub fn next_due(&self) -> Option<SimTime> {
        self.queue.peek().map(|Reverse(e)| e.due)
    }

    /// Takes the next event and advances the clock to its time.
    pub fn pop(&mut self) -> Option<(SimTime, E)> {
        let Reverse(entry) = self.queue.pop()?;
        self.now = entry.due;
        Some((entry.due, entry.event))
    }

    /// Takes the next event if it is due at or before `limit`; otherwise advances the clock to
    /// `limit` (if later than now) and returns `None`.
    pub fn pop_until(&mut self, limit: SimTime) -> Option<(SimTime, E)> {
        if self.next_due().is_some_and(|due| due <= limit) {
            return self.pop();
        }
        self.now = self.now.max(limit);
        None
    }

    /// Pending events.
    pub fn len(&self) -> usize {
        self.queue.len()
    }

    /// True when nothing is pending.
    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }

    /// Events scheduled since the start (the next sequence number).
    pub fn scheduled(&self) -> u64 {
        self.next_seq
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rovlink_base::rng::Rng;

    #[test]
    fn events_leave_in_time_order_and_ties_in_scheduling_order() {
        let mut s = Scheduler::new();
        s.schedule(SimTime(30), "c");
        s.schedule(SimTime(10), "a1");
        s.schedule(SimTime(20), "b");
        s.schedule(SimTime(10), "a2");
        s.schedule(SimTime(10), "a3");
        let order: Vec<_> = std::iter::from_fn(|| s.pop()).collect();
        assert_eq!(
            order,
            [
                (SimTime(10), "a1"),
                (SimTime(10), "a2"),
                (SimTime(10), "a3"),
                (SimTime(20), "b"),
                (SimTime(30), "c")
            ]
        );
        assert_eq!(s.now(), SimTime(30));
        assert_eq!(s.scheduled(), 5);
    }

    #[test]
    fn time_never_runs_backwards() {
        let mut s = Scheduler::new();
        s.schedule(SimTime(100), 1);
        assert_eq!(s.pop(), Some((SimTime(100), 1)));
        s.schedule(SimTime(5), 2);
        s.schedule_in_secs(-1.0, 3);
        s.schedule_in_secs(f64::NAN, 4);
        assert_eq!(s.pop(), Some((SimTime(100), 2)));
        assert_eq!(s.pop(), Some((SimTime(100), 3)));
        assert_eq!(s.pop(), Some((SimTime(100), 4)));
        assert_eq!(s.pop(), None);
    }

    #[test]
    fn pop_until_stops_at_the_limit_and_moves_the_clock() {
        let mut s = Scheduler::new();
        s.schedule_in_secs(0.5, 'x');
        assert_eq!(s.pop_until(SimTime::from_secs_f64(0.25)), None);
        assert_eq!(s.now(), SimTime(250_000_000));
        assert_eq!(
            s.pop_until(SimTime::from_secs_f64(1.0)),
            Some((SimTime(500_000_000), 'x'))
        );
        assert!(s.is_empty());
        assert_eq!(SimTime(1_500_000_000).to_string(), "1.500000000 s");
        assert_eq!(SimTime::from_secs_f64(1e30), SimTime(u64::MAX));
    }

    #[test]
    fn a_streaming_run_keeps_only_pending_events() {
        // A million frames through a queue that schedules each arrival as it takes the
        // previous one: the heap never holds more than the frames in flight.
        let mut s = Scheduler::new();
        let mut rng = Rng::new(7, 0);
        for i in 0..4u32 {
            s.schedule_in_secs(rng.uniform() * 0.01, i);
        }
        let mut taken = 0u32;
        let mut last = SimTime::ZERO;
        while let Some((t, i)) = s.pop() {
            assert!(t >= last);
            last = t;
            taken += 1;
            assert!(s.len() <= 4);
            if taken < 1_000_000 {
                s.schedule_in_secs(rng.uniform() * 0.01, i);
            }
        }
        assert_eq!(taken, 1_000_000 + 3);
    }
}
