//! The handshake layer in front of the Foxglove SDK's server: one port for every viewer, and
//! the only way to it.
//!
//! The official `foxglove` crate (0.30) accepts only the WebSocket subprotocols
//! `foxglove.sdk.v1` and `foxglove.sdk.v1.1`. Foxglove Studio 1.x, Lichtblick before its PR
//! #819, `@foxglove/ws-protocol` 0.8 and the tools built on it offer `foxglove.websocket.v1`,
//! which is the same protocol under its older name (Foxglove's stated position; Lichtblick's
//! fix is adding the new name beside the old). The SDK has no option for it, no way to hand
//! it an accepted connection and no hook in its handshake (no token, no Origin check), so the
//! gate listens on the address the user gave, keeps the SDK on a loopback port of its own, and
//! for each connection:
//!
//! 1. reads the client's HTTP upgrade request (at most [`MAX_REQUEST_BYTES`]), which must be
//!    whole (its TLS handshake included) within [`REQUEST_TIMEOUT`] of the accept however
//!    slowly it comes: a deadline for the whole request, not a limit per read, kept by the
//!    gate's [`Clock`]; past it the connection is closed and reported ([`Reports::take`]);
//! 2. refuses with 403 a request whose `Origin` header is not allowed ([`origin_allowed`]: what
//!    Foxglove Studio and pages on this machine send, and [`Policy::origins`]) and one whose URL
//!    carries a `token` that is not the [`Policy::token`]; a request without `Origin` (a program,
//!    not a browser) passes;
//! 3. grants [`Access::Control`] to a request whose URL carries the token (`?token=...`,
//!    compared in constant time), [`Access::View`] to the rest, and takes the query off the URL;
//! 4. if the client offers an SDK name, passes the request on (the SDK picks the newest); if it
//!    offers only `foxglove.websocket.v1`, passes it on naming `foxglove.sdk.v1` instead and,
//!    in the SDK's answer, names `foxglove.websocket.v1` back; if it offers neither, passes it
//!    on unchanged (the SDK answers 400) and reports the peer once ([`Reports::take`]);
//! 5. once the SDK has accepted, sends it first, as the client, an advertisement of a channel
//!    whose topic carries this process's random secret and the access granted
//!    ([`marker_topic`]): the live view's listener ([`crate::foxglove`]) sends data only to
//!    clients so marked and takes orders only from those marked for control. A program that
//!    connects to the SDK's loopback port directly completes the SDK's handshake but cannot
//!    know the secret: it gets no message and its publishing is refused;
//! 6. then copies bytes both ways until either side closes.
//!
//! At most [`MAX_CONNECTIONS`] connections are carried at once, and at most
//! [`MAX_CONNECTIONS_PER_PEER`] from one peer ([`peer_key`]: an IPv4 address, an IPv6 /64),
//! in handshake or open; one more is closed at once and reported. A peer trickling requests
//! therefore holds at most its share of the slots, each for at most [`REQUEST_TIMEOUT`].
//! Contract: nothing a client sends panics or blocks the session: every connection has its
//! own threads, and a request that is too long, too slow or not HTTP is closed.

use crate::foxglove_server::lock;
use rovlink_base::secret::{constant_time_eq, read_secret_file};
use std::collections::{HashMap, HashSet};
use std::io::{self, Read, Write};
use std::net::{IpAddr, Ipv6Addr, Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// The subprotocol name stock viewers offer.
pub const LEGACY_SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// The names the SDK accepts, oldest first.
pub const SDK_SUBPROTOCOLS: [&str; 2] = ["foxglove.sdk.v1", "foxglove.sdk.v1.1"];
/// The longest upgrade request read.
pub const MAX_REQUEST_BYTES: usize = 16 * 1024;
/// How long a client has, from the accept, to send its whole upgrade request (its TLS
/// handshake included), however slowly it sends it.
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(5);
/// Connections carried at once.
pub const MAX_CONNECTIONS: usize = 256;
/// Connections carried at once from one peer ([`peer_key`]), in handshake or open. A viewer
/// holds one (Foxglove opens one per data source; a reload opens the next while the last
/// closes), so 8 leaves room for a few viewers on one machine, or behind one NAT or SSH tunnel
/// (whose viewers all share its address), while one address holds at most 8 of the
/// [`MAX_CONNECTIONS`] slots: a peer trickling requests, or keeping finished handshakes open
/// and idle, cannot keep the others out. Open connections count too, or a peer that finished
/// its handshakes could hold every slot.
pub const MAX_CONNECTIONS_PER_PEER: usize = 8;
/// Peers remembered as reported (the rest are counted).
const MAX_REPORTED_PEERS: usize = 1024;
/// The `Origin`s a browser sends that are allowed without [`Policy::origins`]: Foxglove's web
/// app, and Foxglove Studio desktop (served from `file://`). Pages served from this machine
/// (`http://` or `https://` on `localhost`, `127.0.0.1` or `[::1]`, any port) are allowed too
/// ([`origin_allowed`]).
pub const DEFAULT_ORIGINS: [&str; 3] = [
    "https://studio.foxglove.dev",
    "https://app.foxglove.dev",
    "file://",
];
/// The query parameter of the URL that carries the control token (`ws://HOST:PORT/?token=...`).
pub const TOKEN_PARAMETER: &str = "token";
/// The shortest control token accepted, characters.
pub const MIN_TOKEN_CHARS: usize = 16;
/// The longest control token accepted, characters.
pub const MAX_TOKEN_CHARS: usize = 256;
/// The client channel id of the gate's marker advertisement ([`marker_topic`]); clients number
/// their channels from 0 or 1 up.
pub const MARKER_CHANNEL_ID: u32 = u32::MAX;
/// The start of the marker channel's topic.
const MARKER_PREFIX: &str = "/rovlink/gate/";

/// What a client connected through the gate may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Receive the session's channels.
    View,
    /// Receive them and publish orders (its URL carried the control token).
    Control,
}

impl Access {
    fn name(self) -> &'static str {
        match self {
            Access::View => "view",
            Access::Control => "control",
        }
    }
}

/// A control token: URL-safe characters (`A-Z a-z 0-9 - . _ ~`), [`MIN_TOKEN_CHARS`] to
/// [`MAX_TOKEN_CHARS`] of them. Its `Debug` does not show it.
#[derive(Clone, PartialEq, Eq)]
pub struct Token(Vec<u8>);

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(..)")
    }
}

impl Token {
    /// The token a token file holds (one line; a final newline is not part of it); `Err` says
    /// what is wrong without showing it.
    pub fn parse(bytes: &[u8]) -> Result<Token, String> {
        let text = bytes.strip_suffix(b"\n").unwrap_or(bytes);
        let text = text.strip_suffix(b"\r").unwrap_or(text);
        if text.len() < MIN_TOKEN_CHARS || text.len() > MAX_TOKEN_CHARS {
            return Err(format!(
                "expected a token of {MIN_TOKEN_CHARS} to {MAX_TOKEN_CHARS} characters on one \
                 line, found {} bytes",
                text.len()
            ));
        }
        if let Some(at) = text.iter().position(|&b| !url_safe(b)) {
            return Err(format!(
                "expected only A-Z a-z 0-9 - . _ ~ (they go into a URL), found another byte at \
                 offset {at}"
            ));
        }
        Ok(Token(text.to_vec()))
    }

