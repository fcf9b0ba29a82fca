//! Files that hold secrets or carry commands, checked as ssh checks a private key: a key file
//! (frame keys, a MAVLink signing key) must be a regular file owned by the user running the
//! tool and neither readable nor writable by group or others; a file or FIFO that carries
//! orders must be owned by that user and not writable by group or others. Anything else is
//! refused with one line saying what was found, before a byte of it is used.
//!
//! [`create_secret_file`] writes a new key file with mode 0600 and never replaces one.

use std::fs::{File, Metadata};
use std::io::{self, Read, Write};
use std::os::unix::fs::{MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

/// Why a secret or command file was refused.
#[derive(Debug, thiserror::Error)]
pub enum SecretFileError {
    /// It could not be opened or read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What failed.
        source: io::Error,
    },
    /// Not a regular file (a directory, a device such as `/dev/zero`, a FIFO) where one is
    /// expected.
    #[error("{path}: expected a regular file, found {found}")]
    NotRegular {
        /// The file.
        path: PathBuf,
        /// What it is.
        found: &'static str,
    },
    /// Owned by another user.
    #[error("{path}: owned by uid {owner}, not by this user (uid {me}): refused")]
    Owner {
        /// The file.
        path: PathBuf,
        /// Its owner.
        owner: u32,
        /// The user running the tool.
        me: u32,
    },
    /// Group or others may read or write it.
    #[error("{path}: permissions {mode:04o} are too open: {what}; chmod {fix:o} {path}")]
    TooOpen {
        /// The file.
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
        /// Who may do what.
        what: &'static str,
        /// The mode to set instead.
        fix: u32,
    },
    /// Empty, or bigger than a key file can be.
    #[error("{path}: {len} bytes: expected 1..={max} bytes")]
    Size {
        /// The file.
        path: PathBuf,
        /// How many bytes it holds (the bound plus one when bigger).
        len: u64,
        /// The most it may hold.
        max: u64,
    },
    /// [`create_secret_file`]: the file exists.
    #[error("{path}: exists; a key file is never overwritten (remove it first)")]
    Exists {
        /// The file.
        path: PathBuf,
    },
}

/// Whether `a` equals `b`, taking a time that depends on their lengths but not on where they
/// differ: every byte of `a` is compared (a token, a tag).
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = u8::from(a.len() != b.len());
    for (k, x) in a.iter().enumerate() {
        diff |= x ^ b.get(k).copied().unwrap_or(!x);
    }
    std::hint::black_box(diff) == 0
}

/// `count` random bytes from the system's source (`/dev/urandom`), for keys and tokens.
pub fn random_bytes(count: usize) -> io::Result<Vec<u8>> {
    let mut buf = vec![0u8; count];
    File::open("/dev/urandom")?.read_exact(&mut buf)?;
    Ok(buf)
}

/// The user running this process.
fn my_uid() -> u32 {
    nix::unistd::geteuid().as_raw()
}

/// What a file type is, for messages.
fn kind(meta: &Metadata) -> &'static str {
    crate::io::kind_name(meta.file_type()).unwrap_or("a device")
}

/// Checks that the file at `meta` is owned by this user and that none of the `forbidden`
/// permission bits are set; `what` says who could then do what, `fix` is the mode to set.
fn check_owner_and_mode(
    path: &Path,
    meta: &Metadata,
    forbidden: u32,
    what: &'static str,
    fix: u32,
) -> Result<(), SecretFileError> {
    let me = my_uid();
    if meta.uid() != me {
        return Err(SecretFileError::Owner {
            path: path.to_path_buf(),
            owner: meta.uid(),
            me,
        });
    }
    let mode = meta.permissions().mode() & 0o7777;
    if mode & forbidden != 0 {
        return Err(SecretFileError::TooOpen {
            path: path.to_path_buf(),
            mode,
            what,
            fix,
        });
    }
    Ok(())
}

/// Checks that a command source (an orders FIFO or file) at `meta` is owned by this user and
/// not writable by group or others: anyone else who can write to it could command the
/// vehicle.
pub fn check_command_source(path: &Path, meta: &Metadata) -> Result<(), SecretFileError> {
    let mode = meta.permissions().mode() & 0o7777;
    let what = "group or others may write orders to it";
    check_owner_and_mode(path, meta, 0o022, what, mode & !0o022 & 0o777)
}

