//! link-sim's real-time runs, each one call from a plain configuration ([`Emulation`]): a
//! [`Link`] between two devices ([`run_link`]), or a [`Medium`] among N ([`run_medium`]) with
//! the counters of each pair of ports ([`PairCounters`]).
//!
//! The devices are named in the one grammar ([`DeviceSpec`]) and opened by the one opener; the
//! dialect the programs on a link's sides speak is emulated by its [`super::dialect::Emulator`].

use std::sync::atomic::AtomicBool;

use super::channel::{DirectionStats, Link, Report};
use super::dialect;
use super::medium::{Medium, MediumReport};
use super::realtime::{
    Ended, Endpoints, Framing, OpenError, PortEnded, Ports, PortsInfo, RunInfo, SideOptions,
};
use super::stats::{Counters, RunFacts, Summary, model_name, port_lines};
use crate::device::DeviceSpec;
use crate::gll::Dialect;

/// What a real-time run is: its devices, how they open, how bytes become packets, and what the
/// programs speak.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Emulation {
    /// One device per side (A, then B) or per port of a medium.
    pub devices: Vec<DeviceSpec>,
    /// How the devices open.
    pub sides: SideOptions,
    /// How bytes are cut into packets.
    pub framing: Framing,
    /// What the programs on a link's two sides speak (a medium's always send bare packets).
    pub dialect: Dialect,
}

impl Emulation {
    /// True when a device is a new pseudo-terminal, whose path its program must be told.
    pub fn creates_ptys(&self) -> bool {
        self.devices.contains(&DeviceSpec::Pty)
    }
}

/// How a run on a link went: how it ended, the ports' figures and both directions' counters.
#[derive(Debug, Clone)]
pub struct LinkRun {
    /// How it ended.
    pub ended: Ended,
    /// The ports' figures.
    pub info: RunInfo,
    /// Both directions' counters.
    pub counters: Counters,
}

impl LinkRun {
    /// The summary and `--stats` of the run on `link`.
    pub fn summary(&self, facts: &RunFacts<'_>, link: &Link) -> Summary {
        self.counters.summary(facts, link, Some(&self.info))
    }

    /// Why the run ended early, when a side closed.
    pub fn closed_line(&self) -> Option<String> {
        self.ended.closed_line()
    }
}

/// Runs `link` between the two devices of `config` until a side closes or `stop` is set.
/// `opened` gets the sides' names (a new pseudo-terminal's path) and a sentence of what runs,
/// once both are open and before any byte moves; `on_report` sees every report when the model
/// decides it.
pub fn run_link<E: From<OpenError>>(
    config: &Emulation,
    link: &mut Link,
    stop: &AtomicBool,
    opened: impl FnOnce(&[String], &str) -> Result<(), E>,
    mut on_report: impl FnMut(&Report),
) -> Result<LinkRun, E> {
    let [a, b] = &config.devices[..] else {
        return Err(OpenError {
            side: "all",
            name: format!("{} devices", config.devices.len()),
            reason: "a link has two sides".into(),
        }
        .into());
    };
    let endpoints = Endpoints::open(&[a.clone(), b.clone()], config.sides)?;
    let [a, b] = endpoints.names();
    let what = format!(
        "forwarding A ({a}) <-> B ({b}) through the model until a side closes or SIGINT/SIGTERM"
    );
    opened(endpoints.names(), &what)?;
    let mut emulator = dialect::emulator(config.dialect);
    let emulator = emulator
        .as_mut()
        .map(|e| e.as_mut() as &mut dyn dialect::Emulator);
    let mut counters = Counters::default();
    let (ended, info) = endpoints.run(link, config.framing, emulator, stop, |report| {
        counters.record(report);
        on_report(report);
    });
    Ok(LinkRun {
        ended,
        info,
        counters,
    })
}

/// How a run on a medium went: how it ended, the ports' figures and each pair's counters.
#[derive(Debug, Clone)]
pub struct MediumRun {
    /// How it ended.
    pub ended: PortEnded,
    /// The ports' figures.
    pub info: PortsInfo,
    /// Each pair's counters.
    pub pairs: PairCounters,
}

impl MediumRun {
    /// The summary and `--stats` of the run on `medium`.
    pub fn summary(&self, facts: &RunFacts<'_>, medium: &Medium) -> Summary {
        Summary {
            stats: self.pairs.stats_json(facts, medium, &self.info),
            lines: self.pairs.summary_lines(facts, medium, &self.info),
        }
    }

    /// Why the run ended early, when a port closed.
    pub fn closed_line(&self) -> Option<String> {
        self.ended.closed_line()
    }
}

