//! The real-time driver: a [`Link`] between two real transports ([`Endpoints`]), or a
//! [`Medium`] among N of them ([`Ports`]), on the monotonic clock.
//!
//! Each side is a pseudo-terminal this process creates, an existing serial port (or someone
//! else's pseudo-terminal), or a UDP socket. One thread per side reads bytes and stamps them
//! with the time they arrived; one thread per side writes what the link delivers, so a side
//! whose reader has stopped reading can never stall the other direction. The main loop owns the
//! link: it cuts the bytes into packets (wire.md frames found by the deframer, or, with raw
//! framing, bytes separated by a quiet gap), offers them at their arrival time, sleeps until the
//! link's next event or the next input, and hands every delivered frame to the writer of the
//! other side at the time the model scheduled (on a medium: to the writer of the port each
//! report is about).
//!
//! The run ends when a side closes or fails (which side, and why, is in [`Ended`]) or when
//! the stop flag given to [`Endpoints::run`] is set (by a signal handler, say): it is checked at
//! every turn of the loop, at least every 200 ms.

use std::fs::File;
use std::io::{self, Read, Write};
use std::net::{SocketAddr, UdpSocket};
use std::os::unix::fs::OpenOptionsExt;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use nix::fcntl::OFlag;
use nix::pty::{PtyMaster, grantpt, posix_openpt, ptsname_r, unlockpt};
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

use super::channel::{Link, Report, Side};
use super::dialect::EvoLogicsEmulator;
use super::medium::{Medium, MediumReport};
use super::sched::SimTime;
use crate::stats::Quantiles;
use crate::wire::{DeframeEvent, Deframer};

/// Frames a side's writer may hold before deliveries to it are counted as not taken.
const WRITE_QUEUE_FRAMES: usize = 1024;

/// Longest sleep of the main loop when nothing is scheduled, so a stop is seen promptly.
const IDLE_POLL: Duration = Duration::from_millis(200);

/// What one side of the link is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PortSpec {
    /// A new pseudo-terminal pair; programs open its path as if it were a serial port.
    Pty,
    /// An existing serial port or pseudo-terminal.
    Serial {
        /// Device path.
        path: String,
        /// Baud rate.
        baud: u32,
    },
    /// A UDP socket bound here; each datagram is one packet. Packets for this side go to
    /// `peer`, or else to whoever sent the last datagram to this socket.
    Udp {
        /// Local address to bind.
        bind: SocketAddr,
        /// Where this side's program listens, if known in advance.
        peer: Option<SocketAddr>,
    },
}

/// How a byte stream is cut into packets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framing {
    /// wire.md link frames; bytes that are not part of a good frame are skipped and counted.
    /// An incomplete frame is given up after this much silence (a false preamble in noise).
    Frames {
        /// Silence after which an incomplete frame is abandoned.
        give_up: Duration,
    },
    /// A modem's transparent mode: bytes separated by more than `idle` of silence are one packet.
    Raw {
        /// The silence that ends a packet.
        idle: Duration,
    },
}

/// The most ports one [`Ports`] opens (a 4-bit address space).
pub const MAX_PORTS: usize = 16;

/// The names of ports in messages: A and B for a link's two sides, 1 ..= 16 for a medium's.
const PORT_LABELS: [&str; MAX_PORTS] = [
    "1", "2", "3", "4", "5", "6", "7", "8", "9", "10", "11", "12", "13", "14", "15", "16",
];

/// Why a side could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("side {side} ({name}): cannot open: {reason}")]
pub struct OpenError {
    /// "A" or "B", or a medium's port number from 1.
    pub side: &'static str,
    /// The device or address.
    pub name: String,
    /// The reason.
    pub reason: String,
}

/// How a real-time run ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Ended {
    /// The stop flag was set (or every reader is gone).
    Stopped,
    /// A side's port closed or failed.
    Closed {
        /// Which side.
        side: Side,
        /// Its device or address.
        name: String,
        /// What happened.
        reason: String,
    },
}

/// Counters of a real-time run beyond the link's own reports.
#[derive(Debug, Clone, Default)]
pub struct RunInfo {
    /// Deliveries a side's writer could not take (its program was not reading), per side.
    pub not_taken: [u64; 2],
    /// Bytes read per side.
    pub bytes_read: [u64; 2],
    /// Bytes that were not part of any frame, per side (frame framing only).
    pub bytes_skipped: [u64; 2],
    /// How late each delivery was handed to its writer after the model's time (fixed memory,
    /// however long the run).
    pub lateness: Quantiles,
}

