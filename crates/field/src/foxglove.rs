//! A live Foxglove view of a session, and a console an operator drives from Foxglove: a
//! WebSocket server (the official `foxglove` SDK, behind [`crate::foxglove_gate`] so that
//! viewers offering `foxglove.websocket.v1` are served as well as `foxglove.sdk.v1`) bound only
//! to the address it is given. A new subscriber gets the latest message of each [`KEPT`]
//! channel at once (on `/session/log`, the session's start line first:
//! [`LiveView::session_started`]), and a still vehicle's pose is republished every
//! [`POSE_EVERY`].
//!
//! [`start`] returns two halves:
//! - [`LiveView`], an [`Observer`]: the channels of the MCAP log ([`Topic`]: pose,
//!   goal, velocities, link frames, link log, completed images, with the same JSON Schemas and
//!   the same messages, built by [`View`]), plus the live view's own: the image in
//!   progress on `/camera/preview` and the session's events on `/session/log`. Messages carry
//!   the wall clock as their log time.
//! - [`LiveOrders`], an [`OrderSource`] (operator end only; a ROV end does not offer
//!   publishing): what clients publish, on channels they advertise with the `json` encoding:
//!   - `/orders`: each message one order object in wire.md's JSON form
//!     (`{"type":"goto","x_cm":300,"y_cm":0,"z_cm":50,"heading_deg":90}`, `velocity`,
//!     `image_settings`, `hold_heading`) or `{"type":"cancel"}`, read by [`Live::from_object`];
//!   - any topic whose schema is `geometry_msgs/Twist` or `geometry_msgs/msg/Twist` (Foxglove's
//!     Teleop panel: topic of the user's choosing, `/cmd_vel` by convention): the joystick,
//!     by [`twist_joystick`]. The panel publishes only while a button is held, so a Twist
//!     holds for [`TWIST_HOLD`]: with none newer by then, the joystick goes neutral (a JSON
//!     `velocity` on `/orders` is kept until the next, as wire.md's joystick is).
//!
//! Who may do what (docs/tdma-foxglove.md, "Who may control"): every connection comes through
//! the gate ([`crate::foxglove_gate`]), which refuses browsers from other sites and marks each
//! client it lets through for [`Access::View`] or, when its URL carries the control token,
//! [`Access::Control`]. The session's messages go only to marked clients (a program connecting
//! to the SDK's own loopback port gets none); orders are taken only from clients marked for
//! control on an operator end started with a [`Policy::token`]; every other client's
//! advertisement is refused, once per client on stderr and in a status to the client. Without a
//! token the view is view-only. Control over plain `ws://` on an address other than loopback
//! is refused unless [`Policy::insecure`]; with [`Policy::tls`] the gate serves `wss://`.
//!
//! The contract: nothing a client sends stops the session, panics, or grows memory without
//! bound. Junk frames, unknown operations and messages on channels never advertised are
//! refused by the SDK (which tells the client); here, a payload larger than
//! [`MAX_PAYLOAD_BYTES`] or one that does not parse is refused with a warning; orders wait in a
//! queue of [`MAX_QUEUED`] (the oldest dropped and counted past that; a joystick replaces a
//! joystick still waiting), warnings in one of [`MAX_WARNINGS`] (the rest counted), all drained
//! by [`OrderSource::poll`] and [`OrderSource::take_warnings`]. Publishing never blocks the
//! session: nothing is built for a channel no client subscribes to, a preview at most every
//! [`PREVIEW_EVERY`], and the SDK queues at most [`BACKLOG_MESSAGES`] messages per client,
//! dropping the oldest for a slow one. [`LiveView::stop`] (or dropping it) closes the server, waiting at
//! most [`STOP_WAIT`] for the clients to be told.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use foxglove::RawChannel;
use foxglove::websocket::{ChannelView, Client, ClientChannel, ServerListener};

pub use crate::foxglove_gate::{Access, Policy, Token};
use crate::foxglove_gate::{MARKER_CHANNEL_ID, Reports};
use crate::foxglove_server::{
    NO_TOKEN_IN_URL, Server, Setup, Viewers, Warnings, channel_name, json_object, lock, say_count,
    shorten,
};
use crate::mcap_log::{Clock, Topic, View, ViewMessage};
use rovlink_link::SimTime;
use rovlink_rcp::operator::Joystick;
use rovlink_rcp::orders::{Live, OrderSource};
use rovlink_rcp::report::{FrameEvent, Observer};
use rovlink_rcp::{Event, PoseSample, Role};
use rovlink_wire::Nav;

