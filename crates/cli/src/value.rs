//! Value parsers for numeric flags: every number a tool accepts is finite, has a sign, and has a
//! maximum that no real campaign reaches, and a value outside says so with its unit:
//! `expected 1 ms ..= 10 min, found 1e-9`.
//!
//! Each constructor returns a parser that clap takes as `value_parser = ...`; the same parsers
//! serve list elements ([`list`]) and points ([`point3`]), and [`check`] applies a range to a
//! number that came from elsewhere (a default computed at run time, a file).

use std::fmt;

/// The longest session any tool runs, in seconds: a week of virtual or real time.
pub const WEEK_S: f64 = 7.0 * 24.0 * 3600.0;
/// The largest count any tool accepts (packets, scans, frames): 10^9.
pub const MAX_COUNT: u64 = 1_000_000_000;
/// The largest distance from a site's origin any position may have, metres (100 km).
pub const MAX_POSITION_M: f64 = 100_000.0;

/// How a quantity is printed in messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unit {
    /// Milliseconds, printed as ms, s, min, h or d, whichever reads best.
    Millis,
    /// Seconds, printed as ms, s, min, h or d.
    Seconds,
    /// A bare number.
    Plain,
    /// A number followed by this unit text (`"m"`, `"bit/s"`, `"%"`).
    Named(&'static str),
}

impl Unit {
    /// `value` with its unit, as a person would write it.
    pub fn show(self, value: f64) -> String {
        match self {
            Unit::Millis => show_time_s(value / 1000.0),
            Unit::Seconds => show_time_s(value),
            Unit::Plain => show_number(value),
            Unit::Named(unit) => format!("{} {unit}", show_number(value)),
        }
    }
}

/// A short decimal form: integers without a fraction, others with up to six significant
/// digits, very large or small values in exponent form.
fn show_number(value: f64) -> String {
    if value == value.trunc() && value.abs() < 1e15 {
        format!("{value:.0}")
    } else if value != 0.0 && !(1e-4..1e15).contains(&value.abs()) {
        format!("{value:e}")
    } else {
        let text = format!("{value:.6}");
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

fn show_time_s(seconds: f64) -> String {
    const STEPS: [(f64, &str); 4] = [(86_400.0, "d"), (3600.0, "h"), (60.0, "min"), (1.0, "s")];
    if seconds == 0.0 {
        return "0 s".into();
    }
    for (size, unit) in STEPS {
        if seconds.abs() >= size && (seconds / size).fract().abs() < 1e-9 {
            return format!("{} {unit}", show_number(seconds / size));
        }
    }
    if seconds.abs() >= 1.0 {
        return format!("{} s", show_number(seconds));
    }
    format!("{} ms", show_number(seconds * 1000.0))
}

/// One end of a range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bound {
    /// The value itself is allowed.
    Incl(f64),
    /// Only values beyond it are allowed.
    Excl(f64),
}

/// A range of real numbers with a unit, the check every real-valued flag gets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// The lower end.
    pub min: Bound,
    /// The upper end (always inclusive).
    pub max: f64,
    /// How values are printed.
    pub unit: Unit,
}

impl fmt::Display for Range {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.min {
            Bound::Incl(min) => write!(
                f,
                "{} ..= {}",
                self.unit.show(min),
                self.unit.show(self.max)
            ),
            Bound::Excl(min) => write!(
                f,
                "more than {}, up to {}",
                self.unit.show(min),
                self.unit.show(self.max)
            ),
        }
    }
}

impl Range {
    /// Checks `value`: `Err("expected 1 ms ..= 10 min, found 1e-9")` when outside.
    pub fn check(&self, value: f64) -> Result<f64, String> {
        self.check_as(value, &show_found(value))
    }

    fn check_as(&self, value: f64, found: &str) -> Result<f64, String> {
        let above_min = match self.min {
            Bound::Incl(min) => value >= min,
            Bound::Excl(min) => value > min,
        };
        if value.is_finite() && above_min && value <= self.max {
            Ok(value)
        } else {
            Err(format!("expected {self}, found {found}"))
        }
    }

    /// Parses and checks a number written by a user.
    pub fn parse(&self, text: &str) -> Result<f64, String> {
        let value: f64 = text
            .trim()
            .parse()
            .map_err(|_| format!("expected a number ({self}), found `{text}`"))?;
        self.check_as(value, text.trim())
    }
}

fn show_found(value: f64) -> String {
    if value.is_nan() {
        "NaN".into()
    } else if value.is_infinite() {
        format!("{value}")
    } else {
        show_number(value)
    }
}

