//! Frame counters: the sender's (never reused under a key), the receiver's high-water mark
//! (a frame at or below it is a replay), the full counter restored from the low bits a frame
//! carries, and the file that keeps both across sessions.
//!
//! A counter is per (SRC, DST) and 48 bits wide; senders start at 1. A frame carries the low
//! [`COUNTER_LOW_BITS`]; the receiver tries the [`WINDOWS`] smallest counters above its
//! high-water mark with those bits ([`candidates`]), so up to `WINDOWS` x 2^14 - 1 = 65,535
//! frames may be lost in a row (9.4 hours of an S100 session's 0.52 s cycle) before the two
//! ends lose step. Each extra window tried gives a forger one more guess: the odds of a forged
//! frame being taken are at most `WINDOWS` x 2^-32 = 2^-30 per frame.
//!
//! Replay across sessions is stopped by persisting, not by fresh session keys: a node's
//! [`CounterStore`] (a small JSON file beside the key file, one per node address) holds the
//! highest counter it may have sent on each (SRC, DST), reserved [`RESERVE_BLOCK`] at a time
//! and synced to disk before any of the block is used (so a crash never reuses a counter,
//! which would also reuse AES-CTR keystream), and the high-water mark of each (SRC, DST) it
//! received, written after every frame it accepts. The store is locked for a process's life:
//! two processes cannot share one.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::sealed::{COUNTER_LOW_BITS, MAX_COUNTER};

/// How many windows of 2^[`COUNTER_LOW_BITS`] counters above the high-water mark a receiver
/// tries.
pub const WINDOWS: u64 = 4;
/// How many send counters a store reserves at once.
pub const RESERVE_BLOCK: u64 = 1024;
/// The largest counter file read, bytes.
const MAX_STORE_BYTES: u64 = 64 * 1024;

/// The full counters a frame with low bits `low` may carry, nearest first, when the highest
/// accepted is `last`.
pub fn candidates(last: u64, low: u16) -> impl Iterator<Item = u64> {
    let span = 1u64 << COUNTER_LOW_BITS;
    let mut first = (last & !(span - 1)) | u64::from(low);
    if first <= last {
        first += span;
    }
    (0..WINDOWS)
        .map(move |k| first + k * span)
        .filter(|&c| c <= MAX_COUNTER)
}

/// The counter a replayed frame with low bits `low` would have: the highest at or below
/// `last` with those bits (none when that would be 0, never used).
pub fn replayed(last: u64, low: u16) -> Option<u64> {
    let span = 1u64 << COUNTER_LOW_BITS;
    let c = (last & !(span - 1)) | u64::from(low);
    let c = if c > last { c.checked_sub(span)? } else { c };
    (c > 0).then_some(c)
}

/// What went wrong with a counter file.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// It could not be read, written or locked.
    #[error("{path}: {what}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The error.
        source: std::io::Error,
    },
    /// Another process holds it.
    #[error("{path}: in use by another process (one counter file per node and process)")]
    Locked {
        /// The file.
        path: PathBuf,
    },
    /// It is not a counter file.
    #[error("{path}: not a counter file: {problem}")]
    Bad {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A sender ran out of counters (2^48 frames).
    #[error("frame counter of {pair} exhausted: make a new key")]
    Exhausted {
        /// `SRC>DST`.
        pair: String,
    },
}

/// The counters of one node: what it sent, what it accepted.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Counters {
    /// The format's version (1).
    pub version: u32,
    /// Per `SRC>DST`, the highest counter this node may have sent.
    pub sent: BTreeMap<String, u64>,
    /// Per `SRC>DST`, the highest counter this node accepted.
    pub received: BTreeMap<String, u64>,
}

/// The key of a pair in the maps.
pub fn pair(src: u8, dst: u8) -> String {
    format!("{src}>{dst}")
}

/// A node's counters, kept in memory (a simulation) or also in a locked file.
pub struct CounterStore {
    counters: Counters,
    /// Per pair, the next counter to send.
    next: BTreeMap<String, u64>,
    /// The file, and the lock on its lock file (held until the store is dropped).
    file: Option<(PathBuf, nix::fcntl::Flock<File>)>,
}