    /// Whether `given` is this token (constant time in `given`'s contents).
    pub fn matches(&self, given: &[u8]) -> bool {
        constant_time_eq(&self.0, given)
    }
}

fn url_safe(b: u8) -> bool {
    b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b'~')
}

/// `bytes` random bytes from the system (`/dev/urandom`) in lower-case hex.
pub fn random_hex(bytes: usize) -> io::Result<String> {
    Ok(rovlink_base::hex::encode(
        &rovlink_base::secret::random_bytes(bytes)?,
    ))
}

/// A new control token: 32 random bytes in hex (64 characters).
pub fn new_token() -> io::Result<String> {
    random_hex(32)
}

/// The topic of the marker channel the gate advertises for a client it let through with
/// `access`, carrying this process's `secret`.
pub fn marker_topic(secret: &str, access: Access) -> String {
    format!("{MARKER_PREFIX}{secret}/{}", access.name())
}

/// The access a marker topic grants, if it carries `secret` (compared in constant time).
pub fn marker_access(topic: &str, secret: &str) -> Option<Access> {
    let rest = topic.strip_prefix(MARKER_PREFIX)?;
    let (given, access) = rest.rsplit_once('/')?;
    let access = match access {
        "view" => Access::View,
        "control" => Access::Control,
        _ => return None,
    };
    constant_time_eq(secret.as_bytes(), given.as_bytes()).then_some(access)
}

/// Whether a browser's `Origin` may connect: one of [`DEFAULT_ORIGINS`] or `extra` (exactly,
/// ASCII case aside), or a page of this machine (`http://` or `https://` on `localhost`,
/// `127.0.0.1` or `[::1]`, with or without a port). `null` (a sandboxed frame of any site, or
/// a local file) is allowed only if `extra` names it.
pub fn origin_allowed(origin: &str, extra: &[String]) -> bool {
    let origin = origin.trim();
    let listed = DEFAULT_ORIGINS
        .iter()
        .copied()
        .chain(extra.iter().map(String::as_str))
        .map(|o| match o.strip_suffix('/') {
            // `https://host/` as a user may write it; `file://` stays whole.
            Some(host) if !host.ends_with('/') => host,
            _ => o,
        })
        .any(|o| o.eq_ignore_ascii_case(origin));
    if listed {
        return true;
    }
    let Some(host_port) = origin
        .strip_prefix("http://")
        .or_else(|| origin.strip_prefix("https://"))
    else {
        return false;
    };
    let host = match host_port.rsplit_once(':') {
        Some((host, port))
            if !port.is_empty() && port.bytes().all(|b| b.is_ascii_digit()) && !host.is_empty() =>
        {
            host
        }
        _ => host_port,
    };
    ["localhost", "127.0.0.1", "[::1]"]
        .iter()
        .any(|h| h.eq_ignore_ascii_case(host))
}

/// Who may connect, and who may control.
#[derive(Debug, Clone, Default)]
pub struct Policy {
    /// The control token: a client whose URL carries it gets [`Access::Control`]; none: every
    /// client gets [`Access::View`], and a URL with a token is refused.
    pub token: Option<Token>,
    /// `Origin`s allowed beside [`DEFAULT_ORIGINS`] and this machine's pages.
    pub origins: Vec<String>,
    /// Control may be served over plain `ws://` on an address other than loopback (the live
    /// view refuses that otherwise; the gate does not look at it).
    pub insecure: bool,
    /// Serve `wss://`: TLS terminated here with this configuration ([`tls_config`]).
    pub tls: Option<Arc<rustls::ServerConfig>>,
}

/// A TLS configuration from a PEM certificate chain (the server's first) and a PEM private key
/// (PKCS#8, PKCS#1 or SEC1); `Err` says which is wrong and why.
pub fn tls_config(cert_pem: &[u8], key_pem: &[u8]) -> Result<Arc<rustls::ServerConfig>, String> {
    use rustls::pki_types::pem::PemObject;
    use rustls::pki_types::{CertificateDer, PrivateKeyDer};
    let certs: Vec<CertificateDer<'static>> = CertificateDer::pem_slice_iter(cert_pem)
        .collect::<Result<_, _>>()
        .map_err(|e| format!("certificate: expected PEM CERTIFICATE blocks: {e}"))?;
    if certs.is_empty() {
        return Err("certificate: expected a PEM CERTIFICATE block, found none".into());
    }
    let key = PrivateKeyDer::from_pem_slice(key_pem)
        .map_err(|e| format!("key: expected a PEM private key: {e}"))?;
    // ring, not aws-lc-rs (rustls' default, which needs cmake and a long C build): its key
    // exchange has no post-quantum group, which rustls 0.23.48 marks by deprecating it.
    #[allow(deprecated)]
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    rustls::ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| format!("TLS: {e}"))?
        .with_no_client_auth()
        .with_single_cert(certs, key)
        .map(Arc::new)
        .map_err(|e| format!("certificate and key: {e}"))
}

/// The time the gate keeps the handshake deadline by: the host's ([`HostClock`]), or one a
/// test moves.
pub trait Clock: Send + Sync {
    /// The time now.
    fn now(&self) -> Instant;
    /// How long a read or a write may wait for the peer, in real time, when `left` remains to
    /// the deadline: `left` on the host's clock; none (until the peer sends or goes) on a clock
    /// a test moves, whose deadline passes only when the test moves it past.
    fn wait(&self, left: Duration) -> Option<Duration>;
}

/// The host's monotonic clock.
#[derive(Debug, Clone, Copy, Default)]
pub struct HostClock;

impl Clock for HostClock {
    fn now(&self) -> Instant {
        Instant::now()
    }

    fn wait(&self, left: Duration) -> Option<Duration> {
        Some(left)
    }
}

/// The peer a connection from `ip` counts against ([`MAX_CONNECTIONS_PER_PEER`]): an IPv4
/// address (an IPv4-mapped IPv6 one as IPv4), or an IPv6 address's /64 (one host commonly
/// has a whole /64 to pick addresses from).
pub fn peer_key(ip: IpAddr) -> IpAddr {
    match ip.to_canonical() {
        IpAddr::V6(v6) => {
            let s = v6.segments();
            IpAddr::V6(Ipv6Addr::new(s[0], s[1], s[2], s[3], 0, 0, 0, 0))
        }
        v4 => v4,
    }
}

/// Why a connection was closed at once, at its accept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Full {
    /// [`MAX_CONNECTIONS`] are carried.
    All,
    /// [`MAX_CONNECTIONS_PER_PEER`] are carried from its peer.
    Peer,
}

impl Full {
    /// The reason's key and the report's words.
    fn said(self) -> (&'static str, String) {
        match self {
            Full::All => (
                "full",
                format!("refused: all {MAX_CONNECTIONS} connections are in use"),
            ),
            Full::Peer => (
                "per-peer",
                format!(
                    "refused: {MAX_CONNECTIONS_PER_PEER} connections from this address are \
                     carried already (in handshake or open)"
                ),
            ),
        }
    }
}

/// The connections carried, in all and per peer ([`peer_key`]).
#[derive(Default)]
struct Slots(Mutex<Taken>);

/// How many connections are carried, in all and per peer (peers with none are not kept).
#[derive(Default)]
struct Taken {
    total: usize,
    by_peer: HashMap<IpAddr, usize>,
}

