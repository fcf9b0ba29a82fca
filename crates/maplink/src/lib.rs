//! octo-delta's live transport (docs/octo-delta-format.md, "Live transport, version 1"): the
//! mapper's stream of records (the `.odl` header and messages, the vehicle's pose) carried over
//! a link in segments that are sequenced, acknowledged, resent after a timeout and shaped to a
//! configured rate, and the operator's requests carried back, each acknowledged.
//!
//! Sans-IO, driven by an injected clock: [`Outbox`] is the vehicle's side (records in, segments
//! out, acknowledgements and requests in), [`Inbox`] the operator's (segments in, records and
//! acknowledgements out, requests out until answered). What carries a segment (a wire.md link
//! frame over a serial port, a PTY, TCP or UDP) is the caller's.
//!
//! - [`segment`]: the byte layout of the four segment types (data, acknowledgement, request,
//!   reply): `Packet<T: AsRef<[u8]>>` views, a plain [`segment::Repr`] with `parse`/`emit`. No
//!   panic on any input.
//! - [`request`]: what the operator asks (resync, full map, full map in a box, ROI, coarse
//!   depth), in bytes and as JSON Lines.
//! - [`outbox`]: the sender: records cut into segments, a window of unacknowledged ones, resends
//!   after the timeout, a rate shaper, a bounded backlog.
//! - [`inbox`]: the receiver: segments reassembled in order into records, acknowledgements,
//!   resynchronisation after a restart on either side.
#![forbid(unsafe_code)]

pub mod inbox;
pub mod outbox;
pub mod request;
pub mod segment;
#[cfg(test)]
mod tests;

pub use inbox::{Inbox, InboxEvent};
pub use outbox::{Backlog, Outbox, OutboxConfig};
pub use request::Request;
pub use segment::Repr;