impl RunInfo {
    /// The `q` quantile (0..=1) of the delivery lateness in milliseconds (none without deliveries).
    pub fn lateness_quantile_ms(&self, q: f64) -> Option<f64> {
        self.lateness.quantile_ms(q)
    }
}

/// How a real-time run on a medium ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PortEnded {
    /// The stop flag was set (or every reader is gone).
    Stopped,
    /// A port closed or failed.
    Closed {
        /// Which port (its index, from 0).
        port: usize,
        /// Its device or address.
        name: String,
        /// What happened.
        reason: String,
    },
}

/// Counters of a real-time run beyond the model's own reports, per port (in port order).
#[derive(Debug, Clone, Default)]
pub struct PortsInfo {
    /// Deliveries a port's writer could not take (its program was not reading).
    pub not_taken: Vec<u64>,
    /// Bytes read.
    pub bytes_read: Vec<u64>,
    /// Bytes that were not part of any frame (frame framing only).
    pub bytes_skipped: Vec<u64>,
    /// How late each delivery was handed to its writer after the model's time.
    pub lateness: Quantiles,
}

impl PortsInfo {
    fn new(ports: usize) -> PortsInfo {
        PortsInfo {
            not_taken: vec![0; ports],
            bytes_read: vec![0; ports],
            bytes_skipped: vec![0; ports],
            lateness: Quantiles::default(),
        }
    }

    /// The `q` quantile (0..=1) of the delivery lateness in milliseconds (none without deliveries).
    pub fn lateness_quantile_ms(&self, q: f64) -> Option<f64> {
        self.lateness.quantile_ms(q)
    }

    /// Counts a port's figure (an unknown port is ignored).
    fn add(counts: &mut [u64], port: usize, n: u64) {
        if let Some(count) = counts.get_mut(port) {
            *count += n;
        }
    }
}

/// Two ports' counters as a link's.
fn two(counts: &[u64]) -> [u64; 2] {
    [0, 1].map(|k| counts.get(k).copied().unwrap_or(0))
}

impl From<PortsInfo> for RunInfo {
    fn from(info: PortsInfo) -> RunInfo {
        RunInfo {
            not_taken: two(&info.not_taken),
            bytes_read: two(&info.bytes_read),
            bytes_skipped: two(&info.bytes_skipped),
            lateness: info.lateness,
        }
    }
}

enum Message {
    Data {
        port: usize,
        at: Instant,
        bytes: Vec<u8>,
        /// A datagram: one packet as it is, not bytes of a stream.
        datagram: bool,
    },
    Closed {
        port: usize,
        reason: String,
    },
}

/// Where a side's deliveries go.
struct Writer {
    queue: SyncSender<Vec<u8>>,
}

/// Open ports (pseudo-terminals, serial ports, UDP sockets) with their reader and writer
/// threads, for a [`Medium`] among them.
pub struct Ports {
    names: Vec<String>,
    writers: Vec<Writer>,
    inbox: Receiver<Message>,
    /// Pseudo-terminal slaves kept open so the pairs live while programs come and go.
    _slaves: Vec<File>,
    /// Run the threads under real-time scheduling.
    realtime_priority: bool,
}

/// The two open sides of a real-time link.
pub struct Endpoints {
    ports: Ports,
    names: [String; 2],
}

/// What the real-time loop drives: a link between two ports or a medium among N.
trait Air {
    type Report;
    fn advance(&mut self, t: SimTime);
    fn next_event_time(&self) -> Option<SimTime>;
    fn offer(&mut self, port: usize, bytes: Vec<u8>) -> u64;
    fn pop_report(&mut self) -> Option<Self::Report>;
}

impl Air for Link {
    type Report = Report;
    fn advance(&mut self, t: SimTime) {
        Link::advance(self, t)
    }
    fn next_event_time(&self) -> Option<SimTime> {
        Link::next_event_time(self)
    }
    fn offer(&mut self, port: usize, bytes: Vec<u8>) -> u64 {
        Link::offer(self, side_of(port), bytes)
    }
    fn pop_report(&mut self) -> Option<Report> {
        Link::pop_report(self)
    }
}

impl Air for Medium {
    type Report = MediumReport;
    fn advance(&mut self, t: SimTime) {
        Medium::advance(self, t)
    }
    fn next_event_time(&self) -> Option<SimTime> {
        Medium::next_event_time(self)
    }
    fn offer(&mut self, port: usize, bytes: Vec<u8>) -> u64 {
        Medium::offer(self, port, bytes)
    }
    fn pop_report(&mut self) -> Option<MediumReport> {
        Medium::pop_report(self)
    }
}