impl Slots {
    /// A slot for a connection from `ip`, given back when dropped; `Err` if it must be closed.
    fn take(self: &Arc<Slots>, ip: IpAddr) -> Result<Slot, Full> {
        let key = peer_key(ip);
        let mut taken = lock(&self.0);
        let mine = taken.by_peer.get(&key).copied().unwrap_or(0);
        if mine >= MAX_CONNECTIONS_PER_PEER {
            return Err(Full::Peer);
        }
        if taken.total >= MAX_CONNECTIONS {
            return Err(Full::All);
        }
        taken.total += 1;
        taken.by_peer.insert(key, mine + 1);
        Ok(Slot {
            slots: self.clone(),
            key,
        })
    }

    /// Connections carried now.
    fn carried(&self) -> usize {
        lock(&self.0).total
    }
}

/// One carried connection's place in [`Slots`].
struct Slot {
    slots: Arc<Slots>,
    key: IpAddr,
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut taken = lock(&self.slots.0);
        taken.total = taken.total.saturating_sub(1);
        if let Some(mine) = taken.by_peer.get_mut(&self.key) {
            *mine = mine.saturating_sub(1);
            if *mine == 0 {
                taken.by_peer.remove(&self.key);
            }
        }
    }
}

/// The gate: its listening thread, stopped when dropped.
pub struct Gate {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    refusals: Arc<Mutex<Refusals>>,
    slots: Arc<Slots>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// Handshakes refused, to be reported once per peer and reason.
#[derive(Default)]
struct Refusals {
    reported: HashSet<(IpAddr, &'static str)>,
    new: Vec<String>,
    unreported: u64,
}

impl Refusals {
    /// Notes a refusal of `peer` for `reason` (a short key), said as `line` if new.
    fn note(&mut self, peer: IpAddr, reason: &'static str, line: impl FnOnce() -> String) {
        let key = (peer, reason);
        if self.reported.contains(&key) {
            return;
        }
        if self.reported.len() < MAX_REPORTED_PEERS {
            self.reported.insert(key);
            self.new.push(line());
        } else {
            self.unreported += 1;
        }
    }
}

/// What the client offered, and what to do with it.
#[derive(Debug, PartialEq, Eq)]
enum Offer {
    /// An SDK name: pass on as it is.
    Sdk,
    /// Only the legacy name: rename it both ways.
    Legacy,
    /// Neither (the list, for the report).
    Neither(String),
}

/// What a connection needs from the gate.
struct Shared {
    inner: SocketAddr,
    policy: Policy,
    secret: Arc<str>,
    refusals: Arc<Mutex<Refusals>>,
    slots: Arc<Slots>,
    clock: Arc<dyn Clock>,
}

impl Shared {
    /// Notes that a connection from `peer` was refused or closed for `reason` (a short key),
    /// said as `line` if new for the peer and reason.
    fn refused(&self, peer: IpAddr, reason: &'static str, line: String) {
        lock(&self.refusals).note(peer, reason, || {
            format!("foxglove: handshake from {peer}: {line}")
        });
    }
}

impl Gate {
    /// Listens on `addr` (as `TcpListener::bind` takes it: `127.0.0.1:8765`, `[::1]:0`) and
    /// carries connections to the SDK's server on `127.0.0.1:inner_port` as `policy` says,
    /// marking each with `secret` ([`marker_topic`]).
    pub fn start(
        addr: &str,
        inner_port: u16,
        policy: Policy,
        secret: Arc<str>,
    ) -> io::Result<Gate> {
        Gate::start_with_clock(addr, inner_port, policy, secret, Arc::new(HostClock))
    }

    /// [`Gate::start`], keeping the handshake deadline by `clock`.
    pub fn start_with_clock(
        addr: &str,
        inner_port: u16,
        policy: Policy,
        secret: Arc<str>,
        clock: Arc<dyn Clock>,
    ) -> io::Result<Gate> {
        let listener = TcpListener::bind(addr)?;
        listener.set_nonblocking(true)?;
        let local = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let refusals = Arc::new(Mutex::new(Refusals::default()));
        let slots = Arc::new(Slots::default());
        let shared = Arc::new(Shared {
            inner: SocketAddr::from(([127, 0, 0, 1], inner_port)),
            policy,
            secret,
            refusals: refusals.clone(),
            slots: slots.clone(),
            clock,
        });
        let thread = {
            let stop = stop.clone();
            std::thread::Builder::new()
                .name("foxglove-gate".into())
                .spawn(move || accept_loop(&listener, &shared, &stop))?
        };
        Ok(Gate {
            addr: local,
            stop,
            refusals,
            slots,
            thread: Some(thread),
        })
    }

