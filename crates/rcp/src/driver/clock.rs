//! The host's monotonic clock as the engines count time in real time, and how long a
//! real-time wait lasts at most ([`WAKE_EVERY`]).

use std::time::{Duration, Instant};

use rovlink_link::SimTime;

/// The longest a real-time wait lasts before the loop looks at the stop flag and live orders.
pub const WAKE_EVERY: Duration = Duration::from_millis(200);

/// The host's monotonic clock: time since the start, as the engines count it.
pub struct Clock {
    start: Instant,
}

impl Clock {
    /// A clock whose time zero is now.
    pub fn start() -> Clock {
        Clock {
            start: Instant::now(),
        }
    }

    /// The time of `instant`.
    pub fn at(&self, instant: Instant) -> SimTime {
        SimTime(
            u64::try_from(instant.saturating_duration_since(self.start).as_nanos())
                .unwrap_or(u64::MAX),
        )
    }

    /// The time now.
    pub fn now(&self) -> SimTime {
        self.at(Instant::now())
    }

    /// The instant of `t`.
    pub fn instant(&self, t: SimTime) -> Instant {
        self.start + Duration::from_nanos(t.0)
    }

    /// When a wait for `at` wakes: then, or [`WAKE_EVERY`] from now if that is sooner.
    pub fn wake_at(&self, at: SimTime) -> Instant {
        self.instant(at).min(Instant::now() + WAKE_EVERY)
    }
}
