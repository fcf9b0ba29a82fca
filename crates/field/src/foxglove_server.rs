//! What the live Foxglove servers share ([`crate::foxglove`], a session's view, and
//! [`crate::foxglove_map`], octo-delta's map view): the SDK's server behind the gate
//! ([`crate::foxglove_gate`]), started and stopped the one way ([`Setup`], [`Server`]); the
//! clients the gate marked, the only ones sent anything ([`Viewers`]); the warnings about what
//! clients did, bounded and said once ([`Warnings`]); a client's JSON object; HOST:PORT.
//!
//! The constants and the error are [`crate::foxglove`]'s: both servers keep to the same
//! bounds ([`BACKLOG_MESSAGES`], [`MAX_PAYLOAD_BYTES`], [`MAX_WARNINGS`], [`STOP_WAIT`]).

use std::borrow::Cow;
use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::{Arc, Mutex, MutexGuard};

use foxglove::websocket::{Capability, Client, ClientChannel, ClientId, ServerListener, Status};
use foxglove::{Context, PartialMetadata, RawChannel, Schema, SinkId, WebSocketServerHandle};

use crate::foxglove::{
    BACKLOG_MESSAGES, FoxgloveError, MAX_PAYLOAD_BYTES, MAX_WARNINGS, STOP_WAIT,
};
use crate::foxglove_gate::{Access, Gate, MARKER_CHANNEL_ID, Policy, Reports};

/// Why a client without the token in its URL may not publish to a view that takes control.
pub(crate) const NO_TOKEN_IN_URL: &str =
    "publishing refused: its URL has no control token (?token=...): it may only view";

/// `mutex`'s contents, even if a thread panicked holding it (every change made under these
/// locks is one insert, push or pop, so the contents stay consistent).
pub(crate) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// At most 80 characters of `text`, for a warning that must stay one short line.
pub(crate) fn shorten(text: &str) -> String {
    const MAX: usize = 80;
    let line: String = text.chars().filter(|c| !c.is_control()).collect();
    if line.chars().count() <= MAX {
        return line;
    }
    let mut short: String = line.chars().take(MAX).collect();
    short.push_str("...");
    short
}

/// Splits HOST:PORT (IPv6 in brackets, `[::1]:8765`).
pub(crate) fn host_port(addr: &str) -> Result<(&str, u16), FoxgloveError> {
    let bad = |why| FoxgloveError::Address {
        found: addr.to_string(),
        why,
    };
    let (host, port) = addr.rsplit_once(':').ok_or_else(|| bad("no port"))?;
    if host.is_empty() {
        return Err(bad("no host"));
    }
    if host.contains(':') && !(host.starts_with('[') && host.ends_with(']')) {
        return Err(bad("an IPv6 host goes in brackets: [::1]:8765"));
    }
    let port = port
        .parse::<u16>()
        .map_err(|_| bad("the port is not a number in 0..=65535"))?;
    Ok((host, port))
}

/// One message a client published, as a JSON object: at most [`MAX_PAYLOAD_BYTES`], strict
/// JSON (`rovlink_base::strict_json`), an object; `Err` says why not in one short line.
pub(crate) fn json_object(
    payload: &[u8],
) -> Result<serde_json::Map<String, serde_json::Value>, String> {
    if payload.len() > MAX_PAYLOAD_BYTES {
        return Err(format!(
            "expected at most {MAX_PAYLOAD_BYTES} bytes, found {}",
            payload.len()
        ));
    }
    let value: serde_json::Value = rovlink_base::strict_json::from_slice(payload)
        .map_err(|e| format!("expected a JSON object: {e}"))?;
    match value {
        serde_json::Value::Object(map) => Ok(map),
        other => Err(format!(
            "expected a JSON object, found {}",
            shorten(&rovlink_wire::json::show(&other))
        )),
    }
}

/// Adds to `lines` the line `say` makes of `count`, unless it is 0, and sets it to 0: what
/// did not fit, said once.
pub(crate) fn say_count(lines: &mut Vec<String>, count: &mut u64, say: impl FnOnce(u64) -> String) {
    if *count > 0 {
        lines.push(say(*count));
        *count = 0;
    }
}

/// How a client's channel is named in a warning.
pub(crate) fn channel_name(client: &Client, channel: &ClientChannel) -> String {
    format!(
        "foxglove client {} channel {} ({})",
        u32::from(client.id()),
        channel.id,
        shorten(&channel.topic)
    )
}

