//! rovlink-mapper: octo-delta's work as library calls, above the map (`rovlink-octo`) and its
//! inputs (`rovlink-scans`).
//!
//! - [`pipeline`]: the build loop (recordings into a map and its delta stream), apply, dump,
//!   full and synth, with every configuration number checked;
//! - [`view`]: the operator's view as it grew, as an MCAP file of `foxglove.SceneUpdate`s.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod live;
pub mod pipeline;
pub mod view;
