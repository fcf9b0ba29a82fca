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
//! Where a frame came from is not known on a shared medium (every node in range hears every
//! transmission); the routed path and the duplicate cache are what keep a frame from going back:
//! a node forwards only towards DST along the path, and never the same bytes twice within the
//! window.
//!
//! A table is checked when it is built ([`Routes::check`]): every address 0..=14 and a node of
//! the network, every next hop a table names shares an interface with its node, and no path
//! loops.
//!
//! No-panic, bounded-memory contract: nothing here panics on any bytes, any JSON, any table or
//! any duplicate window (NaN, negative, infinite); a path is at most [`MAX_PATH_NODES`] nodes;
//! a router's duplicate cache holds at most [`DUPLICATE_CACHE_ENTRIES`] entries and drops those
//! older than its window at every call.

use std::collections::hash_map::DefaultHasher;
use std::collections::{BTreeMap, VecDeque};
use std::hash::Hasher;

use rovlink_link::SimTime;
use rovlink_wire::frame::Frame;

/// The broadcast address.
pub const BROADCAST: u8 = 15;
/// The highest vehicle address.
pub const MAX_VEHICLE: u8 = 14;
/// The longest routed path, in nodes (sixteen addresses).
pub const MAX_PATH_NODES: usize = 16;
/// The most frames a router remembers for its duplicate window.
pub const DUPLICATE_CACHE_ENTRIES: usize = 4096;

/// How much of a value or key an error message shows.
const SHOWN_CHARS: usize = 40;

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

/// At most [`SHOWN_CHARS`] characters of `text`, with `...` when cut.
fn shown(text: &str) -> String {
    match text.char_indices().nth(SHOWN_CHARS) {
        Some((end, _)) => format!("{}...", text.get(..end).unwrap_or_default()),
        None => text.to_string(),
    }
}

/// A JSON value as an error shows it (`"x"`, `15`, `-1`, `1.5`, `[1]`), cut short.
fn shown_value(value: &serde_json::Value) -> String {
    shown(&value.to_string())
}

/// The field name of a key, quoted as JSON quotes it (`"2"`), cut short.
fn shown_key(key: &str) -> String {
    shown(&serde_json::Value::String(key.to_string()).to_string())
}

/// Where following next hops from a source ends.
enum Walk {
    /// At the destination: the path, both ends included.
    Reached(Vec<u8>),
    /// Back at a node already visited: the path, the repeated node last.
    Loops(Vec<u8>),
    /// More than [`MAX_PATH_NODES`] nodes without reaching the destination.
    TooLong(Vec<u8>),
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
    /// addresses as decimal strings "0".."14", values next hops as integers 0..=14). JSON
    /// `null` (a scenario without `routes`) is the empty table, [`Routes::direct`]. A node
    /// routing to itself, or naming itself as a next hop, is refused. Only the syntax and the
    /// addresses are checked here; [`Routes::check`] checks the table against the network.
    pub fn from_json(value: &serde_json::Value) -> Result<Routes, RoutesError> {
        let rows = match value {
            serde_json::Value::Null => return Ok(Routes::direct()),
            serde_json::Value::Object(rows) => rows,
            other => {
                return Err(RoutesError::Syntax {
                    at: "routes".to_string(),
                    what: format!(
                        "expected an object of node addresses to objects of next hops, found {}",
                        shown_value(other)
                    ),
                });
            }
        };
        let mut routes = Routes::direct();
        for (node_key, row) in rows {
            let at_node = format!("routes.{}", shown_key(node_key));
            let node = address_key(node_key, &at_node)?;
            let serde_json::Value::Object(row) = row else {
                return Err(RoutesError::Syntax {
                    at: at_node,
                    what: format!(
                        "expected an object of destination addresses to next hops, found {}",
                        shown_value(row)
                    ),
                });
            };
            for (dst_key, hop) in row {
                let at = format!("{at_node}.{}", shown_key(dst_key));
                let dst = address_key(dst_key, &at)?;
                if dst == node {
                    return Err(RoutesError::Syntax {
                        at,
                        what: format!(
                            "expected a destination other than the node itself, found {dst}"
                        ),
                    });
                }
                let hop = address_value(hop, &at)?;
                if hop == node {
                    return Err(RoutesError::Syntax {
                        at,
                        what: format!(
                            "expected a next hop other than the node itself, found {hop}"
                        ),
                    });
                }
                routes.set(node, dst, hop);
            }
        }
        Ok(routes)
    }

    /// Adds (or replaces) a route: from `node`, frames for `dst` go to `hop`.
    pub fn set(&mut self, node: u8, dst: u8, hop: u8) {
        self.next.entry(node).or_default().insert(dst, hop);
    }

