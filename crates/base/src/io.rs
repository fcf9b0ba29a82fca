//! The command-line conventions every tool shares.
//!
//! - A missing path or `-` means standard input or standard output.
//! - Output files are written atomically: to a temporary file beside the target, renamed into
//!   place only when the tool succeeds, so a failed run never leaves a half-written file.
//! - Binary output is refused when standard output is a terminal.
//! - A pipe from a live process is read through a [`StopReader`], so a signal ends a run that
//!   waits on it.
//! - Errors name the file and what went wrong; [`exit_code`] maps any error to the exit-code
//!   table (0 ok, 1 a requested check failed, 2 bad usage or input), treating a closed pipe
//!   downstream (`tool | head`) as success.

use std::fs::File;
use std::io::{self, BufReader, BufWriter, IsTerminal, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Exit code: success.
pub const EXIT_OK: u8 = 0;
/// Exit code: the tool ran, but the result failed a check the user asked for.
pub const EXIT_CHECK_FAILED: u8 = 1;
/// Exit code: bad usage or bad input.
pub const EXIT_BAD_INPUT: u8 = 2;

/// Errors of the shared I/O conventions.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// A file could not be opened or created.
    #[error("{path}: cannot open: {source}")]
    Open {
        /// The file.
        path: PathBuf,
        /// The reason.
        source: io::Error,
    },
    /// Reading failed.
    #[error("{name}: read failed: {source}")]
    Read {
        /// The file, or `<stdin>`.
        name: String,
        /// The reason.
        source: io::Error,
    },
    /// Writing failed.
    #[error("{name}: write failed: {source}")]
    Write {
        /// The file, or `<stdout>`.
        name: String,
        /// The reason.
        source: io::Error,
    },
    /// Binary output would go to a terminal.
    #[error(
        "refusing to write binary data to a terminal: redirect standard output, pipe it, or use -o FILE"
    )]
    Terminal,
}

/// A requested check failed (exit code 1): the tool ran, the result is not what was asked.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct CheckFailed(pub String);

/// The exit code for an error: 0 for a broken pipe anywhere in its chain, 1 for a
/// [`CheckFailed`], 2 for everything else.
pub fn exit_code(err: &(dyn std::error::Error + 'static)) -> u8 {
    let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(err);
    while let Some(e) = cur {
        if let Some(io) = e.downcast_ref::<io::Error>()
            && io.kind() == io::ErrorKind::BrokenPipe
        {
            return EXIT_OK;
        }
        if let Some(IoError::Write { source, .. }) = e.downcast_ref::<IoError>()
            && source.kind() == io::ErrorKind::BrokenPipe
        {
            return EXIT_OK;
        }
        if e.downcast_ref::<CheckFailed>().is_some() {
            return EXIT_CHECK_FAILED;
        }
        cur = e.source();
    }
    EXIT_BAD_INPUT
}

/// The one-line text of an error and its causes, `: `-separated, leaving out a cause whose
/// text the message before it already contains.
pub fn error_text(err: &(dyn std::error::Error + 'static)) -> String {
    let mut text = err.to_string();
    let mut cur = err.source();
    while let Some(e) = cur {
        let part = e.to_string();
        if !text.contains(&part) {
            text.push_str(": ");
            text.push_str(&part);
        }
        cur = e.source();
    }
    text
}

/// Ends a tool's `main`: maps its outcome to an exit code (see [`exit_code`]) and prints the
/// error, prefixed with the tool's name, unless it was a closed pipe downstream.
pub fn finish_main<E>(tool: &str, outcome: Result<u8, E>) -> std::process::ExitCode
where
    E: AsRef<dyn std::error::Error + 'static>,
{
    match outcome {
        Ok(code) => std::process::ExitCode::from(code),
        Err(err) => {
            let err = err.as_ref();
            let code = exit_code(err);
            if code != EXIT_OK {
                warn(tool, &error_text(err));
            }
            std::process::ExitCode::from(code)
        }
    }
}

/// Whether a read's error only says that nothing came in time (a timed-out serial port or
/// socket, a non-blocking read with nothing ready, a signal): the reader tries again.
pub fn nothing_yet(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

/// Prints one line on standard error, prefixed with the tool's name; a closed standard error
/// is ignored (a tool never fails, let alone panics, for want of a place to complain).
pub fn warn(tool: &str, message: &str) {
    let _ = writeln!(io::stderr(), "{tool}: {message}");
}

/// Reads a whole file of at most `max_bytes`: a bigger one (or an endless one such as
/// `/dev/zero`) is an error of kind `InvalidData` saying so, after reading `max_bytes + 1`
/// bytes at most, so no file can make a tool run out of memory.
pub fn read_at_most(path: &Path, max_bytes: u64) -> io::Result<Vec<u8>> {
    read_file_bounded(path, max_bytes)?.ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("more than {max_bytes} bytes: not a file this tool reads"),
        )
    })
}

