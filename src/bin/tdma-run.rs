//! tdma-run: a whole teleoperation session, operator and ROV: both ends over a link model in
//! virtual time, or one end in real time over a serial port, pseudo-terminal or UDP.
#![forbid(unsafe_code)]

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use std::io::IsTerminal;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result, bail};
use clap::{Parser, ValueEnum};
use rovlink::cli::model::ModelArgs;
use rovlink::cli::port::PortArgs;
use rovlink::gll::PortError;
use rovlink::io::{AtomicFile, EXIT_CHECK_FAILED, EXIT_OK, IoError};
use rovlink::rcp::camera;
use rovlink::rcp::mcap_log::McapLog;
use rovlink::rcp::operator::Joystick;
use rovlink::rcp::realtime::{self, Ended, Role};
use rovlink::rcp::session::{
    self, FrameEvent, JoystickChange, Metrics, Observer, SessionConfig, Waypoint, auto_ipg_s,
};
use rovlink::rcp::{ImageSettings, PoseSample, test_image};
use rovlink::wire::operator::Roi;

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "tdma-run";

macro_rules! say {
    ($($arg:tt)*) => {
        rovlink::io::warn(TOOL, &format!($($arg)*))
    };
}

const EXAMPLES: &str = "\
Examples:
  tdma-run                                   10 minutes over the S100 model, built-in script and image
  tdma-run --sim --model s100 --ipg 640 --ber 0 --duration 600 --metrics m.json
  tdma-run --ber 7e-4 --events events.csv    one row per frame: the data of the paper's Fig. 10
  tdma-run --waypoints wp.csv --buoy 0,0,0 --start 1,0,1 --duration 200 --track track.csv
  tdma-run --images photos/ --image-size 1500 --roi 100,80,420,300 --images-out received/
  tdma-run --mcap session.mcap               open it in Foxglove: pose, velocities, link, images

Real time, one end per process (through link-sim standing in for the modems):
  link-sim --model s100 --pty > ptys.txt &     prints two pseudo-terminals: A, then B
  sleep 1; A=$(sed -n 1p ptys.txt); B=$(sed -n 2p ptys.txt)
  tdma-run --role rov --port $B --duration 130 &
  tdma-run --role operator --port $A --ipg 640 --duration 120 --images-out received/
Real modems: --port /dev/ttyUSB0 (transparent, e.g. WFS S100), --dialect evologics with
--port tcp:192.168.0.209:9200, or --port udp:BIND_ADDR=PEER_ADDR. Start the ROV end first.

--script: CSV t_s,vx,vy,vz,vyaw (joystick, percent of full thrust, from t on).
--waypoints: CSV t_s,x_m,y_m,z_m,heading_deg (a GoTo order queued at t; NED metres).
--track: CSV t_s,x_m,y_m,z_m,heading_deg,distance_m,goal_x_m,goal_y_m,goal_z_m,
  goal_distance_m,backtrack_x_m,backtrack_y_m,backtrack_z_m,link_up (one row per 0.1 s vehicle
  step; distances from the buoy; the data of the paper's Figs. 12-14).
The summary on stderr has Table 4's rows for both directions; --metrics writes them as JSON
with the image, order and link-recovery counters. In real time each end knows only its half:
frames it sent, and frames it received with their arrival times (no one-way delay: that needs
both clocks); the operator adds the round trip from each slot's frame to the ROV's answer.

Exit codes: 0 ok, 1 the port failed during a real-time run (outputs so far kept), 2 bad usage
or input.";

/// Which end runs in real time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum RoleArg {
    /// The TDMA master: sends the slots, plays the script and waypoints, receives images.
    Operator,
    /// The vehicle: answers each slot, drives the simulated vehicle, sends images.
    Rov,
}

/// Run a teleoperation session: operator (TDMA master) and ROV, over a link model in virtual
/// time (the default, --sim) or one end per process over a real port (--role).
///
/// Both ends speak the remote-control protocol of wire.md: joystick and high-level orders down,
/// status and DEBT-coded camera images up, one frame per slot, with heartbeats and the ROV's
/// recovery by backtracking. In simulation the same seed gives the same session.
#[derive(Parser, Debug)]
#[command(version, after_help = EXAMPLES)]
struct Args {
    /// Both ends and the link in one process, in virtual time (the default).
    #[arg(long, conflicts_with_all = ["role", "port"])]
    sim: bool,

