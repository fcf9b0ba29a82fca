//! Modem and channel models: what a link does to each frame, as numbers a file can hold.
//!
//! A [`Model`] describes one direction of a link, the sending modem and the water (or air, or
//! satellite hop) after it, in the terms of the paper's Table 3 and of UWSim-NET's device model
//! (facts.md):
//!
//! - **air time**: a frame of `n` bytes occupies the channel for `n x 8 / bitrate_bps` seconds
//!   (or `/ rate_limit_bps` when a netem-style rate limit is lower);
//! - **intrinsic delay**: the modem's processing before transmission, `intrinsic_delay_ms` plus
//!   a jitter drawn from `jitter_distribution` with standard deviation `jitter_ms`. The sum is
//!   clamped at zero (a delay is never negative), which keeps the mean and the standard
//!   deviation at the model's figures whenever the jitter is small against the delay (S100) and
//!   moves them least when it is not (S2CR);
//! - **propagation**: `propagation_min_ms + propagation_ms_per_m x distance`, and a frame is only
//!   heard when the distance is within `[range_min_m, range_max_m]`;
//! - **bit errors** at `ber` per bit: `errors: drop` loses the frame, `errors: corrupt` delivers
//!   it with exactly the bits that were hit flipped;
//! - **half duplex**: a modem cannot hear while it transmits;
//! - a **transmit FIFO** of `fifo_bytes`: a frame that does not fit is dropped;
//! - netem's extras: random loss, Gilbert-Elliott burst loss, corruption (one flipped bit),
//!   duplication, a rate limit.
//!
//! Presets ([`Model::preset`]) give the paper's modems and the satellite link of the second
//! paper. Model files are the JSON form of [`Model`]; every field is also a command-line flag
//! (`rovlink_cli::model::ModelArgs`), so a file and a command line say the same things.
//!
//! Every figure has a range ([`Model::validate`]) that no real modem or link exceeds: bit rates
//! 1 bit/s ..= 10 Gbit/s, delays and jitter up to an hour, propagation up to 10 ms/m, ranges up
//! to a million km, FIFOs up to 64 MiB. Within them every time a run computes stays far inside
//! virtual time (2^64 ns, 584 years): a frame's fate is decided at most about 20 years of
//! virtual time after it is offered (a full 64 MiB FIFO at 1 bit/s), so nothing saturates.
//!
//! Parsing never panics: a malformed file is a [`ModelError`] naming the field and the problem.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Names of the built-in models, in the order `--help` lists them.
pub const PRESETS: [&str; 5] = [
    "s100",
    "s2cr-burst",
    "s2cr-ack",
    "satellite-up",
    "satellite-down",
];

/// The highest bit error rate a model may have: at 0.5 a bit carries nothing.
pub const MAX_BER: f64 = 0.5;
/// Largest model file read, bytes (a model is a few hundred).
pub const MAX_MODEL_FILE_BYTES: u64 = 1 << 20;
/// The lowest bit rate a model may have, bit/s (`bitrate_bps`, `rate_limit_bps`): the slowest
/// acoustic modems run at tens of bit/s.
pub const MIN_BITRATE_BPS: f64 = 1.0;
/// The highest bit rate a model may have, bit/s: 10 Gbit/s.
pub const MAX_BITRATE_BPS: f64 = 1e10;
/// The longest intrinsic delay, jitter or fixed propagation a model may have, ms: one hour
/// (a satellite hop is 310 ms, an acoustic modem's processing under a second, Mars 22 min).
pub const MAX_DELAY_MS: f64 = 3_600_000.0;
/// The slowest propagation a model may have, ms per metre (sound in water is 0.67, in air 2.9).
pub const MAX_PROPAGATION_MS_PER_M: f64 = 10.0;
/// The farthest range (and distance) a model may have, m: a million km.
pub const MAX_RANGE_M: f64 = 1e9;
/// The largest transmit FIFO a model may have, bytes: 64 MiB (modems hold kilobytes).
pub const MAX_FIFO_BYTES: u64 = 64 << 20;

/// The shape of the intrinsic-delay jitter. Every shape has mean 0 and the model's `jitter_ms`
/// as its standard deviation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JitterDistribution {
    /// No jitter: every frame waits exactly the intrinsic delay.
    None,
    /// Uniform on [-sqrt 3, sqrt 3] x jitter_ms (netem's default shape).
    Uniform,
    /// Normal (Gaussian).
    Normal,
    /// Laplace (double exponential): more small and more large deviations than normal.
    Laplace,
}

