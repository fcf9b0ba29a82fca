//! The MCAP record walk: records read one at a time from a `Read + Seek` input, chunks
//! decompressed (zstd, lz4 frame) into a buffer reused between chunks, and checked (size, CRC).
//!
//! Only the records that matter are parsed (Header, Schema, Channel, Message, Chunk, Statistics,
//! Footer); everything else is skipped by its length. Offsets in errors are file offsets, or,
//! inside a compressed chunk, the chunk record's offset and the offset in its decompressed
//! records. Never panics; a record's length must fit in the bytes left before anything is
//! allocated for it.

use std::collections::HashMap;
use std::io::{self, BufReader, Cursor, Read, Seek, SeekFrom};
use std::sync::atomic::{AtomicBool, Ordering};

use ::mcap::records::op;

use super::{BagError, Location, MAX_CHUNK_BYTES, Message, Topic};
use rovlink_octo::ParseError;

/// MCAP's magic bytes, at the start and at the end of a file.
const MAGIC: &[u8] = ::mcap::MAGIC;
/// A Footer record (opcode, length, 20 bytes of body) and the closing magic.
const FOOTER_AND_MAGIC: u64 = 9 + 20 + 8;
/// Records skipped by reading (rather than seeking, which empties the read buffer) up to this.
const SKIP_BY_READING: u64 = 64 * 1024;

fn err(offset: u64, message: impl Into<String>) -> ParseError {
    ParseError::new(offset, message)
}

/// The first bytes of `bytes` in hex, for error messages.
pub(crate) fn hex(bytes: &[u8]) -> String {
    let mut s = bytes
        .iter()
        .take(8)
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ");
    if s.is_empty() {
        s.push_str("nothing");
    }
    s
}

/// `text` quoted for an error message, cut to a readable length.
fn shown(text: &[u8]) -> String {
    const MAX: usize = 40;
    let cut = text.get(..text.len().min(MAX)).unwrap_or(text);
    let mut s = format!("{:?}", String::from_utf8_lossy(cut));
    if text.len() > MAX {
        s.push_str("...");
    }
    s
}

/// Little-endian fields of one record's body, with errors at their offsets.
struct Fields<'a> {
    body: &'a [u8],
    pos: usize,
    /// Offset of `body[0]`.
    base: u64,
    record: &'static str,
}

impl<'a> Fields<'a> {
    fn new(body: &'a [u8], base: u64, record: &'static str) -> Self {
        Fields {
            body,
            pos: 0,
            base,
            record,
        }
    }

    fn offset(&self) -> u64 {
        self.base + self.pos as u64
    }

    fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8], ParseError> {
        self.take_counted(n, field, self.offset())
    }

    /// `n` bytes; an error is reported at `at` (where the count was read).
    fn take_counted(&mut self, n: usize, field: &str, at: u64) -> Result<&'a [u8], ParseError> {
        let rest = self.body.get(self.pos..).unwrap_or_default();
        let Some(s) = rest.get(..n) else {
            return Err(err(
                at,
                format!(
                    "MCAP {} record field {field}: expected {n} bytes, found {}",
                    self.record,
                    rest.len()
                ),
            ));
        };
        self.pos += n;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, field: &str) -> Result<[u8; N], ParseError> {
        let s = self.take(N, field)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    fn u16(&mut self, field: &str) -> Result<u16, ParseError> {
        self.array(field).map(u16::from_le_bytes)
    }

    fn u32(&mut self, field: &str) -> Result<u32, ParseError> {
        self.array(field).map(u32::from_le_bytes)
    }

    fn u64(&mut self, field: &str) -> Result<u64, ParseError> {
        self.array(field).map(u64::from_le_bytes)
    }

    /// Bytes after a `u32` length.
    fn bytes32(&mut self, field: &str) -> Result<&'a [u8], ParseError> {
        let at = self.offset();
        let n = self.u32(field)?;
        self.take_counted(n as usize, field, at)
    }

    /// Bytes after a `u64` length.
    fn bytes64(&mut self, field: &str) -> Result<&'a [u8], ParseError> {
        let at = self.offset();
        let n = self.u64(field)?;
        self.take_counted(usize::try_from(n).unwrap_or(usize::MAX), field, at)
    }

    fn string(&mut self, field: &str) -> Result<&'a str, ParseError> {
        let at = self.offset();
        let b = self.bytes32(field)?;
        std::str::from_utf8(b).map_err(|_| {
            err(
                at,
                format!(
                    "MCAP {} record field {field}: expected UTF-8 text, found {}",
                    self.record,
                    shown(b)
                ),
            )
        })
    }
}

/// One record inside a buffer: its opcode and body, and the body's offset in the buffer.
struct Record<'a> {
    opcode: u8,
    at: usize,
    body: &'a [u8],
}

/// The record at `pos` of `bytes` (which ends at `end`), `None` at `end`.
fn record_at(bytes: &[u8], pos: usize, end: usize) -> Result<Option<Record<'_>>, ParseError> {
    if pos >= end {
        return Ok(None);
    }
    let Some(head) = bytes.get(pos..end).and_then(|b| b.get(..9)) else {
        return Err(short_head(pos as u64, (end - pos) as u64));
    };
    let opcode = head[0];
    let mut len = [0u8; 8];
    len.copy_from_slice(&head[1..]);
    let len = u64::from_le_bytes(len);
    let available = (end - pos - 9) as u64;
    if len > available {
        return Err(too_long(pos as u64, opcode, available, len));
    }
    let at = pos + 9;
    Ok(bytes
        .get(at..at + len as usize)
        .map(|body| Record { opcode, at, body }))
}

