//! Property tests of the routing layer (`rcp::routing`).
//!
//! - Any JSON as a routes table, checked against any node set and any links, never panics in
//!   `Routes::from_json`, `check` or `path`; every path found follows next hops from its source
//!   to its destination without repeating a node, and a table `check` accepts has a path between
//!   every two nodes whose table-named hops are all linked.
//! - A flood over random shared media (each transmission heard by every other node on the
//!   medium, each hearing possibly lost or heard twice, all hearings in random order) of frames
//!   routed by a table `check` accepts: every node forwards each frame at most once; a unicast
//!   is delivered at most once, only at DST, forwarded only by nodes strictly inside its routed
//!   path, and sent at most (path nodes - 1) times; a broadcast is delivered at most once per
//!   node, never to its source; without losses every destination whose routed path is linked
//!   hop by hop gets the frame exactly once.
//! - Any bytes into `Router::decide` never panic and give a consistent decision.

use std::collections::{BTreeMap, VecDeque};

use proptest::prelude::*;
use rovlink_link::SimTime;
use rovlink_rcp::emit;
use rovlink_rcp::routing::{BROADCAST, Decision, MAX_PATH_NODES, Router, Routes};
use rovlink_wire::Message;
use serde_json::{Map, Number, Value};

/// A key of a routes object: mostly addresses, sometimes not.
fn key() -> impl Strategy<Value = String> {
    prop_oneof![
        6 => (0u8..=14).prop_map(|a| a.to_string()),
        1 => (15u8..=255).prop_map(|a| a.to_string()),
        1 => prop_oneof![Just("01"), Just("-1"), Just(" 2"), Just(""), Just("x"), Just("1.0")]
            .prop_map(str::to_string),
        1 => ".{0,12}",
    ]
}

/// A next hop: mostly addresses, sometimes any JSON scalar.
fn hop() -> impl Strategy<Value = Value> {
    prop_oneof![
        8 => (0u64..=14).prop_map(Value::from),
        1 => (-5i64..300).prop_map(Value::from),
        1 => any::<f64>().prop_map(|x| Number::from_f64(x).map_or(Value::Null, Value::Number)),
        1 => prop_oneof![Just(Value::Null), Just(Value::Bool(true)), Just(Value::from("1"))],
        1 => Just(Value::Array(vec![Value::from(1)])),
    ]
}

/// A row of a routes object: mostly an object of hops.
fn row() -> impl Strategy<Value = Value> {
    prop_oneof![
        8 => proptest::collection::vec((key(), hop()), 0..6)
            .prop_map(|entries| Value::Object(entries.into_iter().collect::<Map<_, _>>())),
        1 => hop(),
    ]
}

/// A routes value: mostly an object of rows.
fn table() -> impl Strategy<Value = Value> {
    prop_oneof![
        10 => proptest::collection::vec((key(), row()), 0..8)
            .prop_map(|rows| Value::Object(rows.into_iter().collect::<Map<_, _>>())),
        1 => row(),
    ]
}

/// Splitmix64: the random order, losses and copies of one flood.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        usize::try_from(self.next() % u64::try_from(n.max(1)).unwrap()).unwrap()
    }

    fn percent(&mut self, p: u64) -> bool {
        self.next() % 100 < p
    }
}

/// A network: node addresses and media (each the addresses on it).
#[derive(Debug, Clone)]
struct Net {
    nodes: Vec<u8>,
    media: Vec<Vec<u8>>,
}

impl Net {
    fn linked(&self, a: u8, b: u8) -> bool {
        a != b && self.media.iter().any(|m| m.contains(&a) && m.contains(&b))
    }

    /// Node `a`'s interfaces: (medium index, the other addresses on it).
    fn interfaces(&self, a: u8) -> Vec<(usize, Vec<u8>)> {
        self.media
            .iter()
            .enumerate()
            .filter(|(_, m)| m.contains(&a))
            .map(|(k, m)| (k, m.iter().copied().filter(|&b| b != a).collect()))
            .collect()
    }

