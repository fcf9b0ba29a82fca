//! rosbag2 bags: `metadata.yaml` and the `.db3` (SQLite) or `.mcap` files it lists.
//!
//! A `.db3` file holds tables `topics(id, name, type, serialization_format, ...)` and
//! `messages(id, topic_id, timestamp, data)`. Its messages are read in `timestamp`, row id
//! order: the ids and times of the wanted messages are listed first (24 bytes a message), then
//! each payload is fetched by its row id, so one payload is in memory at a time. Databases are
//! opened read-only.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use rusqlite::types::ValueRef;
use rusqlite::{Connection, OpenFlags};
use yaml_rust2::parser::{Event, MarkedEventReceiver, Parser};
use yaml_rust2::scanner::Marker;
use yaml_rust2::{Yaml, YamlLoader};

use super::mcap::{McapFile, topic_index};
use super::{Bag, BagError, Location, Message, Source, Topic};

/// The largest `metadata.yaml` read: 16 MiB (a bag of thousands of topics and files is far less).
const MAX_METADATA_BYTES: u64 = 16 << 20;
/// The most files a bag's metadata may list: each is held open while the bag is read (an
/// SQLite connection or an MCAP reader), and a process may have only so many open files.
pub const MAX_BAG_FILES: usize = 1000;

/// What `metadata.yaml` says that matters here.
#[derive(Debug)]
struct Metadata {
    storage: Storage,
    /// The bag's files, by name (in the metadata's directory).
    files: Vec<String>,
    /// (name, type, serialization format, message count).
    topics: Vec<(String, String, String, Option<u64>)>,
    /// `compression_mode: MESSAGE` with `compression_format: zstd`.
    compressed_messages: bool,
    /// `compression_mode: FILE` with `compression_format: zstd`: every file is a zstd stream.
    compressed_files: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Storage {
    Sqlite3,
    Mcap,
}

fn shown(path: &Path) -> String {
    path.display().to_string()
}

/// A bag at `path`: a rosbag2 directory, its metadata.yaml, one .db3 file, or an MCAP file.
pub(super) fn open(path: &Path, stop: &AtomicBool) -> Result<Bag, BagError> {
    let name = shown(path);
    if path.is_dir() {
        let yaml = path.join("metadata.yaml");
        // One that is there but not a file (a FIFO) is named as such when it is opened.
        if !yaml.exists() {
            return Err(BagError::new(
                Location::file(&name),
                "not a rosbag2 directory (expected a metadata.yaml in it, found none)",
            ));
        }
        return open_directory(&yaml, path, stop);
    }
    let file_name = path.file_name().map(|n| n.to_string_lossy().into_owned());
    let dir = path.parent().unwrap_or(Path::new("."));
    if file_name.as_deref() == Some("metadata.yaml") {
        return open_directory(path, dir, stop);
    }
    // One file alone: with the directory's compression mode when its metadata lists the file.
    let beside = dir.join("metadata.yaml");
    let mut compressed_messages = false;
    if beside.is_file() {
        let meta = read_metadata(&beside)?;
        if file_name.is_some_and(|n| meta.files.contains(&n)) {
            compressed_messages = meta.compressed_messages;
        }
    }
    let mut topics = Vec::new();
    // A file of a FILE-compressed bag (`bag_0.db3.zstd`): its decompressed copy is read.
    let zstd = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("zstd"));
    let mut temps = Vec::new();
    let (inner, read) = if zstd {
        let temp = decompress_file(path, stop)?;
        let read = temp.path.clone();
        temps.push(temp);
        (path.with_extension(""), read)
    } else {
        (path.to_path_buf(), path.to_path_buf())
    };
    let db3 = inner
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("db3"));
    let source = if db3 {
        Source::Db3(Db3File::open(&name, &read, &mut topics, true)?)
    } else {
        Source::Mcap(McapFile::open(&name, &read, &mut topics, true, stop)?)
    };
    Ok(Bag {
        topics,
        sources: vec![source],
        compressed_messages,
        _temps: temps,
    })
}

