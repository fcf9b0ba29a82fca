//! Modem characterisation: probe packets, one row per packet, and the figures of the paper's
//! Table 3 computed from the rows.
//!
//! A probe is a wire.md link frame of exactly the requested size (header and CRC included)
//! whose payload starts with the probe's sequence number (u32, big endian) and its send time in
//! microseconds (u48, big endian), then filler. The receiver finds the sequence number in what
//! arrives; the send time lets a receiver on another host compute a delay without the sender's
//! log.
//!
//! A [`Tally`] takes the rows as they come and gives the [`Summary`]: the delay statistics,
//! RFC 3550's interarrival jitter, the inter-arrival times and throughput, and, over a sweep of
//! packet sizes, a least-squares fit of delay on size: `delay = intrinsic + size x 8 / bitrate`,
//! the way Table 3's bit rate and intrinsic delay were obtained. Its memory does not grow with
//! the number of rows: counts, mean and standard deviation are exact (Welford), the delay
//! quantiles come from a fixed-size sketch and are within 0.1 % of the exact nearest-rank
//! quantile, or 1 µs when that is larger ([`rovlink_base::stats::Quantiles`]).
//!
//! Campaigns run in real time over modems ([`live`]) or in virtual time over a link model
//! ([`sim`]); both hand each row over as soon as it is known and stop at a flag.
//!
//! Parsing a received probe never panics: anything that is not a probe is `None`.

pub mod live;
pub mod sim;

use serde::Serialize;

use crate::model::{JitterDistribution, Model};
use std::collections::BTreeMap;

use rovlink_base::stats::{Quantiles, Running};
use rovlink_wire::frame::{self, Frame, OVERHEAD_BYTES};

/// Bytes of the probe header inside the payload: sequence number and send time.
pub const PROBE_HEADER_BYTES: usize = 10;

/// The smallest probe: frame overhead plus the probe header.
pub const MIN_PROBE_BYTES: usize = OVERHEAD_BYTES + PROBE_HEADER_BYTES;

/// The largest probe: a frame with 255 payload bytes.
pub const MAX_PROBE_BYTES: usize = OVERHEAD_BYTES + 255;

/// Builds probe `seq` of `size` bytes (a whole link frame), sent at `t_tx_us` microseconds.
/// `None` when the size is outside [`MIN_PROBE_BYTES`]..=[`MAX_PROBE_BYTES`].
pub fn probe(seq: u32, size: usize, t_tx_us: u64) -> Option<Vec<u8>> {
    if !(MIN_PROBE_BYTES..=MAX_PROBE_BYTES).contains(&size) {
        return None;
    }
    let mut payload = Vec::with_capacity(size - OVERHEAD_BYTES);
    payload.extend_from_slice(&seq.to_be_bytes());
    payload.extend_from_slice(&(t_tx_us & 0xFFFF_FFFF_FFFF).to_be_bytes()[2..]);
    // Filler that differs between probes, so a corrupted probe is unlikely to look intact.
    payload.extend(
        (0..size - OVERHEAD_BYTES - PROBE_HEADER_BYTES).map(|k| (seq as usize * 13 + k * 7) as u8),
    );
    frame::build(1, 2, &payload).ok()
}

/// What a received probe says about itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProbeInfo {
    /// Its sequence number.
    pub seq: u32,
    /// Its send time, microseconds (48 bits).
    pub t_tx_us: u64,
    /// Its length, bytes.
    pub size: usize,
}

/// Reads a probe from a received frame; `None` when the bytes are not an intact probe.
pub fn read_probe(bytes: &[u8]) -> Option<ProbeInfo> {
    let frame = Frame::new_checked(bytes).ok()?;
    frame.check().ok()?;
    let payload = frame.payload();
    if payload.len() < PROBE_HEADER_BYTES {
        return None;
    }
    let seq = u32::from_be_bytes(payload[..4].try_into().ok()?);
    let mut time = [0u8; 8];
    time[2..].copy_from_slice(&payload[4..10]);
    Some(ProbeInfo {
        seq,
        t_tx_us: u64::from_be_bytes(time),
        size: frame.total_len(),
    })
}