/// The largest client message read, bytes (an order is a few hundred).
pub const MAX_PAYLOAD_BYTES: usize = 64 * 1024;
/// The most orders waiting for [`OrderSource::poll`].
pub const MAX_QUEUED: usize = 64;
/// The most warnings waiting for [`OrderSource::take_warnings`].
pub const MAX_WARNINGS: usize = 32;
/// The most messages the SDK queues for one client before it drops the oldest.
pub const BACKLOG_MESSAGES: usize = 256;
/// The longest [`LiveView::stop`] waits for the clients to be closed.
pub const STOP_WAIT: Duration = Duration::from_secs(1);
/// The shortest wall time between two previews of the image in progress (decoding and
/// PNG-encoding one costs milliseconds; a simulation makes trunks far faster than that).
pub const PREVIEW_EVERY: Duration = Duration::from_millis(500);
/// The longest a still vehicle's pose goes unpublished: it is republished this often.
pub const POSE_EVERY: Duration = Duration::from_secs(1);
/// The channels whose latest message a new subscriber gets at once.
pub const KEPT: [Topic; 8] = [
    Topic::Pose,
    Topic::Goal,
    Topic::Actual,
    Topic::Commanded,
    Topic::Image,
    Topic::Preview,
    Topic::Tf,
    Topic::Events,
];
/// The topic of the JSON order channel.
pub const ORDERS_TOPIC: &str = "/orders";
/// How long a Twist stays in force without a newer one (the Teleop panel's default rate is
/// 1 Hz).
pub const TWIST_HOLD: Duration = Duration::from_secs(2);
/// The schema names of a Twist channel (ROS 1 style, as the Teleop panel names it, and ROS 2).
pub const TWIST_SCHEMAS: [&str; 2] = ["geometry_msgs/Twist", "geometry_msgs/msg/Twist"];

/// Why the server did not start.
#[derive(Debug, thiserror::Error)]
pub enum FoxgloveError {
    /// The address is not HOST:PORT.
    #[error("--foxglove: expected HOST:PORT (e.g. 127.0.0.1:8765), found {found:?}: {why}")]
    Address {
        /// What was given.
        found: String,
        /// What is wrong with it.
        why: &'static str,
    },
    /// The address could not be listened on (in use, not this machine's, unknown host).
    #[error("--foxglove {addr}: cannot listen: {source}")]
    Bind {
        /// The address.
        addr: String,
        /// The system's reason.
        source: std::io::Error,
    },
    /// Control on an address other than loopback without TLS and without --foxglove-insecure.
    #[error(
        "--foxglove {addr}: control (--foxglove-token-file) on an address other than loopback \
         would send the token and the orders in clear: serve wss:// (--foxglove-tls-cert and \
         --foxglove-tls-key), or bind 127.0.0.1 and reach it through an SSH tunnel, or add \
         --foxglove-insecure"
    )]
    Exposed {
        /// The address.
        addr: String,
    },
    /// The SDK refused to set up the server or a channel.
    #[error("--foxglove {addr}: {message}")]
    Server {
        /// The address.
        addr: String,
        /// The SDK's reason.
        message: String,
    },
}

/// The channel a client publishes on, by what it advertised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClientTopic {
    /// [`ORDERS_TOPIC`]: wire.md order objects and cancel.
    Orders,
    /// A `geometry_msgs` Twist (the Teleop panel): the joystick.
    Twist,
}

impl ClientTopic {
    /// What a client channel is for, from its topic, schema name and encoding; `Err` says why
    /// it is refused.
    pub fn of(topic: &str, schema_name: &str, encoding: &str) -> Result<ClientTopic, String> {
        let kind = if topic == ORDERS_TOPIC {
            ClientTopic::Orders
        } else if TWIST_SCHEMAS.contains(&schema_name) {
            ClientTopic::Twist
        } else {
            return Err(format!(
                "expected topic {ORDERS_TOPIC} or schema {}, found topic {:?} with schema {:?}",
                TWIST_SCHEMAS.join(" or "),
                shorten(topic),
                shorten(schema_name)
            ));
        };
        if encoding != "json" {
            return Err(format!(
                "expected encoding json, found {:?}",
                shorten(encoding)
            ));
        }
        Ok(kind)
    }

    /// One message published on the channel.
    pub fn parse(self, payload: &[u8]) -> Result<Live, String> {
        let map = json_object(payload)?;
        match self {
            ClientTopic::Orders => Live::from_object(&map).map_err(|e| e.to_string()),
            ClientTopic::Twist => twist_joystick(&map),
        }
    }
}

/// A Twist (`{"linear":{"x","y","z"},"angular":{"x","y","z"}}`, m/s and rad/s as the Teleop
/// panel sends them, full stick at 1) as the joystick, armed, in manual. ROS's body frame is
/// forward-left-up (REP 103), the vehicle's forward-right-down, so: surge = linear.x, sway =
/// -linear.y, heave = -linear.z, yaw = -angular.z, each times 100 % and clamped to
/// -100..=100 %. A missing field is 0; one that is not a number (NaN arrives as null) refuses
/// the message. angular.x and angular.y are ignored.
pub fn twist_joystick(map: &serde_json::Map<String, serde_json::Value>) -> Result<Live, String> {
    let axis = |group: &str, axis: &str| -> Result<f64, String> {
        let value = match map.get(group) {
            None => return Ok(0.0),
            Some(serde_json::Value::Object(inner)) => match inner.get(axis) {
                None => return Ok(0.0),
                Some(v) => v,
            },
            Some(other) => {
                return Err(format!(
                    "field {group}: expected an object, found {}",
                    shorten(&rovlink_wire::json::show(other))
                ));
            }
        };
        match value.as_f64() {
            Some(v) if v.is_finite() => Ok((v * 100.0).clamp(-100.0, 100.0)),
            _ => Err(format!(
                "field {group}.{axis}: expected a number, found {}",
                shorten(&rovlink_wire::json::show(value))
            )),
        }
    };
    Ok(Live::Joystick {
        joystick: Joystick {
            vx: axis("linear", "x")?,
            vy: 0.0 - axis("linear", "y")?,
            vz: 0.0 - axis("linear", "z")?,
            vyaw: 0.0 - axis("angular", "z")?,
        },
        arm: true,
        disarm: false,
        nav: Nav::Manual,
    })
}

