//! rovlink-base: what every crate of the toolkit stands on.
//!
//! - [`io`]: files and streams as every tool uses them (`-` for stdin/stdout, atomic output
//!   files, errors that name the file, bounded reads, the exit-code table);
//! - [`output`]: a run's outputs, claimed before any work is done ([`output::Outputs`]);
//! - [`secret`]: key files and order sources checked as ssh checks a private key;
//! - [`rng`]: seeded random streams, one per simulated quantity;
//! - [`stats`]: running statistics (mean, deviation, jitter estimators);
//! - [`geometry`]: the one distance between two points;
//! - [`hex`]: hex text in and out;
//! - [`strict_json`]: JSON objects read with unknown and duplicate fields refused.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod geometry;
pub mod hex;
pub mod io;
pub mod output;
pub mod rng;
pub mod secret;
pub mod stats;
pub mod strict_json;

/// Bad usage: a flag's value or a combination of flags (exit code 2).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);