/// Sends `payload` on `channel`, logged at `log_time_ns`, to `sink` alone (every subscriber
/// with none).
pub(crate) fn send(channel: &RawChannel, payload: &[u8], log_time_ns: u64, sink: Option<SinkId>) {
    channel.log_with_meta_to_sink(
        payload,
        PartialMetadata {
            log_time: Some(log_time_ns),
        },
        sink,
    );
}

/// A client the gate let through.
#[derive(Clone, Copy, Debug)]
struct Viewer {
    sink: SinkId,
    access: Access,
}

/// The clients the gate marked, by this process's secret (see [`crate::foxglove_gate`]): the
/// only ones a server sends anything to or takes anything from.
pub(crate) struct Viewers {
    secret: Arc<str>,
    marked: Mutex<HashMap<ClientId, Viewer>>,
}

impl Viewers {
    /// No client yet, marks carrying `secret`.
    pub(crate) fn new(secret: Arc<str>) -> Viewers {
        Viewers {
            secret,
            marked: Mutex::new(HashMap::new()),
        }
    }

    /// If `channel` is the gate's marker: notes `client`'s access (when the marker carries the
    /// secret) and returns true, the channel being nothing else; false for any other channel.
    pub(crate) fn advertised(&self, client: &Client, channel: &ClientChannel) -> bool {
        if u32::from(channel.id) != MARKER_CHANNEL_ID {
            return false;
        }
        // Its topic carries the secret, so it is never shown.
        let access = crate::foxglove_gate::marker_access(&channel.topic, &self.secret);
        if let (Some(access), Some(sink)) = (access, client.sink_id()) {
            lock(&self.marked).insert(client.id(), Viewer { sink, access });
        }
        true
    }

    /// If `channel` is the gate's marker (unadvertised when the client leaves): forgets
    /// `client` and returns true; false for any other channel.
    pub(crate) fn unadvertised(&self, client: &Client, channel: &ClientChannel) -> bool {
        if u32::from(channel.id) != MARKER_CHANNEL_ID {
            return false;
        }
        lock(&self.marked).remove(&client.id());
        true
    }

    /// The access of `client`, if the gate marked it.
    pub(crate) fn access(&self, client: &Client) -> Option<Access> {
        lock(&self.marked).get(&client.id()).map(|v| v.access)
    }

    /// The sink of `client`, if the gate marked it.
    pub(crate) fn sink(&self, client: &Client) -> Option<SinkId> {
        lock(&self.marked).get(&client.id()).map(|v| v.sink)
    }

    /// Sends `payload` on `channel` to every marked client subscribed to it.
    pub(crate) fn log(&self, channel: &RawChannel, payload: &[u8], log_time_ns: u64) {
        let sinks: Vec<SinkId> = lock(&self.marked).values().map(|v| v.sink).collect();
        for sink in sinks {
            send(channel, payload, log_time_ns, Some(sink));
        }
    }
}

/// Warnings about what clients did, waiting to be taken: at most [`MAX_WARNINGS`] (the rest
/// counted), a refused client and a refused topic said once each.
#[derive(Default)]
pub(crate) struct Warnings {
    lines: VecDeque<String>,
    dropped: u64,
    /// The client topics already warned about (each is warned about once per server).
    warned_topics: HashSet<String>,
    /// The clients whose publishing was refused (each is warned about once).
    refused_clients: HashSet<ClientId>,
}

impl Warnings {
    /// Adds `warning` (counted instead when [`MAX_WARNINGS`] are waiting).
    pub(crate) fn warn(&mut self, warning: String) {
        if self.lines.len() >= MAX_WARNINGS {
            self.dropped += 1;
        } else {
            self.lines.push_back(warning);
        }
    }

    /// Warns about client topic `topic` once for the server's life: a viewer advertises its
    /// panels' topics again at every layout reload.
    pub(crate) fn warn_topic(&mut self, topic: &str, warning: String) {
        if self.warned_topics.len() < 4 * MAX_WARNINGS && self.warned_topics.insert(topic.into()) {
            self.warn(warning);
        }
    }

    /// Refuses `client`'s publishing for `why`: said once per client, here and, if `tell`, to
    /// the client in a status.
    pub(crate) fn refuse_client(&mut self, client: &Client, why: &str, tell: bool) {
        if self.refused_clients.len() < 4 * MAX_WARNINGS && self.refused_clients.insert(client.id())
        {
            self.warn(format!(
                "foxglove client {}: {why} (said once per client)",
                u32::from(client.id())
            ));
            if tell {
                client.send_status(Status::warning(why));
            }
        }
    }

