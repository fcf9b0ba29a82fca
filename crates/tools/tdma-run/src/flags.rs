//! tdma-run's command line.

use std::path::PathBuf;

use clap::{Parser, ValueEnum};
use rovlink_cli::model::ModelArgs;
use rovlink_cli::port::PortArgs;
use rovlink_cli::value::{self, Bound, Range, RealParser, Unit};
use rovlink_link::Model;
use rovlink_rcp::ImageSettings;
use rovlink_rcp::realtime::Role;
use rovlink_rcp::session::{MAX_DURATION_S, MAX_IPG_S, MIN_IMAGE_BYTES, MIN_IPG_S, auto_ipg_for};
use rovlink_wire::operator::Roi;

const EXAMPLES: &str = "\
Examples:
  tdma-run                                   10 minutes over the S100 model, built-in script and image
  tdma-run --sim --model s100 --ipg 640 --ber 0 --duration 600 --metrics m.json
  tdma-run --ber 7e-4 --events events.csv    one row per frame: the data of the paper's Fig. 10
  tdma-run --waypoints wp.csv --buoy 0,0,0 --start 1,0,1 --duration 200 --track track.csv
  tdma-run --images photos/ --image-size 1500 --roi 100,80,420,300 --images-out received/
  tdma-run --mcap session.mcap               open it in Foxglove: pose, velocities, link, images
  tdma-run --duration 3600 --mcap - | mcap info -   any output may be - (standard output; one)

Real time, one end per process (through link-sim standing in for the modems):
  link-sim --model s100 --pty > ptys.txt &     prints two pseudo-terminals: A, then B
  sleep 1; A=$(sed -n 1p ptys.txt); B=$(sed -n 2p ptys.txt)
  tdma-run --role rov --port $B --duration 130 &
  tdma-run --role operator --port $A --ipg 640 --duration 120 --images-out received/
Real modems: --port /dev/ttyUSB0 (transparent, e.g. WFS S100), --dialect evologics with
--port tcp:192.168.0.209:9200, or --port udp:BIND=PEER. Start the ROV end first.

In the field (docs/tdma-mavlink.md, docs/tdma-console.md, docs/tdma-foxglove.md, docs/ros2.md):
  tdma-run --role rov --port /dev/ttyUSB0 --vehicle mavlink:udpin:127.0.0.1:14550 --camera cam/
  mkfifo -m 600 orders; tdma-run --role operator --port /dev/ttyUSB0 --orders orders --telemetry - &
  echo '{\"type\":\"goto\",\"x_cm\":300,\"y_cm\":0,\"z_cm\":50,\"heading_deg\":90}' > orders
  tdma-run --role operator --port /dev/ttyUSB0 --foxglove 127.0.0.1:8765 --images-out rx/ --preview
  tdma-run --role operator --port /dev/ttyUSB0 --ros2 --ros2-control   on the ROS 2 graph, driven from it
With keys (docs/threat-model.md): rcp-pack --new-key keys (copy it to the vehicle), then
  tdma-run --role rov --port $B --key-file keys --encrypt &
  tdma-run --role operator --port $A --key-file keys --encrypt

--script: CSV t_s,vx,vy,vz,vyaw (joystick, percent of full thrust, from t on).
--waypoints: CSV t_s,x_m,y_m,z_m,heading_deg (a GoTo order queued at t; NED metres, within
  the GoTo order's +-327.67 m).
--images: pictures larger than DEBT's 4096x4096 are scaled down to fit (up to 64 megapixels;
  larger ones are refused).
