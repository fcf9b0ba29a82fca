//! The real air: one node's endpoints (serial ports, pseudo-terminals, sockets), one per
//! interface, with the host's monotonic clock; a wait ends at the next thing due, a frame read,
//! or [`super::WAKE_EVERY`] at most.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use super::addresses;
use super::air::{Air, Heard, Tick};
use super::clock::Clock;
use crate::report::{FrameEvent, MediumMetrics, Observer, direction_of, kind_of};
use crate::scenario::Scenario;
use rovlink_link::SimTime;
use rovlink_link::gll::{Endpoint, GllError, Received};

/// The wait that reads what arrived while a loop was late for its slot.
pub const DRAIN_WAIT: Duration = Duration::from_millis(1);

/// The longest a node with two endpoints waits on one before reading the other.
pub const SLICE: Duration = Duration::from_millis(5);

/// One node's real endpoints (interface k on endpoint k), with the host's clock.
pub struct PortAir<'a> {
    clock: Clock,
    endpoints: Vec<&'a mut dyn Endpoint>,
    /// The node's address.
    node: u8,
    /// Per interface, the medium (index into the scenario's media).
    media: Vec<usize>,
    names: Vec<String>,
    /// The endpoint read first next time (two endpoints are read in turn).
    next_endpoint: usize,
    heard: Option<Heard>,
    /// The latest time handed out: frames are stamped no earlier.
    last: SimTime,
}

impl<'a> PortAir<'a> {
    /// Node `node` of `scenario` over `endpoints`, one per medium it is on; time zero is now.
    pub fn new(scenario: &Scenario, node: u8, endpoints: Vec<&'a mut dyn Endpoint>) -> Self {
        PortAir {
            clock: Clock::start(),
            endpoints,
            node,
            media: scenario.interfaces(node),
            names: scenario.media.iter().map(|m| m.name.clone()).collect(),
            next_endpoint: 0,
            heard: None,
            last: SimTime::ZERO,
        }
    }

    /// The next frame on any endpoint until `deadline`, with the interface it came on.
    fn receive(&mut self, deadline: Instant) -> Result<Option<(usize, Received)>, GllError> {
        let n = self.endpoints.len();
        if n <= 1 {
            return match self.endpoints.first_mut() {
                Some(endpoint) => Ok(endpoint.receive(deadline)?.map(|r| (0, r))),
                None => {
                    std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
                    Ok(None)
                }
            };
        }
        loop {
            for _ in 0..n {
                let k = self.next_endpoint % n;
                self.next_endpoint = (k + 1) % n;
                let slice = deadline.min(Instant::now() + SLICE);
                if let Some(endpoint) = self.endpoints.get_mut(k)
                    && let Some(received) = endpoint.receive(slice)?
                {
                    // The same endpoint first next time: what it still holds comes at once.
                    self.next_endpoint = k;
                    return Ok(Some((k, received)));
                }
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    fn stamp(&mut self, t: SimTime) -> SimTime {
        self.last = self.last.max(t);
        self.last
    }
}

impl Air for PortAir<'_> {
    fn now(&self) -> SimTime {
        self.clock.now().max(self.last)
    }

    fn real_time(&self) -> bool {
        true
    }

    fn advance(&mut self, due: SimTime, end: SimTime, drain: bool) -> Result<Tick, GllError> {
        let now = self.now();
        if now >= end {
            return Ok(Tick::Over);
        }
        let deadline = if drain {
            Instant::now() + DRAIN_WAIT
        } else {
            self.clock.wake_at(due.min(end))
        };
        if let Some((k, received)) = self.receive(deadline)? {
            let t = self.stamp(self.clock.at(received.at));
            self.heard = Some(Heard {
                medium: self.media.get(k).copied().unwrap_or(0),
                interface: k,
                tx: None,
                rx: self.node,
                len: received.bytes.len(),
                kind: kind_of(&received.bytes),
                fate: if received.damaged {
                    "damaged"
                } else {
                    "received"
                },
                intact: !received.damaged,
                t_sent: None,
                t_rx: Some(t),
                bytes: received.bytes,
            });
        }
        let now = self.now();
        Ok(Tick::Ends(self.stamp(now)))
    }

    fn pop(&mut self) -> Option<Heard> {
        self.heard.take()
    }

    fn transmit(
        &mut self,
        t: SimTime,
        node: u8,
        interface: usize,
        bytes: Vec<u8>,
        origin: bool,
        observer: &mut dyn Observer,
    ) -> Result<(), GllError> {
        if let Some(endpoint) = self.endpoints.get_mut(interface) {
            endpoint.send(&bytes)?;
        }
        if origin {
            let sent_at = self.stamp(self.clock.now().max(t));
            let medium = self.media.get(interface).copied().unwrap_or(0);
            let addresses = addresses(&bytes);
            observer.frame(&FrameEvent {
                direction: addresses.map_or("operator_to_rov", |(s, d)| direction_of(s, d)),
                kind: kind_of(&bytes),
                bytes: bytes.len(),
                t_sent_s: Some(sent_at.as_secs_f64()),
                t_received_s: None,
                fate: "sent",
                medium: self.medium_name(medium),
                src: addresses.map(|a| a.0),
                dst: addresses.map(|a| a.1),
                tx: Some(node),
                rx: None,
                action: "",
            });
        }
        Ok(())
    }

    fn moved(&mut self, _node: u8, _position_m: [f64; 3]) {}

    fn medium_name(&self, medium: usize) -> &str {
        self.names.get(medium).map_or("", String::as_str)
    }

    fn media_metrics(&self) -> BTreeMap<String, MediumMetrics> {
        BTreeMap::new()
    }
}
