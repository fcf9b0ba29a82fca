//! The simulated air: a scenario's media ([`Medium`], one per medium) in virtual time, the
//! clock jumping to the next event, or, [`Pace`]d, waiting for it on the wall clock.

use std::collections::{BTreeMap, HashMap};

use super::air::{Air, Heard, Tick};
use super::pace::Pace;
use crate::report::{MediumMetrics, Observer, kind_of};
use crate::scenario::Scenario;
use rovlink_link::gll::GllError;
use rovlink_link::{Fate, Medium, ModelError, SimTime};

/// The simulated media of a scenario, in virtual time.
pub struct SimAir<'a> {
    media: Vec<Medium>,
    names: Vec<String>,
    /// Per medium, the address of each of its nodes (its index on the medium).
    members: Vec<Vec<u8>>,
    /// Per medium, each member's interface index for it.
    interfaces: Vec<Vec<usize>>,
    /// Per vehicle address, (medium, index on it) of each medium it is on.
    places: BTreeMap<u8, Vec<(usize, usize)>>,
    /// What each frame in flight on a medium is, by (medium, sender index, seq), with the
    /// receivers' reports still to come.
    kinds: HashMap<(usize, usize, u64), (&'static str, usize)>,
    metrics: Vec<MediumMetrics>,
    now: SimTime,
    /// Held to the wall clock, when paced.
    pace: Option<Pace<'a>>,
}

impl<'a> SimAir<'a> {
    /// The media of `scenario`, each at its nodes' positions, medium k seeded with the
    /// scenario's seed + k; the error names the medium.
    pub fn new(scenario: &Scenario) -> Result<SimAir<'a>, (String, ModelError)> {
        let mut air = SimAir {
            media: Vec::new(),
            names: Vec::new(),
            members: Vec::new(),
            interfaces: Vec::new(),
            places: BTreeMap::new(),
            kinds: HashMap::new(),
            metrics: vec![MediumMetrics::default(); scenario.media.len()],
            now: SimTime::ZERO,
            pace: None,
        };
        for (k, spec) in scenario.media.iter().enumerate() {
            let positions = spec
                .nodes
                .iter()
                .map(|&a| scenario.node(a).map_or([0.0; 3], |n| n.position_m))
                .collect();
            let medium = Medium::new(
                spec.model.clone(),
                scenario.seed.wrapping_add(k as u64),
                positions,
            )
            .map_err(|error| (spec.name.clone(), error))?;
            air.media.push(medium);
            air.names.push(spec.name.clone());
            air.members.push(spec.nodes.clone());
            air.interfaces.push(
                spec.nodes
                    .iter()
                    .map(|&a| {
                        let on = scenario.interfaces(a);
                        on.iter().position(|&m| m == k).unwrap_or(0)
                    })
                    .collect(),
            );
            for (index, &a) in spec.nodes.iter().enumerate() {
                air.places.entry(a).or_default().push((k, index));
            }
        }
        Ok(air)
    }

    /// The same media, held to the wall clock at `pace`.
    pub fn paced(mut self, pace: Pace<'a>) -> SimAir<'a> {
        self.pace = Some(pace);
        self
    }
}

impl Air for SimAir<'_> {
    fn now(&self) -> SimTime {
        self.now
    }

    fn real_time(&self) -> bool {
        false
    }

    fn advance(&mut self, due: SimTime, end: SimTime, _drain: bool) -> Result<Tick, GllError> {
        let medium_next = self.media.iter().filter_map(Medium::next_event_time).min();
        let t = medium_next.map_or(due, |m| m.min(due));
        if t > end {
            return Ok(Tick::Over);
        }
        if let Some(pace) = &self.pace {
            pace.wait_for(t);
        }
        self.now = t;
        if medium_next == Some(t) {
            for medium in &mut self.media {
                if medium.next_event_time() == Some(t) {
                    medium.step();
                }
            }
            return Ok(Tick::Air(t));
        }
        Ok(Tick::Ends(t))
    }

    fn pop(&mut self) -> Option<Heard> {
        let (medium, report) =
            (0..self.media.len()).find_map(|k| self.media[k].pop_report().map(|r| (k, r)))?;
        let key = (medium, report.from, report.seq);
        let kind = match self.kinds.get_mut(&key) {
            Some((kind, left)) => {
                let kind = *kind;
                if !report.duplicate {
                    *left = left.saturating_sub(1);
                    if *left == 0 {
                        self.kinds.remove(&key);
                    }
                }
                kind
            }
            None => "raw",
        };
        let metrics = &mut self.metrics[medium];
        match report.fate {
            Fate::Delivered => metrics.receptions_delivered += 1,
            Fate::Collision => metrics.receptions_collided += 1,
            Fate::Range => metrics.receptions_out_of_range += 1,
            _ => metrics.receptions_lost += 1,
        }
        let members = &self.members[medium];
        Some(Heard {
            medium,
            interface: self.interfaces[medium].get(report.to).copied().unwrap_or(0),
            tx: Some(members.get(report.from).copied().unwrap_or(0)),
            rx: members.get(report.to).copied().unwrap_or(0),
            len: report.len,
            kind,
            fate: report.fate.as_str(),
            intact: report.fate == Fate::Delivered && report.t_rx.is_some(),
            t_sent: Some(report.t_offered),
            t_rx: report.t_rx,
            bytes: report.bytes,
        })
    }

    fn transmit(
        &mut self,
        t: SimTime,
        node: u8,
        interface: usize,
        bytes: Vec<u8>,
        _origin: bool,
        _observer: &mut dyn Observer,
    ) -> Result<(), GllError> {
        let Some(&(medium, index)) = self.places.get(&node).and_then(|p| {
            p.iter()
                .find(|&&(m, i)| self.interfaces[m].get(i) == Some(&interface))
        }) else {
            return Ok(());
        };
        let kind = kind_of(&bytes);
        let link = &mut self.media[medium];
        link.advance(t);
        let receivers = link.nodes().saturating_sub(1);
        let seq = link.offer(index, bytes);
        self.kinds.insert((medium, index, seq), (kind, receivers));
        self.metrics[medium].transmissions += 1;
        Ok(())
    }

    fn moved(&mut self, node: u8, position_m: [f64; 3]) {
        if let Some(places) = self.places.get(&node) {
            for &(medium, index) in places {
                self.media[medium].set_position(index, position_m);
            }
        }
    }

    fn medium_name(&self, medium: usize) -> &str {
        self.names.get(medium).map_or("", String::as_str)
    }

    fn media_metrics(&self) -> BTreeMap<String, MediumMetrics> {
        self.names
            .iter()
            .cloned()
            .zip(self.metrics.iter().cloned())
            .collect()
    }
}
