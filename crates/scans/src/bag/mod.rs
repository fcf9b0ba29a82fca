//! Recorded robot logs ("bags"): the messages of an MCAP file or a ROS 2 rosbag2 directory, one
//! at a time, in bounded memory.
//!
//! A bag is a set of *topics* (a name, a ROS message type such as
//! `sensor_msgs/msg/PointCloud2`, and a serialization format, normally `cdr`) and a sequence of
//! *messages* (a topic, a log time in nanoseconds, and the serialized payload). This module reads
//! the containers and hands out the payloads; it does not decode them (CDR is decoded elsewhere).
//!
//! # Containers
//!
//! - **MCAP** files ([`mcap`](self) records walked here, not with the `mcap` crate's readers,
//!   which panic on some malformed input and cannot report offsets). Read through a
//!   `BufReader<File>` with seeks, never the whole file: the memory used is one record (or one
//!   chunk, compressed and decompressed) plus one message. Chunks may be uncompressed (`""`),
//!   `zstd` or `lz4` (LZ4 frame format, as the MCAP specification says). A chunk's decompressed
//!   size must be its `uncompressed_size` field exactly (at most [`MAX_CHUNK_BYTES`]) and, when
//!   its `uncompressed_crc` is not zero, have that CRC-32. Topics come from the summary section
//!   (its Schema, Channel and Statistics records) when the file has one, else from a first walk
//!   over the whole file; the message indexes are never needed. Unchunked files work too.
//! - **rosbag2** directories: `metadata.yaml` (versions 1 to 9) listing the storage
//!   (`sqlite3`: `.db3` files read with SQLite, read-only; or `mcap`: `.mcap` files read as above)
//!   and the files of a split bag. Payloads compressed one by one (`compression_mode: MESSAGE`,
//!   `zstd`) are decompressed; whole compressed files (`compression_mode: FILE`) are refused with
//!   a message saying so. A `.db3` (or `.mcap`) of such a directory can also be opened alone: then
//!   only that file is read (its topics from its own tables), with the directory's compression
//!   mode when a `metadata.yaml` next to it lists it.
//!
//! # Order
//!
//! [`Bag::messages`] gives the messages in log-time order across the files of a bag (a merge:
//! the next message is the earliest of each file's next one, ties to the earlier file). Within a
//! `.db3` file the order is `timestamp`, then row id. Within one MCAP file it is file order, which
//! is log-time order for the files recorders write (they write messages as they arrive); a file
//! whose messages are out of log-time order is read in file order, not sorted.
//!
//! # The no-panic contract
//!
//! Nothing here panics, on any input. Every failure is a [`BagError`] naming the file and where
//! in it the input stopped making sense (an MCAP byte offset; inside a compressed chunk the
//! chunk's offset and the offset in its decompressed bytes; a `.db3` row id), and what was wrong,
//! expected vs found. Allocations are bounded by the input (a record's length must fit in the
//! bytes left) and by [`MAX_CHUNK_BYTES`] for decompressed chunks and payloads. The MCAP walk is
//! fuzzed (`fuzz/fuzz_targets/octo_bag.rs`).

use std::fmt;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

pub(crate) mod mcap;
mod rosbag2;

/// A stop flag never set, for the openings that cannot be stopped.
static NEVER: AtomicBool = AtomicBool::new(false);

/// The largest decompressed MCAP chunk or rosbag2 payload accepted: 1 GiB.
pub const MAX_CHUNK_BYTES: u64 = 1 << 30;

/// One topic of a bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topic {
    /// Topic name, e.g. `/points`.
    pub name: String,
    /// The ROS message type, e.g. `sensor_msgs/msg/PointCloud2` (empty when an MCAP channel has
    /// no schema).
    pub schema: String,
    /// How the payloads are serialized, e.g. `cdr` (MCAP's channel message encoding, rosbag2's
    /// `serialization_format`).
    pub encoding: String,
    /// How many messages the topic has, when the bag says (metadata, statistics, a count).
    pub messages: Option<u64>,
}

/// One message, owned (the container's buffers are reused between messages).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Message {
    /// Index of its topic in [`Bag::topics`].
    pub topic: usize,
    /// When it was logged (recorded), nanoseconds since the epoch.
    pub log_time_ns: u64,
    /// The serialized payload (decompressed when the bag compressed it).
    pub data: Vec<u8>,
    /// Where its payload is.
    pub at: Location,
}