/// What clients published, waiting for the session.
#[derive(Default)]
struct Inbox {
    orders: VecDeque<Live>,
    dropped_orders: u64,
    warnings: Warnings,
    /// When the Twist in force arrived, while one is.
    twist_at: Option<Instant>,
}

impl Inbox {
    fn push(&mut self, live: Live) {
        let joystick = |l: &Live| matches!(l, Live::Joystick { .. });
        if joystick(&live)
            && let Some(last) = self.orders.back_mut()
            && joystick(last)
        {
            *last = live;
            return;
        }
        if self.orders.len() >= MAX_QUEUED {
            self.orders.pop_front();
            self.dropped_orders += 1;
        }
        self.orders.push_back(live);
    }

    /// A Twist's joystick, arrived at `at`.
    fn twist(&mut self, live: Live, at: Instant) {
        self.push(live);
        self.twist_at = Some(at);
    }

    /// At `now`: a neutral joystick when the Twist in force is older than [`TWIST_HOLD`].
    fn expire(&mut self, now: Instant) {
        if self
            .twist_at
            .is_some_and(|at| now.saturating_duration_since(at) > TWIST_HOLD)
        {
            self.twist_at = None;
            self.push(Live::scripted_joystick(Joystick::default()));
        }
    }
}

/// The SDK's callbacks: client channels and their messages, into the inbox.
struct Listener {
    inbox: Arc<Mutex<Inbox>>,
    /// The view's channels and their latest messages, for new subscribers.
    latest: Arc<Latest>,
    /// Whose orders this view takes.
    orders: Orders,
}

/// Whose orders a view takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Orders {
    /// Clients marked for control (an operator end with a token).
    FromControl,
    /// None: an operator end without a token.
    NoToken,
    /// None: a ROV end, a network or a network node (their orders come from elsewhere).
    NotHere,
}

/// The view's channels, the latest message of each [`KEPT`] one, the session's start line on
/// each `/session/log`, and the clients that receive them.
struct Latest {
    channels: Vec<Option<Arc<RawChannel>>>,
    messages: Mutex<Vec<Option<ViewMessage>>>,
    /// The start line of each `/session/log` ([`LiveView::session_started`]), by channel.
    start_lines: Mutex<Vec<Option<ViewMessage>>>,
    /// The clients the gate marked (see the module doc).
    viewers: Viewers,
}

impl Latest {
    /// Channel `index`, if the view has it.
    fn channel(&self, index: usize) -> Option<&Arc<RawChannel>> {
        self.channels.get(index).and_then(Option::as_ref)
    }

    /// Keeps the message published on channel `index` if its topic is [`KEPT`].
    fn keep(&self, index: usize, topic: Topic, json: &str, log_time_ns: u64) {
        if KEPT.contains(&topic) {
            let mut messages = lock(&self.messages);
            if let Some(slot) = messages.get_mut(index) {
                *slot = Some(ViewMessage {
                    topic,
                    log_time_ns,
                    json: json.to_string(),
                });
            }
        }
    }

    /// Keeps `message`, published on channel `index`, as the session's start line there.
    fn keep_start(&self, index: usize, message: &ViewMessage) {
        if let Some(slot) = lock(&self.start_lines).get_mut(index) {
            *slot = Some(message.clone());
        }
    }

    /// Sends `channel`'s start line (if it has one), then its latest message (if it has one
    /// and it is not the start line) to `client` alone.
    fn send_to(&self, client: &Client, channel: &ChannelView) {
        let Some(index) =
            (self.channels.iter()).position(|c| c.as_ref().is_some_and(|c| c.id() == channel.id()))
        else {
            return;
        };
        let Some(channel) = self.channel(index) else {
            return;
        };
        let start = lock(&self.start_lines).get(index).cloned().flatten();
        let latest = lock(&self.messages).get(index).cloned().flatten();
        let latest = latest.filter(|m| start.as_ref() != Some(m));
        for message in start.iter().chain(latest.iter()) {
            let json = message.json.as_bytes();
            crate::foxglove_server::send(channel, json, message.log_time_ns, client.sink_id());
        }
    }
}

impl Listener {
    /// Why `client`'s publishing is refused, if it is.
    fn refusal(&self, client: &Client) -> Option<&'static str> {
        match (self.orders, self.latest.viewers.access(client)) {
            (Orders::FromControl, Some(Access::Control)) => None,
            (Orders::FromControl, _) => Some(NO_TOKEN_IN_URL),
            (Orders::NoToken, _) => Some(
                "publishing refused: the live view is view-only; control needs \
                 --foxglove-token-file and the token in the client's URL",
            ),
            (Orders::NotHere, _) => {
                Some("publishing refused: this live view takes no orders (view only)")
            }
        }
    }
}

