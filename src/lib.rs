//! rovlink: the core library of a toolkit for teleoperating underwater vehicles over links of a
//! few kilobits per second or less (acoustic and RF modems, satellite hops).
//!
//! The binaries in `src/bin/` are thin: they parse arguments, call into this library and map the
//! outcome to an exit code (0 success, 1 a requested check failed, 2 bad usage or bad input).
//!
//! Modules, one concept each:
//! - [`wire`]: the link frame, the ROV and operator messages, their JSON Lines text form and a
//!   streaming deframer. The byte layouts are a contract (`shared/design/wire.md`).
//! - [`debt`]: the progressive wavelet image codec with a region of interest, and the image
//!   files it reads and writes.
//! - [`link`]: link models (the paper's modems, netem-like links), the virtual-time scheduler,
//!   the simulated link and its real-time emulator.
//! - [`device`]: the one device grammar of every tool (`/dev/ttyUSB0`, `serial:`, `tcp:`,
//!   `tcpin:`, `udp:`, `udpin:`, `udpout:`, `pty`) and the one opener.
//! - [`gll`]: device adapters (transparent modems, EvoLogics, UDP) behind one endpoint trait,
//!   put on the devices the opener opened.
//! - [`measure`]: probes and Table 3's figures, from a simulated or a real link.
//! - [`rcp`]: the remote-control protocol's operator and ROV engines, sessions and their logs.
//! - [`vehicle`]: the ROV's kinematic model.
//! - [`octo`]: an OctoMap-compatible occupancy octree, point-cloud readers and the map-delta
//!   stream.
//! - [`geometry`]: the one distance between two points.
//! - [`stats`]: running statistics (mean, deviation, jitter estimators).
//! - [`io`]: files and streams as every tool uses them (`-` for stdin/stdout, atomic output
//!   files, errors that name the file, the exit-code table).
//! - [`cli`]: the command-line layer the binaries share, and the only module that uses clap:
//!   range-checked flag values, output claiming, row writers, the stop flag, progress, the
//!   link-model and port flag groups.
// The only `unsafe` in the library, allowed where it stands: calling the AVX2 and AVX-512
// compilations of the octree's ray walk after checking that the processor has those features
// (`octo::cast`).
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod cli;
pub mod debt;
pub mod device;
pub mod geometry;
pub mod gll;
pub mod io;
pub mod link;
pub mod measure;
pub mod octo;
pub mod rcp;
pub mod stats;
pub mod strict_json;
pub mod vehicle;
pub mod wire;
