//! A live Foxglove view of octo-delta's occupancy map (`octo-delta view`): a WebSocket server
//! (the official `foxglove` SDK behind [`crate::foxglove_gate`], started and guarded as
//! [`crate::foxglove`] serves a session) bound only to the address it is given, on these
//! channels (JSON messages, JSON Schemas):
//!
//! | topic | schema | what |
//! |---|---|---|
//! | [`SCENE_TOPIC`] | `foxglove.SceneUpdate` (the schema [`start_map`] is given) | the map's changes ([`MapView::publish_scene`]) and, to a client that just subscribed, the whole map ([`MapView::send_snapshot`]) |
//! | [`POSE_TOPIC`] | `foxglove.PoseInFrame` | the vehicle in frame [`MAP_FRAME`]; a new subscriber gets the latest at once |
//! | [`LOG_TOPIC`] | `foxglove.Log` | the view's lines; a new subscriber gets the latest [`LOG_KEPT`] at once |
//! | [`REQUESTS_TOPIC`] | published by clients, encoding `json` | one JSON object a message, for the view to read ([`MapView::take_requests`]) |
//!
//! A SceneUpdate changes only the entities it names, so a client that subscribes late needs
//! the whole scene once: [`MapView::take_snapshot_wanted`] says when one subscribed, and
//! [`MapView::send_snapshot`] sends the whole scene to the clients that subscribed since the
//! last one, and to no other.
//!
//! Who may do what is the session view's rule (docs/tdma-foxglove.md, "Who may control"):
//! every connection comes through the gate, which refuses browsers from other sites and marks
//! each client it lets through for [`Access::View`] or, when its URL carries the control
//! token, [`Access::Control`]. The channels go only to marked clients; requests are taken only
//! from clients marked for control, on [`REQUESTS_TOPIC`] only, and only when the view was
//! started with a [`Policy::token`]. Every other client's advertisement is refused, once per
//! client in [`MapView::take_warnings`] and in a status to the client; a channel on another
//! topic or encoding is refused once per topic. Without a token the view is view-only. Control
//! over plain `ws://` on an address other than loopback is [`FoxgloveError::Exposed`] unless
//! [`Policy::insecure`]; with [`Policy::tls`] the gate serves `wss://`.
//!
//! The contract: nothing a client sends panics, blocks publishing, or grows memory without
//! bound. A request larger than [`MAX_PAYLOAD_BYTES`], or one that is not a JSON object, is
//! refused with a warning and a status to the client (the SDK disconnects a client that
//! floods it with such requests without reading the statuses); requests wait in a queue of
//! [`MAX_REQUESTS`] (the oldest dropped and counted past that), warnings in one of
//! [`crate::foxglove::MAX_WARNINGS`] (the rest counted). Publishing never blocks: nothing is
//! built or sent on a channel no client subscribes to, and the SDK queues at most
//! [`crate::foxglove::BACKLOG_MESSAGES`] messages per client, dropping the oldest for a slow
//! one. [`MapView::stop`] (or dropping it) closes the server, waiting at most
//! [`crate::foxglove::STOP_WAIT`] for the clients to be told.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};

use foxglove::websocket::{ChannelView, Client, ClientChannel, ClientId, ServerListener, Status};
use foxglove::{RawChannel, SinkId};

pub use crate::foxglove::{FoxgloveError, MAX_PAYLOAD_BYTES};
use crate::foxglove_gate::Reports;
pub use crate::foxglove_gate::{Access, Policy, Token};
use crate::foxglove_server::{
    NO_TOKEN_IN_URL, Server, Setup, Viewers, Warnings, channel_name, json_object, lock, say_count,
    send, shorten,
};
use crate::mcap_log::{Topic, log_json, pose_json, timestamp_json};

/// The map's changes and snapshots: `foxglove.SceneUpdate`.
pub const SCENE_TOPIC: &str = "/octo_delta/view";
/// The vehicle's pose: `foxglove.PoseInFrame` in [`MAP_FRAME`].
pub const POSE_TOPIC: &str = "/octo_delta/vehicle";
/// The view's lines: `foxglove.Log`.
pub const LOG_TOPIC: &str = "/octo_delta/log";
/// Where clients with control publish requests: one JSON object a message, encoding `json`.
pub const REQUESTS_TOPIC: &str = "/octo_delta/requests";
/// The schema name of [`SCENE_TOPIC`].
pub const SCENE_SCHEMA_NAME: &str = "foxglove.SceneUpdate";
/// The frame of the vehicle's pose.
pub const MAP_FRAME: &str = "map";
/// The most requests waiting for [`MapView::take_requests`].
pub const MAX_REQUESTS: usize = 64;
/// The log lines a new subscriber of [`LOG_TOPIC`] gets at once (the latest).
pub const LOG_KEPT: usize = 16;

