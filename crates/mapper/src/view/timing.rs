//! When each scene update is logged: one message every scan period, or at the `t_shown_s` of
//! the arrivals file's rows, checked against the stream message by message.

use super::arrivals_csv::{arrivals_error, read_arrivals};
use super::{MAX_TIME_S, ViewError};
use crate::pipeline::{self, ConfigError};
use rovlink_octo::delta::{Framed, Message};

/// When each message is logged.
#[derive(Debug, Clone, Copy)]
pub enum Timing<'a> {
    /// Message k at `k x` this many seconds.
    Period(f64),
    /// At the `t_shown_s` of an arrivals file's rows.
    Arrivals {
        /// The file's bytes.
        text: &'a [u8],
        /// Its name, for errors.
        name: &'a str,
    },
}

impl<'a> Timing<'a> {
    /// The timing of an arrivals file (its bytes and name, as [`pipeline::read_input`] gives
    /// them) when there is one, else one message every `period_s` seconds.
    pub fn new(arrivals: Option<&'a (Vec<u8>, String)>, period_s: f64) -> Self {
        match arrivals {
            Some((text, name)) => Timing::Arrivals { text, name },
            None => Timing::Period(period_s),
        }
    }
}

/// The log time of each of the first `count` messages of `msgs`, ns.
pub fn log_times_ns(
    msgs: &[Framed],
    count: usize,
    timing: Timing<'_>,
) -> Result<Vec<u64>, ViewError> {
    let count = count.min(msgs.len());
    let ns = |t_s: f64| (t_s * 1e9).round() as u64;
    match timing {
        Timing::Period(period_s) => {
            pipeline::check_scan_period(period_s)?;
            let last_s = count.saturating_sub(1) as f64 * period_s;
            if last_s > MAX_TIME_S {
                return Err(ConfigError {
                    option: "--scan-period",
                    expected: format!("message {} logged within {MAX_TIME_S:e} s", count - 1),
                    found: format!("{period_s} s x {} = {last_s:e} s", count - 1),
                }
                .into());
            }
            Ok((0..count).map(|k| ns(k as f64 * period_s)).collect())
        }
        Timing::Arrivals { text, name } => {
            let bad = |source| ViewError::Arrivals {
                name: name.to_string(),
                source,
            };
            let rows = read_arrivals(text).map_err(bad)?;
            if rows.len() > msgs.len() {
                let line = rows[msgs.len()].line;
                return Err(bad(arrivals_error(
                    line,
                    "row",
                    format!(
                        "the stream has {} messages, this is row {}",
                        msgs.len(),
                        msgs.len() + 1
                    ),
                )));
            }
            if rows.len() < count {
                let scan = match &msgs[rows.len()].message {
                    Message::Delta { scan, .. }
                    | Message::Full { scan, .. }
                    | Message::Region { scan, .. } => *scan,
                };
                return Err(bad(arrivals_error(
                    rows.last().map_or(1, |r| r.line) + 1,
                    "scan",
                    format!(
                        "expected a row for message {} (scan {scan}), found the end of the file (to view only the {} messages that arrived: --messages {})",
                        rows.len(),
                        rows.len(),
                        rows.len()
                    ),
                )));
            }
            let mut out = Vec::with_capacity(count);
            for (k, (row, m)) in rows.iter().zip(msgs).take(count).enumerate() {
                let scan = match &m.message {
                    Message::Delta { scan, .. }
                    | Message::Full { scan, .. }
                    | Message::Region { scan, .. } => *scan,
                };
                if row.scan != scan {
                    return Err(bad(arrivals_error(
                        row.line,
                        "scan",
                        format!(
                            "expected {scan} (message {k} of the stream), found {}",
                            row.scan
                        ),
                    )));
                }
                if row.bytes != m.bytes {
                    return Err(bad(arrivals_error(
                        row.line,
                        "bytes",
                        format!(
                            "expected {} (message {k}'s size in the stream), found {}",
                            m.bytes, row.bytes
                        ),
                    )));
                }
                out.push(ns(row.t_shown_s));
            }
            Ok(out)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::HEADER;
    use super::*;
    use rovlink_octo::delta::Delta;

    fn framed(scans: &[(u32, usize)]) -> Vec<Framed> {
        scans
            .iter()
            .map(|&(scan, bytes)| Framed {
                offset: 0,
                bytes,
                message: Message::Delta {
                    scan,
                    delta: Delta::default(),
                },
            })
            .collect()
    }

    #[test]
    fn log_times_follow_the_arrivals_or_the_period() {
        let msgs = framed(&[(0, 89), (1, 94), (2, 50)]);
        let at = |text: &str, count| {
            log_times_ns(
                &msgs,
                count,
                Timing::Arrivals {
                    text: text.as_bytes(),
                    name: "a.csv",
                },
            )
            .map_err(|e| e.to_string())
        };
        let two = format!("{HEADER}0,89,0,0.31,0.31,0.31\n1,94,1,1.5,1.5,0.5\n");
        assert_eq!(at(&two, 2), Ok(vec![310_000_000, 1_500_000_000]));
        assert_eq!(
            at(&two, usize::MAX),
            Err("a.csv: line 4, column scan: expected a row for message 2 (scan 2), found the end of the file (to view only the 2 messages that arrived: --messages 2)".into())
        );
        let wrong = format!("{HEADER}0,89,0,0.31,0.31,0.31\n2,94,1,1.5,1.5,0.5\n");
        assert_eq!(
            at(&wrong, 2),
            Err("a.csv: line 3, column scan: expected 1 (message 1 of the stream), found 2".into())
        );
        let size = format!("{HEADER}0,90,0,0.31,0.31,0.31\n");
        assert_eq!(
            at(&size, 1),
            Err("a.csv: line 2, column bytes: expected 89 (message 0's size in the stream), found 90".into())
        );
        let four = format!("{two}2,50,2,2,2,0\n3,50,3,3,3,0\n");
        assert_eq!(
            at(&four, 1),
            Err("a.csv: line 5, column row: the stream has 3 messages, this is row 4".into())
        );
        let period = |p, n| log_times_ns(&msgs, n, Timing::Period(p)).map_err(|e| e.to_string());
        assert_eq!(period(0.5, 9), Ok(vec![0, 500_000_000, 1_000_000_000]));
        assert!(period(-1.0, 9).unwrap_err().starts_with("--scan-period"));
        let many = framed(&vec![(0, 1); 20_000]);
        let err = log_times_ns(&many, usize::MAX, Timing::Period(86_400.0)).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("--scan-period: expected message 19999 logged within 1e9 s"),
            "{err}"
        );
    }
}
