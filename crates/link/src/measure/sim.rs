//! A characterisation campaign in virtual time, over a link model: `modem-bench --sim`.
//!
//! The same probes as a real campaign ([`super::live`]) go from side A to side B of a [`Link`]
//! through the virtual-time driver ([`pipe::run`]): back to back (each when the transmitter is
//! free) or one every `interval`, sizes interleaved (probe `k` has size `sizes[k % sizes.len()]`),
//! each stamped with its offer time. Rows are handed over as fates are decided (deliveries in
//! arrival order), so a caller that writes them as they come keeps every row when the run is
//! cut short; memory holds only the probes in flight.
//!
//! The stop flag is checked at every event: a stopped campaign ends at once, its rows so far
//! handed over, the probes still in flight not recorded.

use std::sync::atomic::AtomicBool;

use super::{PlanError, Row, probe, probe_total};
use crate::pipe::{self, HORIZON, Pace};
use crate::{Fate, Link, Side};

/// What to send.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Probe sizes, bytes (each a whole link frame), interleaved.
    pub sizes: Vec<usize>,
    /// Probes per size.
    pub count_per_size: u32,
    /// When probes are offered.
    pub pace: Pace,
}

impl Plan {
    /// Checks the plan against the link it will run on: sizes, count, and a length that fits
    /// in virtual time ([`HORIZON`]; estimated from the interval, or back to back from each
    /// probe's intrinsic delay and air time); returns the number of probes.
    pub fn check(&self, link: &Link) -> Result<u64, PlanError> {
        let total = probe_total(&self.sizes, self.count_per_size)?;
        let model = link.model(Side::A);
        let round_s: f64 = match self.pace {
            Pace::IntervalNs(ns) => ns as f64 * 1e-9 * self.sizes.len() as f64,
            Pace::BackToBack => self
                .sizes
                .iter()
                .map(|&size| model.air_time_s(size) + model.intrinsic_delay_ms * 1e-3)
                .sum(),
        };
        let length_s = round_s * f64::from(self.count_per_size);
        if length_s > HORIZON.as_secs_f64() {
            return Err(PlanError::TooLong {
                years: length_s / (365.0 * 24.0 * 3600.0),
            });
        }
        Ok(total)
    }
}

/// How a simulated campaign ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// Every probe was sent and its fate recorded.
    Done,
    /// Stopped at the flag; `unresolved` probes were still in flight (not in the rows).
    Stopped {
        /// Probes sent whose fate was not decided yet.
        unresolved: u64,
    },
}