/// What a file of this type is, for messages ("a FIFO"); `None` for a device (character or
/// block), which only opening it tells more about.
pub fn kind_name(kind: std::fs::FileType) -> Option<&'static str> {
    use std::os::unix::fs::FileTypeExt;
    if kind.is_file() {
        Some("a regular file")
    } else if kind.is_dir() {
        Some("a directory")
    } else if kind.is_fifo() {
        Some("a FIFO")
    } else if kind.is_socket() {
        Some("a socket")
    } else {
        None
    }
}

/// Opens `path` for reading if it is a regular file, without blocking: a FIFO, a socket or a
/// device where a file of a set is expected (a bag's `.db3`, its `metadata.yaml`) is refused
/// with an error of kind `InvalidInput` naming what it is, instead of waiting forever in the
/// open for a writer that never comes. The file is opened `O_NONBLOCK` (which only affects
/// FIFOs and devices), checked, then switched back to blocking reads.
pub fn open_regular(path: &Path) -> io::Result<File> {
    use nix::fcntl::{FcntlArg, OFlag, fcntl};
    use std::os::unix::fs::OpenOptionsExt;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(OFlag::O_NONBLOCK.bits())
        .open(path)?;
    let kind = file.metadata()?.file_type();
    if !kind.is_file() {
        let what = kind_name(kind).unwrap_or("a device");
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("expected a regular file, found {what}"),
        ));
    }
    fcntl(&file, FcntlArg::F_SETFL(OFlag::empty())).map_err(io::Error::from)?;
    Ok(file)
}

/// The bytes of the file at `path` through [`read_bounded`]: `None` when it holds more than
/// `max_bytes`, so that the caller says so in its own words ([`read_at_most`] is this with
/// the error every tool shares).
pub fn read_file_bounded(path: &Path, max_bytes: u64) -> io::Result<Option<Vec<u8>>> {
    read_bounded(File::open(path)?, max_bytes)
}

/// Reads what is left of `reader` if it holds at most `max_bytes` (`None` if it holds more),
/// reading `max_bytes + 1` bytes at most: the one bounded read every whole-input reader uses.
pub fn read_bounded(reader: impl Read, max_bytes: u64) -> io::Result<Option<Vec<u8>>> {
    let mut data = Vec::new();
    reader
        .take(max_bytes.saturating_add(1))
        .read_to_end(&mut data)?;
    Ok((data.len() as u64 <= max_bytes).then_some(data))
}

/// What is wrong with a table of numbers ([`read_number_table`]).
#[derive(Debug, thiserror::Error)]
#[error("line {line}: field `{field}`: {problem}")]
pub struct TableError {
    /// Line in the text, from 1.
    pub line: u64,
    /// The column (or `header`, `row`).
    pub field: String,
    /// What is wrong, with what was found.
    pub problem: String,
}

/// Reads CSV text with a header row as numbers: for every row, its line number and the values
/// of `columns` (found by name, in the order asked), each a finite number >= `lowest`. Fields
/// and names are trimmed; lines starting with `#` are comments. Never panics.
pub fn read_number_table(
    text: &[u8],
    columns: &[&str],
    lowest: f64,
) -> Result<Vec<(u64, Vec<f64>)>, TableError> {
    let error = |line: u64, field: &str, problem: String| TableError {
        line,
        field: field.to_string(),
        problem,
    };
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(text);
    let headers = reader
        .headers()
        .map_err(|e| error(1, "header", e.to_string()))?
        .clone();
    let index: Vec<usize> = columns
        .iter()
        .map(|name| {
            headers.iter().position(|h| h == *name).ok_or_else(|| {
                let header: Vec<&str> = headers.iter().collect();
                error(
                    1,
                    name,
                    format!("missing column (header is `{}`)", header.join(",")),
                )
            })
        })
        .collect::<Result<_, _>>()?;
    let expected = if lowest.is_finite() {
        format!("a number >= {lowest}")
    } else {
        "a number".to_string()
    };
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            error(line, "row", e.to_string())
        })?;
        let line = record.position().map_or(0, |p| p.line());
        let values = index
            .iter()
            .zip(columns)
            .map(|(&col, name)| {
                let field = record.get(col).unwrap_or("");
                field
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v >= lowest)
                    .ok_or_else(|| {
                        error(line, name, format!("expected {expected}, found `{field}`"))
                    })
            })
            .collect::<Result<Vec<f64>, _>>()?;
        rows.push((line, values));
    }
    Ok(rows)
}