    /// Next hops along shortest paths (BFS from each destination), the entries `keep` says.
    fn shortest_routes(&self, keep: &[bool]) -> Routes {
        let mut routes = Routes::direct();
        let mut bits = keep.iter().cycle();
        for &dst in &self.nodes {
            let mut dist = BTreeMap::from([(dst, 0usize)]);
            let mut queue = VecDeque::from([dst]);
            while let Some(at) = queue.pop_front() {
                for &b in &self.nodes {
                    if self.linked(at, b) && !dist.contains_key(&b) {
                        dist.insert(b, dist[&at] + 1);
                        queue.push_back(b);
                    }
                }
            }
            for &node in &self.nodes {
                let Some(&d) = dist.get(&node) else { continue };
                let hop =
                    self.nodes.iter().copied().find(|&b| {
                        self.linked(node, b) && dist.get(&b) == Some(&(d.wrapping_sub(1)))
                    });
                if let Some(hop) = hop
                    && d > 0
                    && *bits.next().unwrap_or(&true)
                {
                    routes.set(node, dst, hop);
                }
            }
        }
        routes
    }
}

prop_compose! {
    fn net()(nodes in proptest::sample::subsequence((0u8..=14).collect::<Vec<_>>(), 2..=7))
        (masks in proptest::collection::vec(1u32..(1 << nodes.len()), 1..=4), nodes in Just(nodes))
        -> Net
    {
        let media = masks
            .iter()
            .map(|mask| {
                nodes
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| mask & (1 << k) != 0)
                    .map(|(_, &a)| a)
                    .collect()
            })
            .collect();
        Net { nodes, media }
    }
}

/// What a flood did with each frame.
#[derive(Debug, Default)]
struct Outcome {
    /// Deliveries per frame and node.
    delivered: BTreeMap<(usize, u8), usize>,
    /// Decisions with a forward per frame and node.
    forwards: BTreeMap<(usize, u8), usize>,
    /// Transmissions per frame, the source's included.
    transmissions: BTreeMap<usize, usize>,
}

/// Floods `frames` over `net` with `routes`; `loss_percent` of hearings lost, 30 % heard twice.
fn flood(
    net: &Net,
    routes: &Routes,
    frames: &[(u8, u8, Vec<u8>)],
    seed: u64,
    loss_percent: u64,
) -> Result<Outcome, TestCaseError> {
    let mut rng = Rng(seed);
    let mut routers: BTreeMap<u8, (Router, Vec<usize>)> = net
        .nodes
        .iter()
        .map(|&a| {
            let (media, reach): (Vec<usize>, Vec<Vec<u8>>) = net.interfaces(a).into_iter().unzip();
            (a, (Router::new(a, routes.clone(), reach, 10.0), media))
        })
        .collect();
    let mut outcome = Outcome::default();
    // Hearings waiting: (frame, hearer, medium).
    let mut pending: Vec<(usize, u8, usize)> = Vec::new();
    let mut t_ms = 0u64;
    let transmit = |frame: usize,
                    sender: u8,
                    medium: usize,
                    pending: &mut Vec<(usize, u8, usize)>,
                    outcome: &mut Outcome,
                    rng: &mut Rng| {
        *outcome.transmissions.entry(frame).or_default() += 1;
        for &hearer in net.media[medium].iter().filter(|&&b| b != sender) {
            if rng.percent(loss_percent) {
                continue;
            }
            let copies = if rng.percent(30) { 2 } else { 1 };
            for _ in 0..copies {
                pending.push((frame, hearer, medium));
            }
        }
    };
    for (id, (src, dst, bytes)) in frames.iter().enumerate() {
        let (router, media) = routers.get_mut(src).expect("the source is a node");
        router.sent(SimTime(t_ms * 1_000_000), bytes);
        for interface in router.originate_on(*dst) {
            let medium = *media.get(interface).ok_or_else(|| {
                TestCaseError::fail(format!(
                    "node {src} sends on interface {interface} it has not"
                ))
            })?;
            transmit(id, *src, medium, &mut pending, &mut outcome, &mut rng);
        }
    }
    while !pending.is_empty() {
        let (id, hearer, medium) = pending.swap_remove(rng.below(pending.len()));
        t_ms += 1;
        let (router, media) = routers.get_mut(&hearer).expect("hearers are nodes");
        let interface = media
            .iter()
            .position(|&m| m == medium)
            .expect("on the medium");
        let decision: Decision = router.decide(SimTime(t_ms * 1_000_000), &frames[id].2, interface);
        prop_assert_eq!(decision.addresses, Some((frames[id].0, frames[id].1)));
        prop_assert_eq!(
            decision.dropped.is_some(),
            !decision.deliver && decision.forward_on.is_empty()
        );
        if decision.deliver {
            *outcome.delivered.entry((id, hearer)).or_default() += 1;
        }
        if !decision.forward_on.is_empty() {
            *outcome.forwards.entry((id, hearer)).or_default() += 1;
        }
        let mut sorted = decision.forward_on.clone();
        sorted.dedup();
        prop_assert_eq!(
            &sorted,
            &decision.forward_on,
            "forward_on repeats an interface"
        );
        for &k in &decision.forward_on {
            let medium = *media.get(k).ok_or_else(|| {
                TestCaseError::fail(format!(
                    "node {hearer} forwards on interface {k} it has not"
                ))
            })?;
            transmit(id, hearer, medium, &mut pending, &mut outcome, &mut rng);
        }
    }
    Ok(outcome)
}