/// Runs the campaign on `link`; `on_row` gets each row when its fate is decided (a duplicated
/// delivery is not a row), `on_progress` the number of rows so far, every 1024 rows. The plan is
/// checked first ([`Plan::check`]); a campaign whose jitter still carries it past [`HORIZON`]
/// ends there with [`PlanError::TooLong`], its rows so far handed over. An error from `on_row`
/// stops the run and is returned.
pub fn run<E: From<PlanError>>(
    link: &mut Link,
    plan: &Plan,
    stop: &AtomicBool,
    mut on_row: impl FnMut(Row) -> Result<(), E>,
    mut on_progress: impl FnMut(u64),
) -> Result<Ended, E> {
    let total = plan.check(link)?;
    let mut seq: u64 = 0;
    let mut done: u64 = 0;
    let sizes = &plan.sizes;
    let ended = pipe::run(
        link,
        plan.pace,
        stop,
        |t| -> Result<Option<Vec<u8>>, E> {
            if seq == total {
                return Ok(None);
            }
            let size = sizes[(seq % sizes.len() as u64) as usize];
            let bytes = probe(seq as u32, size, t.0 / 1000);
            seq += 1;
            Ok(bytes)
        },
        |report| -> Result<(), E> {
            if report.duplicate {
                return Ok(());
            }
            let t_tx_s = report.t_offered.as_secs_f64();
            let t_rx_s = report.t_rx.map(|t| t.as_secs_f64());
            let delay_ms = report
                .t_rx
                .map(|t| t.0.saturating_sub(report.t_offered.0) as f64 * 1e-6);
            on_row(Row {
                seq: report.seq as u32,
                size_bytes: report.len,
                t_tx_s,
                t_rx_s,
                delay_ms,
                delivered: report.fate.arrived(),
                corrupted: report.fate == Fate::Corrupted,
            })?;
            done += 1;
            if done.is_multiple_of(1024) {
                on_progress(done);
            }
            Ok(())
        },
    )?;
    on_progress(done);
    Ok(match ended {
        pipe::Ended::Done => Ended::Done,
        pipe::Ended::Stopped => Ended::Stopped {
            unresolved: link.in_flight() as u64,
        },
        pipe::Ended::Horizon => return Err(PlanError::TooLong { years: 100.0 }.into()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::{Summary, Tally};
    use crate::{Distance, Model};
    use std::sync::atomic::Ordering;

    fn link(model: &str) -> Link {
        Link::symmetric(Model::preset(model).unwrap(), 1, Distance::Fixed(1.0)).unwrap()
    }

    fn plan(sizes: &[usize], count: u32) -> Plan {
        Plan {
            sizes: sizes.to_vec(),
            count_per_size: count,
            pace: Pace::BackToBack,
        }
    }

    #[test]
    fn a_sweep_streams_rows_in_arrival_order_and_fits_the_model() {
        let mut link = link("s100");
        let mut rows = Vec::new();
        let mut tally = Tally::new();
        let ended = run::<PlanError>(
            &mut link,
            &plan(&[16, 57, 100], 300),
            &AtomicBool::new(false),
            |row| {
                tally.push(&row);
                rows.push(row);
                Ok(())
            },
            |_| {},
        )
        .unwrap();
        assert_eq!(ended, Ended::Done);
        assert_eq!(rows.len(), 900);
        let arrivals: Vec<f64> = rows.iter().filter_map(|r| r.t_rx_s).collect();
        assert!(arrivals.windows(2).all(|w| w[0] <= w[1]), "arrival order");
        // Streaming gives the figures of the whole set of rows.
        let streamed = tally.summary();
        let whole = Summary::from_rows(&rows);
        assert_eq!(
            serde_json::to_value(&streamed).unwrap(),
            serde_json::to_value(&whole).unwrap()
        );
        let rate = streamed.fit_bitrate_bps.unwrap();
        assert!((rate / 1900.0 - 1.0).abs() < 0.03, "{rate}");
    }

    #[test]
    fn the_stop_flag_ends_the_campaign_at_the_next_event() {
        let mut link = link("s100");
        let stop = AtomicBool::new(false);
        let mut rows = 0u64;
        let ended = run::<PlanError>(
            &mut link,
            &plan(&[57], 1_000_000_000),
            &stop,
            |_| {
                rows += 1;
                if rows == 50 {
                    stop.store(true, Ordering::Relaxed);
                }
                Ok(())
            },
            |_| {},
        )
        .unwrap();
        assert!(matches!(ended, Ended::Stopped { unresolved } if unresolved <= 2));
        assert_eq!(rows, 50);
    }

    #[test]
    fn plans_beyond_sequence_numbers_or_virtual_time_are_refused() {
        let link = link("s100");
        let too_many = plan(&[16, 17, 18, 19, 20], 1_000_000_000).check(&link);
        assert!(matches!(too_many, Err(PlanError::TooMany(5_000_000_000))));
        assert!(matches!(plan(&[57], 0).check(&link), Err(PlanError::Empty)));
        assert!(matches!(
            plan(&[10], 1).check(&link),
            Err(PlanError::Size(10))
        ));
        let mut slow = Model::preset("s100").unwrap();
        slow.bitrate_bps = 1.0;
        let slow = Link::symmetric(slow, 1, Distance::Fixed(1.0)).unwrap();
        let message = plan(&[260], 1_000_000_000)
            .check(&slow)
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("years of virtual time (at most 100)"),
            "{message}"
        );
        let paced = Plan {
            pace: Pace::IntervalNs(3_600_000_000_000),
            ..plan(&[57], 1_000_000)
        };
        assert!(matches!(paced.check(&link), Err(PlanError::TooLong { .. })));
        assert_eq!(
            plan(&[57], 1_000_000_000).check(&link).unwrap(),
            1_000_000_000
        );
    }
}