/// Runs `medium` (node k on device k) among the devices of `config` until one closes or `stop`
/// is set; `opened` gets their names and a sentence of what runs once all are open.
pub fn run_medium<E: From<OpenError>>(
    config: &Emulation,
    medium: &mut Medium,
    stop: &AtomicBool,
    opened: impl FnOnce(&[String], &str) -> Result<(), E>,
) -> Result<MediumRun, E> {
    let ports = Ports::open(&config.devices, config.sides)?;
    let what = format!(
        "forwarding among {} ports on one medium ({}) until a port closes or SIGINT/SIGTERM",
        ports.names().len(),
        model_name(medium.model())
    );
    opened(ports.names(), &what)?;
    let mut pairs = PairCounters::new(medium.nodes());
    let (ended, info) = ports.run(medium, config.framing, stop, |report| pairs.record(report));
    Ok(MediumRun { ended, info, pairs })
}

/// The counters of every (from, to) pair of a medium's ports.
#[derive(Debug, Clone)]
pub struct PairCounters {
    ports: usize,
    /// Row-major: from * ports + to.
    pairs: Vec<DirectionStats>,
}

impl PairCounters {
    /// Zero counters for `ports` ports.
    pub fn new(ports: usize) -> PairCounters {
        PairCounters {
            ports,
            pairs: vec![DirectionStats::default(); ports * ports],
        }
    }

    /// Counts a report in its pair.
    pub fn record(&mut self, report: &MediumReport) {
        if let Some(stats) = self.pairs.get_mut(report.from * self.ports + report.to) {
            stats.record_medium(report);
        }
    }

    /// The name of pair `k`, ports numbered from 1 (`1->3`).
    fn name(&self, k: usize) -> String {
        format!("{}->{}", k / self.ports + 1, k % self.ports + 1)
    }

    /// The pairs of two different ports, in order.
    fn used(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.pairs.len()).filter(|k| k / self.ports != k % self.ports)
    }

    /// The summary, one line each: model, seed, medium time and ports, each pair that carried
    /// frames, the ports' delivery figures, and why the run was cut short.
    pub fn summary_lines(
        &self,
        facts: &RunFacts<'_>,
        medium: &Medium,
        info: &PortsInfo,
    ) -> Vec<String> {
        let mut lines = vec![format!(
            "real time: model {}, seed {}, {:.3} s of medium time, {} ports",
            model_name(medium.model()),
            facts.seed,
            facts.duration_s,
            self.ports
        )];
        for k in self.used().filter(|&k| self.pairs[k].frames_offered > 0) {
            lines.push(self.pairs[k].summary_line(&self.name(k)));
        }
        let labels: Vec<String> = (1..=self.ports).map(|p| p.to_string()).collect();
        let labels: Vec<&str> = labels.iter().map(String::as_str).collect();
        lines.extend(port_lines(&info.lateness, &info.not_taken, &labels));
        if let Some(note) = facts.interrupted {
            lines.push(format!("{note}: the figures cover the run until then"));
        }
        lines
    }

    /// The `--stats` document of a shared medium: mode, seed, duration, the ports' positions,
    /// each (from, to) pair's counters, frames in flight, the model and the ports' figures.
    pub fn stats_json(
        &self,
        facts: &RunFacts<'_>,
        medium: &Medium,
        info: &PortsInfo,
    ) -> serde_json::Value {
        let pairs: serde_json::Map<String, serde_json::Value> = self
            .used()
            .map(|k| (self.name(k), self.pairs[k].to_json()))
            .collect();
        let positions: Vec<[f64; 3]> = (0..medium.nodes()).map(|n| medium.position_m(n)).collect();
        serde_json::json!({
            "mode": facts.mode.name(),
            "seed": facts.seed,
            "duration_s": facts.duration_s,
            "interrupted": facts.interrupted,
            "ports": medium.nodes(),
            "positions_m": positions,
            "pairs": pairs,
            "in_flight_at_end": medium.in_flight(),
            "model": medium.model(),
            "real_time": {
                "bytes_read": info.bytes_read,
                "bytes_skipped": info.bytes_skipped,
                "foreign_datagrams_dropped": info.foreign_datagrams_dropped,
                "deliveries_not_taken": info.not_taken,
                "delivery_lateness_ms_p50": info.lateness_quantile_ms(0.5),
                "delivery_lateness_ms_p99": info.lateness_quantile_ms(0.99),
                "delivery_lateness_ms_max": info.lateness_quantile_ms(1.0),
            },
        })
    }
}
