//! Output handling shared by every tool: which outputs a run writes, checked before it starts.
//!
//! A run registers its inputs ([`Outputs::input`]) and then claims every output it will write
//! ([`Outputs::claim`], [`Outputs::claim_dir`]) before doing any work, so that bad usage fails
//! with exit code 2 and leaves no file behind:
//! - `-` means standard output, for side outputs too (`--metrics -`); only one output of a run
//!   may go there, and binary output is refused when standard output is a terminal;
//! - an output that is the same file as an input (same device and inode, through links) is
//!   refused, so the input is never truncated;
//! - two outputs naming the same file are refused;
//! - a path that is a directory, or whose directory does not exist, is named as such.
//!
//! A claimed [`Dest`] is then opened as a whole-file output ([`Dest::open`]: standard output,
//! or an atomic file renamed into place on success) or as a row stream
//! (`rovlink_cli::rows::RowWriter`).

use std::io::IsTerminal;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use crate::UsageError;
use crate::io::{IoError, Output};

/// What an output holds: binary output is refused on a terminal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Text (CSV, JSON, lines for people).
    Text,
    /// Bytes (frames, images, MCAP, maps).
    Binary,
}

/// Where one output goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Dest {
    /// Standard output.
    Stdout,
    /// A file, by the path the user gave.
    File(PathBuf),
}

impl Dest {
    /// The name messages carry: the path, or `<stdout>`.
    pub fn name(&self) -> String {
        match self {
            Dest::Stdout => "<stdout>".into(),
            Dest::File(path) => path.display().to_string(),
        }
    }

    /// True for standard output.
    pub fn is_stdout(&self) -> bool {
        matches!(self, Dest::Stdout)
    }

    /// The path, for a file.
    pub fn path(&self) -> Option<&Path> {
        match self {
            Dest::Stdout => None,
            Dest::File(path) => Some(path),
        }
    }

    /// Opens a whole-file output: standard output, or a temporary file renamed onto the path
    /// by [`Output::finish`] (dropped unfinished, it is removed and the path left untouched).
    pub fn open(&self) -> Result<Output, IoError> {
        match self {
            Dest::Stdout => Output::open(None, false),
            Dest::File(path) => Output::open(Some(path), false),
        }
    }

    /// Writes `bytes` as the whole output and commits it: the file whole, or no file.
    pub fn write_whole(&self, bytes: &[u8]) -> Result<(), IoError> {
        self.write_pieces([bytes])
    }

    /// Writes `pieces` one after the other as the whole output and commits it: the file
    /// whole, or no file.
    pub fn write_pieces<'a>(
        &self,
        pieces: impl IntoIterator<Item = &'a [u8]>,
    ) -> Result<(), IoError> {
        let mut out = self.open()?;
        for piece in pieces {
            out.write_bytes(piece)?;
        }
        out.finish()
    }
}