    /// The warnings waiting, and a line counting those that did not fit.
    pub(crate) fn take(&mut self) -> Vec<String> {
        let mut lines: Vec<String> = self.lines.drain(..).collect();
        say_count(&mut lines, &mut self.dropped, |n| {
            format!("foxglove: {n} more client messages skipped or channels refused")
        });
        lines
    }

    /// How many are waiting (not counting those that did not fit).
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.lines.len()
    }
}

/// A server being set up: its address checked, its context (for its channels) and its secret
/// made.
pub(crate) struct Setup {
    addr: String,
    /// The SDK's channels live as long as it.
    pub(crate) context: Arc<Context>,
    /// This process's secret, which the gate's marker carries ([`Viewers::new`]).
    pub(crate) secret: Arc<str>,
}

/// The SDK's error as the server's, naming `addr`.
fn sdk_error(addr: &str, e: foxglove::FoxgloveError) -> FoxgloveError {
    match e {
        foxglove::FoxgloveError::Bind(source) => FoxgloveError::Bind {
            addr: addr.to_string(),
            source,
        },
        other => FoxgloveError::Server {
            addr: addr.to_string(),
            message: other.to_string(),
        },
    }
}

impl Setup {
    /// A server to be bound to `addr` (HOST:PORT, checked here).
    pub(crate) fn new(addr: &str) -> Result<Setup, FoxgloveError> {
        host_port(addr)?;
        let secret: Arc<str> = crate::foxglove_gate::random_hex(32)
            .map_err(|e| FoxgloveError::Server {
                addr: addr.to_string(),
                message: format!("cannot read /dev/urandom: {e}"),
            })?
            .into();
        Ok(Setup {
            addr: addr.to_string(),
            context: Context::new(),
            secret,
        })
    }

    /// A channel on `topic` of JSON messages whose JSON Schema `schema` is named
    /// `schema_name`.
    pub(crate) fn channel(
        &self,
        topic: &str,
        schema_name: &str,
        schema: impl Into<Cow<'static, [u8]>>,
    ) -> Result<Arc<RawChannel>, FoxgloveError> {
        self.context
            .channel_builder(topic)
            .message_encoding("json")
            .schema(Schema::new(schema_name, "jsonschema", schema))
            .build_raw()
            .map_err(|e| sdk_error(&self.addr, e))
    }

    /// Starts the server named `name` with `listener`, behind the gate on the address given,
    /// as `policy` says. `control`: some client may control (the view takes what clients with
    /// the token publish); then an address other than loopback without TLS and without
    /// [`Policy::insecure`] is [`FoxgloveError::Exposed`]. Must not be called from inside an
    /// async runtime.
    pub(crate) fn serve(
        self,
        name: &str,
        policy: &Policy,
        control: bool,
        listener: Arc<dyn ServerListener>,
    ) -> Result<Server, FoxgloveError> {
        let addr = self.addr;
        let (host, port) = host_port(&addr)?;
        // The SDK listens on a loopback port of its own; the gate, on the address given,
        // carries every viewer's connection to it (see `foxglove_gate`: stock viewers offer
        // the protocol's older name, which the SDK refuses) and marks it. Every server offers
        // publishing, since the marker is a client advertisement; the listener refuses what it
        // does not take.
        let handle = self
            .context
            .websocket_server()
            .name(name)
            .bind("127.0.0.1", 0)
            .message_backlog_size(BACKLOG_MESSAGES)
            .listener(listener)
            .capabilities([Capability::ClientPublish])
            .supported_encodings(["json"])
            .start_blocking()
            .map_err(|e| sdk_error(&addr, e))?;
        let gate = Gate::start(
            &format!("{host}:{port}"),
            handle.port(),
            policy.clone(),
            self.secret,
        )
        .map_err(|source| FoxgloveError::Bind {
            addr: addr.clone(),
            source,
        })?;
        if control
            && !gate.local_addr().ip().is_loopback()
            && !policy.insecure
            && policy.tls.is_none()
        {
            drop(gate);
            handle.stop().detach_all();
            return Err(FoxgloveError::Exposed { addr });
        }
        Ok(Server {
            gate: Some(gate),
            handle: Some(handle),
            _context: self.context,
            addr,
            tls: policy.tls.is_some(),
        })
    }
}

