//! The real-time driver: a [`Link`] between two real transports ([`Endpoints`]), or a
//! [`Medium`] among N of them ([`Ports`]), on the monotonic clock.
//!
//! Each side is a device in the one grammar ([`DeviceSpec`], opened by [`crate::device::open`]):
//! a pseudo-terminal this process creates, an existing serial port (or someone else's
//! pseudo-terminal), a TCP connection, or a UDP socket. One thread per side reads bytes and stamps them
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
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender, SyncSender, TrySendError};
use std::thread;
use std::time::{Duration, Instant};

use super::channel::{Link, Report, Side};
use super::dialect::Emulator;
use super::medium::{Medium, MediumReport};
use super::sched::SimTime;
use crate::device::{self, DeviceSpec, ForeignDrops, OpenOptions};
use rovlink_base::stats::Quantiles;
use rovlink_wire::{DeframeEvent, Deframer};

/// Frames a side's writer may hold before deliveries to it are counted as not taken.
const WRITE_QUEUE_FRAMES: usize = 1024;

/// Longest sleep of the main loop when nothing is scheduled, so a stop is seen promptly.
const IDLE_POLL: Duration = Duration::from_millis(200);

/// How the sides are opened: the baud rate of a bare serial path, and whether the threads ask
/// for real-time scheduling ([`raise_priority`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SideOptions {
    /// The baud rate of a side given as a path (`serial:PATH:BAUD` carries its own).
    pub baud: u32,
    /// Run the threads under real-time scheduling.
    pub realtime_priority: bool,
}

