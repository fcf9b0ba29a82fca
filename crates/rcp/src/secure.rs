//! Frame security in a session: which node holds which keys, and what a refused frame shows.
//!
//! A session with keys gives every node it runs a [`Guard`]: in a simulation the operator
//! holds every vehicle's key and each vehicle its own (and the broadcast key), counters in
//! memory (nothing leaves the process); in real time the one node of the process holds what
//! its key file holds, its counters in a locked file beside it. Without keys no node has a
//! guard and the paper's protocol runs unchanged.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::scenario::Scenario;
use rovlink_security::counter::{CounterStore, StoreError, default_store_path};
use rovlink_security::{Guard, KeyRing, Refusal};

pub use rovlink_security::sealed::OVERHEAD_BYTES;

/// A session's keys and policy.
#[derive(Debug, Clone)]
pub struct Security {
    /// The keys.
    pub ring: KeyRing,
    /// Encrypt the messages too (`--encrypt`).
    pub encrypt: bool,
    /// The key file they came from (where real-time counters are kept beside).
    pub key_file: PathBuf,
}

impl Security {
    /// The guards of a simulation of `scenario`: one per node, counters in memory.
    pub fn simulation_guards(&self, scenario: &Scenario) -> BTreeMap<u8, Guard> {
        scenario
            .nodes
            .iter()
            .map(|n| {
                let ring = if n.address == 0 {
                    self.ring.clone()
                } else {
                    self.ring.for_vehicle(n.address)
                };
                let guard = Guard::new(ring, self.encrypt, CounterStore::in_memory());
                (n.address, guard)
            })
            .collect()
    }

    /// The guard of real-time node `address`, its counters in `store` (default: beside the
    /// key file, [`default_store_path`]).
    pub fn node_guard(&self, address: u8, store: Option<&Path>) -> Result<Guard, StoreError> {
        let path = store.map_or_else(
            || default_store_path(&self.key_file, address),
            Path::to_path_buf,
        );
        Ok(Guard::new(
            self.ring.clone(),
            self.encrypt,
            CounterStore::open(&path)?,
        ))
    }
}

/// The bytes a frame grows by under `security`.
pub fn overhead_bytes(security: Option<&Security>) -> usize {
    security.map_or(0, |_| OVERHEAD_BYTES)
}

/// The `--events` action of a frame refused for `reason`, after forwarding it (`forwarded`: a
/// broadcast a relay passes on) or not.
pub fn refused_action(reason: Refusal, forwarded: bool) -> &'static str {
    match (reason, forwarded) {
        (Refusal::Unsecured, false) => "refused:unsecured",
        (Refusal::Malformed, false) => "refused:malformed",
        (Refusal::NoKey, false) => "refused:no_key",
        (Refusal::BadTag, false) => "refused:bad_tag",
        (Refusal::Replay, false) => "refused:replay",
        (Refusal::Unsecured, true) => "forwarded+refused:unsecured",
        (Refusal::Malformed, true) => "forwarded+refused:malformed",
        (Refusal::NoKey, true) => "forwarded+refused:no_key",
        (Refusal::BadTag, true) => "forwarded+refused:bad_tag",
        (Refusal::Replay, true) => "forwarded+refused:replay",
    }
}

/// The warning a real-time end gives once when it runs without keys.
pub const OPEN_LINK_WARNING: &str = "frames are not authenticated (no --key-file): anyone who can \
transmit on the link can command the vehicle or fake its status; see docs/threat-model.md";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_refusal_has_its_action() {
        for r in Refusal::ALL {
            assert!(refused_action(r, false).ends_with(r.as_str()));
            assert!(refused_action(r, true).starts_with("forwarded+refused:"));
        }
    }
}
