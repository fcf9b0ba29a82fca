//! Points in a local Cartesian frame (the NED frame of the sessions, the media's positions): the
//! one distance every layer uses.

/// The straight-line distance between two points, m.
pub fn distance_m(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_distance_is_euclidean() {
        assert_eq!(super::distance_m([1.0, 2.0, 2.0], [0.0; 3]), 3.0);
        assert_eq!(super::distance_m([-1.0, 5.0, 0.5], [-1.0, 5.0, 0.5]), 0.0);
    }
}
