//! The virtual-time driver: frames from one side, offered back to back or at a fixed interval,
//! through a [`Link`] as fast as the CPU allows.
//!
//! Back to back means each frame is offered when the previous one's air time is over (the
//! transmitter is free), which is how a modem is fed at its own pace: no frame waits in the
//! FIFO, so its delay is exactly the intrinsic delay, its jitter, its air time and the
//! propagation. With an interval, frame `k` is offered at `k x interval` whatever the link is
//! doing, and the FIFO absorbs (or drops) what the link cannot keep up with.
//!
//! Frames are pulled from the source only when they are offered, and reports are pushed to the
//! sink as soon as they are decided, so memory holds only the frames in flight.

use super::channel::{Link, Report, Side};
use super::sched::SimTime;

/// When frames are offered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pace {
    /// Each frame when the transmitter is free.
    BackToBack,
    /// Frame `k` at `k x` this many nanoseconds.
    IntervalNs(u64),
}

/// Offers every frame `source` yields from side A of `link`, in virtual time at `pace`, and
/// hands each report to `sink` (in the order fates are decided) until the last frame's fate is
/// known. `source` is called at each offer time, with that time, and returns the frame to offer
/// (`None` ends the input). Errors from the source or the sink stop the run and are returned.
pub fn run<E>(
    link: &mut Link,
    pace: Pace,
    mut source: impl FnMut(SimTime) -> Result<Option<Vec<u8>>, E>,
    mut sink: impl FnMut(Report) -> Result<(), E>,
) -> Result<(), E> {
    let mut exhausted = false;
    let mut offered: u64 = 0;
    loop {
        if !exhausted {
            let offer_at = match pace {
                Pace::BackToBack => link.tx_idle(Side::A).then(|| link.now()),
                Pace::IntervalNs(interval) => Some(SimTime(offered.saturating_mul(interval))),
            };
            match offer_at {
                // Events due at the offer time come first: a transmitter freed at t takes a
                // frame offered at t. (Back to back with nothing pending: the link is idle.)
                Some(t) if link.next_event_time().is_none_or(|due| due > t) => {
                    link.advance(t);
                    match source(link.now())? {
                        Some(frame) => {
                            link.offer(Side::A, frame);
                            offered += 1;
                        }
                        None => exhausted = true,
                    }
                }
                _ => {
                    link.step();
                }
            }
        } else if !link.step() {
            while let Some(report) = link.pop_report() {
                sink(report)?;
            }
            return Ok(());
        }
        while let Some(report) = link.pop_report() {
            sink(report)?;
        }
    }
}
