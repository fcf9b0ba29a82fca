//! tdma-run `--scenario`: a multi-vehicle session in virtual time ([`rovlink_rcp::network`]).

use std::path::Path;

use crate::outputs::{Layout, Recorder, summary, write_metrics};
use anyhow::Result;
use rovlink_base::UsageError;
use rovlink_base::io::EXIT_OK;
use rovlink_cli::say;
use rovlink_cli::{progress, stop};
use rovlink_rcp::network::{self, NetworkMetrics};
use rovlink_rcp::report::{FrameEvent, Observer, Tee};
use rovlink_rcp::scenario::Scenario;
use rovlink_rcp::{Event, PoseSample, Role, camera};

use crate::TOOL;
use crate::flags::Args;

/// Runs the scenario at `path` with the flags that apply to it.
pub fn run(args: &Args, path: &Path) -> Result<u8> {
    let (metrics_dest, dests) = crate::setup::claim_outputs(args)?;
    if args.model.model.is_some() || args.model.model_file.is_some() {
        return Err(UsageError(
            "--model/--model-file: a scenario names each medium's model; the other link flags \
             (e.g. --loss-percent) change every medium's"
                .into(),
        )
        .into());
    }
    let mut scenario =
        Scenario::from_file(path).map_err(|e| UsageError(format!("--scenario {e}")))?;
    if let Some(duration_s) = args.duration {
        scenario.duration_s = duration_s;
    }
    if let Some(seed) = args.seed {
        scenario.seed = seed;
    }
    for medium in &mut scenario.media {
        args.model.apply(&mut medium.model);
        medium
            .model
            .validate()
            .map_err(|e| UsageError(format!("medium {}: {e}", medium.name)))?;
    }
    let pictures = camera::load_or_builtin(args.images.as_deref())?;
    if let Some(note) = pictures.note() {
        say!("{note}");
    }
    let mut metrics_out = metrics_dest.map(|dest| dest.open()).transpose()?;
    let template = "{spinner} {pos}/{len} s [{bar:30}] {msg}";
    let security = crate::setup::security(args)?;
    if let Some(security) = &security {
        scenario.frame_overhead_bytes = rovlink_rcp::secure::OVERHEAD_BYTES;
        crate::setup::say_secured(security);
    }
    let bar = progress::bar(true, scenario.duration_s.ceil() as u64, template);
    let mut recorder = Recorder::new(
        dests,
        &Layout::Network {
            vehicles: scenario.vehicles(),
        },
        bar,
    )?;
    let cycle = scenario.cycle();
    let slots: Vec<String> = cycle
        .iter()
        .map(|s| format!("{} {:.1} ms", s.address, s.length_s * 1e3))
        .collect();
    let started = format!(
        "{} vehicles, cycle {:.1} ms (slots: {})",
        cycle.len(),
        scenario.cycle_s() * 1e3,
        slots.join(", ")
    );
    say!("{started}");
    // A live view of every vehicle (`/vehicle/N/...`), as the MCAP log has them.
    let mut live = match &args.foxglove {
        Some(addr) => {
            let mut view = rovlink_field::foxglove::start_network(
                addr,
                &scenario.vehicles(),
                &crate::setup::foxglove_policy(args)?,
            )
            .map_err(|e| UsageError(e.to_string()))?;
            say!(
                "Foxglove: {}://{}:{} (every vehicle under /vehicle/N/)",
                view.scheme(),
                crate::setup::host_of(addr),
                view.port()
            );
            view.session_started(&started);
            Some(view)
        }
        None => None,
    };
    let wall = std::time::Instant::now();
    let mut metrics = {
        let mut both = Both(&mut recorder);
        let mut observers = Tee(Vec::new());
        observers.0.push(&mut both);
        if let Some(view) = live.as_mut() {
            observers.0.push(view);
        }
        network::run(
            &scenario,
            &pictures.images,
            security.as_ref(),
            &mut observers,
            stop::flag(),
            args.pace,
        )?
    };
    if let Some(view) = live.take() {
        view.take_refusals().iter().for_each(|line| say!("{line}"));
        view.stop();
    }
    mark_interrupted(&mut metrics);
    if let Some(out) = metrics_out.as_mut() {
        write_metrics(out, scenario.seed, &metrics)?;
    }
    recorder.finish()?;
    metrics_out.map(|out| out.finish()).transpose()?;
    say!(
        "{:.0} s of {} nodes (seed {}), {:.3} s of wall time",
        metrics.duration_s,
        scenario.nodes.len(),
        scenario.seed,
        wall.elapsed().as_secs_f64()
    );
    if let Some(note) = stop::note() {
        let at_s = metrics.duration_s;
        say!("{note} at {at_s:.1} s: the outputs hold what was done");
    }
    for line in network_summary(&metrics) {
        say!("{line}");
    }
    Ok(stop::code_or(EXIT_OK))
}

/// Marks the figures (the network's and each vehicle's) with the signal that ended the run.
pub(super) fn mark_interrupted(metrics: &mut NetworkMetrics) {
    if let Some(name) = stop::signal_name() {
        metrics.interrupted = Some(name.to_string());
        for m in metrics.vehicles.values_mut() {
            m.interrupted = Some(name.to_string());
        }
    }
}

/// Each vehicle's summary, then each relay's forwarding.
pub(super) fn network_summary(metrics: &NetworkMetrics) -> Vec<String> {
    let mut lines = Vec::new();
    for (address, m) in &metrics.vehicles {
        lines.push(format!("vehicle {address}:"));
        lines.extend(summary(m).into_iter().map(|l| format!("  {l}")));
    }
    for (address, n) in &metrics.nodes {
        if n.frames_forwarded > 0 {
            lines.push(format!(
                "node {address} forwarded {} frames, dropped {} duplicates",
                n.frames_forwarded, n.duplicates_dropped
            ));
        }
    }
    lines
}

/// The recorder, with warnings also on standard error.
pub(super) struct Both<'a>(pub(super) &'a mut Recorder);

impl Observer for Both<'_> {
    fn frame(&mut self, event: &FrameEvent<'_>) {
        self.0.frame(event);
    }

    fn image(&mut self, vehicle: u8, t_s: f64, stream: &[u8]) {
        self.0.image(vehicle, t_s, stream);
    }

    fn pose(&mut self, vehicle: u8, pose: &PoseSample) {
        self.0.pose(vehicle, pose);
    }

    fn event(&mut self, vehicle: u8, end: Role, t_s: f64, event: &Event) {
        self.0.event(vehicle, end, t_s, event);
    }

    fn warning(&mut self, t_s: f64, text: &str) {
        say!("{text}");
        self.0.warning(t_s, text);
    }

    fn failed(&self) -> bool {
        self.0.failed()
    }

    fn wants_poses(&self) -> bool {
        self.0.wants_poses()
    }
}