impl ServerListener for Listener {
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        if self.latest.viewers.access(&client).is_some() {
            self.latest.send_to(&client, &channel);
        }
    }

    fn on_client_unadvertise(&self, client: Client, channel: &ClientChannel) {
        self.latest.viewers.unadvertised(&client, channel);
    }

    fn on_client_advertise(&self, client: Client, channel: &ClientChannel) {
        if self.latest.viewers.advertised(&client, channel) {
            return;
        }
        if let Some(why) = self.refusal(&client) {
            // A view that never takes orders does not tell the client: a viewer's panels
            // advertise on their own (Foxglove's 3D panel), and nothing can change it.
            let tell = self.orders != Orders::NotHere;
            lock(&self.inbox).warnings.refuse_client(&client, why, tell);
            return;
        }
        if let Err(why) = ClientTopic::of(&channel.topic, &channel.schema_name, &channel.encoding) {
            let warning = format!(
                "{}: refused: {why} (said once per topic)",
                channel_name(&client, channel)
            );
            lock(&self.inbox)
                .warnings
                .warn_topic(&channel.topic, warning);
        }
    }

    fn on_message_data(&self, client: Client, channel: &ClientChannel, payload: &[u8]) {
        // A refused channel or client was reported when it advertised; its messages are
        // ignored.
        if u32::from(channel.id) == MARKER_CHANNEL_ID || self.refusal(&client).is_some() {
            return;
        }
        let Ok(kind) = ClientTopic::of(&channel.topic, &channel.schema_name, &channel.encoding)
        else {
            return;
        };
        let parsed = kind.parse(payload);
        let mut inbox = lock(&self.inbox);
        match parsed {
            Ok(live) if kind == ClientTopic::Twist => inbox.twist(live, Instant::now()),
            Ok(live) => {
                // A joystick from /orders is kept until the next: no Twist is in force.
                if matches!(live, Live::Joystick { .. }) {
                    inbox.twist_at = None;
                }
                inbox.push(live);
            }
            Err(why) => inbox.warnings.warn(format!(
                "{}: message skipped: {why}",
                channel_name(&client, channel)
            )),
        }
    }
}

/// The orders Foxglove clients publish (see the module doc), as they come.
pub struct LiveOrders {
    inbox: Arc<Mutex<Inbox>>,
    /// The handshakes the gate refused.
    reports: Option<Reports>,
}

impl OrderSource for LiveOrders {
    fn poll(&mut self, _now: SimTime) -> Vec<Live> {
        let mut inbox = lock(&self.inbox);
        inbox.expire(Instant::now());
        inbox.orders.drain(..).collect()
    }

    fn take_warnings(&mut self) -> Vec<String> {
        let mut inbox = lock(&self.inbox);
        let mut warnings = inbox.warnings.take();
        warnings.extend(self.reports.iter().flat_map(Reports::take));
        say_count(&mut warnings, &mut inbox.dropped_orders, |n| {
            format!("foxglove: {n} orders dropped: more than {MAX_QUEUED} waiting")
        });
        warnings
    }
}

/// The live view: an [`Observer`] of a single session or of a network (one lane per vehicle
/// under `/vehicle/N/`) publishing the session on the server's channels.
pub struct LiveView {
    /// The gate and the SDK's server behind it (closed when the view is dropped).
    server: Server,
    /// The channels (they live as long as the server), and the latest message of each kept
    /// one: lane `k`'s topic `t` at `k * Topic::ALL.len() + t.index()` (none for a network
    /// vehicle's link frames), then a network's `/network/frames` or a node's `/link/frames`.
    latest: Arc<Latest>,
    lanes: Vec<Lane>,
    /// A real-time network node's view of its own frames (its `/link/frames`).
    node: Option<View>,
    /// What its frames are: a single session's link, a network's hops, a node's own.
    extra: Extra,
    /// What clients published (a view without [`LiveOrders`] reports its refusals itself).
    inbox: Arc<Mutex<Inbox>>,
}

/// One vehicle's part of the view.
struct Lane {
    /// Its vehicle's address in a network (none in a single session).
    vehicle: Option<u8>,
    view: View,
    /// When the last preview was built, and the length of the prefix it showed.
    last_preview: Option<(Instant, usize)>,
    /// The last pose, and when it was published (a still vehicle's is republished).
    last_pose: Option<(PoseSample, Instant)>,
}

/// Starts the server, bound to `addr` only (HOST:PORT; port 0 picks a free one, see
/// [`LiveView::port`]). A bad address or one that cannot be listened on (a port in use) is an
/// `Err` naming it. Returns the observer that publishes and the source of client orders; a
/// `role` of [`Role::Rov`] takes no orders from clients (its orders come over the link), and
/// its [`LiveOrders`] stays empty; nor does an operator end without a [`Policy::token`].
/// `policy` says who may connect and who may control (see the module doc); control on an
/// address other than loopback without [`Policy::insecure`] is [`FoxgloveError::Exposed`].
/// Must not be called from inside an async runtime.
pub fn start(
    addr: &str,
    role: Role,
    policy: &Policy,
) -> Result<(LiveView, LiveOrders), FoxgloveError> {
    let name = format!("tdma-run {}", role.name());
    let orders = match (role, &policy.token) {
        (Role::Operator, Some(_)) => Orders::FromControl,
        (Role::Operator, None) => Orders::NoToken,
        (Role::Rov, _) => Orders::NotHere,
    };
    serve(addr, &name, orders, policy, &[None], Extra::Nothing)
}