fn short_head(pos: u64, left: u64) -> ParseError {
    err(
        pos,
        format!("MCAP record: expected 9 bytes (opcode, u64 length), found {left}"),
    )
}

fn too_long(pos: u64, opcode: u8, available: u64, len: u64) -> ParseError {
    err(
        pos + 1,
        format!(
            "MCAP record 0x{opcode:02x} length: expected at most the {available} bytes left, \
             found {len}"
        ),
    )
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct SchemaDef {
    name: String,
    encoding: String,
    data: Vec<u8>,
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct ChannelDef {
    schema_id: u16,
    topic: String,
    encoding: String,
    metadata: Vec<u8>,
}

/// A channel of the file and the topic (in the bag's list) its messages belong to.
struct Known {
    def: ChannelDef,
    topic: usize,
}

/// Anything the walk reads from.
trait Input: Read + Seek + Send {}
impl<T: Read + Seek + Send> Input for T {}

/// One MCAP file of a bag: its input, where its data section ends, and its channels.
pub(crate) struct McapFile {
    name: String,
    input: Box<dyn Input>,
    /// Where `input` is (reads in file order never seek); `None` after a failed read.
    input_at: Option<u64>,
    len: u64,
    /// Where the records after the Header end: a valid Footer's offset or the summary's start.
    /// `None` when the file has no valid Footer at its end: then the walk must find one.
    data_end: Option<u64>,
    known: HashMap<u16, Known>,
}

/// The bag's topic for (name, schema, encoding), added when new; its index.
pub(crate) fn topic_index(
    topics: &mut Vec<Topic>,
    name: &str,
    schema: &str,
    encoding: &str,
) -> usize {
    if let Some(i) = topics
        .iter()
        .position(|t| t.name == name && t.schema == schema && t.encoding == encoding)
    {
        return i;
    }
    topics.push(Topic {
        name: name.to_string(),
        schema: schema.to_string(),
        encoding: encoding.to_string(),
        messages: None,
    });
    topics.len() - 1
}

impl McapFile {
    /// The MCAP file at `path`, named `name` in errors; its channels are added to `topics`
    /// (with their message counts when `count` and the file says).
    pub(crate) fn open(
        name: &str,
        path: &std::path::Path,
        topics: &mut Vec<Topic>,
        count: bool,
        stop: &AtomicBool,
    ) -> Result<McapFile, BagError> {
        let file = rovlink_base::io::open_regular(path)
            .map_err(|e| BagError::io(Location::file(name), "opening", e))?;
        Self::new(
            name,
            Box::new(BufReader::with_capacity(1 << 16, file)),
            topics,
            count,
            stop,
        )
    }

    /// An MCAP file in memory.
    pub(crate) fn from_bytes(
        name: &str,
        bytes: Vec<u8>,
        topics: &mut Vec<Topic>,
        stop: &AtomicBool,
    ) -> Result<McapFile, BagError> {
        Self::new(name, Box::new(Cursor::new(bytes)), topics, true, stop)
    }

    pub(crate) fn name(&self) -> &str {
        &self.name
    }

    fn new(
        name: &str,
        mut input: Box<dyn Input>,
        topics: &mut Vec<Topic>,
        count: bool,
        stop: &AtomicBool,
    ) -> Result<McapFile, BagError> {
        let io = |e| BagError::io(Location::file(name), "reading", e);
        let len = input.seek(SeekFrom::End(0)).map_err(io)?;
        let mut file = McapFile {
            name: name.to_string(),
            input,
            input_at: Some(len),
            len,
            data_end: None,
            known: HashMap::new(),
        };
        let at = |e: ParseError| BagError::new(Location::offset(name, e.offset), e.message);
        let header_end = file.header().map_err(at)?;
        let mut found = Found::default();
        if let Some((footer_at, summary_start)) = file.footer(header_end).map_err(at)? {
            file.data_end = Some(footer_at);
            if summary_start != 0 {
                file.summary(summary_start, footer_at, &mut found)
                    .map_err(at)?;
                file.data_end = Some(summary_start);
                if found.channels.is_empty() {
                    found = Found::default();
                }
            }
        }
        if found.channels.is_empty() {
            // No summary to trust: a first walk over the file finds the channels and counts.
            let mut walk = Walk::new(true);
            while walk.next(&mut file, &[], Some(stop))?.is_some() {}
            if stop.load(Ordering::Relaxed) {
                return Err(BagError::new(
                    Location::file(name),
                    "stopped (by a signal) during the first walk over the file",
                ));
            }
            found = walk.found;
            found.counted = true;
        }
        for (id, def, schema) in found.channels {
            let topic = topic_index(topics, &def.topic, &schema, &def.encoding);
            if count && found.counted {
                let n = found.counts.get(&id).copied().unwrap_or(0);
                if let Some(t) = topics.get_mut(topic) {
                    t.messages = Some(t.messages.unwrap_or(0).saturating_add(n));
                }
            }
            file.known.insert(id, Known { def, topic });
        }
        Ok(file)
    }

    /// Reads exactly `buf.len()` bytes at `pos`.
    fn read_at(&mut self, pos: u64, buf: &mut [u8]) -> Result<(), ParseError> {
        let seek = if self.input_at == Some(pos) {
            Ok(pos)
        } else {
            self.input.seek(SeekFrom::Start(pos))
        };
        self.input_at = None;
        seek.and_then(|_| self.input.read_exact(buf))
            .map_err(|e| err(pos, format!("reading: {e}")))?;
        self.input_at = Some(pos + buf.len() as u64);
        Ok(())
    }

    /// Checks the magic and the Header record; the Header's end.
    fn header(&mut self) -> Result<u64, ParseError> {
        let mut head = [0u8; 8];
        let n = self.len.min(8) as usize;
        self.read_at(0, &mut head[..n])?;
        if &head[..n] != MAGIC {
            return Err(err(
                0,
                format!(
                    "MCAP magic: expected {}, found {}",
                    hex(MAGIC),
                    hex(&head[..n])
                ),
            ));
        }
        let pos = MAGIC.len() as u64;
        let Some((opcode, len)) = self.head(pos, self.len)? else {
            return Err(no_footer(pos));
        };
        if opcode != op::HEADER {
            return Err(err(
                pos,
                format!(
                    "MCAP: expected a Header record (opcode 0x01) first, found opcode \
                     0x{opcode:02x}"
                ),
            ));
        }
        Ok(pos + 9 + len)
    }

    /// The opcode and length of the record at `pos` (before `end`), `None` at `end`.
    fn head(&mut self, pos: u64, end: u64) -> Result<Option<(u8, u64)>, ParseError> {
        if pos >= end {
            return Ok(None);
        }
        let left = end - pos;
        if left < 9 {
            return Err(short_head(pos, left));
        }
        let mut head = [0u8; 9];
        self.read_at(pos, &mut head)?;
        let mut len = [0u8; 8];
        len.copy_from_slice(&head[1..]);
        let len = u64::from_le_bytes(len);
        if len > left - 9 {
            return Err(too_long(pos, head[0], left - 9, len));
        }
        Ok(Some((head[0], len)))
    }

    /// A valid Footer record and closing magic at the end: the Footer's offset and its
    /// `summary_start` (checked to lie between the Header's end and the Footer).
    fn footer(&mut self, header_end: u64) -> Result<Option<(u64, u64)>, ParseError> {
        let Some(footer_at) = self.len.checked_sub(FOOTER_AND_MAGIC) else {
            return Ok(None);
        };
        if footer_at < header_end {
            return Ok(None);
        }
        let mut tail = [0u8; FOOTER_AND_MAGIC as usize];
        self.read_at(footer_at, &mut tail)?;
        let (record, magic) = tail.split_at(29);
        if magic != MAGIC || record[0] != op::FOOTER || record[1..9] != 20u64.to_le_bytes() {
            return Ok(None);
        }
        let mut f = Fields::new(&record[9..], footer_at + 9, "Footer");
        let start_at = f.offset();
        let summary_start = f.u64("summary_start")?;
        if summary_start != 0 && !(header_end..=footer_at).contains(&summary_start) {
            return Err(err(
                start_at,
                format!(
                    "MCAP Footer record field summary_start: expected 0 or an offset in \
                     {header_end}..={footer_at}, found {summary_start}"
                ),
            ));
        }
        Ok(Some((footer_at, summary_start)))
    }

    /// The summary section's schemas, channels and statistics.
    fn summary(&mut self, start: u64, end: u64, found: &mut Found) -> Result<(), ParseError> {
        let mut state = State::new(true);
        let mut pos = start;
        let mut body = Vec::new();
        while let Some((opcode, len)) = self.head(pos, end)? {
            let at = pos + 9;
            if matches!(opcode, op::SCHEMA | op::CHANNEL | op::STATISTICS) {
                body.resize(len as usize, 0);
                self.read_at(at, &mut body)?;
                if opcode == op::STATISTICS {
                    statistics(&body, at, &mut found.counts)?;
                    found.counted = true;
                } else {
                    state.record(opcode, at, &body, &self.known, &[])?;
                }
            }
            pos = at + len;
        }
        found.channels = state.found_channels();
        Ok(())
    }

    /// The messages of the topics `wanted` (by index in the bag's topics), in file order.
    pub(crate) fn messages<'a>(
        &'a mut self,
        wanted: Vec<bool>,
        stop: &'a AtomicBool,
    ) -> Result<McapMessages<'a>, BagError> {
        let walk = Walk::new(false);
        Ok(McapMessages {
            file: self,
            walk,
            wanted,
            stop,
        })
    }
}