--track: CSV t_s,x_m,y_m,z_m,heading_deg,distance_m,goal_x_m,goal_y_m,goal_z_m,
  goal_distance_m,backtrack_x_m,backtrack_y_m,backtrack_z_m,link_up (one row per 0.1 s vehicle
  step; distances from the buoy; the data of the paper's Figs. 12-14).
The summary on stderr has Table 4's rows for both directions; --metrics writes them as one
line of JSON with the image, order and link-recovery counters, every parameter of the run
(\"params\") and its seed, so that many runs' files concatenate (scripts/sweep runs grids). In real time each end knows only its half:
frames it sent, and frames it received with their arrival times (no one-way delay: that needs
both clocks); the operator adds the round trip from each slot's frame to the ROV's answer.

Exit codes: 0 ok (also when Ctrl-C ends a real-time run), 1 the port failed during a real-time
run (outputs so far kept), 2 bad usage or input, 130/143/129 a simulation stopped by SIGINT,
SIGTERM or SIGHUP (at its next event: the summary and every output hold what was done, and
the metrics say \"interrupted\").";

/// Which end runs in real time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RoleArg {
    /// The TDMA master: sends the slots, plays the script and waypoints, receives images.
    Operator,
    /// The vehicle: answers each slot, drives the simulated vehicle, sends images.
    Rov,
}

impl RoleArg {
    /// The library's role.
    pub fn role(self) -> Role {
        match self {
            RoleArg::Operator => Role::Operator,
            RoleArg::Rov => Role::Rov,
        }
    }
}

/// The inter-packet gap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Ipg {
    /// Derived from the model.
    Auto,
    /// Given, ms.
    Millis(f64),
}

fn ipg(text: &str) -> Result<Ipg, String> {
    if text == "auto" {
        return Ok(Ipg::Auto);
    }
    value::millis(MIN_IPG_S * 1e3, MAX_IPG_S * 1e3)
        .0
        .parse(text)
        .map(Ipg::Millis)
        .map_err(|e| format!("{e} (or `auto`)"))
}

fn duration() -> RealParser {
    RealParser(Range {
        min: Bound::Excl(0.0),
        max: MAX_DURATION_S,
        unit: Unit::Seconds,
    })
}

fn roi(text: &str) -> Result<Roi, String> {
    let [x0, y0, x1, y1] = value::rect(1023).parse(text)?.map(|v| v as u16);
    Ok(Roi { x0, y0, x1, y1 })
}

/// Run a teleoperation session: operator (TDMA master) and ROV, over a link model in virtual
/// time (the default, --sim) or one end per process over a real port (--role).
///
/// Both ends speak the remote-control protocol of wire.md: joystick and high-level orders down,
/// status and DEBT-coded camera images up, one frame per slot, with heartbeats and the ROV's
/// recovery by backtracking. In simulation the same seed gives the same session.
#[derive(Parser, Debug)]
#[command(version, after_help = format!("{EXAMPLES}\n\n{}", rovlink_link::device::HELP))]
pub struct Args {
    /// Both ends and the link in one process, in virtual time (the default).
    #[arg(long, conflicts_with_all = ["role", "port"])]
    pub sim: bool,

    /// Run one end in real time over --port.
    #[arg(long, value_enum, requires = "port", help_heading = "Real time")]
    pub role: Option<RoleArg>,

    /// The modem: a device (see Devices below): a serial port or pseudo-terminal path,
    /// serial:PATH:BAUD, tcp:HOST:PORT, tcpin:HOST:PORT, udp:BIND=PEER, udpin:HOST:PORT or
    /// udpout:HOST:PORT.
    #[arg(long, value_name = "DEV", requires = "role", help_heading = "Real time",
          value_parser = value::device)]
    pub port: Option<String>,

    /// A network (docs/tdma-network.md): a scenario file whose nodes, media and routes are
    /// used (the rest ignored), the same file for every process. --address is then this
    /// node's own address (a ROV's; default 1), --port its first medium's modem.
    #[arg(
        long,
        value_name = "FILE",
        requires = "role",
        help_heading = "Real time"
    )]
    pub routes: Option<PathBuf>,

    /// With --routes: the modem of the node's second medium (a relay between two media), a
    /// device as --port.
    #[arg(long, value_name = "DEV", requires = "routes", help_heading = "Real time",
          value_parser = value::device)]
    pub port2: Option<String>,

    /// The port's dialect and pacing (with `--role`).
    #[command(flatten)]
    pub port_args: PortArgs,

    /// The link model (a built-in, a file, or flags).
    #[command(flatten)]
    pub model: ModelArgs,

    /// Inter-packet gap, 1 ms ..= 10 min, or `auto` (air times + 2 x delays + 3 jitter sigmas).
    #[arg(long, value_name = "MS|auto", default_value = "auto", value_parser = ipg)]
    pub ipg: Ipg,

    /// Run a simulation (--sim or --scenario) at X times real time (1 = real time), to watch
    /// it live, e.g. in Foxglove with --foxglove; the results are the same as unpaced.
    #[arg(long, value_name = "X", conflicts_with = "role",
          value_parser = value::real(rovlink_rcp::driver::MIN_PACE, rovlink_rcp::driver::MAX_PACE, "x"))]
    pub pace: Option<f64>,

    /// Session length, s (at most a week) [default: 600, or the scenario's].
    #[arg(long, value_name = "S", value_parser = duration())]
    pub duration: Option<f64>,

    /// Seed of the link's random streams [default: 1, or the scenario's].
    #[arg(long, value_parser = value::count(0, u64::MAX))]
    pub seed: Option<u64>,

    /// A multi-vehicle session in virtual time: nodes, media, routes and waypoints from this
    /// JSON file (docs/tdma-network.md); --duration and --seed override the file's.
    #[arg(long, value_name = "FILE", help_heading = "Network",
          conflicts_with_all = ["sim", "role", "port", "script", "waypoints", "buoy", "start",
                                "ipg", "image_size", "trunk", "fec", "roi", "orders", "camera",
                                "camera_cmd", "preview", "vehicle"])]
    pub scenario: Option<PathBuf>,

    /// The operator modem's position, NED m (each within 100 km): its distance to the ROV
    /// drives the range model.
    #[arg(long, value_name = "X,Y,Z", default_value = "0,0,0", allow_hyphen_values = true,
          value_parser = value::point3())]
    pub buoy: [f64; 3],

    /// The ROV's initial position, NED m (each within 100 km).
    #[arg(long, value_name = "X,Y,Z", default_value = "1,0,0", allow_hyphen_values = true,
          value_parser = value::point3())]
    pub start: [f64; 3],

    /// Joystick script, CSV t_s,vx,vy,vz,vyaw [default: a built-in 10-minute script].
    #[arg(long, value_name = "FILE")]
    pub script: Option<PathBuf>,

    /// GoTo orders, CSV t_s,x_m,y_m,z_m,heading_deg [default: the built-in script's].
    #[arg(long, value_name = "FILE")]
    pub waypoints: Option<PathBuf>,

    /// Encoded image size, 16 ..= 65535 bytes (cut at 64 trunks).
    #[arg(long, value_name = "BYTES", default_value_t = 2000,
          value_parser = value::bytes(u64::from(MIN_IMAGE_BYTES), 65_535))]
    pub image_size: u64,

    /// Trunk size, 1 ..= 242 bytes (39 makes the paper's 57-byte ROV frame).
    #[arg(long, value_name = "BYTES", default_value_t = 39,
          value_parser = value::bytes(1, rovlink_wire::rov::MAX_TRUNK_BYTES as u64))]
    pub trunk: u64,

    /// Spend PERCENT (1 ..= 50) of each image's trunks on Reed-Solomon parity, sent after its
    /// data trunks (progressive display unchanged): the operator completes an image once any
    /// data-trunk count of them arrived, and asks (RIT) only for what parity cannot recover.
    #[arg(long, value_name = "PERCENT",
          value_parser = value::count(1, u64::from(rovlink_debt::fec::MAX_PERCENT)))]
    pub fec: Option<u64>,

    /// Region of interest x0,y0,x1,y1 in pixels (each < 1024).
    #[arg(long, value_name = "X0,Y0,X1,Y1", value_parser = roi)]
    pub roi: Option<Roi>,

    /// Camera pictures: a directory of images or one image file, cycled [default: built-in].
    #[arg(long, value_name = "DIR|FILE")]
    pub images: Option<PathBuf>,

    /// Write the session's figures, every parameter and the seed as one line of JSON here
    /// (- for standard output).
    #[arg(long, value_name = "FILE")]
    pub metrics: Option<PathBuf>,

    /// Write one CSV row per frame here (-: standard output):
    /// direction,kind,bytes,t_sent_s,t_received_s,fate.
    #[arg(long, value_name = "FILE")]
    pub events: Option<PathBuf>,

    /// Write every completed image here as PNG (image-0001.png, ...).
    #[arg(long, value_name = "DIR")]
    pub images_out: Option<PathBuf>,

    /// Write the vehicle's track here, one CSV row per vehicle step (see below; - for
    /// standard output).
    #[arg(long, value_name = "FILE")]
    pub track: Option<PathBuf>,

    /// Write an MCAP session log here (Foxglove: pose, goal, velocities, link, images; - for
    /// standard output, not a terminal).
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,

    /// What moves the vehicle: `sim` (the built-in model), `ros2` (a vehicle whose own stack
    /// speaks ROS 2: Twist and goal pose out, Odometry in; real time, --role rov) or
    /// `mavlink:ENDPOINT`, an ArduSub
    /// autopilot (real time, --role rov) at a device (see Devices below): udpin:127.0.0.1:14550
    /// (listen; the first autopilot heard, its address and system id, is the only one listened
    /// to and answered), udpout:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT or
    /// serial:/dev/ttyACM0:115200. Aliases, as before: udp:HOST:PORT = udpin:HOST:PORT (here
    /// as for --port, udp: with = is BIND=PEER), tcpout:HOST:PORT = tcp:HOST:PORT.
    #[arg(long, value_name = "sim|ros2|mavlink:ENDPOINT", default_value = "sim",
          value_parser = vehicle, help_heading = "Field")]
    pub vehicle: Vehicle,

    /// With --vehicle mavlink:...: sign every MAVLink message sent to the autopilot with this
    /// MAVLink 2 signing key and use only messages signed with it (unsigned, badly signed and
    /// replayed ones are refused, counted in --metrics as mavlink_refused, said once per
    /// source). FILE holds 64 hex digits and an optional newline, or exactly 32 raw bytes,
    /// mode 0600, e.g. made with `head -c 32 /dev/urandom | xxd -p -c 64 > key; chmod 600
    /// key` and loaded into ArduSub with scripts/mavlink-setup-signing.py (see
    /// docs/tdma-mavlink.md). Without it MAVLink is unsigned (said once on stderr).
    #[arg(long, value_name = "FILE", help_heading = "Field")]
    pub mavlink_key_file: Option<PathBuf>,

    /// Camera: the newest image file in DIR at each capture; or ros2:TOPIC, the newest frame
    /// of a ROS 2 image topic (sensor_msgs/msg/Image rgb8, bgr8, rgba8, bgra8 or mono8; a
    /// topic ending in /compressed: sensor_msgs/msg/CompressedImage, JPEG or PNG), e.g.
    /// --camera ros2:/camera/image_raw/compressed (domain: --ros2-domain).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["images", "camera_cmd"],
          help_heading = "Field")]
    pub camera: Option<PathBuf>,

    /// Camera: run CMD (with sh -c) at each capture and read one image from its standard
    /// output, e.g. "ffmpeg -f v4l2 -i /dev/video0 -frames:v 1 -f image2pipe -c:v png -".
    #[arg(
        long,
        value_name = "CMD",
        conflicts_with = "images",
        help_heading = "Field"
    )]
    pub camera_cmd: Option<String>,

    /// Live orders: JSON Lines, each an order in wire.md's JSON form or {"type":"cancel"},
    /// read as they come (a pipe or FIFO; - for standard input), each sent at the next free
    /// slot. In simulation a line's "t_s" says when. Without --script/--waypoints the
    /// built-in script is then not played. A file or FIFO another user owns or group or
    /// others may write is refused (make it with mkfifo -m 600 orders).
    #[arg(long, value_name = "FILE|-", help_heading = "Field")]
    pub orders: Option<PathBuf>,

    /// Write JSON Lines as things happen (- for standard output): each status received,
    /// orders sent/acknowledged/cancelled, image progress, link lost/recovered.
    #[arg(long, value_name = "FILE|-", help_heading = "Field")]
    pub telemetry: Option<PathBuf>,

    /// With --images-out: write the image in progress as its trunks arrive, so it sharpens.
    #[arg(long, requires = "images_out", help_heading = "Field")]
    pub preview: bool,

    /// Serve a live Foxglove WebSocket view here (HOST:PORT; binds only there), e.g.
    /// --foxglove 127.0.0.1:8765: the --mcap channels live, and on a single session's operator
    /// end client channels /orders (JSON orders) and Twist (Teleop panel) for clients holding
    /// the token of --foxglove-token-file (view-only without it). With --scenario or --routes,
    /// every vehicle under /vehicle/N/ (view only). The port carries at most 256 connections,
    /// 8 from one address (in handshake or open), each upgrade request whole within 5 s of
    /// connecting; one more, or one slower, is closed and said once per address.
    #[arg(long, value_name = "HOST:PORT", help_heading = "Field")]
    pub foxglove: Option<String>,

    /// Authenticate every frame, both ways, with the keys in FILE (docs/threat-model.md):
    /// frames with a bad tag, replayed or plain are refused (they move nothing and are no
    /// heartbeat) and counted in --metrics. Lines `ADDRESS KEY` (32 or 64 hex digits; `*` is
    /// every vehicle, `broadcast` address 15); the file must be yours and private (chmod 600).
    /// Every end needs it; make one with `rcp-pack --new-key FILE`. Each frame is 6 bytes
    /// longer, and the automatic IPG counts them.
    #[arg(long, value_name = "FILE", help_heading = "Security")]
    pub key_file: Option<PathBuf>,

    /// With --key-file: also encrypt every message (AES-CTR, no extra bytes), so images and
    /// positions cannot be read on the medium.
    #[arg(long, requires = "key_file", help_heading = "Security")]
    pub encrypt: bool,

    /// With --key-file in real time: this node's frame counters (what it sent, the highest it
    /// accepted: a frame at or below is a replay, in this session or a later one), default
    /// FILE.nodeN.counters beside the key file. Keep it with the key; one per node.
    #[arg(
        long,
        value_name = "FILE",
        requires = "key_file",
        help_heading = "Security"
    )]
    pub key_state: Option<PathBuf>,

    /// With --foxglove: the file holding the control token (one line of 16 to 256 of
    /// A-Z a-z 0-9 - . _ ~; yours, mode 0600). A client whose URL carries it
    /// (ws://127.0.0.1:8765/?token=TOKEN) may send orders; the others only view. Without it
    /// the live view is view-only. E.g. --foxglove-token-file ~/.config/rovlink/foxglove.token
    /// (make one with --new-foxglove-token).
    #[arg(long, value_name = "FILE", requires = "foxglove", help_heading = "Field",
          conflicts_with_all = ["scenario", "routes"])]
    pub foxglove_token_file: Option<PathBuf>,

    /// With --foxglove: also let browser pages from this Origin connect (exactly as the
    /// browser sends it; repeatable), e.g. --foxglove-origin https://viewer.example:8443.
    /// Allowed already: https://studio.foxglove.dev, https://app.foxglove.dev, file://
    /// (Foxglove Studio desktop) and pages on localhost, 127.0.0.1 and [::1]; a client that
    /// sends no Origin (not a browser) always may.
    #[arg(long, value_name = "ORIGIN", requires = "foxglove", help_heading = "Field",
          value_parser = origin)]
    pub foxglove_origin: Vec<String>,

    /// With --foxglove-token-file on an address other than loopback: serve control over plain
    /// ws:// anyway (the token and the orders travel in clear; better: bind 127.0.0.1 and use
    /// an SSH tunnel), e.g. --foxglove 192.168.1.5:8765 --foxglove-token-file t
    /// --foxglove-insecure.
    #[arg(long, requires = "foxglove_token_file", help_heading = "Field")]
    pub foxglove_insecure: bool,

    /// With --foxglove: serve wss:// with this certificate (PEM, the server's first, then its
    /// chain) and --foxglove-tls-key, e.g. --foxglove-tls-cert /etc/rovlink/view.crt
    /// --foxglove-tls-key /etc/rovlink/view.key. Clients then open wss://HOST:PORT/.
    #[arg(long, value_name = "FILE", requires_all = ["foxglove", "foxglove_tls_key"],
          help_heading = "Field")]
    pub foxglove_tls_cert: Option<PathBuf>,

    /// The private key of --foxglove-tls-cert (PEM; yours, mode 0600), e.g.
    /// --foxglove-tls-key /etc/rovlink/view.key.
    #[arg(
        long,
        value_name = "FILE",
        requires = "foxglove_tls_cert",
        help_heading = "Field"
    )]
    pub foxglove_tls_key: Option<PathBuf>,

    /// Publish the session on a ROS 2 graph (the operator end, or a simulation): the pose
    /// (/rov/pose and /tf), goal, actual and commanded velocities, completed images
    /// (/rov/image/compressed, PNG), a status with the link figures once a second
    /// (/rov/status) and the session's log (/rosout). View-only: orders need --ros2-control.
    #[arg(long, help_heading = "Field")]
    pub ros2: bool,

    /// With --ros2, --camera ros2:TOPIC or --vehicle ros2: the DDS domain [default:
    /// ROS_DOMAIN_ID, else 0].
    #[arg(long, value_name = "ID", help_heading = "Field",
          value_parser = value::count(0, rovlink_ros2::names::MAX_DOMAIN_ID as u64))]
    pub ros2_domain: Option<u64>,

    /// With --ros2 or --vehicle ros2: the namespace of the session's or the vehicle's topics
    /// (the vehicle's: NS/cmd_vel, NS/goal_pose and NS/arm out, NS/odom in).
    #[arg(
        long,
        value_name = "NS",
        default_value = "/rov",
        help_heading = "Field"
    )]
    pub ros2_namespace: String,

    /// With --ros2: also take orders from the graph: geometry_msgs/msg/Twist on NS/cmd_vel
    /// (the joystick) and geometry_msgs/msg/PoseStamped on NS/goal_pose (a GoTo, frame ned).
    /// Plain DDS authenticates nobody: any node on the domain can then drive the vehicle.
    #[arg(long, requires = "ros2", help_heading = "Field")]
    pub ros2_control: bool,

    /// Write a new control token for --foxglove-token-file (64 random hex characters) to FILE,
    /// mode 0600 (an existing file is never replaced), and exit, e.g.
    /// tdma-run --new-foxglove-token ~/.config/rovlink/foxglove.token
    #[arg(long, value_name = "FILE", help_heading = "Field", exclusive = true)]
    pub new_foxglove_token: Option<PathBuf>,

    /// True when `--address` is on the command line, not its default ([`Args::from_command_line`]
    /// reads it): with `--routes` the flag is the node's own address, and its default, 2, is
    /// the EvoLogics destination's, not a node's.
    #[arg(skip)]
    pub address_given: bool,
}