/// Starts the server of a simulated network's view (see [`start`]): each vehicle's channels
/// under `/vehicle/N/` (as the network's MCAP log has them: all but the single link's
/// `link/frames`; its body frame `vehicle_N` on `/vehicle/N/tf`), and `/network/frames`, every
/// hop of every frame. Clients cannot publish: a network's orders come from its scenario.
/// `policy`'s origins are kept; a token gives no control here.
pub fn start_network(
    addr: &str,
    vehicles: &[u8],
    policy: &Policy,
) -> Result<LiveView, FoxgloveError> {
    let lanes: Vec<Option<u8>> = vehicles.iter().map(|&v| Some(v)).collect();
    serve(
        addr,
        "tdma-run network",
        Orders::NotHere,
        policy,
        &lanes,
        Extra::NetworkFrames,
    )
    .map(|(view, _)| view)
}

/// Starts the server of one real-time node of a network (`tdma-run --routes`, see
/// [`start`]): the channels of `vehicles` (every vehicle for the operator, its own for a ROV)
/// under `/vehicle/N/` as [`start_network`] has them, and `/link/frames`, the frames this node
/// sent and received (`rovlink.LinkFrame`, as a single session's link: a received frame's send
/// time is the far node's, so it has no `t_sent_s` or `delay_ms`), fed by
/// [`Observer::frame`]. Clients cannot publish: a node's orders come from its flags.
/// `policy`'s origins are kept; a token gives no control here.
pub fn start_node(
    addr: &str,
    role: Role,
    vehicles: &[u8],
    policy: &Policy,
) -> Result<LiveView, FoxgloveError> {
    let lanes: Vec<Option<u8>> = vehicles.iter().map(|&v| Some(v)).collect();
    let name = format!("tdma-run {} (network node)", role.name());
    serve(
        addr,
        &name,
        Orders::NotHere,
        policy,
        &lanes,
        Extra::NodeFrames,
    )
    .map(|(view, _)| view)
}

/// A view's channels beyond its lanes'.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Extra {
    /// None (a single session).
    Nothing,
    /// A simulated network's `/network/frames`.
    NetworkFrames,
    /// A real-time node's own `/link/frames`.
    NodeFrames,
}

fn serve(
    addr: &str,
    name: &str,
    orders: Orders,
    policy: &Policy,
    lanes: &[Option<u8>],
    extra: Extra,
) -> Result<(LiveView, LiveOrders), FoxgloveError> {
    let setup = Setup::new(addr)?;
    let channel = |name: &str, schema_name: &str, schema: &'static str| {
        setup.channel(name, schema_name, schema.as_bytes())
    };
    let mut channels = Vec::with_capacity(lanes.len() * Topic::ALL.len() + 1);
    for lane in lanes {
        for topic in Topic::ALL {
            let name = match lane {
                // A vehicle of a network has no link of its own: its frames are the network's.
                Some(_) if topic == Topic::Frames => {
                    channels.push(None);
                    continue;
                }
                Some(vehicle) => crate::net_mcap::vehicle_topic(*vehicle, topic),
                None => topic.name().to_string(),
            };
            channels.push(Some(channel(&name, topic.schema_name(), topic.schema())?));
        }
    }
    match extra {
        Extra::Nothing => {}
        Extra::NetworkFrames => channels.push(Some(channel(
            crate::net_mcap::NETWORK_FRAMES_TOPIC,
            "rovlink.HopFrame",
            crate::net_mcap::HOP_FRAME,
        )?)),
        Extra::NodeFrames => channels.push(Some(channel(
            Topic::Frames.name(),
            Topic::Frames.schema_name(),
            Topic::Frames.schema(),
        )?)),
    }
    let latest = Arc::new(Latest {
        messages: Mutex::new(vec![None; channels.len()]),
        start_lines: Mutex::new(vec![None; channels.len()]),
        channels,
        viewers: Viewers::new(setup.secret.clone()),
    });
    let inbox = Arc::new(Mutex::new(Inbox::default()));
    let listener = Arc::new(Listener {
        inbox: inbox.clone(),
        latest: latest.clone(),
        orders,
    });
    let server = setup.serve(name, policy, orders == Orders::FromControl, listener)?;
    let lanes = lanes
        .iter()
        .map(|&vehicle| Lane {
            vehicle,
            view: match vehicle {
                Some(v) => View::new(Clock::Wall).with_body_frame(&format!("vehicle_{v}")),
                None => View::new(Clock::Wall),
            },
            last_preview: None,
            last_pose: None,
        })
        .collect();
    let reports = server.reports();
    let view = LiveView {
        server,
        latest,
        lanes,
        node: (extra == Extra::NodeFrames).then(|| View::new(Clock::Wall)),
        extra,
        inbox: inbox.clone(),
    };
    Ok((view, LiveOrders { inbox, reports }))
}

impl LiveView {
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

    /// The handshakes the gate refused and the clients whose publishing was refused, not yet
    /// reported (a network's view has no [`LiveOrders`] to report them).
    pub fn take_refusals(&self) -> Vec<String> {
        let mut lines = lock(&self.inbox).warnings.take();
        lines.extend(self.server.reports().iter().flat_map(Reports::take));
        lines
    }