impl std::fmt::Debug for CounterStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CounterStore")
            .field("counters", &self.counters)
            .field("file", &self.file.as_ref().map(|(p, _)| p))
            .finish()
    }
}

impl CounterStore {
    /// Counters in memory only, from 1.
    pub fn in_memory() -> CounterStore {
        CounterStore {
            counters: Counters {
                version: 1,
                ..Counters::default()
            },
            next: BTreeMap::new(),
            file: None,
        }
    }

    /// Opens (creating it, mode 0600) and locks the counter file at `path`.
    pub fn open(path: &Path) -> Result<CounterStore, StoreError> {
        use nix::fcntl::{Flock, FlockArg};
        use std::os::unix::fs::OpenOptionsExt;
        let io_err = |what| {
            move |source| StoreError::Io {
                path: path.to_path_buf(),
                what,
                source,
            }
        };
        let lock_path = lock_path(path);
        let lock = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .mode(0o600)
            .open(&lock_path)
            .map_err(io_err("cannot create its lock file"))?;
        let lock =
            Flock::lock(lock, FlockArg::LockExclusiveNonblock).map_err(|_| StoreError::Locked {
                path: path.to_path_buf(),
            })?;
        let counters = match std::fs::metadata(path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Counters {
                version: 1,
                ..Counters::default()
            },
            _ => {
                let bytes = rovlink_base::io::read_at_most(path, MAX_STORE_BYTES)
                    .map_err(io_err("cannot read"))?;
                let counters: Counters =
                    serde_json::from_slice(&bytes).map_err(|e| StoreError::Bad {
                        path: path.to_path_buf(),
                        problem: e.to_string(),
                    })?;
                if counters.version != 1 {
                    return Err(StoreError::Bad {
                        path: path.to_path_buf(),
                        problem: format!("version {}, expected 1", counters.version),
                    });
                }
                counters
            }
        };
        let next = counters
            .sent
            .iter()
            .map(|(k, &v)| (k.clone(), v.saturating_add(1)))
            .collect();
        Ok(CounterStore {
            counters,
            next,
            file: Some((path.to_path_buf(), lock)),
        })
    }

    /// The counter for the next frame from `src` to `dst`; in a file, the block it lies in
    /// is reserved and synced first.
    pub fn next_send(&mut self, src: u8, dst: u8) -> Result<u64, StoreError> {
        let key = pair(src, dst);
        let counter = *self.next.get(&key).unwrap_or(&1);
        if counter > crate::sealed::MAX_COUNTER {
            return Err(StoreError::Exhausted { pair: key });
        }
        let reserved = self.counters.sent.get(&key).copied().unwrap_or(0);
        if counter > reserved {
            let block_end = (counter + RESERVE_BLOCK - 1).min(crate::sealed::MAX_COUNTER);
            self.counters.sent.insert(key.clone(), block_end);
            self.write(true)?;
        }
        self.next.insert(key, counter + 1);
        Ok(counter)
    }

    /// The highest counter accepted from `src` to `dst` (0: none yet).
    pub fn last_received(&self, src: u8, dst: u8) -> u64 {
        self.counters
            .received
            .get(&pair(src, dst))
            .copied()
            .unwrap_or(0)
    }

    /// Records `counter` as accepted from `src` to `dst` and writes the file (not synced: a
    /// power cut may forget the last few, see the threat model).
    pub fn accepted(&mut self, src: u8, dst: u8, counter: u64) -> Result<(), StoreError> {
        self.counters.received.insert(pair(src, dst), counter);
        self.write(false)
    }

    /// The counters as they stand.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Writes the counters to the file through a temporary file and a rename; `sync` makes
    /// both durable before returning.
    fn write(&mut self, sync: bool) -> Result<(), StoreError> {
        let Some((path, _lock)) = &self.file else {
            return Ok(());
        };
        let io_err = |what| {
            move |source| StoreError::Io {
                path: path.clone(),
                what,
                source,
            }
        };
        let tmp = tmp_path(path);
        let text = serde_json::to_vec(&self.counters).unwrap_or_default();
        {
            use std::os::unix::fs::OpenOptionsExt;
            let mut f = std::fs::OpenOptions::new()
                .create(true)
                .truncate(true)
                .write(true)
                .mode(0o600)
                .open(&tmp)
                .map_err(io_err("cannot write"))?;
            f.write_all(&text).map_err(io_err("cannot write"))?;
            if sync {
                f.sync_all().map_err(io_err("cannot sync"))?;
            }
        }
        std::fs::rename(&tmp, path).map_err(io_err("cannot replace"))?;
        if sync && let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            File::open(dir)
                .and_then(|d| d.sync_all())
                .map_err(io_err("cannot sync its directory"))?;
        }
        Ok(())
    }

    /// Makes the counters durable (at the end of a run).
    pub fn sync(&mut self) -> Result<(), StoreError> {
        self.write(true)
    }
}