/// A link's side by port index (A is 0).
fn side_of(port: usize) -> Side {
    if port == 0 { Side::A } else { Side::B }
}

/// Puts the calling thread under SCHED_FIFO at the lowest real-time priority: above every
/// ordinary process, below the kernel's own real-time threads. Timer wake-ups of such a thread
/// are not delayed by other work on the machine (nor by timer slack). Needs root or
/// CAP_SYS_NICE; the error says why not.
pub fn raise_priority() -> Result<(), String> {
    use thread_priority::{
        RealtimeThreadSchedulePolicy, ThreadPriority, ThreadSchedulePolicy,
        set_thread_priority_and_policy, thread_native_id,
    };
    set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Min,
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map_err(|e| format!("{e:?}"))
}

/// Whether this process may use real-time scheduling: tried on a throwaway thread
/// ([`raise_priority`]); the error says why not.
pub fn priority_allowed() -> Result<(), String> {
    match thread::spawn(raise_priority).join() {
        Ok(result) => result,
        Err(_) => Err("the trial thread failed".into()),
    }
}

impl Ports {
    /// Opens every port (at most [`MAX_PORTS`]) and starts their reader and writer threads;
    /// with `realtime_priority` every thread asks for real-time scheduling
    /// ([`raise_priority`]).
    pub fn open(specs: Vec<PortSpec>, realtime_priority: bool) -> Result<Ports, OpenError> {
        Ports::open_labelled(specs, &PORT_LABELS, realtime_priority)
    }

