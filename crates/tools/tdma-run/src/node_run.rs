//! tdma-run `--role ... --routes FILE`: one node of a multi-vehicle network in real time
//! ([`rovlink_rcp::realnet`]), over `--port` and, for a node on two media, `--port2`.

use std::path::Path;

use crate::outputs::{Layout, Recorder, write_metrics};
use anyhow::Result;
use rovlink_base::UsageError;
use rovlink_base::io::EXIT_OK;
use rovlink_cli::say;
use rovlink_cli::{progress, stop};
use rovlink_link::gll::Endpoint;
use rovlink_rcp::realnet::{self, Network};
use rovlink_rcp::realtime::Role;
use rovlink_rcp::report::Tee;
use rovlink_rcp::scenario::Scenario;
use rovlink_rcp::session::{SessionConfig, bound_ipg};
use rovlink_rcp::{camera, script};

use crate::TOOL;
use crate::flags::{Args, Ipg, RoleArg};
use crate::scenario_run::{Both, mark_interrupted, network_summary};

/// Runs this process's node of the network in `path`.
pub fn run(args: &Args, path: &Path) -> Result<u8> {
    let (metrics_dest, dests) = crate::setup::claim_outputs(args)?;
    let role = args.role.map_or(Role::Operator, RoleArg::role);
    usage(args)?;
    crate::setup::field_usage(args, Some(role))?;
    let file = format!("--routes {}", path.display());
    let mut scenario =
        Scenario::from_file(path).map_err(|e| UsageError(format!("--routes {e}")))?;
    // The frames sent are the flags' (the trunk size sets the ROV frame and so the slots).
    scenario.settings = args.settings();
    let address = match (role, args.address_given) {
        (_, true) => u8::try_from(args.port_args.address).unwrap_or(u8::MAX),
        (Role::Operator, false) => 0,
        (Role::Rov, false) => 1,
    };
    let ports: Vec<&str> = [args.port.as_deref(), args.port2.as_deref()]
        .into_iter()
        .flatten()
        .collect();
    let network = Network::new(scenario, &file, role, address, ports.len())
        .map_err(|e| UsageError(e.to_string()))?;
    let config = session_config(args, &network, role)?;
    let mut parts = match crate::setup::parts(args, &config) {
        Err(e) if e.is::<crate::setup::Stopped>() => {
            say!("{e}: nothing was run");
            return Ok(stop::code_or(EXIT_OK));
        }
        other => other?,
    };
    parts.guards = crate::setup::guards(args, &network.scenario, Some(network.address))?;
    // Every packet to the dialect's broadcast address, if its packets carry one: the routers
    // decide who takes a frame.
    let mut options = args.port_args.options();
    if let Some(broadcast) = options.dialect.broadcast_address() {
        options.address = broadcast;
    }
    let mut endpoints: Vec<Box<dyn Endpoint>> = Vec::new();
    for device in &ports {
        endpoints.push(options.open(device)?);
    }
    let mut metrics_out = metrics_dest.map(|dest| dest.open()).transpose()?;
    let template = "{spinner} {pos}/{len} s [{bar:30}] {msg}";
    let bar = progress::bar(false, config.duration_s.ceil() as u64, template);
    let shown = match role {
        Role::Operator => network.scenario.vehicles(),
        Role::Rov => vec![network.address],
    };
    // A live view of the vehicles this node shows (`/vehicle/N/...`), as its MCAP log has them,
    // and the node's own frames on `/link/frames`.
    let mut live = match &args.foxglove {
        Some(addr) => {
            let view = rovlink_field::foxglove::start_node(
                addr,
                role,
                &shown,
                &crate::setup::foxglove_policy(args)?,
            )
            .map_err(|e| UsageError(e.to_string()))?;
            say!(
                "Foxglove: {}://{}:{} (every vehicle under /vehicle/N/, this node's frames on \
                 /link/frames)",
                view.scheme(),
                crate::setup::host_of(addr),
                view.port()
            );
            Some(view)
        }
        None => None,
    };
    let mut recorder = Recorder::new(
        dests,
        &Layout::Network {
            vehicles: shown.clone(),
        },
        bar,
    )?;
    let started = start_line(&network, role, &ports, config.duration_s);
    if let Some(view) = live.as_mut() {
        view.session_started(&started);
    }
    say!("{started} (Ctrl-C stops and keeps the outputs)");
    let (mut metrics, ended) = {
        let mut both = Both(&mut recorder);
        let mut observer = Tee(vec![&mut both]);
        if let Some(view) = live.as_mut() {
            observer.0.push(view);
        }
        realnet::run(
            role,
            &config,
            &network,
            parts,
            &mut endpoints,
            stop::flag(),
            &mut observer,
        )
    };
    if let Some(view) = live.take() {
        view.take_refusals().iter().for_each(|line| say!("{line}"));
        view.stop();
    }
    let code = crate::setup::ended_code(ended, metrics.duration_s);
    mark_interrupted(&mut metrics);
    if let Some(out) = metrics_out.as_mut() {
        write_metrics(out, network.scenario.seed, &metrics)?;
    }
    recorder.finish()?;
    metrics_out.map(|out| out.finish()).transpose()?;
    for line in network_summary(&metrics) {
        say!("{line}");
    }
    Ok(code)
}