/// The most probes a campaign sends: sequence numbers are 32 bits.
pub const MAX_PROBES: u64 = 1 << 32;

/// A campaign that cannot be run as asked.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// A probe size outside what a probe can be.
    #[error(
        "--size/--sizes: {0} bytes is outside {MIN_PROBE_BYTES}..={MAX_PROBE_BYTES} (a frame with the probe's sequence number and send time)"
    )]
    Size(usize),
    /// No size, or no packet per size.
    #[error("--count: expected at least 1 packet per size")]
    Empty,
    /// More probes than sequence numbers.
    #[error(
        "--count x --sizes: {0} probes in all, more than the 4294967296 that 32-bit sequence numbers tell apart"
    )]
    TooMany(u64),
    /// A simulated campaign longer than virtual time holds.
    #[error(
        "the campaign would last about {years:.0} years of virtual time (at most 100): fewer --count, a shorter --interval or a faster model"
    )]
    TooLong {
        /// Its estimated length, years.
        years: f64,
    },
}

/// Checks a campaign's sizes and count; returns the number of probes in all.
pub fn probe_total(sizes: &[usize], count_per_size: u32) -> Result<u64, PlanError> {
    if let Some(&bad) = sizes
        .iter()
        .find(|s| !(MIN_PROBE_BYTES..=MAX_PROBE_BYTES).contains(*s))
    {
        return Err(PlanError::Size(bad));
    }
    let total = sizes.len() as u64 * u64::from(count_per_size);
    match total {
        0 => Err(PlanError::Empty),
        t if t > MAX_PROBES => Err(PlanError::TooMany(t)),
        t => Ok(t),
    }
}

/// One packet of a campaign: the row of `packets.csv`.
///
/// It serialises with the columns of [`ROW_COLUMNS`], times rounded to the microsecond (the
/// resolution of a probe's send time) and delays to the microsecond too.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Sequence number, from 0 across the whole campaign.
    pub seq: u32,
    /// Bytes written to the modem.
    pub size_bytes: usize,
    /// Send time, seconds from the start.
    pub t_tx_s: f64,
    /// Arrival time, seconds from the start (none when lost).
    pub t_rx_s: Option<f64>,
    /// Arrival minus send time, ms (none when lost).
    pub delay_ms: Option<f64>,
    /// True when it arrived (intact or not).
    pub delivered: bool,
    /// True when it arrived with errors.
    pub corrupted: bool,
}

/// The columns of [`Row`], in order: the header of `packets.csv`.
pub const ROW_COLUMNS: [&str; 7] = [
    "seq",
    "size_bytes",
    "t_tx_s",
    "t_rx_s",
    "delay_ms",
    "delivered",
    "corrupted",
];

/// `value` rounded to `per_unit`ths.
fn rounded(value: f64, per_unit: f64) -> f64 {
    (value * per_unit).round() / per_unit
}

impl Serialize for Row {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut row = serializer.serialize_struct("Row", ROW_COLUMNS.len())?;
        row.serialize_field("seq", &self.seq)?;
        row.serialize_field("size_bytes", &self.size_bytes)?;
        row.serialize_field("t_tx_s", &rounded(self.t_tx_s, 1e6))?;
        row.serialize_field("t_rx_s", &self.t_rx_s.map(|t| rounded(t, 1e6)))?;
        row.serialize_field("delay_ms", &self.delay_ms.map(|d| rounded(d, 1e3)))?;
        row.serialize_field("delivered", &self.delivered)?;
        row.serialize_field("corrupted", &self.corrupted)?;
        row.end()
    }
}

/// Least-squares fit of delay on packet size: `delay_ms = intercept + slope x size_bytes`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// Delay at zero bytes, ms: the intrinsic delay (plus propagation).
    pub intercept_ms: f64,
    /// ms per byte.
    pub slope_ms_per_byte: f64,
    /// Standard deviation of the points around the line, ms (n - 2 degrees of freedom): the
    /// delay's jitter once the size is accounted for, Table 3's "intrinsic jitter".
    pub residual_std_ms: f64,
}

