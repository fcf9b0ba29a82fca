//! What a link run reports: the trace (one row per frame), the counters of both directions,
//! the summary lines and the `--stats` JSON.
//!
//! The trace's columns are `seq,bytes,t_offered_s,t_tx_start_s,t_rx_s,fate`, and in real time,
//! where both sides send, a last column `side` (the sender). Times are seconds from the start of
//! the run with nine decimals (the link's nanoseconds); a time that does not apply (a frame
//! that never went on air, or never arrived) is empty. A duplicated frame has a second row with
//! the same `seq`.
//!
//! Memory does not grow with the run: the counters are sums and Welford's running figures
//! ([`rovlink_base::stats::Running`]).

use serde::Serialize;
use serde::ser::SerializeStruct;

use super::channel::{DirectionStats, Link, Report, Side};
use super::model::Model;
use super::realtime::RunInfo;
use super::sched::SimTime;
use rovlink_base::stats::Quantiles;

/// The trace's columns in real time (both directions: the sending side is the last column).
pub const TRACE_COLUMNS_SIDES: [&str; 7] = [
    "seq",
    "bytes",
    "t_offered_s",
    "t_tx_start_s",
    "t_rx_s",
    "fate",
    "side",
];

/// The trace's columns in the pipe (one direction, A to B): all but `side`.
pub const TRACE_COLUMNS: &[&str] = TRACE_COLUMNS_SIDES.split_at(6).0;

/// How a run was driven, for the summary and the stats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Frames from a byte stream, in virtual time.
    Pipe,
    /// Two ports, in real time.
    RealTime,
}

impl Mode {
    /// The name the summary and the stats use: `pipe` or `real time`.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Pipe => "pipe",
            Mode::RealTime => "real time",
        }
    }

    /// The trace's columns in this mode.
    pub fn trace_columns(self) -> &'static [&'static str] {
        match self {
            Mode::Pipe => TRACE_COLUMNS,
            Mode::RealTime => &TRACE_COLUMNS_SIDES,
        }
    }
}

/// One row of the trace, borrowed from a report; serialises with the columns of
/// [`Mode::trace_columns`] (times as text with nine decimals).
#[derive(Debug, Clone, Copy)]
pub struct TraceRow<'a> {
    report: &'a Report,
    with_side: bool,
}

impl<'a> TraceRow<'a> {
    /// The row of `report` in a trace of `mode`.
    pub fn new(report: &'a Report, mode: Mode) -> TraceRow<'a> {
        TraceRow {
            report,
            with_side: mode == Mode::RealTime,
        }
    }
}

/// A time as the trace writes it: seconds with nine decimals, empty when absent.
fn seconds(t: Option<SimTime>) -> String {
    t.map_or(String::new(), |t| format!("{:.9}", t.as_secs_f64()))
}

impl Serialize for TraceRow<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let r = self.report;
        let mut row = serializer.serialize_struct("TraceRow", 6 + usize::from(self.with_side))?;
        row.serialize_field("seq", &r.seq)?;
        row.serialize_field("bytes", &r.len)?;
        row.serialize_field("t_offered_s", &seconds(Some(r.t_offered)))?;
        row.serialize_field("t_tx_start_s", &seconds(r.t_tx_start))?;
        row.serialize_field("t_rx_s", &seconds(r.t_rx))?;
        row.serialize_field("fate", r.fate.as_str())?;
        if self.with_side {
            row.serialize_field("side", r.from.name())?;
        }
        row.end()
    }
}

/// What a run reports: its `--stats` document and its summary, one line each.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// The `--stats` document.
    pub stats: serde_json::Value,
    /// The summary lines, for stderr.
    pub lines: Vec<String>,
}

/// The counters of both directions of a run.
#[derive(Debug, Clone, Default)]
pub struct Counters {
    /// A to B, then B to A.
    pub directions: [DirectionStats; 2],
}

/// What the summary and the stats say about a run besides the counters.
#[derive(Debug, Clone, Copy)]
pub struct RunFacts<'a> {
    /// How it was driven.
    pub mode: Mode,
    /// The seed of its random streams.
    pub seed: u64,
    /// Link time at the end, s.
    pub duration_s: f64,
    /// Why it ended early (`interrupted by SIGTERM`), when it did.
    pub interrupted: Option<&'a str>,
}

