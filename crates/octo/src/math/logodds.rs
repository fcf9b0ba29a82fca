//! Log-odds as OctoMap computes them, and the sensor model's parameters ([`Params`]).

/// OctoMap's `logodds(p)`: computed in `f64`, stored as `f32`.
pub fn logodds(probability: f64) -> f32 {
    (probability / (1.0 - probability)).ln() as f32
}

/// OctoMap's `probability(l)`.
pub fn probability(log_odds: f64) -> f64 {
    1.0 - (1.0 / (1.0 + log_odds.exp()))
}

/// The sensor model and clamping, as log-odds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Log-odds added to a voxel a point ends in (OctoMap: `logodds(0.7)`).
    pub hit_log: f32,
    /// Log-odds added to a voxel a ray crosses (OctoMap: `logodds(0.4)`).
    pub miss_log: f32,
    /// Lower clamp (OctoMap: `logodds(0.1192)`).
    pub clamp_min_log: f32,
    /// Upper clamp (OctoMap: `logodds(0.971)`).
    pub clamp_max_log: f32,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            hit_log: logodds(0.7),
            miss_log: logodds(0.4),
            clamp_min_log: logodds(0.1192),
            clamp_max_log: logodds(0.971),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_params_are_octomaps_floats() {
        let p = Params::default();
        assert_eq!(p.clamp_min_log.to_bits(), 0xc000_0075);
        assert_eq!(p.clamp_max_log.to_bits(), 0x4060_b4ba);
        assert_eq!(p.hit_log.to_bits(), 0x3f58_e883);
        assert_eq!(p.miss_log.to_bits(), 0xbecf_991f);
        // graph2tree re-derives them through probability(): the same floats.
        assert_eq!(logodds(probability(p.hit_log as f64)), p.hit_log);
        assert_eq!(
            logodds(probability(p.clamp_min_log as f64)),
            p.clamp_min_log
        );
    }
}