/// Opens `path` for reading without waiting (`O_NONBLOCK`: a FIFO without a writer, a serial
/// line without carrier) and returns the handle with its metadata, so that what is checked is
/// what is read, whatever the path names meanwhile.
fn open_nonblocking(path: &Path) -> Result<(File, Metadata), SecretFileError> {
    let read_err = |source| SecretFileError::Read {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(nix::fcntl::OFlag::O_NONBLOCK.bits())
        .open(path)
        .map_err(read_err)?;
    let meta = file.metadata().map_err(read_err)?;
    Ok((file, meta))
}

/// Opens a command source (an orders file or FIFO, a script) for reading and checks the open
/// handle with [`check_command_source`] before a byte is read: the open never waits
/// (`O_NONBLOCK`: a FIFO without a writer, a serial line without carrier), and what is checked
/// is what is read, whatever the path names meanwhile (a symlink swapped after the check
/// changes nothing). Returns the file, reading blocking again, and its metadata.
///
/// A FIFO is then reopened through `/proc/self/fd` (the same FIFO, not the path again):
/// read-only, which waits for a writer as an open of its path would, or, with
/// `fifo_keep_writer`, for reading and writing, which does not wait and never sees an end of
/// file while writers come and go (Linux's fifo(7)).
pub fn open_command_source(
    path: &Path,
    fifo_keep_writer: bool,
) -> Result<(File, Metadata), SecretFileError> {
    use nix::fcntl::{FcntlArg, OFlag, fcntl};
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::FileTypeExt;
    let read_err = |source| SecretFileError::Read {
        path: path.to_path_buf(),
        source,
    };
    let (file, meta) = open_nonblocking(path)?;
    check_command_source(path, &meta)?;
    if !meta.file_type().is_fifo() {
        fcntl(&file, FcntlArg::F_SETFL(OFlag::empty()))
            .map_err(|e| read_err(io::Error::from(e)))?;
        return Ok((file, meta));
    }
    let same = PathBuf::from(format!("/proc/self/fd/{}", file.as_raw_fd()));
    let reopened = std::fs::OpenOptions::new()
        .read(true)
        .write(fifo_keep_writer)
        .open(&same)
        .map_err(read_err)?;
    let again = reopened.metadata().map_err(read_err)?;
    if (again.dev(), again.ino()) != (meta.dev(), meta.ino()) {
        let changed = io::Error::other("the FIFO changed while it was opened");
        return Err(read_err(changed));
    }
    Ok((reopened, meta))
}

/// Checks a key file's metadata: a regular file, owned by this user, mode allowing nothing
/// to group or others.
fn check_secret(path: &Path, meta: &Metadata) -> Result<(), SecretFileError> {
    if !meta.file_type().is_file() {
        return Err(SecretFileError::NotRegular {
            path: path.to_path_buf(),
            found: kind(meta),
        });
    }
    let what = "group or others may read or write it";
    check_owner_and_mode(path, meta, 0o077, what, 0o600)
}

/// Reads a key file of 1..=`max_bytes` bytes after checking it as ssh checks a private key
/// (see the module doc). The file is opened without blocking and checked on the open handle,
/// so a FIFO or device is refused without waiting and a file swapped after the check is not
/// read.
pub fn read_secret_file(path: &Path, max_bytes: u64) -> Result<Vec<u8>, SecretFileError> {
    let (file, meta) = open_nonblocking(path)?;
    check_secret(path, &meta)?;
    let mut bytes = Vec::new();
    (&file)
        .take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|source| SecretFileError::Read {
            path: path.to_path_buf(),
            source,
        })?;
    let len = bytes.len() as u64;
    if len == 0 || len > max_bytes {
        return Err(SecretFileError::Size {
            path: path.to_path_buf(),
            len,
            max: max_bytes,
        });
    }
    Ok(bytes)
}