impl Fit {
    /// Fits `(size_bytes, delay_ms)` points; none with fewer than two distinct sizes.
    pub fn from_points(points: impl IntoIterator<Item = (f64, f64)>) -> Option<Fit> {
        let mut groups: BTreeMap<u64, (f64, Running)> = BTreeMap::new();
        for (x, y) in points {
            groups
                .entry(x.to_bits())
                .or_insert((x, Running::new()))
                .1
                .push(y);
        }
        Fit::from_groups(groups.values().map(|(x, ys)| (*x, ys)))
    }

    /// Fits points given as groups of equal size: each size with the running figures of its
    /// delays. The same line as the fit of every point, in memory for the groups only, and
    /// without the cancellation of raw sums of squares.
    pub fn from_groups<'a>(
        groups: impl IntoIterator<Item = (f64, &'a Running)> + Clone,
    ) -> Option<Fit> {
        let (mut n, mut sum_x, mut sum_y) = (0.0, 0.0, 0.0);
        for (x, ys) in groups.clone() {
            let count = ys.count() as f64;
            n += count;
            sum_x += count * x;
            sum_y += count * ys.mean();
        }
        if n < 2.0 {
            return None;
        }
        let (mean_x, mean_y) = (sum_x / n, sum_y / n);
        let (mut sxx, mut sxy, mut sum_x2) = (0.0, 0.0, 0.0);
        for (x, ys) in groups.clone() {
            let count = ys.count() as f64;
            sxx += count * (x - mean_x).powi(2);
            sxy += count * (x - mean_x) * (ys.mean() - mean_y);
            sum_x2 += count * x * x;
        }
        if sxx <= 1e-9 * sum_x2.max(1.0) {
            return None;
        }
        let slope = sxy / sxx;
        let intercept = mean_y - slope * mean_x;
        let squares: f64 = groups
            .into_iter()
            .map(|(x, ys)| {
                ys.sum_squared_deviations()
                    + ys.count() as f64 * (ys.mean() - intercept - slope * x).powi(2)
            })
            .sum();
        Some(Fit {
            intercept_ms: intercept,
            slope_ms_per_byte: slope,
            residual_std_ms: if n > 2.0 {
                (squares / (n - 2.0)).sqrt()
            } else {
                0.0
            },
        })
    }

    /// The bit rate the slope means, bit/s (none when the slope is not positive).
    pub fn bitrate_bps(&self) -> Option<f64> {
        (self.slope_ms_per_byte > 0.0).then(|| 8000.0 / self.slope_ms_per_byte)
    }
}

/// The figures of a campaign (`--summary`): Table 3's columns and more.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Packets sent.
    pub count: u64,
    /// Packets that arrived.
    pub delivered: u64,
    /// Packets that arrived corrupted.
    pub corrupted: u64,
    /// 1 - delivered / count.
    pub loss_ratio: f64,
    /// Mean delay, ms.
    pub delay_ms_mean: Option<f64>,
    /// Median delay, ms (nearest rank, from a sketch: within 0.1 % or 1 µs).
    pub delay_ms_p50: Option<f64>,
    /// 99th percentile of the delay, ms (as the median).
    pub delay_ms_p99: Option<f64>,
    /// Standard deviation of the delay, ms (the paper's jitter).
    pub jitter_ms: Option<f64>,
    /// RFC 3550's interarrival jitter estimate at the end of the run, ms.
    pub jitter_rfc3550_ms: Option<f64>,
    /// Mean time between consecutive arrivals, ms.
    pub iat_ms_mean: Option<f64>,
    /// Standard deviation of the time between arrivals, ms.
    pub iat_ms_std: Option<f64>,
    /// Bits of the packets that arrived per second, from the first send to the last arrival.
    pub throughput_bps: Option<f64>,
    /// Bit rate from the fit of delay on size (needs two sizes or more).
    pub fit_bitrate_bps: Option<f64>,
    /// Intrinsic delay from the fit, ms.
    pub fit_intrinsic_delay_ms: Option<f64>,
    /// Standard deviation of the delays around the fit, ms: the jitter with the size's share
    /// taken out (equal to `jitter_ms` for a single size, up to n - 2 against n - 1).
    pub fit_jitter_ms: Option<f64>,
    /// Per size: packets, delivered, mean delay, jitter.
    pub sizes: Vec<SizeSummary>,
    /// Why the campaign ended early (`interrupted by SIGINT`): the figures cover the packets
    /// up to then. None for a campaign that ran to its end.
    pub interrupted: Option<String>,
}

