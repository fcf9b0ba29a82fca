//! The handshake layer in front of the Foxglove SDK's server: one port for every viewer.
//!
//! The official `foxglove` crate (0.30) accepts only the WebSocket subprotocols
//! `foxglove.sdk.v1` and `foxglove.sdk.v1.1`. Foxglove Studio 1.x, Lichtblick before its PR
//! #819, `@foxglove/ws-protocol` 0.8 and the tools built on it offer `foxglove.websocket.v1`,
//! which is the same protocol under its older name (Foxglove's stated position; Lichtblick's
//! fix is adding the new name beside the old). The SDK has no option for it and no way to hand
//! it an accepted connection, so the gate listens on the address the user gave, keeps the SDK
//! on a loopback port of its own, and for each connection:
//!
//! 1. reads the client's HTTP upgrade request (at most [`MAX_REQUEST_BYTES`], within
//!    [`REQUEST_TIMEOUT`]);
//! 2. if the client offers an SDK name, passes the request on unchanged (the SDK picks the
//!    newest); if it offers only `foxglove.websocket.v1`, passes it on naming
//!    `foxglove.sdk.v1` instead and, in the SDK's answer, names `foxglove.websocket.v1` back;
//!    if it offers neither, passes it on unchanged (the SDK answers 400) and reports the peer
//!    once ([`Reports::take`]);
//! 3. then copies bytes both ways until either side closes.
//!
//! At most [`MAX_CONNECTIONS`] connections are carried at once; one more is closed at once.
//! Contract: nothing a client sends panics or blocks the session: every connection has its
//! own threads, and a request that is too long, too slow or not HTTP is closed.