impl Counters {
    /// Counts a report in its direction.
    pub fn record(&mut self, report: &Report) {
        self.directions[report.from.index()].record(report);
    }

    /// The summary of a run, one line each: the models, the seed and the link time, each
    /// direction that carried frames (both in real time), frames still in flight, and why the
    /// run was cut short.
    pub fn summary_lines(&self, facts: &RunFacts<'_>, link: &Link) -> Vec<String> {
        let (forward, reverse) = (link.model(Side::A), link.model(Side::B));
        let models = if forward == reverse {
            format!("model {}", model_name(forward))
        } else {
            format!(
                "models {} (A->B), {} (B->A)",
                model_name(forward),
                model_name(reverse)
            )
        };
        let mut lines = vec![format!(
            "{}: {models}, seed {}, {:.3} s of link time",
            facts.mode.name(),
            facts.seed,
            facts.duration_s
        )];
        for (side, stats) in [Side::A, Side::B].iter().zip(&self.directions) {
            if stats.frames_offered > 0 || facts.mode == Mode::RealTime {
                lines.push(stats.summary_line(&format!(
                    "{}->{}",
                    side.name(),
                    side.other().name()
                )));
            }
        }
        if link.in_flight() > 0 {
            lines.push(format!(
                "{} frames still in flight when the run ended",
                link.in_flight()
            ));
        }
        if let Some(note) = facts.interrupted {
            lines.push(format!("{note}: the figures cover the run until then"));
        }
        lines
    }

    /// The summary and the `--stats` document of a run on `link` (in real time, with the ports'
    /// figures `info`, whose lines follow the counters').
    pub fn summary(&self, facts: &RunFacts<'_>, link: &Link, info: Option<&RunInfo>) -> Summary {
        let mut lines = self.summary_lines(facts, link);
        lines.extend(info.map(real_time_lines).unwrap_or_default());
        Summary {
            stats: self.stats_json(facts, link, info),
            lines,
        }
    }

    /// The `--stats` document: mode, seed, duration, both directions' counters, frames in
    /// flight, both models, `interrupted` (null, or why), and in real time the ports' figures.
    pub fn stats_json(
        &self,
        facts: &RunFacts<'_>,
        link: &Link,
        info: Option<&RunInfo>,
    ) -> serde_json::Value {
        let mut json = serde_json::json!({
            "mode": facts.mode.name(),
            "seed": facts.seed,
            "duration_s": facts.duration_s,
            "interrupted": facts.interrupted,
            "a_to_b": self.directions[0].to_json(),
            "b_to_a": self.directions[1].to_json(),
            "in_flight_at_end": link.in_flight(),
            "model_a_to_b": link.model(Side::A),
            "model_b_to_a": link.model(Side::B),
        });
        if let Some(info) = info {
            json["real_time"] = serde_json::json!({
                "bytes_read": {"a": info.bytes_read[0], "b": info.bytes_read[1]},
                "bytes_skipped": {"a": info.bytes_skipped[0], "b": info.bytes_skipped[1]},
                "foreign_datagrams_dropped": {
                    "a": info.foreign_datagrams_dropped[0],
                    "b": info.foreign_datagrams_dropped[1],
                },
                "deliveries_not_taken": {"a": info.not_taken[0], "b": info.not_taken[1]},
                "delivery_lateness_ms_p50": info.lateness_quantile_ms(0.5),
                "delivery_lateness_ms_p99": info.lateness_quantile_ms(0.99),
                "delivery_lateness_ms_max": info.lateness_quantile_ms(1.0),
            });
        }
        json
    }
}

/// What a real-time run's summary adds: the delivery lateness and the deliveries a side did
/// not take, one line each.
pub fn real_time_lines(info: &RunInfo) -> Vec<String> {
    port_lines(&info.lateness, &info.not_taken, &["A", "B"])
}