/// The figures of one packet size.
#[derive(Debug, Clone, Serialize)]
pub struct SizeSummary {
    /// Packet size, bytes.
    pub size_bytes: usize,
    /// Packets sent.
    pub count: u64,
    /// Packets that arrived.
    pub delivered: u64,
    /// Mean delay, ms.
    pub delay_ms_mean: Option<f64>,
    /// Standard deviation of the delay, ms.
    pub jitter_ms: Option<f64>,
}

/// The figures of one packet size while rows come in.
#[derive(Debug, Clone, Default)]
struct SizeTally {
    count: u64,
    delivered: u64,
    delay: Running,
}

/// A campaign's figures accumulated one row at a time, in memory that does not grow with the
/// number of rows: counters, Welford's running mean and standard deviation ([`Running`]), a
/// fixed-size quantile sketch ([`Quantiles`]: within 0.1 % or 1 µs) and one tally per packet
/// size (at most 246 sizes: [`MIN_PROBE_BYTES`]..=[`MAX_PROBE_BYTES`]).
///
/// Rows of delivered packets are expected in arrival order, the order both campaigns
/// ([`live::run`], [`sim::run`]) hand them over: RFC 3550's jitter and the inter-arrival times
/// follow that order.
#[derive(Debug, Clone, Default)]
pub struct Tally {
    count: u64,
    delivered: u64,
    corrupted: u64,
    delay: Running,
    delay_quantiles: Quantiles,
    rfc_jitter_ms: f64,
    last_arrival: Option<(f64, f64)>,
    iat_ms: Running,
    first_tx_s: Option<f64>,
    last_rx_s: Option<f64>,
    bits_delivered: f64,
    sizes: BTreeMap<usize, SizeTally>,
}

impl Tally {
    /// No rows yet.
    pub fn new() -> Tally {
        Tally::default()
    }

    /// Counts a row.
    pub fn push(&mut self, row: &Row) {
        self.count += 1;
        self.first_tx_s = Some(self.first_tx_s.map_or(row.t_tx_s, |t| t.min(row.t_tx_s)));
        let size = self.sizes.entry(row.size_bytes).or_default();
        size.count += 1;
        if !row.delivered {
            return;
        }
        self.delivered += 1;
        size.delivered += 1;
        self.corrupted += u64::from(row.corrupted);
        self.bits_delivered += row.size_bytes as f64 * 8.0;
        if let Some(delay) = row.delay_ms {
            self.delay.push(delay);
            self.delay_quantiles.push_ms(delay);
            size.delay.push(delay);
        }
        if let Some(t_rx) = row.t_rx_s {
            // RFC 3550 A.8: J += (|D(i-1, i)| - J) / 16 over packets in arrival order.
            let transit = row.delay_ms.unwrap_or(0.0);
            if let Some((last_rx, last_transit)) = self.last_arrival {
                self.rfc_jitter_ms += ((transit - last_transit).abs() - self.rfc_jitter_ms) / 16.0;
                self.iat_ms.push((t_rx - last_rx) * 1e3);
            }
            self.last_arrival = Some((t_rx, transit));
            self.last_rx_s = Some(self.last_rx_s.map_or(t_rx, |t| t.max(t_rx)));
        }
    }