impl SideOptions {
    /// What the one opener is asked: pseudo-terminals offered, serial reads waiting 100 ms at
    /// most, sockets blocking, `tcpin:` waiting for its peer.
    fn open_options(&self) -> OpenOptions {
        OpenOptions {
            baud: self.baud,
            serial_timeout: Duration::from_millis(100),
            pty: true,
            ..OpenOptions::default()
        }
    }
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

impl Ended {
    /// What a run that ended when a side closed says of it (none when it was stopped).
    pub fn closed_line(&self) -> Option<String> {
        match self {
            Ended::Stopped => None,
            Ended::Closed { side, name, reason } => {
                Some(format!("side {} ({name}) closed: {reason}", side.name()))
            }
        }
    }
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
    /// Datagrams dropped because they came from someone other than the side's UDP peer.
    pub foreign_datagrams_dropped: [u64; 2],
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

impl PortEnded {
    /// What a run that ended when a port closed says of it (ports numbered from 1; none when
    /// it was stopped).
    pub fn closed_line(&self) -> Option<String> {
        match self {
            PortEnded::Stopped => None,
            PortEnded::Closed { port, name, reason } => {
                Some(format!("port {} ({name}) closed: {reason}", port + 1))
            }
        }
    }
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
    /// Datagrams dropped because they came from someone other than the port's UDP peer.
    pub foreign_datagrams_dropped: Vec<u64>,
    /// How late each delivery was handed to its writer after the model's time.
    pub lateness: Quantiles,
}

impl PortsInfo {
    fn new(ports: usize) -> PortsInfo {
        PortsInfo {
            not_taken: vec![0; ports],
            bytes_read: vec![0; ports],
            bytes_skipped: vec![0; ports],
            foreign_datagrams_dropped: vec![0; ports],
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
            foreign_datagrams_dropped: two(&info.foreign_datagrams_dropped),
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
    /// Each UDP port's count of datagrams that were not its peer's (none for other ports).
    foreign: Vec<Option<ForeignDrops>>,
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
    /// Opens every port (at most [`MAX_PORTS`]) and starts their reader and writer threads.
    pub fn open(specs: &[DeviceSpec], options: SideOptions) -> Result<Ports, OpenError> {
        Ports::open_labelled(specs, &PORT_LABELS, options)
    }

    fn open_labelled(
        specs: &[DeviceSpec],
        labels: &[&'static str],
        options: SideOptions,
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
        let mut foreign = Vec::new();
        for (port, (spec, label)) in specs.iter().zip(labels).enumerate() {
            let side = open_side(port, label, spec, options, sender.clone())?;
            names.push(side.name);
            writers.push(side.writer);
            slaves.extend(side.keep);
            foreign.push(side.foreign);
        }
        Ok(Ports {
            names,
            writers,
            inbox,
            _slaves: slaves,
            foreign,
            realtime_priority: options.realtime_priority,
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

    /// The loop both drivers share ([`Ports::drive_loop`]), with each UDP port's count of
    /// datagrams dropped because they were not its peer's.
    fn drive<A: Air>(
        &self,
        air: &mut A,
        framing: Framing,
        stop: &AtomicBool,
        deliver: impl FnMut(&mut A, A::Report, &mut PortsInfo) -> Option<SimTime>,
        receive: impl FnMut(&mut A, usize, Vec<u8>, &mut PortsInfo) -> Option<Vec<u8>>,
    ) -> (PortEnded, PortsInfo) {
        let (ended, mut info) = self.drive_loop(air, framing, stop, deliver, receive);
        for (count, foreign) in info.foreign_datagrams_dropped.iter_mut().zip(&self.foreign) {
            *count = foreign.as_ref().map_or(0, ForeignDrops::count);
        }
        (ended, info)
    }

    /// The loop: `deliver` handles a report (and returns its arrival time, for the lateness);
    /// `receive` may take bytes a port read before framing (returning none) or hand them on.
    fn drive_loop<A: Air>(
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
    /// Opens both sides and starts their reader and writer threads.
    pub fn open(specs: &[DeviceSpec; 2], options: SideOptions) -> Result<Endpoints, OpenError> {
        let ports = Ports::open_labelled(specs, &["A", "B"], options)?;
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
    /// a modem's commands (see [`Emulator`]) instead of sending bare packets (`framing` is then
    /// unused).
    /// The run ends ([`Ended::Stopped`]) within 200 ms of `stop` being set.
    pub fn run(
        &self,
        link: &mut Link,
        framing: Framing,
        dialect: Option<&mut dyn Emulator>,
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
                        let notes = emulator.on_report(&report, link.model(report.from));
                        ports.write(to.index(), notes.to_receiver, info);
                        ports.write(report.from.index(), notes.to_sender, info);
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
                let replies = emulator.host_wrote(side, &bytes, &mut |data| link.offer(side, data));
                ports.write(port, replies, info);
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

/// One port opened by [`open_side`].
struct OpenSide {
    /// Its name (for a new pseudo-terminal, the path programs open).
    name: String,
    /// Where its deliveries go.
    writer: Writer,
    /// A pseudo-terminal's slave to keep open.
    keep: Option<File>,
    /// A UDP port's count of datagrams that were not its peer's.
    foreign: Option<ForeignDrops>,
}

/// Opens one port with the one opener and starts its reader and writer threads.
fn open_side(
    port: usize,
    label: &'static str,
    spec: &DeviceSpec,
    options: SideOptions,
    inbox: Sender<Message>,
) -> Result<OpenSide, OpenError> {
    let opened = device::open(spec, &options.open_options()).map_err(|e| OpenError {
        side: label,
        name: e.device,
        reason: e.error.to_string(),
    })?;
    let name = opened.name;
    let halves = opened.io.split().map_err(|e| OpenError {
        side: label,
        name: name.clone(),
        reason: e.to_string(),
    })?;
    let rt = options.realtime_priority;
    let (queue, outbox) = mpsc::sync_channel::<Vec<u8>>(WRITE_QUEUE_FRAMES);
    let mut reader = halves.reader;
    spawn_reader(port, rt, halves.datagrams, inbox.clone(), move |buf| {
        reader.read(buf)
    });
    let mut writer = halves.writer;
    spawn_writer(port, rt, inbox, outbox, move |bytes| {
        writer.write_all(bytes)?;
        writer.flush()
    });
    Ok(OpenSide {
        name,
        writer: Writer { queue },
        keep: halves.keep,
        foreign: halves.foreign,
    })
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
                Err(e) if rovlink_base::io::nothing_yet(&e) => {}
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