/// A running server: the gate on the address given and the SDK's server behind it, closed
/// when stopped or dropped.
pub(crate) struct Server {
    /// The handshake layer on the address given (dropped first: no new connections).
    gate: Option<Gate>,
    handle: Option<WebSocketServerHandle>,
    _context: Arc<Context>,
    addr: String,
    /// Whether it serves `wss://`.
    tls: bool,
}

impl Server {
    /// The port it listens on (the gate's).
    pub(crate) fn port(&self) -> u16 {
        self.gate.as_ref().map_or(0, Gate::port)
    }

    /// The address it was started on, as given.
    pub(crate) fn addr(&self) -> &str {
        &self.addr
    }

    /// Clients connected now.
    pub(crate) fn clients(&self) -> usize {
        self.handle
            .as_ref()
            .map_or(0, WebSocketServerHandle::client_count)
    }

    /// The URL scheme clients use: `wss` with TLS, else `ws`.
    pub(crate) fn scheme(&self) -> &'static str {
        if self.tls { "wss" } else { "ws" }
    }

    /// Whether it listens on an address other than loopback.
    pub(crate) fn exposed(&self) -> bool {
        self.gate
            .as_ref()
            .is_some_and(|g| !g.local_addr().ip().is_loopback())
    }

    /// Where the gate reports refused handshakes.
    pub(crate) fn reports(&self) -> Option<Reports> {
        self.gate.as_ref().map(Gate::reports)
    }

    /// Closes the server: the clients are told, for at most [`STOP_WAIT`].
    pub(crate) fn shut_down(&mut self) {
        self.gate.take();
        let Some(handle) = self.handle.take() else {
            return;
        };
        let shutdown = handle.stop();
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        let waiter = std::thread::Builder::new()
            .name("foxglove-stop".into())
            .spawn(move || {
                shutdown.wait_blocking();
                let _ = done_tx.send(());
            });
        if waiter.is_ok() {
            let _ = done_rx.recv_timeout(STOP_WAIT);
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.shut_down();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_are_host_and_port() {
        assert_eq!(host_port("127.0.0.1:8765").unwrap(), ("127.0.0.1", 8765));
        assert_eq!(host_port("[::1]:0").unwrap(), ("[::1]", 0));
        for (bad, why) in [
            ("8765", "no port"),
            (":8765", "no host"),
            ("::1:8765", "brackets"),
            ("localhost:99999", "0..=65535"),
            ("localhost:", "0..=65535"),
        ] {
            let error = host_port(bad).unwrap_err().to_string();
            assert!(error.contains(why) && error.contains(bad), "{bad}: {error}");
        }
    }

    #[test]
    fn warnings_stay_one_short_line() {
        assert_eq!(shorten("a\nb"), "ab");
        assert_eq!(shorten(&"x".repeat(200)).len(), 83);
    }

    #[test]
    fn client_messages_are_json_objects_or_say_why() {
        let map = json_object(br#"{"a":1}"#).unwrap();
        assert_eq!(map["a"], 1);
        let error = json_object(b"{").unwrap_err();
        assert!(error.starts_with("expected a JSON object: "), "{error}");
        assert_eq!(
            json_object(b"[1,2]").unwrap_err(),
            "expected a JSON object, found [1,2]"
        );
        let huge = vec![b' '; MAX_PAYLOAD_BYTES + 1];
        assert_eq!(
            json_object(&huge).unwrap_err(),
            format!(
                "expected at most {MAX_PAYLOAD_BYTES} bytes, found {}",
                MAX_PAYLOAD_BYTES + 1
            )
        );
    }

    #[test]
    fn warnings_are_bounded_and_the_rest_counted() {
        let mut warnings = Warnings::default();
        for k in 0..2 * MAX_WARNINGS {
            warnings.warn(format!("w{k}"));
        }
        assert_eq!(warnings.len(), MAX_WARNINGS);
        let lines = warnings.take();
        assert_eq!(lines.len(), MAX_WARNINGS + 1, "{lines:?}");
        assert!(lines[MAX_WARNINGS].starts_with(&format!("foxglove: {MAX_WARNINGS} more")));
        assert!(warnings.take().is_empty());
        warnings.warn_topic("/t", "once".into());
        warnings.warn_topic("/t", "twice".into());
        assert_eq!(warnings.take(), ["once"]);
    }
}