/// A parser of a real number in `range` (a clap `value_parser`).
#[derive(Debug, Clone, Copy)]
pub struct RealParser(pub Range);

impl clap::builder::TypedValueParser for RealParser {
    type Value = f64;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<f64, clap::Error> {
        let range = self.0;
        delegate(move |text: &str| range.parse(text), cmd, arg, value)
    }
}

/// Runs `parse` as clap's own closure parsers run: a failure is clap's "invalid value" error
/// with the reason as its source, which [`crate::one_line`] prints as `--flag: reason`.
fn delegate<T, F>(
    parse: F,
    cmd: &clap::Command,
    arg: Option<&clap::Arg>,
    value: &std::ffi::OsStr,
) -> Result<T, clap::Error>
where
    T: Clone + Send + Sync + 'static,
    F: Fn(&str) -> Result<T, String> + Clone + Send + Sync + 'static,
{
    clap::builder::TypedValueParser::parse_ref(&parse, cmd, arg, value)
}

/// Milliseconds in `min_ms ..= max_ms`.
pub fn millis(min_ms: f64, max_ms: f64) -> RealParser {
    RealParser(Range {
        min: Bound::Incl(min_ms),
        max: max_ms,
        unit: Unit::Millis,
    })
}

/// Seconds in `min_s ..= max_s`.
pub fn seconds(min_s: f64, max_s: f64) -> RealParser {
    RealParser(Range {
        min: Bound::Incl(min_s),
        max: max_s,
        unit: Unit::Seconds,
    })
}

/// A real number in `min ..= max`, printed with `unit` (`""` for none).
pub fn real(min: f64, max: f64, unit: &'static str) -> RealParser {
    RealParser(Range {
        min: Bound::Incl(min),
        max,
        unit: named(unit),
    })
}

/// A real number above 0, up to `max`, printed with `unit`.
pub fn positive(max: f64, unit: &'static str) -> RealParser {
    RealParser(Range {
        min: Bound::Excl(0.0),
        max,
        unit: named(unit),
    })
}

/// A probability, 0 ..= 1.
pub fn probability() -> RealParser {
    real(0.0, 1.0, "")
}

/// A percentage, 0 ..= 100.
pub fn percent() -> RealParser {
    real(0.0, 100.0, "%")
}

fn named(unit: &'static str) -> Unit {
    if unit.is_empty() {
        Unit::Plain
    } else {
        Unit::Named(unit)
    }
}

/// A parser of a whole number in `min ..= max` (a clap `value_parser`).
#[derive(Debug, Clone, Copy)]
pub struct CountParser {
    /// The smallest value allowed.
    pub min: u64,
    /// The largest value allowed.
    pub max: u64,
    /// The unit printed after the bounds (`""` for none).
    pub unit: &'static str,
}

impl CountParser {
    /// Parses and checks a whole number written by a user.
    pub fn parse(&self, text: &str) -> Result<u64, String> {
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        let expected = format!("{} ..= {}{unit}", self.min, self.max);
        let trimmed = text.trim();
        match trimmed.parse::<u64>() {
            Ok(value) if (self.min..=self.max).contains(&value) => Ok(value),
            Ok(_) => Err(format!("expected {expected}, found {trimmed}")),
            Err(_) if trimmed.parse::<f64>().is_ok() || trimmed.parse::<i128>().is_ok() => Err(
                format!("expected a whole number {expected}, found {trimmed}"),
            ),
            Err(_) => Err(format!(
                "expected a whole number {expected}, found `{text}`"
            )),
        }
    }
}

impl clap::builder::TypedValueParser for CountParser {
    type Value = u64;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<u64, clap::Error> {
        let this = *self;
        delegate(move |text: &str| this.parse(text), cmd, arg, value)
    }
}

/// A whole number in `min ..= max`.
pub fn count(min: u64, max: u64) -> CountParser {
    CountParser { min, max, unit: "" }
}

/// A number of bytes in `min ..= max`.
pub fn bytes(min: u64, max: u64) -> CountParser {
    CountParser {
        min,
        max,
        unit: "bytes",
    }
}

/// What a list element is parsed with: a range of reals or of whole numbers.
pub trait Item: Copy + Send + Sync + 'static {
    /// The parsed value.
    type Value: Clone + Send + Sync + 'static;
    /// Parses and checks one element.
    fn parse_item(&self, text: &str) -> Result<Self::Value, String>;
}

impl Item for Range {
    type Value = f64;
    fn parse_item(&self, text: &str) -> Result<f64, String> {
        self.parse(text)
    }
}

