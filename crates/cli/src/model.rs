//! The link-model flags every tool that runs a link shares (`link-sim`, `modem-bench`,
//! `tdma-run`): a preset or a file, then any field overridden. Each override flag is the model
//! file's JSON field with dashes, range-checked with its unit before the run starts; the
//! model as a whole is then checked by [`Model::validate`].

use std::path::PathBuf;

use crate::value;
use rovlink_link::model::{
    ErrorMode, GilbertElliott, JitterDistribution, MAX_BER, MAX_BITRATE_BPS, MAX_DELAY_MS,
    MAX_FIFO_BYTES, MAX_PROPAGATION_MS_PER_M, MAX_RANGE_M, MIN_BITRATE_BPS, parse_gilbert_elliott,
};
use rovlink_link::{Model, ModelError};

/// `--jitter-distribution`'s values: a [`JitterDistribution`] as a flag (clap's traits live
/// in this crate, the link model's types in `rovlink-link`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JitterFlag(pub JitterDistribution);

/// `--errors`' values: an [`ErrorMode`] as a flag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorsFlag(pub ErrorMode);

impl clap::ValueEnum for JitterFlag {
    fn value_variants<'a>() -> &'a [Self] {
        &[
            JitterFlag(JitterDistribution::None),
            JitterFlag(JitterDistribution::Uniform),
            JitterFlag(JitterDistribution::Normal),
            JitterFlag(JitterDistribution::Laplace),
        ]
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(match self.0 {
            JitterDistribution::None => "none",
            JitterDistribution::Uniform => "uniform",
            JitterDistribution::Normal => "normal",
            JitterDistribution::Laplace => "laplace",
        }))
    }
}

impl clap::ValueEnum for ErrorsFlag {
    fn value_variants<'a>() -> &'a [Self] {
        &[ErrorsFlag(ErrorMode::Drop), ErrorsFlag(ErrorMode::Corrupt)]
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(match self.0 {
            ErrorMode::Drop => "drop",
            ErrorMode::Corrupt => "corrupt",
        }))
    }
}

/// The model flags every tool that runs a link shares: a preset or a file, then any field
/// overridden. Each override flag is the JSON field's name with dashes.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ModelArgs {
    /// Built-in model: s100, s2cr-burst, s2cr-ack, satellite-up, satellite-down [default: s100].
    #[arg(
        long,
        value_name = "NAME",
        conflicts_with = "model_file",
        help_heading = "Link model"
    )]
    pub model: Option<String>,
    /// Model file (JSON; `--print-model NAME` prints one to start from).
    #[arg(long, value_name = "FILE", help_heading = "Link model")]
    pub model_file: Option<PathBuf>,
    /// Bit rate on the air, bit/s.
    #[arg(long, value_parser = value::real(MIN_BITRATE_BPS, MAX_BITRATE_BPS, "bit/s"), value_name = "BPS", help_heading = "Link model")]
    pub bitrate_bps: Option<f64>,
    /// Intrinsic (processing) delay before transmission, ms.
    #[arg(long, value_parser = value::millis(0.0, MAX_DELAY_MS), value_name = "MS", help_heading = "Link model")]
    pub intrinsic_delay_ms: Option<f64>,
    /// Shape of the delay jitter.
    #[arg(long, value_enum, value_name = "SHAPE", help_heading = "Link model")]
    pub jitter_distribution: Option<JitterFlag>,
    /// Standard deviation of the delay jitter, ms.
    #[arg(long, value_parser = value::millis(0.0, MAX_DELAY_MS), value_name = "MS", help_heading = "Link model")]
    pub jitter_ms: Option<f64>,
    /// Propagation delay at zero distance, ms.
    #[arg(long, value_parser = value::millis(0.0, MAX_DELAY_MS), value_name = "MS", help_heading = "Link model")]
    pub propagation_min_ms: Option<f64>,
    /// Propagation delay per metre, ms/m.
    #[arg(long, value_parser = value::real(0.0, MAX_PROPAGATION_MS_PER_M, "ms/m"), value_name = "MS_PER_M", help_heading = "Link model")]
    pub propagation_ms_per_m: Option<f64>,
    /// Nearest distance at which frames are heard, m.
    #[arg(long, value_parser = value::real(0.0, MAX_RANGE_M, "m"), value_name = "M", help_heading = "Link model")]
    pub range_min_m: Option<f64>,
    /// Farthest distance at which frames are heard, m.
    #[arg(long, value_parser = value::real(0.0, MAX_RANGE_M, "m"), value_name = "M", help_heading = "Link model")]
    pub range_max_m: Option<f64>,
    /// Bit error rate, e.g. 7e-4.
    #[arg(long, value_parser = value::real(0.0, MAX_BER, ""), value_name = "P", help_heading = "Link model")]
    pub ber: Option<f64>,
    /// What a frame with bit errors becomes: dropped, or delivered with the bits flipped.
    #[arg(long, value_enum, value_name = "MODE", help_heading = "Link model")]
    pub errors: Option<ErrorsFlag>,
    /// Half duplex (a modem cannot hear while it transmits): true or false.
    #[arg(long, value_name = "BOOL", help_heading = "Link model")]
    pub half_duplex: Option<bool>,
    /// Transmit FIFO capacity, bytes.
    #[arg(long, value_parser = value::bytes(1, MAX_FIFO_BYTES), value_name = "BYTES", help_heading = "Link model")]
    pub fifo_bytes: Option<u64>,
    /// Let jitter reorder frames.
    #[arg(long, help_heading = "Link model")]
    pub reorder: bool,
    /// Random loss, percent.
    #[arg(long, value_parser = value::percent(), value_name = "PCT", help_heading = "Link model")]
    pub loss_percent: Option<f64>,
    /// Gilbert-Elliott burst loss, percent: P,R[,BAD[,GOOD]] as netem's gemodel.
    #[arg(long, value_name = "P,R[,BAD[,GOOD]]", value_parser = parse_gilbert_elliott, help_heading = "Link model")]
    pub gilbert_elliott: Option<GilbertElliott>,
    /// Corruption (one bit flipped), percent.
    #[arg(long, value_parser = value::percent(), value_name = "PCT", help_heading = "Link model")]
    pub corrupt_percent: Option<f64>,
    /// Duplication, percent.
    #[arg(long, value_parser = value::percent(), value_name = "PCT", help_heading = "Link model")]
    pub duplicate_percent: Option<f64>,
    /// Rate limit, bit/s (netem's rate; applies when below the bit rate).
    #[arg(long, value_parser = value::real(MIN_BITRATE_BPS, MAX_BITRATE_BPS, "bit/s"), value_name = "BPS", help_heading = "Link model")]
    pub rate_limit_bps: Option<f64>,
}

