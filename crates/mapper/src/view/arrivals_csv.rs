//! The arrivals CSV (`build --link ... --arrivals`), read strictly for the view: one row per
//! stream message, with when the operator's view showed it.

use super::MAX_TIME_S;
use crate::pipeline::ARRIVAL_COLUMNS;

/// One row of an arrivals file as the view needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArrivalTime {
    /// Line of the row in the file, from 1 (the header is line 1).
    pub line: u64,
    /// Scan number.
    pub scan: u32,
    /// Message bytes.
    pub bytes: usize,
    /// When the operator's view showed it, s.
    pub t_shown_s: f64,
}

/// What is wrong in an arrivals file: where (line, column) and what.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}, column {column}: {message}")]
pub struct ArrivalsError {
    /// Line, from 1.
    pub line: u64,
    /// Column name (or `header`, `row`).
    pub column: String,
    /// Expected vs found.
    pub message: String,
}

pub(super) fn arrivals_error(line: u64, column: &str, message: impl Into<String>) -> ArrivalsError {
    ArrivalsError {
        line,
        column: column.to_string(),
        message: message.into(),
    }
}

/// Reads the CSV `build --arrivals` writes: the header exactly [`ARRIVAL_COLUMNS`], then rows
/// of six fields: whole numbers, times in seconds within 0 ..= [`MAX_TIME_S`] with
/// `t_ready_s <= t_complete_s <= t_shown_s` and `t_shown_s` never going back.
pub fn read_arrivals(text: &[u8]) -> Result<Vec<ArrivalTime>, ArrivalsError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(text);
    let mut records = reader.records();
    let header = ARRIVAL_COLUMNS.join(",");
    let first = match records.next() {
        None => {
            return Err(arrivals_error(
                1,
                "header",
                format!("expected `{header}`, found an empty file"),
            ));
        }
        Some(r) => r.map_err(|e| arrivals_error(1, "header", e.to_string()))?,
    };
    let found: Vec<&str> = first.iter().collect();
    if found != ARRIVAL_COLUMNS {
        return Err(arrivals_error(
            1,
            "header",
            format!("expected `{header}`, found `{}`", found.join(",")),
        ));
    }
    let mut rows = Vec::new();
    let mut last_shown = 0.0f64;
    for record in records {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            arrivals_error(line, "row", e.to_string())
        })?;
        let line = record.position().map_or(0, |p| p.line());
        if record.len() != ARRIVAL_COLUMNS.len() {
            return Err(arrivals_error(
                line,
                "row",
                format!(
                    "expected {} fields, found {}",
                    ARRIVAL_COLUMNS.len(),
                    record.len()
                ),
            ));
        }
        let field = |i: usize| record.get(i).unwrap_or("");
        let whole = |i: usize, max: u64| {
            field(i)
                .parse::<u64>()
                .ok()
                .filter(|&v| v <= max)
                .ok_or_else(|| {
                    arrivals_error(
                        line,
                        ARRIVAL_COLUMNS[i],
                        format!("expected a whole number 0 ..= {max}, found `{}`", field(i)),
                    )
                })
        };
        let time = |i: usize| {
            field(i)
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && (0.0..=MAX_TIME_S).contains(v))
                .ok_or_else(|| {
                    arrivals_error(
                        line,
                        ARRIVAL_COLUMNS[i],
                        format!("expected seconds 0 ..= 1e9, found `{}`", field(i)),
                    )
                })
        };
        let scan = whole(0, u64::from(u32::MAX))? as u32;
        let bytes = whole(1, u64::from(u32::MAX))? as usize;
        let (ready, complete, shown) = (time(2)?, time(3)?, time(4)?);
        // latency_s is t_shown_s - t_ready_s: any number of seconds, checked as one.
        time(5)?;
        if complete < ready || shown < complete {
            return Err(arrivals_error(
                line,
                "t_shown_s",
                format!(
                    "expected t_ready_s <= t_complete_s <= t_shown_s, found {ready}, {complete}, {shown}"
                ),
            ));
        }
        if shown < last_shown {
            return Err(arrivals_error(
                line,
                "t_shown_s",
                format!("expected at least the row before's {last_shown} s, found {shown}"),
            ));
        }
        last_shown = shown;
        rows.push(ArrivalTime {
            line,
            scan,
            bytes,
            t_shown_s: shown,
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::super::test_support::HEADER;
    use super::*;

    #[test]
    fn arrivals_are_read_strictly() {
        let ok = format!("{HEADER}0,89,0.0,0.31,0.31,0.31\n1,94,1.0,1.2,1.3,0.3\n");
        let rows = read_arrivals(ok.as_bytes()).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[1].line, rows[1].scan, rows[1].bytes), (3, 1, 94));
        assert_eq!(rows[1].t_shown_s, 1.3);
        let err = |text: &str| read_arrivals(text.as_bytes()).unwrap_err().to_string();
        assert_eq!(
            err(""),
            "line 1, column header: expected `scan,bytes,t_ready_s,t_complete_s,t_shown_s,latency_s`, found an empty file"
        );
        assert_eq!(
            err("scan,bytes\n"),
            "line 1, column header: expected `scan,bytes,t_ready_s,t_complete_s,t_shown_s,latency_s`, found `scan,bytes`"
        );
        assert_eq!(
            err(&format!("{HEADER}0,89,0,0.3,x,0.3\n")),
            "line 2, column t_shown_s: expected seconds 0 ..= 1e9, found `x`"
        );
        assert_eq!(
            err(&format!("{HEADER}0,89,0,0.3,0.3\n")),
            "line 2, column row: expected 6 fields, found 5"
        );
        assert_eq!(
            err(&format!("{HEADER}-1,89,0,0.3,0.3,0.3\n")),
            "line 2, column scan: expected a whole number 0 ..= 4294967295, found `-1`"
        );
        assert!(err(&format!("{HEADER}0,89,0,0.3,NaN,0.3\n")).contains("found `NaN`"));
        assert!(err(&format!("{HEADER}0,89,0,0.3,1e10,0.3\n")).contains("found `1e10`"));
        assert!(err(&format!("{HEADER}0,89,0,0.5,0.3,0.3\n")).starts_with(
            "line 2, column t_shown_s: expected t_ready_s <= t_complete_s <= t_shown_s"
        ));
        assert!(
            err(&format!("{HEADER}0,89,0,2,2,2\n1,9,1,1,1,0\n"))
                .starts_with("line 3, column t_shown_s: expected at least the row before's 2 s")
        );
    }
}