/// A request a client published: one JSON object.
pub type Request = serde_json::Map<String, serde_json::Value>;

/// How much a log line matters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogLevel {
    /// Foxglove's INFO.
    Info,
    /// Foxglove's WARNING.
    Warning,
    /// Foxglove's ERROR.
    Error,
}

impl LogLevel {
    /// Its number in `foxglove.Log` (2 info, 3 warning, 4 error).
    pub fn foxglove(self) -> u8 {
        match self {
            LogLevel::Info => crate::mcap_log::INFO,
            LogLevel::Warning => crate::mcap_log::WARNING,
            LogLevel::Error => crate::mcap_log::ERROR,
        }
    }
}

/// Whether a client channel is the requests channel; `Err` says why not.
pub fn request_channel(topic: &str, encoding: &str) -> Result<(), String> {
    if topic != REQUESTS_TOPIC {
        return Err(format!(
            "expected topic {REQUESTS_TOPIC}, found {:?}",
            shorten(topic)
        ));
    }
    if encoding != "json" {
        return Err(format!(
            "expected encoding json, found {:?}",
            shorten(encoding)
        ));
    }
    Ok(())
}

/// The vehicle's latest pose.
#[derive(Debug, Clone, Copy)]
struct Pose {
    t_ns: u64,
    position_m: [f64; 3],
    orientation: [f64; 4],
}

/// A line of the view's log.
#[derive(Debug, Clone)]
struct LogLine {
    t_ns: u64,
    level: LogLevel,
    text: String,
}

/// What a new subscriber gets at once.
#[derive(Default)]
struct Kept {
    pose: Option<Pose>,
    /// The latest [`LOG_KEPT`] lines, oldest first.
    logs: VecDeque<LogLine>,
}

/// The clients that subscribed to the scene since the last snapshot.
#[derive(Default)]
struct Fresh {
    /// One subscribed since [`MapView::take_snapshot_wanted`] last said so.
    wanted: bool,
    clients: HashMap<ClientId, SinkId>,
}

/// What clients published, waiting for the view.
#[derive(Default)]
struct Inbox {
    requests: VecDeque<Request>,
    dropped: u64,
    warnings: Warnings,
}

impl Inbox {
    fn push(&mut self, request: Request) {
        if self.requests.len() >= MAX_REQUESTS {
            self.requests.pop_front();
            self.dropped += 1;
        }
        self.requests.push_back(request);
    }
}

/// What the view and the SDK's callbacks share.
struct Shared {
    /// The name on the view's log lines.
    name: String,
    viewers: Viewers,
    scene: Arc<RawChannel>,
    pose: Arc<RawChannel>,
    log: Arc<RawChannel>,
    kept: Mutex<Kept>,
    fresh: Mutex<Fresh>,
    inbox: Mutex<Inbox>,
}

impl Shared {
    fn pose_message(pose: &Pose) -> String {
        let timestamp = timestamp_json(pose.t_ns);
        pose_json(&timestamp, MAP_FRAME, pose.position_m, pose.orientation).to_string()
    }

    fn log_message(&self, line: &LogLine) -> String {
        let timestamp = timestamp_json(line.t_ns);
        log_json(&timestamp, line.level.foxglove(), &self.name, &line.text).to_string()
    }
}

/// The SDK's callbacks.
struct Listener {
    shared: Arc<Shared>,
    /// Whether clients marked for control may publish requests (the view has a token).
    control: bool,
}

impl Listener {
    /// Why `client`'s publishing is refused, if it is.
    fn refusal(&self, client: &Client) -> Option<&'static str> {
        match (self.control, self.shared.viewers.access(client)) {
            (true, Some(Access::Control)) => None,
            (true, _) => Some(NO_TOKEN_IN_URL),
            (false, _) => Some(
                "publishing refused: the map view is view-only (started without a control token)",
            ),
        }
    }
}