/// What moves the vehicle.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Vehicle {
    /// The built-in kinematic model.
    Sim,
    /// An autopilot over MAVLink at this endpoint.
    Mavlink(String),
    /// A vehicle whose own stack speaks ROS 2 (docs/ros2.md).
    Ros2,
}

fn vehicle(text: &str) -> Result<Vehicle, String> {
    match text.split_once(':') {
        _ if text == "sim" => Ok(Vehicle::Sim),
        _ if text == "ros2" => Ok(Vehicle::Ros2),
        Some(("mavlink", endpoint)) if !endpoint.is_empty() => {
            rovlink_field::mavlink::parse_endpoint(endpoint).map_err(|e| e.to_string())?;
            Ok(Vehicle::Mavlink(endpoint.to_string()))
        }
        _ => Err(format!(
            "expected sim, ros2 or mavlink:ENDPOINT (e.g. mavlink:udpin:127.0.0.1:14550), found {text:?}"
        )),
    }
}

impl Args {
    /// The process's command line, parsed as every tool's is (`rovlink_cli::parse`: a bad one
    /// is said and exits), with [`Args::address_given`].
    pub fn from_command_line() -> Args {
        let (mut args, matches) = rovlink_cli::parse_with_matches::<Args>(crate::TOOL);
        args.address_given =
            matches.value_source("address") == Some(clap::parser::ValueSource::CommandLine);
        args
    }