/// The files reading the bag at `path` reads: the path itself when it is a file, the
/// `metadata.yaml` of its directory (when there is one) and the files that metadata lists (all
/// of them; when it does not parse, none).
pub(super) fn files(path: &Path) -> Vec<PathBuf> {
    let (dir, mut out) = if path.is_dir() {
        (path, Vec::new())
    } else {
        (
            path.parent().unwrap_or(Path::new(".")),
            vec![path.to_path_buf()],
        )
    };
    let yaml = dir.join("metadata.yaml");
    if yaml.is_file() {
        if let Ok(meta) = read_metadata(&yaml) {
            out.extend(meta.files.iter().map(|f| dir.join(f)));
        }
        out.push(yaml);
    }
    out
}

/// The largest decompressed file of a FILE-compressed bag: 64 GiB (it goes to a temporary file).
pub const MAX_DECOMPRESSED_FILE_BYTES: u64 = 64 << 30;

/// A temporary file, removed when dropped.
#[derive(Debug)]
pub(super) struct TempFile {
    path: PathBuf,
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Decompresses the zstd file `path` (a file of a `compression_mode: FILE` bag) into a
/// temporary file (in `$TMPDIR`), at most [`MAX_DECOMPRESSED_FILE_BYTES`]; SQLite and the MCAP
/// reader then read that. Gives up (an error) once `stop` is set.
fn decompress_file(path: &Path, stop: &AtomicBool) -> Result<TempFile, BagError> {
    use std::io::{Read, Write};
    use std::sync::atomic::{AtomicU64, Ordering};
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let name = shown(path);
    let at = Location::file(&name);
    let input =
        rovlink_base::io::open_regular(path).map_err(|e| BagError::io(at.clone(), "opening", e))?;
    let mut decoder = zstd::stream::read::Decoder::new(input)
        .map_err(|e| BagError::io(at.clone(), "reading zstd", e))?;
    let stem = path
        .file_stem()
        .map_or_else(|| "bag".into(), |s| s.to_string_lossy().into_owned());
    let temp = TempFile {
        path: std::env::temp_dir().join(format!(
            "rovlink-{}-{}-{stem}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        )),
    };
    let mut out = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&temp.path)
        .map_err(|e| {
            BagError::io(
                at.clone(),
                &format!("creating {} for the decompressed file", temp.path.display()),
                e,
            )
        })?;
    let mut buf = vec![0u8; 1 << 20];
    let mut total = 0u64;
    loop {
        if stop.load(Ordering::Relaxed) {
            return Err(BagError::new(at, "stopped while decompressing"));
        }
        let n = decoder.read(&mut buf).map_err(|e| {
            BagError::new(
                at.clone(),
                format!("zstd (compression_mode FILE): {e} after {total} decompressed bytes"),
            )
        })?;
        if n == 0 {
            break;
        }
        total += n as u64;
        if total > MAX_DECOMPRESSED_FILE_BYTES {
            return Err(BagError::new(
                at,
                format!(
                    "zstd (compression_mode FILE): expected at most {MAX_DECOMPRESSED_FILE_BYTES} \
                     bytes decompressed, found more"
                ),
            ));
        }
        out.write_all(&buf[..n]).map_err(|e| {
            BagError::io(at.clone(), &format!("writing {}", temp.path.display()), e)
        })?;
    }
    Ok(temp)
}

fn open_directory(yaml: &Path, dir: &Path, stop: &AtomicBool) -> Result<Bag, BagError> {
    let meta = read_metadata(yaml)?;
    let mut topics: Vec<Topic> = Vec::new();
    for (name, schema, encoding, count) in &meta.topics {
        let i = topic_index(&mut topics, name, schema, encoding);
        if let Some(t) = topics.get_mut(i) {
            t.messages = match (t.messages, count) {
                (Some(a), Some(b)) => Some(a.saturating_add(*b)),
                (a, b) => a.or(*b),
            };
        }
    }
    let mut sources = Vec::new();
    let mut temps = Vec::new();
    for file in &meta.files {
        let given = dir.join(file);
        let name = shown(&given);
        let path = if meta.compressed_files {
            let temp = decompress_file(&given, stop)?;
            let path = temp.path.clone();
            temps.push(temp);
            path
        } else {
            given
        };
        sources.push(match meta.storage {
            Storage::Sqlite3 => Source::Db3(Db3File::open(&name, &path, &mut topics, false)?),
            Storage::Mcap => Source::Mcap(McapFile::open(&name, &path, &mut topics, false, stop)?),
        });
    }
    Ok(Bag {
        topics,
        sources,
        compressed_messages: meta.compressed_messages,
        _temps: temps,
    })
}

fn read_metadata(path: &Path) -> Result<Metadata, BagError> {
    let name = shown(path);
    let at = Location::file(&name);
    let bytes = rovlink_base::io::read_bounded(
        rovlink_base::io::open_regular(path).map_err(|e| BagError::io(at.clone(), "opening", e))?,
        MAX_METADATA_BYTES,
    )
    .map_err(|e| BagError::io(at.clone(), "reading", e))?
    .ok_or_else(|| {
        BagError::new(
            at.clone(),
            format!("rosbag2 metadata: expected at most {MAX_METADATA_BYTES} bytes, found more"),
        )
    })?;
    let text = String::from_utf8(bytes).map_err(|e| {
        BagError::new(
            at.clone(),
            format!("rosbag2 metadata: expected UTF-8 text: {e}"),
        )
    })?;
    parse_metadata(&text).map_err(|m| BagError::new(at, m))
}

/// The text of a YAML value, for messages.
fn yaml_shown(y: &Yaml) -> String {
    match y {
        Yaml::BadValue => "nothing".into(),
        Yaml::String(s) => format!("{s:?}"),
        Yaml::Integer(i) => i.to_string(),
        Yaml::Real(r) => r.clone(),
        Yaml::Boolean(b) => b.to_string(),
        Yaml::Null => "null".into(),
        Yaml::Array(_) => "a list".into(),
        Yaml::Hash(_) => "a mapping".into(),
        Yaml::Alias(_) => "an alias".into(),
    }
}

fn text<'y>(y: &'y Yaml, field: &str) -> Result<&'y str, String> {
    match y {
        Yaml::String(s) => Ok(s),
        // An absent or empty field reads as "" (rosbag2 writes `compression_format: ""`).
        Yaml::BadValue | Yaml::Null => Ok(""),
        other => Err(format!(
            "rosbag2 metadata field {field}: expected text, found {}",
            yaml_shown(other)
        )),
    }
}