use std::collections::HashSet;
use std::io::{self, Read, Write};
use std::net::{IpAddr, Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The subprotocol name stock viewers offer.
pub const LEGACY_SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// The names the SDK accepts, oldest first.
pub const SDK_SUBPROTOCOLS: [&str; 2] = ["foxglove.sdk.v1", "foxglove.sdk.v1.1"];
/// The longest upgrade request read.
pub const MAX_REQUEST_BYTES: usize = 16 * 1024;
/// How long a client has to send its whole upgrade request.
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(5);
/// Connections carried at once.
pub const MAX_CONNECTIONS: usize = 256;
/// Peers remembered as reported (the rest are counted).
const MAX_REPORTED_PEERS: usize = 1024;

/// The gate: its listening thread, stopped when dropped.
pub struct Gate {
    port: u16,
    stop: Arc<AtomicBool>,
    refusals: Arc<Mutex<Refusals>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// Handshakes refused, to be reported once per peer.
#[derive(Default)]
struct Refusals {
    reported: HashSet<IpAddr>,
    new: Vec<String>,
    unreported: u64,
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

impl Gate {
    /// Listens on `addr` (as `TcpListener::bind` takes it: `127.0.0.1:8765`, `[::1]:0`) and
    /// carries connections to the SDK's server on `127.0.0.1:inner_port`.
    pub fn start(addr: &str, inner_port: u16) -> io::Result<Gate> {
        let listener = TcpListener::bind(addr)?;
        listener.set_nonblocking(true)?;
        let port = listener.local_addr()?.port();
        let stop = Arc::new(AtomicBool::new(false));
        let refusals = Arc::new(Mutex::new(Refusals::default()));
        let inner = SocketAddr::from(([127, 0, 0, 1], inner_port));
        let thread = {
            let stop = stop.clone();
            let refusals = refusals.clone();
            std::thread::Builder::new()
                .name("foxglove-gate".into())
                .spawn(move || accept_loop(&listener, inner, &stop, &refusals))?
        };
        Ok(Gate {
            port,
            stop,
            refusals,
            thread: Some(thread),
        })
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.port
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
    /// The refused handshakes not yet reported, one line each (once per peer address).
    pub fn take(&self) -> Vec<String> {
        let mut r = self.0.lock().unwrap_or_else(|p| p.into_inner());
        let mut lines = std::mem::take(&mut r.new);
        if r.unreported > 0 {
            lines.push(format!(
                "foxglove: {} more handshakes refused from other peers",
                r.unreported
            ));
            r.unreported = 0;
        }
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

fn accept_loop(
    listener: &TcpListener,
    inner: SocketAddr,
    stop: &AtomicBool,
    refusals: &Arc<Mutex<Refusals>>,
) {
    let open = Arc::new(AtomicUsize::new(0));
    while !stop.load(Ordering::SeqCst) {
        match listener.accept() {
            Ok((client, peer)) => {
                if open.load(Ordering::SeqCst) >= MAX_CONNECTIONS {
                    drop(client);
                    continue;
                }
                open.fetch_add(1, Ordering::SeqCst);
                let still_open = open.clone();
                let refusals = refusals.clone();
                let spawned = std::thread::Builder::new()
                    .name("foxglove-conn".into())
                    .stack_size(128 * 1024)
                    .spawn(move || {
                        let _ = carry(client, peer, inner, &refusals);
                        still_open.fetch_sub(1, Ordering::SeqCst);
                    });
                if spawned.is_err() {
                    // The thread (and the connection it owned) is gone.
                    open.fetch_sub(1, Ordering::SeqCst);
                }
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
fn read_head(stream: &mut TcpStream) -> io::Result<(Vec<u8>, Vec<u8>)> {
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

/// The subprotocols of every `Sec-WebSocket-Protocol` header of `head`.
fn offered(head: &str) -> Vec<String> {
    head.split("\r\n")
        .skip(1)
        .filter_map(|line| line.split_once(':'))
        .filter(|(name, _)| name.trim().eq_ignore_ascii_case("sec-websocket-protocol"))
        .flat_map(|(_, value)| value.split(','))
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

/// `head` with every `Sec-WebSocket-Protocol` header replaced by one naming `protocol`.
fn with_protocol(head: &str, protocol: &str) -> String {
    let mut out = String::with_capacity(head.len());
    let mut replaced = false;
    for line in head.trim_end_matches("\r\n").split("\r\n") {
        let is_protocol = line
            .split_once(':')
            .is_some_and(|(n, _)| n.trim().eq_ignore_ascii_case("sec-websocket-protocol"));
        if is_protocol {
            if !replaced {
                out.push_str("Sec-WebSocket-Protocol: ");
                out.push_str(protocol);
                out.push_str("\r\n");
                replaced = true;
            }
        } else {
            out.push_str(line);
            out.push_str("\r\n");
        }
    }
    out.push_str("\r\n");
    out
}

fn carry(
    mut client: TcpStream,
    peer: SocketAddr,
    inner: SocketAddr,
    refusals: &Mutex<Refusals>,
) -> io::Result<()> {
    client.set_nonblocking(false)?;
    client.set_read_timeout(Some(REQUEST_TIMEOUT))?;
    let (head, rest) = read_head(&mut client)?;
    let text = String::from_utf8_lossy(&head).into_owned();
    let offer = classify(&offered(&text));
    let request = match &offer {
        Offer::Legacy => with_protocol(&text, SDK_SUBPROTOCOLS[0]).into_bytes(),
        Offer::Sdk => head,
        Offer::Neither(list) => {
            let mut r = refusals.lock().unwrap_or_else(|p| p.into_inner());
            let known = r.reported.contains(&peer.ip());
            if !known && r.reported.len() < MAX_REPORTED_PEERS {
                r.reported.insert(peer.ip());
                r.new.push(format!(
                    "foxglove: handshake from {} refused: it offered subprotocol(s) {list}; \
                     expected {LEGACY_SUBPROTOCOL}, {} or {}",
                    peer.ip(),
                    SDK_SUBPROTOCOLS[0],
                    SDK_SUBPROTOCOLS[1]
                ));
            } else if !known {
                r.unreported += 1;
            }
            head
        }
    };
    let mut server = TcpStream::connect_timeout(&inner, REQUEST_TIMEOUT)?;
    server.set_nodelay(true)?;
    client.set_nodelay(true)?;
    server.write_all(&request)?;
    server.write_all(&rest)?;
    server.set_read_timeout(Some(REQUEST_TIMEOUT))?;
    let (answer, after) = read_head(&mut server)?;
    let answer = if offer == Offer::Legacy {
        with_protocol(&String::from_utf8_lossy(&answer), LEGACY_SUBPROTOCOL).into_bytes()
    } else {
        answer
    };
    client.write_all(&answer)?;
    client.write_all(&after)?;
    client.set_read_timeout(None)?;
    server.set_read_timeout(None)?;
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
    Ok(())
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
}
