//! Pacing a simulation to the wall clock, so that it can be watched live (`--pace X`).
//!
//! A simulated session runs in virtual time as fast as it can. A [`Pacer`] is an observer put
//! first among a run's observers: at every frame, pose and event of virtual time `t` it waits
//! until `t / pace` seconds of wall time have passed since the run began, so the session (and
//! a Foxglove view of it) moves at `pace` times real time. A waiting pacer wakes every
//! [`POLL`] to look at the stop flag, so a signal ends a paced run at once. The simulation's
//! results are unchanged: pacing only delays the observers' calls.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::report::{FrameEvent, Observer};
use super::{Event, PoseSample, Role};

/// How often a waiting pacer looks at the stop flag.
pub const POLL: Duration = Duration::from_millis(50);
/// The slowest pace (virtual seconds per wall second).
pub const MIN_PACE: f64 = 0.01;
/// The fastest pace.
pub const MAX_PACE: f64 = 10_000.0;

/// Holds a run's observers back to `pace` times real time.
pub struct Pacer<'a> {
    pace: f64,
    started: Instant,
    stop: &'a AtomicBool,
}

impl<'a> Pacer<'a> {
    /// A pacer for a run starting now, at `pace` (clamped to [`MIN_PACE`] ..= [`MAX_PACE`]),
    /// giving up its waits once `stop` is set.
    pub fn new(pace: f64, stop: &'a AtomicBool) -> Pacer<'a> {
        let pace = if pace.is_finite() { pace } else { 1.0 };
        Pacer {
            pace: pace.clamp(MIN_PACE, MAX_PACE),
            started: Instant::now(),
            stop,
        }
    }

    /// Waits until virtual time `t_s` is due on the wall clock.
    pub fn wait_for(&self, t_s: f64) {
        if !(t_s.is_finite() && t_s > 0.0) {
            return;
        }
        let due = self.started + Duration::from_secs_f64((t_s / self.pace).min(1e9));
        loop {
            let now = Instant::now();
            if now >= due || self.stop.load(Ordering::Relaxed) {
                return;
            }
            std::thread::sleep((due - now).min(POLL));
        }
    }
}

impl Observer for Pacer<'_> {
    fn frame(&mut self, e: &FrameEvent<'_>) {
        self.wait_for(e.t_received_s.or(e.t_sent_s).unwrap_or(0.0));
    }

    fn pose(&mut self, _vehicle: u8, pose: &PoseSample) {
        self.wait_for(pose.t_s);
    }

    fn event(&mut self, _vehicle: u8, _end: Role, t_s: f64, _event: &Event) {
        self.wait_for(t_s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn it_waits_for_virtual_time_at_its_pace_and_gives_up_on_a_stop() {
        let never = AtomicBool::new(false);
        let pacer = Pacer::new(10.0, &never);
        // 1 s of virtual time at 10x: 0.1 s of wall time after the start.
        pacer.wait_for(1.0);
        assert!(pacer.started.elapsed() >= Duration::from_millis(100));
        // Times already past, NaN and negative ones do not wait.
        let waited = Instant::now();
        for t in [0.5, f64::NAN, -3.0, f64::NEG_INFINITY] {
            pacer.wait_for(t);
        }
        assert!(waited.elapsed() < Duration::from_millis(50));
        let stopped = AtomicBool::new(true);
        let waited = Instant::now();
        Pacer::new(MIN_PACE, &stopped).wait_for(1e6);
        assert!(waited.elapsed() < POLL);
        assert_eq!(Pacer::new(f64::NAN, &never).pace, 1.0);
        assert_eq!(Pacer::new(1e9, &never).pace, MAX_PACE);
    }
}