/// What a bit error does to a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ErrorMode {
    /// The frame is lost (a modem that checks its own CRC).
    Drop,
    /// The frame is delivered with the hit bits flipped (a transparent modem).
    Corrupt,
}

/// Gilbert-Elliott burst loss, netem's `loss gemodel p r 1-h 1-k` in percent.
///
/// The channel is in a good or a bad state; each frame is lost with the state's loss
/// probability, then the state moves on (good to bad with `p_percent`, bad to good with
/// `r_percent`). The long-run loss is `(p x bad + r x good) / (p + r)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GilbertElliott {
    /// Probability of moving from the good to the bad state, per frame, in percent.
    pub p_percent: f64,
    /// Probability of moving from the bad to the good state, per frame, in percent.
    pub r_percent: f64,
    /// Loss probability in the bad state, in percent (netem's 1-h; default 100).
    #[serde(default = "hundred")]
    pub loss_bad_percent: f64,
    /// Loss probability in the good state, in percent (netem's 1-k; default 0).
    #[serde(default)]
    pub loss_good_percent: f64,
}

fn hundred() -> f64 {
    100.0
}

fn yes() -> bool {
    true
}

fn default_jitter() -> JitterDistribution {
    JitterDistribution::Normal
}

fn default_errors() -> ErrorMode {
    ErrorMode::Drop
}

fn default_fifo_bytes() -> u64 {
    65_536
}

/// One direction of a link: the sending modem and the channel after it.
///
/// Field names carry their units; the JSON form uses the same names. Only `bitrate_bps` and
/// `intrinsic_delay_ms` are required in a file; the rest default to an ideal channel (jitter 0,
/// no range limit, no errors or losses, half duplex, a 64 KiB FIFO).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// A name for reports.
    #[serde(default)]
    pub name: String,
    /// Where the figures come from.
    #[serde(default)]
    pub description: String,
    /// Bit rate on the air, bit/s.
    pub bitrate_bps: f64,
    /// The modem's processing delay before it transmits, ms.
    pub intrinsic_delay_ms: f64,
    /// Shape of the jitter added to the intrinsic delay.
    #[serde(default = "default_jitter")]
    pub jitter_distribution: JitterDistribution,
    /// Standard deviation of that jitter, ms.
    #[serde(default)]
    pub jitter_ms: f64,
    /// Propagation delay at zero distance, ms.
    #[serde(default)]
    pub propagation_min_ms: f64,
    /// Propagation delay per metre of distance, ms/m.
    #[serde(default)]
    pub propagation_ms_per_m: f64,
    /// Nearest distance at which a frame is heard, m.
    #[serde(default)]
    pub range_min_m: f64,
    /// Farthest distance at which a frame is heard, m (absent: no limit).
    #[serde(default)]
    pub range_max_m: Option<f64>,
    /// Bit error rate (probability that a bit is flipped), 0 ..= 0.5.
    #[serde(default)]
    pub ber: f64,
    /// What a frame with bit errors becomes.
    #[serde(default = "default_errors")]
    pub errors: ErrorMode,
    /// The receiving modem cannot hear while it transmits (a reception that overlaps its own
    /// transmission is lost).
    #[serde(default = "yes")]
    pub half_duplex: bool,
    /// Transmit FIFO capacity, bytes: frames waiting for the air that do not fit are dropped.
    #[serde(default = "default_fifo_bytes")]
    pub fifo_bytes: u64,
    /// Let jitter reorder frames (a later frame with less delay goes on air first).
    #[serde(default)]
    pub reorder: bool,
    /// Random loss of a received frame, percent.
    #[serde(default)]
    pub loss_percent: f64,
    /// Gilbert-Elliott burst loss (absent: none).
    #[serde(default)]
    pub gilbert_elliott: Option<GilbertElliott>,
    /// Corruption of a received frame (one random bit flipped), percent.
    #[serde(default)]
    pub corrupt_percent: f64,
    /// Duplication of a delivered frame, percent.
    #[serde(default)]
    pub duplicate_percent: f64,
    /// A rate limit below the bit rate, bit/s (absent: none).
    #[serde(default)]
    pub rate_limit_bps: Option<f64>,
}