fn no_footer(pos: u64) -> ParseError {
    err(
        pos,
        "MCAP: expected a Footer record and the closing magic, found end of input",
    )
}

/// `channel_message_counts` of a Statistics record, added to `counts`.
fn statistics(body: &[u8], at: u64, counts: &mut HashMap<u16, u64>) -> Result<(), ParseError> {
    let mut f = Fields::new(body, at, "Statistics");
    f.take(8 + 2 + 4 * 4 + 8 + 8, "message_count..message_end_time")?;
    let map_at = f.offset();
    let map = f.bytes32("channel_message_counts")?;
    if map.len() % 10 != 0 {
        return Err(err(
            map_at,
            format!(
                "MCAP Statistics record field channel_message_counts: expected a multiple of 10 \
                 bytes (u16 channel id, u64 count), found {}",
                map.len()
            ),
        ));
    }
    let mut f = Fields::new(map, map_at + 4, "Statistics");
    while f.pos < map.len() {
        let id = f.u16("channel_message_counts id")?;
        let n = f.u64("channel_message_counts count")?;
        counts.insert(id, n);
    }
    Ok(())
}

/// Channels (id, definition, schema name) and message counts found by the summary or a walk.
#[derive(Default)]
struct Found {
    channels: Vec<(u16, ChannelDef, String)>,
    counts: HashMap<u16, u64>,
    /// Whether `counts` is complete (a walk counted, or a Statistics record said).
    counted: bool,
}

