//! What every tdma-run mode shares: the flags that apply to one end only, the ends' parts
//! (order sources, the vehicle, the camera), how a real-time run's end is said.

use std::path::Path;

use crate::outputs::{Destinations, check_images_out};
use anyhow::Result;
use rovlink_base::UsageError;
use rovlink_base::io::{EXIT_CHECK_FAILED, EXIT_OK};
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_base::secret::create_secret_file;
use rovlink_cli::say;
use rovlink_cli::stop;
use rovlink_field::foxglove::{LiveView, Policy};
use rovlink_rcp::camera;
use rovlink_rcp::realtime::{Ended, Role};
use rovlink_rcp::report::Observer;
use rovlink_rcp::session::{Parts, SessionConfig};

use crate::TOOL;
use crate::flags::{Args, Vehicle};

/// The exit code of a real-time run that ended so after `duration_s`, said on stderr.
pub(super) fn ended_code(ended: Ended, duration_s: f64) -> u8 {
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
pub(super) struct Stderr;

impl Observer for Stderr {
    fn warning(&mut self, _t_s: f64, text: &str) {
        say!("{text}");
    }

    fn wants_poses(&self) -> bool {
        false
    }
}

/// The field flags that apply only to one end.
pub(super) fn field_usage(args: &Args, role: Option<Role>) -> Result<()> {
    use rovlink_base::UsageError;
    let rov_side = role != Some(Role::Operator);
    let operator_side = role != Some(Role::Rov);
    if args.vehicle == Vehicle::Ros2 && role != Some(Role::Rov) {
        return Err(UsageError(
            "--vehicle ros2 drives a vehicle on a ROS 2 graph: it needs --role rov (real time)"
                .into(),
        )
        .into());
    }
    if matches!(args.vehicle, Vehicle::Mavlink(_)) && role != Some(Role::Rov) {
        return Err(UsageError(
            "--vehicle mavlink:... drives a real autopilot: it needs --role rov (real time)".into(),
        )
        .into());
    }
    if args.mavlink_key_file.is_some() && !matches!(args.vehicle, Vehicle::Mavlink(_)) {
        return Err(UsageError(
            "--mavlink-key-file signs the MAVLink of --vehicle mavlink:...: found --vehicle sim"
                .into(),
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
        (operator_side, "--ros2", args.ros2, "the operator end"),
    ];
    for (applies, flag, given, end) in checks {
        if given && !applies {
            return Err(rovlink_base::UsageError(format!("{flag} only applies to {end}")).into());
        }
    }
    Ok(())
}

/// What the ends run beyond the config: order sources, the vehicle, the camera.
pub(super) fn parts(args: &Args, config: &SessionConfig) -> Result<Parts> {
    let mut parts = Parts::from_config(config);
    if args.vehicle == Vehicle::Ros2 {
        let drive = rovlink_field::ros2_vehicle::ros2_drive(
            &args.ros2_namespace,
            args.ros2_domain.map(|d| d as u16),
        )
        .map_err(|e| rovlink_base::UsageError(format!("--vehicle ros2: {e}")))?;
        say!(
            "vehicle on ROS 2: {ns}/cmd_vel, {ns}/goal_pose and {ns}/arm out, {ns}/odom in \
             (DDS authenticates nobody: keep the vehicle's domain to the vehicle)",
            ns = args.ros2_namespace.trim_end_matches('/')
        );
        parts.drive = Box::new(drive);
    }
    if let Vehicle::Mavlink(endpoint) = &args.vehicle {
        use rovlink_field::mavlink::{MavlinkOptions, SigningKey, connect};
        let key = (args.mavlink_key_file.as_deref())
            .map(SigningKey::read)
            .transpose()
            .map_err(|e| rovlink_base::UsageError(format!("--mavlink-key-file: {e}")))?;
        let options = MavlinkOptions {
            key,
            tool: Some(crate::TOOL),
            ..MavlinkOptions::default()
        };
        let drive = connect(endpoint, &options)
            .map_err(|e| rovlink_base::UsageError(format!("--vehicle: {e}")))?;
        if drive.signed() {
            say!(
                "vehicle: ArduSub over MAVLink at {}, signed: only messages signed with the key \
                 are used",
                drive.endpoint()
            );
        } else {
            say!("vehicle: ArduSub over MAVLink at {}", drive.endpoint());
            say!(
                "warning: MAVLink is unsigned: anyone who can reach {} can command the \
                 autopilot and feed the operator a pose (give --mavlink-key-file; see \
                 docs/tdma-mavlink.md)",
                drive.endpoint()
            );
        }
        parts.drive = Box::new(drive);
    }
    if let Some(dir) = &args.camera {
        match dir.to_str().and_then(|s| s.strip_prefix("ros2:")) {
            Some(topic) => {
                use rovlink_field::ros2_camera::{Frames, ros2_camera};
                let frames = Frames::of_topic(topic);
                let cam = ros2_camera(topic, frames, args.ros2_domain.map(|d| d as u16))
                    .map_err(|e| rovlink_base::UsageError(format!("--camera ros2:{topic}: {e}")))?;
                parts.camera = Box::new(cam);
            }
            None => parts.camera = Box::new(camera::newest_in_dir(dir)?),
        }
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

/// The guards of the nodes this run holds ([`rovlink_rcp::secure`]): none without
/// `--key-file`; in a simulation one per node of `scenario`; in real time the one node at
/// `node`, its counters in `--key-state` or beside the key file. Without keys, a real-time end
/// warns once that the link is open.
pub(super) fn guards(
    args: &Args,
    scenario: &rovlink_rcp::scenario::Scenario,
    node: Option<u8>,
) -> Result<std::collections::BTreeMap<u8, rovlink_security::Guard>> {
    let Some(security) = security(args)? else {
        if node.is_some() {
            say!("warning: {}", rovlink_rcp::secure::OPEN_LINK_WARNING);
        }
        return Ok(Default::default());
    };
    let guards = match node {
        None => security.simulation_guards(scenario),
        Some(address) => {
            let guard = security
                .node_guard(address, args.key_state.as_deref())
                .map_err(|e| {
                    let flag = match args.key_state {
                        Some(_) => "--key-state",
                        None => "--key-file (its counters)",
                    };
                    rovlink_base::UsageError(format!("{flag}: {e}"))
                })?;
            std::collections::BTreeMap::from([(address, guard)])
        }
    };
    say_secured(&security);
    Ok(guards)
}

/// Says once, at start, that a run's frames are secured and how.
pub(super) fn say_secured(security: &rovlink_rcp::secure::Security) {
    let encrypted = if security.encrypt { ", encrypted" } else { "" };
    say!("frames authenticated (AES-CMAC, 6 bytes a frame{encrypted}); others are refused");
}

/// `--key-file` and `--encrypt`, read and checked (the trunk must leave room for the tag).
pub(super) fn security(args: &Args) -> Result<Option<rovlink_rcp::secure::Security>> {
    let Some(path) = &args.key_file else {
        return Ok(None);
    };
    let ring = rovlink_security::KeyRing::load(path)
        .map_err(|e| rovlink_base::UsageError(format!("--key-file: {e}")))?;
    let max = rovlink_wire::rov::MAX_EXTENDED_TRUNK_BYTES - rovlink_rcp::secure::OVERHEAD_BYTES;
    if args.trunk > max as u64 {
        return Err(rovlink_base::UsageError(format!(
            "--trunk {}: with --key-file a trunk is at most {max} bytes (the frame carries a \
             6-byte tag and counter)",
            args.trunk
        ))
        .into());
    }
    Ok(Some(rovlink_rcp::secure::Security {
        ring,
        encrypt: args.encrypt,
        key_file: path.clone(),
    }))
}

/// A signal came while the run was still starting.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub(super) struct Stopped(pub(super) String);

/// Opens `--orders`. In simulation the whole input is read at start, which waits for a
/// FIFO's writer (or a terminal's end of input): that wait is done aside, so a signal
/// meanwhile ends the run ([`Stopped`]) instead of being left for later.
fn open_orders(path: &std::path::Path, live: bool) -> Result<rovlink_field::console::JsonOrders> {
    use std::sync::mpsc::RecvTimeoutError;
    if live {
        return Ok(rovlink_field::console::open_orders(path, true)?);
    }
    let (tx, rx) = std::sync::mpsc::channel();
    let owned = path.to_path_buf();
    std::thread::Builder::new()
        .name("orders-open".into())
        .spawn(move || {
            let _ = tx.send(rovlink_field::console::open_orders(&owned, false));
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

/// The live view's policy from the flags: the control token of --foxglove-token-file (read as
/// a key file is: yours, mode 0600), --foxglove-origin, --foxglove-insecure, TLS.
pub(super) fn foxglove_policy(args: &Args) -> Result<Policy> {
    let tls = args
        .foxglove_tls_cert
        .as_deref()
        .zip(args.foxglove_tls_key.as_deref());
    rovlink_field::foxglove_gate::policy_from_flags(
        args.foxglove_token_file.as_deref(),
        &args.foxglove_origin,
        args.foxglove_insecure,
        tls,
    )
    .map_err(|e| UsageError(e).into())
}

/// Says once at start who may control the live view `view` of an end taking orders from it.
pub(super) fn say_control(view: &LiveView, policy: &Policy) {
    match &policy.token {
        None => say!("Foxglove: live view is view-only; control needs --foxglove-token-file"),
        Some(_) if view.exposed() && view.scheme() == "ws" => say!(
            "Foxglove: control over plain ws:// on {} (--foxglove-insecure): the token and the \
             orders travel in clear",
            view.addr()
        ),
        Some(_) => say!(
            "Foxglove: control for clients whose URL ends in ?token= and the token of \
             --foxglove-token-file; the others view"
        ),
    }
}

/// --new-foxglove-token FILE: a new control token there (mode 0600, never replacing a file).
pub(super) fn new_foxglove_token(path: &Path) -> Result<u8> {
    let token = rovlink_field::foxglove_gate::new_token()
        .map_err(|e| anyhow::anyhow!("--new-foxglove-token: cannot read /dev/urandom: {e}"))?;
    create_secret_file(path, format!("{token}\n").as_bytes())
        .map_err(|e| UsageError(format!("--new-foxglove-token {e}")))?;
    say!(
        "wrote a new control token to {} (mode 0600): start with --foxglove-token-file {0} and \
         open ws://HOST:PORT/?token=<its contents>",
        path.display()
    );
    Ok(EXIT_OK)
}

/// The host part of HOST:PORT, for the URL said at start.
pub(super) fn host_of(addr: &str) -> &str {
    addr.rsplit_once(':').map_or(addr, |(host, _)| host)
}

/// Every output the flags name, claimed before any work (so bad usage leaves no file): the
/// metrics' destination and the others', in every kind of session.
pub(super) fn claim_outputs(args: &Args) -> Result<(Option<Dest>, Destinations)> {
    let mut outs = Outputs::new();
    outs.inputs(args.inputs());
    let metrics = outs.claim_opt("--metrics", args.metrics.as_deref(), Kind::Text)?;
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
    Ok((metrics, dests))
}