    /// The URL scheme clients use: `wss` with TLS, else `ws`.
    pub fn scheme(&self) -> &'static str {
        self.server.scheme()
    }

    /// Whether it listens on an address other than loopback.
    pub fn exposed(&self) -> bool {
        self.server.exposed()
    }

    /// The lane of `vehicle` (the only one in a single session).
    fn lane_of(&self, vehicle: u8) -> Option<usize> {
        match self.extra {
            Extra::Nothing => (!self.lanes.is_empty()).then_some(0),
            _ => self.lanes.iter().position(|l| l.vehicle == Some(vehicle)),
        }
    }

    /// Lane `lane` builds what some client subscribes to, and the kept channels' messages
    /// (but the preview's: a decode for nobody), whose latest a new subscriber gets at once.
    fn follow_subscriptions(&mut self, lane: usize) {
        let base = lane * Topic::ALL.len();
        let latest = &self.latest;
        if let Some(lane) = self.lanes.get_mut(lane) {
            lane.view.want(|topic| {
                (KEPT.contains(&topic) && topic != Topic::Preview)
                    || latest
                        .channel(base + topic.index())
                        .is_some_and(|c| c.has_sinks())
            });
        }
    }

    fn publish_at(&self, index: usize, topic: Topic, json: &str, log_time_ns: u64) {
        self.latest.keep(index, topic, json, log_time_ns);
        if let Some(channel) = self.latest.channel(index) {
            (self.latest.viewers).log(channel, json.as_bytes(), log_time_ns);
        }
    }

    fn publish_all(&self, lane: usize, messages: &[ViewMessage]) {
        for m in messages {
            let index = lane * Topic::ALL.len() + m.topic.index();
            self.publish_at(index, m.topic, &m.json, m.log_time_ns);
        }
    }

    /// Closes the server: the clients are told, for at most [`STOP_WAIT`].
    pub fn stop(mut self) {
        self.server.shut_down();
    }

    /// Says on every vehicle's `/session/log` that the session starts, as `text` (what runs,
    /// where, for how long; an INFO line). The line is kept: every client that subscribes to
    /// the channel later gets it at once, before the channel's latest line.
    pub fn session_started(&mut self, text: &str) {
        let messages = self.every_lane(|view| view.started(0.0, text));
        for (index, message) in messages {
            self.latest.keep_start(index, &message);
        }
    }

    /// Publishes on each lane what `build` makes of its view; what was published, with its
    /// channel's index.
    fn every_lane(
        &mut self,
        build: impl Fn(&View) -> Vec<ViewMessage>,
    ) -> Vec<(usize, ViewMessage)> {
        let mut published = Vec::new();
        for lane in 0..self.lanes.len() {
            self.follow_subscriptions(lane);
            let Some(l) = self.lanes.get(lane) else {
                continue;
            };
            let messages = build(&l.view);
            self.publish_all(lane, &messages);
            let base = lane * Topic::ALL.len();
            published.extend(messages.into_iter().map(|m| (base + m.topic.index(), m)));
        }
        published
    }

    fn lane_frame(&mut self, lane: usize, e: &FrameEvent<'_>) {
        self.follow_subscriptions(lane);
        let Some(l) = self.lanes.get(lane) else {
            return;
        };
        let messages = l.view.frame(e);
        self.publish_all(lane, &messages);
        self.republish_still(lane, e.t_received_s.or(e.t_sent_s));
    }

    /// A still vehicle's status changes nothing, so no pose comes: the last one is published
    /// again (stamped `t_s`) at least every [`POSE_EVERY`], so that a viewer opened now shows it.
    fn republish_still(&mut self, lane: usize, t_s: Option<f64>) {
        let now = Instant::now();
        if let Some((mut pose, at)) = self.lanes.get(lane).and_then(|l| l.last_pose)
            && now.saturating_duration_since(at) >= POSE_EVERY
        {
            pose.t_s = pose.t_s.max(t_s.unwrap_or(pose.t_s));
            self.lane_pose(lane, &pose);
        }
    }

    fn lane_image(&mut self, lane: usize, t_s: f64, stream: &[u8]) {
        self.follow_subscriptions(lane);
        if let Some(message) = self.lanes.get(lane).and_then(|l| l.view.image(t_s, stream)) {
            self.publish_all(lane, &[message]);
        }
    }

    fn lane_pose(&mut self, lane: usize, pose: &PoseSample) {
        self.follow_subscriptions(lane);
        let Some(l) = self.lanes.get_mut(lane) else {
            return;
        };
        let messages = l.view.pose(pose);
        l.last_pose = Some((*pose, Instant::now()));
        self.publish_all(lane, &messages);
    }

    fn lane_event(&mut self, lane: usize, end: Role, t_s: f64, event: &Event) {
        let Some(l) = self.lanes.get_mut(lane) else {
            return;
        };
        if let Event::ImageProgress { prefix, .. } = event {
            // Only when new trunks changed the picture, and at most every PREVIEW_EVERY.
            let now = Instant::now();
            if l.last_preview.is_some_and(|(at, len)| {
                len == prefix.len() || now.saturating_duration_since(at) < PREVIEW_EVERY
            }) {
                return;
            }
            l.last_preview = Some((now, prefix.len()));
        }
        self.follow_subscriptions(lane);
        let Some(l) = self.lanes.get(lane) else {
            return;
        };
        let messages = l.view.event(end, t_s, event);
        self.publish_all(lane, &messages);
    }
}