/// What one walk has seen: the schemas and channels defined so far (a record must be defined
/// before it is used, and a repeat must be identical).
struct State {
    schemas: HashMap<u16, SchemaDef>,
    channels: HashMap<u16, ChannelDef>,
    /// Channel ids in the order first seen.
    order: Vec<u16>,
    /// First walk or summary: every channel is new to the file (nothing is checked against
    /// `known`), and messages are counted.
    collect: bool,
    counts: HashMap<u16, u64>,
}

impl State {
    fn new(collect: bool) -> State {
        State {
            schemas: HashMap::new(),
            channels: HashMap::new(),
            order: Vec::new(),
            collect,
            counts: HashMap::new(),
        }
    }

    fn found_channels(&mut self) -> Vec<(u16, ChannelDef, String)> {
        let mut out = Vec::new();
        for id in &self.order {
            if let Some(def) = self.channels.remove(id) {
                let schema = self
                    .schemas
                    .get(&def.schema_id)
                    .map(|s| s.name.clone())
                    .unwrap_or_default();
                out.push((*id, def, schema));
            }
        }
        out
    }

    /// Handles a Schema, Channel or Message record whose body is at offset `at` (others are
    /// ignored). A Message of a `wanted` topic: its topic and log time, and where its data
    /// starts in `body`.
    fn record(
        &mut self,
        opcode: u8,
        at: u64,
        body: &[u8],
        known: &HashMap<u16, Known>,
        wanted: &[bool],
    ) -> Result<Option<(usize, u64, usize)>, ParseError> {
        match opcode {
            op::SCHEMA => {
                let mut f = Fields::new(body, at, "Schema");
                let id = f.u16("id")?;
                let schema = SchemaDef {
                    name: f.string("name")?.to_string(),
                    encoding: f.string("encoding")?.to_string(),
                    data: f.bytes32("data")?.to_vec(),
                };
                if id == 0 {
                    return Err(err(
                        at,
                        "MCAP Schema record field id: expected 1..65535, found 0",
                    ));
                }
                match self.schemas.get(&id) {
                    Some(s) if *s != schema => {
                        return Err(err(
                            at,
                            format!(
                                "MCAP Schema record {id}: expected the content of its earlier \
                                 record, found different content"
                            ),
                        ));
                    }
                    Some(_) => {}
                    None => {
                        self.schemas.insert(id, schema);
                    }
                }
            }
            op::CHANNEL => {
                let mut f = Fields::new(body, at, "Channel");
                let id = f.u16("id")?;
                let schema_at = f.offset();
                let schema_id = f.u16("schema_id")?;
                let channel = ChannelDef {
                    schema_id,
                    topic: f.string("topic")?.to_string(),
                    encoding: f.string("message_encoding")?.to_string(),
                    metadata: f.bytes32("metadata")?.to_vec(),
                };
                if schema_id != 0 && !self.schemas.contains_key(&schema_id) {
                    return Err(err(
                        schema_at,
                        format!(
                            "MCAP Channel record field schema_id: expected a schema defined \
                             earlier (or 0), found {schema_id}"
                        ),
                    ));
                }
                if let Some(c) = self.channels.get(&id) {
                    if *c != channel {
                        return Err(err(
                            at,
                            format!(
                                "MCAP Channel record {id}: expected the content of its earlier \
                                 record, found different content"
                            ),
                        ));
                    }
                    return Ok(None);
                }
                if !self.collect {
                    match known.get(&id) {
                        Some(k) if k.def == channel => {}
                        Some(_) => {
                            return Err(err(
                                at,
                                format!(
                                    "MCAP Channel record {id}: expected the content of its \
                                     record in the summary section, found different content"
                                ),
                            ));
                        }
                        None => {
                            return Err(err(
                                at,
                                format!(
                                    "MCAP Channel record {id} (topic {:?}): expected a channel \
                                     listed in the summary section, found one it does not list",
                                    channel.topic
                                ),
                            ));
                        }
                    }
                }
                self.order.push(id);
                self.channels.insert(id, channel);
            }
            op::MESSAGE => {
                let mut f = Fields::new(body, at, "Message");
                let channel = f.u16("channel_id")?;
                f.u32("sequence")?;
                let log_time = f.u64("log_time")?;
                f.u64("publish_time")?;
                if !self.channels.contains_key(&channel) {
                    return Err(err(
                        at,
                        format!(
                            "MCAP Message record field channel_id: expected a channel defined \
                             earlier, found {channel}"
                        ),
                    ));
                }
                if self.collect {
                    *self.counts.entry(channel).or_insert(0) += 1;
                } else if let Some(k) = known.get(&channel)
                    && wanted.get(k.topic).copied().unwrap_or(false)
                {
                    return Ok(Some((k.topic, log_time, f.pos)));
                }
            }
            _ => {}
        }
        Ok(None)
    }
}

/// The chunk being walked: its records are `records[pos..end]` of the walk's decompressed
/// buffer (compressed chunks) or of its record buffer (uncompressed ones).
struct Chunk {
    pos: usize,
    end: usize,
    /// Compressed: the chunk record's file offset (records' offsets are in the decompressed
    /// bytes). Uncompressed: `None`, and `base` is the file offset of the record buffer.
    compressed_at: Option<u64>,
    base: u64,
}