    /// Connections carried now, in handshake or open.
    pub fn connections(&self) -> usize {
        self.slots.carried()
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.addr.port()
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Where the refused handshakes are reported.
    pub fn reports(&self) -> Reports {
        Reports(self.refusals.clone())
    }
}

/// The refused handshakes of a [`Gate`], for whoever reports warnings.
#[derive(Clone)]
pub struct Reports(Arc<Mutex<Refusals>>);

impl Reports {
    /// The refused handshakes not yet reported, one line each (once per peer address and
    /// reason).
    pub fn take(&self) -> Vec<String> {
        let mut r = lock(&self.0);
        let mut lines = std::mem::take(&mut r.new);
        crate::foxglove_server::say_count(&mut lines, &mut r.unreported, |n| {
            format!("foxglove: {n} more handshakes refused from other peers")
        });
        lines
    }
}

impl Drop for Gate {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn accept_loop(listener: &TcpListener, shared: &Arc<Shared>, stop: &AtomicBool) {
    while !stop.load(Ordering::SeqCst) {
        match listener.accept() {
            Ok((client, peer)) => {
                // The deadline runs from here, whatever comes after.
                let accepted = shared.clock.now();
                let slot = match shared.slots.take(peer.ip()) {
                    Ok(slot) => slot,
                    Err(full) => {
                        // Noted before the close, which the peer sees.
                        let (reason, line) = full.said();
                        shared.refused(peer.ip(), reason, line);
                        drop(client);
                        continue;
                    }
                };
                let shared = shared.clone();
                // If the thread cannot be made, the closure (the connection and its slot) is
                // dropped with it.
                let _ = std::thread::Builder::new()
                    .name("foxglove-conn".into())
                    .stack_size(128 * 1024)
                    .spawn(move || {
                        let _ = carry(client, peer, accepted + REQUEST_TIMEOUT, &shared);
                        drop(slot);
                    });
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

/// The end of an HTTP head (`\r\n\r\n`) in `buf`: the index just after it.
fn head_end(buf: &[u8]) -> Option<usize> {
    buf.windows(4).position(|w| w == b"\r\n\r\n").map(|i| i + 4)
}

/// Reads an HTTP head from `stream`: the head and whatever came after it in the same reads.
fn read_head(stream: &mut impl Read) -> io::Result<(Vec<u8>, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        if let Some(end) = head_end(&buf) {
            let rest = buf.split_off(end);
            return Ok((buf, rest));
        }
        if buf.len() > MAX_REQUEST_BYTES {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                "HTTP head too long",
            ));
        }
        let n = stream.read(&mut chunk)?;
        if n == 0 {
            return Err(io::ErrorKind::UnexpectedEof.into());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// The values of every `name` header of `head` (ASCII case ignored), trimmed.
fn header_values<'a>(head: &'a str, name: &'a str) -> impl Iterator<Item = &'a str> {
    head.split("\r\n")
        .skip(1)
        .filter_map(|line| line.split_once(':'))
        .filter(move |(n, _)| n.trim().eq_ignore_ascii_case(name))
        .map(|(_, value)| value.trim())
}

/// The subprotocols of every `Sec-WebSocket-Protocol` header of `head`.
fn offered(head: &str) -> Vec<String> {
    header_values(head, "sec-websocket-protocol")
        .flat_map(|value| value.split(','))
        .map(|p| p.trim().to_string())
        .filter(|p| !p.is_empty())
        .collect()
}

fn classify(offered: &[String]) -> Offer {
    if offered
        .iter()
        .any(|p| SDK_SUBPROTOCOLS.contains(&p.as_str()))
    {
        Offer::Sdk
    } else if offered.iter().any(|p| p == LEGACY_SUBPROTOCOL) {
        Offer::Legacy
    } else if offered.is_empty() {
        Offer::Neither("none".into())
    } else {
        let list: String = offered.join(", ").chars().take(120).collect();
        Offer::Neither(list)
    }
}

/// The value of query parameter `name` in the request line of `head` (the last one given).
fn query_value<'a>(head: &'a str, name: &str) -> Option<&'a str> {
    let target = head.split("\r\n").next()?.split(' ').nth(1)?;
    let (_, query) = target.split_once('?')?;
    let query = query.split('#').next().unwrap_or(query);
    query
        .split('&')
        .rev()
        .map(|pair| pair.split_once('=').unwrap_or((pair, "")))
        .find(|(n, _)| *n == name)
        .map(|(_, v)| v)
}

/// `head` with its request line's query taken off and every `Sec-WebSocket-Protocol` header
/// replaced by one naming `protocol` (if one is given).
fn rewritten(head: &str, protocol: Option<&str>) -> String {
    let mut out = String::with_capacity(head.len());
    let mut replaced = false;
    for (k, line) in head.trim_end_matches("\r\n").split("\r\n").enumerate() {
        if k == 0 {
            let mut parts: Vec<&str> = line.split(' ').collect();
            if let Some(target) = parts.get_mut(1) {
                *target = target.split('?').next().unwrap_or(target);
            }
            out.push_str(&parts.join(" "));
            out.push_str("\r\n");
            continue;
        }
        let is_protocol = line
            .split_once(':')
            .is_some_and(|(n, _)| n.trim().eq_ignore_ascii_case("sec-websocket-protocol"));
        match protocol {
            Some(protocol) if is_protocol => {
                if !replaced {
                    out.push_str("Sec-WebSocket-Protocol: ");
                    out.push_str(protocol);
                    out.push_str("\r\n");
                    replaced = true;
                }
            }
            _ => {
                out.push_str(line);
                out.push_str("\r\n");
            }
        }
    }
    out.push_str("\r\n");
    out
}

/// A masked WebSocket text frame carrying `text`, as a client sends one.
fn client_text_frame(text: &str) -> Vec<u8> {
    const MASK: [u8; 4] = [0x5a, 0x17, 0x3c, 0x81];
    let payload = text.as_bytes();
    let mut frame = vec![0x81];
    match payload.len() {
        n @ 0..=125 => frame.push(0x80 | n as u8),
        n @ 126..=0xffff => {
            frame.push(0x80 | 126);
            frame.extend_from_slice(&(n as u16).to_be_bytes());
        }
        n => {
            frame.push(0x80 | 127);
            frame.extend_from_slice(&(n as u64).to_be_bytes());
        }
    }
    frame.extend_from_slice(&MASK);
    frame.extend(payload.iter().enumerate().map(|(k, b)| b ^ MASK[k % 4]));
    frame
}

/// The client advertisement of the marker channel (see the module doc).
fn marker_frame(secret: &str, access: Access) -> Vec<u8> {
    let message = serde_json::json!({
        "op": "advertise",
        "channels": [{
            "id": MARKER_CHANNEL_ID,
            "topic": marker_topic(secret, access),
            "encoding": "json",
            "schemaName": "",
        }],
    });
    client_text_frame(&message.to_string())
}

/// Answers `client` with status 403 and `why`, and closes it.
fn forbid(mut client: ClientSide, why: &str) -> io::Result<()> {
    let answer = format!(
        "HTTP/1.1 403 Forbidden\r\nContent-Type: text/plain\r\nContent-Length: {}\r\n\
         Connection: close\r\n\r\n{why}",
        why.len()
    );
    client.write_all(answer.as_bytes())?;
    client.close()
}

/// A stream whose reads and writes can be bounded in real time.
trait Bounded: Read + Write {
    /// Reads and writes wait at most `wait` (none: as long as it takes).
    fn bound(&self, wait: Option<Duration>) -> io::Result<()>;
}

impl Bounded for TcpStream {
    fn bound(&self, wait: Option<Duration>) -> io::Result<()> {
        self.set_read_timeout(wait)?;
        self.set_write_timeout(wait)
    }
}

/// The client's socket under a deadline: until it is lifted ([`Deadlined::lift`]), every read
/// and write waits at most until `until` on `clock`, and fails with `TimedOut` once it has
/// passed, however little the peer sends at a time.
struct Deadlined<S> {
    stream: S,
    until: Option<Instant>,
    clock: Arc<dyn Clock>,
}

impl<S: Bounded> Deadlined<S> {
    fn new(stream: S, until: Instant, clock: Arc<dyn Clock>) -> Deadlined<S> {
        Deadlined {
            stream,
            until: Some(until),
            clock,
        }
    }

    /// Bounds the next read or write by the time left; `Err` once there is none.
    fn arm(&self) -> io::Result<()> {
        let Some(until) = self.until else {
            return Ok(());
        };
        let left = until.saturating_duration_since(self.clock.now());
        if left.is_zero() {
            return Err(too_slow());
        }
        self.stream.bound(self.clock.wait(left))
    }

    /// What a read or write gave: a wait that ended at the deadline is `TimedOut`.
    fn within<T>(&self, done: io::Result<T>) -> io::Result<T> {
        match done {
            Err(e)
                if self.until.is_some()
                    && matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) =>
            {
                Err(too_slow())
            }
            other => other,
        }
    }

    /// No deadline any more (the request is whole): each read and write waits at most `wait`
    /// (none: as long as it takes).
    fn lift(&mut self, wait: Option<Duration>) -> io::Result<()> {
        self.until = None;
        self.stream.bound(wait)
    }
}

/// The error of a request not whole by its deadline.
fn too_slow() -> io::Error {
    io::Error::new(
        io::ErrorKind::TimedOut,
        "the upgrade request was not whole by its deadline",
    )
}

impl<S: Bounded> Read for Deadlined<S> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.arm()?;
        let done = self.stream.read(buf);
        self.within(done)
    }
}

impl<S: Bounded> Write for Deadlined<S> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.arm()?;
        let done = self.stream.write(buf);
        self.within(done)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.stream.flush()
    }
}

/// The client's socket, under the handshake's deadline until it is lifted.
type ClientSocket = Deadlined<TcpStream>;

/// The client's side of a connection: plain, or TLS terminated here.
enum ClientSide {
    Plain(ClientSocket),
    Tls(Box<rustls::StreamOwned<rustls::ServerConnection, ClientSocket>>),
}

impl ClientSide {
    fn socket(&mut self) -> &mut ClientSocket {
        match self {
            ClientSide::Plain(socket) => socket,
            ClientSide::Tls(tls) => &mut tls.sock,
        }
    }

