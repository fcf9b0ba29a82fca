//! rovlink-security: the one place frame security lives (keys, authenticated and encrypted
//! link frames, replay counters), used by the tools that pack, dump and run sessions.
//!
//! - [`key`]: frame keys and the key file (ssh-style permissions), a new key;
//! - [`suite`]: the cryptography: AES-CMAC tags, AES-CTR, derived keys;
//! - [`sealed`]: the secured frame's layout (docs/wire-extensions.md), sealing and checking
//!   one frame with a given counter;
//! - [`counter`]: counters, the high-water mark, restoring a counter from its low bits, the
//!   counter file;
//! - [`guard`]: a node's gate: seal what it sends, open what it takes, refuse the rest;
//! - [`stream`]: a stream of frames as the tools pack and dump it (counters set by hand, a
//!   verdict per frame).
//!
//! docs/threat-model.md says what this protects, from whom, and what it does not.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod counter;
pub mod guard;
pub mod key;
pub mod sealed;
pub mod stream;
pub mod suite;
#[cfg(test)]
mod vectors;

pub use guard::{Guard, Opened, Refusal, SealError};
pub use key::{Key, KeyError, KeyRing};