impl Message {
    /// An error about this message's payload: `error.offset` is an offset in [`Message::data`],
    /// turned into a place in the file.
    pub fn error(&self, error: rovlink_octo::ParseError) -> BagError {
        BagError::new(self.at.within(error.offset), error.message)
    }
}

/// Where a message (or an error) is: the file (one of a rosbag2 directory's files) and a byte
/// offset in it (MCAP) or the row id (`.db3`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Location {
    /// The file, as it was named when opened.
    pub file: String,
    /// Byte offset in the file (MCAP). Inside a compressed chunk: the chunk record's offset, and
    /// [`Location::inner`] says where in the decompressed bytes.
    pub offset: Option<u64>,
    /// The row id in the `messages` table (`.db3`).
    pub row: Option<i64>,
    /// Byte offset inside what `offset` or `row` names: the decompressed records of a compressed
    /// MCAP chunk, or a `.db3` row's (decompressed) payload.
    pub inner: Option<u64>,
}

impl Location {
    /// The file alone.
    pub fn file(file: &str) -> Location {
        Location {
            file: file.to_string(),
            ..Location::default()
        }
    }

    /// `file` at byte `offset`.
    pub fn offset(file: &str, offset: u64) -> Location {
        Location {
            offset: Some(offset),
            ..Location::file(file)
        }
    }

    /// `file` at row `row`.
    pub fn row(file: &str, row: i64) -> Location {
        Location {
            row: Some(row),
            ..Location::file(file)
        }
    }

    /// `bytes` further on inside the thing this location names (a message's payload).
    pub fn within(&self, bytes: u64) -> Location {
        let mut at = self.clone();
        match (at.inner, at.offset) {
            (Some(inner), _) => at.inner = Some(inner.saturating_add(bytes)),
            (None, Some(offset)) if at.row.is_none() => {
                at.offset = Some(offset.saturating_add(bytes));
            }
            _ => at.inner = Some(bytes),
        }
        at
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.file)?;
        match (self.offset, self.row, self.inner) {
            (_, Some(row), Some(inner)) => write!(f, ": row {row}, payload byte {inner}"),
            (_, Some(row), None) => write!(f, ": row {row}"),
            (Some(offset), None, Some(inner)) => {
                write!(f, ": chunk at offset {offset}, decompressed offset {inner}")
            }
            (Some(offset), None, None) => write!(f, ": offset {offset}"),
            (None, None, _) => Ok(()),
        }
    }
}

/// An error naming the file and where: Display is "FILE: offset N: message" or
/// "FILE: row N: message" (or "FILE: message" when no place in it applies).
#[derive(Debug, thiserror::Error)]
#[error("{at}: {message}")]
pub struct BagError {
    /// Where.
    pub at: Location,
    /// What was wrong: field, expected vs found (or the system's words for an I/O error).
    pub message: String,
    /// The I/O error behind it, if any.
    #[source]
    pub io: Option<std::io::Error>,
}

impl BagError {
    /// An error at `at` saying `message`.
    pub fn new(at: Location, message: impl Into<String>) -> BagError {
        BagError {
            at,
            message: message.into(),
            io: None,
        }
    }

    /// An I/O error while `doing` something with `file`.
    pub fn io(at: Location, doing: &str, error: std::io::Error) -> BagError {
        BagError {
            at,
            message: format!("{doing}: {error}"),
            io: Some(error),
        }
    }
}

/// One file of a bag.
enum Source {
    Mcap(mcap::McapFile),
    Db3(rosbag2::Db3File),
}

/// An open bag: its topics, and the files to read messages from.
pub struct Bag {
    topics: Vec<Topic>,
    sources: Vec<Source>,
    /// rosbag2 `compression_mode: MESSAGE`: every payload is a zstd frame.
    compressed_messages: bool,
    /// rosbag2 `compression_mode: FILE`: the decompressed copies the sources read, removed
    /// with the bag (after the sources, which are dropped first).
    _temps: Vec<rosbag2::TempFile>,
}

/// A stream of messages in log-time order.
type Messages<'a> = Box<dyn Iterator<Item = Result<Message, BagError>> + 'a>;

