//! Secured frames a stream at a time, as the tools that pack and dump frames handle them:
//! [`Sealer`] seals plain frames with counters the caller may set (`rcp-pack --key-file`),
//! [`Checker`] tells what each frame of a dump is and opens the good ones (`rcp-dump`).
//!
//! A sealer is not a node: it keeps no counter file, and it seals whatever counter it is told
//! to (a test vector, a replay on purpose), saying when one was already used. A checker keeps a
//! high-water mark per (SRC, DST) across the stream, as a receiving node does, so a frame
//! repeated in a dump is named a replay.

use std::collections::HashMap;

use rovlink_wire::frame::Frame;
use rovlink_wire::print::{Inspected, Inspector, Security, VERDICT_OK, VERDICT_UNVERIFIED};

use crate::counter::CounterStore;
use crate::guard::{Guard, Refusal};
use crate::key::KeyRing;
use crate::sealed::{self, MAX_COUNTER, Sealed, SealedError, is_sealed};
use crate::suite::Suites;

/// Why a frame could not be sealed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StreamSealError {
    /// The key file has no key for the frame's SRC and DST.
    #[error(
        "no key for frames from {src} to {dst} in the key file (a vehicle's own line or `*`; \
         `broadcast` for DST 15; frames between two vehicles have none)"
    )]
    NoKey {
        /// SRC.
        src: u8,
        /// DST.
        dst: u8,
    },
    /// A counter out of range.
    #[error("counter {0}: expected 1..={MAX_COUNTER}")]
    Counter(u64),
    /// The counters of a pair ran out.
    #[error("counter of {src}>{dst}: the next would pass {MAX_COUNTER}")]
    Exhausted {
        /// SRC.
        src: u8,
        /// DST.
        dst: u8,
    },
    /// The frame cannot be sealed (too long, not a frame).
    #[error(transparent)]
    Frame(#[from] SealedError),
}

/// One frame the [`Sealer`] sealed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SealedFrame {
    /// The secured link frame.
    pub bytes: Vec<u8>,
    /// The counter it carries.
    pub counter: u64,
    /// The highest counter of its (SRC, DST) sealed before it, when this one is not above
    /// it: a receiver that took that one refuses this one as a replay (and, encrypted, the two
    /// share keystream).
    pub not_above: Option<u64>,
}

/// Seals plain frames with a counter per (SRC, DST): from a first value up, one a frame, or
/// the value the caller gives for a frame (the pair goes on from there).
#[derive(Debug)]
pub struct Sealer {
    ring: KeyRing,
    encrypt: bool,
    first: u64,
    /// Per pair, the next counter.
    next: HashMap<(u8, u8), u64>,
    /// Per pair, the highest counter sealed.
    highest: HashMap<(u8, u8), u64>,
    /// Working keys per pair, derived once.
    suites: Suites,
}

/// Checks that `counter` is one a sender may use.
fn check_counter(counter: u64) -> Result<u64, StreamSealError> {
    if (1..=MAX_COUNTER).contains(&counter) {
        Ok(counter)
    } else {
        Err(StreamSealError::Counter(counter))
    }
}

impl Sealer {
    /// A sealer over `ring` whose counters start at `first` (1..=[`MAX_COUNTER`]); `encrypt`
    /// also encrypts every message.
    pub fn new(ring: KeyRing, encrypt: bool, first: u64) -> Result<Sealer, StreamSealError> {
        Ok(Sealer {
            ring,
            encrypt,
            first: check_counter(first)?,
            next: HashMap::new(),
            highest: HashMap::new(),
            suites: Suites::default(),
        })
    }

    /// True when it encrypts what it seals.
    pub fn encrypts(&self) -> bool {
        self.encrypt
    }

    /// Seals the plain link frame `plain` with counter `counter`, or its pair's next one.
    pub fn seal(
        &mut self,
        plain: &[u8],
        counter: Option<u64>,
    ) -> Result<SealedFrame, StreamSealError> {
        let f = Frame::new_checked(plain).map_err(|e| SealedError::NotAFrame(e.to_string()))?;
        let pair = (f.src(), f.dst());
        let counter = match counter {
            Some(c) => check_counter(c)?,
            None => match self.next.get(&pair) {
                Some(&c) if c > MAX_COUNTER => {
                    return Err(StreamSealError::Exhausted {
                        src: pair.0,
                        dst: pair.1,
                    });
                }
                Some(&c) => c,
                None => self.first,
            },
        };
        let suite = self
            .suites
            .get(&self.ring, pair.0, pair.1)
            .ok_or(StreamSealError::NoKey {
                src: pair.0,
                dst: pair.1,
            })?;
        let bytes = sealed::seal(suite, plain, counter, self.encrypt)?;
        let not_above = self.highest.get(&pair).copied().filter(|&h| counter <= h);
        self.next.insert(pair, counter + 1);
        let highest = self.highest.entry(pair).or_default();
        *highest = (*highest).max(counter);
        Ok(SealedFrame {
            bytes,
            counter,
            not_above,
        })
    }
}

/// Tells what each frame of a stream is: with keys, verified against a high-water mark per
/// (SRC, DST) and opened; without, a secured frame is named as one, unverified.
#[derive(Debug)]
pub struct Checker {
    guard: Option<Guard>,
}

impl Checker {
    /// A checker with the keys of `ring` (`None`: no key, nothing is verified).
    pub fn new(ring: Option<KeyRing>) -> Checker {
        Checker {
            guard: ring.map(|r| Guard::new(r, false, CounterStore::in_memory())),
        }
    }
}