    /// Every entry of the table as (node, destination, next hop), in address order.
    pub fn entries(&self) -> impl Iterator<Item = (u8, u8, u8)> + '_ {
        self.next
            .iter()
            .flat_map(|(&node, row)| row.iter().map(move |(&dst, &hop)| (node, dst, hop)))
    }

    /// True when the table has no entry (every destination one hop away).
    pub fn is_empty(&self) -> bool {
        self.entries().next().is_none()
    }

    /// The next hop from `node` towards `dst` (`dst` itself without an entry).
    pub fn next_hop(&self, node: u8, dst: u8) -> u8 {
        self.next
            .get(&node)
            .and_then(|row| row.get(&dst))
            .copied()
            .unwrap_or(dst)
    }

    /// True when the table holds an entry for `node` towards `dst`.
    fn has_entry(&self, node: u8, dst: u8) -> bool {
        self.next
            .get(&node)
            .is_some_and(|row| row.contains_key(&dst))
    }

    fn walk(&self, src: u8, dst: u8) -> Walk {
        let mut path = vec![src];
        let mut at = src;
        while at != dst {
            at = self.next_hop(at, dst);
            let seen = path.contains(&at);
            path.push(at);
            if seen {
                return Walk::Loops(path);
            }
            if path.len() > MAX_PATH_NODES {
                return Walk::TooLong(path);
            }
        }
        Walk::Reached(path)
    }

    /// The routed path from `src` to `dst`, both included (`[src]` when they are equal); none
    /// when it loops or is longer than [`MAX_PATH_NODES`] nodes.
    pub fn path(&self, src: u8, dst: u8) -> Option<Vec<u8>> {
        match self.walk(src, dst) {
            Walk::Reached(path) => Some(path),
            Walk::Loops(_) | Walk::TooLong(_) => None,
        }
    }

    /// Checks the table against the network: `nodes` are its addresses; `linked(a, b)` is true
    /// when a and b share an interface (a medium, a port). Every address in the table must be a
    /// node, every next hop linked to its node, and no path between two nodes may loop. A
    /// destination with no entry is one hop away even when out of reach (it is then simply
    /// unreachable); only the hops the table names must be linked.
    pub fn check(&self, nodes: &[u8], linked: &dyn Fn(u8, u8) -> bool) -> Result<(), RoutesError> {
        for (node, dst, hop) in self.entries() {
            let at_node = format!("routes.\"{node}\"");
            if !nodes.contains(&node) {
                return Err(RoutesError::Address {
                    at: at_node,
                    found: node.to_string(),
                });
            }
            let at = format!("{at_node}.\"{dst}\"");
            for address in [dst, hop] {
                if !nodes.contains(&address) {
                    return Err(RoutesError::Address {
                        at,
                        found: address.to_string(),
                    });
                }
            }
        }
        let mut sorted = nodes.to_vec();
        sorted.sort_unstable();
        sorted.dedup();
        for &src in &sorted {
            for &dst in &sorted {
                if src == dst {
                    continue;
                }
                let path = match self.walk(src, dst) {
                    Walk::Reached(path) => path,
                    Walk::Loops(path) => return Err(RoutesError::Loop { src, dst, path }),
                    Walk::TooLong(path) => {
                        return Err(RoutesError::Syntax {
                            at: "routes".to_string(),
                            what: format!(
                                "expected paths of at most {MAX_PATH_NODES} nodes, found one from \
                                 {src} to {dst} longer: {}",
                                path_text(&path)
                            ),
                        });
                    }
                };
                for pair in path.windows(2) {
                    if let [a, b] = *pair
                        && self.has_entry(a, dst)
                        && !linked(a, b)
                    {
                        return Err(RoutesError::NoInterface {
                            node: a,
                            dst,
                            hop: b,
                        });
                    }
                }
            }
        }
        Ok(())
    }
}

/// An address given as a key: a decimal string 0..=14.
fn address_key(key: &str, at: &str) -> Result<u8, RoutesError> {
    let canonical = !key.is_empty()
        && key.bytes().all(|b| b.is_ascii_digit())
        && (key == "0" || !key.starts_with('0'));
    if !canonical {
        return Err(RoutesError::Syntax {
            at: at.to_string(),
            what: format!(
                "expected an address 0..=14 as a decimal string, found {}",
                shown_key(key)
            ),
        });
    }
    match key.parse::<u8>() {
        Ok(address) if address <= MAX_VEHICLE => Ok(address),
        _ => Err(RoutesError::Address {
            at: at.to_string(),
            found: shown(key),
        }),
    }
}