impl ServerListener for Listener {
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        let shared = &self.shared;
        let Some(sink) = shared.viewers.sink(&client) else {
            return;
        };
        let id = channel.id();
        if id == shared.scene.id() {
            let mut fresh = lock(&shared.fresh);
            fresh.clients.insert(client.id(), sink);
            fresh.wanted = true;
        } else if id == shared.pose.id() {
            let pose = lock(&shared.kept).pose;
            if let Some(pose) = pose {
                let json = Shared::pose_message(&pose);
                send(&shared.pose, json.as_bytes(), pose.t_ns, Some(sink));
            }
        } else if id == shared.log.id() {
            let lines: Vec<LogLine> = lock(&shared.kept).logs.iter().cloned().collect();
            for line in lines {
                let json = shared.log_message(&line);
                send(&shared.log, json.as_bytes(), line.t_ns, Some(sink));
            }
        }
    }

    fn on_unsubscribe(&self, client: Client, channel: ChannelView) {
        if channel.id() == self.shared.scene.id() {
            lock(&self.shared.fresh).clients.remove(&client.id());
        }
    }

    fn on_client_advertise(&self, client: Client, channel: &ClientChannel) {
        if self.shared.viewers.advertised(&client, channel) {
            return;
        }
        let mut inbox = lock(&self.shared.inbox);
        if let Some(why) = self.refusal(&client) {
            // Only a client that offers requests is told (a status Studio lists as a Problem):
            // the topics Studio's 3D panel advertises by itself are refused silently.
            let offers_requests = channel.topic == REQUESTS_TOPIC;
            inbox.warnings.refuse_client(&client, why, offers_requests);
        } else if let Err(why) = request_channel(&channel.topic, &channel.encoding) {
            let warning = format!(
                "{}: refused: {why} (said once per topic)",
                channel_name(&client, channel)
            );
            inbox.warnings.warn_topic(&channel.topic, warning);
        }
    }

    fn on_client_unadvertise(&self, client: Client, channel: &ClientChannel) {
        self.shared.viewers.unadvertised(&client, channel);
    }

    fn on_message_data(&self, client: Client, channel: &ClientChannel, payload: &[u8]) {
        // A refused channel or client was reported when it advertised; its messages are
        // ignored.
        if self.refusal(&client).is_some()
            || request_channel(&channel.topic, &channel.encoding).is_err()
        {
            return;
        }
        match json_object(payload) {
            Ok(request) => lock(&self.shared.inbox).push(request),
            Err(why) => {
                let warning = format!("{}: request skipped: {why}", channel_name(&client, channel));
                lock(&self.shared.inbox).warnings.warn(warning);
                client.send_status(Status::warning(format!("request refused: {why}")));
            }
        }
    }
}

/// The live map view: the server and its channels (see the module doc).
pub struct MapView {
    /// The gate and the SDK's server behind it (closed when the view is dropped).
    server: Server,
    shared: Arc<Shared>,
}

/// Starts the server named `name`, bound to `addr` only (HOST:PORT; port 0 picks a free one,
/// see [`MapView::port`]); [`SCENE_TOPIC`]'s JSON Schema is `scene_schema_json`
/// (`foxglove.SceneUpdate`'s). A bad address, or one that cannot be listened on (a port in
/// use), is an `Err` naming it. `policy` says who may connect and who may publish requests
/// (see the module doc); control on an address other than loopback without
/// [`Policy::insecure`] or [`Policy::tls`] is [`FoxgloveError::Exposed`]. Must not be called
/// from inside an async runtime.
pub fn start_map(
    addr: &str,
    name: &str,
    policy: &Policy,
    scene_schema_json: &str,
) -> Result<MapView, FoxgloveError> {
    let setup = Setup::new(addr)?;
    let scene = setup.channel(
        SCENE_TOPIC,
        SCENE_SCHEMA_NAME,
        scene_schema_json.as_bytes().to_vec(),
    )?;
    let pose = setup.channel(
        POSE_TOPIC,
        Topic::Pose.schema_name(),
        Topic::Pose.schema().as_bytes(),
    )?;
    let log = setup.channel(
        LOG_TOPIC,
        Topic::Log.schema_name(),
        Topic::Log.schema().as_bytes(),
    )?;
    let shared = Arc::new(Shared {
        name: name.to_string(),
        viewers: Viewers::new(setup.secret.clone()),
        scene,
        pose,
        log,
        kept: Mutex::default(),
        fresh: Mutex::default(),
        inbox: Mutex::default(),
    });
    let control = policy.token.is_some();
    let listener = Arc::new(Listener {
        shared: shared.clone(),
        control,
    });
    let server = setup.serve(name, policy, control, listener)?;
    Ok(MapView { server, shared })
}

impl MapView {
    /// Whether some client subscribes to [`SCENE_TOPIC`] (nothing need be built otherwise).
    pub fn scene_subscribed(&self) -> bool {
        self.shared.scene.has_sinks()
    }

