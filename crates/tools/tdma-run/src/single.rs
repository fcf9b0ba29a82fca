//! tdma-run's single-vehicle session: both ends in virtual time ([`rovlink_rcp::session`]),
//! or one end in real time ([`rovlink_rcp::realtime`]), each a one-vehicle network run by the
//! library's one driver.

use crate::outputs::{Layout, Recorder, summary, wall_clock_ns, write_metrics};
use anyhow::Result;
use rovlink_base::io::EXIT_OK;
use rovlink_cli::say;
use rovlink_cli::{progress, stop};
use rovlink_rcp::realtime::{self, Role};
use rovlink_rcp::report::Tee;
use rovlink_rcp::session::{self, SessionConfig};
use rovlink_rcp::{camera, script};

use crate::TOOL;
use crate::flags::{Args, RoleArg};
use crate::setup::{Stderr, Stopped, ended_code, field_usage, host_of, parts};

/// Runs the session the flags describe.
pub fn run(args: &Args) -> Result<u8> {
    // Every output is claimed before any work, so bad usage leaves no file.
    let (metrics_dest, dests) = crate::setup::claim_outputs(args)?;
    let role = args.role.map(RoleArg::role);
    let port_flags = "each of --dialect, --instant and --chunk-bytes";
    rovlink_cli::only_with(
        role.is_some(),
        "--role",
        &[(port_flags, args.port_args.any_set())],
    )?;
    field_usage(args, role)?;
    let model = args.model.resolve()?;
    let (script, waypoints) =
        if args.orders.is_some() && args.script.is_none() && args.waypoints.is_none() {
            (Vec::new(), Vec::new())
        } else {
            script::load(args.script.as_deref(), args.waypoints.as_deref())?
        };
    let settings = args.settings();
    let pictures = camera::load_or_builtin(args.images.as_deref())?;
    if let Some(note) = pictures.note() {
        say!("{note}");
    }
    let ipg_s = args.ipg_s(&model, &settings);
    let config = SessionConfig {
        model: model.clone(),
        seed: args.seed(),
        ipg_s,
        duration_s: args.duration_s(),
        buoy_m: args.buoy,
        start_m: args.start,
        script,
        waypoints,
        settings,
        images: pictures.images,
    };
    config.validate()?;
    let mut parts = match parts(args, &config) {
        Err(e) if e.is::<Stopped>() => {
            say!("{e}: nothing was run");
            return Ok(stop::code_or(EXIT_OK));
        }
        other => other?,
    };
    let node = role.map(|r| match r {
        Role::Operator => 0,
        Role::Rov => session::rov_address(),
    });
    parts.guards = crate::setup::guards(args, &session::scenario(&config), node)?;
    let mut live = match &args.foxglove {
        Some(addr) => {
            let end = role.unwrap_or(Role::Operator);
            let policy = crate::setup::foxglove_policy(args)?;
            let (view, orders) = rovlink_field::foxglove::start(addr, end, &policy)
                .map_err(|e| rovlink_base::UsageError(e.to_string()))?;
            say!(
                "Foxglove: {}://{}:{} (open it in Foxglove's WebSocket connection)",
                view.scheme(),
                host_of(addr),
                view.port()
            );
            if end == Role::Operator {
                crate::setup::say_control(&view, &policy);
            }
            parts.orders.push(Box::new(orders));
            Some(view)
        }
        None => None,
    };
    let mut ros2 = match args.ros2 {
        false => None,
        true => {
            let options = rovlink_field::ros2_session::Ros2Options {
                domain: args.ros2_domain.map(|d| d as u16),
                namespace: args.ros2_namespace.clone(),
                control: args.ros2_control,
            };
            let (view, orders) = rovlink_field::ros2_session::start(&options)
                .map_err(|e| rovlink_base::UsageError(format!("--ros2: {e}")))?;
            let ns = &options.namespace;
            if orders.control() {
                say!(
                    "ROS 2: the session on {ns}/* and /rosout; control on: {ns}/cmd_vel and \
                     {ns}/goal_pose drive the vehicle, from any node on the domain (DDS \
                     authenticates nobody)"
                );
                parts.orders.push(Box::new(orders));
            } else {
                say!(
                    "ROS 2: the session on {ns}/* and /rosout, view-only (orders from the \
                     graph need --ros2-control)"
                );
            }
            Some(view)
        }
    };
    let model_name = match model.name.as_str() {
        "" => "a model file",
        name => name,
    };
    // What runs, said on stderr and kept on the live view's /session/log for late viewers.
    let started = match (role, &args.port) {
        (Some(Role::Operator), Some(device)) => format!(
            "operator: IPG {:.1} ms on {device}, {:.0} s",
            ipg_s * 1e3,
            args.duration_s()
        ),
        (Some(Role::Rov), Some(device)) => format!(
            "ROV: answering every slot on {device}, {:.0} s",
            args.duration_s()
        ),
        _ => format!(
            "simulation: both ends, {:.0} s over {model_name} (seed {}), IPG {:.1} ms",
            args.duration_s(),
            args.seed(),
            ipg_s * 1e3
        ),
    };
    if let Some(view) = live.as_mut() {
        view.session_started(&started);
    }
    // Opened (aside) before the run: a metrics file that cannot be created fails now.
    let mut metrics_out = metrics_dest.map(|dest| dest.open()).transpose()?;
    let base_ns = if role.is_some() { wall_clock_ns() } else { 0 };
    let template = "{spinner} {pos}/{len} s [{bar:30}] {msg}";
    let bar = progress::bar(role.is_none(), args.duration_s().ceil() as u64, template);
    let layout = Layout::Single {
        buoy_m: args.buoy,
        base_ns,
    };
    let mut recorder = Recorder::new(dests, &layout, bar)?;
    let mut stderr = Stderr;
    let mut observer = Tee(Vec::new());
    observer.0.push(&mut recorder);
    observer.0.push(&mut stderr);
    if let Some(view) = live.as_mut() {
        observer.0.push(view);
    }
    if let Some(view) = ros2.as_mut() {
        observer.0.push(view);
    }
    let (wall, mut done) = (std::time::Instant::now(), None);
    let (mut metrics, code) = match (role, &args.port) {
        (Some(role), Some(device)) => {
            let mut endpoint = args.port_args.open(device)?;
            say!("{started} (Ctrl-C stops and keeps the outputs)");
            let (metrics, ended) = realtime::run(
                role,
                &config,
                parts,
                endpoint.as_mut(),
                stop::flag(),
                &mut observer,
            );
            let code = ended_code(ended, metrics.duration_s);
            (metrics, code)
        }
        _ => {
            let metrics =
                session::run_with(&config, parts, &mut observer, stop::flag(), args.pace)?;
            done = Some(format!(
                "{:.0} s over {model_name} (seed {}), IPG {:.1} ms, {:.3} s of wall time",
                metrics.duration_s,
                args.seed(),
                ipg_s * 1e3,
                wall.elapsed().as_secs_f64()
            ));
            (metrics, stop::code_or(EXIT_OK))
        }
    };
    drop(observer);
    for problem in ros2.iter().flat_map(|view| view.problems()) {
        say!("{problem}");
    }
    if let Some(name) = stop::signal_name() {
        metrics.interrupted = Some(name.to_string());
    }
    // Every output complete (metrics written aside) before any is committed or said done.
    if let Some(out) = metrics_out.as_mut() {
        write_metrics(out, args.seed(), &metrics)?;
    }
    recorder.finish()?;
    metrics_out.map(|out| out.finish()).transpose()?;
    if let Some(line) = done {
        say!("{line}");
    }
    if let Some(note) = stop::note() {
        let at_s = metrics.duration_s;
        say!("{note} at {at_s:.1} s: the outputs hold what was done");
    }
    for line in summary(&metrics) {
        say!("{line}");
    }
    Ok(code)
}