/// The first ten topics with their types, for error messages: `NOUN "/points"
/// (sensor_msgs/msg/PointCloud2), ..., and 3 more`, or `no NOUN`.
pub fn listing(topics: &[Topic], noun: &str) -> String {
    if topics.is_empty() {
        return format!("no {noun}");
    }
    let mut list: Vec<String> = topics
        .iter()
        .take(10)
        .map(|t| {
            let schema = if t.schema.is_empty() {
                "no schema"
            } else {
                &t.schema
            };
            format!("{:?} ({schema})", t.name)
        })
        .collect();
    if topics.len() > 10 {
        list.push(format!("and {} more", topics.len() - 10));
    }
    format!("{noun} {}", list.join(", "))
}

/// Whether the name alone says a rosbag2 file: `metadata.yaml`, a `.db3`, or a file of a
/// `compression_mode: FILE` bag (`.db3.zstd`, `.mcap.zstd`). Looks at no file.
pub fn is_rosbag2_file_name(path: &Path) -> bool {
    let db3 = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("db3"));
    let compressed = path.to_str().is_some_and(|p| {
        let p = p.to_ascii_lowercase();
        p.ends_with(".db3.zstd") || p.ends_with(".mcap.zstd")
    });
    path.file_name().is_some_and(|n| n == "metadata.yaml") || db3 || compressed
}

impl Bag {
    /// An MCAP file, a rosbag2 directory, its metadata.yaml, or one .db3 (or .mcap) file of it.
    pub fn open(path: &Path) -> Result<Bag, BagError> {
        Bag::open_until(path, &NEVER)
    }

    /// [`Bag::open`], giving up (with an error) once `stop` is set: opening an MCAP file
    /// without a summary walks the whole file.
    pub fn open_until(path: &Path, stop: &AtomicBool) -> Result<Bag, BagError> {
        rosbag2::open(path, stop)
    }

    /// An MCAP file already in memory (standard input), named `name` in errors.
    pub fn from_mcap_bytes(name: &str, bytes: Vec<u8>) -> Result<Bag, BagError> {
        Bag::from_mcap_bytes_until(name, bytes, &NEVER)
    }

    /// [`Bag::from_mcap_bytes`], giving up (with an error) once `stop` is set.
    pub fn from_mcap_bytes_until(
        name: &str,
        bytes: Vec<u8>,
        stop: &AtomicBool,
    ) -> Result<Bag, BagError> {
        let mut topics = Vec::new();
        let file = mcap::McapFile::from_bytes(name, bytes, &mut topics, stop)?;
        Ok(Bag {
            topics,
            sources: vec![Source::Mcap(file)],
            compressed_messages: false,
            _temps: Vec::new(),
        })
    }

    /// The files opening the bag at `path` may read (the path itself, its directory's
    /// `metadata.yaml` and the files that lists), so a caller can refuse to write over them.
    pub fn files(path: &Path) -> Vec<std::path::PathBuf> {
        rosbag2::files(path)
    }

    /// Whether `path` is a bag this module opens by its name/shape (a directory with
    /// metadata.yaml, a [rosbag2 file name](is_rosbag2_file_name), a .mcap), for format
    /// detection.
    pub fn is_bag_path(path: &Path) -> bool {
        if path.is_dir() {
            return path.join("metadata.yaml").is_file();
        }
        is_rosbag2_file_name(path)
            || path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
    }

    /// The topics, in the order the bag lists them.
    pub fn topics(&self) -> &[Topic] {
        &self.topics
    }

    /// The messages of the topics whose indices are in `topics`, in log-time order across the
    /// bag's files (within one MCAP file: file order, which is how recorders write), read
    /// lazily: one message (and one MCAP chunk) in memory at a time per file.
    ///
    /// Can be called more than once; each call reads from the start. When `stop` is set the
    /// iterator ends early (returns `None`), so a Ctrl-C during a long read stops promptly.
    /// After an error the iterator ends. An index out of range is an error.
    pub fn messages<'a>(
        &'a mut self,
        topics: &[usize],
        stop: &'a AtomicBool,
    ) -> Result<Messages<'a>, BagError> {
        let mut wanted = vec![false; self.topics.len()];
        for &t in topics {
            match wanted.get_mut(t) {
                Some(w) => *w = true,
                None => {
                    return Err(BagError::new(
                        self.sources.first().map_or_else(Location::default, |s| {
                            Location::file(match s {
                                Source::Mcap(m) => m.name(),
                                Source::Db3(d) => d.name(),
                            })
                        }),
                        format!("topic index: expected 0..{}, found {t}", self.topics.len()),
                    ));
                }
            }
        }
        let compressed = self.compressed_messages;
        let mut streams: Vec<Messages<'a>> = Vec::new();
        for source in &mut self.sources {
            let stream: Messages<'a> = match source {
                Source::Mcap(m) => Box::new(m.messages(wanted.clone(), stop)?),
                Source::Db3(d) => Box::new(d.messages(&wanted)?),
            };
            streams.push(if compressed {
                Box::new(stream.map(|m| m.and_then(decompress_payload)))
            } else {
                stream
            });
        }
        let merged: Messages<'a> = if streams.len() == 1 {
            streams
                .pop()
                .unwrap_or_else(|| Box::new(std::iter::empty()))
        } else {
            Box::new(Merge {
                heads: streams.into_iter().map(|s| (s, None)).collect(),
                started: false,
            })
        };
        let mut failed = false;
        Ok(Box::new(merged.map_while(move |m| {
            if failed || stop.load(Ordering::Relaxed) {
                return None;
            }
            failed = m.is_err();
            Some(m)
        })))
    }
}