/// A model that cannot be used, or a model file that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// A field holds a value the model cannot use.
    #[error("field `{field}`: {problem}")]
    Field {
        /// The field's name, as in the JSON file.
        field: String,
        /// What is wrong, with the value found.
        problem: String,
    },
    /// No preset of that name.
    #[error("unknown model `{0}` (presets: {presets})", presets = PRESETS.join(", "))]
    UnknownPreset(String),
    /// The file is not valid JSON for a model.
    #[error("{path}: {source}")]
    File {
        /// The model file.
        path: PathBuf,
        /// What is wrong.
        source: Box<ModelError>,
    },
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The model file.
        path: PathBuf,
        /// The reason.
        source: std::io::Error,
    },
    /// The JSON does not describe a model.
    #[error("field `{field}`: {message}")]
    Json {
        /// Where in the document (`.` when the problem is the document itself).
        field: String,
        /// serde's description, with line and column.
        message: String,
    },
}

impl Model {
    /// A built-in model by name (see [`PRESETS`]).
    pub fn preset(name: &str) -> Result<Model, ModelError> {
        let base = Model {
            name: name.to_string(),
            description: String::new(),
            bitrate_bps: 1.0,
            intrinsic_delay_ms: 0.0,
            jitter_distribution: JitterDistribution::Normal,
            jitter_ms: 0.0,
            propagation_min_ms: 0.0,
            propagation_ms_per_m: 0.0,
            range_min_m: 0.0,
            range_max_m: None,
            ber: 0.0,
            errors: ErrorMode::Drop,
            half_duplex: true,
            fifo_bytes: default_fifo_bytes(),
            reorder: false,
            loss_percent: 0.0,
            gilbert_elliott: None,
            corrupt_percent: 0.0,
            duplicate_percent: 0.0,
            rate_limit_bps: None,
        };
        let model = match name {
            "s100" => Model {
                description: "WFS S100 RF modem (paper Table 3)".into(),
                bitrate_bps: 1900.0,
                intrinsic_delay_ms: 85.0,
                jitter_ms: 13.20,
                propagation_ms_per_m: 3.3e-9,
                range_min_m: 0.5,
                range_max_m: Some(5.0),
                fifo_bytes: 2048,
                ..base
            },
            "s2cr-burst" => Model {
                description: "EvoLogics S2CR acoustic modem, burst mode (paper Table 3)".into(),
                bitrate_bps: 1620.0,
                intrinsic_delay_ms: 443.0,
                jitter_ms: 412.99,
                propagation_ms_per_m: 0.67,
                range_max_m: Some(3500.0),
                fifo_bytes: 8192,
                ..base
            },
            "s2cr-ack" => Model {
                description: "EvoLogics S2CR acoustic modem, data in D-MAC acks (paper Table 3)"
                    .into(),
                bitrate_bps: 100.0,
                intrinsic_delay_ms: 443.0,
                jitter_ms: 443.63,
                propagation_ms_per_m: 0.67,
                range_max_m: Some(3500.0),
                fifo_bytes: 1024,
                ..base
            },
            "satellite-up" => Model {
                description: "DexROV satellite link, vessel to shore (768 kbit/s, 310 ms)".into(),
                bitrate_bps: 768_000.0,
                intrinsic_delay_ms: 310.0,
                jitter_distribution: JitterDistribution::None,
                half_duplex: false,
                fifo_bytes: 1 << 20,
                ..base
            },
            "satellite-down" => Model {
                description: "DexROV satellite link, shore to vessel (256 kbit/s, 310 ms)".into(),
                bitrate_bps: 256_000.0,
                intrinsic_delay_ms: 310.0,
                jitter_distribution: JitterDistribution::None,
                half_duplex: false,
                fifo_bytes: 1 << 20,
                ..base
            },
            other => return Err(ModelError::UnknownPreset(other.to_string())),
        };
        Ok(model)
    }

    /// Reads a model from JSON text, then checks it ([`Model::validate`]).
    pub fn from_json(text: &str) -> Result<Model, ModelError> {
        // A repeated key is refused before the typed read (which would keep the last one).
        rovlink_base::strict_json::from_str(text).map_err(|err| ModelError::Json {
            field: ".".into(),
            message: err.to_string(),
        })?;
        let mut de = serde_json::Deserializer::from_str(text);
        let model: Model = serde_path_to_error::deserialize(&mut de).map_err(|err| {
            let field = err.path().to_string();
            ModelError::Json {
                field,
                message: err.into_inner().to_string(),
            }
        })?;
        de.end().map_err(|err| ModelError::Json {
            field: ".".into(),
            message: err.to_string(),
        })?;
        model.validate()?;
        Ok(model)
    }