    fn tcp(&self) -> &TcpStream {
        match self {
            ClientSide::Plain(socket) => &socket.stream,
            ClientSide::Tls(tls) => &tls.sock.stream,
        }
    }

    /// Ends the connection (a TLS one with its close_notify).
    fn close(mut self) -> io::Result<()> {
        if let ClientSide::Tls(tls) = &mut self {
            tls.conn.send_close_notify();
            tls.flush()?;
        }
        self.tcp().shutdown(Shutdown::Both)
    }

    /// Copies bytes both ways between this and `server` until either side closes.
    fn pump(self, mut server: TcpStream) -> io::Result<()> {
        match self {
            ClientSide::Plain(client) => {
                let mut client = client.stream;
                // Client to server on a thread of its own; server to client here.
                let (mut from_client, mut to_server) = (client.try_clone()?, server.try_clone()?);
                let upstream = std::thread::Builder::new()
                    .name("foxglove-up".into())
                    .stack_size(64 * 1024)
                    .spawn(move || {
                        let _ = io::copy(&mut from_client, &mut to_server);
                        let _ = to_server.shutdown(Shutdown::Write);
                    })?;
                let _ = io::copy(&mut server, &mut client);
                let _ = client.shutdown(Shutdown::Both);
                let _ = server.shutdown(Shutdown::Both);
                let _ = upstream.join();
            }
            ClientSide::Tls(tls) => {
                let rustls::StreamOwned { conn, sock } = *tls;
                let sock = sock.stream;
                let tls = Arc::new(Mutex::new((conn, sock.try_clone()?)));
                let (mut from_client, mut to_server) = (sock.try_clone()?, server.try_clone()?);
                let up = tls.clone();
                let upstream = std::thread::Builder::new()
                    .name("foxglove-up".into())
                    .stack_size(64 * 1024)
                    .spawn(move || {
                        let _ = tls_upstream(&up, &mut from_client, &mut to_server);
                        let _ = to_server.shutdown(Shutdown::Write);
                    })?;
                let _ = tls_downstream(&tls, &mut server);
                let _ = sock.shutdown(Shutdown::Both);
                let _ = server.shutdown(Shutdown::Both);
                let _ = upstream.join();
            }
        }
        Ok(())
    }
}

/// A TLS connection and the socket its records are written to, used by both directions: each
/// holds the lock while it decrypts or encrypts and writes, so records go out in order.
type SharedTls = Mutex<(rustls::ServerConnection, TcpStream)>;

fn lock_tls(tls: &SharedTls) -> MutexGuard<'_, (rustls::ServerConnection, TcpStream)> {
    tls.lock().unwrap_or_else(|p| p.into_inner())
}

/// Client to server: TLS records read from `from_client`, decrypted, written to `server`.
fn tls_upstream(
    tls: &SharedTls,
    from_client: &mut TcpStream,
    server: &mut TcpStream,
) -> io::Result<()> {
    let mut records = [0u8; 16 * 1024];
    let mut plain = Vec::with_capacity(16 * 1024);
    loop {
        let n = from_client.read(&mut records)?;
        if n == 0 {
            return Ok(());
        }
        plain.clear();
        let closed = {
            let mut guard = lock_tls(tls);
            let (conn, sock) = &mut *guard;
            let mut fed = &records[..n];
            while !fed.is_empty() {
                conn.read_tls(&mut fed)?;
                let state = conn
                    .process_new_packets()
                    .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e))?;
                let ready = state.plaintext_bytes_to_read();
                let start = plain.len();
                plain.resize(start + ready, 0);
                conn.reader().read_exact(&mut plain[start..])?;
            }
            while conn.wants_write() {
                conn.write_tls(sock)?;
            }
            conn.is_handshaking() || !conn.wants_read()
        };
        server.write_all(&plain)?;
        if closed {
            return Ok(());
        }
    }
}

/// Server to client: bytes read from `server`, encrypted, written as TLS records.
fn tls_downstream(tls: &SharedTls, server: &mut TcpStream) -> io::Result<()> {
    let mut buf = [0u8; 16 * 1024];
    loop {
        let n = server.read(&mut buf)?;
        let mut guard = lock_tls(tls);
        let (conn, sock) = &mut *guard;
        if n == 0 {
            conn.send_close_notify();
        } else {
            conn.writer().write_all(&buf[..n])?;
        }
        while conn.wants_write() {
            conn.write_tls(sock)?;
        }
        if n == 0 {
            return Ok(());
        }
    }
}

impl Read for ClientSide {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self {
            ClientSide::Plain(tcp) => tcp.read(buf),
            ClientSide::Tls(tls) => tls.read(buf),
        }
    }
}

impl Write for ClientSide {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match self {
            ClientSide::Plain(tcp) => tcp.write(buf),
            ClientSide::Tls(tls) => tls.write(buf),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        match self {
            ClientSide::Plain(tcp) => tcp.flush(),
            ClientSide::Tls(tls) => tls.flush(),
        }
    }
}

/// At most 80 characters of `text`, without control characters, for a report.
fn shown(text: &str) -> String {
    text.chars().filter(|c| !c.is_control()).take(80).collect()
}

/// What the gate does with a request: refuse it (the reason's key, the report, the answer) or
/// let it through with an access.
fn admit(head: &str, policy: &Policy) -> Result<Access, (&'static str, String, &'static str)> {
    if let Some(origin) =
        header_values(head, "origin").find(|o| !origin_allowed(o, &policy.origins))
    {
        return Err((
            "origin",
            format!(
                "refused (403): Origin {:?} is not allowed (add it with --foxglove-origin if \
                 it is your viewer's)",
                shown(origin)
            ),
            "Origin not allowed",
        ));
    }
    match (query_value(head, TOKEN_PARAMETER), &policy.token) {
        (None, _) => Ok(Access::View),
        (Some(given), Some(token)) if token.matches(given.as_bytes()) => Ok(Access::Control),
        (Some(_), Some(_)) => Err((
            "token",
            "refused (403): the token in its URL is not the control token".into(),
            "wrong token",
        )),
        (Some(_), None) => Err((
            "token",
            "refused (403): its URL has a token, but this live view has no control token \
             (--foxglove-token-file): open it without ?token="
                .into(),
            "no control token on this server",
        )),
    }
}

