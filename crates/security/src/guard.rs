//! A secured node's gate: it seals every frame the node originates and opens every frame the
//! node's engines are to take, refusing what is not authentic or not fresh.
//!
//! A refused frame ([`Refusal`]) is not a heartbeat, acknowledges nothing and moves nothing:
//! the caller drops it before any engine sees it. Forwarding is not the guard's business: a
//! relay forwards secured frames unchanged, and only their destination opens them.
//!
//! No-panic contract: [`Guard::open`] takes any bytes and returns a verdict, never a panic.

use rovlink_wire::frame::{self, Frame};

use crate::counter::{CounterStore, StoreError, candidates, replayed};
use crate::key::KeyRing;
use crate::sealed::{self, Sealed, SealedError, is_sealed};
use crate::suite::Suites;

/// Why a frame was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Refusal {
    /// A plain (version-0) frame reached a secured node.
    Unsecured,
    /// Marked secured but too short to be one.
    Malformed,
    /// No key for this SRC and DST.
    NoKey,
    /// The tag is wrong for every counter tried: forged, damaged, or under another key.
    BadTag,
    /// Authentic, but at or below the highest counter accepted: a replay.
    Replay,
}

impl Refusal {
    /// The name used in `--metrics`, `--events` and messages.
    pub fn as_str(self) -> &'static str {
        match self {
            Refusal::Unsecured => "unsecured",
            Refusal::Malformed => "malformed",
            Refusal::NoKey => "no_key",
            Refusal::BadTag => "bad_tag",
            Refusal::Replay => "replay",
        }
    }

    /// Every reason, for documentation and tables.
    pub const ALL: [Refusal; 5] = [
        Refusal::Unsecured,
        Refusal::Malformed,
        Refusal::NoKey,
        Refusal::BadTag,
        Refusal::Replay,
    ];
}

/// A frame that passed: the plain frame for the engines, and what it carried.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Opened {
    /// The plain link frame (wire.md's), as the sender's engine made it.
    pub frame: Vec<u8>,
    /// Its full counter.
    pub counter: u64,
    /// True when it was encrypted on the air.
    pub encrypted: bool,
}