/// The identity of an existing file: device and inode.
fn identity(path: &Path) -> Option<(u64, u64)> {
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

/// A claimed file output: its flag, identity if it exists, and absolute path.
#[derive(Debug)]
struct Claimed {
    flag: String,
    id: Option<(u64, u64)>,
    lexical: PathBuf,
}

/// The inputs and outputs of one run.
#[derive(Debug, Default)]
pub struct Outputs {
    inputs: Vec<(PathBuf, (u64, u64))>,
    outputs: Vec<Claimed>,
    stdout_flag: Option<String>,
}

impl Outputs {
    /// A run with no inputs or outputs yet.
    pub fn new() -> Outputs {
        Outputs::default()
    }

    /// Registers an input file (`None` or `-` is standard input and needs no check).
    pub fn input(&mut self, path: Option<&Path>) {
        let Some(path) = path.filter(|p| p.as_os_str() != "-") else {
            return;
        };
        if let Some(id) = identity(path) {
            self.inputs.push((path.to_path_buf(), id));
        }
    }

    /// Registers several input files.
    pub fn inputs<'a>(&mut self, paths: impl IntoIterator<Item = &'a Path>) {
        for path in paths {
            self.input(Some(path));
        }
    }

    /// Checks the output of `flag` at `path` (`-` for standard output) and claims it.
    pub fn claim(&mut self, flag: &str, path: &Path, kind: Kind) -> Result<Dest, UsageError> {
        if path.as_os_str() == "-" {
            return self.claim_stdout(flag, kind);
        }
        if path.as_os_str().is_empty() {
            return Err(UsageError(format!("{flag}: the path is empty")));
        }
        let meta = std::fs::metadata(path).ok();
        if meta.as_ref().is_some_and(|m| m.is_dir()) {
            return Err(UsageError(format!(
                "{flag}: {} is a directory, expected a file",
                path.display()
            )));
        }
        if meta.is_none() {
            let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
            if let Some(dir) = parent
                && !dir.is_dir()
            {
                let what = if dir.exists() {
                    "is not a directory"
                } else {
                    "does not exist"
                };
                return Err(UsageError(format!(
                    "{flag}: cannot create {}: {} {what}",
                    path.display(),
                    dir.display()
                )));
            }
        }
        let id = meta.as_ref().map(|m| (m.dev(), m.ino()));
        let regular = meta.as_ref().is_none_or(|m| m.is_file());
        if regular {
            probe_directory(flag, path)?;
        }
        if let Some(id) = id
            && regular
            && let Some((input, _)) = self.inputs.iter().find(|(_, i)| *i == id)
        {
            return Err(UsageError(format!(
                "{flag}: {} is the input {}: refusing to overwrite an input",
                path.display(),
                input.display()
            )));
        }
        let lexical = lexical_path(path);
        if regular
            && let Some(other) = self
                .outputs
                .iter()
                .find(|o| (id.is_some() && o.id == id) || o.lexical == lexical)
        {
            return Err(UsageError(format!(
                "{flag}: {} is also the output of {}",
                path.display(),
                other.flag
            )));
        }
        self.outputs.push(Claimed {
            flag: flag.to_string(),
            id,
            lexical,
        });
        Ok(Dest::File(path.to_path_buf()))
    }

    /// Claims standard output for `flag`.
    pub fn claim_stdout(&mut self, flag: &str, kind: Kind) -> Result<Dest, UsageError> {
        if let Some(other) = &self.stdout_flag {
            return Err(UsageError(format!(
                "{flag} and {other} both write to standard output: give one of them a file"
            )));
        }
        if kind == Kind::Binary && std::io::stdout().is_terminal() {
            return Err(UsageError(format!(
                "{flag}: refusing to write binary data to a terminal: redirect standard output, \
                 pipe it, or give a file"
            )));
        }
        self.stdout_flag = Some(flag.to_string());
        Ok(Dest::Stdout)
    }

    /// Claims an optional output: `None` means not requested.
    pub fn claim_opt(
        &mut self,
        flag: &str,
        path: Option<&Path>,
        kind: Kind,
    ) -> Result<Option<Dest>, UsageError> {
        path.map(|p| self.claim(flag, p, kind)).transpose()
    }

    /// Checks a directory output; `-` is refused. A missing directory is not created here
    /// (the tool creates it, with `std::fs::create_dir_all`, when it writes the first file), so
    /// bad usage still leaves nothing behind; its nearest existing ancestor must be a
    /// directory.
    pub fn claim_dir(&mut self, flag: &str, path: &Path) -> Result<PathBuf, UsageError> {
        if path.as_os_str() == "-" || path.as_os_str().is_empty() {
            return Err(UsageError(format!(
                "{flag}: expected a directory, found `{}`",
                path.display()
            )));
        }
        match std::fs::metadata(path) {
            Ok(meta) if meta.is_dir() => {}
            Ok(_) => {
                return Err(UsageError(format!(
                    "{flag}: {} is not a directory",
                    path.display()
                )));
            }
            Err(_) => {
                let ancestor = path.ancestors().skip(1).find(|a| a.exists());
                if let Some(a) = ancestor.filter(|a| !a.as_os_str().is_empty() && !a.is_dir()) {
                    return Err(UsageError(format!(
                        "{flag}: cannot create the directory {}: {} is not a directory",
                        path.display(),
                        a.display()
                    )));
                }
            }
        }
        Ok(path.to_path_buf())
    }

    /// True when some output of this run goes to standard output.
    pub fn stdout_taken(&self) -> bool {
        self.stdout_flag.is_some()
    }
}