/// True when `path` means standard input/output (`None` or `-`).
pub fn is_std(path: Option<&Path>) -> bool {
    path.is_none_or(|p| p.as_os_str() == "-")
}

/// The name to print for a path (`<stdin>` or `<stdout>` for the standard streams).
pub fn display_name(path: Option<&Path>, std_name: &str) -> String {
    match path {
        Some(p) if !is_std(Some(p)) => p.display().to_string(),
        _ => std_name.to_string(),
    }
}

/// An input stream with the name its errors carry.
pub struct Input {
    /// `<stdin>` or the path.
    pub name: String,
    reader: Box<dyn Read>,
}

impl Input {
    /// Opens a file, or standard input for `None` / `-`.
    pub fn open(path: Option<&Path>) -> Result<Input, IoError> {
        let name = display_name(path, "<stdin>");
        let reader: Box<dyn Read> = match path {
            Some(p) if !is_std(Some(p)) => {
                let file = File::open(p).map_err(|source| IoError::Open {
                    path: p.to_path_buf(),
                    source,
                })?;
                Box::new(BufReader::with_capacity(64 * 1024, file))
            }
            _ => Box::new(io::stdin().lock()),
        };
        Ok(Input { name, reader })
    }

    /// Reads into `buf`; errors carry the input's name. Interrupted reads are retried.
    pub fn read_chunk(&mut self, buf: &mut [u8]) -> Result<usize, IoError> {
        loop {
            match self.reader.read(buf) {
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                other => {
                    return other.map_err(|source| IoError::Read {
                        name: self.name.clone(),
                        source,
                    });
                }
            }
        }
    }

    /// Reads everything that is left.
    pub fn read_all(&mut self) -> Result<Vec<u8>, IoError> {
        let mut out = Vec::new();
        self.reader
            .read_to_end(&mut out)
            .map_err(|source| IoError::Read {
                name: self.name.clone(),
                source,
            })?;
        Ok(out)
    }

    /// The reader itself, for line-based parsing.
    pub fn reader(&mut self) -> &mut dyn Read {
        &mut self.reader
    }
}

/// A file written beside its target and renamed into place by [`commit`](Self::commit); dropped
/// without a successful commit, the temporary file is removed and the target left as it was.
///
/// A symbolic link as target is kept: the file it points to is replaced. A target that exists
/// and is not a regular file (a FIFO, a device such as `/dev/null`) is written directly, since
/// replacing it would destroy it; a directory is refused.
pub struct AtomicFile {
    /// The path as the user gave it, for messages.
    target: PathBuf,
    /// Where the rename goes: the target, or the file a symbolic link points to.
    dest: PathBuf,
    /// The temporary file, or `None` when writing directly to a special file.
    temp: Option<PathBuf>,
    writer: Option<BufWriter<File>>,
    committed: bool,
}

/// Distinguishes temporary files of one process.
static TEMP_COUNTER: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);

impl AtomicFile {
    /// Creates the temporary file beside `target` (or opens a special file directly).
    pub fn create(target: &Path) -> Result<AtomicFile, IoError> {
        let open_err = |source| IoError::Open {
            path: target.to_path_buf(),
            source,
        };
        if let Ok(meta) = std::fs::metadata(target) {
            if meta.is_dir() {
                return Err(open_err(io::Error::other("is a directory")));
            }
            if !meta.is_file() {
                let file = File::options().write(true).open(target).map_err(open_err)?;
                return Ok(AtomicFile {
                    target: target.to_path_buf(),
                    dest: target.to_path_buf(),
                    temp: None,
                    writer: Some(BufWriter::with_capacity(64 * 1024, file)),
                    committed: false,
                });
            }
        }
        let is_link = std::fs::symlink_metadata(target).is_ok_and(|m| m.file_type().is_symlink());
        let dest = if is_link {
            std::fs::canonicalize(target).map_err(open_err)?
        } else {
            target.to_path_buf()
        };
        let file_name = dest.file_name().map(|n| n.to_string_lossy().into_owned());
        let file_name = file_name.unwrap_or_else(|| "output".into());
        let serial = TEMP_COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let temp = dest.with_file_name(format!(".{file_name}.tmp-{}-{serial}", std::process::id()));
        let file = File::options()
            .write(true)
            .create_new(true)
            .open(&temp)
            .map_err(|e| {
                let dir = temp.parent().map(|d| d.display().to_string());
                let dir = dir.filter(|d| !d.is_empty()).unwrap_or_else(|| ".".into());
                open_err(io::Error::new(
                    e.kind(),
                    format!(
                        "cannot create a temporary file in {dir} to replace it atomically: {e}"
                    ),
                ))
            })?;
        Ok(AtomicFile {
            target: target.to_path_buf(),
            dest,
            temp: Some(temp),
            writer: Some(BufWriter::with_capacity(64 * 1024, file)),
            committed: false,
        })
    }