    /// Reads a model file; errors name the file.
    pub fn from_file(path: &Path) -> Result<Model, ModelError> {
        let text =
            rovlink_base::io::read_at_most(path, MAX_MODEL_FILE_BYTES).map_err(|source| {
                ModelError::Read {
                    path: path.to_path_buf(),
                    source,
                }
            })?;
        let text = String::from_utf8_lossy(&text);
        Model::from_json(&text).map_err(|err| ModelError::File {
            path: path.to_path_buf(),
            source: Box::new(err),
        })
    }

    /// The model as pretty JSON, the form [`Model::from_json`] reads.
    pub fn to_json(&self) -> String {
        let mut text = serde_json::to_string_pretty(self).unwrap_or_default();
        text.push('\n');
        text
    }

    /// Checks every field against its meaning and its range ([`MIN_BITRATE_BPS`] and the other
    /// limits: wider than any real modem or link, narrow enough that no time of a run leaves
    /// virtual time); the error names the first bad field, the range with its units and the value.
    pub fn validate(&self) -> Result<(), ModelError> {
        fn bad(field: &str, problem: String) -> Result<(), ModelError> {
            Err(ModelError::Field {
                field: field.to_string(),
                problem,
            })
        }
        let within = |field: &str, value: f64, min: f64, max: f64, range: &str| {
            if value.is_finite() && (min..=max).contains(&value) {
                Ok(())
            } else {
                bad(field, format!("expected {range}, found {}", shown(value)))
            }
        };
        let rate = |field: &str, value: f64| {
            within(
                field,
                value,
                MIN_BITRATE_BPS,
                MAX_BITRATE_BPS,
                "1 bit/s ..= 10 Gbit/s (1e10)",
            )
        };
        let delay = |field: &str, value: f64| {
            within(field, value, 0.0, MAX_DELAY_MS, "0 ..= 3600000 ms (1 h)")
        };
        let metres = |field: &str, value: f64| {
            within(field, value, 0.0, MAX_RANGE_M, "0 ..= 1e9 m (a million km)")
        };
        let percent = |field: &str, value: f64| within(field, value, 0.0, 100.0, "0 ..= 100 %");
        rate("bitrate_bps", self.bitrate_bps)?;
        delay("intrinsic_delay_ms", self.intrinsic_delay_ms)?;
        delay("jitter_ms", self.jitter_ms)?;
        delay("propagation_min_ms", self.propagation_min_ms)?;
        within(
            "propagation_ms_per_m",
            self.propagation_ms_per_m,
            0.0,
            MAX_PROPAGATION_MS_PER_M,
            "0 ..= 10 ms/m (sound in water is 0.67)",
        )?;
        metres("range_min_m", self.range_min_m)?;
        if let Some(max) = self.range_max_m {
            metres("range_max_m", max)?;
            if max < self.range_min_m {
                return bad(
                    "range_max_m",
                    format!("{max} is below range_min_m {}", self.range_min_m),
                );
            }
        }
        if !(0.0..=MAX_BER).contains(&self.ber) {
            return bad(
                "ber",
                format!("expected a probability 0 ..= {MAX_BER}, found {}", self.ber),
            );
        }
        if !(1..=MAX_FIFO_BYTES).contains(&self.fifo_bytes) {
            return bad(
                "fifo_bytes",
                format!(
                    "expected 1 ..= {MAX_FIFO_BYTES} bytes (64 MiB), found {}",
                    self.fifo_bytes
                ),
            );
        }
        percent("loss_percent", self.loss_percent)?;
        percent("corrupt_percent", self.corrupt_percent)?;
        percent("duplicate_percent", self.duplicate_percent)?;
        if let Some(ge) = &self.gilbert_elliott {
            percent("gilbert_elliott.p_percent", ge.p_percent)?;
            percent("gilbert_elliott.r_percent", ge.r_percent)?;
            percent("gilbert_elliott.loss_bad_percent", ge.loss_bad_percent)?;
            percent("gilbert_elliott.loss_good_percent", ge.loss_good_percent)?;
        }
        if let Some(limit) = self.rate_limit_bps {
            rate("rate_limit_bps", limit)?;
        }
        Ok(())
    }

    /// The model's main figures in one line: `1900.0 bit/s, intrinsic delay 85.00 ms, jitter
    /// 13.20 ms, BER 0.000e0`.
    pub fn figures(&self) -> String {
        format!(
            "{:.1} bit/s, intrinsic delay {:.2} ms, jitter {:.2} ms, BER {:.3e}",
            self.bitrate_bps, self.intrinsic_delay_ms, self.jitter_ms, self.ber
        )
    }