/// Checks that a file can be created beside `path` (where its temporary file goes), by
/// creating and removing an empty one: a read-only file system or a directory such as `/proc`
/// is found before the run, not after it.
fn probe_directory(flag: &str, path: &Path) -> Result<(), UsageError> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let probe = dir.join(format!(".rovlink-probe-{}", std::process::id()));
    match std::fs::File::options()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(()),
        Err(e) => Err(UsageError(format!(
            "{flag}: cannot write {}: no file can be created in {}: {e}",
            path.display(),
            dir.display()
        ))),
    }
}

/// An absolute, `.`-free form of a path that may not exist yet, to compare two outputs.
fn lexical_path(path: &Path) -> PathBuf {
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .map(|d| d.join(path))
            .unwrap_or_else(|_| path.to_path_buf())
    };
    let parent = absolute
        .parent()
        .and_then(|p| std::fs::canonicalize(p).ok());
    match (parent, absolute.file_name()) {
        (Some(dir), Some(name)) => dir.join(name),
        _ => absolute,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_input_is_never_an_output() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.bin");
        std::fs::write(&input, b"x").unwrap();
        let link = dir.path().join("link.bin");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        let mut outs = Outputs::new();
        outs.input(Some(&input));
        let err = outs.claim("-o", &link, Kind::Binary).unwrap_err();
        assert!(err.0.contains("refusing to overwrite an input"), "{err}");
        let other = dir.path().join("out.bin");
        assert_eq!(
            outs.claim("-o", &other, Kind::Binary).unwrap(),
            Dest::File(other.clone())
        );
        let err = outs.claim("--stats", &other, Kind::Text).unwrap_err();
        assert!(err.0.contains("also the output of -o"), "{err}");
    }

    #[test]
    fn one_output_on_stdout() {
        let mut outs = Outputs::new();
        outs.claim("--metrics", Path::new("-"), Kind::Text).unwrap();
        let err = outs
            .claim("--events", Path::new("-"), Kind::Text)
            .unwrap_err();
        assert!(err.0.contains("both write to standard output"), "{err}");
    }

    #[test]
    fn directories_and_missing_parents_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let mut outs = Outputs::new();
        let err = outs.claim("-o", dir.path(), Kind::Text).unwrap_err();
        assert!(err.0.contains("is a directory"), "{err}");
        let err = outs
            .claim("-o", &dir.path().join("no/such/x.csv"), Kind::Text)
            .unwrap_err();
        assert!(err.0.contains("does not exist"), "{err}");
        let err = outs
            .claim_dir("--images-out", Path::new("/dev/full"))
            .unwrap_err();
        assert!(err.0.contains("is not a directory"), "{err}");
        let fresh = dir.path().join("a/b");
        assert_eq!(outs.claim_dir("--images-out", &fresh).unwrap(), fresh);
        assert!(!fresh.exists());
        let err = outs
            .claim_dir("--images-out", Path::new("/dev/null/x"))
            .unwrap_err();
        assert!(err.0.contains("/dev/null is not a directory"), "{err}");
        let err = outs
            .claim("-o", Path::new("/proc/version"), Kind::Text)
            .unwrap_err();
        assert!(err.0.contains("no file can be created in /proc"), "{err}");
        // A device is not an input's twin: /dev/null as both is fine.
        outs.input(Some(Path::new("/dev/null")));
        outs.claim("-o", Path::new("/dev/null"), Kind::Text)
            .unwrap();
    }
}