/// [`real_time_lines`] for any number of ports: the delivery lateness, then each port (named
/// by `labels`, in order) whose program did not take deliveries.
pub fn port_lines(lateness: &Quantiles, not_taken: &[u64], labels: &[&str]) -> Vec<String> {
    let mut lines = Vec::new();
    if let (Some(p50), Some(p99)) = (lateness.quantile_ms(0.5), lateness.quantile_ms(0.99)) {
        lines.push(format!(
            "deliveries handed to the port {p50:.3} ms (median), {p99:.3} ms (p99) after their model time"
        ));
    }
    for (label, &count) in labels.iter().zip(not_taken) {
        if count > 0 {
            lines.push(format!(
                "side {label}: {count} deliveries not taken (its program was not reading)"
            ));
        }
    }
    lines
}

/// A model's name for the summary (`(unnamed)` when it has none).
pub fn model_name(model: &Model) -> String {
    if model.name.is_empty() {
        "(unnamed)".into()
    } else {
        model.name.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipe::{self, Pace};
    use crate::{Distance, Fate};
    use std::sync::atomic::AtomicBool;

    fn report(fate: Fate, t_rx: Option<u64>, from: Side) -> Report {
        Report {
            from,
            to: from.other(),
            seq: 7,
            len: 57,
            t_offered: SimTime(1_500_000_000),
            t_tx_start: Some(SimTime(1_585_000_000)),
            t_rx: t_rx.map(SimTime),
            fate,
            duplicate: false,
            bytes: Vec::new(),
        }
    }

    #[test]
    fn trace_rows_have_nine_decimals_and_empty_absent_times() {
        let csv_line = |row: TraceRow<'_>| {
            let mut csv = csv::WriterBuilder::new()
                .has_headers(false)
                .from_writer(Vec::new());
            csv.serialize(row).unwrap();
            String::from_utf8(csv.into_inner().unwrap()).unwrap()
        };
        let delivered = report(Fate::Delivered, Some(1_825_000_001), Side::A);
        assert_eq!(
            csv_line(TraceRow::new(&delivered, Mode::Pipe)),
            "7,57,1.500000000,1.585000000,1.825000001,delivered\n"
        );
        let lost = report(Fate::Range, None, Side::B);
        assert_eq!(
            csv_line(TraceRow::new(&lost, Mode::RealTime)),
            "7,57,1.500000000,1.585000000,,range,B\n"
        );
        let json = serde_json::to_value(TraceRow::new(&lost, Mode::RealTime)).unwrap();
        let keys: Vec<&str> = json.as_object().unwrap().keys().map(|k| &k[..]).collect();
        assert_eq!(keys, TRACE_COLUMNS_SIDES);
        assert_eq!(json["t_rx_s"], "");
    }

    #[test]
    fn counters_summarise_a_pipe_run() {
        let model = Model::preset("s100").unwrap();
        let mut link = Link::symmetric(model, 1, Distance::Fixed(1.0)).unwrap();
        let mut counters = Counters::default();
        let mut sent = 0;
        pipe::run::<()>(
            &mut link,
            Pace::BackToBack,
            &AtomicBool::new(false),
            |_| {
                sent += 1;
                Ok((sent <= 20).then(|| vec![0; 57]))
            },
            |r| {
                counters.record(&r);
                Ok(())
            },
        )
        .unwrap();
        let facts = RunFacts {
            mode: Mode::Pipe,
            seed: 1,
            duration_s: link.now().as_secs_f64(),
            interrupted: Some("interrupted by SIGTERM"),
        };
        let lines = counters.summary_lines(&facts, &link);
        assert!(
            lines[0].starts_with("pipe: model s100, seed 1, "),
            "{lines:?}"
        );
        assert!(lines[1].starts_with("A->B: 20 frames offered, 20 delivered"));
        assert_eq!(lines.len(), 3, "B->A carried nothing: {lines:?}");
        assert!(lines[2].starts_with("interrupted by SIGTERM"));
        let json = counters.stats_json(&facts, &link, None);
        assert_eq!(json["a_to_b"]["frames_delivered"], 20);
        assert_eq!(json["interrupted"], "interrupted by SIGTERM");
        assert_eq!(json["model_a_to_b"]["name"], "s100");
    }
}