/// Carries the connection of `tcp`, from `peer`, whose upgrade request must be whole by
/// `deadline`.
fn carry(tcp: TcpStream, peer: SocketAddr, deadline: Instant, shared: &Shared) -> io::Result<()> {
    tcp.set_nonblocking(false)?;
    let socket = Deadlined::new(tcp, deadline, shared.clock.clone());
    let mut client = match &shared.policy.tls {
        None => ClientSide::Plain(socket),
        Some(config) => {
            let conn = rustls::ServerConnection::new(config.clone())
                .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e))?;
            ClientSide::Tls(Box::new(rustls::StreamOwned::new(conn, socket)))
        }
    };
    let report = |reason, line: String| shared.refused(peer.ip(), reason, line);
    let (head, rest) = match read_head(&mut client) {
        Ok(read) => read,
        Err(e) => {
            if e.kind() == io::ErrorKind::TimedOut {
                report(
                    "deadline",
                    format!(
                        "closed: its upgrade request was not whole within {} s of connecting",
                        REQUEST_TIMEOUT.as_secs()
                    ),
                );
            }
            return Err(e);
        }
    };
    // The request is whole: what the gate writes back waits on its own bound.
    client.socket().lift(Some(REQUEST_TIMEOUT))?;
    let text = String::from_utf8_lossy(&head).into_owned();
    let access = match admit(&text, &shared.policy) {
        Ok(access) => access,
        Err((reason, line, answer)) => {
            report(reason, line);
            return forbid(client, answer);
        }
    };
    let offer = classify(&offered(&text));
    let request = match &offer {
        Offer::Legacy => rewritten(&text, Some(SDK_SUBPROTOCOLS[0])),
        Offer::Sdk => rewritten(&text, None),
        Offer::Neither(list) => {
            report(
                "subprotocol",
                format!(
                    "refused: it offered subprotocol(s) {list}; expected {LEGACY_SUBPROTOCOL}, \
                     {} or {}",
                    SDK_SUBPROTOCOLS[0], SDK_SUBPROTOCOLS[1]
                ),
            );
            rewritten(&text, None)
        }
    };
    // The SDK's side is this machine's own server: its answer has a wait of its own.
    let mut server = TcpStream::connect_timeout(&shared.inner, REQUEST_TIMEOUT)?;
    server.set_nodelay(true)?;
    client.tcp().set_nodelay(true)?;
    server.write_all(request.as_bytes())?;
    server.set_read_timeout(Some(REQUEST_TIMEOUT))?;
    let (answer, after) = read_head(&mut server)?;
    if answer.starts_with(b"HTTP/1.1 101") {
        // The marker goes first: before any frame of the client's.
        server.write_all(&marker_frame(&shared.secret, access))?;
    }
    server.write_all(&rest)?;
    let answer = if offer == Offer::Legacy {
        with_protocol(&String::from_utf8_lossy(&answer), LEGACY_SUBPROTOCOL).into_bytes()
    } else {
        answer
    };
    client.write_all(&answer)?;
    client.write_all(&after)?;
    client.flush()?;
    client.socket().lift(None)?;
    server.set_read_timeout(None)?;
    client.pump(server)
}

/// An HTTP answer `head` with every `Sec-WebSocket-Protocol` header replaced by one naming
/// `protocol`.
fn with_protocol(head: &str, protocol: &str) -> String {
    rewritten(head, Some(protocol))
}

/// The longest token file read, bytes.
const MAX_TOKEN_FILE_BYTES: u64 = 4096;
/// The longest TLS certificate chain or key file read, bytes.
const MAX_TLS_FILE_BYTES: u64 = 1 << 20;

