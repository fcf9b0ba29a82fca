//! Row streams: CSV or JSON Lines, one whole line per write, flushed as it goes.
//!
//! Measurements must survive whatever ends a run: each row is formatted into a buffer and
//! handed to the OS in one `write` of the whole line, then flushed, so a kill, a full disk or a
//! closed pipe leaves the file ending at a line boundary. The file is created at the first row
//! (the header goes in the same write), so a run that fails before measuring anything leaves no
//! file at all; [`RowWriter::finish`] writes a header-only CSV for a run that completed with no
//! rows, and nothing for JSON Lines.

use std::fs::File;
use std::io::{self, Write};

use serde::Serialize;

use super::output::Dest;
use rovlink_base::io::IoError;

/// How rows are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RowFormat {
    /// Comma-separated values with a header line.
    Csv,
    /// One JSON object per line (the header names its fields).
    Ndjson,
}

enum Sink {
    NotOpen,
    File(File),
    Stdout,
}

/// A stream of rows to one [`Dest`].
pub struct RowWriter {
    dest: Dest,
    format: RowFormat,
    header: Vec<String>,
    sink: Sink,
    rows: u64,
}

impl RowWriter {
    /// A writer of rows with these columns; nothing is created until the first row.
    pub fn new(dest: Dest, format: RowFormat, header: &[&str]) -> RowWriter {
        RowWriter {
            dest,
            format,
            header: header.iter().map(|h| h.to_string()).collect(),
            sink: Sink::NotOpen,
            rows: 0,
        }
    }

    /// The number of rows written.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Where the rows go.
    pub fn dest(&self) -> &Dest {
        &self.dest
    }

    fn write_err(&self, source: io::Error) -> IoError {
        IoError::Write {
            name: self.dest.name(),
            source,
        }
    }

    fn header_line(&self) -> Result<Vec<u8>, IoError> {
        let mut csv = csv::WriterBuilder::new().from_writer(Vec::new());
        csv.write_record(&self.header)
            .map_err(|e| self.write_err(io::Error::other(e)))?;
        csv.into_inner()
            .map_err(|e| self.write_err(io::Error::other(e.to_string())))
    }

    /// The bytes of one row (one line, with its newline).
    fn line<T: Serialize>(&self, row: &T) -> Result<Vec<u8>, IoError> {
        match self.format {
            RowFormat::Csv => {
                let mut csv = csv::WriterBuilder::new()
                    .has_headers(false)
                    .from_writer(Vec::new());
                csv.serialize(row)
                    .map_err(|e| self.write_err(io::Error::other(e)))?;
                csv.into_inner()
                    .map_err(|e| self.write_err(io::Error::other(e.to_string())))
            }
            RowFormat::Ndjson => {
                let value =
                    serde_json::to_value(row).map_err(|e| self.write_err(io::Error::other(e)))?;
                let value = match value {
                    serde_json::Value::Array(items) if items.len() == self.header.len() => {
                        serde_json::Value::Object(self.header.iter().cloned().zip(items).collect())
                    }
                    other => other,
                };
                let mut line =
                    serde_json::to_vec(&value).map_err(|e| self.write_err(io::Error::other(e)))?;
                line.push(b'\n');
                Ok(line)
            }
        }
    }

    fn open(&mut self) -> Result<(), IoError> {
        if !matches!(self.sink, Sink::NotOpen) {
            return Ok(());
        }
        self.sink = match &self.dest {
            Dest::Stdout => Sink::Stdout,
            Dest::File(path) => Sink::File(File::create(path).map_err(|source| IoError::Open {
                path: path.clone(),
                source,
            })?),
        };
        Ok(())
    }

    fn emit(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.open()?;
        let result = match &mut self.sink {
            Sink::File(file) => file.write_all(bytes),
            Sink::Stdout => {
                let mut out = io::stdout().lock();
                out.write_all(bytes).and_then(|()| out.flush())
            }
            Sink::NotOpen => Ok(()),
        };
        result.map_err(|e| self.write_err(e))
    }