    /// The input files, for the outputs' same-file check.
    pub fn inputs(&self) -> impl Iterator<Item = &std::path::Path> {
        [
            &self.script,
            &self.waypoints,
            &self.images,
            &self.orders,
            &self.model.model_file,
            &self.scenario,
            &self.routes,
            &self.mavlink_key_file,
        ]
        .into_iter()
        .flatten()
        .map(PathBuf::as_path)
    }

    /// The session length, s: given, or 600.
    pub fn duration_s(&self) -> f64 {
        self.duration.unwrap_or(600.0)
    }

    /// The seed: given, or 1.
    pub fn seed(&self) -> u64 {
        self.seed.unwrap_or(1)
    }

    /// The image settings the flags give (the parsers bound each to its type).
    pub fn settings(&self) -> ImageSettings {
        ImageSettings {
            roi: self.roi,
            size_bytes: u16::try_from(self.image_size).unwrap_or(u16::MAX),
            trunk_bytes: u8::try_from(self.trunk).unwrap_or(u8::MAX),
            fec_percent: self.fec.map_or(0, |p| p as u8),
            ..ImageSettings::default()
        }
    }

    /// The IPG, s: given, or derived from `model` and `settings`.
    pub fn ipg_s(&self, model: &Model, settings: &ImageSettings) -> f64 {
        match self.ipg {
            Ipg::Millis(ms) => ms / 1e3,
            Ipg::Auto => auto_ipg_for(
                model,
                settings,
                self.start,
                self.buoy,
                if self.key_file.is_some() {
                    rovlink_rcp::secure::OVERHEAD_BYTES
                } else {
                    0
                },
            ),
        }
    }
}

/// An `Origin` for --foxglove-origin: not empty, printable ASCII without spaces or commas.
fn origin(text: &str) -> Result<String, String> {
    if !text.is_empty() && text.bytes().all(|b| b.is_ascii_graphic() && b != b',') {
        Ok(text.to_string())
    } else {
        Err(format!(
            "expected an Origin such as https://viewer.example:8443, found {text:?}"
        ))
    }
}