/// A policy from a tool's flags: the control token of `--foxglove-token-file` (read as a key
/// file is: yours, mode 0600), `--foxglove-origin`s, `--foxglove-insecure`, and TLS from
/// `--foxglove-tls-cert` and `--foxglove-tls-key`; the error names the flag and the file.
pub fn policy_from_flags(
    token_file: Option<&std::path::Path>,
    origins: &[String],
    insecure: bool,
    tls: Option<(&std::path::Path, &std::path::Path)>,
) -> Result<Policy, String> {
    let token = match token_file {
        None => None,
        Some(path) => {
            let bytes = read_secret_file(path, MAX_TOKEN_FILE_BYTES)
                .map_err(|e| format!("--foxglove-token-file {e}"))?;
            let token = Token::parse(&bytes)
                .map_err(|why| format!("--foxglove-token-file {}: {why}", path.display()))?;
            Some(token)
        }
    };
    let tls = match tls {
        Some((cert, key)) => {
            let cert_pem = rovlink_base::io::read_at_most(cert, MAX_TLS_FILE_BYTES)
                .map_err(|e| format!("--foxglove-tls-cert {}: {e}", cert.display()))?;
            let key_pem = read_secret_file(key, MAX_TLS_FILE_BYTES)
                .map_err(|e| format!("--foxglove-tls-key {e}"))?;
            let config = tls_config(&cert_pem, &key_pem).map_err(|why| {
                format!(
                    "--foxglove-tls-cert {} --foxglove-tls-key {}: {why}",
                    cert.display(),
                    key.display()
                )
            })?;
            Some(config)
        }
        None => None,
    };
    Ok(Policy {
        token,
        origins: origins.to_vec(),
        insecure,
        tls,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const REQUEST: &str = "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n\
        sec-websocket-protocol: foxglove.websocket.v1\r\nSec-WebSocket-Key: k\r\n\r\n";

    #[test]
    fn offers_are_read_from_every_header_and_list() {
        let head = "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: a, foxglove.sdk.v1\r\n\
                    SEC-WEBSOCKET-PROTOCOL: b\r\n\r\n";
        assert_eq!(offered(head), ["a", "foxglove.sdk.v1", "b"]);
        assert_eq!(classify(&offered(head)), Offer::Sdk);
        assert_eq!(classify(&offered(REQUEST)), Offer::Legacy);
        assert_eq!(
            classify(&offered("GET / HTTP/1.1\r\n\r\n")),
            Offer::Neither("none".into())
        );
        assert_eq!(
            classify(&["x".into(), "y".into()]),
            Offer::Neither("x, y".into())
        );
    }

    #[test]
    fn the_legacy_name_is_renamed_in_one_header_and_the_rest_kept() {
        let renamed = with_protocol(REQUEST, "foxglove.sdk.v1");
        assert_eq!(
            renamed,
            "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n\
             Sec-WebSocket-Protocol: foxglove.sdk.v1\r\nSec-WebSocket-Key: k\r\n\r\n"
        );
        assert_eq!(head_end(renamed.as_bytes()), Some(renamed.len()));
        assert_eq!(head_end(b"GET / HTTP/1.1\r\n"), None);
    }

    #[test]
    fn tokens_are_one_line_of_url_safe_characters() {
        let token = Token::parse(b"0123456789abcdef-._~XYZ\n").unwrap();
        assert!(token.matches(b"0123456789abcdef-._~XYZ"));
        assert!(!token.matches(b"0123456789abcdef-._~XY"));
        assert_eq!(format!("{token:?}"), "Token(..)");
        assert!(
            Token::parse(b"short\n")
                .unwrap_err()
                .contains("found 5 bytes")
        );
        let error = Token::parse(b"0123456789abcdef&x=1").unwrap_err();
        assert!(
            error.contains("offset 16") && !error.contains("x=1"),
            "{error}"
        );
        assert!(Token::parse(b"0123456789abcdef\n\n").is_err(), "two lines");
        let fresh = new_token().unwrap();
        assert_eq!(fresh.len(), 64);
        assert!(Token::parse(fresh.as_bytes()).is_ok());
        assert_ne!(fresh, new_token().unwrap());
    }

    #[test]
    fn origins_are_foxgloves_this_machines_and_the_listed() {
        let extra = ["https://viewer.example/".to_string()];
        for allowed in [
            "https://studio.foxglove.dev",
            "https://app.foxglove.dev",
            "file://",
            "http://localhost:8080",
            "http://127.0.0.1:5173",
            "https://[::1]",
            "http://LOCALHOST",
            "https://viewer.example",
        ] {
            assert!(origin_allowed(allowed, &extra), "{allowed}");
        }
        for refused in [
            "https://evil.example",
            "null",
            "http://localhost.evil.example",
            "http://127.0.0.1.evil.example:80",
            "http://evil.example/?http://localhost",
            "http://localhost:80@evil.example",
            "https://studio.foxglove.dev.evil.example",
            "",
        ] {
            assert!(!origin_allowed(refused, &extra), "{refused}");
        }
        assert!(origin_allowed("null", &["null".to_string()]));
    }

    #[test]
    fn the_token_comes_from_the_query_and_the_query_is_not_passed_on() {
        let head = "GET /?a=1&token=s3cret-0123456789#x HTTP/1.1\r\nHost: x\r\n\r\n";
        assert_eq!(query_value(head, "token"), Some("s3cret-0123456789"));
        assert_eq!(query_value(head, "b"), None);
        assert_eq!(query_value("GET / HTTP/1.1\r\n\r\n", "token"), None);
        assert_eq!(
            rewritten(head, None),
            "GET / HTTP/1.1\r\nHost: x\r\n\r\n",
            "the token stays in the gate"
        );
    }

    #[test]
    fn requests_are_admitted_by_origin_and_token() {
        let policy = Policy {
            token: Some(Token::parse(b"0123456789abcdef").unwrap()),
            ..Policy::default()
        };
        let request = |target: &str, origin: Option<&str>| {
            let origin = origin.map_or(String::new(), |o| format!("Origin: {o}\r\n"));
            format!("GET {target} HTTP/1.1\r\nHost: x\r\n{origin}\r\n")
        };
        assert_eq!(admit(&request("/", None), &policy), Ok(Access::View));
        assert_eq!(
            admit(&request("/?token=0123456789abcdef", None), &policy),
            Ok(Access::Control)
        );
        assert_eq!(
            admit(
                &request("/?token=0123456789abcdef", Some("http://localhost:3000")),
                &policy
            ),
            Ok(Access::Control)
        );
        let refused = |target, origin| admit(&request(target, origin), &policy).unwrap_err().0;
        assert_eq!(refused("/?token=0123456789abcdeg", None), "token");
        assert_eq!(refused("/?token=", None), "token");
        assert_eq!(
            refused("/?token=0123456789abcdef", Some("https://evil.example")),
            "origin"
        );
        assert_eq!(refused("/", Some("null")), "origin");
        let open = Policy::default();
        assert_eq!(admit(&request("/", None), &open), Ok(Access::View));
        assert_eq!(
            admit(&request("/?token=0123456789abcdef", None), &open)
                .unwrap_err()
                .0,
            "token"
        );
    }

    #[test]
    fn the_marker_carries_the_secret_and_the_access() {
        let secret = random_hex(32).unwrap();
        for access in [Access::View, Access::Control] {
            assert_eq!(
                marker_access(&marker_topic(&secret, access), &secret),
                Some(access)
            );
        }
        let other = random_hex(32).unwrap();
        assert_eq!(
            marker_access(&marker_topic(&other, Access::Control), &secret),
            None
        );
        assert_eq!(marker_access("/orders", &secret), None);
        assert_eq!(
            marker_access(&format!("/rovlink/gate/{secret}/admin"), &secret),
            None
        );
        // The frame is a masked text frame whose payload unmasks to the advertisement.
        let frame = marker_frame(&secret, Access::View);
        assert_eq!(frame[0], 0x81);
        assert_eq!(frame[1], 0x80 | 126);
        let len = usize::from(u16::from_be_bytes([frame[2], frame[3]]));
        let mask = &frame[4..8];
        let payload: Vec<u8> = (frame[8..].iter().enumerate())
            .map(|(k, b)| b ^ mask[k % 4])
            .collect();
        assert_eq!(payload.len(), len);
        let message: serde_json::Value = serde_json::from_slice(&payload).unwrap();
        assert_eq!(message["op"], "advertise");
        assert_eq!(message["channels"][0]["id"], MARKER_CHANNEL_ID);
        assert_eq!(
            message["channels"][0]["topic"],
            marker_topic(&secret, Access::View)
        );
        assert_eq!(client_text_frame("hi")[1], 0x80 | 2);
    }

    /// A clock the test moves; reads wait for the peer as long as it takes.
    struct TestClock(Mutex<Instant>);

    impl TestClock {
        fn new() -> Arc<TestClock> {
            Arc::new(TestClock(Mutex::new(Instant::now())))
        }

        fn advance(&self, by: Duration) {
            *lock(&self.0) += by;
        }
    }

    impl Clock for TestClock {
        fn now(&self) -> Instant {
            *lock(&self.0)
        }

        fn wait(&self, _left: Duration) -> Option<Duration> {
            None
        }
    }

    /// A peer that sends `bytes` one at a time, `every` apart on `clock`.
    struct Trickle {
        bytes: Vec<u8>,
        sent: usize,
        every: Duration,
        clock: Arc<TestClock>,
    }

    impl Read for Trickle {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            let Some(&byte) = self.bytes.get(self.sent) else {
                return Ok(0);
            };
            self.clock.advance(self.every);
            buf[0] = byte;
            self.sent += 1;
            Ok(1)
        }
    }

    impl Write for Trickle {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            Ok(buf.len())
        }

        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Bounded for Trickle {
        fn bound(&self, _wait: Option<Duration>) -> io::Result<()> {
            Ok(())
        }
    }

    /// The request head read from a peer sending `REQUEST` a byte every `every`, and how
    /// many bytes were read.
    fn trickled(every: Duration) -> (io::Result<Vec<u8>>, usize) {
        let clock = TestClock::new();
        let deadline = clock.now() + REQUEST_TIMEOUT;
        let mut peer = Deadlined::new(
            Trickle {
                bytes: REQUEST.as_bytes().to_vec(),
                sent: 0,
                every,
                clock: clock.clone(),
            },
            deadline,
            clock,
        );
        let head = read_head(&mut peer).map(|(head, _)| head);
        (head, peer.stream.sent)
    }

    #[test]
    fn a_request_must_be_whole_by_its_deadline_however_it_trickles() {
        // A byte a second: each read is quick, but the request is cut at 5 s, 5 bytes in.
        let (read, sent) = trickled(Duration::from_secs(1));
        assert_eq!(read.unwrap_err().kind(), io::ErrorKind::TimedOut);
        assert_eq!(sent, 5);
        // The same request sent in less than the deadline is read whole.
        let every = REQUEST_TIMEOUT / (REQUEST.len() as u32 + 1);
        let (read, sent) = trickled(every);
        assert_eq!(read.unwrap(), REQUEST.as_bytes());
        assert_eq!(sent, REQUEST.len());
        // Lifted, the deadline is gone.
        let clock = TestClock::new();
        let mut socket = Deadlined::new(
            Trickle {
                bytes: b"late".to_vec(),
                sent: 0,
                every: Duration::ZERO,
                clock: clock.clone(),
            },
            clock.now(),
            clock.clone(),
        );
        assert_eq!(
            socket.write(b"x").unwrap_err().kind(),
            io::ErrorKind::TimedOut
        );
        socket.lift(None).unwrap();
        assert_eq!(socket.write(b"x").unwrap(), 1);
        assert_eq!(socket.read(&mut [0; 4]).unwrap(), 1);
    }

    #[test]
    fn one_peer_holds_at_most_its_share_of_the_slots() {
        let slots = Arc::new(Slots::default());
        let ip = |text: &str| text.parse::<IpAddr>().unwrap();
        let mut mine: Vec<Slot> = (0..MAX_CONNECTIONS_PER_PEER)
            .map(|_| slots.take(ip("10.0.0.5")).unwrap())
            .collect();
        assert_eq!(slots.take(ip("10.0.0.5")).err(), Some(Full::Peer));
        // The same peer written as IPv4-mapped IPv6.
        assert_eq!(slots.take(ip("::ffff:10.0.0.5")).err(), Some(Full::Peer));
        let other = slots.take(ip("10.0.0.6")).unwrap();
        assert_eq!(slots.carried(), MAX_CONNECTIONS_PER_PEER + 1);
        // One closed: the peer may connect once more.
        mine.pop();
        let again = slots.take(ip("10.0.0.5")).unwrap();
        assert_eq!(slots.take(ip("10.0.0.5")).err(), Some(Full::Peer));
        drop((other, again));
        assert_eq!(slots.carried(), MAX_CONNECTIONS_PER_PEER - 1);
        // An IPv6 host's whole /64 is one peer; the next /64 is another.
        let v6: Vec<Slot> = (0..MAX_CONNECTIONS_PER_PEER)
            .map(|k| {
                slots
                    .take(ip(&format!("2001:db8:0:1::{:x}", k + 1)))
                    .unwrap()
            })
            .collect();
        assert_eq!(
            slots.take(ip("2001:db8:0:1:ffff::9")).err(),
            Some(Full::Peer)
        );
        assert!(slots.take(ip("2001:db8:0:2::1")).is_ok());
        drop((v6, mine));
        assert_eq!(slots.carried(), 0);
        // The total stays: many peers fill it, and one more from anywhere is refused.
        let many: Vec<Slot> = (0..MAX_CONNECTIONS)
            .map_while(|k| {
                slots
                    .take(IpAddr::from([10, 1, (k / 250) as u8, (k % 250) as u8]))
                    .ok()
            })
            .collect();
        assert_eq!(slots.carried(), MAX_CONNECTIONS);
        assert_eq!(slots.take(ip("192.0.2.1")).err(), Some(Full::All));
        drop(many);
        assert_eq!(slots.carried(), 0);
        assert!(
            lock(&slots.0).by_peer.is_empty(),
            "peers with none are not kept"
        );
    }

    /// Waits until `sign` holds (failing after a minute: it never came).
    fn wait_for(what: &str, sign: impl Fn() -> bool) {
        let start = Instant::now();
        while !sign() {
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "no sign of {what}"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// A gate on a loopback port keeping time by `clock`, in front of a listener standing for
    /// the SDK's server.
    fn test_gate(clock: &Arc<TestClock>) -> (Gate, TcpListener) {
        let sdk = TcpListener::bind("127.0.0.1:0").unwrap();
        let gate = Gate::start_with_clock(
            "127.0.0.1:0",
            sdk.local_addr().unwrap().port(),
            Policy::default(),
            "secret".into(),
            clock.clone(),
        )
        .unwrap();
        (gate, sdk)
    }

    /// Reads `stream` to its end: true if it ended (closed or reset), as the gate closes it.
    fn ends(stream: &mut TcpStream) -> bool {
        // A bound on a test that went wrong, not a wait for the gate.
        stream
            .set_read_timeout(Some(Duration::from_secs(60)))
            .unwrap();
        let mut buf = [0u8; 256];
        loop {
            match stream.read(&mut buf) {
                Ok(0) => return true,
                Ok(_) => {}
                Err(e) if e.kind() == io::ErrorKind::ConnectionReset => return true,
                Err(_) => return false,
            }
        }
    }

    #[test]
    fn the_gate_closes_a_request_not_whole_at_its_deadline_and_says_so() {
        let clock = TestClock::new();
        let (gate, sdk) = test_gate(&clock);
        let port = gate.port();
        // Whole within the deadline, however slowly: passed on to the SDK.
        let mut on_time = TcpStream::connect(("127.0.0.1", port)).unwrap();
        wait_for("the accept", || gate.connections() == 1);
        let (first, last) = REQUEST.split_at(20);
        on_time.write_all(first.as_bytes()).unwrap();
        clock.advance(REQUEST_TIMEOUT - Duration::from_millis(1));
        on_time.write_all(last.as_bytes()).unwrap();
        let (mut passed, _) = sdk.accept().unwrap();
        let (head, _) = read_head(&mut passed).unwrap();
        assert_eq!(
            head,
            rewritten(REQUEST, Some(SDK_SUBPROTOCOLS[0])).as_bytes()
        );
        drop((passed, on_time));
        wait_for("the connection's end", || gate.connections() == 0);
        // Not whole at the deadline: closed at the peer's next byte, never passed on.
        let mut late = TcpStream::connect(("127.0.0.1", port)).unwrap();
        wait_for("the accept", || gate.connections() == 1);
        late.write_all(first.as_bytes()).unwrap();
        clock.advance(REQUEST_TIMEOUT);
        late.write_all(b"X").unwrap();
        assert!(ends(&mut late), "closed");
        let said = gate.reports().take();
        assert_eq!(
            said,
            [
                "foxglove: handshake from 127.0.0.1: closed: its upgrade request was not whole \
              within 5 s of connecting"
            ]
        );
        sdk.set_nonblocking(true).unwrap();
        assert_eq!(
            sdk.accept().unwrap_err().kind(),
            io::ErrorKind::WouldBlock,
            "nothing passed on"
        );
        wait_for("the connection's end", || gate.connections() == 0);
    }

    #[test]
    fn the_gate_closes_one_connection_too_many_from_a_peer_at_once() {
        let clock = TestClock::new();
        let (gate, _sdk) = test_gate(&clock);
        let port = gate.port();
        let connect = || TcpStream::connect(("127.0.0.1", port)).unwrap();
        // Held in handshake: the test's clock never reaches their deadline.
        let mut held: Vec<TcpStream> = (0..MAX_CONNECTIONS_PER_PEER).map(|_| connect()).collect();
        wait_for("the accepts", || {
            gate.connections() == MAX_CONNECTIONS_PER_PEER
        });
        let mut refused = connect();
        assert!(ends(&mut refused), "closed at once");
        assert_eq!(gate.connections(), MAX_CONNECTIONS_PER_PEER);
        let said = gate.reports().take();
        assert_eq!(
            said,
            [format!(
                "foxglove: handshake from 127.0.0.1: refused: {MAX_CONNECTIONS_PER_PEER} \
                 connections from this address are carried already (in handshake or open)"
            )]
        );
        // Said once per peer and reason.
        assert!(ends(&mut connect()));
        assert!(gate.reports().take().is_empty());
        // One of them gone: the peer may connect again.
        held.pop();
        wait_for("the connection's end", || {
            gate.connections() == MAX_CONNECTIONS_PER_PEER - 1
        });
        held.push(connect());
        wait_for("the accept", || {
            gate.connections() == MAX_CONNECTIONS_PER_PEER
        });
    }

    #[test]
    fn tls_needs_a_certificate_and_its_key() {
        let cert = include_bytes!("../../../testdata/tls/localhost.crt");
        let key = include_bytes!("../../../testdata/tls/localhost.key");
        assert!(tls_config(cert, key).is_ok());
        let error = tls_config(b"junk", key).unwrap_err();
        assert!(error.starts_with("certificate: "), "{error}");
        let error = tls_config(cert, b"junk").unwrap_err();
        assert!(error.starts_with("key: "), "{error}");
        let error = tls_config(key, key).unwrap_err();
        assert!(error.starts_with("certificate: "), "{error}");
    }
}