/// Finds the first YAML alias (`*name`) of a document, where it is.
#[derive(Default)]
struct FirstAlias(Option<Marker>);

impl MarkedEventReceiver for FirstAlias {
    fn on_event(&mut self, ev: Event, mark: Marker) {
        if matches!(ev, Event::Alias(_)) && self.0.is_none() {
            self.0 = Some(mark);
        }
    }
}

/// `metadata.yaml`'s text parsed; the error says which field is wrong.
///
/// Aliases are refused before the document is loaded: the loader copies the anchored value at
/// each alias, so a few lines of nested aliases (a "billion laughs") would fill memory, and
/// rosbag2 never writes any.
fn parse_metadata(text_in: &str) -> Result<Metadata, String> {
    let yaml_error = |e: yaml_rust2::ScanError| {
        let m = e.marker();
        format!(
            "rosbag2 metadata: line {} column {}: expected YAML, found an error: {}",
            m.line(),
            m.col() + 1,
            e.info()
        )
    };
    let mut alias = FirstAlias::default();
    Parser::new_from_str(text_in)
        .load(&mut alias, true)
        .map_err(yaml_error)?;
    if let Some(m) = alias.0 {
        return Err(format!(
            "rosbag2 metadata: line {} column {}: expected plain YAML (rosbag2 writes no \
             anchors or aliases), found an alias",
            m.line(),
            m.col() + 1
        ));
    }
    let docs = YamlLoader::load_from_str(text_in).map_err(yaml_error)?;
    let root = docs.first().unwrap_or(&Yaml::BadValue);
    let info = &root["rosbag2_bagfile_information"];
    if !matches!(info, Yaml::Hash(_)) {
        return Err(format!(
            "rosbag2 metadata: expected a mapping rosbag2_bagfile_information, found {}",
            yaml_shown(info)
        ));
    }
    let field = |f: &str| format!("rosbag2_bagfile_information.{f}");
    let version = &info["version"];
    match version.as_i64() {
        Some(1..=9) => {}
        _ => {
            return Err(format!(
                "rosbag2 metadata field {}: expected a version 1..9, found {}",
                field("version"),
                yaml_shown(version)
            ));
        }
    }
    let storage = match text(&info["storage_identifier"], &field("storage_identifier"))? {
        "sqlite3" | "" => Storage::Sqlite3,
        "mcap" => Storage::Mcap,
        other => {
            return Err(format!(
                "rosbag2 metadata field {}: expected sqlite3 or mcap, found {other:?}",
                field("storage_identifier")
            ));
        }
    };
    let list = |name: &str| -> Result<&[Yaml], String> {
        match &info[name] {
            Yaml::Array(a) => Ok(a.as_slice()),
            Yaml::BadValue | Yaml::Null => Ok(&[]),
            other => Err(format!(
                "rosbag2 metadata field {}: expected a list, found {}",
                field(name),
                yaml_shown(other)
            )),
        }
    };
    let mut files: Vec<String> = Vec::new();
    let listed = list("relative_file_paths")?;
    if listed.len() > MAX_BAG_FILES {
        return Err(format!(
            "rosbag2 metadata field {}: expected at most {MAX_BAG_FILES} files, found {}",
            field("relative_file_paths"),
            listed.len()
        ));
    }
    for (i, f) in listed.iter().enumerate() {
        let path = text(f, &format!("{}[{i}]", field("relative_file_paths")))?;
        // As rosbag2's later versions write it: a name in the bag's directory (older ones
        // prefixed the directory's own name).
        let name = Path::new(path)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if name.is_empty() {
            return Err(format!(
                "rosbag2 metadata field {}[{i}]: expected a file name, found {path:?}",
                field("relative_file_paths")
            ));
        }
        // Listed twice, a file's clouds would be inserted twice.
        if let Some(first) = files.iter().position(|f| *f == name) {
            return Err(format!(
                "rosbag2 metadata field {}[{i}]: {name:?} is listed twice (first at [{first}])",
                field("relative_file_paths")
            ));
        }
        files.push(name);
    }
    if files.is_empty() {
        return Err(format!(
            "rosbag2 metadata field {}: expected at least one file, found none",
            field("relative_file_paths")
        ));
    }
    let mut topics = Vec::new();
    for (i, t) in list("topics_with_message_count")?.iter().enumerate() {
        let at = format!("{}[{i}]", field("topics_with_message_count"));
        let meta = &t["topic_metadata"];
        let name = text(&meta["name"], &format!("{at}.topic_metadata.name"))?;
        let schema = text(&meta["type"], &format!("{at}.topic_metadata.type"))?;
        let encoding = text(
            &meta["serialization_format"],
            &format!("{at}.topic_metadata.serialization_format"),
        )?;
        let count = &t["message_count"];
        let count = match count {
            Yaml::BadValue => None,
            Yaml::Integer(n) => Some(u64::try_from(*n).map_err(|_| {
                format!("rosbag2 metadata field {at}.message_count: expected a count, found {n}")
            })?),
            other => {
                return Err(format!(
                    "rosbag2 metadata field {at}.message_count: expected a count, found {}",
                    yaml_shown(other)
                ));
            }
        };
        if name.is_empty() {
            return Err(format!(
                "rosbag2 metadata field {at}.topic_metadata.name: expected a topic name, found \
                 nothing"
            ));
        }
        topics.push((name.into(), schema.into(), encoding.into(), count));
    }
    let mode = text(&info["compression_mode"], &field("compression_mode"))?;
    let format = text(&info["compression_format"], &field("compression_format"))?;
    let compressed_messages = match mode.to_ascii_uppercase().as_str() {
        "" | "NONE" => false,
        "MESSAGE" if format == "zstd" => true,
        "MESSAGE" => {
            return Err(format!(
                "rosbag2 metadata field {}: expected zstd (with compression_mode MESSAGE), found \
                 {format:?}",
                field("compression_format")
            ));
        }
        "FILE" if format == "zstd" => false,
        "FILE" => {
            return Err(format!(
                "rosbag2 metadata field {}: expected zstd (with compression_mode FILE), found \
                 {format:?}",
                field("compression_format")
            ));
        }
        _ => {
            return Err(format!(
                "rosbag2 metadata field {}: expected \"\", NONE, MESSAGE or FILE, found {mode:?}",
                field("compression_mode")
            ));
        }
    };
    let compressed_files = mode.eq_ignore_ascii_case("FILE");
    Ok(Metadata {
        storage,
        files,
        topics,
        compressed_messages,
        compressed_files,
    })
}