/// A rosbag2 payload compressed on its own (`compression_mode: MESSAGE`, zstd), decompressed.
fn decompress_payload(mut m: Message) -> Result<Message, BagError> {
    let mut out = Vec::new();
    mcap::zstd_into(&m.data, MAX_CHUNK_BYTES, &mut out).map_err(|e| {
        BagError::new(
            m.at.clone(),
            format!("zstd-compressed payload (compression_mode MESSAGE): {e}"),
        )
    })?;
    m.data = out;
    Ok(m)
}

/// The messages of several files, merged by log time (ties: the earlier file first).
struct Merge<'a> {
    /// Each file's stream and its next message (`None`: not fetched yet, or the stream ended).
    heads: Vec<(Messages<'a>, Option<Message>)>,
    started: bool,
}

impl Iterator for Merge<'_> {
    type Item = Result<Message, BagError>;

    fn next(&mut self) -> Option<Self::Item> {
        if !self.started {
            self.started = true;
            for (stream, head) in &mut self.heads {
                match stream.next() {
                    Some(Ok(m)) => *head = Some(m),
                    Some(Err(e)) => return Some(Err(e)),
                    None => {}
                }
            }
        }
        let (i, _) = self
            .heads
            .iter()
            .enumerate()
            .filter_map(|(i, (_, h))| h.as_ref().map(|m| (i, m.log_time_ns)))
            .min_by_key(|&(i, t)| (t, i))?;
        let (stream, head) = self.heads.get_mut(i)?;
        let out = head.take();
        match stream.next() {
            Some(Ok(m)) => *head = Some(m),
            Some(Err(e)) => return Some(Err(e)),
            None => {}
        }
        out.map(Ok)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locations_display_where() {
        assert_eq!(
            Location::offset("a.mcap", 12).to_string(),
            "a.mcap: offset 12"
        );
        assert_eq!(Location::row("b.db3", 7).to_string(), "b.db3: row 7");
        assert_eq!(Location::file("m.yaml").to_string(), "m.yaml");
        assert_eq!(
            Location::offset("a.mcap", 12).within(5).to_string(),
            "a.mcap: offset 17"
        );
        assert_eq!(
            Location::row("b.db3", 7).within(5).to_string(),
            "b.db3: row 7, payload byte 5"
        );
        let mut chunk = Location::offset("a.mcap", 100);
        chunk.inner = Some(40);
        assert_eq!(
            chunk.within(2).to_string(),
            "a.mcap: chunk at offset 100, decompressed offset 42"
        );
        let e = BagError::new(Location::offset("x.mcap", 3), "field: expected 1, found 2");
        assert_eq!(
            e.to_string(),
            "x.mcap: offset 3: field: expected 1, found 2"
        );
    }

    #[test]
    fn bag_paths_by_name() {
        assert!(Bag::is_bag_path(Path::new("x/metadata.yaml")));
        assert!(Bag::is_bag_path(Path::new("x/run_0.db3")));
        assert!(Bag::is_bag_path(Path::new("x/run.MCAP")));
        assert!(!Bag::is_bag_path(Path::new("x/cloud.pcd")));
        let dir = tempfile::tempdir().unwrap();
        assert!(!Bag::is_bag_path(dir.path()));
        std::fs::write(dir.path().join("metadata.yaml"), "").unwrap();
        assert!(Bag::is_bag_path(dir.path()));
    }
}