/// What went wrong sealing a frame.
#[derive(Debug, thiserror::Error)]
pub enum SealError {
    /// No key for the frame's SRC and DST.
    #[error("no key for frames from {src} to {dst}")]
    NoKey {
        /// SRC.
        src: u8,
        /// DST.
        dst: u8,
    },
    /// The frame cannot be sealed (too long, not a frame).
    #[error(transparent)]
    Frame(#[from] SealedError),
    /// The counters could not be kept.
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// A node's keys, counters and policy.
#[derive(Debug)]
pub struct Guard {
    ring: KeyRing,
    encrypt: bool,
    store: CounterStore,
    /// Working keys per (SRC, DST), derived once.
    suites: Suites,
}

impl Guard {
    /// A guard over `ring` with counters in `store`; `encrypt` encrypts what it seals.
    pub fn new(ring: KeyRing, encrypt: bool, store: CounterStore) -> Guard {
        Guard {
            ring,
            encrypt,
            store,
            suites: Suites::default(),
        }
    }

    /// True when it encrypts what it seals.
    pub fn encrypts(&self) -> bool {
        self.encrypt
    }

    /// Seals the plain frame `plain` with the next counter of its (SRC, DST).
    pub fn seal(&mut self, plain: &[u8]) -> Result<Vec<u8>, SealError> {
        let f = Frame::new_checked(plain).map_err(|e| SealedError::NotAFrame(e.to_string()))?;
        let (src, dst) = (f.src(), f.dst());
        if f.payload_len() > sealed::MAX_MESSAGE_BYTES {
            return Err(SealedError::TooLong(f.payload_len()).into());
        }
        let suite = self
            .suites
            .get(&self.ring, src, dst)
            .ok_or(SealError::NoKey { src, dst })?;
        let counter = self.store.next_send(src, dst)?;
        Ok(sealed::seal(suite, plain, counter, self.encrypt)?)
    }

    /// Opens the frame `bytes` (a whole link frame whose CRC was checked): the plain frame,
    /// or why it is refused. An accepted counter raises the high-water mark (and is written
    /// to the counter file; a failure to write is returned beside the frame, which is still
    /// good).
    pub fn open(&mut self, bytes: &[u8]) -> Result<(Opened, Option<StoreError>), Refusal> {
        let f = Frame::new_checked(bytes).map_err(|_| Refusal::Malformed)?;
        let (src, dst) = (f.src(), f.dst());
        let payload = f.payload();
        if !is_sealed(payload) {
            return Err(Refusal::Unsecured);
        }
        let p = Sealed::new_checked(payload).map_err(|_| Refusal::Malformed)?;
        let last = self.store.last_received(src, dst);
        let suite = self
            .suites
            .get(&self.ring, src, dst)
            .ok_or(Refusal::NoKey)?;
        let low = p.counter_low();
        let Some(counter) = candidates(last, low).find(|&c| p.verify(suite, src, dst, c)) else {
            let again = replayed(last, low).is_some_and(|c| p.verify(suite, src, dst, c));
            return Err(if again {
                Refusal::Replay
            } else {
                Refusal::BadTag
            });
        };
        let message = p.plain_message(suite, src, dst, counter);
        let encrypted = p.encrypted();
        let frame = frame::build(src, dst, &message).map_err(|_| Refusal::Malformed)?;
        let stored = self.store.accepted(src, dst, counter).err();
        Ok((
            Opened {
                frame,
                counter,
                encrypted,
            },
            stored,
        ))
    }

    /// Makes the counters durable (at the end of a run).
    pub fn sync(&mut self) -> Result<(), StoreError> {
        self.store.sync()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::key::Key;

    fn guard(encrypt: bool) -> Guard {
        let ring = KeyRing::single(Key::from_bytes(&[9u8; 16]).unwrap());
        Guard::new(ring, encrypt, CounterStore::in_memory())
    }

    fn goto() -> Vec<u8> {
        frame::build(0, 1, &[0x84, 0, 0, 10, 0, 20, 0, 30, 0, 90, 0]).unwrap()
    }

    #[test]
    fn a_sealed_frame_opens_once_and_a_replay_is_named() {
        let (mut op, mut rov) = (guard(false), guard(false));
        let sealed = op.seal(&goto()).unwrap();
        assert_eq!(sealed.len(), goto().len() + sealed::OVERHEAD_BYTES);
        let (opened, stored) = rov.open(&sealed).unwrap();
        assert!(stored.is_none());
        assert_eq!(opened.frame, goto());
        assert_eq!(opened.counter, 1);
        assert_eq!(rov.open(&sealed).err(), Some(Refusal::Replay));
        let second = op.seal(&goto()).unwrap();
        assert_ne!(second, sealed);
        assert_eq!(rov.open(&second).unwrap().0.counter, 2);
        assert_eq!(rov.open(&sealed).err(), Some(Refusal::Replay));
    }

    #[test]
    fn plain_forged_and_foreign_frames_are_refused() {
        let (mut op, mut rov) = (guard(true), guard(true));
        assert_eq!(rov.open(&goto()).err(), Some(Refusal::Unsecured));
        let mut forged = op.seal(&goto()).unwrap();
        forged[5] ^= 1;
        let n = forged.len();
        let crc = frame::CRC16.checksum(&forged[1..n - 2]);
        forged[n - 2..].copy_from_slice(&crc.to_be_bytes());
        assert_eq!(rov.open(&forged).err(), Some(Refusal::BadTag));
        let other = Guard::new(
            KeyRing::single(Key::from_bytes(&[8u8; 16]).unwrap()),
            false,
            CounterStore::in_memory(),
        )
        .seal(&goto())
        .unwrap();
        assert_eq!(rov.open(&other).err(), Some(Refusal::BadTag));
        let between = frame::build(1, 2, &[0x20, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(rov.open(&between).err(), Some(Refusal::NoKey));
        let short = frame::build(0, 1, &[0x20, 0, 0]).unwrap();
        assert_eq!(rov.open(&short).err(), Some(Refusal::Malformed));
        assert!(rov.open(&[]).is_err());
    }

    #[test]
    fn frames_lost_in_between_do_not_lose_step() {
        let (mut op, mut rov) = (guard(false), guard(false));
        for _ in 0..40_000 {
            op.store.next_send(0, 1).unwrap();
        }
        let late = op.seal(&goto()).unwrap();
        assert_eq!(rov.open(&late).unwrap().0.counter, 40_001);
    }
}