    /// The rate frames go on air at, bit/s: the bit rate, or the rate limit when lower.
    pub fn effective_rate_bps(&self) -> f64 {
        match self.rate_limit_bps {
            Some(limit) if limit < self.bitrate_bps => limit,
            _ => self.bitrate_bps,
        }
    }

    /// Air time of a frame of `bytes` bytes, seconds.
    pub fn air_time_s(&self, bytes: usize) -> f64 {
        bytes as f64 * 8.0 / self.effective_rate_bps()
    }

    /// Propagation delay over `distance_m`, seconds.
    pub fn propagation_s(&self, distance_m: f64) -> f64 {
        (self.propagation_min_ms + self.propagation_ms_per_m * distance_m) * 1e-3
    }

    /// True when a frame is heard at `distance_m`.
    pub fn in_range(&self, distance_m: f64) -> bool {
        distance_m >= self.range_min_m && self.range_max_m.is_none_or(|max| distance_m <= max)
    }

    /// Probability that a frame of `bytes` bytes has at least one bit error: 1 - (1 - BER)^bits.
    pub fn packet_error_rate(&self, bytes: usize) -> f64 {
        1.0 - (1.0 - self.ber).powf(bytes as f64 * 8.0)
    }
}

/// A number as a message shows it: plain when it reads well, in exponent form when tiny or huge.
fn shown(value: f64) -> String {
    if value == 0.0 || !value.is_finite() || (1e-4..1e16).contains(&value.abs()) {
        format!("{value}")
    } else {
        format!("{value:e}")
    }
}