    /// Rows counted.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Bytes the tally holds: the same after ten rows as after a billion (the per-size
    /// tallies aside, one per distinct size).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Tally>()
            + self.delay_quantiles.cells() * std::mem::size_of::<u64>()
            + self.sizes.len() * (std::mem::size_of::<(usize, SizeTally)>() + 16)
    }

    /// The figures of the rows so far.
    pub fn summary(&self) -> Summary {
        let count = self.count;
        let delay = &self.delay;
        let fit = Fit::from_groups(
            self.sizes
                .iter()
                .filter(|(_, s)| s.delay.count() > 0)
                .map(|(&size, s)| (size as f64, &s.delay)),
        );
        let throughput_bps = match (self.first_tx_s, self.last_rx_s) {
            (Some(first), Some(last)) if last > first => Some(self.bits_delivered / (last - first)),
            _ => None,
        };
        let sizes = self
            .sizes
            .iter()
            .map(|(&size, s)| SizeSummary {
                size_bytes: size,
                count: s.count,
                delivered: s.delivered,
                delay_ms_mean: (s.delay.count() > 0).then(|| s.delay.mean()),
                jitter_ms: (s.delay.count() > 1).then(|| s.delay.std()),
            })
            .collect();
        Summary {
            count,
            delivered: self.delivered,
            corrupted: self.corrupted,
            loss_ratio: if count == 0 {
                0.0
            } else {
                1.0 - self.delivered as f64 / count as f64
            },
            delay_ms_mean: (delay.count() > 0).then(|| delay.mean()),
            delay_ms_p50: self.delay_quantiles.quantile_ms(0.5),
            delay_ms_p99: self.delay_quantiles.quantile_ms(0.99),
            jitter_ms: (delay.count() > 1).then(|| delay.std()),
            jitter_rfc3550_ms: (self.iat_ms.count() > 0).then_some(self.rfc_jitter_ms),
            iat_ms_mean: (self.iat_ms.count() > 0).then(|| self.iat_ms.mean()),
            iat_ms_std: (self.iat_ms.count() > 1).then(|| self.iat_ms.std()),
            throughput_bps,
            fit_bitrate_bps: fit.and_then(|f| f.bitrate_bps()),
            fit_intrinsic_delay_ms: fit.map(|f| f.intercept_ms),
            fit_jitter_ms: fit.map(|f| f.residual_std_ms),
            sizes,
            interrupted: None,
        }
    }
}

impl Summary {
    /// The figures of rows in any order (delivered ones are taken in arrival order).
    pub fn from_rows(rows: &[Row]) -> Summary {
        let mut by_arrival: Vec<&Row> = rows.iter().collect();
        by_arrival.sort_by(|a, b| {
            let key = |r: &Row| r.t_rx_s.unwrap_or(f64::INFINITY);
            key(a).total_cmp(&key(b))
        });
        let mut tally = Tally::new();
        by_arrival.into_iter().for_each(|row| tally.push(row));
        tally.summary()
    }

    /// The summary for people, one line each: counts and loss, delay figures, inter-arrival
    /// times and throughput, the fit, each size of a sweep, and why the run ended early.
    pub fn lines(&self) -> Vec<String> {
        let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
        let mut lines = vec![
            format!(
                "{} packets, {} delivered ({} corrupted), loss ratio {:.4}",
                self.count, self.delivered, self.corrupted, self.loss_ratio
            ),
            format!(
                "delay ms: mean {}  p50 {}  p99 {}  jitter (std) {}  RFC 3550 jitter {}",
                ms(self.delay_ms_mean),
                ms(self.delay_ms_p50),
                ms(self.delay_ms_p99),
                ms(self.jitter_ms),
                ms(self.jitter_rfc3550_ms)
            ),
            format!(
                "inter-arrival ms: mean {}  std {};  throughput {} bit/s",
                ms(self.iat_ms_mean),
                ms(self.iat_ms_std),
                ms(self.throughput_bps)
            ),
        ];
        if let (Some(rate), Some(intrinsic)) = (self.fit_bitrate_bps, self.fit_intrinsic_delay_ms) {
            lines.push(format!(
                "fit of delay on size: bit rate {rate:.1} bit/s, intrinsic delay {intrinsic:.2} ms, jitter around the fit {} ms",
                ms(self.fit_jitter_ms)
            ));
        }
        if self.sizes.len() > 1 {
            lines.extend(self.sizes.iter().map(|size| {
                format!(
                    "  {:>4} bytes: {} sent, {} delivered, delay {} ms, jitter {} ms",
                    size.size_bytes,
                    size.count,
                    size.delivered,
                    ms(size.delay_ms_mean),
                    ms(size.jitter_ms)
                )
            }));
        }
        if let Some(note) = &self.interrupted {
            lines.push(format!("{note}: the figures cover the packets until then"));
        }
        lines
    }