/// The flags a network node does not take.
fn usage(args: &Args) -> Result<(), UsageError> {
    let refused = [
        ("--ipg", matches!(args.ipg, Ipg::Millis(_))),
        ("--preview", args.preview),
    ];
    match refused.iter().find(|(_, given)| *given) {
        Some((flag, _)) => Err(UsageError(format!(
            "{flag} does not apply with --routes (the cycle is the file's slots; outputs are \
             --metrics, --events, --track, --images-out, --telemetry, --mcap and --foxglove)"
        ))),
        None => Ok(()),
    }
}

/// The session this node runs: the flags' duration, images and orders; the network's
/// cycle; the node's own position.
fn session_config(args: &Args, network: &Network, role: Role) -> Result<SessionConfig> {
    let scenario = &network.scenario;
    let position = |address: u8| scenario.node(address).map_or([0.0; 3], |n| n.position_m);
    let first_medium = scenario.interfaces(network.address).first().copied();
    let model = first_medium
        .and_then(|k| scenario.media.get(k))
        .map(|m| m.model.clone())
        .ok_or_else(|| UsageError(format!("node {} is on no medium", network.address)))?;
    let (script, waypoints) = if args.script.is_some() || args.waypoints.is_some() {
        script::load(args.script.as_deref(), args.waypoints.as_deref())?
    } else {
        (Vec::new(), Vec::new())
    };
    let pictures = camera::load_or_builtin(args.images.as_deref())?;
    if let Some(note) = pictures.note() {
        say!("{note}");
    }
    let config = SessionConfig {
        model,
        seed: scenario.seed,
        // The cycle held to an IPG's bounds: only validation looks at it (see bound_ipg).
        ipg_s: bound_ipg(network.cycle_s()).ipg_s,
        duration_s: args.duration_s(),
        buoy_m: position(0),
        start_m: match role {
            Role::Rov => position(network.address),
            Role::Operator => args.start,
        },
        script,
        waypoints,
        settings: args.settings(),
        images: pictures.images,
    };
    config.validate()?;
    Ok(config)
}

/// What the node says as it starts (and keeps on its live view's /session/log).
fn start_line(network: &Network, role: Role, ports: &[&str], duration_s: f64) -> String {
    let slots: Vec<String> = network
        .scenario
        .cycle()
        .iter()
        .map(|s| format!("{} {:.1} ms", s.address, s.length_s * 1e3))
        .collect();
    let who = match role {
        Role::Operator => "operator".to_string(),
        Role::Rov => format!("ROV {}", network.address),
    };
    format!(
        "{who}: cycle {:.1} ms (slots: {}) on {}, {duration_s:.0} s",
        network.cycle_s() * 1e3,
        slots.join(", "),
        ports.join(" and ")
    )
}