/// Parses netem's `P,R[,BAD[,GOOD]]` (percent) for `--gilbert-elliott`.
pub fn parse_gilbert_elliott(text: &str) -> Result<GilbertElliott, String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|part| {
            part.trim()
                .parse::<f64>()
                .map_err(|_| format!("`{part}` is not a number"))
        })
        .collect::<Result<_, _>>()?;
    if !(2..=4).contains(&values.len()) {
        return Err(format!(
            "expected P,R[,BAD[,GOOD]] (2 to 4 percentages), found {} values",
            values.len()
        ));
    }
    Ok(GilbertElliott {
        p_percent: values[0],
        r_percent: values[1],
        loss_bad_percent: values.get(2).copied().unwrap_or(100.0),
        loss_good_percent: values.get(3).copied().unwrap_or(0.0),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_is_valid_and_round_trips_through_json() {
        for name in PRESETS {
            let model = Model::preset(name).unwrap();
            model.validate().unwrap();
            assert_eq!(Model::from_json(&model.to_json()).unwrap(), model, "{name}");
        }
    }

    #[test]
    fn numbers_read_back_exactly() {
        // Found by fuzzing: without exact float parsing this came back one ulp off.
        let mut model = Model::preset("satellite-up").unwrap();
        model.bitrate_bps = 7333.333333333335;
        model.jitter_ms = 0.1 + 0.2;
        assert_eq!(Model::from_json(&model.to_json()).unwrap(), model);
    }

    #[test]
    fn s100_air_time_of_a_57_byte_frame_is_240_ms() {
        let model = Model::preset("s100").unwrap();
        assert!((model.air_time_s(57) - 0.240).abs() < 1e-12);
        assert!((model.packet_error_rate(57) - 0.0).abs() < 1e-15);
    }

    #[test]
    fn a_minimal_file_needs_only_the_rate_and_the_delay() {
        let model = Model::from_json(r#"{"bitrate_bps": 1000, "intrinsic_delay_ms": 5}"#).unwrap();
        assert_eq!(model.fifo_bytes, 65_536);
        assert!(model.half_duplex);
        assert_eq!(model.range_max_m, None);
    }

    #[test]
    fn bad_files_name_the_field() {
        let cases = [
            (
                r#"{"bitrate_bps": -3, "intrinsic_delay_ms": 5}"#,
                "field `bitrate_bps`: expected 1 bit/s ..= 10 Gbit/s (1e10), found -3",
            ),
            (
                r#"{"bitrate_bps": 9, "intrinsic_delay_ms": "x"}"#,
                "field `intrinsic_delay_ms`: invalid type",
            ),
            (
                r#"{"bitrate_bps": 9, "intrinsic_delay_ms": 1, "jitter_distribution": "gauss"}"#,
                "field `jitter_distribution`: unknown variant `gauss`",
            ),
            (
                r#"{"bitrate_bps": 9, "intrinsic_delay_ms": 1, "bitrate": 3}"#,
                "field `bitrate`: unknown field `bitrate`",
            ),
            (
                r#"{"bitrate_bps": 9}"#,
                "field `.`: missing field `intrinsic_delay_ms`",
            ),
            (
                r#"{"bitrate_bps": 9, "intrinsic_delay_ms": 1, "gilbert_elliott": {"p_percent": 1, "r_percent": 400}}"#,
                "field `gilbert_elliott.r_percent`: expected 0 ..= 100 %, found 400",
            ),
            (
                r#"{"bitrate_bps": 9, "intrinsic_delay_ms": 1, "range_min_m": 5, "range_max_m": 2}"#,
                "field `range_max_m`: 2 is below range_min_m 5",
            ),
            (
                r#"{"bitrate_bps": 9, "intrinsic_delay_ms": 1, "ber": 1}"#,
                "field `ber`: expected a probability",
            ),
            (
                r#"{"bitrate_bps": 9, "intrinsic_delay_ms": 1} x"#,
                "field `.`: trailing characters",
            ),
            (
                r#"{"bitrate_bps": 9, "intrinsic_delay_ms": 1, "bitrate_bps": 90}"#,
                "field `.`: duplicate key \"bitrate_bps\" (at bitrate_bps)",
            ),
        ];
        for (text, expected) in cases {
            let message = Model::from_json(text).unwrap_err().to_string();
            assert!(message.starts_with(expected), "{text}: {message}");
        }
    }

    #[test]
    fn figures_beyond_any_real_link_are_refused_with_their_range() {
        // Issue 14: these saturated virtual time at 2^64 ns without a word.
        let cases = [
            (
                r#""bitrate_bps": 1e-300, "intrinsic_delay_ms": 5"#,
                "field `bitrate_bps`: expected 1 bit/s ..= 10 Gbit/s (1e10), found 1e-300",
            ),
            (
                r#""bitrate_bps": 1e11, "intrinsic_delay_ms": 5"#,
                "field `bitrate_bps`: expected 1 bit/s ..= 10 Gbit/s (1e10), found 100000000000",
            ),
            (
                r#""bitrate_bps": 9, "intrinsic_delay_ms": 1, "jitter_ms": 1e300"#,
                "field `jitter_ms`: expected 0 ..= 3600000 ms (1 h), found 1e300",
            ),
            (
                r#""bitrate_bps": 9, "intrinsic_delay_ms": 3600001"#,
                "field `intrinsic_delay_ms`: expected 0 ..= 3600000 ms (1 h), found 3600001",
            ),
            (
                r#""bitrate_bps": 9, "intrinsic_delay_ms": 1, "propagation_ms_per_m": 11"#,
                "field `propagation_ms_per_m`: expected 0 ..= 10 ms/m",
            ),
            (
                r#""bitrate_bps": 9, "intrinsic_delay_ms": 1, "range_max_m": 2e9"#,
                "field `range_max_m`: expected 0 ..= 1e9 m",
            ),
            (
                r#""bitrate_bps": 9, "intrinsic_delay_ms": 1, "fifo_bytes": 18446744073709551615"#,
                "field `fifo_bytes`: expected 1 ..= 67108864 bytes (64 MiB)",
            ),
            (
                r#""bitrate_bps": 9, "intrinsic_delay_ms": 1, "rate_limit_bps": 0.5"#,
                "field `rate_limit_bps`: expected 1 bit/s",
            ),
        ];
        for (fields, expected) in cases {
            let text = format!("{{{fields}}}");
            let message = Model::from_json(&text).unwrap_err().to_string();
            assert!(message.starts_with(expected), "{text}: {message}");
        }
        // The edges themselves are real (if extreme) links.
        let mut model = Model::preset("s100").unwrap();
        model.bitrate_bps = MIN_BITRATE_BPS;
        model.intrinsic_delay_ms = MAX_DELAY_MS;
        model.jitter_ms = MAX_DELAY_MS;
        model.propagation_ms_per_m = MAX_PROPAGATION_MS_PER_M;
        model.range_max_m = Some(MAX_RANGE_M);
        model.fifo_bytes = MAX_FIFO_BYTES;
        model.validate().unwrap();
    }

    #[test]
    fn unknown_preset_lists_the_presets() {
        let message = Model::preset("s200").unwrap_err().to_string();
        assert!(message.contains("s100, s2cr-burst"), "{message}");
    }
}
