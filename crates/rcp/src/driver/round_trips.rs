//! An operator's round trips in real time, where one-way delays would need both ends' clocks.

use crate::report::Metrics;
use rovlink_base::stats::Running;
use rovlink_link::SimTime;

/// An operator's round trips in real time: from a slot's frame to the next answer heard. When a
/// slot goes out while the one before is unanswered, the next answer may be that late one, so
/// it is not timed (it would give a round trip shorter than the link allows).
#[derive(Debug, Default)]
pub struct RoundTrips {
    /// The last slot's send time, until its answer arrives.
    awaiting: Option<SimTime>,
    /// A slot went out while the one before was unanswered: the next answer is not timed.
    ambiguous: bool,
    /// The round trips timed, ms.
    ms: Running,
}

impl RoundTrips {
    /// A slot's frame went out at `t`.
    pub fn sent(&mut self, t: SimTime) {
        self.ambiguous = self.awaiting.is_some();
        self.awaiting = Some(t);
    }

    /// An answer arrived at `t`.
    pub fn answered(&mut self, t: SimTime) {
        if let Some(sent) = self.awaiting.take() {
            if self.ambiguous {
                self.ambiguous = false;
            } else {
                self.ms.push(t.0.saturating_sub(sent.0) as f64 * 1e-6);
            }
        }
    }

    /// The figures' round trip and its jitter, once one was timed.
    pub fn fill(&self, metrics: &mut Metrics) {
        if self.ms.count() > 0 {
            metrics.round_trip_ms = Some(self.ms.mean());
            metrics.round_trip_jitter_ms = Some(self.ms.std());
        }
    }
}