    /// Run one end in real time over --port.
    #[arg(long, value_enum, requires = "port", help_heading = "Real time")]
    role: Option<RoleArg>,

    /// The modem: a serial port or pseudo-terminal, tcp:HOST:PORT or udp:BIND_ADDR=PEER_ADDR.
    #[arg(
        long,
        value_name = "DEV",
        requires = "role",
        help_heading = "Real time"
    )]
    port: Option<String>,

    #[command(flatten)]
    port_args: PortArgs,

    #[command(flatten)]
    model: ModelArgs,

    /// Inter-packet gap: milliseconds, or `auto` (air times + 2 x delays + 3 jitter sigmas).
    #[arg(long, value_name = "MS|auto", default_value = "auto")]
    ipg: String,

    /// Session length, s.
    #[arg(long, value_name = "S", default_value_t = 600.0)]
    duration: f64,

    /// Seed of the link's random streams.
    #[arg(long, default_value_t = 1)]
    seed: u64,

    /// The operator modem's position, NED m: its distance to the ROV drives the range model.
    #[arg(long, value_name = "X,Y,Z", default_value = "0,0,0")]
    buoy: String,

    /// The ROV's initial position, NED m.
    #[arg(long, value_name = "X,Y,Z", default_value = "1,0,0")]
    start: String,

    /// Joystick script, CSV t_s,vx,vy,vz,vyaw [default: a built-in 10-minute script].
    #[arg(long, value_name = "FILE")]
    script: Option<PathBuf>,

    /// GoTo orders, CSV t_s,x_m,y_m,z_m,heading_deg [default: the built-in script's].
    #[arg(long, value_name = "FILE")]
    waypoints: Option<PathBuf>,

    /// Encoded image size, bytes (at most 64 trunks).
    #[arg(long, value_name = "BYTES", default_value_t = 2000)]
    image_size: u16,

    /// Trunk size, bytes (39 makes the paper's 57-byte ROV frame).
    #[arg(long, value_name = "BYTES", default_value_t = 39, value_parser = clap::value_parser!(u8).range(1..))]
    trunk: u8,

    /// Region of interest x0,y0,x1,y1 in pixels.
    #[arg(long, value_name = "X0,Y0,X1,Y1")]
    roi: Option<String>,

    /// Camera pictures: a directory of images or one image file, cycled [default: built-in].
    #[arg(long, value_name = "DIR|FILE")]
    images: Option<PathBuf>,

    /// Write the session's figures as JSON here.
    #[arg(long, value_name = "FILE")]
    metrics: Option<PathBuf>,

    /// Write one CSV row per frame here: direction,kind,bytes,t_sent_s,t_received_s,fate.
    #[arg(long, value_name = "FILE")]
    events: Option<PathBuf>,

    /// Write every completed image here as PNG (image-0001.png, ...).
    #[arg(long, value_name = "DIR")]
    images_out: Option<PathBuf>,

    /// Write the vehicle's track here, one CSV row per vehicle step (see below).
    #[arg(long, value_name = "FILE")]
    track: Option<PathBuf>,

    /// Write an MCAP session log here (Foxglove: pose, goal, velocities, link, images).
    #[arg(long, value_name = "FILE")]
    mcap: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    rovlink::io::finish_main(TOOL, run(&args))
}

#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct BadInput(String);

fn bad(message: String) -> anyhow::Error {
    anyhow::Error::new(BadInput(message))
}

fn triple(flag: &str, text: &str) -> Result<[f64; 3]> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad(format!("{flag}: expected X,Y,Z in metres, found `{text}`")))?;
    match values[..] {
        [x, y, z] if values.iter().all(|v| v.is_finite()) => Ok([x, y, z]),
        _ => Err(bad(format!(
            "{flag}: expected X,Y,Z in metres, found `{text}`"
        ))),
    }
}

