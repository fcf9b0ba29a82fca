//! The figures every report prints: running mean and standard deviation of a series, and its
//! quantiles in fixed memory.
//!
//! [`Running`] keeps Welford's running sums, so a million delays cost three numbers of memory
//! and the result does not suffer the cancellation of the naive sum of squares: mean and
//! standard deviation are exact (to floating point).
//!
//! [`Quantiles`] is a sketch of fixed size (about 250 KiB, whatever the number of values): an
//! HDR histogram ([`hdrhistogram`]) of durations in microseconds with 3 significant digits. A
//! quantile it gives is within 0.1 % of the exact nearest-rank quantile, or 1 µs when that is
//! larger; durations beyond [`Quantiles::MAX_US`] (about 12.7 days) count as that.

/// Count, mean, standard deviation, minimum and maximum of a series, updated one value at a time.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Running {
    count: u64,
    mean: f64,
    m2: f64,
    min: f64,
    max: f64,
}

impl Running {
    /// An empty series.
    pub fn new() -> Running {
        Running::default()
    }

    /// Adds a value.
    pub fn push(&mut self, value: f64) {
        self.count += 1;
        if self.count == 1 {
            self.min = value;
            self.max = value;
        } else {
            self.min = self.min.min(value);
            self.max = self.max.max(value);
        }
        let delta = value - self.mean;
        self.mean += delta / self.count as f64;
        self.m2 += delta * (value - self.mean);
    }

    /// Number of values.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Mean (0 for an empty series).
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Sample standard deviation (n - 1 in the denominator; 0 below two values).
    pub fn std(&self) -> f64 {
        if self.count < 2 {
            0.0
        } else {
            (self.m2 / (self.count - 1) as f64).sqrt()
        }
    }

    /// Sum of the squared deviations from the mean (Welford's M2): `std² x (count - 1)` without
    /// the round trip through the square root.
    pub fn sum_squared_deviations(&self) -> f64 {
        self.m2
    }

    /// Smallest value (0 for an empty series).
    pub fn min(&self) -> f64 {
        self.min
    }

    /// Largest value (0 for an empty series).
    pub fn max(&self) -> f64 {
        self.max
    }
}

/// Quantiles of a series of durations in fixed memory: see the module documentation for the
/// accuracy.
#[derive(Debug, Clone)]
pub struct Quantiles {
    histogram: hdrhistogram::Histogram<u64>,
}

impl Default for Quantiles {
    fn default() -> Quantiles {
        Quantiles::new()
    }
}

impl Quantiles {
    /// The largest duration told apart, µs (2^40, about 12.7 days); larger ones count as this.
    pub const MAX_US: u64 = 1 << 40;

    /// Significant digits kept of every value.
    pub const SIGNIFICANT_DIGITS: u8 = 3;

    /// An empty sketch.
    pub fn new() -> Quantiles {
        let histogram = hdrhistogram::Histogram::new_with_bounds(
            1,
            Quantiles::MAX_US,
            Self::SIGNIFICANT_DIGITS,
        )
        .unwrap_or_else(|_| unreachable!("1 ..= 2^40 with 3 digits is a valid histogram"));
        Quantiles { histogram }
    }

    /// Adds a duration in milliseconds (rounded to the microsecond; negative or not a number
    /// counts as 0, beyond [`Quantiles::MAX_US`] as that).
    pub fn push_ms(&mut self, ms: f64) {
        let us = (ms * 1e3).round();
        let us = if us >= 0.0 { us as u64 } else { 0 };
        self.push_us(us);
    }

    /// Adds a duration in microseconds (beyond [`Quantiles::MAX_US`]: counted as that).
    pub fn push_us(&mut self, us: u64) {
        self.histogram.saturating_record(us.min(Quantiles::MAX_US));
    }

    /// Number of values.
    pub fn count(&self) -> u64 {
        self.histogram.len()
    }

