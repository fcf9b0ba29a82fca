//! A simulation held to the wall clock (`--pace X`): virtual time at X times real time, to
//! watch a simulation live; the results are those of the unpaced run.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use rovlink_link::SimTime;

/// The slowest pace (virtual seconds per wall second).
pub const MIN_PACE: f64 = 0.01;
/// The fastest pace.
pub const MAX_PACE: f64 = 10_000.0;
/// How often a paced wait looks at the stop flag.
pub const PACE_POLL: Duration = Duration::from_millis(50);

/// Virtual time held back to the wall clock: virtual time `t` is reached no sooner than
/// `t / pace` seconds of wall time after the start, so a simulation (and a live view of it)
/// moves at `pace` times real time. A wait wakes every [`PACE_POLL`] to look at the stop flag.
/// Only the wall time changes: the run's results are those of the unpaced run.
pub struct Pace<'a> {
    pace: f64,
    started: Instant,
    stop: &'a AtomicBool,
}

impl<'a> Pace<'a> {
    /// A pace starting now (clamped to [`MIN_PACE`] ..= [`MAX_PACE`]; not finite is 1),
    /// giving up its waits once `stop` is set.
    pub fn new(pace: f64, stop: &'a AtomicBool) -> Pace<'a> {
        let pace = if pace.is_finite() { pace } else { 1.0 };
        Pace {
            pace: pace.clamp(MIN_PACE, MAX_PACE),
            started: Instant::now(),
            stop,
        }
    }

    /// Waits until virtual time `t` is due on the wall clock.
    pub fn wait_for(&self, t: SimTime) {
        let due = self.started + Duration::from_secs_f64((t.as_secs_f64() / self.pace).min(1e9));
        loop {
            let now = Instant::now();
            if now >= due || self.stop.load(Ordering::Relaxed) {
                return;
            }
            std::thread::sleep((due - now).min(PACE_POLL));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pace_waits_for_virtual_time_and_gives_up_on_a_stop() {
        let never = AtomicBool::new(false);
        let pace = Pace::new(10.0, &never);
        // 1 s of virtual time at 10x: 0.1 s of wall time after the start.
        pace.wait_for(SimTime::from_secs_f64(1.0));
        assert!(pace.started.elapsed() >= Duration::from_millis(100));
        // A time already past does not wait.
        let waited = Instant::now();
        pace.wait_for(SimTime::from_secs_f64(0.5));
        assert!(waited.elapsed() < Duration::from_millis(50));
        let stopped = AtomicBool::new(true);
        let waited = Instant::now();
        Pace::new(MIN_PACE, &stopped).wait_for(SimTime::from_secs_f64(1e6));
        assert!(waited.elapsed() < PACE_POLL);
        assert_eq!(Pace::new(f64::NAN, &never).pace, 1.0);
        assert_eq!(Pace::new(1e9, &never).pace, MAX_PACE);
        assert_eq!(Pace::new(0.0, &never).pace, MIN_PACE);
    }
}
