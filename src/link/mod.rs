//! Links: the discrete-event scheduler every simulation runs on, and its seeded random streams.
//!
//! Simulations run in virtual time ([`SimTime`], integer nanoseconds): events wait in a
//! [`Scheduler`], a binary heap ordered by (time, sequence number), so two events due at the same
//! instant come out in the order they were scheduled and a run never depends on the heap's
//! internals. Every random quantity draws from its own [`Rng`] stream, derived from the run's
//! seed and the stream's number, so adding a random stream never changes the others and the same
//! seed gives the same bytes and the same trace.
//!
//! Status (issue 4): the scheduler and the random streams. The modem and channel models,
//! `link-sim` and the real-time driver are still to come.

pub mod rng;
pub mod sched;

pub use rng::Rng;
pub use sched::{Scheduler, SimTime};