    /// The jitter to put in a model: the mean of the per-size standard deviations (the delay's
    /// spread around each size's own mean, so the size sweep itself does not count as jitter).
    pub fn jitter_within_sizes_ms(&self) -> Option<f64> {
        let spreads: Vec<f64> = self.sizes.iter().filter_map(|s| s.jitter_ms).collect();
        (!spreads.is_empty()).then(|| spreads.iter().sum::<f64>() / spreads.len() as f64)
    }

    /// A link model from the measurement: the fitted bit rate and intrinsic delay (or, with one
    /// size, the mean delay less the air time at `assumed_bitrate_bps`), normal jitter with the
    /// spread around the fit (or within the size), and the observed loss as a bit error rate
    /// for the mean size.
    pub fn to_model(&self, name: &str, assumed_bitrate_bps: f64) -> Option<Model> {
        let (bitrate_bps, intrinsic_delay_ms) =
            match (self.fit_bitrate_bps, self.fit_intrinsic_delay_ms) {
                (Some(rate), Some(intrinsic)) => (rate, intrinsic.max(0.0)),
                _ => {
                    let size = self.sizes.first()?;
                    let mean = size.delay_ms_mean?;
                    let air_ms = size.size_bytes as f64 * 8.0 / assumed_bitrate_bps * 1e3;
                    (assumed_bitrate_bps, (mean - air_ms).max(0.0))
                }
            };
        let mean_bits = {
            let (bytes, n) = self.sizes.iter().fold((0.0, 0.0), |(b, n), s| {
                (b + s.size_bytes as f64 * s.count as f64, n + s.count as f64)
            });
            if n > 0.0 { bytes * 8.0 / n } else { 0.0 }
        };
        // Packet error rate p = 1 - (1 - ber)^bits, so ber = 1 - (1 - p)^(1 / bits).
        let ber = if mean_bits > 0.0 && self.loss_ratio > 0.0 {
            (1.0 - (1.0 - self.loss_ratio.min(0.999_999)).powf(1.0 / mean_bits)).min(0.5)
        } else {
            0.0
        };
        let mut model = Model::preset("s100").ok()?;
        model.name = name.to_string();
        model.description = format!(
            "fitted by modem-bench from {} packets ({} delivered)",
            self.count, self.delivered
        );
        model.bitrate_bps = bitrate_bps;
        model.intrinsic_delay_ms = intrinsic_delay_ms;
        model.jitter_distribution = JitterDistribution::Normal;
        model.jitter_ms = self
            .fit_jitter_ms
            .or_else(|| self.jitter_within_sizes_ms())
            .unwrap_or(0.0);
        model.propagation_ms_per_m = 0.0;
        model.range_min_m = 0.0;
        model.range_max_m = None;
        model.ber = ber;
        model.fifo_bytes = 65_536;
        model.validate().ok()?;
        Some(model)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn probes_carry_their_number_time_and_size() {
        for size in [MIN_PROBE_BYTES, 16, 57, 100, MAX_PROBE_BYTES] {
            let bytes = probe(70_000, size, 0x1234_5678_9abc).unwrap();
            assert_eq!(bytes.len(), size);
            let info = read_probe(&bytes).unwrap();
            assert_eq!(
                info,
                ProbeInfo {
                    seq: 70_000,
                    t_tx_us: 0x1234_5678_9abc,
                    size
                }
            );
        }
        assert!(probe(0, MIN_PROBE_BYTES - 1, 0).is_none());
        assert!(probe(0, MAX_PROBE_BYTES + 1, 0).is_none());
        let mut damaged = probe(3, 57, 9).unwrap();
        damaged[20] ^= 1;
        assert!(read_probe(&damaged).is_none());
        assert!(read_probe(&[0x55]).is_none());
    }

    #[test]
    fn the_fit_recovers_a_line() {
        let points = (0..30).map(|k| {
            let size = [16.0, 57.0, 100.0][k % 3];
            (size, 85.0 + size * 8.0 / 1900.0 * 1e3)
        });
        let fit = Fit::from_points(points).unwrap();
        assert!((fit.intercept_ms - 85.0).abs() < 1e-9);
        assert!((fit.bitrate_bps().unwrap() - 1900.0).abs() < 1e-6);
        assert!(fit.residual_std_ms < 1e-9);
        assert!(Fit::from_points([(57.0, 300.0), (57.0, 310.0)]).is_none());
    }

    fn row(seq: u32, size: usize, t_tx: f64, delay_ms: Option<f64>) -> Row {
        Row {
            seq,
            size_bytes: size,
            t_tx_s: t_tx,
            t_rx_s: delay_ms.map(|d| t_tx + d / 1e3),
            delay_ms,
            delivered: delay_ms.is_some(),
            corrupted: false,
        }
    }

    #[test]
    fn summary_figures() {
        let rows = vec![
            row(0, 57, 0.0, Some(320.0)),
            row(1, 57, 1.0, Some(330.0)),
            row(2, 57, 2.0, None),
            row(3, 57, 3.0, Some(325.0)),
        ];
        let s = Summary::from_rows(&rows);
        assert_eq!((s.count, s.delivered), (4, 3));
        assert!((s.loss_ratio - 0.25).abs() < 1e-12);
        assert!((s.delay_ms_mean.unwrap() - 325.0).abs() < 1e-9);
        // From the sketch: within 0.1 %.
        assert!((s.delay_ms_p50.unwrap() / 325.0 - 1.0).abs() < 1e-3);
        assert!(s.interrupted.is_none());
        assert!((s.jitter_ms.unwrap() - 5.0).abs() < 1e-9);
        // Arrivals at 0.320, 1.330, 3.325 s.
        assert!((s.iat_ms_mean.unwrap() - 1502.5).abs() < 1e-6);
        // J = 10/16 = 0.625, then += (5 - 0.625) / 16.
        assert!((s.jitter_rfc3550_ms.unwrap() - (0.625 + 4.375 / 16.0)).abs() < 1e-9);
        assert!((s.throughput_bps.unwrap() - 3.0 * 456.0 / 3.325).abs() < 1e-6);
        assert_eq!(s.fit_bitrate_bps, None);
    }

    #[test]
    fn the_tally_keeps_no_row_and_matches_exact_figures() {
        // Issue 14: modem-bench --sim kept every row for its summary (4.5 MB/s).
        let mut tally = Tally::new();
        let mut exact = Running::new();
        let mut delays = Vec::new();
        let mut after_thousand = 0;
        for k in 0..1_000_000u32 {
            let size = [16usize, 57, 100][k as usize % 3];
            let delay = 85.0 + size as f64 * 4.2 + f64::from(k % 1000) * 0.37;
            let lost = k % 7 == 0;
            let row = row(k, size, f64::from(k) * 0.3, (!lost).then_some(delay));
            tally.push(&row);
            if !lost {
                exact.push(delay);
                delays.push(delay);
            }
            if k == 999 {
                after_thousand = tally.memory_bytes();
            }
        }
        assert_eq!(
            tally.memory_bytes(),
            after_thousand,
            "memory grew with the rows"
        );
        assert!(after_thousand < 300 * 1024, "{after_thousand} bytes");
        let s = tally.summary();
        assert_eq!(s.count, 1_000_000);
        assert_eq!(s.delivered, exact.count());
        assert!((s.delay_ms_mean.unwrap() - exact.mean()).abs() < 1e-9);
        assert!((s.jitter_ms.unwrap() - exact.std()).abs() < 1e-9);
        delays.sort_by(f64::total_cmp);
        for (q, sketched) in [(0.5, s.delay_ms_p50), (0.99, s.delay_ms_p99)] {
            let exact = rovlink_base::stats::quantile_sorted(&delays, q).unwrap();
            let sketched = sketched.unwrap();
            assert!(
                (sketched - exact).abs() <= exact * 1e-3,
                "{q}: {sketched} against {exact}"
            );
        }
        // The grouped fit is the least-squares line of every point, computed in two passes.
        let points: Vec<(f64, f64)> = (0..1_000_000u32)
            .filter(|k| k % 7 != 0)
            .map(|k| {
                let size = [16usize, 57, 100][k as usize % 3];
                (
                    size as f64,
                    85.0 + size as f64 * 4.2 + f64::from(k % 1000) * 0.37,
                )
            })
            .collect();
        let n = points.len() as f64;
        let mean_x = points.iter().map(|p| p.0).sum::<f64>() / n;
        let mean_y = points.iter().map(|p| p.1).sum::<f64>() / n;
        let sxx: f64 = points.iter().map(|p| (p.0 - mean_x).powi(2)).sum();
        let sxy: f64 = points.iter().map(|p| (p.0 - mean_x) * (p.1 - mean_y)).sum();
        let slope = sxy / sxx;
        let intercept = mean_y - slope * mean_x;
        let residual: f64 = points
            .iter()
            .map(|p| (p.1 - intercept - slope * p.0).powi(2))
            .sum();
        let residual_std = (residual / (n - 2.0)).sqrt();
        assert!((s.fit_intrinsic_delay_ms.unwrap() - intercept).abs() < 1e-6);
        assert!((s.fit_bitrate_bps.unwrap() - 8000.0 / slope).abs() < 1e-6);
        assert!((s.fit_jitter_ms.unwrap() - residual_std).abs() < 1e-6);
    }

    #[test]
    fn rows_serialise_rounded_to_the_microsecond() {
        let row = Row {
            seq: 3,
            size_bytes: 57,
            t_tx_s: 0.240_000_000_4,
            t_rx_s: Some(0.565_000_000_4),
            delay_ms: Some(325.000_000_4),
            delivered: true,
            corrupted: false,
        };
        let json = serde_json::to_value(&row).unwrap();
        let keys: Vec<&str> = json.as_object().unwrap().keys().map(|k| &k[..]).collect();
        assert_eq!(keys, ROW_COLUMNS);
        assert_eq!(json["t_tx_s"], 0.24);
        assert_eq!(json["delay_ms"], 325.0);
        let lost = Row {
            t_rx_s: None,
            delay_ms: None,
            delivered: false,
            ..row
        };
        assert!(serde_json::to_value(&lost).unwrap()["t_rx_s"].is_null());
    }

    #[test]
    fn plans_are_checked() {
        assert_eq!(probe_total(&[16, 57], 10).unwrap(), 20);
        let message = probe_total(&[10], 5).unwrap_err().to_string();
        assert!(
            message.contains("10 bytes is outside 15..=260"),
            "{message}"
        );
        assert!(matches!(probe_total(&[57], 0), Err(PlanError::Empty)));
        assert!(matches!(
            probe_total(&[16; 5], 1_000_000_000),
            Err(PlanError::TooMany(_))
        ));
    }

    #[test]
    fn a_model_from_a_measurement() {
        let mut rows = Vec::new();
        for k in 0..300u32 {
            let size = [16usize, 57, 100][k as usize % 3];
            let wobble = if (k / 3) % 2 == 0 { 10.0 } else { -10.0 };
            let delay = 85.0 + size as f64 * 8.0 / 1900.0 * 1e3 + wobble;
            rows.push(row(k, size, k as f64, (k % 10 != 0).then_some(delay)));
        }
        let s = Summary::from_rows(&rows);
        let model = s.to_model("fitted", 1900.0).unwrap();
        assert!(
            (model.bitrate_bps - 1900.0).abs() < 1.0,
            "{}",
            model.bitrate_bps
        );
        assert!((model.intrinsic_delay_ms - 85.0).abs() < 1.0);
        assert!((model.jitter_ms - 10.0).abs() < 0.2, "{}", model.jitter_ms);
        // 10 % of packets of 57.67 bytes on average lost.
        assert!((model.packet_error_rate(57) - 0.1).abs() < 0.01);
    }
}
