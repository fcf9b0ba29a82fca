//! The command-line conventions every tool shares.
//!
//! - A missing path or `-` means standard input or standard output.
//! - Output files are written atomically: to a temporary file beside the target, renamed into
//!   place only when the tool succeeds, so a failed run never leaves a half-written file.
//! - Binary output is refused when standard output is a terminal.
//! - Errors name the file and what went wrong; [`exit_code`] maps any error to the exit-code
//!   table (0 ok, 1 a requested check failed, 2 bad usage or input), treating a closed pipe
//!   downstream (`tool | head`) as success.

use std::fs::File;
use std::io::{self, BufReader, BufWriter, IsTerminal, Read, Write};
use std::path::{Path, PathBuf};

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
                eprintln!("{tool}: {}", error_text(err));
            }
            std::process::ExitCode::from(code)
        }
    }
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
/// without a commit, the temporary file is removed and the target left as it was.
pub struct AtomicFile {
    target: PathBuf,
    temp: PathBuf,
    writer: Option<BufWriter<File>>,
}

impl AtomicFile {
    /// Creates the temporary file beside `target`.
    pub fn create(target: &Path) -> Result<AtomicFile, IoError> {
        let file_name = target.file_name().map(|n| n.to_string_lossy().into_owned());
        let file_name = file_name.unwrap_or_else(|| "output".into());
        let temp = target.with_file_name(format!(".{file_name}.tmp-{}", std::process::id()));
        let file = File::create(&temp).map_err(|source| IoError::Open {
            path: target.to_path_buf(),
            source,
        })?;
        Ok(AtomicFile {
            target: target.to_path_buf(),
            temp,
            writer: Some(BufWriter::with_capacity(64 * 1024, file)),
        })
    }

    /// Flushes, syncs and renames the file into place.
    pub fn commit(mut self) -> Result<(), IoError> {
        let write_err = |source| IoError::Write {
            name: self.target.display().to_string(),
            source,
        };
        if let Some(writer) = self.writer.take() {
            let file = writer.into_inner().map_err(|e| write_err(e.into_error()))?;
            file.sync_all().map_err(write_err)?;
        }
        std::fs::rename(&self.temp, &self.target).map_err(write_err)
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

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.writer.take().is_some() {
            // Best effort: the run failed, so the partial file goes.
            let _ = std::fs::remove_file(&self.temp);
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
