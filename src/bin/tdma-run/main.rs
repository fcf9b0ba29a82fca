//! tdma-run: a whole teleoperation session, operator and ROV: both ends over a link model in
//! virtual time, or one end in real time over a serial port, pseudo-terminal or UDP.
//!
//! The pipeline is the library's: [`rovlink::rcp::session`] (virtual time),
//! [`rovlink::rcp::realtime`] (one end), [`rovlink::rcp::outputs`] (what is written as it goes).
#![forbid(unsafe_code)]

mod cli;
mod network;
mod realnet;

use std::process::ExitCode;

use anyhow::Result;
use rovlink::cli::output::{Kind, Outputs};
use rovlink::cli::{progress, stop};
use rovlink::io::{EXIT_CHECK_FAILED, EXIT_OK};
use rovlink::rcp::outputs::{
    Destinations, Recorder, check_images_out, summary, wall_clock_ns, write_metrics,
};
use rovlink::rcp::pace::Pacer;
use rovlink::rcp::realtime::{self, Ended, Role};
use rovlink::rcp::report::{Observer, Tee};
use rovlink::rcp::session::{self, Parts, SessionConfig};
use rovlink::rcp::{camera, script};
use rovlink::say;

use cli::{Args, RoleArg, Vehicle};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "tdma-run";

fn main() -> ExitCode {
    let args: Args = rovlink::cli::parse(TOOL);
    rovlink::cli::finish(TOOL, run(&args))
}