/// One `.db3` file of a bag.
pub(super) struct Db3File {
    name: String,
    conn: Connection,
    /// Topic index in the bag's topics, by the file's topic id.
    topics: HashMap<i64, usize>,
}

fn not_rosbag2(name: &str, found: impl std::fmt::Display) -> BagError {
    BagError::new(
        Location::file(name),
        format!("not a rosbag2 database (expected tables topics and messages, found {found})"),
    )
}

impl Db3File {
    /// The database at `path`, named `name` in errors; its topics are added to `topics` (with
    /// their message counts when `count`).
    pub(super) fn open(
        name: &str,
        path: &Path,
        topics: &mut Vec<Topic>,
        count: bool,
    ) -> Result<Db3File, BagError> {
        // A clear message for a missing or unreadable file (SQLite only says "unable to open").
        rovlink_base::io::open_regular(path)
            .map_err(|e| BagError::io(Location::file(name), "opening", e))?;
        let conn = Connection::open_with_flags(
            PathBuf::from(path),
            OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
        )
        .map_err(|e| BagError::new(Location::file(name), format!("opening with SQLite: {e}")))?;
        let tables: Vec<String> = conn
            .prepare("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name")
            .and_then(|mut s| {
                s.query_map([], |r| r.get::<_, String>(0))?
                    .collect::<Result<_, _>>()
            })
            .map_err(|e| not_rosbag2(name, format!("a file SQLite does not read: {e}")))?;
        if !(tables.iter().any(|t| t == "topics") && tables.iter().any(|t| t == "messages")) {
            return Err(not_rosbag2(
                name,
                if tables.is_empty() {
                    "no tables".to_string()
                } else {
                    format!("tables {}", tables.join(", "))
                },
            ));
        }
        let table_error = |table: &str, e: rusqlite::Error| {
            BagError::new(
                Location::file(name),
                format!("rosbag2 table {table}: expected rosbag2's columns, found an error: {e}"),
            )
        };
        let rows: Vec<(i64, String, String, String)> = conn
            .prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id")
            .and_then(|mut s| {
                s.query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))?
                    .collect::<Result<_, _>>()
            })
            .map_err(|e| table_error("topics", e))?;
        let counts: HashMap<i64, u64> = if count {
            conn.prepare("SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id")
                .and_then(|mut s| {
                    s.query_map([], |r| Ok((r.get::<_, i64>(0)?, r.get::<_, i64>(1)?)))?
                        .map(|r| r.map(|(id, n)| (id, n.max(0) as u64)))
                        .collect::<Result<_, _>>()
                })
                .map_err(|e| table_error("messages", e))?
        } else {
            HashMap::new()
        };
        let mut map = HashMap::new();
        for (id, topic, schema, encoding) in rows {
            let i = topic_index(topics, &topic, &schema, &encoding);
            if count && let Some(t) = topics.get_mut(i) {
                let n = counts.get(&id).copied().unwrap_or(0);
                t.messages = Some(t.messages.unwrap_or(0).saturating_add(n));
            }
            map.insert(id, i);
        }
        Ok(Db3File {
            name: name.to_string(),
            conn,
            topics: map,
        })
    }

    pub(super) fn name(&self) -> &str {
        &self.name
    }

    /// The messages of the `wanted` topics, by timestamp then row id.
    pub(super) fn messages(&mut self, wanted: &[bool]) -> Result<Db3Messages<'_>, BagError> {
        let ids: Vec<i64> = self
            .topics
            .iter()
            .filter(|&(_, &t)| wanted.get(t).copied().unwrap_or(false))
            .map(|(&id, _)| id)
            .collect();
        let mut rows = Vec::new();
        if !ids.is_empty() {
            // Integers only, so the list is safe to write into the statement.
            let list = ids.iter().map(i64::to_string).collect::<Vec<_>>().join(",");
            let sql = format!(
                "SELECT id, topic_id, timestamp FROM messages WHERE topic_id IN ({list}) \
                 ORDER BY timestamp, id"
            );
            let mut statement = self.conn.prepare(&sql).map_err(|e| self.sql_error(e))?;
            let mut query = statement.query([]).map_err(|e| self.sql_error(e))?;
            while let Some(r) = query.next().map_err(|e| self.sql_error(e))? {
                let row: i64 = r.get(0).map_err(|e| self.sql_error(e))?;
                let topic: i64 = r.get(1).map_err(|e| self.row_error(row, "topic_id", e))?;
                let time: i64 = r.get(2).map_err(|e| self.row_error(row, "timestamp", e))?;
                let time = u64::try_from(time).map_err(|_| {
                    BagError::new(
                        Location::row(&self.name, row),
                        format!("rosbag2 messages field timestamp: expected nanoseconds >= 0, found {time}"),
                    )
                })?;
                let topic = self.topics.get(&topic).copied().unwrap_or(usize::MAX);
                rows.push((row, topic, time));
            }
        }
        Ok(Db3Messages {
            file: self,
            rows: rows.into_iter(),
        })
    }

    fn sql_error(&self, e: rusqlite::Error) -> BagError {
        BagError::new(
            Location::file(&self.name),
            format!("rosbag2 table messages: {e}"),
        )
    }

    fn row_error(&self, row: i64, field: &str, e: rusqlite::Error) -> BagError {
        BagError::new(
            Location::row(&self.name, row),
            format!("rosbag2 messages field {field}: {e}"),
        )
    }

    /// The payload of row `row`.
    fn data(&self, row: i64) -> Result<Vec<u8>, BagError> {
        let mut s = self
            .conn
            .prepare_cached("SELECT data FROM messages WHERE id = ?1")
            .map_err(|e| self.sql_error(e))?;
        s.query_row([row], |r| {
            Ok(match r.get_ref(0)? {
                ValueRef::Blob(b) => Ok(b.to_vec()),
                other => Err(other.data_type()),
            })
        })
        .map_err(|e| self.row_error(row, "data", e))?
        .map_err(|t| {
            BagError::new(
                Location::row(&self.name, row),
                format!("rosbag2 messages field data: expected a BLOB, found {t}"),
            )
        })
    }
}