impl Observer for LiveView {
    fn frame(&mut self, e: &FrameEvent<'_>) {
        match self.extra {
            Extra::Nothing => self.lane_frame(0, e),
            Extra::NetworkFrames => self.network_frame(e),
            Extra::NodeFrames => self.node_frame(e),
        }
    }

    fn image(&mut self, vehicle: u8, t_s: f64, stream: &[u8]) {
        if let Some(lane) = self.lane_of(vehicle) {
            self.lane_image(lane, t_s, stream);
        }
    }

    fn pose(&mut self, vehicle: u8, pose: &PoseSample) {
        if let Some(lane) = self.lane_of(vehicle) {
            self.lane_pose(lane, pose);
        }
    }

    fn event(&mut self, vehicle: u8, end: Role, t_s: f64, event: &Event) {
        if let Some(lane) = self.lane_of(vehicle) {
            self.lane_event(lane, end, t_s, event);
        }
    }

    /// A warning (a source whose frames are refused, a bad order line) goes on every
    /// vehicle's `/session/log`.
    fn warning(&mut self, t_s: f64, text: &str) {
        self.every_lane(|view| view.warning(t_s, text));
    }
}

impl LiveView {
    /// A simulated network's frame at one receiver, on `/network/frames`.
    fn network_frame(&mut self, e: &FrameEvent<'_>) {
        let index = self.lanes.len() * Topic::ALL.len();
        let Some(channel) = self.latest.channel(index) else {
            return;
        };
        if channel.has_sinks() {
            let now_ns = crate::mcap_log::wall_clock_ns();
            let json = crate::net_mcap::hop_json(e, now_ns);
            (self.latest.viewers).log(channel, json.as_bytes(), now_ns);
        }
        // A still vehicle's pose is republished on the network's ticks too.
        for lane in 0..self.lanes.len() {
            self.republish_still(lane, e.t_received_s.or(e.t_sent_s));
        }
    }