/// The lock file beside a counter file.
fn lock_path(path: &Path) -> PathBuf {
    let mut p = path.as_os_str().to_owned();
    p.push(".lock");
    PathBuf::from(p)
}

/// The temporary file a write goes through.
fn tmp_path(path: &Path) -> PathBuf {
    let mut p = path.as_os_str().to_owned();
    p.push(".tmp");
    PathBuf::from(p)
}

/// The counter file a node at `address` keeps beside `key_file` when none is named:
/// `KEYFILE.nodeN.counters`.
pub fn default_store_path(key_file: &Path, address: u8) -> PathBuf {
    let mut p = key_file.as_os_str().to_owned();
    p.push(format!(".node{address}.counters"));
    PathBuf::from(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_are_the_nearest_counters_above_the_mark() {
        let c: Vec<u64> = candidates(0, 1).collect();
        assert_eq!(c, vec![1, 16385, 32769, 49153]);
        let c: Vec<u64> = candidates(16383, 0).collect();
        assert_eq!(c[0], 16384);
        let c: Vec<u64> = candidates(20000, 20000 & 0x3fff).collect();
        assert_eq!(c[0], 20000 + 16384);
        assert!(candidates(MAX_COUNTER, 5).next().is_none());
        assert_eq!(replayed(20000, (20000 & 0x3fff) as u16), Some(20000));
        assert_eq!(replayed(20000, (19999 & 0x3fff) as u16), Some(19999));
        assert_eq!(replayed(5, 6), None);
        assert_eq!(replayed(16390, 10), Some(10));
    }

    #[test]
    fn a_store_reserves_before_it_sends_and_keeps_marks_across_opens() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("node0.counters");
        let mut store = CounterStore::open(&path).unwrap();
        assert_eq!(store.next_send(0, 1).unwrap(), 1);
        assert_eq!(store.next_send(0, 1).unwrap(), 2);
        assert_eq!(store.next_send(0, 2).unwrap(), 1);
        store.accepted(1, 0, 41).unwrap();
        assert!(matches!(
            CounterStore::open(&path),
            Err(StoreError::Locked { .. })
        ));
        drop(store);
        let mut again = CounterStore::open(&path).unwrap();
        assert_eq!(again.next_send(0, 1).unwrap(), RESERVE_BLOCK + 1);
        assert_eq!(again.last_received(1, 0), 41);
        assert_eq!(again.last_received(2, 0), 0);
        let mode = {
            use std::os::unix::fs::PermissionsExt;
            std::fs::metadata(&path).unwrap().permissions().mode() & 0o777
        };
        assert_eq!(mode, 0o600);
    }

    #[test]
    fn a_damaged_counter_file_is_refused_not_reset() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c");
        std::fs::write(
            &path,
            b"{\"version\":1,\"sent\":{},\"received\":{},\"x\":1}",
        )
        .unwrap();
        let err = CounterStore::open(&path).unwrap_err().to_string();
        assert!(err.contains("not a counter file"), "{err}");
        std::fs::write(&path, b"").unwrap();
        assert!(CounterStore::open(&path).is_err());
        assert!(CounterStore::open(dir.path()).is_err());
    }

    #[test]
    fn memory_counters_start_at_one() {
        let mut s = CounterStore::in_memory();
        assert_eq!(s.next_send(3, 0).unwrap(), 1);
        s.accepted(0, 3, 9).unwrap();
        assert_eq!(s.last_received(0, 3), 9);
        assert_eq!(
            default_store_path(Path::new("/k/keys"), 3),
            Path::new("/k/keys.node3.counters")
        );
    }
}