    fn open_labelled(
        specs: Vec<PortSpec>,
        labels: &[&'static str],
        realtime_priority: bool,
    ) -> Result<Ports, OpenError> {
        if specs.len() > labels.len() {
            return Err(OpenError {
                side: "all",
                name: format!("{} ports", specs.len()),
                reason: format!("expected at most {} ports", labels.len()),
            });
        }
        let (sender, inbox) = mpsc::channel();
        let (mut names, mut writers, mut slaves) = (Vec::new(), Vec::new(), Vec::new());
        for (port, (spec, label)) in specs.into_iter().zip(labels).enumerate() {
            let (name, writer, slave) =
                open_side(port, label, spec, sender.clone(), realtime_priority)?;
            names.push(name);
            writers.push(writer);
            slaves.extend(slave);
        }
        Ok(Ports {
            names,
            writers,
            inbox,
            _slaves: slaves,
            realtime_priority,
        })
    }

    /// The device path or address of each port, in order: for a pseudo-terminal, the path
    /// programs open.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Hands bytes to a port's writer; counts them as not taken when its queue is full.
    fn write(&self, port: usize, bytes: Vec<u8>, info: &mut PortsInfo) {
        let Some(writer) = self.writers.get(port).filter(|_| !bytes.is_empty()) else {
            return;
        };
        match writer.queue.try_send(bytes) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                PortsInfo::add(&mut info.not_taken, port, 1)
            }
        }
    }

    /// Runs `medium` (node k on port k) among the ports until one closes or the run is
    /// stopped. `on_report` sees every report when the model decides it (the bytes of a frame
    /// that arrived are then written to the port the report is about), with the medium's
    /// clock anchored at the start of the call. The run ends ([`PortEnded::Stopped`]) within
    /// 200 ms of `stop` being set.
    pub fn run(
        &self,
        medium: &mut Medium,
        framing: Framing,
        stop: &AtomicBool,
        mut on_report: impl FnMut(&MediumReport),
    ) -> (PortEnded, PortsInfo) {
        self.drive(
            medium,
            framing,
            stop,
            |_, report, info| {
                if report.fate.arrived() {
                    self.write(report.to, report.bytes.clone(), info);
                }
                on_report(&report);
                report.t_rx.filter(|_| report.fate.arrived())
            },
            |_, _, bytes, _| Some(bytes),
        )
    }

    /// The loop both drivers share. `deliver` handles a report (and returns its arrival time,
    /// for the lateness); `receive` may take bytes a port read before framing (returning none)
    /// or hand them on.
    fn drive<A: Air>(
        &self,
        air: &mut A,
        framing: Framing,
        stop: &AtomicBool,
        mut deliver: impl FnMut(&mut A, A::Report, &mut PortsInfo) -> Option<SimTime>,
        mut receive: impl FnMut(&mut A, usize, Vec<u8>, &mut PortsInfo) -> Option<Vec<u8>>,
    ) -> (PortEnded, PortsInfo) {
        if self.realtime_priority {
            let _ = raise_priority();
        }
        let start = Instant::now();
        let clock = |at: Instant| SimTime(at.saturating_duration_since(start).as_nanos() as u64);
        let mut info = PortsInfo::new(self.names.len());
        let mut framers: Vec<Framer> = self.names.iter().map(|_| Framer::new(framing)).collect();
        loop {
            if stop.load(Ordering::Relaxed) {
                return (PortEnded::Stopped, info);
            }
            let now = clock(Instant::now());
            air.advance(now);
            while let Some(report) = air.pop_report() {
                if let Some(t_rx) = deliver(air, report, &mut info) {
                    let late_us = now.0.saturating_sub(t_rx.0) / 1000;
                    info.lateness.push_us(late_us);
                }
            }
            for (port, framer) in framers.iter_mut().enumerate() {
                for packet in framer.due(now) {
                    air.offer(port, packet);
                }
            }
            let mut wake = air.next_event_time();
            for framer in &framers {
                if let Some(due) = framer.deadline() {
                    wake = Some(wake.map_or(due, |w| w.min(due)));
                }
            }
            let idle_until = start + Duration::from_nanos(now.0) + IDLE_POLL;
            let deadline = match wake {
                Some(due) => (start + Duration::from_nanos(due.0)).min(idle_until),
                None => idle_until,
            };
            let timeout = deadline.saturating_duration_since(Instant::now());
            match self.inbox.recv_timeout(timeout) {
                Ok(Message::Data {
                    port,
                    at,
                    bytes,
                    datagram,
                }) => {
                    let t = clock(at);
                    air.advance(t);
                    PortsInfo::add(&mut info.bytes_read, port, bytes.len() as u64);
                    let Some(bytes) = receive(air, port, bytes, &mut info) else {
                        continue;
                    };
                    if datagram {
                        air.offer(port, bytes);
                        continue;
                    }
                    let Some(framer) = framers.get_mut(port) else {
                        continue;
                    };
                    for packet in framer.push(t, &bytes) {
                        air.offer(port, packet);
                    }
                    if let Some(skipped) = info.bytes_skipped.get_mut(port) {
                        *skipped = framer.skipped;
                    }
                }
                Ok(Message::Closed { port, reason }) => {
                    let name = self.names.get(port).cloned().unwrap_or_default();
                    return (PortEnded::Closed { port, name, reason }, info);
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return (PortEnded::Stopped, info);
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
        }
    }
}

impl Endpoints {
    /// Opens both sides and starts their reader and writer threads; with `realtime_priority`
    /// every thread of the link asks for real-time scheduling ([`raise_priority`]).
    pub fn open(specs: [PortSpec; 2], realtime_priority: bool) -> Result<Endpoints, OpenError> {
        let ports = Ports::open_labelled(specs.into(), &["A", "B"], realtime_priority)?;
        let names = [0, 1].map(|k| ports.names.get(k).cloned().unwrap_or_default());
        Ok(Endpoints { ports, names })
    }

    /// The device path or address of each side (A, then B): for a pseudo-terminal, the path
    /// programs open.
    pub fn names(&self) -> &[String; 2] {
        &self.names
    }

    /// Runs `link` between the two sides until one closes or the run is stopped. `on_report`
    /// sees every report when the model decides it (delivered frames are then written), with
    /// the link's clock anchored at the start of the call. With a `dialect`, the sides speak
    /// the EvoLogics AT commands instead of sending bare packets (`framing` is then unused).
    /// The run ends ([`Ended::Stopped`]) within 200 ms of `stop` being set.
    pub fn run(
        &self,
        link: &mut Link,
        framing: Framing,
        dialect: Option<&mut EvoLogicsEmulator>,
        stop: &AtomicBool,
        mut on_report: impl FnMut(&Report),
    ) -> (Ended, RunInfo) {
        let ports = &self.ports;
        let dialect = std::cell::RefCell::new(dialect);
        let (ended, info) = ports.drive(
            link,
            framing,
            stop,
            |link, report, info| {
                let to = report.from.other();
                match dialect.borrow_mut().as_deref_mut() {
                    Some(emulator) => {
                        let (to_receiver, to_sender) =
                            emulator.on_report(&report, link.model(report.from));
                        ports.write(to.index(), to_receiver, info);
                        ports.write(report.from.index(), to_sender, info);
                    }
                    None if report.fate.arrived() => {
                        ports.write(to.index(), report.bytes.clone(), info)
                    }
                    None => {}
                }
                on_report(&report);
                report.t_rx.filter(|_| report.fate.arrived())
            },
            |link, port, bytes, info| {
                let mut dialect = dialect.borrow_mut();
                let Some(emulator) = dialect.as_deref_mut() else {
                    return Some(bytes);
                };
                let side = side_of(port);
                let (packets, replies) = emulator.from_host(side, &bytes);
                ports.write(port, replies, info);
                for (data, kind) in packets {
                    let seq = link.offer(side, data);
                    emulator.sent(side, seq, kind);
                }
                None
            },
        );
        let ended = match ended {
            PortEnded::Stopped => Ended::Stopped,
            PortEnded::Closed { port, name, reason } => Ended::Closed {
                side: side_of(port),
                name,
                reason,
            },
        };
        (ended, info.into())
    }
}

/// Cuts one side's bytes into packets.
struct Framer {
    framing: Framing,
    deframer: Deframer,
    raw: Vec<u8>,
    last_byte: SimTime,
    skipped: u64,
}

impl Framer {
    fn new(framing: Framing) -> Framer {
        Framer {
            framing,
            deframer: Deframer::new(),
            raw: Vec::new(),
            last_byte: SimTime::ZERO,
            skipped: 0,
        }
    }

    /// Takes bytes that arrived at `t`; returns the packets they complete.
    fn push(&mut self, t: SimTime, bytes: &[u8]) -> Vec<Vec<u8>> {
        let mut packets = Vec::new();
        if let Framing::Raw { idle } = self.framing {
            if !self.raw.is_empty() && t.0.saturating_sub(self.last_byte.0) > idle.as_nanos() as u64
            {
                packets.push(std::mem::take(&mut self.raw));
            }
            self.raw.extend_from_slice(bytes);
            self.last_byte = t;
            return packets;
        }
        self.last_byte = t;
        self.deframer.push(bytes);
        self.drain(&mut packets);
        packets
    }

    fn drain(&mut self, packets: &mut Vec<Vec<u8>>) {
        while let Some(event) = self.deframer.next_event() {
            match event {
                DeframeEvent::Frame { frame, .. } => packets.push(frame.into_inner().to_vec()),
                DeframeEvent::Skipped { len, .. } => self.skipped += len,
                DeframeEvent::BadCrc { .. } | DeframeEvent::Truncated { .. } => {}
            }
        }
    }

    /// When the pending bytes are due to become a packet (raw) or be given up (frames).
    fn deadline(&self) -> Option<SimTime> {
        match self.framing {
            Framing::Raw { idle } => (!self.raw.is_empty())
                .then(|| SimTime(self.last_byte.0 + idle.as_nanos() as u64 + 1)),
            Framing::Frames { give_up } => (self.deframer.pending_bytes() > 0
                && !give_up.is_zero())
            .then(|| SimTime(self.last_byte.0 + give_up.as_nanos() as u64)),
        }
    }

    /// The packets completed by silence at `now`: a raw packet, or, for frames, those found
    /// after giving up a stalled incomplete frame.
    fn due(&mut self, now: SimTime) -> Vec<Vec<u8>> {
        if self.deadline().is_none_or(|deadline| deadline > now) {
            return Vec::new();
        }
        match self.framing {
            Framing::Raw { .. } => vec![std::mem::take(&mut self.raw)],
            Framing::Frames { .. } => {
                self.deframer.abandon_incomplete();
                let mut packets = Vec::new();
                self.drain(&mut packets);
                packets
            }
        }
    }
}

fn open_side(
    side: usize,
    label: &'static str,
    spec: PortSpec,
    inbox: Sender<Message>,
    rt: bool,
) -> Result<(String, Writer, Option<File>), OpenError> {
    let fail = |name: &str, reason: String| OpenError {
        side: label,
        name: name.to_string(),
        reason,
    };
    let (queue, outbox) = mpsc::sync_channel::<Vec<u8>>(WRITE_QUEUE_FRAMES);
    match spec {
        PortSpec::Pty => {
            let (master, slave, path) = open_pty().map_err(|e| fail("pty", e.to_string()))?;
            let master = Arc::new(master);
            let reader = Arc::clone(&master);
            spawn_reader(side, rt, false, inbox.clone(), move |buf| {
                (&*reader).read(buf)
            });
            spawn_writer(side, rt, inbox, outbox, move |bytes| {
                (&*master).write_all(bytes)
            });
            Ok((path, Writer { queue }, Some(slave)))
        }
        PortSpec::Serial { path, baud } => {
            let port = serialport::new(&path, baud)
                .timeout(Duration::from_millis(100))
                .open()
                .map_err(|e| {
                    let not_a_tty = crate::gll::not_a_terminal(&path);
                    fail(&path, not_a_tty.unwrap_or_else(|| e.to_string()))
                })?;
            let mut writer = port.try_clone().map_err(|e| fail(&path, e.to_string()))?;
            let mut reader = port;
            spawn_reader(side, rt, false, inbox.clone(), move |buf| reader.read(buf));
            spawn_writer(side, rt, inbox, outbox, move |bytes| {
                writer.write_all(bytes)?;
                writer.flush()
            });
            Ok((path, Writer { queue }, None))
        }
        PortSpec::Udp { bind, peer } => {
            let name = bind.to_string();
            let socket = UdpSocket::bind(bind).map_err(|e| fail(&name, e.to_string()))?;
            let reader = socket.try_clone().map_err(|e| fail(&name, e.to_string()))?;
            let peer = Arc::new(Mutex::new(peer));
            let learned = Arc::clone(&peer);
            let fixed = peer.lock().map(|p| p.is_some()).unwrap_or(false);
            spawn_reader(side, rt, true, inbox.clone(), move |buf| {
                let (n, from) = reader.recv_from(buf)?;
                if !fixed && let Ok(mut peer) = learned.lock() {
                    *peer = Some(from);
                }
                if n == 0 {
                    // An empty datagram is no packet (and 0 would read as end of file).
                    return Err(io::ErrorKind::Interrupted.into());
                }
                Ok(n)
            });
            spawn_writer(side, rt, inbox, outbox, move |bytes| {
                let target = peer.lock().ok().and_then(|p| *p);
                match target {
                    Some(addr) => socket.send_to(bytes, addr).map(|_| ()),
                    None => Ok(()), // nobody has spoken on this side yet: the packet is lost
                }
            });
            Ok((name, Writer { queue }, None))
        }
    }
}

/// A pseudo-terminal pair in raw mode: the master, the slave (kept open), the slave's path.
fn open_pty() -> nix::Result<(PtyMaster, File, String)> {
    let master = posix_openpt(OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_CLOEXEC)?;
    grantpt(&master)?;
    unlockpt(&master)?;
    let path = ptsname_r(&master)?;
    let slave = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(OFlag::O_NOCTTY.bits())
        .open(&path)
        .map_err(|e| nix::Error::from_raw(e.raw_os_error().unwrap_or(0)))?;
    let mut termios = tcgetattr(&slave)?;
    cfmakeraw(&mut termios);
    tcsetattr(&slave, SetArg::TCSANOW, &termios)?;
    Ok((master, slave, path))
}

fn spawn_reader(
    port: usize,
    rt: bool,
    datagram: bool,
    inbox: Sender<Message>,
    mut read: impl FnMut(&mut [u8]) -> io::Result<usize> + Send + 'static,
) {
    thread::spawn(move || {
        if rt {
            let _ = raise_priority();
        }
        let mut buf = vec![0u8; 65_536];
        loop {
            match read(&mut buf) {
                Ok(0) => {
                    let _ = inbox.send(Message::Closed {
                        port,
                        reason: "end of file (the other end closed)".into(),
                    });
                    return;
                }
                Ok(n) => {
                    let message = Message::Data {
                        port,
                        at: Instant::now(),
                        bytes: buf[..n].to_vec(),
                        datagram,
                    };
                    if inbox.send(message).is_err() {
                        return;
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut
                            | io::ErrorKind::Interrupted
                            | io::ErrorKind::WouldBlock
                    ) => {}
                Err(e) => {
                    let _ = inbox.send(Message::Closed {
                        port,
                        reason: format!("read failed: {e}"),
                    });
                    return;
                }
            }
        }
    });
}

fn spawn_writer(
    port: usize,
    rt: bool,
    inbox: Sender<Message>,
    outbox: Receiver<Vec<u8>>,
    mut write: impl FnMut(&[u8]) -> io::Result<()> + Send + 'static,
) {
    thread::spawn(move || {
        if rt {
            let _ = raise_priority();
        }
        for bytes in outbox {
            if let Err(e) = write(&bytes) {
                let _ = inbox.send(Message::Closed {
                    port,
                    reason: format!("write failed: {e}"),
                });
                return;
            }
        }
    });
}