    /// Sends a SceneUpdate (`scene_update_json`, JSON text), logged at `t_ns`, to every
    /// client subscribed to [`SCENE_TOPIC`].
    pub fn publish_scene(&self, t_ns: u64, scene_update_json: &[u8]) {
        let shared = &self.shared;
        if shared.scene.has_sinks() {
            shared.viewers.log(&shared.scene, scene_update_json, t_ns);
        }
    }

    /// True once after one or more clients subscribed to [`SCENE_TOPIC`] (SceneUpdates change
    /// only what they name: a client that just subscribed needs the whole scene, from
    /// [`MapView::send_snapshot`]); false until another subscribes.
    pub fn take_snapshot_wanted(&self) -> bool {
        std::mem::take(&mut lock(&self.shared.fresh).wanted)
    }

    /// Sends a SceneUpdate of the whole scene (`scene_update_json`), logged at `t_ns`, to the
    /// clients that subscribed to [`SCENE_TOPIC`] since the last snapshot and are still
    /// subscribed, and to no other.
    pub fn send_snapshot(&self, t_ns: u64, scene_update_json: &[u8]) {
        let shared = &self.shared;
        let sinks: Vec<SinkId> = lock(&shared.fresh)
            .clients
            .drain()
            .map(|(_, s)| s)
            .collect();
        for sink in sinks {
            send(&shared.scene, scene_update_json, t_ns, Some(sink));
        }
    }

    /// The vehicle at `position_m` (x, y, z in [`MAP_FRAME`]) turned by the quaternion
    /// `orientation_xyzw`, at `t_ns`: sent to [`POSE_TOPIC`]'s subscribers, and kept for the
    /// next.
    pub fn publish_pose(&self, t_ns: u64, position_m: [f64; 3], orientation_xyzw: [f64; 4]) {
        let pose = Pose {
            t_ns,
            position_m,
            orientation: orientation_xyzw,
        };
        lock(&self.shared.kept).pose = Some(pose);
        let shared = &self.shared;
        if shared.pose.has_sinks() {
            let json = Shared::pose_message(&pose);
            shared.viewers.log(&shared.pose, json.as_bytes(), t_ns);
        }
    }

    /// A line `text` of `level` on [`LOG_TOPIC`] at `t_ns`: sent to its subscribers, and kept
    /// (the latest [`LOG_KEPT`]) for the next.
    pub fn log(&self, t_ns: u64, level: LogLevel, text: &str) {
        let line = LogLine {
            t_ns,
            level,
            text: text.to_string(),
        };
        let shared = &self.shared;
        if shared.log.has_sinks() {
            let json = shared.log_message(&line);
            shared.viewers.log(&shared.log, json.as_bytes(), t_ns);
        }
        let mut kept = lock(&shared.kept);
        if kept.logs.len() >= LOG_KEPT {
            kept.logs.pop_front();
        }
        kept.logs.push_back(line);
    }

    /// The requests clients with control published on [`REQUESTS_TOPIC`] since the last call,
    /// oldest first.
    pub fn take_requests(&self) -> Vec<Request> {
        lock(&self.shared.inbox).requests.drain(..).collect()
    }

    /// What was refused or dropped since the last call, one line each, each said once: the
    /// handshakes the gate refused, the clients and channels whose publishing was refused,
    /// the requests skipped, and how many requests and warnings did not fit.
    pub fn take_warnings(&self) -> Vec<String> {
        let mut inbox = lock(&self.shared.inbox);
        let mut warnings = inbox.warnings.take();
        warnings.extend(self.server.reports().iter().flat_map(Reports::take));
        say_count(&mut warnings, &mut inbox.dropped, |n| {
            format!("foxglove: {n} requests dropped: more than {MAX_REQUESTS} waiting")
        });
        warnings
    }

    /// The port the server listens on (the gate's).
    pub fn port(&self) -> u16 {
        self.server.port()
    }

    /// The address it was started on, as given.
    pub fn addr(&self) -> &str {
        self.server.addr()
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.server.clients()
    }

    /// The URL scheme clients use: `wss` with TLS, else `ws`.
    pub fn scheme(&self) -> &'static str {
        self.server.scheme()
    }

    /// Whether it listens on an address other than loopback.
    pub fn exposed(&self) -> bool {
        self.server.exposed()
    }

    /// Closes the server: the clients are told, for at most
    /// [`crate::foxglove::STOP_WAIT`].
    pub fn stop(mut self) {
        self.server.shut_down();
    }
}

#[cfg(test)]
mod tests {
    //! The server against the stock client (`@foxglove/ws-protocol` 0.8.0 run by Node:
    //! tests/foxglove/map_client.mjs, its packages installed by `npm ci --prefix
    //! tests/foxglove`); a test that needs it and cannot start it says so and passes.