    /// Writes all of `bytes`, naming the target on failure.
    pub fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.write_all(bytes).map_err(|source| IoError::Write {
            name: self.target.display().to_string(),
            source,
        })
    }

    /// Writes `bytes` and commits: the whole file or nothing.
    pub fn commit_with(mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.write_bytes(bytes)?;
        self.commit()
    }

    /// Writes `value` as pretty JSON ending in a newline, and commits.
    pub fn commit_json<T: serde::Serialize + ?Sized>(self, value: &T) -> Result<(), IoError> {
        let mut text = serde_json::to_string_pretty(value).map_err(|e| IoError::Write {
            name: self.target.display().to_string(),
            source: io::Error::other(e),
        })?;
        text.push('\n');
        self.commit_with(text.as_bytes())
    }

    /// Flushes and syncs what was written so far, without committing: a later
    /// [`AtomicFile::commit`] then finds little or nothing left to sync.
    pub fn sync(&mut self) -> Result<(), IoError> {
        let write_err = |source| IoError::Write {
            name: self.target.display().to_string(),
            source,
        };
        if let Some(writer) = &mut self.writer {
            writer.flush().map_err(write_err)?;
            if self.temp.is_some() {
                writer.get_ref().sync_all().map_err(write_err)?;
            }
        }
        Ok(())
    }

    /// Flushes, syncs and renames the file into place.
    pub fn commit(mut self) -> Result<(), IoError> {
        self.sync()?;
        // Closed (its buffer is flushed already) before the rename.
        drop(self.writer.take());
        if let Some(temp) = &self.temp {
            std::fs::rename(temp, &self.dest).map_err(|source| IoError::Write {
                name: self.target.display().to_string(),
                source,
            })?;
        }
        self.committed = true;
        Ok(())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match &mut self.writer {
            Some(w) => w.write(buf),
            None => Err(io::Error::other("file already committed")),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        match &mut self.writer {
            Some(w) => w.flush(),
            None => Ok(()),
        }
    }
}

/// Seeking serves formats that patch what they wrote (MCAP's summary offsets); a special file
/// (a pipe, a terminal) refuses it.
impl io::Seek for AtomicFile {
    fn seek(&mut self, position: io::SeekFrom) -> io::Result<u64> {
        match &mut self.writer {
            Some(w) => w.seek(position),
            None => Err(io::Error::other("file already committed")),
        }
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.committed
            && let Some(temp) = &self.temp
        {
            // Best effort: the run failed, so the partial file goes.
            let _ = std::fs::remove_file(temp);
        }
    }
}

/// Where a tool's main output goes: standard output or an atomic file.
pub enum Output {
    /// Standard output, buffered.
    Stdout(BufWriter<io::Stdout>),
    /// A file, renamed into place on [`finish`](Self::finish).
    File(AtomicFile),
}

impl Output {
    /// Opens standard output for `None` / `-`, else an atomic file. With `binary`, refuses a
    /// terminal on standard output.
    pub fn open(path: Option<&Path>, binary: bool) -> Result<Output, IoError> {
        match path {
            Some(p) if !is_std(Some(p)) => Ok(Output::File(AtomicFile::create(p)?)),
            _ => {
                let stdout = io::stdout();
                if binary && stdout.is_terminal() {
                    return Err(IoError::Terminal);
                }
                Ok(Output::Stdout(BufWriter::with_capacity(64 * 1024, stdout)))
            }
        }
    }

    /// The name errors carry.
    pub fn name(&self) -> String {
        match self {
            Output::Stdout(_) => "<stdout>".into(),
            Output::File(f) => f.target.display().to_string(),
        }
    }

