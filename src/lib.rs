//! rovlink: the core library of a toolkit for teleoperating underwater vehicles over links of a
//! few kilobits per second or less (acoustic and RF modems, satellite hops).
//!
//! The binaries in `src/bin/` are thin: they parse arguments, call into this library and map the
//! outcome to an exit code (0 success, 1 a requested check failed, 2 bad usage or bad input).
//!
//! Modules, one concept each:
//! - [`wire`]: the link frame, the ROV and operator messages, their JSON Lines text form and a
//!   streaming deframer. The byte layouts are a contract (`shared/design/wire.md`).
//! - [`octo`]: an OctoMap-compatible occupancy octree, point-cloud readers and the map-delta
//!   stream.
//! - [`io`]: the command-line conventions every tool shares (`-` for stdin/stdout, atomic output
//!   files, refusing binary output to a terminal, error messages that name the file).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod debt;
pub mod gll;
pub mod io;
pub mod link;
pub mod measure;
pub mod octo;
pub mod rcp;
pub mod stats;
pub mod vehicle;
pub mod wire;