    /// A frame a real-time node sent or heard, on its `/link/frames`.
    fn node_frame(&mut self, e: &FrameEvent<'_>) {
        let index = self.lanes.len() * Topic::ALL.len();
        if let Some(node) = self.node.as_mut() {
            let subscribed = self.latest.channel(index).is_some_and(|c| c.has_sinks());
            node.want(|topic| topic == Topic::Frames && subscribed);
            let frames: Vec<ViewMessage> = (node.frame(e).into_iter())
                .filter(|m| m.topic == Topic::Frames)
                .collect();
            for m in frames {
                self.publish_at(index, m.topic, &m.json, m.log_time_ns);
            }
        }
        // A still vehicle's pose is republished on the node's frames too.
        for lane in 0..self.lanes.len() {
            self.republish_still(lane, e.t_received_s.or(e.t_sent_s));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rovlink_wire::operator::Order;

    fn object(text: &str) -> serde_json::Map<String, serde_json::Value> {
        serde_json::from_str(text).unwrap()
    }

    #[test]
    fn a_teleop_twist_is_the_joystick_in_the_vehicles_frame() {
        let live = twist_joystick(&object(
            r#"{"linear":{"x":0.5,"y":0.25,"z":-1},"angular":{"x":9,"y":9,"z":1}}"#,
        ))
        .unwrap();
        assert_eq!(
            live,
            Live::Joystick {
                joystick: Joystick {
                    vx: 50.0,
                    vy: -25.0,
                    vz: 100.0,
                    vyaw: -100.0
                },
                arm: true,
                disarm: false,
                nav: Nav::Manual,
            }
        );
        let Live::Joystick { joystick, .. } =
            twist_joystick(&object(r#"{"linear":{"x":7},"angular":{"z":-3}}"#)).unwrap()
        else {
            panic!("not a joystick");
        };
        assert_eq!(
            (joystick.vx, joystick.vy, joystick.vyaw),
            (100.0, 0.0, 100.0),
            "clamped, missing is 0"
        );
        let error = twist_joystick(&object(r#"{"linear":{"x":null}}"#)).unwrap_err();
        assert_eq!(error, "field linear.x: expected a number, found null");
        let error = twist_joystick(&object(r#"{"angular":[1]}"#)).unwrap_err();
        assert!(
            error.starts_with("field angular: expected an object"),
            "{error}"
        );
    }

    #[test]
    fn client_channels_are_orders_or_twists_in_json() {
        assert_eq!(
            ClientTopic::of("/orders", "", "json"),
            Ok(ClientTopic::Orders)
        );
        assert_eq!(
            ClientTopic::of("/cmd_vel", "geometry_msgs/msg/Twist", "json"),
            Ok(ClientTopic::Twist)
        );
        assert_eq!(
            ClientTopic::of("/teleop", "geometry_msgs/Twist", "json"),
            Ok(ClientTopic::Twist)
        );
        let error = ClientTopic::of("/cmd_vel", "geometry_msgs/Twist", "cdr").unwrap_err();
        assert_eq!(error, r#"expected encoding json, found "cdr""#);
        assert!(ClientTopic::of("/other", "std_msgs/String", "json").is_err());
    }

    #[test]
    fn client_messages_parse_or_say_why() {
        assert_eq!(
            ClientTopic::Orders
                .parse(br#"{"type":"goto","x_cm":300,"y_cm":0,"z_cm":50,"heading_deg":90}"#),
            Ok(Live::Order(Order::GoTo {
                x_cm: 300,
                y_cm: 0,
                z_cm: 50,
                heading_deg: 90
            }))
        );
        assert_eq!(
            ClientTopic::Orders.parse(br#"{"type":"cancel"}"#),
            Ok(Live::Cancel)
        );
        let error = ClientTopic::Orders.parse(b"{").unwrap_err();
        assert!(error.starts_with("expected a JSON object: "), "{error}");
        let error = ClientTopic::Twist.parse(b"[1,2]").unwrap_err();
        assert_eq!(error, "expected a JSON object, found [1,2]");
        let huge = vec![b' '; MAX_PAYLOAD_BYTES + 1];
        let error = ClientTopic::Orders.parse(&huge).unwrap_err();
        assert_eq!(
            error,
            format!(
                "expected at most {MAX_PAYLOAD_BYTES} bytes, found {}",
                MAX_PAYLOAD_BYTES + 1
            )
        );
        let error = ClientTopic::Orders
            .parse(br#"{"type":"goto"}"#)
            .unwrap_err();
        assert!(error.contains("x_cm"), "{error}");
    }

    #[test]
    fn the_inbox_is_bounded_and_joysticks_coalesce() {
        let mut inbox = Inbox::default();
        let stick = |vx| {
            Live::scripted_joystick(Joystick {
                vx,
                ..Joystick::default()
            })
        };
        inbox.push(stick(1.0));
        inbox.push(stick(2.0));
        assert_eq!(inbox.orders, [stick(2.0)]);
        inbox.push(Live::Cancel);
        inbox.push(stick(3.0));
        assert_eq!(inbox.orders.len(), 3);
        for _ in 0..2 * MAX_QUEUED {
            inbox.push(Live::Cancel);
        }
        assert_eq!(inbox.orders.len(), MAX_QUEUED);
        assert_eq!(
            inbox.dropped_orders,
            (3 + 2 * MAX_QUEUED - MAX_QUEUED) as u64
        );
        for k in 0..2 * MAX_WARNINGS {
            inbox.warnings.warn(format!("w{k}"));
        }
        assert_eq!(inbox.warnings.len(), MAX_WARNINGS);
        let mut orders = LiveOrders {
            inbox: Arc::new(Mutex::new(inbox)),
            reports: None,
        };
        assert_eq!(orders.poll(SimTime::ZERO).len(), MAX_QUEUED);
        assert!(orders.poll(SimTime::ZERO).is_empty());
        let warnings = orders.take_warnings();
        assert_eq!(warnings.len(), MAX_WARNINGS + 2, "{warnings:?}");
        assert!(warnings.iter().any(|w| w.contains("orders dropped")));
        let more = format!("{MAX_WARNINGS} more client messages");
        assert!(warnings.iter().any(|w| w.contains(&more)));
        assert!(orders.take_warnings().is_empty());
    }

    #[test]
    fn a_twist_holds_for_a_while_then_the_joystick_goes_neutral() {
        let mut inbox = Inbox::default();
        let t0 = Instant::now();
        let ahead = Live::scripted_joystick(Joystick {
            vx: 50.0,
            ..Joystick::default()
        });
        inbox.twist(ahead, t0);
        inbox.expire(t0 + TWIST_HOLD / 2);
        assert_eq!(inbox.orders, [ahead]);
        inbox.orders.clear();
        inbox.expire(t0 + TWIST_HOLD + Duration::from_millis(1));
        assert_eq!(inbox.orders, [Live::scripted_joystick(Joystick::default())]);
        inbox.orders.clear();
        inbox.expire(t0 + 10 * TWIST_HOLD);
        assert!(inbox.orders.is_empty(), "neutral once");
    }

    proptest::proptest! {
        #[test]
        fn any_bytes_parse_or_fail_without_panicking(data in proptest::collection::vec(proptest::num::u8::ANY, 0..200)) {
            let _ = ClientTopic::Orders.parse(&data);
            let _ = ClientTopic::Twist.parse(&data);
        }

        #[test]
        fn any_twist_numbers_give_a_joystick_in_range(
            v in proptest::collection::vec(-1e300f64..1e300, 4),
        ) {
            let text = format!(
                r#"{{"linear":{{"x":{},"y":{},"z":{}}},"angular":{{"z":{}}}}}"#,
                v[0], v[1], v[2], v[3]
            );
            let Ok(Live::Joystick { joystick, .. }) = ClientTopic::Twist.parse(text.as_bytes()) else {
                panic!("{text}");
            };
            for axis in [joystick.vx, joystick.vy, joystick.vz, joystick.vyaw] {
                proptest::prop_assert!((-100.0..=100.0).contains(&axis));
            }
        }
    }

    #[test]
    fn the_docs_orders_are_orders() {
        let doc = include_str!("../../../docs/tdma-foxglove.md");
        let block = doc
            .split("```json\n")
            .nth(1)
            .and_then(|rest| rest.split("```").next())
            .expect("docs/tdma-foxglove.md has a json block");
        let orders: Vec<Live> = block
            .lines()
            .map(|line| ClientTopic::Orders.parse(line.as_bytes()))
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(orders.len(), 5);
        assert_eq!(orders[4], Live::Cancel);
    }
}
