//! A routes table and frames heard by a router, from any bytes: `Routes::from_json`,
//! `Routes::check`, `Routes::path`, `Router::decide`, `Router::originate_on`.
//!
//! Input: the bytes before the first 0x00 are a routes table as JSON text (not UTF-8 or not
//! JSON: no table); the bytes after it are the router's address (low 4 bits of the first byte)
//! and a stream of frames heard, each a length byte then that many bytes.
//!
//! Checks:
//! - an accepted table names only addresses 0..=14, no node routing to itself or through itself;
//! - `check` against the table's nodes with every pair linked fails only with a loop (or a path
//!   too long); when it passes, every two of those nodes have a path;
//! - every path `path` finds starts at its source, ends at its destination, follows next hops,
//!   repeats no node and has at most 16 nodes;
//! - every decision of a router (with the accepted table, or none) is consistent: dropped
//!   exactly when neither delivered nor forwarded, malformed exactly when no addresses,
//!   delivered only when DST is the node or broadcast, forwarded only on interfaces it has, in
//!   increasing order, and a unicast only by a node strictly inside the frame's routed path;
//!   the same bytes heard again at once are neither delivered nor forwarded.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_link::SimTime;
use rovlink_rcp::routing::{BROADCAST, Dropped, MAX_PATH_NODES, Router, Routes, RoutesError};

fuzz_target!(|data: &[u8]| {
    let split = data.iter().position(|&b| b == 0).unwrap_or(data.len());
    let (text, rest) = data.split_at(split);
    let value = std::str::from_utf8(text)
        .ok()
        .and_then(|text| serde_json::from_str::<serde_json::Value>(text).ok());
    let routes = match value.as_ref().map(Routes::from_json) {
        Some(Ok(routes)) => routes,
        Some(Err(e)) => {
            let _ = e.to_string();
            Routes::direct()
        }
        None => Routes::direct(),
    };

    let mut nodes = vec![0u8];
    for (node, dst, hop) in routes.entries() {
        assert!(node <= 14 && dst <= 14 && hop <= 14, "address out of range");
        assert!(
            node != dst && node != hop,
            "a node routes to or through itself"
        );
        nodes.extend([node, dst, hop]);
    }
    nodes.sort_unstable();
    nodes.dedup();

    match routes.check(&nodes, &|a, b| a != b) {
        Ok(()) => {
            for &src in &nodes {
                for &dst in &nodes {
                    assert!(
                        routes.path(src, dst).is_some(),
                        "check passed without a path"
                    );
                }
            }
        }
        Err(RoutesError::Loop { path, .. }) => {
            assert!(path.len() >= 2 && path.len() <= MAX_PATH_NODES + 1);
        }
        Err(RoutesError::Syntax { .. }) => {}
        Err(other) => panic!("check with every pair linked: {other}"),
    }
    let _ = routes.check(&nodes, &|_, _| false);

    for src in 0..=BROADCAST {
        for dst in 0..=BROADCAST {
            let Some(path) = routes.path(src, dst) else {
                continue;
            };
            assert_eq!(path.first(), Some(&src));
            assert_eq!(path.last(), Some(&dst));
            assert!(path.len() <= MAX_PATH_NODES);
            for (k, pair) in path.windows(2).enumerate() {
                assert_eq!(routes.next_hop(pair[0], dst), pair[1]);
                assert!(
                    !path[..=k].contains(&pair[1]),
                    "path {path:?} repeats a node"
                );
            }
        }
    }

    let Some((&first, mut stream)) = rest.split_first().and_then(|(_, r)| r.split_first()) else {
        return;
    };
    let address = first & 0x0f;
    let others: Vec<u8> = nodes.iter().copied().filter(|&a| a != address).collect();
    let interfaces = vec![others.clone(), others.into_iter().rev().take(2).collect()];
    let count = interfaces.len();
    let mut router = Router::new(address, routes.clone(), interfaces, 0.5);
    for dst in 0..=BROADCAST {
        assert!(router.originate_on(dst).iter().all(|&k| k < count));
    }
    let mut t_ns = 0u64;
    while let Some((&len, after)) = stream.split_first() {
        let (bytes, next) = after.split_at(usize::from(len).min(after.len()));
        stream = next;
        t_ns += 100_000_000;
        let decision = router.decide(SimTime(t_ns), bytes, 0);
        assert_eq!(
            decision.dropped.is_some(),
            !decision.deliver && decision.forward_on.is_empty()
        );
        assert_eq!(
            decision.addresses.is_none(),
            decision.dropped == Some(Dropped::Malformed)
        );
        assert!(decision.forward_on.windows(2).all(|w| w[0] < w[1]));
        assert!(decision.forward_on.iter().all(|&k| k < count));
        if let Some((src, dst)) = decision.addresses {
            if decision.deliver {
                assert!(dst == address || dst == BROADCAST);
            }
            if !decision.forward_on.is_empty() && dst != BROADCAST {
                let path = routes.path(src, dst).expect("a forward follows a path");
                let at = path
                    .iter()
                    .position(|&a| a == address)
                    .expect("on the path");
                assert!(
                    at > 0 && at + 1 < path.len(),
                    "forwarded from an end of {path:?}"
                );
            }
        }
        let again = router.decide(SimTime(t_ns), bytes, 0);
        assert!(!again.deliver && again.forward_on.is_empty(), "taken twice");
    }
});