impl Inspector for Checker {
    fn inspect(&mut self, frame: &[u8]) -> Option<Inspected> {
        let f = Frame::new_checked(frame).ok()?;
        let carried = Sealed::new_checked(f.payload()).ok();
        let low = carried.map(|s| s.counter_low());
        let encrypted = carried.is_some_and(|s| s.encrypted());
        let Some(guard) = &mut self.guard else {
            // Without a key, only what is a secured frame's whole layout is named one: a
            // shorter payload with the S bit prints as version 0 reads it.
            carried?;
            return Some(Inspected {
                security: Security {
                    secured: true,
                    encrypted,
                    ctr: None,
                    ctr_low: low,
                    verdict: VERDICT_UNVERIFIED,
                },
                plain: None,
            });
        };
        Some(match guard.open(frame) {
            Ok((opened, _)) => Inspected {
                security: Security {
                    secured: true,
                    encrypted: opened.encrypted,
                    ctr: Some(opened.counter),
                    ctr_low: None,
                    verdict: VERDICT_OK,
                },
                plain: Some(opened.frame),
            },
            Err(Refusal::Unsecured) => Inspected {
                security: Security {
                    secured: false,
                    encrypted: false,
                    ctr: None,
                    ctr_low: None,
                    verdict: Refusal::Unsecured.as_str(),
                },
                plain: Some(frame.to_vec()),
            },
            Err(refusal) => Inspected {
                security: Security {
                    secured: is_sealed(f.payload()),
                    encrypted,
                    ctr: None,
                    ctr_low: low,
                    verdict: refusal.as_str(),
                },
                plain: None,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::key::Key;
    use rovlink_wire::frame;

    fn ring(byte: u8) -> KeyRing {
        KeyRing::single(Key::from_bytes(&[byte; 16]).unwrap())
    }

    fn goto() -> Vec<u8> {
        frame::build(0, 1, &[0x84, 0, 0, 10, 0, 20, 0, 30, 0, 90, 0]).unwrap()
    }

    #[test]
    fn counters_count_per_pair_from_the_first_and_go_on_from_a_given_one() {
        let mut s = Sealer::new(ring(1), false, 5).unwrap();
        let to2 = frame::build(0, 2, &[0x84, 0, 0, 10, 0, 20, 0, 30, 0, 90, 0]).unwrap();
        assert_eq!(s.seal(&goto(), None).unwrap().counter, 5);
        assert_eq!(s.seal(&goto(), None).unwrap().counter, 6);
        assert_eq!(s.seal(&to2, None).unwrap().counter, 5);
        let set = s.seal(&goto(), Some(100)).unwrap();
        assert_eq!((set.counter, set.not_above), (100, None));
        assert_eq!(s.seal(&goto(), None).unwrap().counter, 101);
        let again = s.seal(&goto(), Some(6)).unwrap();
        assert_eq!(again.not_above, Some(101));
        assert_eq!(s.seal(&goto(), None).unwrap().counter, 7);
        assert_eq!(s.seal(&goto(), Some(0)), Err(StreamSealError::Counter(0)));
        assert_eq!(
            s.seal(&goto(), Some(MAX_COUNTER + 1)),
            Err(StreamSealError::Counter(MAX_COUNTER + 1))
        );
        s.seal(&goto(), Some(MAX_COUNTER)).unwrap();
        assert_eq!(
            s.seal(&goto(), None),
            Err(StreamSealError::Exhausted { src: 0, dst: 1 })
        );
        let between = frame::build(1, 2, &[0; 11]).unwrap();
        assert_eq!(
            s.seal(&between, None),
            Err(StreamSealError::NoKey { src: 1, dst: 2 })
        );
        assert!(matches!(
            Sealer::new(ring(1), false, 0),
            Err(StreamSealError::Counter(0))
        ));
    }

    #[test]
    fn the_checker_names_every_verdict() {
        let mut s = Sealer::new(ring(1), true, 1).unwrap();
        let first = s.seal(&goto(), None).unwrap().bytes;
        let second = s.seal(&goto(), None).unwrap().bytes;
        let mut c = Checker::new(Some(ring(1)));
        let ok = c.inspect(&first).unwrap();
        assert_eq!(ok.plain, Some(goto()));
        assert_eq!(
            ok.security,
            Security {
                secured: true,
                encrypted: true,
                ctr: Some(1),
                ctr_low: None,
                verdict: "ok"
            }
        );
        assert_eq!(c.inspect(&second).unwrap().security.ctr, Some(2));
        let replay = c.inspect(&first).unwrap();
        assert_eq!(
            (
                replay.security.verdict,
                replay.security.ctr_low,
                replay.plain
            ),
            ("replay", Some(1), None)
        );
        let plain = c.inspect(&goto()).unwrap();
        assert_eq!(plain.security.verdict, "unsecured");
        assert_eq!(plain.plain, Some(goto()));
        let wrong = Checker::new(Some(ring(2))).inspect(&first).unwrap();
        assert_eq!(wrong.security.verdict, "bad_tag");
        let short = frame::build(0, 1, &[0x20, 0, 0]).unwrap();
        assert_eq!(c.inspect(&short).unwrap().security.verdict, "malformed");
        assert_eq!(c.inspect(&[0x55]), None);

        let mut blind = Checker::new(None);
        let unverified = blind.inspect(&second).unwrap();
        assert_eq!(
            (
                unverified.security.verdict,
                unverified.security.ctr_low,
                unverified.security.encrypted,
                unverified.plain
            ),
            ("unverified", Some(2), true, None)
        );
        assert_eq!(blind.inspect(&goto()), None);
        assert_eq!(blind.inspect(&short), None);
    }
}