/// An address given as a value: an integer 0..=14.
fn address_value(value: &serde_json::Value, at: &str) -> Result<u8, RoutesError> {
    if !value.is_number() {
        return Err(RoutesError::Syntax {
            at: at.to_string(),
            what: format!(
                "expected a next hop address as an integer 0..=14, found {}",
                shown_value(value)
            ),
        });
    }
    match value.as_u64() {
        Some(address) if address <= u64::from(MAX_VEHICLE) => {
            u8::try_from(address).map_err(|_| RoutesError::Address {
                at: at.to_string(),
                found: shown_value(value),
            })
        }
        _ => Err(RoutesError::Address {
            at: at.to_string(),
            found: shown_value(value),
        }),
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
    /// The interfaces to send it on, unchanged, in increasing order, each once (empty: not
    /// forwarded).
    pub forward_on: Vec<usize>,
    /// Why it was neither delivered nor forwarded.
    pub dropped: Option<Dropped>,
}

impl Decision {
    fn dropped(addresses: Option<(u8, u8)>, why: Dropped) -> Decision {
        Decision {
            addresses,
            deliver: false,
            forward_on: Vec::new(),
            dropped: Some(why),
        }
    }
}

/// One node's routing: its address, the table, its interfaces, and the frames it took lately.
#[derive(Debug, Clone)]
pub struct Router {
    address: u8,
    routes: Routes,
    interfaces: Vec<Vec<u8>>,
    /// The duplicate window in nanoseconds; none: no cache.
    window_ns: Option<u64>,
    /// (when, hash of the frame's bytes) of the frames taken or sent, oldest first.
    seen: VecDeque<(SimTime, u64)>,
}

/// The bytes a frame occupies in `bytes` (all of them when it does not parse).
fn frame_bytes(bytes: &[u8]) -> &[u8] {
    match Frame::new_checked(bytes) {
        Ok(frame) => bytes.get(..frame.total_len()).unwrap_or(bytes),
        Err(_) => bytes,
    }
}

/// True when `node` is on `path` and neither its first nor its last node.
fn strictly_inside(path: &[u8], node: u8) -> bool {
    path.iter()
        .position(|&at| at == node)
        .is_some_and(|at| at > 0 && at + 1 < path.len())
}

fn hash_of(bytes: &[u8]) -> u64 {
    let mut hasher = DefaultHasher::new();
    hasher.write(bytes);
    hasher.finish()
}

impl Router {
    /// The router of node `address`. `interfaces[k]` lists the addresses interface k reaches
    /// (the other nodes on its medium, or behind its port). `duplicate_window_s`: a frame whose
    /// bytes equal one the node took (delivered or forwarded) or sent less than this long ago
    /// is a copy; zero, negative or NaN: no cache (no frame is ever a duplicate). Give it less
    /// than the shortest time in which a sender sends the same bytes again (half the TDMA
    /// cycle).
    pub fn new(
        address: u8,
        routes: Routes,
        interfaces: Vec<Vec<u8>>,
        duplicate_window_s: f64,
    ) -> Router {
        // `as` saturates: infinity gives u64::MAX; NaN and negatives are caught first.
        let window_ns = if duplicate_window_s > 0.0 {
            Some((duplicate_window_s * 1e9) as u64).filter(|&ns| ns > 0)
        } else {
            None
        };
        Router {
            address,
            routes,
            interfaces,
            window_ns,
            seen: VecDeque::new(),
        }
    }

    /// The node's address.
    pub fn address(&self) -> u8 {
        self.address
    }

    /// The network's table this router follows.
    pub fn routes(&self) -> &Routes {
        &self.routes
    }

    /// The addresses each interface reaches.
    pub fn interfaces(&self) -> &[Vec<u8>] {
        &self.interfaces
    }

    /// The interface a frame this node originates for `dst` goes out on: the one reaching its
    /// next hop (the first interface when none does, or for broadcast).
    pub fn interface_to(&self, dst: u8) -> usize {
        if dst == BROADCAST {
            return 0;
        }
        self.interface_reaching(self.routes.next_hop(self.address, dst))
            .unwrap_or(0)
    }

    /// Every interface a frame this node originates for `dst` goes out on: for broadcast each
    /// interface that reaches a node (a relay's broadcast reaches both its media); otherwise
    /// [`Router::interface_to`] alone. Empty when the node has no interface.
    pub fn originate_on(&self, dst: u8) -> Vec<usize> {
        if dst == BROADCAST {
            return (0..self.interfaces.len())
                .filter(|&k| {
                    self.interfaces
                        .get(k)
                        .is_some_and(|reach| !reach.is_empty())
                })
                .collect();
        }
        let interface = self.interface_to(dst);
        if interface < self.interfaces.len() {
            vec![interface]
        } else {
            Vec::new()
        }
    }

    fn interface_reaching(&self, hop: u8) -> Option<usize> {
        self.interfaces
            .iter()
            .position(|reach| reach.contains(&hop))
    }

    /// Notes a frame the node itself sends at `t` (so its copy relayed back is dropped).
    pub fn sent(&mut self, t: SimTime, bytes: &[u8]) {
        self.prune(t);
        self.remember(t, hash_of(frame_bytes(bytes)));
    }

    /// Forgets the frames taken a window or more before `t` (all of them without a window).
    fn prune(&mut self, t: SimTime) {
        match self.window_ns {
            None => self.seen.clear(),
            Some(window_ns) => self
                .seen
                .retain(|&(when, _)| t.0.saturating_sub(when.0) < window_ns),
        }
    }

    fn remember(&mut self, t: SimTime, hash: u64) {
        if self.window_ns.is_none() {
            return;
        }
        while self.seen.len() >= DUPLICATE_CACHE_ENTRIES {
            self.seen.pop_front();
        }
        self.seen.push_back((t, hash));
    }

    /// The interfaces towards the next hops of the routed paths from `src` this node is
    /// strictly inside, for every destination (a broadcast's forwarding).
    fn broadcast_interfaces(&self, src: u8) -> Vec<usize> {
        let mut out = Vec::new();
        for dst in 0..=MAX_VEHICLE {
            if dst == src || dst == self.address {
                continue;
            }
            let Some(path) = self.routes.path(src, dst) else {
                continue;
            };
            if strictly_inside(&path, self.address) {
                self.push_interface(&mut out, self.routes.next_hop(self.address, dst));
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Adds the interface reaching `hop` (the first interface when none does, if any).
    fn push_interface(&self, out: &mut Vec<usize>, hop: u8) {
        let interface = self.interface_reaching(hop).unwrap_or(0);
        if interface < self.interfaces.len() {
            out.push(interface);
        }
    }

    /// What to do with `bytes`, heard at `t` on interface `interface`. `interface` is where it
    /// was heard; the decision does not depend on it (on a shared medium a relay forwards on
    /// the interface it heard the frame on).
    pub fn decide(&mut self, t: SimTime, bytes: &[u8], interface: usize) -> Decision {
        let _ = interface;
        self.prune(t);
        let frame = match Frame::new_checked(bytes) {
            Ok(frame) if frame.check().is_ok() => frame,
            _ => return Decision::dropped(None, Dropped::Malformed),
        };
        let (src, dst) = (frame.src(), frame.dst());
        let addresses = Some((src, dst));
        if src == self.address {
            return Decision::dropped(addresses, Dropped::Own);
        }
        let hash = hash_of(frame_bytes(bytes));
        if self.seen.iter().any(|&(_, seen)| seen == hash) {
            return Decision::dropped(addresses, Dropped::Duplicate);
        }
        let decision = if dst == self.address {
            Decision {
                addresses,
                deliver: true,
                forward_on: Vec::new(),
                dropped: None,
            }
        } else if dst == BROADCAST {
            Decision {
                addresses,
                deliver: true,
                forward_on: self.broadcast_interfaces(src),
                dropped: None,
            }
        } else {
            let mut forward_on = Vec::new();
            let on_path = self.routes.path(src, dst);
            if on_path.is_some_and(|path| strictly_inside(&path, self.address)) {
                self.push_interface(&mut forward_on, self.routes.next_hop(self.address, dst));
            }
            if forward_on.is_empty() {
                return Decision::dropped(addresses, Dropped::OffPath);
            }
            Decision {
                addresses,
                deliver: false,
                forward_on,
                dropped: None,
            }
        };
        self.remember(t, hash);
        decision
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rovlink_wire::operator::Order;
    use rovlink_wire::rov::{BasicStatus, Status};
    use rovlink_wire::{Message, operator, rov};
    use serde_json::json;

    /// An operator frame for `dst`; `x_cm` makes frames differ.
    fn op_frame(dst: u8, x_cm: i16) -> Vec<u8> {
        crate::emit(
            0,
            dst,
            Message::Operator(operator::Repr {
                oid: false,
                clo: false,
                eisn: false,
                ic: false,
                rit: 0,
                order: Order::GoTo {
                    x_cm,
                    y_cm: 0,
                    z_cm: 0,
                    heading_deg: 0,
                },
            }),
        )
    }

    /// A vehicle frame from `src` to `dst`; `itsn` makes frames differ.
    fn rov_frame(src: u8, dst: u8, itsn: u8) -> Vec<u8> {
        crate::emit(
            src,
            dst,
            Message::Rov(rov::Repr {
                ft: false,
                lt: false,
                isn: false,
                ci: false,
                itsn,
                status: Status::Basic(BasicStatus::default()),
                trunk: Vec::new(),
            }),
        )
    }

    fn issue_routes() -> Routes {
        Routes::from_json(&json!({"0":{"2":1},"2":{"0":1}})).unwrap()
    }

    fn at(seconds: f64) -> SimTime {
        SimTime::from_secs_f64(seconds)
    }

    /// Node `address` of the issue's scenario: one RF interface reaching the other two.
    fn issue_router(address: u8) -> Router {
        let others = [0, 1, 2].into_iter().filter(|&a| a != address).collect();
        Router::new(address, issue_routes(), vec![others], 0.5)
    }

    fn forwarded(decision: &Decision, on: &[usize]) -> bool {
        !decision.deliver && decision.forward_on == on && decision.dropped.is_none()
    }

    fn delivered(decision: &Decision) -> bool {
        decision.deliver && decision.forward_on.is_empty() && decision.dropped.is_none()
    }

    #[test]
    fn the_issue_table_parses_and_routes_through_the_relay() {
        let routes = issue_routes();
        assert_eq!(
            routes.entries().collect::<Vec<_>>(),
            vec![(0, 2, 1), (2, 0, 1)]
        );
        assert_eq!(routes.path(0, 2), Some(vec![0, 1, 2]));
        assert_eq!(routes.path(2, 0), Some(vec![2, 1, 0]));
        assert_eq!(routes.path(0, 1), Some(vec![0, 1]));
        assert_eq!(routes.path(1, 2), Some(vec![1, 2]));
        assert_eq!(routes.path(1, 1), Some(vec![1]));
        // The far vehicle is out of the operator's range: only the relay's links exist.
        let linked = |a: u8, b: u8| matches!((a.min(b), a.max(b)), (0, 1) | (1, 2));
        assert_eq!(routes.check(&[0, 1, 2], &linked), Ok(()));
        assert!(!routes.is_empty());
        assert!(Routes::direct().is_empty());
        assert_eq!(Routes::direct().check(&[0, 1, 2], &linked), Ok(()));
    }

    #[test]
    fn the_relay_forwards_each_way_once_and_drops_its_own_echo() {
        let mut relay = issue_router(1);
        let down = op_frame(2, 150);
        let first = relay.decide(at(1.0), &down, 0);
        assert!(forwarded(&first, &[0]), "{first:?}");
        assert_eq!(first.addresses, Some((0, 2)));
        // Its own forward heard back (or a second copy of the operator's frame).
        let echo = relay.decide(at(1.1), &down, 0);
        assert_eq!(echo.dropped, Some(Dropped::Duplicate));
        assert!(!echo.deliver && echo.forward_on.is_empty());

        let up = rov_frame(2, 0, 3);
        assert!(forwarded(&relay.decide(at(1.2), &up, 0), &[0]));
        assert_eq!(
            relay.decide(at(1.3), &up, 0).dropped,
            Some(Dropped::Duplicate)
        );

        // Its own frame relayed back by anyone.
        let own = rov_frame(1, 0, 0);
        let decision = relay.decide(at(1.4), &own, 0);
        assert_eq!(decision.dropped, Some(Dropped::Own));
        assert_eq!(decision.addresses, Some((1, 0)));

        // Frames for the relay itself are delivered, not forwarded.
        assert!(delivered(&relay.decide(at(1.5), &op_frame(1, 0), 0)));
    }

    #[test]
    fn the_far_vehicle_drops_frames_for_the_relay_as_off_path() {
        let mut far = issue_router(2);
        let for_relay = op_frame(1, 10);
        let decision = far.decide(at(2.0), &for_relay, 0);
        assert_eq!(decision.dropped, Some(Dropped::OffPath));
        assert!(!decision.deliver && decision.forward_on.is_empty());
        // Off-path frames are not remembered: the same copy is off-path again, not a duplicate.
        assert_eq!(
            far.decide(at(2.1), &for_relay, 0).dropped,
            Some(Dropped::OffPath)
        );
        // The relay's answer to the operator, overheard.
        assert_eq!(
            far.decide(at(2.2), &rov_frame(1, 0, 1), 0).dropped,
            Some(Dropped::OffPath)
        );
        // Its own frame forwarded by the relay.
        assert_eq!(
            far.decide(at(2.3), &rov_frame(2, 0, 1), 0).dropped,
            Some(Dropped::Own)
        );
        // Its order, forwarded by the relay, then the operator's original heard late.
        let order = op_frame(2, 20);
        assert!(delivered(&far.decide(at(2.4), &order, 0)));
        assert_eq!(
            far.decide(at(2.5), &order, 0).dropped,
            Some(Dropped::Duplicate)
        );
    }

    #[test]
    fn the_operator_drops_the_relayed_copy_of_its_own_frame() {
        let mut operator = issue_router(0);
        let order = op_frame(2, 30);
        operator.sent(at(3.0), &order);
        let copy = operator.decide(at(3.1), &order, 0);
        assert_eq!(copy.dropped, Some(Dropped::Own));
        // The far vehicle's answer: delivered once, the second copy is a duplicate.
        let answer = rov_frame(2, 0, 5);
        assert!(delivered(&operator.decide(at(3.2), &answer, 0)));
        assert_eq!(
            operator.decide(at(3.3), &answer, 0).dropped,
            Some(Dropped::Duplicate)
        );
        assert_eq!(operator.interface_to(2), 0);
    }

    #[test]
    fn an_identical_frame_after_the_window_is_taken_again() {
        let mut relay = issue_router(1);
        let down = op_frame(2, 40);
        assert!(forwarded(&relay.decide(at(10.0), &down, 0), &[0]));
        assert_eq!(
            relay.decide(at(10.499), &down, 0).dropped,
            Some(Dropped::Duplicate)
        );
        assert!(forwarded(&relay.decide(at(10.5), &down, 0), &[0]));
        assert!(forwarded(&relay.decide(at(11.2), &down, 0), &[0]));
    }

    #[test]
    fn a_frame_the_node_sent_is_a_duplicate_when_it_comes_back() {
        let mut relay = issue_router(1);
        let down = op_frame(2, 50);
        relay.sent(at(4.0), &down);
        assert_eq!(
            relay.decide(at(4.1), &down, 0).dropped,
            Some(Dropped::Duplicate)
        );
    }

    #[test]
    fn no_window_means_no_duplicates_whatever_the_number() {
        for window_s in [0.0, -1.0, f64::NAN, f64::NEG_INFINITY, 1e-12] {
            let mut relay = Router::new(1, issue_routes(), vec![vec![0, 2]], window_s);
            let down = op_frame(2, 60);
            relay.sent(at(0.0), &down);
            for k in 0..3_u32 {
                let decision = relay.decide(at(f64::from(k) * 1e-3), &down, 0);
                assert!(
                    forwarded(&decision, &[0]),
                    "window {window_s}: {decision:?}"
                );
            }
            assert!(relay.seen.is_empty());
        }
        let mut forever = Router::new(1, issue_routes(), vec![vec![0, 2]], f64::INFINITY);
        let down = op_frame(2, 61);
        assert!(forwarded(&forever.decide(at(0.0), &down, 0), &[0]));
        assert_eq!(
            forever.decide(at(1e6), &down, 0).dropped,
            Some(Dropped::Duplicate)
        );
    }

    #[test]
    fn the_duplicate_cache_is_bounded() {
        let mut relay = Router::new(1, issue_routes(), vec![vec![0, 2]], 1e9);
        for k in 0..(DUPLICATE_CACHE_ENTRIES + 100) {
            let x_cm = i16::try_from(k).unwrap();
            assert!(forwarded(
                &relay.decide(at(1.0), &op_frame(2, x_cm), 0),
                &[0]
            ));
        }
        assert_eq!(relay.seen.len(), DUPLICATE_CACHE_ENTRIES);
        // The oldest entries went first.
        assert!(forwarded(&relay.decide(at(1.0), &op_frame(2, 0), 0), &[0]));
    }

    #[test]
    fn malformed_frames_are_dropped() {
        let mut relay = issue_router(1);
        let good = op_frame(2, 70);
        let mut bad_crc = good.clone();
        let last = bad_crc.len() - 1;
        bad_crc[last] ^= 0x01;
        let mut bad_preamble = good.clone();
        bad_preamble[0] = 0x54;
        for bytes in [
            Vec::new(),
            vec![0x55],
            good[..good.len() - 1].to_vec(),
            bad_crc,
            bad_preamble,
        ] {
            let decision = relay.decide(at(5.0), &bytes, 0);
            assert_eq!(decision, Decision::dropped(None, Dropped::Malformed));
        }
        // Bytes after a whole frame are ignored, and the frame is the same frame.
        let mut trailing = good.clone();
        trailing.extend_from_slice(&[0xde, 0xad]);
        assert!(forwarded(&relay.decide(at(5.0), &trailing, 0), &[0]));
        assert_eq!(
            relay.decide(at(5.1), &good, 0).dropped,
            Some(Dropped::Duplicate)
        );
    }

    #[test]
    fn a_loop_is_refused_with_its_path() {
        let routes = Routes::from_json(&json!({"1":{"3":2},"2":{"3":1}})).unwrap();
        assert_eq!(routes.path(1, 3), None);
        assert_eq!(routes.path(2, 3), None);
        let err = routes.check(&[1, 2, 3], &|_, _| true).unwrap_err();
        assert_eq!(
            err,
            RoutesError::Loop {
                src: 1,
                dst: 3,
                path: vec![1, 2, 1]
            }
        );
        assert_eq!(
            err.to_string(),
            "routes: the path from 1 to 3 loops: 1 -> 2 -> 1"
        );
    }

    #[test]
    fn a_path_longer_than_sixteen_nodes_is_none() {
        let mut routes = Routes::direct();
        for node in 20..40 {
            routes.set(node, 200, node + 1);
        }
        assert_eq!(routes.path(20, 200), None);
        assert_eq!(routes.path(30, 200).map(|p| p.len()), Some(12));
        let nodes: Vec<u8> = (20..41).chain([200]).collect();
        let err = routes.check(&nodes, &|_, _| true).unwrap_err();
        assert!(
            err.to_string().starts_with(
                "routes: expected paths of at most 16 nodes, found one from 20 to 200"
            ),
            "{err}"
        );
    }

    #[test]
    fn a_route_through_a_node_without_a_shared_interface_is_refused() {
        // A star around the operator: 1 and 2 each reach only 0.
        let star = |a: u8, b: u8| a.min(b) == 0 && a != b;
        let routes = Routes::from_json(&json!({"2":{"0":1}})).unwrap();
        let err = routes.check(&[0, 1, 2], &star).unwrap_err();
        assert_eq!(
            err,
            RoutesError::NoInterface {
                node: 2,
                dst: 0,
                hop: 1
            }
        );
        assert_eq!(
            err.to_string(),
            "routes: node 2 routes to 0 through 1, but 2 and 1 share no interface"
        );
        // An entry naming the destination itself still claims an interface.
        let named = Routes::from_json(&json!({"1":{"2":2}})).unwrap();
        assert_eq!(
            named.check(&[0, 1, 2], &star),
            Err(RoutesError::NoInterface {
                node: 1,
                dst: 2,
                hop: 2
            })
        );
    }

    #[test]
    fn every_address_in_the_table_must_be_a_node() {
        let all = |_: u8, _: u8| true;
        let cases = [
            (json!({"3":{"0":1}}), "routes.\"3\"", "3"),
            (json!({"0":{"3":1}}), "routes.\"0\".\"3\"", "3"),
            (json!({"0":{"2":3}}), "routes.\"0\".\"2\"", "3"),
        ];
        for (table, at, found) in cases {
            let err = Routes::from_json(&table)
                .unwrap()
                .check(&[0, 1, 2], &all)
                .unwrap_err();
            assert_eq!(
                err,
                RoutesError::Address {
                    at: at.to_string(),
                    found: found.to_string()
                }
            );
            assert_eq!(
                err.to_string(),
                format!("{at}: expected an address 0..=14 of a node in the network, found {found}")
            );
        }
    }

    #[test]
    fn malformed_tables_are_refused_with_exact_messages() {
        let cases = [
            (
                json!([1]),
                "routes: expected an object of node addresses to objects of next hops, found [1]",
            ),
            (
                json!("0"),
                "routes: expected an object of node addresses to objects of next hops, found \"0\"",
            ),
            (
                json!({"x":{}}),
                "routes.\"x\": expected an address 0..=14 as a decimal string, found \"x\"",
            ),
            (
                json!({"01":{}}),
                "routes.\"01\": expected an address 0..=14 as a decimal string, found \"01\"",
            ),
            (
                json!({"-1":{}}),
                "routes.\"-1\": expected an address 0..=14 as a decimal string, found \"-1\"",
            ),
            (
                json!({"15":{}}),
                "routes.\"15\": expected an address 0..=14 of a node in the network, found 15",
            ),
            (
                json!({"2":5}),
                "routes.\"2\": expected an object of destination addresses to next hops, found 5",
            ),
            (
                json!({"2":{" 0":1}}),
                "routes.\"2\".\" 0\": expected an address 0..=14 as a decimal string, found \" 0\"",
            ),
            (
                json!({"2":{"15":1}}),
                "routes.\"2\".\"15\": expected an address 0..=14 of a node in the network, found 15",
            ),
            (
                json!({"2":{"0":"x"}}),
                "routes.\"2\".\"0\": expected a next hop address as an integer 0..=14, found \"x\"",
            ),
            (
                json!({"2":{"0":null}}),
                "routes.\"2\".\"0\": expected a next hop address as an integer 0..=14, found null",
            ),
            (
                json!({"2":{"0":15}}),
                "routes.\"2\".\"0\": expected an address 0..=14 of a node in the network, found 15",
            ),
            (
                json!({"2":{"0":-1}}),
                "routes.\"2\".\"0\": expected an address 0..=14 of a node in the network, found -1",
            ),
            (
                json!({"2":{"0":1.5}}),
                "routes.\"2\".\"0\": expected an address 0..=14 of a node in the network, found 1.5",
            ),
            (
                json!({"2":{"2":1}}),
                "routes.\"2\".\"2\": expected a destination other than the node itself, found 2",
            ),
            (
                json!({"2":{"0":2}}),
                "routes.\"2\".\"0\": expected a next hop other than the node itself, found 2",
            ),
        ];
        for (table, message) in cases {
            let err = Routes::from_json(&table).unwrap_err();
            assert_eq!(err.to_string(), message, "{table}");
        }
        assert_eq!(
            Routes::from_json(&json!({"2":{"0":15}})).unwrap_err(),
            RoutesError::Address {
                at: "routes.\"2\".\"0\"".to_string(),
                found: "15".to_string()
            }
        );
        assert!(matches!(
            Routes::from_json(&json!({"2":{"0":"x"}})),
            Err(RoutesError::Syntax { .. })
        ));
    }

    #[test]
    fn long_keys_and_values_are_cut_short_in_messages() {
        let key = "k".repeat(1000);
        let err = Routes::from_json(&json!({ key: {} }))
            .unwrap_err()
            .to_string();
        assert!(err.len() < 200, "{err}");
        assert!(err.contains("..."), "{err}");
        let err = Routes::from_json(&json!({"1": {"0": "v".repeat(1000)}}))
            .unwrap_err()
            .to_string();
        assert!(err.len() < 200, "{err}");
    }

    #[test]
    fn null_and_empty_objects_are_no_routes() {
        assert_eq!(
            Routes::from_json(&serde_json::Value::Null),
            Ok(Routes::direct())
        );
        assert_eq!(Routes::from_json(&json!({})), Ok(Routes::direct()));
        assert_eq!(Routes::from_json(&json!({"3":{}})), Ok(Routes::direct()));
    }

    /// A chain 0 - 1 - 2 - 3, each link its own medium, with routes along it both ways.
    fn chain() -> (Routes, Vec<Router>) {
        let routes = Routes::from_json(&json!({
            "0": {"2": 1, "3": 1},
            "1": {"3": 2},
            "2": {"0": 1},
            "3": {"0": 2, "1": 2}
        }))
        .unwrap();
        let linked = |a: u8, b: u8| a.abs_diff(b) == 1;
        routes.check(&[0, 1, 2, 3], &linked).unwrap();
        let interfaces = [
            vec![vec![1]],
            vec![vec![0], vec![2]],
            vec![vec![1], vec![3]],
            vec![vec![2]],
        ];
        let routers = interfaces
            .into_iter()
            .enumerate()
            .map(|(address, reach)| {
                Router::new(u8::try_from(address).unwrap(), routes.clone(), reach, 0.5)
            })
            .collect();
        (routes, routers)
    }

    /// Floods `bytes` sent by `from` over the chain; the deliveries per node and the number of
    /// transmissions.
    fn flood(routers: &mut [Router], from: usize, bytes: &[u8]) -> ([usize; 4], usize) {
        let t = at(7.0);
        let mut delivered = [0; 4];
        let mut transmissions = 0;
        let dst = Frame::new_checked(bytes).unwrap().dst();
        routers[from].sent(t, bytes);
        let mut on_air: Vec<(usize, usize)> = routers[from]
            .originate_on(dst)
            .into_iter()
            .map(|k| (from, k))
            .collect();
        while let Some((sender, interface)) = on_air.pop() {
            transmissions += 1;
            let address = routers[sender].address();
            let hearers = routers[sender].interfaces()[interface].clone();
            for hearer in hearers {
                let node = usize::from(hearer);
                let back = routers[node].interface_reaching(address).unwrap();
                let decision = routers[node].decide(t, bytes, back);
                if decision.deliver {
                    delivered[node] += 1;
                }
                on_air.extend(decision.forward_on.iter().map(|&k| (node, k)));
            }
        }
        (delivered, transmissions)
    }

    #[test]
    fn a_broadcast_reaches_every_node_of_a_chain_once() {
        let (_, mut routers) = chain();
        let broadcast = op_frame(BROADCAST, 80);
        let (delivered, transmissions) = flood(&mut routers, 0, &broadcast);
        assert_eq!(delivered, [0, 1, 1, 1]);
        assert_eq!(transmissions, 3);

        let (_, mut routers) = chain();
        let from_far = rov_frame(3, BROADCAST, 9);
        let (delivered, transmissions) = flood(&mut routers, 3, &from_far);
        assert_eq!(delivered, [1, 1, 1, 0]);
        assert_eq!(transmissions, 3);
    }

    #[test]
    fn a_unicast_crosses_the_chain_along_its_path() {
        let (routes, mut routers) = chain();
        let order = op_frame(3, 90);
        let (delivered, transmissions) = flood(&mut routers, 0, &order);
        assert_eq!(delivered, [0, 0, 0, 1]);
        assert_eq!(transmissions, routes.path(0, 3).unwrap().len() - 1);
        // The middle relay sends it on the interface towards its next hop.
        assert_eq!(routers[1].interface_to(3), 1);
        assert_eq!(routers[1].interface_to(0), 0);
        assert_eq!(routers[2].interface_to(0), 0);
        assert_eq!(routers[2].interface_to(BROADCAST), 0);
    }

    #[test]
    fn without_routes_the_far_end_of_a_chain_gets_nothing() {
        let (_, routers) = chain();
        let mut bare: Vec<Router> = routers
            .into_iter()
            .map(|r| Router::new(r.address, Routes::direct(), r.interfaces, 0.5))
            .collect();
        let (delivered, transmissions) = flood(&mut bare, 0, &op_frame(3, 91));
        assert_eq!((delivered, transmissions), ([0; 4], 1));
        let (delivered, _) = flood(&mut bare, 0, &op_frame(BROADCAST, 92));
        assert_eq!(delivered, [0, 1, 0, 0]);
    }

    #[test]
    fn a_relay_originates_a_broadcast_on_every_interface_it_has() {
        let (_, routers) = chain();
        assert_eq!(routers[1].originate_on(BROADCAST), vec![0, 1]);
        assert_eq!(routers[1].originate_on(3), vec![1]);
        assert_eq!(routers[1].originate_on(0), vec![0]);
        let silent = Router::new(1, Routes::direct(), vec![Vec::new(), vec![2]], 0.5);
        assert_eq!(silent.originate_on(BROADCAST), vec![1]);
        let lonely = Router::new(1, Routes::direct(), Vec::new(), 0.5);
        assert_eq!(lonely.originate_on(BROADCAST), Vec::<usize>::new());
        assert_eq!(lonely.originate_on(0), Vec::<usize>::new());
    }

    #[test]
    fn a_router_without_interfaces_never_forwards() {
        let mut lonely = Router::new(1, issue_routes(), Vec::new(), 0.5);
        assert_eq!(lonely.interface_to(2), 0);
        assert_eq!(
            lonely.decide(at(0.0), &op_frame(2, 1), 0).dropped,
            Some(Dropped::OffPath)
        );
        assert!(lonely.decide(at(0.0), &op_frame(BROADCAST, 1), 0).deliver);
    }
}