/// Reads a CSV file with a header holding `columns`; every row's fields as numbers.
fn read_table(path: &Path, columns: &[&str]) -> Result<Vec<Vec<f64>>> {
    let text = std::fs::read(path).map_err(|source| IoError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    let rows = rovlink::io::read_number_table(&text, columns, f64::NEG_INFINITY)
        .map_err(|e| bad(format!("{}: {e}", path.display())))?;
    Ok(rows.into_iter().map(|(_, values)| values).collect())
}

/// The built-in 10-minute session: some joystick driving, then three GoTo orders, all within
/// the S100's 5 m of the buoy.
fn builtin_script() -> (Vec<JoystickChange>, Vec<Waypoint>) {
    let js = |t_s, vx, vy, vz, vyaw| JoystickChange {
        t_s,
        joystick: Joystick { vx, vy, vz, vyaw },
    };
    let script = vec![
        js(5.0, 20.0, 0.0, 10.0, 0.0),
        js(15.0, 0.0, 0.0, 0.0, 0.0),
        js(30.0, 0.0, 0.0, 0.0, 30.0),
        js(36.0, 0.0, 0.0, 0.0, 0.0),
        js(60.0, -15.0, 10.0, 0.0, 0.0),
        js(75.0, 0.0, 0.0, 0.0, 0.0),
    ];
    let wp = |t_s, x, y, z, heading_deg| Waypoint {
        t_s,
        position_m: [x, y, z],
        heading_deg,
    };
    let waypoints = vec![
        wp(120.0, 3.0, 1.0, 0.5, 90.0),
        wp(300.0, 1.5, -1.0, 0.5, 180.0),
        wp(450.0, 1.0, 0.0, 0.0, 0.0),
    ];
    (script, waypoints)
}

fn load_images(path: Option<&Path>) -> Result<Vec<rovlink::debt::Image>> {
    let Some(path) = path else {
        return Ok((0..4).map(|k| test_image(320, 240, k)).collect());
    };
    let pictures = camera::load(path).map_err(|e| bad(e.to_string()))?;
    if let Some(first) = pictures.scaled.first() {
        say!(
            "{} picture(s) larger than DEBT's {side}x{side} scaled down to fit ({}: {}x{} to {}x{})",
            pictures.scaled.len(),
            first.path.display(),
            first.from.0,
            first.from.1,
            first.to.0,
            first.to.1,
            side = rovlink::debt::MAX_SIDE
        );
    }
    Ok(pictures.images)
}

/// Writes the chosen outputs as the session goes: events, track, MCAP, images, progress.
struct Outputs {
    events: Option<AtomicFile>,
    track: Option<AtomicFile>,
    mcap: Option<McapLog>,
    images_out: Option<PathBuf>,
    images: u64,
    buoy_m: [f64; 3],
    progress: indicatif::ProgressBar,
    error: Option<anyhow::Error>,
}

/// The header of `--track`.
const TRACK_HEADER: &str = "t_s,x_m,y_m,z_m,heading_deg,distance_m,goal_x_m,goal_y_m,goal_z_m,goal_distance_m,backtrack_x_m,backtrack_y_m,backtrack_z_m,link_up\n";

impl Outputs {
    fn keep(&mut self, outcome: Result<(), impl Into<anyhow::Error>>) {
        if let (Err(error), None) = (outcome, self.error.as_ref()) {
            self.error = Some(error.into());
        }
    }

    /// Commits every file; the first error wins.
    fn finish(mut self) -> Result<()> {
        self.progress.finish_and_clear();
        if let Some(error) = self.error.take() {
            return Err(error);
        }
        if let Some(out) = self.events.take() {
            out.commit()?;
        }
        if let Some(out) = self.track.take() {
            out.commit()?;
        }
        if let Some(log) = self.mcap.take() {
            log.finish()?;
        }
        Ok(())
    }
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

impl Observer for Outputs {
    fn frame(&mut self, e: &FrameEvent) {
        let t = e.t_received_s.or(e.t_sent_s).unwrap_or(0.0);
        self.progress.set_position(t as u64);
        if let Some(log) = self.mcap.as_mut() {
            log.frame(e);
        }
        if self.error.is_some() {
            return;
        }
        if let Some(out) = self.events.as_mut() {
            let time = |t: Option<f64>| t.map_or(String::new(), |t| format!("{t:.6}"));
            let row = format!(
                "{},{},{},{},{},{}\n",
                e.direction,
                e.kind,
                e.bytes,
                time(e.t_sent_s),
                time(e.t_received_s),
                e.fate
            );
            let outcome = out.write_bytes(row.as_bytes());
            self.keep(outcome);
        }
    }

    fn image(&mut self, t_s: f64, stream: &[u8]) {
        self.images += 1;
        if let Some(log) = self.mcap.as_mut() {
            log.image(t_s, stream);
        }
        let (Some(dir), None) = (self.images_out.as_ref(), self.error.as_ref()) else {
            return;
        };
        let path = dir.join(format!("image-{:04}.png", self.images));
        let saved = rovlink::debt::decode(stream)
            .map_err(|e| anyhow::anyhow!("image {}: {e}", self.images))
            .and_then(|img| {
                let png = rovlink::debt::picture::to_png(&img)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
                Ok(AtomicFile::create(&path)?.commit_with(&png)?)
            });
        self.keep(saved);
    }

    fn pose(&mut self, pose: &PoseSample) {
        if let Some(log) = self.mcap.as_mut() {
            log.pose(pose);
        }
        let (Some(out), None) = (self.track.as_mut(), self.error.as_ref()) else {
            return;
        };
        let point = |p: Option<[f64; 3]>| {
            p.map_or(",,".to_string(), |p| {
                format!("{:.4},{:.4},{:.4}", p[0], p[1], p[2])
            })
        };
        let [x, y, z] = pose.position_m;
        let row = format!(
            "{:.3},{x:.4},{y:.4},{z:.4},{:.2},{:.4},{},{},{},{}\n",
            pose.t_s,
            pose.heading_deg,
            distance(pose.position_m, self.buoy_m),
            point(pose.goal_m),
            pose.goal_m.map_or(String::new(), |g| format!(
                "{:.4}",
                distance(g, self.buoy_m)
            )),
            point(pose.backtrack_m),
            u8::from(pose.link_up)
        );
        let outcome = out.write_bytes(row.as_bytes());
        self.keep(outcome);
    }
}

fn run(args: &Args) -> Result<u8> {
    let model = args.model.resolve()?;
    let buoy = triple("--buoy", &args.buoy)?;
    let start = triple("--start", &args.start)?;
    if !(args.duration.is_finite() && args.duration > 0.0) {
        bail!(bad(format!(
            "--duration: expected seconds > 0, found {}",
            args.duration
        )));
    }
    let settings = ImageSettings {
        roi: match &args.roi {
            None => None,
            Some(text) => {
                let v: Vec<u16> = text
                    .split(',')
                    .map(|p| p.trim().parse::<u16>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| {
                        bad(format!(
                            "--roi: expected x0,y0,x1,y1 in pixels, found `{text}`"
                        ))
                    })?;
                match v[..] {
                    [x0, y0, x1, y1] if x0 < x1 && y0 < y1 && x1 < 1024 && y1 < 1024 => {
                        Some(Roi { x0, y0, x1, y1 })
                    }
                    _ => bail!(bad(format!(
                        "--roi: expected x0 < x1, y0 < y1, all < 1024, found `{text}`"
                    ))),
                }
            }
        },
        size_bytes: args.image_size,
        trunk_bytes: args.trunk,
        ..ImageSettings::default()
    };
    let rov_frame = 5 + 13 + usize::from(args.trunk);
    let distance = ((0..3).map(|k| (start[k] - buoy[k]).powi(2)).sum::<f64>()).sqrt();
    let ipg_s = if args.ipg == "auto" {
        auto_ipg_s(&model, 16, rov_frame, distance)
    } else {
        match args.ipg.parse::<f64>() {
            Ok(ms) if ms.is_finite() && ms > 0.0 => ms / 1e3,
            _ => bail!(bad(format!(
                "--ipg: expected milliseconds > 0 or `auto`, found `{}`",
                args.ipg
            ))),
        }
    };
    let (mut script, mut waypoints) = builtin_script();
    if let Some(path) = &args.script {
        script = read_table(path, &["t_s", "vx", "vy", "vz", "vyaw"])?
            .into_iter()
            .map(|r| JoystickChange {
                t_s: r[0],
                joystick: Joystick {
                    vx: r[1],
                    vy: r[2],
                    vz: r[3],
                    vyaw: r[4],
                },
            })
            .collect();
        if args.waypoints.is_none() {
            waypoints.clear();
        }
    }
    if let Some(path) = &args.waypoints {
        waypoints = read_table(path, &["t_s", "x_m", "y_m", "z_m", "heading_deg"])?
            .into_iter()
            .map(|r| Waypoint {
                t_s: r[0],
                position_m: [r[1], r[2], r[3]],
                heading_deg: r[4],
            })
            .collect();
        if args.script.is_none() {
            script.clear();
        }
    }
    script.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    waypoints.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let images = load_images(args.images.as_deref())?;
    let role = args.role.map(|r| match r {
        RoleArg::Operator => Role::Operator,
        RoleArg::Rov => Role::Rov,
    });
    if role.is_none() && args.port_args.any_set() {
        bail!(bad(
            "--dialect, --instant and --chunk-bytes apply to real modems (--role with --port)"
                .into()
        ));
    }
    let config = SessionConfig {
        model: model.clone(),
        seed: args.seed,
        ipg_s,
        duration_s: args.duration,
        buoy_m: buoy,
        start_m: start,
        script,
        waypoints,
        settings,
        images,
    };
    config.validate().map_err(|e| bad(e.to_string()))?;
    // Every output file is created before the session starts, so a bad path fails at once.
    let metrics_file = args
        .metrics
        .as_deref()
        .map(AtomicFile::create)
        .transpose()?;
    let with_header = |path: &Option<PathBuf>, header: &str| -> Result<Option<AtomicFile>> {
        let Some(path) = path else { return Ok(None) };
        let mut out = AtomicFile::create(path)?;
        out.write_bytes(header.as_bytes())?;
        Ok(Some(out))
    };
    let events = with_header(
        &args.events,
        "direction,kind,bytes,t_sent_s,t_received_s,fate\n",
    )?;
    let track = with_header(&args.track, TRACK_HEADER)?;
    if let Some(dir) = &args.images_out {
        if dir.exists() && !dir.is_dir() {
            bail!(bad(format!(
                "--images-out: {}: not a directory",
                dir.display()
            )));
        }
        std::fs::create_dir_all(dir).map_err(|source| IoError::Open {
            path: dir.clone(),
            source,
        })?;
    }
    let base_ns = if role.is_some() {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(0))
    } else {
        0
    };
    let mcap = args
        .mcap
        .as_deref()
        .map(|path| McapLog::create(path, base_ns))
        .transpose()?;
    let mut outputs = Outputs {
        events,
        track,
        mcap,
        images_out: args.images_out.clone(),
        images: 0,
        buoy_m: buoy,
        progress: progress_bar(role.is_some(), args.duration),
        error: None,
    };
    let wall = std::time::Instant::now();
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .context("cannot install the Ctrl-C handler")?;
    let (metrics, code) = match (role, &args.port) {
        (Some(role), Some(device)) => {
            let mut endpoint = args.port_args.open(device).map_err(|e| match e {
                PortError::Usage(message) => bad(message),
                PortError::Open(error) => error.into(),
            })?;
            match role {
                Role::Operator => say!(
                    "operator on {device}: {:.0} s, IPG {:.1} ms (Ctrl-C stops and keeps the outputs)",
                    args.duration,
                    ipg_s * 1e3
                ),
                Role::Rov => say!(
                    "ROV on {device}: {:.0} s, answering every slot (Ctrl-C stops and keeps the outputs)",
                    args.duration
                ),
            }
            let (metrics, ended) =
                realtime::run(role, &config, endpoint.as_mut(), &stop, &mut outputs);
            let code = match ended {
                Ended::Done => EXIT_OK,
                Ended::Stopped => {
                    say!("stopped after {:.1} s", metrics.duration_s);
                    EXIT_OK
                }
                Ended::Failed(error) => {
                    say!(
                        "{error} after {:.1} s; outputs so far kept",
                        metrics.duration_s
                    );
                    EXIT_CHECK_FAILED
                }
            };
            (metrics, code)
        }
        _ => {
            let metrics =
                session::run(&config, &mut outputs, &stop).map_err(|e| bad(e.to_string()))?;
            say!(
                "{:.0} s over {} (seed {}), IPG {:.1} ms, {:.3} s of wall time",
                args.duration,
                if model.name.is_empty() {
                    "a model file"
                } else {
                    &model.name
                },
                args.seed,
                ipg_s * 1e3,
                wall.elapsed().as_secs_f64()
            );
            (metrics, EXIT_OK)
        }
    };
    outputs.finish()?;
    if let Some(file) = metrics_file {
        file.commit_json(&metrics)?;
    }
    print_summary(&metrics);
    Ok(code)
}

/// A progress bar in seconds of session time, only for real-time runs on a terminal.
fn progress_bar(real_time: bool, duration_s: f64) -> indicatif::ProgressBar {
    if !real_time || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(duration_s.ceil() as u64);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{spinner} {pos}/{len} s [{bar:30}] {msg}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// Table 4's rows for both directions, then the counters, on stderr.
fn print_summary(metrics: &Metrics) {
    let (r, o) = (&metrics.rov_to_operator, &metrics.operator_to_rov);
    let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    if metrics.measured_by != "simulation" {
        print_half(metrics);
        return;
    }
    say!("{:<18} {:>10} {:>10}", "", "ROV->op", "op->ROV");
    say!(
        "{:<18} {:>10.3} {:>10.3}",
        "throughput kbit/s",
        r.throughput_kbps,
        o.throughput_kbps
    );
    say!(
        "{:<18} {:>10} {:>10}",
        "delay ms",
        ms(r.delay_ms),
        ms(o.delay_ms)
    );
    say!(
        "{:<18} {:>10} {:>10}",
        "jitter ms",
        ms(r.jitter_ms),
        ms(o.jitter_ms)
    );
    say!("{:<18} {:>10.2} {:>10.2}", "IAT ms", r.iat_ms, o.iat_ms);
    say!(
        "{:<18} {:>10.2} {:>10.2}",
        "IAT sigma ms",
        r.iat_sigma_ms,
        o.iat_sigma_ms
    );
    say!(
        "{:<18} {:>10} {:>10}",
        "frames sent",
        r.frames_sent,
        o.frames_sent
    );
    say!(
        "{:<18} {:>10} {:>10}",
        "frames delivered",
        r.frames_delivered,
        o.frames_delivered
    );
    print_counters(metrics);
}

/// One end's figures in real time: what it sent, what it received.
fn print_half(metrics: &Metrics) {
    let (sent, received, sent_name, received_name) = if metrics.measured_by == "operator" {
        (
            &metrics.operator_to_rov,
            &metrics.rov_to_operator,
            "op->ROV",
            "ROV->op",
        )
    } else {
        (
            &metrics.rov_to_operator,
            &metrics.operator_to_rov,
            "ROV->op",
            "op->ROV",
        )
    };
    say!(
        "sent {sent_name}: {} frames; received {received_name}: {} frames, {:.3} kbit/s, IAT {:.2} ms (sigma {:.2} ms)",
        sent.frames_sent,
        received.frames_delivered,
        received.throughput_kbps,
        received.iat_ms,
        received.iat_sigma_ms
    );
    if let (Some(rtt), Some(jitter)) = (metrics.round_trip_ms, metrics.round_trip_jitter_ms) {
        say!("round trip slot -> answer {rtt:.2} ms (sigma {jitter:.2} ms)");
    }
    print_counters(metrics);
}

/// Images, orders and link recovery.
fn print_counters(metrics: &Metrics) {
    let period = metrics
        .image_period_s
        .map_or("-".into(), |p| format!("{p:.1} s"));
    match metrics.measured_by {
        "operator" => say!(
            "images completed {} (one every {period}); orders sent {}, acknowledged {}",
            metrics.images_completed,
            metrics.orders_sent,
            metrics.orders_acknowledged
        ),
        "rov" => say!(
            "images started {}; orders executed {}; link lost {} times, recovered {}",
            metrics.images_started,
            metrics.orders_executed,
            metrics.link_losses,
            metrics.link_recoveries
        ),
        _ => say!(
            "images completed {} of {} started (one every {period}); orders sent {}, acknowledged {}, executed {}, executed twice {}; link lost {} times, recovered {}",
            metrics.images_completed,
            metrics.images_started,
            metrics.orders_sent,
            metrics.orders_acknowledged,
            metrics.orders_executed,
            metrics.orders_executed_twice,
            metrics.link_losses,
            metrics.link_recoveries
        ),
    }
}