/// One pass over a file's records.
struct Walk {
    pos: u64,
    state: State,
    chunk: Option<Chunk>,
    /// The current record's body (a chunk, still compressed).
    body: Vec<u8>,
    /// The current chunk's records, decompressed; reused between chunks.
    records: Vec<u8>,
    /// Small records read past (message indexes), apart from `body`: shrunk to one of them,
    /// `body` would be zeroed whole again for the next chunk.
    skipped: Vec<u8>,
    done: bool,
    /// What a collecting walk found.
    found: Found,
}

impl Walk {
    fn new(collect: bool) -> Walk {
        Walk {
            pos: MAGIC.len() as u64,
            state: State::new(collect),
            chunk: None,
            body: Vec::new(),
            records: Vec::new(),
            skipped: Vec::new(),
            done: false,
            found: Found::default(),
        }
    }

    /// The next message of a wanted topic (none when collecting), `None` at the end (or once
    /// `stop` is set).
    fn next(
        &mut self,
        file: &mut McapFile,
        wanted: &[bool],
        stop: Option<&AtomicBool>,
    ) -> Result<Option<Message>, BagError> {
        if self.done {
            return Ok(None);
        }
        let r = self.step(file, wanted, stop);
        if !matches!(r, Ok(Some(_))) {
            self.done = true;
        }
        if self.state.collect && matches!(r, Ok(None)) {
            self.found.channels = self.state.found_channels();
            self.found.counts = std::mem::take(&mut self.state.counts);
        }
        r
    }

    fn step(
        &mut self,
        file: &mut McapFile,
        wanted: &[bool],
        stop: Option<&AtomicBool>,
    ) -> Result<Option<Message>, BagError> {
        let name = file.name.clone();
        loop {
            // Also inside a chunk: a decompressed chunk of a million small records is a long walk.
            if stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
                return Ok(None);
            }
            if let Some(chunk) = &mut self.chunk {
                let buf = if chunk.compressed_at.is_some() {
                    &self.records
                } else {
                    &self.body
                };
                let place = |offset: u64| match chunk.compressed_at {
                    Some(c) => Location {
                        offset: Some(c),
                        inner: Some(offset),
                        ..Location::file(&name)
                    },
                    None => Location::offset(&name, chunk.base + offset),
                };
                let in_chunk = |e: ParseError| BagError::new(place(e.offset), e.message);
                match record_at(buf, chunk.pos, chunk.end).map_err(in_chunk)? {
                    None => self.chunk = None,
                    Some(Record { opcode, at, body }) => {
                        chunk.pos = at + body.len();
                        // Only schemas, channels and messages belong in a chunk; anything else
                        // (a chunk in a chunk) is skipped.
                        if opcode != op::CHUNK
                            && let Some((topic, log_time_ns, data)) = self
                                .state
                                .record(opcode, at as u64, body, &file.known, wanted)
                                .map_err(in_chunk)?
                        {
                            return Ok(Some(Message {
                                topic,
                                log_time_ns,
                                data: body.get(data..).unwrap_or_default().to_vec(),
                                at: place((at + data) as u64),
                            }));
                        }
                    }
                }
                continue;
            }
            let at_file =
                |e: ParseError| BagError::new(Location::offset(&name, e.offset), e.message);
            let end = file.data_end.unwrap_or(file.len);
            let pos = self.pos;
            let Some((opcode, len)) = file.head(pos, end).map_err(at_file)? else {
                if file.data_end.is_some() {
                    return Ok(None);
                }
                return Err(at_file(no_footer(pos)));
            };
            let at = pos + 9;
            let next = at + len;
            self.pos = next;
            match opcode {
                op::FOOTER => {
                    let mut tail = [0u8; 9];
                    let n = (file.len - next).min(9) as usize;
                    file.read_at(next, &mut tail[..n]).map_err(at_file)?;
                    if file.len - next != 8 || &tail[..n] != MAGIC {
                        let left = file.len - next;
                        return Err(at_file(err(
                            next,
                            format!(
                                "MCAP closing magic: expected {} and the end of input, found {}{}",
                                hex(MAGIC),
                                hex(&tail[..n]),
                                if left > 8 {
                                    format!(" ({left} bytes)")
                                } else {
                                    String::new()
                                }
                            ),
                        )));
                    }
                    return Ok(None);
                }
                op::CHUNK | op::SCHEMA | op::CHANNEL | op::MESSAGE => {
                    // `len` fits in the bytes left in the input, so this is bounded by it.
                    self.body.resize(len as usize, 0);
                    file.read_at(at, &mut self.body).map_err(at_file)?;
                    if opcode == op::CHUNK {
                        self.chunk =
                            Some(open_chunk(&self.body, at, &mut self.records).map_err(at_file)?);
                        continue;
                    }
                    if let Some((topic, log_time_ns, data)) = self
                        .state
                        .record(opcode, at, &self.body, &file.known, wanted)
                        .map_err(at_file)?
                    {
                        return Ok(Some(Message {
                            topic,
                            log_time_ns,
                            data: self.body.get(data..).unwrap_or_default().to_vec(),
                            at: Location::offset(&name, at + data as u64),
                        }));
                    }
                }
                _ if len <= SKIP_BY_READING => {
                    // Small records (message indexes, after every chunk) are read past, which
                    // keeps the read buffer; the next `read_at` seeks within it.
                    self.skipped.resize(len as usize, 0);
                    file.read_at(at, &mut self.skipped).map_err(at_file)?;
                }
                _ => {}
            }
        }
    }
}