impl ModelArgs {
    /// The model the flags describe: the preset or file, with every given field overridden,
    /// checked.
    pub fn resolve(&self) -> Result<Model, ModelError> {
        let mut model = match (&self.model_file, &self.model) {
            (Some(path), _) => Model::from_file(path)?,
            (None, Some(name)) => Model::preset(name)?,
            (None, None) => Model::preset("s100")?,
        };
        self.apply(&mut model);
        model.validate()?;
        Ok(model)
    }

    /// Overrides the fields given on the command line.
    pub fn apply(&self, model: &mut Model) {
        fn set<T: Clone>(target: &mut T, value: &Option<T>) {
            if let Some(value) = value {
                *target = value.clone();
            }
        }
        set(&mut model.bitrate_bps, &self.bitrate_bps);
        set(&mut model.intrinsic_delay_ms, &self.intrinsic_delay_ms);
        set(
            &mut model.jitter_distribution,
            &self.jitter_distribution.map(|f| f.0),
        );
        set(&mut model.jitter_ms, &self.jitter_ms);
        set(&mut model.propagation_min_ms, &self.propagation_min_ms);
        set(&mut model.propagation_ms_per_m, &self.propagation_ms_per_m);
        set(&mut model.range_min_m, &self.range_min_m);
        if self.range_max_m.is_some() {
            model.range_max_m = self.range_max_m;
        }
        set(&mut model.ber, &self.ber);
        set(&mut model.errors, &self.errors.map(|f| f.0));
        set(&mut model.half_duplex, &self.half_duplex);
        set(&mut model.fifo_bytes, &self.fifo_bytes);
        model.reorder |= self.reorder;
        set(&mut model.loss_percent, &self.loss_percent);
        if self.gilbert_elliott.is_some() {
            model.gilbert_elliott = self.gilbert_elliott;
        }
        set(&mut model.corrupt_percent, &self.corrupt_percent);
        set(&mut model.duplicate_percent, &self.duplicate_percent);
        if self.rate_limit_bps.is_some() {
            model.rate_limit_bps = self.rate_limit_bps;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn command_line_overrides_every_field_it_names() {
        let args = ModelArgs {
            model: Some("s2cr-burst".into()),
            ber: Some(1e-3),
            reorder: true,
            gilbert_elliott: Some(parse_gilbert_elliott("1,30").unwrap()),
            range_max_m: Some(100.0),
            ..ModelArgs::default()
        };
        let model = args.resolve().unwrap();
        assert_eq!(model.ber, 1e-3);
        assert!(model.reorder);
        assert_eq!(model.range_max_m, Some(100.0));
        let ge = model.gilbert_elliott.unwrap();
        assert_eq!(
            (ge.p_percent, ge.r_percent, ge.loss_bad_percent),
            (1.0, 30.0, 100.0)
        );
        assert!(parse_gilbert_elliott("1").is_err());
        assert!(parse_gilbert_elliott("1,x").is_err());
    }

    #[derive(Parser)]
    struct Tool {
        #[command(flatten)]
        model: ModelArgs,
    }

    #[test]
    fn flags_out_of_range_are_refused_with_their_unit() {
        for (flag, value, expected) in [
            (
                "--bitrate-bps",
                "1e-300",
                "expected 1 bit/s ..= 10000000000 bit/s, found 1e-300",
            ),
            ("--jitter-ms", "1e300", "expected 0 s ..= 1 h, found 1e300"),
            ("--ber", "NaN", "found NaN"),
            (
                "--fifo-bytes",
                "0",
                "expected 1 ..= 67108864 bytes, found 0",
            ),
        ] {
            let err = Tool::try_parse_from(["tool", flag, value])
                .err()
                .unwrap()
                .to_string();
            assert!(err.contains(expected), "{flag} {value}: {err}");
        }
    }
}