/// The messages of one `.db3` file, in `timestamp`, row id order.
pub(super) struct Db3Messages<'a> {
    file: &'a Db3File,
    rows: std::vec::IntoIter<(i64, usize, u64)>,
}

impl Iterator for Db3Messages<'_> {
    type Item = Result<Message, BagError>;

    fn next(&mut self) -> Option<Self::Item> {
        let (row, topic, log_time_ns) = self.rows.next()?;
        Some(self.file.data(row).map(|data| Message {
            topic,
            log_time_ns,
            data,
            at: Location::row(&self.file.name, row),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const META: &str = "\
rosbag2_bagfile_information:
  version: 5
  storage_identifier: sqlite3
  duration:
    nanoseconds: 10
  relative_file_paths:
    - run_0.db3
    - run/run_1.db3
  topics_with_message_count:
    - topic_metadata:
        name: /points
        type: sensor_msgs/msg/PointCloud2
        serialization_format: cdr
        offered_qos_profiles: \"\"
      message_count: 3
  compression_format: \"\"
  compression_mode: \"\"
";

    #[test]
    fn metadata_fields() {
        let m = parse_metadata(META).unwrap();
        assert_eq!(m.storage, Storage::Sqlite3);
        assert_eq!(m.files, ["run_0.db3", "run_1.db3"]);
        assert_eq!(
            m.topics,
            [(
                "/points".to_string(),
                "sensor_msgs/msg/PointCloud2".to_string(),
                "cdr".to_string(),
                Some(3)
            )]
        );
        assert!(!m.compressed_messages);
        let zstd = META.replace(
            "compression_format: \"\"\n  compression_mode: \"\"",
            "compression_format: zstd\n  compression_mode: MESSAGE",
        );
        assert!(parse_metadata(&zstd).unwrap().compressed_messages);
    }

    #[test]
    fn metadata_errors_name_the_field() {
        let cases = [
            (
                META.replace("version: 5", "version: 10"),
                "version: expected a version 1..9, found 10",
            ),
            (
                META.replace("sqlite3", "rosbag_v1"),
                "storage_identifier: expected sqlite3 or mcap, found \"rosbag_v1\"",
            ),
            (
                META.replace("message_count: 3", "message_count: -3"),
                "topics_with_message_count[0].message_count: expected a count, found -3",
            ),
            (
                META.replace("compression_mode: \"\"", "compression_mode: FILE"),
                "compression_format: expected zstd (with compression_mode FILE)",
            ),
            (
                META.replace("compression_mode: \"\"", "compression_mode: MESSAGE"),
                "compression_format: expected zstd",
            ),
            (
                "rosbag2_bagfile_information: [1".to_string(),
                "rosbag2 metadata: line ",
            ),
            (
                "other: 1".to_string(),
                "expected a mapping rosbag2_bagfile_information, found nothing",
            ),
            (
                META.replace("    - run_0.db3\n    - run/run_1.db3\n", ""),
                "relative_file_paths: expected at least one file",
            ),
        ];
        for (text, want) in cases {
            let e = parse_metadata(&text).unwrap_err();
            assert!(e.contains(want), "{e}\n(wanted {want})");
        }
    }

    #[test]
    fn not_a_database() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("junk.db3");
        std::fs::write(
            &path,
            b"this is not sqlite at all, just some bytes to look at...........",
        )
        .unwrap();
        let e = Bag::open(&path).err().unwrap().to_string();
        assert!(e.starts_with(&format!("{}: not a rosbag2 database (expected tables topics and messages, found a file SQLite does not read", path.display())), "{e}");
        let path = dir.path().join("other.db3");
        let conn = Connection::open(&path).unwrap();
        conn.execute_batch("CREATE TABLE things(id INTEGER); CREATE TABLE topics(id INTEGER);")
            .unwrap();
        drop(conn);
        let e = Bag::open(&path).err().unwrap().to_string();
        assert!(e.ends_with("not a rosbag2 database (expected tables topics and messages, found tables things, topics)"), "{e}");
        let e = Bag::open(&dir.path().join("missing.db3"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("missing.db3: opening: "), "{e}");
        let e = Bag::open(dir.path()).err().unwrap().to_string();
        assert!(e.contains("not a rosbag2 directory"), "{e}");
    }

    #[test]
    fn hand_made_database_in_time_order_with_bad_rows() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.db3");
        let conn = Connection::open(&path).unwrap();
        conn.execute_batch(
            "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
                 serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);
             CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
                 timestamp INTEGER NOT NULL, data BLOB);
             INSERT INTO topics VALUES (1, '/a', 'std_msgs/msg/String', 'cdr', ''),
                                       (2, '/b', 'std_msgs/msg/String', 'cdr', '');
             INSERT INTO messages VALUES (1, 1, 30, x'03'), (2, 2, 10, x'01'), (3, 1, 10, x'02'),
                                         (4, 2, 20, NULL);",
        )
        .unwrap();
        drop(conn);
        let mut bag = Bag::open(&path).unwrap();
        assert_eq!(bag.topics().len(), 2);
        assert_eq!(bag.topics()[0].messages, Some(2));
        assert_eq!(bag.topics()[1].messages, Some(2));
        let stop = std::sync::atomic::AtomicBool::new(false);
        let got: Vec<_> = bag
            .messages(&[0], &stop)
            .unwrap()
            .map(|m| m.map(|m| (m.log_time_ns, m.data, m.at.row)))
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(got, [(10, vec![2], Some(3)), (30, vec![3], Some(1))]);
        let all: Vec<_> = bag.messages(&[0, 1], &stop).unwrap().collect();
        assert_eq!(all.len(), 3, "ends after the error");
        assert_eq!(all[0].as_ref().unwrap().data, [1]);
        assert_eq!(all[1].as_ref().unwrap().data, [2]);
        let e = all[2].as_ref().unwrap_err().to_string();
        assert_eq!(
            e,
            format!(
                "{}: row 4: rosbag2 messages field data: expected a BLOB, found Null",
                path.display()
            )
        );
    }
}