/// True when every hop of `path` is linked.
fn linked_along(net: &Net, path: &[u8]) -> bool {
    path.windows(2).all(|w| net.linked(w[0], w[1]))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn any_table_parses_checks_and_paths_without_panicking(
        value in table(),
        nodes in proptest::collection::vec(0u8..=15, 0..8),
        links in any::<u64>(),
    ) {
        let linked = |a: u8, b: u8| a != b && links & (1 << ((a.min(b) * 7 + a.max(b)) % 64)) != 0;
        let Ok(routes) = Routes::from_json(&value) else { return Ok(()) };
        for (node, dst, hop) in routes.entries() {
            prop_assert!(node <= 14 && dst <= 14 && hop <= 14);
            prop_assert!(node != dst && node != hop);
        }
        let checked = routes.check(&nodes, &linked);
        for src in 0..=15u8 {
            for dst in 0..=15u8 {
                let Some(path) = routes.path(src, dst) else {
                    prop_assert!(
                        checked.is_err() || !nodes.contains(&src) || !nodes.contains(&dst),
                        "check accepted a table with no path from {} to {}", src, dst
                    );
                    continue;
                };
                prop_assert_eq!(path.first(), Some(&src));
                prop_assert_eq!(path.last(), Some(&dst));
                prop_assert!(path.len() <= MAX_PATH_NODES);
                let mut distinct = path.clone();
                distinct.sort_unstable();
                distinct.dedup();
                prop_assert_eq!(distinct.len(), path.len(), "path {:?} repeats a node", path);
                for w in path.windows(2) {
                    prop_assert_eq!(routes.next_hop(w[0], dst), w[1]);
                    let named = routes.entries().any(|(n, d, _)| n == w[0] && d == dst);
                    if checked.is_ok() && nodes.contains(&src) && nodes.contains(&dst) && named {
                        prop_assert!(linked(w[0], w[1]), "check accepted an unlinked hop");
                    }
                }
            }
        }
        if checked.is_ok() {
            for (node, dst, hop) in routes.entries() {
                prop_assert!(nodes.contains(&node) && nodes.contains(&dst) && nodes.contains(&hop));
            }
        }
        let _ = checked.map_err(|e| e.to_string());
    }

    #[test]
    fn a_flood_forwards_each_frame_once_per_node_and_along_its_path(
        net in net(),
        keep in proptest::collection::vec(prop_oneof![4 => Just(true), 1 => Just(false)], 1..40),
        detour in proptest::option::of((any::<usize>(), any::<usize>(), any::<usize>())),
        specs in proptest::collection::vec(
            (any::<usize>(), proptest::option::weighted(0.7, any::<usize>())), 1..6),
        seed in any::<u64>(),
        lossy in any::<bool>(),
    ) {
        let mut routes = net.shortest_routes(&keep);
        let n = net.nodes.len();
        if let Some((a, b, c)) = detour {
            let (node, dst, hop) = (net.nodes[a % n], net.nodes[b % n], net.nodes[c % n]);
            if node != dst && node != hop {
                routes.set(node, dst, hop);
            }
        }
        if routes.check(&net.nodes, &|a, b| net.linked(a, b)).is_err() {
            return Ok(());
        }
        let mut frames = Vec::new();
        for (k, (s, d)) in specs.iter().enumerate() {
            let src = net.nodes[s % n];
            let dst = match d {
                Some(d) if net.nodes[d % n] != src => net.nodes[d % n],
                Some(_) => continue,
                None => BROADCAST,
            };
            let tag = u8::try_from(k).unwrap();
            frames.push((src, dst, emit(src, dst, Message::Raw(vec![tag, src, dst]))));
        }
        let loss_percent = if lossy { 20 } else { 0 };
        let outcome = flood(&net, &routes, &frames, seed, loss_percent)?;

        for (&(id, node), &count) in &outcome.forwards {
            prop_assert_eq!(count, 1, "node {} forwarded frame {} {} times", node, id, count);
        }
        for (&(id, node), &count) in &outcome.delivered {
            prop_assert_eq!(count, 1, "node {} took frame {} {} times", node, id, count);
            prop_assert!(node != frames[id].0, "frame {} delivered to its source", id);
        }
        for (id, (src, dst, _)) in frames.iter().enumerate() {
            let (src, dst) = (*src, *dst);
            let got = |node: u8| outcome.delivered.get(&(id, node)).copied().unwrap_or(0);
            if dst == BROADCAST {
                for &node in net.nodes.iter().filter(|&&node| node != src) {
                    let path = routes.path(src, node).expect("check accepted the table");
                    if !lossy && linked_along(&net, &path) {
                        prop_assert_eq!(got(node), 1, "broadcast {} missed node {}", id, node);
                    }
                }
                continue;
            }
            let path = routes.path(src, dst).expect("check accepted the table");
            let sent = outcome.transmissions.get(&id).copied().unwrap_or(0);
            prop_assert!(sent < path.len(), "frame {} sent {} times on path {:?}", id, sent, path);
            for (&(frame, node), _) in outcome.forwards.range((id, 0)..=(id, u8::MAX)) {
                prop_assert_eq!(frame, id);
                let inside = path.iter().position(|&p| p == node)
                    .is_some_and(|at| at > 0 && at + 1 < path.len());
                prop_assert!(inside, "node {} off path {:?} forwarded frame {}", node, path, id);
            }
            for &node in net.nodes.iter().filter(|&&node| node != dst) {
                prop_assert_eq!(got(node), 0, "unicast {} delivered to {}", id, node);
            }
            if !lossy && linked_along(&net, &path) {
                prop_assert_eq!(got(dst), 1, "unicast {} along {:?} not delivered", id, path);
            }
        }
    }

    #[test]
    fn any_bytes_into_a_router_give_a_consistent_decision(
        chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 1..20),
        address in 0u8..=15,
        window_s in prop_oneof![Just(f64::NAN), Just(f64::INFINITY), -1.0..5.0f64],
        interfaces in proptest::collection::vec(proptest::collection::vec(0u8..=15, 0..4), 0..3),
    ) {
        let routes = Routes::from_json(&serde_json::json!({"0":{"2":1},"2":{"0":1}})).unwrap();
        let count = interfaces.len();
        let mut router = Router::new(address, routes, interfaces, window_s);
        for (k, mut bytes) in chunks.into_iter().enumerate() {
            // Every other chunk made a well-formed frame of its bytes.
            if k % 2 == 1 && bytes.len() >= 2 {
                let (src, dst) = (bytes[0] >> 4, bytes[0] & 0x0f);
                bytes = emit(src, dst, Message::Raw(bytes[1..].to_vec()));
            }
            let t = SimTime(u64::try_from(k).unwrap() * 100_000_000);
            let decision = router.decide(t, &bytes, k);
            prop_assert_eq!(
                decision.dropped.is_some(),
                !decision.deliver && decision.forward_on.is_empty()
            );
            prop_assert!(decision.forward_on.iter().all(|&i| i < count));
            if k % 3 == 0 {
                router.sent(t, &bytes);
            }
        }
    }
}