fn run(args: &Args) -> Result<u8> {
    stop::install()?;
    if let Some(path) = &args.scenario {
        return network::run(args, path);
    }
    if let Some(path) = &args.routes {
        return realnet::run(args, path);
    }
    // Every output is claimed before any work, so bad usage leaves no file.
    let mut outs = Outputs::new();
    outs.inputs(args.inputs());
    let metrics_dest = outs.claim_opt("--metrics", args.metrics.as_deref(), Kind::Text)?;
    let dests = Destinations {
        events: outs.claim_opt("--events", args.events.as_deref(), Kind::Text)?,
        track: outs.claim_opt("--track", args.track.as_deref(), Kind::Text)?,
        mcap: outs.claim_opt("--mcap", args.mcap.as_deref(), Kind::Binary)?,
        images_out: (args.images_out.as_deref())
            .map(|dir| outs.claim_dir("--images-out", dir))
            .transpose()?,
        telemetry: outs.claim_opt("--telemetry", args.telemetry.as_deref(), Kind::Text)?,
        preview: args.preview,
    };
    if let Some(dir) = &dests.images_out {
        check_images_out(dir, args.inputs())?;
    }
    let role = args.role.map(RoleArg::role);
    let port_flags = "each of --dialect, --instant and --chunk-bytes";
    rovlink::cli::only_with(
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
    let mut live = match &args.foxglove {
        Some(addr) => {
            let end = role.unwrap_or(Role::Operator);
            let (view, orders) = rovlink::rcp::foxglove::start(addr, end)
                .map_err(|e| rovlink::cli::UsageError(e.to_string()))?;
            say!(
                "Foxglove: ws://{}:{} (open it in Foxglove's WebSocket connection)",
                host_of(addr),
                view.port()
            );
            parts.orders.push(Box::new(orders));
            Some(view)
        }
        None => None,
    };
    // Opened (aside) before the run: a metrics file that cannot be created fails now.
    let mut metrics_out = metrics_dest.map(|dest| dest.open()).transpose()?;
    let base_ns = if role.is_some() { wall_clock_ns() } else { 0 };
    let template = "{spinner} {pos}/{len} s [{bar:30}] {msg}";
    let bar = progress::bar(role.is_none(), args.duration_s().ceil() as u64, template);
    let mut recorder = Recorder::new(dests, args.buoy, base_ns, bar)?;
    let mut stderr = Stderr;
    let mut pacer = args.pace.map(|pace| Pacer::new(pace, stop::flag()));
    let mut observer = Tee(Vec::new());
    if let Some(pacer) = pacer.as_mut() {
        observer.0.push(pacer);
    }
    observer.0.push(&mut recorder);
    observer.0.push(&mut stderr);
    if let Some(view) = live.as_mut() {
        observer.0.push(view);
    }
    let (wall, mut done) = (std::time::Instant::now(), None);
    let (mut metrics, code) = match (role, &args.port) {
        (Some(role), Some(device)) => {
            let mut endpoint = args.port_args.open(device)?;
            let what = match role {
                Role::Operator => format!("operator: IPG {:.1} ms", ipg_s * 1e3),
                Role::Rov => "ROV: answering every slot".into(),
            };
            say!(
                "{what} on {device}, {:.0} s (Ctrl-C stops and keeps the outputs)",
                args.duration_s()
            );
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
            let metrics = session::run_with(&config, parts, &mut observer, stop::flag())?;
            let model_name = match model.name.as_str() {
                "" => "a model file",
                name => name,
            };
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

/// The exit code of a real-time run that ended so after `duration_s`, said on stderr.
fn ended_code(ended: Ended, duration_s: f64) -> u8 {
    match ended {
        Ended::Done => EXIT_OK,
        Ended::Stopped => {
            say!("stopped after {duration_s:.1} s");
            EXIT_OK
        }
        Ended::Failed(error) => {
            say!("{error} after {duration_s:.1} s; outputs so far kept");
            EXIT_CHECK_FAILED
        }
    }
}

/// Warnings of the session (a bad order line) on standard error, as they come.
struct Stderr;

impl Observer for Stderr {
    fn warning(&mut self, _t_s: f64, text: &str) {
        say!("{text}");
    }
}

/// The field flags that apply only to one end.
fn field_usage(args: &Args, role: Option<Role>) -> Result<()> {
    use rovlink::cli::UsageError;
    let rov_side = role != Some(Role::Operator);
    let operator_side = role != Some(Role::Rov);
    if matches!(args.vehicle, Vehicle::Mavlink(_)) && role != Some(Role::Rov) {
        return Err(UsageError(
            "--vehicle mavlink:... drives a real autopilot: it needs --role rov (real time)".into(),
        )
        .into());
    }
    let checks = [
        (rov_side, "--camera", args.camera.is_some(), "the ROV end"),
        (
            rov_side,
            "--camera-cmd",
            args.camera_cmd.is_some(),
            "the ROV end",
        ),
        (
            operator_side,
            "--orders",
            args.orders.is_some(),
            "the operator end",
        ),
        (operator_side, "--preview", args.preview, "the operator end"),
    ];
    for (applies, flag, given, end) in checks {
        if given && !applies {
            return Err(UsageError(format!("{flag} only applies to {end}")).into());
        }
    }
    Ok(())
}

/// What the ends run beyond the config: order sources, the vehicle, the camera.
fn parts(args: &Args, config: &SessionConfig) -> Result<Parts> {
    let mut parts = Parts::from_config(config);
    if let Vehicle::Mavlink(endpoint) = &args.vehicle {
        let options = rovlink::rcp::mavlink::MavlinkOptions::default();
        let drive = rovlink::rcp::mavlink::connect(endpoint, &options)
            .map_err(|e| rovlink::cli::UsageError(format!("--vehicle: {e}")))?;
        say!("vehicle: ArduSub over MAVLink at {}", drive.endpoint());
        parts.drive = Box::new(drive);
    }
    if let Some(dir) = &args.camera {
        parts.camera = Box::new(camera::newest_in_dir(dir)?);
    }
    if let Some(command) = &args.camera_cmd {
        // In virtual time a capture waits for the command's run (the session's time stands
        // still meanwhile); in real time it never waits.
        parts.camera = Box::new(match args.role {
            Some(_) => camera::command_camera(command)?,
            None => camera::command_camera_waiting(command)?.stop_on(stop::flag()),
        });
    }
    if let Some(path) = &args.orders {
        let live = args.role.is_some();
        parts.orders.push(Box::new(open_orders(path, live)?));
    }
    Ok(parts)
}

/// A signal came while the run was still starting.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct Stopped(String);

/// Opens `--orders`. In simulation the whole input is read at start, which waits for a
/// FIFO's writer (or a terminal's end of input): that wait is done aside, so a signal
/// meanwhile ends the run ([`Stopped`]) instead of being left for later.
fn open_orders(path: &std::path::Path, live: bool) -> Result<rovlink::rcp::console::JsonOrders> {
    use std::sync::mpsc::RecvTimeoutError;
    if live {
        return Ok(rovlink::rcp::console::open_orders(path, true)?);
    }
    let (tx, rx) = std::sync::mpsc::channel();
    let owned = path.to_path_buf();
    std::thread::Builder::new()
        .name("orders-open".into())
        .spawn(move || {
            let _ = tx.send(rovlink::rcp::console::open_orders(&owned, false));
        })?;
    loop {
        match rx.recv_timeout(std::time::Duration::from_millis(50)) {
            Ok(opened) => return Ok(opened?),
            Err(RecvTimeoutError::Timeout) if !stop::requested() => {}
            Err(_) => {
                let what = format!(
                    "stopped while waiting for the orders of --orders {}",
                    path.display()
                );
                return Err(Stopped(what).into());
            }
        }
    }
}

/// The host part of HOST:PORT, for the URL said at start.
pub(crate) fn host_of(addr: &str) -> &str {
    addr.rsplit_once(':').map_or(addr, |(host, _)| host)
}