impl Item for CountParser {
    type Value = u64;
    fn parse_item(&self, text: &str) -> Result<u64, String> {
        self.parse(text)
    }
}

/// A serial port's baud rate, 50 ..= 4000000.
pub fn baud() -> clap::builder::MapValueParser<CountParser, fn(u64) -> u32> {
    fn narrow(value: u64) -> u32 {
        u32::try_from(value).unwrap_or(u32::MAX)
    }
    clap::builder::TypedValueParser::map(
        CountParser {
            min: 50,
            max: 4_000_000,
            unit: "baud",
        },
        narrow as fn(u64) -> u32,
    )
}

/// A device in the one grammar ([`rovlink_link::device::DeviceSpec`]), kept as the text given (the
/// tool opens it later): a device flag's error says what was expected and what was found.
pub fn device(text: &str) -> Result<String, rovlink_link::device::DeviceSpecError> {
    text.parse::<rovlink_link::device::DeviceSpec>()
        .map(|_| text.to_string())
}

/// A comma-separated list, each element checked by `item`, 1 ..= `max_len` of them.
#[derive(Debug, Clone, Copy)]
pub struct ListParser<I> {
    /// How each element is checked.
    pub item: I,
    /// The most elements allowed.
    pub max_len: usize,
}

impl<I: Item> ListParser<I> {
    /// Parses and checks a list written by a user.
    pub fn parse(&self, text: &str) -> Result<Vec<I::Value>, String> {
        split_list(text, self.max_len)?
            .iter()
            .enumerate()
            .map(|(i, part)| {
                self.item
                    .parse_item(part)
                    .map_err(|e| format!("element {}: {e}", i + 1))
            })
            .collect()
    }
}

fn split_list(text: &str, max_len: usize) -> Result<Vec<&str>, String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if text.trim().is_empty() || parts.iter().any(|p| p.is_empty()) {
        return Err(format!(
            "expected a comma-separated list of 1 ..= {max_len} values, found `{text}`"
        ));
    }
    if parts.len() > max_len {
        return Err(format!(
            "expected at most {max_len} values, found {}",
            parts.len()
        ));
    }
    Ok(parts)
}

impl<I: Item> clap::builder::TypedValueParser for ListParser<I> {
    type Value = Vec<I::Value>;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<Vec<I::Value>, clap::Error> {
        let this = *self;
        delegate(move |text: &str| this.parse(text), cmd, arg, value)
    }
}

/// A comma list of reals in `item`'s range; for example `list(seconds(0.0, WEEK_S), 1000)`.
pub fn list(item: RealParser, max_len: usize) -> ListParser<Range> {
    ListParser {
        item: item.0,
        max_len,
    }
}

/// A comma list of whole numbers in `item`'s range.
pub fn count_list(item: CountParser, max_len: usize) -> ListParser<CountParser> {
    ListParser { item, max_len }
}

/// A parser of exactly `N` comma-separated reals, each in one range (points, boxes).
#[derive(Debug, Clone, Copy)]
pub struct TupleParser<const N: usize>(pub Range);

impl<const N: usize> TupleParser<N> {
    /// Parses and checks `N` numbers written by a user.
    pub fn parse(&self, text: &str) -> Result<[f64; N], String> {
        let parts: Vec<&str> = text.split(',').collect();
        if parts.len() != N {
            return Err(format!(
                "expected {N} comma-separated numbers, found {} in `{text}`",
                parts.len()
            ));
        }
        let mut out = [0.0; N];
        for (i, part) in parts.iter().enumerate() {
            out[i] = self
                .0
                .parse(part)
                .map_err(|e| format!("number {}: {e}", i + 1))?;
        }
        Ok(out)
    }
}

impl<const N: usize> clap::builder::TypedValueParser for TupleParser<N> {
    type Value = [f64; N];

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<[f64; N], clap::Error> {
        let this = *self;
        delegate(move |text: &str| this.parse(text), cmd, arg, value)
    }
}

/// A point `X,Y,Z` in metres, each coordinate within ±[`MAX_POSITION_M`].
pub fn point3() -> TupleParser<3> {
    TupleParser(Range {
        min: Bound::Incl(-MAX_POSITION_M),
        max: MAX_POSITION_M,
        unit: Unit::Named("m"),
    })
}

/// `N` comma-separated reals each in `item`'s range (a box is `tuple::<6>(...)`).
pub fn tuple<const N: usize>(item: RealParser) -> TupleParser<N> {
    TupleParser(item.0)
}