/// Writes `bytes` to a new file at `path` with mode 0600 (set at creation: the secret is never
/// readable by others, not even for an instant); an existing file is refused, never replaced.
pub fn create_secret_file(path: &Path, bytes: &[u8]) -> Result<(), SecretFileError> {
    let mut file: File = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)
        .map_err(|source| {
            if source.kind() == io::ErrorKind::AlreadyExists {
                SecretFileError::Exists {
                    path: path.to_path_buf(),
                }
            } else {
                SecretFileError::Read {
                    path: path.to_path_buf(),
                    source,
                }
            }
        })?;
    let written = file.write_all(bytes).and_then(|()| file.sync_all());
    if let Err(source) = written {
        let _ = std::fs::remove_file(path);
        return Err(SecretFileError::Read {
            path: path.to_path_buf(),
            source,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_mode(dir: &Path, name: &str, bytes: &[u8], mode: u32) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
        path
    }

    #[test]
    fn the_constant_time_compare_is_equality() {
        assert!(constant_time_eq(b"", b""));
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        assert!(!constant_time_eq(b"abc", b"ab"));
        assert!(!constant_time_eq(b"ab", b"abc"));
        assert!(!constant_time_eq(b"", b"a"));
        assert!(!constant_time_eq(b"a", b""));
        // A shorter `b` is padded with bytes that differ from `a`'s, never equal to them.
        assert!(!constant_time_eq(&[0xff], &[]));
        assert!(!constant_time_eq(&[0x00], &[]));
        assert_eq!(random_bytes(32).unwrap().len(), 32);
        assert_ne!(random_bytes(16).unwrap(), random_bytes(16).unwrap());
    }

    #[test]
    fn a_private_file_is_read_and_an_open_one_refused() {
        let dir = tempfile::tempdir().unwrap();
        let good = with_mode(dir.path(), "k", b"secret", 0o600);
        assert_eq!(read_secret_file(&good, 64).unwrap(), b"secret");
        let readonly = with_mode(dir.path(), "r", b"secret", 0o400);
        assert!(read_secret_file(&readonly, 64).is_ok());
        for mode in [0o640, 0o604, 0o660, 0o666, 0o620] {
            let open = with_mode(dir.path(), "o", b"secret", mode);
            let err = read_secret_file(&open, 64).unwrap_err().to_string();
            assert!(
                err.contains("too open") && err.contains("chmod 600"),
                "{err}"
            );
        }
    }

    #[test]
    fn directories_devices_empty_and_huge_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let err = read_secret_file(dir.path(), 64).unwrap_err().to_string();
        assert!(err.contains("found a directory"), "{err}");
        let err = read_secret_file(Path::new("/dev/zero"), 64)
            .unwrap_err()
            .to_string();
        assert!(err.contains("found a device"), "{err}");
        let empty = with_mode(dir.path(), "e", b"", 0o600);
        let err = read_secret_file(&empty, 64).unwrap_err().to_string();
        assert!(err.contains("0 bytes: expected 1..=64"), "{err}");
        let big = with_mode(dir.path(), "b", &[b'a'; 100], 0o600);
        let err = read_secret_file(&big, 64).unwrap_err().to_string();
        assert!(err.contains("65 bytes"), "{err}");
        let err = read_secret_file(&dir.path().join("none"), 64)
            .unwrap_err()
            .to_string();
        assert!(err.contains("cannot read"), "{err}");
    }

    #[test]
    fn a_new_secret_is_private_and_never_replaces_a_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("new");
        create_secret_file(&path, b"k").unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        let err = create_secret_file(&path, b"other").unwrap_err().to_string();
        assert!(err.contains("exists"), "{err}");
        assert_eq!(std::fs::read(&path).unwrap(), b"k");
    }

    #[test]
    fn a_command_source_is_checked_on_its_handle_and_a_fifo_opens_without_waiting() {
        use nix::sys::stat::Mode;
        let dir = tempfile::tempdir().unwrap();
        let ok = with_mode(dir.path(), "orders", b"{}\n", 0o600);
        let (mut file, meta) = open_command_source(&ok, false).unwrap();
        assert!(meta.is_file());
        let mut text = String::new();
        file.read_to_string(&mut text).unwrap();
        assert_eq!(text, "{}\n");
        let open = with_mode(dir.path(), "open", b"{}\n", 0o666);
        let err = open_command_source(&open, false).unwrap_err().to_string();
        assert!(err.contains("0666 are too open"), "{err}");
        // A FIFO of ours, kept open for writers: no writer is waited for.
        let fifo = dir.path().join("fifo");
        nix::unistd::mkfifo(&fifo, Mode::from_bits_truncate(0o600)).unwrap();
        let (mut file, meta) = open_command_source(&fifo, true).unwrap();
        assert!(std::os::unix::fs::FileTypeExt::is_fifo(&meta.file_type()));
        std::fs::OpenOptions::new()
            .write(true)
            .open(&fifo)
            .unwrap()
            .write_all(b"line\n")
            .unwrap();
        let mut buf = [0u8; 5];
        file.read_exact(&mut buf).unwrap();
        assert_eq!(&buf, b"line\n");
        // Someone else's FIFO mode: refused before the open could wait for a writer.
        let shared = dir.path().join("shared");
        nix::unistd::mkfifo(&shared, Mode::from_bits_truncate(0o600)).unwrap();
        std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o622)).unwrap();
        let err = open_command_source(&shared, false).unwrap_err().to_string();
        assert!(err.contains("0622 are too open"), "{err}");
    }

    #[test]
    fn a_command_source_writable_by_others_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let ok = with_mode(dir.path(), "ok", b"", 0o644);
        let meta = std::fs::metadata(&ok).unwrap();
        check_command_source(&ok, &meta).unwrap();
        let open = with_mode(dir.path(), "open", b"", 0o666);
        let meta = std::fs::metadata(&open).unwrap();
        let err = check_command_source(&open, &meta).unwrap_err().to_string();
        assert!(
            err.contains("0666 are too open") && err.contains("chmod 644"),
            "{err}"
        );
    }
}