    /// Writes one row (a struct, or a tuple in header order) as one whole line, flushed.
    pub fn row<T: Serialize>(&mut self, row: &T) -> Result<(), IoError> {
        let mut bytes = if self.rows == 0 && self.format == RowFormat::Csv {
            self.header_line()?
        } else {
            Vec::new()
        };
        bytes.extend_from_slice(&self.line(row)?);
        self.emit(&bytes)?;
        self.rows += 1;
        Ok(())
    }

    /// Ends a run that failed on bad input (exit 2): the file this writer created is removed,
    /// so no output is left behind. Standard output, and a path that is not a regular file
    /// (a device, a FIFO), are left as they are. A run that measured something and then lost
    /// its port keeps its rows: it calls [`finish`](Self::finish) instead.
    pub fn discard(self) {
        if let (Sink::File(_), Dest::File(path)) = (&self.sink, &self.dest)
            && std::fs::symlink_metadata(path).is_ok_and(|m| m.is_file())
        {
            let _ = std::fs::remove_file(path);
        }
    }

    /// Writes every row of a completed table, then [finishes](Self::finish).
    pub fn write_all<T: Serialize>(mut self, rows: &[T]) -> Result<(), IoError> {
        rows.iter().try_for_each(|r| self.row(r))?;
        self.finish()
    }

    /// Ends a completed run: a CSV with no rows gets its header, so the file exists and reads.
    pub fn finish(mut self) -> Result<(), IoError> {
        if self.rows == 0 && self.format == RowFormat::Csv {
            let header = self.header_line()?;
            self.emit(&header)?;
        }
        if let Sink::File(file) = &mut self.sink {
            file.flush().map_err(|e| IoError::Write {
                name: self.dest.name(),
                source: e,
            })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[derive(Serialize)]
    struct Row {
        seq: u64,
        delay_ms: f64,
        note: &'static str,
    }

    #[test]
    fn rows_are_whole_lines_and_the_file_appears_with_the_first() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.csv");
        let mut rows = RowWriter::new(
            Dest::File(path.clone()),
            RowFormat::Csv,
            &["seq", "delay_ms", "note"],
        );
        assert!(!path.exists());
        rows.row(&Row {
            seq: 1,
            delay_ms: 2.5,
            note: "a,b",
        })
        .unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "seq,delay_ms,note\n1,2.5,\"a,b\"\n"
        );
        rows.row(&(2u64, 3.0f64, "")).unwrap();
        rows.finish().unwrap();
        assert!(
            std::fs::read_to_string(&path)
                .unwrap()
                .ends_with("2,3.0,\n")
        );

        let json = dir.path().join("p.jsonl");
        let mut rows = RowWriter::new(Dest::File(json.clone()), RowFormat::Ndjson, &["a", "b"]);
        rows.row(&(1u8, "x")).unwrap();
        rows.finish().unwrap();
        assert_eq!(
            std::fs::read_to_string(&json).unwrap(),
            "{\"a\":1,\"b\":\"x\"}\n"
        );
    }

    #[test]
    fn an_unused_writer_leaves_nothing_and_a_finished_empty_csv_has_its_header() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.csv");
        drop(RowWriter::new(
            Dest::File(path.clone()),
            RowFormat::Csv,
            &["a"],
        ));
        assert!(!path.exists());
        RowWriter::new(Dest::File(path.clone()), RowFormat::Csv, &["a", "b"])
            .finish()
            .unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "a,b\n");
    }

    #[test]
    fn a_discarded_writer_removes_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.csv");
        let mut rows = RowWriter::new(Dest::File(path.clone()), RowFormat::Csv, &["a"]);
        rows.row(&(1u8,)).unwrap();
        assert!(path.exists());
        rows.discard();
        assert!(!path.exists());
        let mut rows = RowWriter::new(Dest::File("/dev/null".into()), RowFormat::Csv, &["a"]);
        rows.row(&(1u8,)).unwrap();
        rows.discard();
        assert!(Path::new("/dev/null").exists());
    }

    #[test]
    fn a_full_disk_is_an_error_naming_the_file() {
        let mut rows = RowWriter::new(Dest::File("/dev/full".into()), RowFormat::Csv, &["a"]);
        let err = rows.row(&(1u8,)).unwrap_err().to_string();
        assert!(err.starts_with("/dev/full: write failed"), "{err}");
    }
}