/// A parser of a pixel rectangle `x0,y0,x1,y1` (whole pixels, `x0 < x1 <= max_px`,
/// `y0 < y1 <= max_px`), as `[x0, y0, x1, y1]`.
#[derive(Debug, Clone, Copy)]
pub struct RectParser {
    /// The largest coordinate allowed, pixels.
    pub max_px: u64,
}

impl RectParser {
    /// Parses and checks a rectangle written by a user.
    pub fn parse(&self, text: &str) -> Result<[u64; 4], String> {
        let expected = || {
            format!(
                "expected whole pixels x0,y0,x1,y1 with x0 < x1 <= {0} and y0 < y1 <= {0}, found `{text}`",
                self.max_px
            )
        };
        let parts: Vec<&str> = text.split(',').map(str::trim).collect();
        let numbers: Vec<u64> = parts
            .iter()
            .map(|p| p.parse::<u64>())
            .collect::<Result<_, _>>()
            .map_err(|_| expected())?;
        match numbers[..] {
            [x0, y0, x1, y1] if x0 < x1 && y0 < y1 && x1 <= self.max_px && y1 <= self.max_px => {
                Ok([x0, y0, x1, y1])
            }
            _ => Err(expected()),
        }
    }
}

impl clap::builder::TypedValueParser for RectParser {
    type Value = [u64; 4];

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<[u64; 4], clap::Error> {
        let this = *self;
        delegate(move |text: &str| this.parse(text), cmd, arg, value)
    }
}

/// A pixel rectangle `x0,y0,x1,y1` with coordinates up to `max_px`.
pub fn rect(max_px: u64) -> RectParser {
    RectParser { max_px }
}

/// Checks a number that did not come through a parser: `Err("--ipg: expected ..., found ...")`.
pub fn check(flag: &str, value: f64, parser: RealParser) -> Result<f64, rovlink_base::UsageError> {
    parser
        .0
        .check(value)
        .map_err(|e| rovlink_base::UsageError(format!("{flag}: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_carry_units_and_the_value_found() {
        let ipg = millis(1.0, 600_000.0);
        assert_eq!(
            ipg.0.parse("1e-9").unwrap_err(),
            "expected 1 ms ..= 10 min, found 1e-9"
        );
        assert_eq!(ipg.0.parse("640").unwrap(), 640.0);
        assert_eq!(
            seconds(0.0, WEEK_S).0.parse("inf").unwrap_err(),
            "expected 0 s ..= 7 d, found inf"
        );
        assert_eq!(
            positive(1e9, "bit/s").0.parse("0").unwrap_err(),
            "expected more than 0 bit/s, up to 1000000000 bit/s, found 0"
        );
        assert!(
            probability()
                .0
                .parse("NaN")
                .unwrap_err()
                .ends_with("found NaN")
        );
        assert!(percent().0.parse("x").unwrap_err().contains("found `x`"));
        assert_eq!(
            seconds(0.5, 90.0).0.check(0.25).unwrap_err(),
            "expected 500 ms ..= 90 s, found 0.25"
        );
    }

    #[test]
    fn counts_refuse_fractions_signs_and_overflow() {
        let c = count(1, MAX_COUNT);
        assert_eq!(c.parse("2000").unwrap(), 2000);
        assert!(c.parse("0").unwrap_err().contains("1 ..= 1000000000"));
        assert!(c.parse("-3").unwrap_err().contains("whole number"));
        assert!(c.parse("1.5").unwrap_err().contains("whole number"));
        assert!(
            c.parse("18446744073709551616")
                .unwrap_err()
                .contains("whole number")
        );
        assert!(c.parse("4294967296").is_err());
    }

    #[test]
    fn lists_and_points() {
        let l = list(real(0.0, 1.0, ""), 3);
        assert_eq!(l.parse("0, 0.5,1").unwrap(), vec![0.0, 0.5, 1.0]);
        assert!(l.parse("0,,1").is_err());
        assert!(l.parse("0,0,0,0").unwrap_err().contains("at most 3"));
        assert!(l.parse("0,2").unwrap_err().starts_with("element 2"));
        assert_eq!(point3().parse("1,-2,3").unwrap(), [1.0, -2.0, 3.0]);
        assert!(
            point3()
                .parse("1e300,0,0")
                .unwrap_err()
                .contains("number 1")
        );
        assert!(point3().parse("1,2").is_err());
        assert_eq!(rect(100).parse("1, 2,30,40").unwrap(), [1, 2, 30, 40]);
        for bad in ["3,2,1,4", "1,2,3", "0,0,101,5", "0,0,1.5,4", "-1,0,2,2", ""] {
            assert!(rect(100).parse(bad).is_err(), "{bad}");
        }
    }
}