    /// The `q` quantile (0..=1, nearest rank), ms; none when empty.
    pub fn quantile_ms(&self, q: f64) -> Option<f64> {
        if self.histogram.is_empty() {
            return None;
        }
        let value = self.histogram.value_at_quantile(q.clamp(0.0, 1.0));
        // The middle of the value's bucket halves the error of either end.
        let middle = self.histogram.median_equivalent(value);
        Some(middle.min(Quantiles::MAX_US) as f64 * 1e-3)
    }

    /// Counters the sketch holds: fixed when it is created, whatever is pushed.
    pub fn cells(&self) -> usize {
        self.histogram.distinct_values()
    }
}

/// The `q` quantile (0..=1, nearest rank) of values sorted in ascending order; none when empty.
pub fn quantile_sorted<T: Copy>(sorted: &[T], q: f64) -> Option<T> {
    if sorted.is_empty() {
        return None;
    }
    let rank = (q.clamp(0.0, 1.0) * sorted.len() as f64).ceil() as usize;
    Some(sorted[rank.clamp(1, sorted.len()) - 1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_two_pass_formulas() {
        let values = [325.0, 310.5, 341.25, 330.0, 299.75, 1e-3];
        let mut running = Running::new();
        values.iter().for_each(|&v| running.push(v));
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
        assert_eq!(running.count(), 6);
        assert!((running.mean() - mean).abs() < 1e-9);
        assert!((running.std() - var.sqrt()).abs() < 1e-9);
        assert_eq!((running.min(), running.max()), (1e-3, 341.25));
    }

    #[test]
    fn quantiles_are_nearest_rank() {
        let values: Vec<u32> = (1..=100).collect();
        assert_eq!(quantile_sorted(&values, 0.5), Some(50));
        assert_eq!(quantile_sorted(&values, 0.99), Some(99));
        assert_eq!(quantile_sorted(&values, 1.0), Some(100));
        assert_eq!(quantile_sorted(&values, 0.0), Some(1));
        assert_eq!(quantile_sorted::<u32>(&[], 0.5), None);
    }

    #[test]
    fn sketch_quantiles_are_within_a_thousandth_in_fixed_memory() {
        let mut sketch = Quantiles::new();
        assert_eq!(sketch.quantile_ms(0.5), None);
        let cells = sketch.cells();
        // Delays from 0.5 ms to 5000 s, in a scrambled order.
        let values: Vec<f64> = (0..200_000u64)
            .map(|k| 0.5 * 1.0001f64.powi(((k * 7919) % 200_000) as i32 / 2))
            .collect();
        values.iter().for_each(|&v| sketch.push_ms(v));
        let mut sorted = values.clone();
        sorted.sort_by(f64::total_cmp);
        for q in [0.0, 0.01, 0.25, 0.5, 0.9, 0.99, 0.999, 1.0] {
            let exact = quantile_sorted(&sorted, q).unwrap();
            let sketched = sketch.quantile_ms(q).unwrap();
            let tolerance = (exact * 1e-3).max(1e-3);
            assert!(
                (sketched - exact).abs() <= tolerance,
                "q {q}: {sketched} against {exact}"
            );
        }
        assert_eq!(sketch.count(), 200_000);
        assert_eq!(sketch.cells(), cells, "the sketch grew");
        assert!(cells * 8 < 300 * 1024, "{cells} cells");
        // Small whole microseconds are exact; out-of-range values are clamped, not lost.
        let mut small = Quantiles::new();
        [1.0, 2.0, 3.0, -4.0, f64::NAN, 1e300]
            .iter()
            .for_each(|&v| small.push_ms(v));
        assert_eq!(small.quantile_ms(0.5), Some(1.0));
        assert_eq!(small.quantile_ms(0.0), Some(0.0));
        let top = small.quantile_ms(1.0).unwrap();
        assert!(
            (top / (Quantiles::MAX_US as f64 * 1e-3) - 1.0).abs() < 1e-3,
            "{top}"
        );
    }

    #[test]
    fn empty_and_single_series_are_zero_spread() {
        let mut running = Running::new();
        assert_eq!((running.mean(), running.std()), (0.0, 0.0));
        running.push(4.0);
        assert_eq!((running.mean(), running.std()), (4.0, 0.0));
    }
}