/// A Chunk record's header checked, its records decompressed into `records` when compressed;
/// where its records are.
fn open_chunk(body: &[u8], at: u64, records: &mut Vec<u8>) -> Result<Chunk, ParseError> {
    let mut f = Fields::new(body, at, "Chunk");
    f.u64("message_start_time")?;
    f.u64("message_end_time")?;
    let size_at = f.offset();
    let uncompressed_size = f.u64("uncompressed_size")?;
    let crc_at = f.offset();
    let crc = f.u32("uncompressed_crc")?;
    let compression_at = f.offset();
    let compression = f.string("compression")?;
    let data = f.bytes64("records")?;
    let start = f.pos - data.len();
    let size_error = |found: String| {
        err(
            size_at,
            format!(
                "MCAP Chunk record field uncompressed_size: expected {found}, found \
                 {uncompressed_size}"
            ),
        )
    };
    let (chunk, checked): (Chunk, &[u8]) = match compression {
        "" => {
            if uncompressed_size != data.len() as u64 {
                return Err(size_error(format!(
                    "{} (the records' length, uncompressed)",
                    data.len()
                )));
            }
            let chunk = Chunk {
                pos: start,
                end: start + data.len(),
                compressed_at: None,
                base: at,
            };
            (chunk, data)
        }
        "zstd" | "lz4" => {
            if uncompressed_size > MAX_CHUNK_BYTES {
                return Err(size_error(format!(
                    "at most {MAX_CHUNK_BYTES} (1 GiB, this reader's limit)"
                )));
            }
            let what = format!(
                "MCAP Chunk record ({compression}-compressed records at offset {})",
                at + start as u64
            );
            let r = if compression == "zstd" {
                zstd_into(data, uncompressed_size, records)
            } else {
                lz4_into(data, uncompressed_size, records)
            };
            r.map_err(|e| err(at + start as u64, format!("{what}: {e}")))?;
            if records.len() as u64 != uncompressed_size {
                return Err(size_error(format!(
                    "{} (the size the records decompress to)",
                    if records.len() as u64 > uncompressed_size {
                        format!("more than {uncompressed_size}")
                    } else {
                        records.len().to_string()
                    }
                )));
            }
            let chunk = Chunk {
                pos: 0,
                end: records.len(),
                compressed_at: Some(at - 9),
                base: 0,
            };
            (chunk, records.as_slice())
        }
        other => {
            return Err(err(
                compression_at,
                format!(
                    "MCAP Chunk record field compression: expected \"\", \"zstd\" or \"lz4\", \
                     found {:?}",
                    other
                ),
            ));
        }
    };
    if crc != 0 {
        let computed = crc32(checked);
        if computed != crc {
            return Err(err(
                crc_at,
                format!(
                    "MCAP Chunk record field uncompressed_crc: expected {computed:08x} (the \
                     records' CRC-32), found {crc:08x}"
                ),
            ));
        }
    }
    Ok(chunk)
}

/// CRC-32 (ISO HDLC, as MCAP uses), with the CPU's carry-less multiply where it has one.
fn crc32(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

/// Decompresses `input` (zstd frames) into `out` (cleared first), at most `max + 1` bytes (so a
/// caller sees when there is more than `max`). The error text says what went wrong.
pub(crate) fn zstd_into(input: &[u8], max: u64, out: &mut Vec<u8>) -> Result<(), String> {
    // A single frame that states its size (what MCAP and rosbag2 writers make) goes in one call
    // into a buffer of exactly that size: no streaming window buffer beside the output (4 MB
    // less at the peak). Anything else (several frames, no size) streams.
    out.clear();
    if let Ok(Some(size)) = zstd::zstd_safe::get_frame_content_size(input)
        && size <= max
        && let Ok(size) = usize::try_from(size)
    {
        out.reserve_exact(size);
        let whole = zstd::bulk::Decompressor::new()
            .and_then(|mut d| d.decompress_to_buffer(input, out))
            .is_ok();
        if whole && out.len() == size {
            return Ok(());
        }
        out.clear();
    }
    let decoder =
        zstd::stream::read::Decoder::with_buffer(input).map_err(|e| format!("zstd: {e}"))?;
    read_limited(decoder, max, out).map_err(|e| format!("zstd: {e}"))
}

/// Decompresses `input` (LZ4 frames) into `out`, as [`zstd_into`].
///
/// The decoder stops quietly when the input ends where a block size (or the end mark) should
/// be, so the frame's end is checked here: its last 4 bytes (before the content checksum, when
/// the frame descriptor's flag says there is one) must be the end mark, zero.
fn lz4_into(input: &[u8], max: u64, out: &mut Vec<u8>) -> Result<(), String> {
    read_limited(lz4_flex::frame::FrameDecoder::new(input), max, out)
        .map_err(|e| format!("lz4 frame: {e}"))?;
    let checksum = input.get(4).is_some_and(|flg| flg & 0x04 != 0);
    let end = input.len().saturating_sub(if checksum { 4 } else { 0 });
    let mark = input.get(end.saturating_sub(4)..end);
    if mark != Some(&[0u8; 4][..]) {
        return Err(format!(
            "lz4 frame: expected the end mark (4 zero bytes) at the end, found {}",
            mark.map_or_else(|| "too few bytes".to_string(), hex)
        ));
    }
    Ok(())
}

fn read_limited(reader: impl Read, max: u64, out: &mut Vec<u8>) -> io::Result<()> {
    out.clear();
    // Room for exactly what the chunk says (and the one byte that shows it lied), so the buffer
    // is one chunk, not read_to_end's doubling of it; claims above 256 MiB grow as they prove true.
    let want = usize::try_from(max.saturating_add(1).min(1 << 28)).unwrap_or(1 << 28);
    out.reserve_exact(want);
    reader.take(max.saturating_add(1)).read_to_end(out)?;
    Ok(())
}

/// The messages of one MCAP file, in file order.
pub(crate) struct McapMessages<'a> {
    file: &'a mut McapFile,
    walk: Walk,
    wanted: Vec<bool>,
    stop: &'a AtomicBool,
}