    /// Writes all bytes, naming the output on failure.
    pub fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.write_all(bytes).map_err(|source| IoError::Write {
            name: self.name(),
            source,
        })
    }

    /// Flushes, naming the output on failure.
    pub fn flush_named(&mut self) -> Result<(), IoError> {
        self.flush().map_err(|source| IoError::Write {
            name: self.name(),
            source,
        })
    }

    /// Flushes standard output, or flushes and syncs the file without committing it
    /// ([`AtomicFile::sync`]).
    pub fn sync(&mut self) -> Result<(), IoError> {
        match self {
            Output::Stdout(_) => self.flush_named(),
            Output::File(f) => f.sync(),
        }
    }

    /// Flushes standard output, or commits the file.
    pub fn finish(self) -> Result<(), IoError> {
        match self {
            Output::Stdout(mut w) => w.flush().map_err(|source| IoError::Write {
                name: "<stdout>".into(),
                source,
            }),
            Output::File(f) => f.commit(),
        }
    }
}

impl Write for Output {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match self {
            Output::Stdout(w) => w.write(buf),
            Output::File(f) => f.write(buf),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        match self {
            Output::Stdout(w) => w.flush(),
            Output::File(f) => f.flush(),
        }
    }
}

/// Most chunks a [`StopReader`]'s thread reads ahead.
const CHUNKS_AHEAD: usize = 4;

/// A file (`None`: standard input) read on a thread of its own, so that a read waiting on a
/// silent pipe gives up once `stop` is set (an error saying so, never `Interrupted`, which
/// readers retry): a signal then ends a run that reads a pipe from a live process. The file is
/// opened on that thread too, since a named pipe without a writer blocks in `open`.
pub struct StopReader<'a> {
    chunks: std::sync::mpsc::Receiver<Result<Vec<u8>, IoError>>,
    chunk: Vec<u8>,
    at: usize,
    ended: bool,
    stop: &'a AtomicBool,
}

