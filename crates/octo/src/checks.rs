//! Numbers in a configuration checked against their ranges, with units: [`check_range`], and
//! the error that names the option, the range and what was found ([`ConfigError`]). The map's
//! own parameters (the synthetic survey's, a transfer's scan period) and octo-delta's flags
//! (`rovlink-mapper`) are checked by the same rule.

use crate::transfer;

/// A wrong number in a configuration: which option, what was expected (with its unit) and what
/// was found. Displays as `--res: expected 0.0001 m ..= 1000 m, found 0`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{option}: expected {expected}, found {found}")]
pub struct ConfigError {
    /// The option, as the command line names it (`--res`).
    pub option: &'static str,
    /// The accepted values, with units.
    pub expected: String,
    /// The value given.
    pub found: String,
}

impl ConfigError {
    /// An error for `option`: `expected` (with its unit), `found`.
    pub fn new(option: &'static str, expected: impl Into<String>, found: impl ToString) -> Self {
        ConfigError {
            option,
            expected: expected.into(),
            found: found.to_string(),
        }
    }
}

/// A number as messages show it: plain, or in exponent form when very large or small
/// (`1e300`, `1e-9`, not 300 digits).
pub fn shown(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && a.is_finite() && !(1e-4..1e7).contains(&a) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// Checks that `v` is finite and within `lo ..= hi` (`unit` for the message).
pub fn check_range(
    option: &'static str,
    v: f64,
    lo: f64,
    hi: f64,
    unit: &str,
) -> Result<f64, ConfigError> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        let u = if unit.is_empty() {
            String::new()
        } else {
            format!(" {unit}")
        };
        Err(ConfigError::new(
            option,
            format!("{}{u} ..= {}{u}", shown(lo), shown(hi)),
            shown(v),
        ))
    }
}

/// Checks a transfer's time between scans (0 ..= [`transfer::MAX_PERIOD_S`]).
pub fn check_scan_period(period_s: f64) -> Result<f64, ConfigError> {
    check_range("--scan-period", period_s, 0.0, transfer::MAX_PERIOD_S, "s")
}