impl Iterator for McapMessages<'_> {
    type Item = Result<Message, BagError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.stop.load(Ordering::Relaxed) {
            return None;
        }
        self.walk
            .next(self.file, &self.wanted, Some(self.stop))
            .transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bag::Bag;

    fn rec(out: &mut Vec<u8>, opcode: u8, body: &[u8]) {
        out.push(opcode);
        out.extend((body.len() as u64).to_le_bytes());
        out.extend_from_slice(body);
    }

    fn string(s: &str) -> Vec<u8> {
        let mut v = (s.len() as u32).to_le_bytes().to_vec();
        v.extend_from_slice(s.as_bytes());
        v
    }

    /// Schema 1, channel 1 on `/t` (cdr), and messages with payloads `[i; 3]` at log time i.
    fn records(messages: u8) -> Vec<u8> {
        let mut out = Vec::new();
        let mut b = 1u16.to_le_bytes().to_vec();
        b.extend(string("std_msgs/msg/String"));
        b.extend(string("ros2msg"));
        b.extend(string(""));
        rec(&mut out, op::SCHEMA, &b);
        let mut b = 1u16.to_le_bytes().to_vec();
        b.extend(1u16.to_le_bytes());
        b.extend(string("/t"));
        b.extend(string("cdr"));
        b.extend(0u32.to_le_bytes());
        rec(&mut out, op::CHANNEL, &b);
        for i in 0..messages {
            let mut b = 1u16.to_le_bytes().to_vec();
            b.extend(0u32.to_le_bytes());
            b.extend(u64::from(i).to_le_bytes());
            b.extend(u64::from(i).to_le_bytes());
            b.extend([i; 3]);
            rec(&mut out, op::MESSAGE, &b);
        }
        out
    }

    /// Offset of the chunk record in [`file`]: after the magic and the 8-byte Header.
    const CHUNK_AT: u64 = 8 + 9 + 8;

    /// A file of one chunk: `compressed` (the records as stored), with the given size and CRC
    /// fields.
    fn file(compression: &str, compressed: &[u8], size: u64, crc: u32) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        rec(&mut out, op::HEADER, &[0; 8]);
        let mut b = Vec::new();
        b.extend(0u64.to_le_bytes());
        b.extend(0u64.to_le_bytes());
        b.extend(size.to_le_bytes());
        b.extend(crc.to_le_bytes());
        b.extend(string(compression));
        b.extend((compressed.len() as u64).to_le_bytes());
        b.extend_from_slice(compressed);
        rec(&mut out, op::CHUNK, &b);
        rec(&mut out, op::FOOTER, &[0; 20]);
        out.extend_from_slice(MAGIC);
        out
    }

    /// Offsets of a chunk's fields in [`file`].
    const SIZE_AT: u64 = CHUNK_AT + 9 + 16;
    const CRC_AT: u64 = SIZE_AT + 8;
    const COMPRESSION_AT: u64 = CRC_AT + 4;

    fn records_at(compression: &str) -> u64 {
        COMPRESSION_AT + 4 + compression.len() as u64 + 8
    }

    fn zstd(data: &[u8]) -> Vec<u8> {
        zstd::bulk::compress(data, 3).unwrap()
    }

    fn lz4(data: &[u8]) -> Vec<u8> {
        let mut w = lz4_flex::frame::FrameEncoder::new(Vec::new());
        std::io::Write::write_all(&mut w, data).unwrap();
        w.finish().unwrap()
    }

    fn read_all(bytes: Vec<u8>) -> Result<Vec<(u64, Vec<u8>, Location)>, BagError> {
        let mut bag = Bag::from_mcap_bytes("f.mcap", bytes)?;
        let all: Vec<usize> = (0..bag.topics().len()).collect();
        let stop = AtomicBool::new(false);
        bag.messages(&all, &stop)?
            .map(|m| m.map(|m| (m.log_time_ns, m.data, m.at)))
            .collect()
    }

    fn error(bytes: Vec<u8>) -> (Location, String) {
        let e = read_all(bytes).unwrap_err();
        (e.at, e.message)
    }

    #[test]
    fn chunk_crc_is_crc32_iso_hdlc() {
        // The catalogue's check value of CRC-32/ISO-HDLC.
        assert_eq!(crc32(b"123456789"), 0xcbf4_3926);
    }

    #[test]
    fn compressed_chunks_read_with_places() {
        let plain = records(3);
        let crc = crc32(&plain);
        for (compression, stored) in [
            ("", plain.clone()),
            ("zstd", zstd(&plain)),
            ("lz4", lz4(&plain)),
        ] {
            for crc in [0, crc] {
                let got = read_all(file(compression, &stored, plain.len() as u64, crc)).unwrap();
                assert_eq!(got.len(), 3, "{compression}");
                for (i, (t, data, at)) in got.iter().enumerate() {
                    assert_eq!(*t, i as u64);
                    assert_eq!(*data, vec![i as u8; 3]);
                    // The payload is where the location says.
                    let inner = (plain.len() - (3 - i) * (9 + 25) + 9 + 22) as u64;
                    if compression.is_empty() {
                        assert_eq!(at.offset, Some(records_at("") + inner));
                        assert_eq!(at.inner, None);
                    } else {
                        assert_eq!(at.offset, Some(CHUNK_AT));
                        assert_eq!(at.inner, Some(inner));
                    }
                }
            }
        }
    }

    #[test]
    fn chunk_checks_carry_offsets() {
        let plain = records(2);
        let n = plain.len() as u64;
        let good_crc = crc32(&plain);
        let cases: Vec<(Vec<u8>, u64, String)> = vec![
            (
                file("zstd", &zstd(&plain), n, good_crc ^ 1),
                CRC_AT,
                "uncompressed_crc: expected".to_string(),
            ),
            (
                file("lz4", &lz4(&plain), n, good_crc ^ 1),
                CRC_AT,
                "uncompressed_crc: expected".to_string(),
            ),
            (
                file("zstd", &zstd(&plain), n + 1, 0),
                SIZE_AT,
                format!(
                    "uncompressed_size: expected {n} (the size the records decompress to), found {}",
                    n + 1
                ),
            ),
            (
                file("lz4", &lz4(&plain), n - 1, 0),
                SIZE_AT,
                format!(
                    "uncompressed_size: expected more than {} (the size the records decompress to), found {}",
                    n - 1,
                    n - 1
                ),
            ),
            (
                file("zstd", &zstd(&plain), MAX_CHUNK_BYTES + 1, 0),
                SIZE_AT,
                "expected at most 1073741824 (1 GiB".to_string(),
            ),
            (
                file("", &plain, n + 1, 0),
                SIZE_AT,
                "(the records' length, uncompressed)".to_string(),
            ),
            (
                file("bz2", &plain, n, 0),
                COMPRESSION_AT,
                "compression: expected \"\", \"zstd\" or \"lz4\", found \"bz2\"".to_string(),
            ),
        ];
        for (bytes, at, want) in cases {
            let (loc, msg) = error(bytes);
            assert_eq!(loc.offset, Some(at), "{msg}");
            assert!(msg.contains(&want), "{msg}\n(wanted {want})");
        }
        // Truncated compressed data (the chunk's own length says where it ends).
        for (compression, stored) in [("zstd", zstd(&plain)), ("lz4", lz4(&plain))] {
            for cut in [1, stored.len() / 2, stored.len() - 1] {
                let (loc, msg) = error(file(compression, &stored[..cut], n, 0));
                assert_eq!(loc.offset, Some(records_at(compression)), "{msg}");
                assert!(
                    msg.contains(&format!("{compression}-compressed records")),
                    "{msg}"
                );
                assert_eq!(
                    loc.to_string(),
                    format!("f.mcap: offset {}", records_at(compression))
                );
            }
        }
        // A record inside a compressed chunk that runs past its end: chunk and inner offset.
        let mut bad = plain.clone();
        bad.truncate(plain.len() - 1);
        let (loc, msg) = error(file("zstd", &zstd(&bad), bad.len() as u64, 0));
        assert_eq!(loc.offset, Some(CHUNK_AT));
        assert_eq!(loc.inner, Some((plain.len() - (9 + 25) + 1) as u64));
        assert!(
            msg.contains("length: expected at most the 24 bytes left, found 25"),
            "{msg}"
        );
    }

    #[test]
    fn summary_topics_and_counts_and_stop() {
        let scans = vec![rovlink_octo::Scan::default(); 4];
        let bytes = crate::cloud::write_clouds_mcap(&scans);
        let mut bag = Bag::from_mcap_bytes("w.mcap", bytes).unwrap();
        let topics: Vec<_> = bag
            .topics()
            .iter()
            .map(|t| (t.name.as_str(), t.encoding.as_str(), t.messages))
            .collect();
        assert_eq!(
            topics,
            [("/points", "cdr", Some(4)), ("/pose", "cdr", Some(4))]
        );
        let stop = AtomicBool::new(false);
        let times: Vec<u64> = bag
            .messages(&[0, 1], &stop)
            .unwrap()
            .map(|m| m.unwrap().log_time_ns)
            .collect();
        assert_eq!(times.len(), 8);
        assert!(times.is_sorted());
        stop.store(true, Ordering::Relaxed);
        assert_eq!(bag.messages(&[0, 1], &stop).unwrap().count(), 0);
        let e = bag.messages(&[2], &stop).err().unwrap();
        assert_eq!(e.to_string(), "w.mcap: topic index: expected 0..2, found 2");
    }

    #[test]
    fn every_prefix_and_byte_flip_is_an_error_or_messages_never_a_panic() {
        let plain = records(2);
        for bytes in [
            file("zstd", &zstd(&plain), plain.len() as u64, crc32(&plain)),
            file("lz4", &lz4(&plain), plain.len() as u64, 0),
            crate::cloud::write_clouds_mcap(&[rovlink_octo::Scan::default()]),
        ] {
            for cut in 0..bytes.len() {
                assert!(read_all(bytes[..cut].to_vec()).is_err());
            }
            for i in 0..bytes.len() {
                let mut b = bytes.clone();
                b[i] ^= 0x55;
                let _ = read_all(b);
            }
        }
    }
}
