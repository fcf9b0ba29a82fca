//! Links: modem and channel models, the discrete-event scheduler every simulation runs on, and
//! its seeded random streams.
//!
//! Simulations run in virtual time ([`SimTime`], integer nanoseconds): events wait in a
//! [`Scheduler`], a binary heap ordered by (time, sequence number), so two events due at the same
//! instant come out in the order they were scheduled and a run never depends on the heap's
//! internals. Every random quantity draws from its own [`Rng`] stream, derived from the run's
//! seed and the stream's number, so adding a random stream never changes the others and the same
//! seed gives the same bytes and the same trace.
//!
//! A [`Model`] holds one direction's figures (bit rate, delays, jitter, range, errors, netem's
//! extras); a [`Link`] runs two of them as a state machine given time, which the virtual-time
//! driver ([`pipe`]) and the real-time driver ([`realtime`]) both drive; [`stats`] holds what a
//! run reports (trace rows, counters, summary, `--stats` JSON). [`emulate`] is link-sim's
//! real-time runs as library calls, and [`dialect`] the modem dialects they can emulate.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod channel;
pub mod device;
pub mod dialect;
pub mod distance;
pub mod emulate;
pub mod gll;
pub mod measure;
pub mod medium;
pub mod model;
pub mod pipe;
pub mod realtime;
pub mod sched;
pub mod stats;

pub use channel::{Fate, Link, Report, Side};
pub use distance::Distance;
pub use medium::{Medium, MediumReport};
pub use model::{Model, ModelError};
pub use rovlink_base::rng::{self, Rng};
pub use sched::{Scheduler, SimTime};
