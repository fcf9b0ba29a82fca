//! The routing layer of wire.md: 4-bit addresses, a static table of next hops, and the rule a
//! node follows for every frame it hears.
//!
//! Address 0 is the operator, 1..=14 are vehicles, 15 is broadcast. SRC and DST stay end to
//! end; a frame is never changed on its way. The [`Routes`] table is the network's, the same at
//! every node: for a node and a destination, the next hop (no entry: the destination itself,
//! one hop away). The routed path from S to D follows next hops from S until D.
//!
//! A node that hears a frame ([`Router::decide`]):
//!
//! - drops it when it does not parse as a link frame, when the node sent it (SRC is the node:
//!   its own frame relayed back), or when it is a copy of a frame the node took within its
//!   duplicate window (a copy overheard on a shared medium, or its own forward coming back);
//! - delivers it when DST is the node, or broadcast;
//! - forwards it, unchanged and once, onto the interface of its next hop towards DST when the
//!   node lies inside the routed path from SRC to DST (a broadcast: inside the routed path from
//!   SRC to any node); a node off that path never forwards, so without routes a node out of
//!   range of the sender is unreachable.
//!
//! A table is checked when it is built ([`Routes::check`]): every address 0..=14, every next
//! hop shares an interface with the node, and no path loops.
//!
//! Nothing here panics on any bytes or any table.

use std::collections::BTreeMap;

use crate::link::SimTime;

/// The broadcast address.
pub const BROADCAST: u8 = 15;
/// The highest vehicle address.
pub const MAX_VEHICLE: u8 = 14;

/// Why a routes table is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RoutesError {
    /// Not the JSON object expected; `at` names the field (`routes."2"."0"`).
    #[error("{at}: {what}")]
    Syntax {
        /// Where.
        at: String,
        /// What was wrong, expected vs found.
        what: String,
    },
    /// An address outside 0..=14 (or one not in the network).
    #[error("{at}: expected an address 0..=14 of a node in the network, found {found}")]
    Address {
        /// Where.
        at: String,
        /// The value given.
        found: String,
    },
    /// Following next hops from `src` towards `dst` comes back to a node: the path.
    #[error("routes: the path from {src} to {dst} loops: {}", path_text(.path))]
    Loop {
        /// Source.
        src: u8,
        /// Destination.
        dst: u8,
        /// The nodes visited, the repeated one last.
        path: Vec<u8>,
    },
    /// A next hop the node has no interface to.
    #[error(
        "routes: node {node} routes to {dst} through {hop}, but {node} and {hop} share no interface"
    )]
    NoInterface {
        /// The node.
        node: u8,
        /// The destination.
        dst: u8,
        /// The next hop it names.
        hop: u8,
    },
}

fn path_text(path: &[u8]) -> String {
    path.iter()
        .map(u8::to_string)
        .collect::<Vec<_>>()
        .join(" -> ")
}

/// The network's static routes: for each node and destination, the next hop.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Routes {
    /// node -> destination -> next hop (absent: the destination itself).
    next: BTreeMap<u8, BTreeMap<u8, u8>>,
}

impl Routes {
    /// No routes: every destination is one hop away.
    pub fn direct() -> Routes {
        Routes::default()
    }

    /// The table of a scenario's `routes` object: `{"0":{"2":1},"2":{"0":1}}` (keys are
    /// addresses as strings, values next hops as numbers). Only the syntax and the addresses
    /// (0..=14) are checked here; [`Routes::check`] checks it against the network.
    pub fn from_json(value: &serde_json::Value) -> Result<Routes, RoutesError> {
        let _ = value;
        todo!("helper B")
    }

    /// Adds (or replaces) a route: from `node`, frames for `dst` go to `hop`.
    pub fn set(&mut self, node: u8, dst: u8, hop: u8) {
        self.next.entry(node).or_default().insert(dst, hop);
    }

    /// The next hop from `node` towards `dst` (`dst` itself without an entry).
    pub fn next_hop(&self, node: u8, dst: u8) -> u8 {
        self.next
            .get(&node)
            .and_then(|row| row.get(&dst))
            .copied()
            .unwrap_or(dst)
    }

    /// The routed path from `src` to `dst`, both included (`[src]` when they are equal); none
    /// when it loops or is longer than 16 nodes.
    pub fn path(&self, src: u8, dst: u8) -> Option<Vec<u8>> {
        let _ = (src, dst);
        todo!("helper B")
    }

    /// Checks the table against the network: `nodes` are its addresses; `linked(a, b)` is true
    /// when a and b share an interface (a medium, a port). Every address in the table must be a
    /// node, every next hop linked to its node, and no path between two nodes may loop.
    pub fn check(&self, nodes: &[u8], linked: &dyn Fn(u8, u8) -> bool) -> Result<(), RoutesError> {
        let _ = (nodes, linked);
        todo!("helper B")
    }
}

/// Why a node took no action on a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dropped {
    /// Not a link frame (bad preamble, length or CRC).
    Malformed,
    /// The node's own frame (SRC is the node).
    Own,
    /// A copy of a frame taken within the duplicate window.
    Duplicate,
    /// Neither for the node nor on its routed path.
    OffPath,
}

impl Dropped {
    /// The name used in events: `malformed`, `own`, `duplicate`, `off_path`.
    pub fn as_str(self) -> &'static str {
        match self {
            Dropped::Malformed => "malformed",
            Dropped::Own => "own",
            Dropped::Duplicate => "duplicate",
            Dropped::OffPath => "off_path",
        }
    }
}

/// What a node does with a frame it heard.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Decision {
    /// The frame's SRC and DST (none when it does not parse).
    pub addresses: Option<(u8, u8)>,
    /// True when the frame is for this node (DST, or broadcast): hand it to the engine.
    pub deliver: bool,
    /// The interfaces to send it on, unchanged (empty: not forwarded).
    pub forward_on: Vec<usize>,
    /// Why it was neither delivered nor forwarded.
    pub dropped: Option<Dropped>,
}

/// One node's routing: its address, the table, its interfaces, and the frames it took lately.
pub struct Router {
    _private: (),
}

impl Router {
    /// The router of node `address`. `interfaces[k]` lists the addresses interface k reaches
    /// (the other nodes on its medium, or behind its port). `duplicate_window_s`: a frame whose
    /// bytes equal one the node took (delivered or forwarded) less than this long ago is a copy.
    /// Give it less than the shortest time in which a sender sends the same bytes again (half
    /// the TDMA cycle).
    pub fn new(
        address: u8,
        routes: Routes,
        interfaces: Vec<Vec<u8>>,
        duplicate_window_s: f64,
    ) -> Router {
        let _ = (address, routes, interfaces, duplicate_window_s);
        todo!("helper B")
    }

    /// The node's address.
    pub fn address(&self) -> u8 {
        todo!("helper B")
    }

    /// The interface a frame this node originates for `dst` goes out on: the one reaching its
    /// next hop (the first interface when none does, or for broadcast).
    pub fn interface_to(&self, dst: u8) -> usize {
        let _ = dst;
        todo!("helper B")
    }

    /// Notes a frame the node itself sends at `t` (so its copy relayed back is dropped).
    pub fn sent(&mut self, t: SimTime, bytes: &[u8]) {
        let _ = (t, bytes);
        todo!("helper B")
    }

    /// What to do with `bytes`, heard at `t` on interface `interface`.
    pub fn decide(&mut self, t: SimTime, bytes: &[u8], interface: usize) -> Decision {
        let _ = (t, bytes, interface);
        todo!("helper B")
    }
}
