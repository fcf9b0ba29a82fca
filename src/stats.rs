//! The figures every report prints: running mean and standard deviation of a series.
//!
//! [`Running`] keeps Welford's running sums, so a million delays cost three numbers of memory
//! and the result does not suffer the cancellation of the naive sum of squares.

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

    /// Smallest value (0 for an empty series).
    pub fn min(&self) -> f64 {
        self.min
    }

    /// Largest value (0 for an empty series).
    pub fn max(&self) -> f64 {
        self.max
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
    fn empty_and_single_series_are_zero_spread() {
        let mut running = Running::new();
        assert_eq!((running.mean(), running.std()), (0.0, 0.0));
        running.push(4.0);
        assert_eq!((running.mean(), running.std()), (4.0, 0.0));
    }
}