impl<'a> StopReader<'a> {
    /// Opens `path` (`None` or `-`: standard input) and starts reading it.
    pub fn open(path: Option<&Path>, stop: &'a AtomicBool) -> StopReader<'a> {
        let name = display_name(path, "<stdin>");
        let path = path.filter(|p| !is_std(Some(p))).map(Path::to_path_buf);
        let (tx, rx) = std::sync::mpsc::sync_channel::<Result<Vec<u8>, IoError>>(CHUNKS_AHEAD);
        std::thread::spawn(move || {
            let mut reader: Box<dyn Read> = match path {
                Some(path) => match std::fs::File::open(&path) {
                    Ok(file) => Box::new(file),
                    Err(source) => return drop(tx.send(Err(IoError::Open { path, source }))),
                },
                None => Box::new(io::stdin()),
            };
            loop {
                let mut buf = vec![0u8; 64 * 1024];
                let read = match reader.read(&mut buf) {
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                    read => read,
                };
                let last = !matches!(read, Ok(n) if n > 0);
                let chunk = read.map(|n| {
                    buf.truncate(n);
                    buf
                });
                let sent = tx.send(chunk.map_err(|source| IoError::Read {
                    name: name.clone(),
                    source,
                }));
                if last || sent.is_err() {
                    break;
                }
            }
        });
        StopReader {
            chunks: rx,
            chunk: Vec::new(),
            at: 0,
            ended: false,
            stop,
        }
    }

    /// The next chunk read, `Ok(None)` at the end, or `Err` with what failed (opening,
    /// reading, or [`STOPPED`] once the flag is set while waiting).
    pub fn next_chunk(&mut self) -> Result<Option<Vec<u8>>, IoError> {
        use std::sync::mpsc::RecvTimeoutError;
        while !self.ended {
            if self.stop.load(Ordering::SeqCst) {
                return Err(IoError::Read {
                    name: STOPPED.into(),
                    source: io::Error::other(STOPPED),
                });
            }
            match self.chunks.recv_timeout(Duration::from_millis(100)) {
                Ok(Ok(chunk)) if chunk.is_empty() => self.ended = true,
                Ok(Ok(chunk)) => return Ok(Some(chunk)),
                Ok(Err(e)) => {
                    self.ended = true;
                    return Err(e);
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => self.ended = true,
            }
        }
        Ok(None)
    }
}

/// What a [`StopReader`] says when the stop flag ended a read.
pub const STOPPED: &str = "reading stopped by a signal";

impl Read for StopReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.at == self.chunk.len() {
            match self.next_chunk() {
                Ok(Some(chunk)) => (self.chunk, self.at) = (chunk, 0),
                Ok(None) => return Ok(0),
                // The reader's caller names the file: hand on the system's own error.
                Err(IoError::Read { source, .. }) => return Err(source),
                Err(e) => return Err(io::Error::other(e.to_string())),
            }
        }
        let n = buf.len().min(self.chunk.len() - self.at);
        buf[..n].copy_from_slice(&self.chunk[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

/// The MCAP writer of the project's Foxglove files (the session log, the map view): no
/// compression, never seeking (chunks are assembled in memory), so a pipe is as good as a file.
pub fn json_mcap_writer<W: Write>(
    out: W,
) -> Result<mcap::Writer<mcap::write::NoSeek<W>>, mcap::McapError> {
    mcap::WriteOptions::new()
        .profile("")
        .library(concat!("rovlink ", env!("CARGO_PKG_VERSION")))
        .compression(None)
        .disable_seeking(true)
        .create(mcap::write::NoSeek::new(out))
}

/// A JSON channel on `topic` whose messages follow the JSON Schema `schema_text` named
/// `schema_name` (a Foxglove well-known schema such as `foxglove.SceneUpdate`); its id.
pub fn json_mcap_channel<W: Write + io::Seek>(
    writer: &mut mcap::Writer<W>,
    schema_name: &str,
    schema_text: &str,
    topic: &str,
    metadata: &std::collections::BTreeMap<String, String>,
) -> Result<u16, mcap::McapError> {
    let schema = writer.add_schema(schema_name, "jsonschema", schema_text.as_bytes())?;
    writer.add_channel(schema, topic, "json", metadata)
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_file_appears_only_on_commit() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.bin");
        let mut f = AtomicFile::create(&target).unwrap();
        f.write_all(b"abc").unwrap();
        assert!(!target.exists());
        f.commit().unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"abc");
        let mut g = AtomicFile::create(&target).unwrap();
        g.write_all(b"partial").unwrap();
        drop(g);
        assert_eq!(std::fs::read(&target).unwrap(), b"abc");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_synced_file_still_appears_only_on_commit_and_whole() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.bin");
        let mut f = Output::open(Some(&target), true).unwrap();
        f.write_bytes(b"abc").unwrap();
        f.sync().unwrap();
        assert!(!target.exists());
        f.write_bytes(b"def").unwrap();
        f.finish().unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"abcdef");
        // Synced, then dropped unfinished: no file, no temporary.
        let other = dir.path().join("other.bin");
        let mut g = Output::open(Some(&other), true).unwrap();
        g.write_bytes(b"partial").unwrap();
        g.sync().unwrap();
        drop(g);
        assert!(!other.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn failed_commit_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.bin");
        let f = AtomicFile::create(&target).unwrap();
        // A directory appears where the file should go: the rename fails.
        std::fs::create_dir(&target).unwrap();
        assert!(f.commit().is_err());
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("out.bin")]);
        assert!(matches!(
            AtomicFile::create(dir.path()),
            Err(IoError::Open { .. })
        ));
    }

    #[test]
    fn symlink_target_is_kept_and_special_files_written_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.bin");
        let link = dir.path().join("link.bin");
        std::fs::write(&real, b"old").unwrap();
        std::os::unix::fs::symlink(&real, &link).unwrap();
        let mut f = AtomicFile::create(&link).unwrap();
        f.write_all(b"new").unwrap();
        f.commit().unwrap();
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
        let mut null = AtomicFile::create(Path::new("/dev/null")).unwrap();
        null.write_all(b"gone").unwrap();
        null.commit().unwrap();
        assert!(!std::fs::metadata("/dev/null").unwrap().is_file());
    }

    #[test]
    fn exit_codes() {
        let pipe = IoError::Write {
            name: "<stdout>".into(),
            source: io::Error::from(io::ErrorKind::BrokenPipe),
        };
        assert_eq!(exit_code(&pipe), EXIT_OK);
        assert_eq!(exit_code(&CheckFailed("x".into())), EXIT_CHECK_FAILED);
        assert_eq!(exit_code(&IoError::Terminal), EXIT_BAD_INPUT);
    }

    #[test]
    fn error_text_skips_repeated_causes() {
        let err = IoError::Open {
            path: "x.bin".into(),
            source: io::Error::from(io::ErrorKind::NotFound),
        };
        assert_eq!(error_text(&err), "x.bin: cannot open: entity not found");
    }
}