    use super::*;
    use std::io::BufRead;
    use std::process::{Child, Command, Stdio};
    use std::sync::mpsc::{Receiver, RecvTimeoutError};
    use std::time::{Duration, Instant};

    use serde_json::{Value, json};

    const CLIENT: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/foxglove/map_client.mjs"
    );
    const PACKAGES: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/foxglove/node_modules/@foxglove/ws-protocol"
    );
    /// The control token of the views these tests start with one.
    const TOKEN: &str = "map-test-token-0123456789abcdef";
    /// A SceneUpdate schema, as the view would give it.
    const SCHEMA: &str = r#"{"title":"foxglove.SceneUpdate","type":"object"}"#;
    /// The longest any sign is waited for.
    const PATIENCE: Duration = Duration::from_secs(20);

    /// Whether Node and the stock client's packages are here (said when not).
    fn node_here() -> bool {
        let node = Command::new("node")
            .arg("--version")
            .stdout(Stdio::null())
            .status();
        let here = node.is_ok_and(|s| s.success()) && std::path::Path::new(PACKAGES).is_dir();
        if !here {
            println!(
                "skipped: node or {PACKAGES} is missing (apt-get install nodejs npm; \
                 npm ci --prefix tests/foxglove)"
            );
        }
        here
    }

    fn with_token() -> Policy {
        Policy {
            token: Some(Token::parse(TOKEN.as_bytes()).unwrap()),
            ..Policy::default()
        }
    }

    fn url(view: &MapView, token: bool) -> String {
        let query = if token {
            format!("?token={TOKEN}")
        } else {
            String::new()
        };
        format!("ws://127.0.0.1:{}/{query}", view.port())
    }

    /// map_client.mjs running, its lines read aside; killed when dropped.
    struct MapClient {
        child: Child,
        lines: Receiver<Value>,
        seen: Vec<Value>,
    }

    impl MapClient {
        fn start(url: &str, args: &[&str]) -> MapClient {
            let mut child = Command::new("node")
                .arg(CLIENT)
                .arg(url)
                .args(args)
                .stdin(Stdio::null())
                .stdout(Stdio::piped())
                .spawn()
                .expect("node runs tests/foxglove/map_client.mjs");
            let stdout = std::io::BufReader::new(child.stdout.take().unwrap());
            let (tx, lines) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                for line in stdout.lines().map_while(Result::ok) {
                    let value = serde_json::from_str(&line)
                        .unwrap_or_else(|e| panic!("map_client said {line:?}: {e}"));
                    if tx.send(value).is_err() {
                        break;
                    }
                }
            });
            MapClient {
                child,
                lines,
                seen: Vec::new(),
            }
        }

        /// The first line (of all it said) that `wanted` says yes to, waiting for it at most
        /// [`PATIENCE`].
        fn line(&mut self, what: &str, wanted: impl Fn(&Value) -> bool) -> Value {
            let deadline = Instant::now() + PATIENCE;
            loop {
                if let Some(found) = self.seen.iter().find(|v| wanted(v)) {
                    return found.clone();
                }
                let left = deadline.saturating_duration_since(Instant::now());
                match self.lines.recv_timeout(left) {
                    Ok(value) => self.seen.push(value),
                    Err(RecvTimeoutError::Timeout) => {
                        panic!("no {what} within {PATIENCE:?}; said: {:?}", self.seen)
                    }
                    Err(RecvTimeoutError::Disconnected) => {
                        panic!("map_client ended without {what}; said: {:?}", self.seen)
                    }
                }
            }
        }

        /// Its message on `topic` logged at `t_ns`.
        fn message(&mut self, topic: &str, t_ns: u64) -> Value {
            self.line(&format!("{topic} at {t_ns}"), |v| {
                v["topic"] == topic && v["t_ns"] == t_ns
            })
        }

        /// Waits for it to end by itself (at most [`PATIENCE`]), successfully.
        fn finish(mut self) {
            let deadline = Instant::now() + PATIENCE;
            let status = loop {
                if let Some(status) = self.child.try_wait().unwrap() {
                    break status;
                }
                assert!(Instant::now() < deadline, "map_client still running");
                std::thread::sleep(Duration::from_millis(10));
            };
            assert!(status.success(), "map_client: {status}");
        }
    }

    impl Drop for MapClient {
        fn drop(&mut self) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }

    /// Waits (at most [`PATIENCE`]) for `sign` to give something.
    fn wait_for<T>(what: &str, mut sign: impl FnMut() -> Option<T>) -> T {
        let deadline = Instant::now() + PATIENCE;
        loop {
            if let Some(found) = sign() {
                return found;
            }
            assert!(Instant::now() < deadline, "no {what} within {PATIENCE:?}");
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Checks that `client`'s publishing was refused, and it was told so in a status that
    /// says `why`; that once the server has handled what it published (it subscribes to the
    /// scene after publishing, and the server handles a client's messages in order), no
    /// request came of it. The warnings.
    fn refused(view: &MapView, client: &mut MapClient, why: &str) -> Vec<String> {
        let status = client.line("a status", |v| v["status"].is_string());
        assert!(status["status"].as_str().unwrap().contains(why), "{status}");
        wait_for("scene subscription", || {
            view.take_snapshot_wanted().then_some(())
        });
        assert!(view.take_requests().is_empty());
        view.take_warnings()
    }

    /// A SceneUpdate of `entities` cubes each, deleting `deletions` entities.
    fn scene(entities: &[usize], deletions: usize) -> Vec<u8> {
        let entities: Vec<Value> = (entities.iter().enumerate())
            .map(|(k, &cubes)| {
                let cube = json!({"pose": {}, "size": {"x": 1, "y": 1, "z": 1}});
                json!({"id": format!("e{k}"), "frame_id": MAP_FRAME, "cubes": vec![cube; cubes]})
            })
            .collect();
        let deletions: Vec<Value> = (0..deletions)
            .map(|k| json!({"type": 0, "id": format!("gone{k}")}))
            .collect();
        json!({"deletions": deletions, "entities": entities})
            .to_string()
            .into_bytes()
    }

    #[test]
    fn a_new_subscriber_gets_the_whole_scene_then_the_changes_and_the_latest_pose_and_logs() {
        if !node_here() {
            return;
        }
        let view = start_map("127.0.0.1:0", "map test", &Policy::default(), SCHEMA).unwrap();
        view.publish_pose(5, [1.0, 2.0, -3.0], [0.0, 0.0, 0.0, 1.0]);
        for k in 0..LOG_KEPT + 2 {
            view.log(10 + k as u64, LogLevel::Info, &format!("line {k}"));
        }
        view.publish_scene(1000, &scene(&[1], 0));
        assert!(!view.take_snapshot_wanted(), "nobody subscribed yet");
        assert!(!view.scene_subscribed());
        let mut client = MapClient::start(&url(&view, false), &[]);
        wait_for("scene subscription", || {
            view.take_snapshot_wanted().then_some(())
        });
        assert!(!view.take_snapshot_wanted(), "said once");
        assert!(view.scene_subscribed());
        assert_eq!(view.clients(), 1);

        view.send_snapshot(30, &scene(&[2, 3], 0));
        let snapshot = client.message(SCENE_TOPIC, 30);
        assert_eq!(
            (
                &snapshot["entities"],
                &snapshot["cubes"],
                &snapshot["deletions"]
            ),
            (&json!(2), &json!(5), &json!(0)),
            "{snapshot}"
        );
        view.publish_scene(31, &scene(&[1], 2));
        let change = client.message(SCENE_TOPIC, 31);
        assert_eq!(
            (&change["entities"], &change["deletions"]),
            (&json!(1), &json!(2))
        );

        let pose = client.message(POSE_TOPIC, 5);
        assert_eq!(pose["frame_id"], MAP_FRAME);
        // JavaScript writes 1.0 as 1.
        assert_eq!(pose["position"], json!([1, 2, -3]));
        assert_eq!(pose["orientation"], json!([0, 0, 0, 1]));
        view.publish_pose(40, [4.0, 5.0, 6.0], [0.0, 0.0, 1.0, 0.0]);
        assert_eq!(client.message(POSE_TOPIC, 40)["position"], json!([4, 5, 6]));

        // The latest LOG_KEPT lines came at once, in order; the two before them did not.
        let newest = client.message(LOG_TOPIC, 10 + LOG_KEPT as u64 + 1);
        assert_eq!(newest["message"], format!("line {}", LOG_KEPT + 1));
        assert_eq!(newest["level"], 2);
        let logs: Vec<&Value> = (client.seen.iter())
            .filter(|v| v["topic"] == LOG_TOPIC)
            .map(|v| &v["message"])
            .collect();
        let expected: Vec<Value> = (2..LOG_KEPT + 2)
            .map(|k| json!(format!("line {k}")))
            .collect();
        assert_eq!(logs, expected.iter().collect::<Vec<_>>());
        view.log(50, LogLevel::Error, "broken");
        let error = client.message(LOG_TOPIC, 50);
        assert_eq!(
            (&error["message"], &error["level"]),
            (&json!("broken"), &json!(4))
        );

        // The scene published before the client came is not among what it got.
        let early = |v: &Value| v["topic"] == SCENE_TOPIC && v["t_ns"] == 1000;
        assert!(!client.seen.iter().any(early), "{:?}", client.seen);
        assert!(view.take_requests().is_empty());
        assert!(view.take_warnings().is_empty());
        view.stop();
    }

    #[test]
    fn a_snapshot_goes_only_to_the_clients_that_just_subscribed() {
        if !node_here() {
            return;
        }
        let view = start_map("127.0.0.1:0", "map test", &Policy::default(), SCHEMA).unwrap();
        let mut first = MapClient::start(&url(&view, false), &[]);
        wait_for("first subscription", || {
            view.take_snapshot_wanted().then_some(())
        });
        view.send_snapshot(1, &scene(&[1], 0));
        first.message(SCENE_TOPIC, 1);
        let mut second = MapClient::start(&url(&view, false), &[]);
        wait_for("second subscription", || {
            view.take_snapshot_wanted().then_some(())
        });
        view.send_snapshot(2, &scene(&[1, 1], 0));
        // A change after the snapshot reaches both; the first saw no second snapshot before it.
        view.publish_scene(3, &scene(&[], 1));
        assert_eq!(second.message(SCENE_TOPIC, 2)["entities"], 2);
        second.message(SCENE_TOPIC, 3);
        first.message(SCENE_TOPIC, 3);
        let second_snapshot = |v: &Value| v["topic"] == SCENE_TOPIC && v["t_ns"] == 2;
        assert!(!first.seen.iter().any(second_snapshot), "{:?}", first.seen);
    }

    #[test]
    fn a_view_only_server_takes_no_request_and_says_so() {
        if !node_here() {
            return;
        }
        let view = start_map("127.0.0.1:0", "map test", &Policy::default(), SCHEMA).unwrap();
        let mut client = MapClient::start(
            &url(&view, false),
            &["--publish", r#"{"op":"full"}"#, "--publish", "junk"],
        );
        client.line("publishing", |v| v["published"] == true);
        let warnings = refused(&view, &mut client, "view-only");
        assert_eq!(warnings.len(), 1, "once per client: {warnings:?}");
        assert!(warnings[0].contains("publishing refused: the map view is view-only"));
    }

    #[test]
    fn only_a_client_with_the_token_publishes_requests() {
        if !node_here() {
            return;
        }
        let view = start_map("127.0.0.1:0", "map test", &with_token(), SCHEMA).unwrap();
        let mut viewer = MapClient::start(&url(&view, false), &["--publish", r#"{"op":"a"}"#]);
        let warnings = refused(&view, &mut viewer, "no control token");
        assert!(
            warnings.len() == 1 && warnings[0].contains("no control token"),
            "{warnings:?}"
        );

        let request = r#"{"op":"full","depth":[1,2]}"#;
        let controller = MapClient::start(&url(&view, true), &["--publish", request]);
        let requests = wait_for("a request", || {
            Some(view.take_requests()).filter(|r| !r.is_empty())
        });
        assert_eq!(
            requests,
            [serde_json::from_str::<Request>(request).unwrap()]
        );
        assert!(view.take_warnings().is_empty());
        drop(controller);
    }

    #[test]
    fn junk_and_oversized_requests_are_refused_with_a_warning_and_a_status() {
        if !node_here() {
            return;
        }
        let view = start_map("127.0.0.1:0", "map test", &with_token(), SCHEMA).unwrap();
        let big = format!(r#"{{"pad":"{}"}}"#, "x".repeat(MAX_PAYLOAD_BYTES));
        let mut client = MapClient::start(
            &url(&view, true),
            &[
                "--publish",
                "not json",
                "--publish",
                &big,
                "--publish",
                "[1]",
                "--publish",
                r#"{"op":"ok"}"#,
            ],
        );
        // The good request came after the bad ones: they have been handled.
        let requests = wait_for("a request", || {
            Some(view.take_requests()).filter(|r| !r.is_empty())
        });
        assert_eq!(requests.len(), 1);
        assert_eq!(requests[0]["op"], "ok");
        let warnings = view.take_warnings();
        assert_eq!(warnings.len(), 3, "{warnings:?}");
        assert!(warnings[0].contains("request skipped: expected a JSON object: "));
        assert!(warnings[1].contains(&format!("expected at most {MAX_PAYLOAD_BYTES} bytes")));
        assert!(warnings[2].contains("expected a JSON object, found [1]"));
        assert!(
            warnings.iter().all(|w| w.len() < 200),
            "one short line each: {warnings:?}"
        );
        for why in ["expected a JSON object: ", "expected at most", "found [1]"] {
            client.line(why, |v| {
                v["status"]
                    .as_str()
                    .is_some_and(|s| s.starts_with("request refused: ") && s.contains(why))
            });
        }
    }

    #[test]
    fn a_client_that_publishes_and_leaves_is_gone() {
        if !node_here() {
            return;
        }
        let view = start_map("127.0.0.1:0", "map test", &with_token(), SCHEMA).unwrap();
        let client = MapClient::start(
            &url(&view, true),
            &["--publish", r#"{"op":"bye"}"#, "--count", "0"],
        );
        client.finish();
        wait_for("the client gone", || (view.clients() == 0).then_some(()));
        let requests = view.take_requests();
        assert_eq!(requests.len(), 1, "handled before it left: {requests:?}");
        // Its scene subscription ended with it: a snapshot goes to nobody.
        view.send_snapshot(1, &scene(&[1], 0));
    }

    #[test]
    fn the_client_ends_after_its_count_or_its_seconds() {
        if !node_here() {
            return;
        }
        let view = start_map("127.0.0.1:0", "map test", &Policy::default(), SCHEMA).unwrap();
        view.publish_pose(7, [0.0; 3], [0.0, 0.0, 0.0, 1.0]);
        let mut counted = MapClient::start(&url(&view, false), &["--count", "1"]);
        counted.message(POSE_TOPIC, 7);
        counted.finish();
        MapClient::start(&url(&view, false), &["--seconds", "0.5"]).finish();
    }

    #[test]
    fn requests_wait_in_a_bounded_queue() {
        let mut inbox = Inbox::default();
        for k in 0..MAX_REQUESTS + 3 {
            let mut request = Request::new();
            request.insert("k".into(), k.into());
            inbox.push(request);
        }
        assert_eq!(inbox.requests.len(), MAX_REQUESTS);
        assert_eq!(inbox.requests[0]["k"], 3, "the oldest dropped");
        assert_eq!(inbox.dropped, 3);
    }

    #[test]
    fn requests_come_on_their_topic_in_json() {
        assert_eq!(request_channel(REQUESTS_TOPIC, "json"), Ok(()));
        let error = request_channel("/orders", "json").unwrap_err();
        assert_eq!(
            error,
            r#"expected topic /octo_delta/requests, found "/orders""#
        );
        let error = request_channel(REQUESTS_TOPIC, "cdr").unwrap_err();
        assert_eq!(error, r#"expected encoding json, found "cdr""#);
    }

    #[test]
    fn poses_and_logs_are_foxglove_messages() {
        let pose = Shared::pose_message(&Pose {
            t_ns: 1_500_000_000,
            position_m: [1.0, 2.0, 3.0],
            orientation: [0.0, 0.0, 0.5, 0.5],
        });
        let pose: Value = serde_json::from_str(&pose).unwrap();
        assert_eq!(
            pose,
            json!({"timestamp": {"sec": 1, "nsec": 500_000_000}, "frame_id": "map",
                   "pose": {"position": {"x": 1.0, "y": 2.0, "z": 3.0},
                            "orientation": {"x": 0.0, "y": 0.0, "z": 0.5, "w": 0.5}}})
        );
        let levels = [LogLevel::Info, LogLevel::Warning, LogLevel::Error].map(LogLevel::foxglove);
        assert_eq!(levels, [2, 3, 4]);
    }

    #[test]
    fn addresses_and_exposure_are_checked() {
        let error = start_map("8765", "map test", &Policy::default(), SCHEMA)
            .err()
            .unwrap();
        assert!(matches!(error, FoxgloveError::Address { .. }), "{error}");
        let error = start_map("0.0.0.0:0", "map test", &with_token(), SCHEMA)
            .err()
            .unwrap();
        assert!(matches!(error, FoxgloveError::Exposed { .. }), "{error}");
        let insecure = Policy {
            insecure: true,
            ..with_token()
        };
        let view = start_map("0.0.0.0:0", "map test", &insecure, SCHEMA).unwrap();
        assert!(view.exposed() && view.port() != 0 && view.scheme() == "ws");
        assert_eq!(view.addr(), "0.0.0.0:0");
        view.stop();
        let view = start_map("127.0.0.1:0", "map test", &Policy::default(), SCHEMA).unwrap();
        assert!(!view.exposed());
        let busy = format!("127.0.0.1:{}", view.port());
        let error = start_map(&busy, "map test", &Policy::default(), SCHEMA)
            .err()
            .unwrap();
        assert!(matches!(error, FoxgloveError::Bind { .. }), "{error}");
    }
}
