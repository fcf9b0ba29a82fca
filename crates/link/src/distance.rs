//! The distance between the two ends of a link over time: fixed, or a track read from a file.
//!
//! A track is a CSV file with a header row and the columns `t_s,distance_m`: times in seconds
//! from the start of the run (non-decreasing), distances in metres (0 ..= 1e9, as a model's
//! range). Between two points the distance is interpolated linearly; before the first and after
//! the last it holds.
//! Reading never panics: a malformed file is a [`DistanceError`] with the line and the field.

use std::path::{Path, PathBuf};

use super::model::MAX_RANGE_M;

/// Latest time a distance track may name, seconds (about 31 years: far beyond any run).
pub const MAX_TRACK_TIME_S: f64 = 1e9;
/// Largest distance-track file read, bytes (a week of 0.1 s rows is about 100 MB).
pub const MAX_TRACK_FILE_BYTES: u64 = 256 << 20;

/// Distance between the two sides over time.
#[derive(Debug, Clone, PartialEq)]
pub enum Distance {
    /// Always the same, m (a driver may change it with [`super::Link::set_distance`]).
    Fixed(f64),
    /// `(t_s, distance_m)` points sorted by time, linearly interpolated, held at both ends.
    Track(Vec<(f64, f64)>),
}

impl Distance {
    /// The distance at `t_s`; `cursor` remembers where the last lookup was (times mostly grow).
    pub(crate) fn at(&self, t_s: f64, cursor: &mut usize) -> f64 {
        match self {
            Distance::Fixed(d) => *d,
            Distance::Track(points) => {
                let Some(&(t_first, d_first)) = points.first() else {
                    return 0.0;
                };
                if t_s <= t_first {
                    *cursor = 0;
                    return d_first;
                }
                if *cursor >= points.len() || points[*cursor].0 > t_s {
                    *cursor = 0;
                }
                while *cursor + 1 < points.len() && points[*cursor + 1].0 <= t_s {
                    *cursor += 1;
                }
                let (t0, d0) = points[*cursor];
                match points.get(*cursor + 1) {
                    None => d0,
                    Some(&(t1, d1)) if t1 > t0 => d0 + (d1 - d0) * (t_s - t0) / (t1 - t0),
                    Some(_) => d0,
                }
            }
        }
    }
}

impl Distance {
    /// Reads a `t_s,distance_m` track from CSV text.
    pub fn from_csv(text: &[u8]) -> Result<Distance, DistanceError> {
        let rows = rovlink_base::io::read_number_table(text, &["t_s", "distance_m"], 0.0)
            .map_err(|e| DistanceError::at(e.line, &e.field, e.problem))?;
        let mut points: Vec<(f64, f64)> = Vec::with_capacity(rows.len());
        for (line, values) in rows {
            let (t, d) = (values[0], values[1]);
            if let Some(&(last, _)) = points.last()
                && t < last
            {
                return Err(DistanceError::at(
                    line,
                    "t_s",
                    format!("{t} is before the previous row's {last}: times must not decrease"),
                ));
            }
            if t > MAX_TRACK_TIME_S {
                return Err(DistanceError::at(
                    line,
                    "t_s",
                    format!("expected 0 ..= 1e9 s (about 31 years), found {t:e}"),
                ));
            }
            if d > MAX_RANGE_M {
                return Err(DistanceError::at(
                    line,
                    "distance_m",
                    format!("expected 0 ..= 1e9 m (a million km), found {d:e}"),
                ));
            }
            points.push((t, d));
        }
        if points.is_empty() {
            return Err(DistanceError::at(
                1,
                "row",
                "no rows: expected at least one `t_s,distance_m` point".into(),
            ));
        }
        Ok(Distance::Track(points))
    }

    /// Reads a track file (at most [`MAX_TRACK_FILE_BYTES`]); errors name the file.
    pub fn from_csv_file(path: &Path) -> Result<Distance, DistanceError> {
        let text = rovlink_base::io::read_at_most(path, MAX_TRACK_FILE_BYTES).map_err(|e| {
            DistanceError::Read {
                path: path.to_path_buf(),
                reason: e.to_string(),
            }
        })?;
        Distance::from_csv(&text).map_err(|e| match e {
            DistanceError::Line {
                line,
                field,
                problem,
                ..
            } => DistanceError::Line {
                path: Some(path.to_path_buf()),
                line,
                field,
                problem,
            },
            other => other,
        })
    }
}

/// A distance track that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum DistanceError {
    /// The file could not be read.
    #[error("{}: cannot read: {reason}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The reason.
        reason: String,
    },
    /// A line is wrong.
    #[error("{}line {line}: field `{field}`: {problem}", path.as_ref().map(|p| format!("{}: ", p.display())).unwrap_or_default())]
    Line {
        /// The file, when known.
        path: Option<PathBuf>,
        /// Line number, from 1.
        line: u64,
        /// The column (or `header`, `row`).
        field: String,
        /// What is wrong.
        problem: String,
    },
}

impl DistanceError {
    fn at(line: u64, field: &str, problem: String) -> DistanceError {
        DistanceError::Line {
            path: None,
            line,
            field: field.to_string(),
            problem,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_track_interpolates_and_holds_at_the_ends() {
        let track = Distance::from_csv(b"t_s,distance_m\n0,1\n10,6\n20,1\n").unwrap();
        let mut cursor = 0;
        let at = |t: f64, cursor: &mut usize| track.at(t, cursor);
        assert_eq!(at(-1.0, &mut cursor), 1.0);
        assert_eq!(at(5.0, &mut cursor), 3.5);
        assert_eq!(at(10.0, &mut cursor), 6.0);
        assert_eq!(at(15.0, &mut cursor), 3.5);
        assert_eq!(at(2.0, &mut cursor), 2.0); // going back in time still works
        assert_eq!(at(99.0, &mut cursor), 1.0);
    }

    #[test]
    fn bad_tracks_name_the_line_and_field() {
        let cases: [(&[u8], &str); 7] = [
            (
                b"t_s,distance_m\n0,1\n1,1e300\n",
                "line 3: field `distance_m`: expected 0 ..= 1e9 m (a million km), found 1e300",
            ),
            (b"t,d\n0,1\n", "line 1: field `t_s`: missing column"),
            (
                b"t_s,distance_m\n0,1\n1e300,1\n",
                "line 3: field `t_s`: expected 0 ..= 1e9 s (about 31 years), found 1e300",
            ),
            (
                b"t_s,distance_m\n0,1\n1,x\n",
                "line 3: field `distance_m`: expected a number >= 0, found `x`",
            ),
            (
                b"t_s,distance_m\n5,1\n1,1\n",
                "line 3: field `t_s`: 1 is before the previous row's 5",
            ),
            (b"t_s,distance_m\n", "line 1: field `row`: no rows"),
            (b"t_s,distance_m\n0,1,2\n", "line 2: field `row`"),
        ];
        for (text, expected) in cases {
            let message = Distance::from_csv(text).unwrap_err().to_string();
            assert!(message.starts_with(expected), "{message}");
        }
    }
}
