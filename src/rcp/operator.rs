//! The operator's side of the protocol, the TDMA master: one message per inter-packet gap.
//!
//! Each slot carries the joystick state as a Velocity order, or the high-level order at the head
//! of the queue, resent with the same OID until the ROV's EOID toggles (the acknowledgement).
//! ROV replies feed the image reassembly: a bitmap of received trunks, RIT = the lowest missing
//! trunk, EISN toggled when the image is complete, IC when the ROV cancels an image.

use std::collections::VecDeque;

use super::{Event, emit};
use crate::link::SimTime;
use crate::wire::frame::{ADDR_OPERATOR, Frame};
use crate::wire::operator::{self, Order};
use crate::wire::rov::Status;
use crate::wire::{Message, MessageRepr, Nav};

/// Joystick state, percent of full thrust (-100..=100).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Joystick {
    /// Surge.
    pub vx: f64,
    /// Sway.
    pub vy: f64,
    /// Heave.
    pub vz: f64,
    /// Yaw.
    pub vyaw: f64,
}

/// What a slot's frame carries, for the caller's accounting.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlotContent {
    /// The joystick.
    Velocity,
    /// High-level order number `index` (in the order they were queued).
    Order(u64),
}

/// The operator engine.
pub struct Operator {
    rov_address: u8,
    ipg_ns: u64,
    next_slot: SimTime,
    joystick: Joystick,
    orders: VecDeque<(u64, Order)>,
    next_index: u64,
    /// OID the head order was first sent with.
    head_oid: Option<bool>,
    last_eoid: bool,
    cancel: bool,
    eisn: bool,
    ic: bool,
    bitmap: u64,
    trunks: Vec<Vec<u8>>,
    count: Option<usize>,
    /// The latest ROV status seen.
    pub last_status: Option<crate::wire::rov::BasicStatus>,
    events: Vec<Event>,
}

impl Operator {
    /// An operator talking to `rov_address`, one message every `ipg_ns`, the first at time 0.
    pub fn new(rov_address: u8, ipg_ns: u64) -> Operator {
        Operator {
            rov_address,
            ipg_ns: ipg_ns.max(1),
            next_slot: SimTime::ZERO,
            joystick: Joystick::default(),
            orders: VecDeque::new(),
            next_index: 0,
            head_oid: None,
            last_eoid: false,
            cancel: false,
            eisn: false,
            ic: false,
            bitmap: 0,
            trunks: vec![Vec::new(); 64],
            count: None,
            last_status: None,
            events: Vec::new(),
        }
    }

    /// Sets the joystick.
    pub fn set_joystick(&mut self, joystick: Joystick) {
        self.joystick = joystick;
    }

    /// Queues a high-level order; returns its index.
    pub fn push_order(&mut self, order: Order) -> u64 {
        let index = self.next_index;
        self.next_index += 1;
        self.orders.push_back((index, order));
        index
    }

    /// Asks the ROV to cancel the order it is executing.
    pub fn cancel(&mut self) {
        self.cancel = true;
    }

    /// Takes the events since the last call.
    pub fn take_events(&mut self) -> Vec<Event> {
        std::mem::take(&mut self.events)
    }

    /// The next slot.
    pub fn poll_at(&self) -> SimTime {
        self.next_slot
    }

    /// The lowest trunk not yet received.
    fn rit(&self) -> u8 {
        (!self.bitmap).trailing_zeros().min(63) as u8
    }

    /// The frame of the slot due at `now` (call when `now >= poll_at()`).
    pub fn poll(&mut self, now: SimTime) -> (Vec<u8>, SlotContent) {
        while self.next_slot <= now {
            self.next_slot = SimTime(self.next_slot.0 + self.ipg_ns);
        }
        let (order, oid, content) = match self.orders.front() {
            Some(&(index, order)) => {
                let oid = *self.head_oid.get_or_insert(self.last_eoid);
                (order, oid, SlotContent::Order(index))
            }
            None => {
                let scale = |v: f64| (v.clamp(-100.0, 100.0) * 127.0 / 100.0).round() as i8;
                let order = Order::Velocity {
                    vx: scale(self.joystick.vx),
                    vy: scale(self.joystick.vy),
                    vz: scale(self.joystick.vz),
                    vyaw: scale(self.joystick.vyaw),
                    arm: true,
                    disarm: false,
                    nav: Nav::Manual,
                };
                // A cancel refers to the last acknowledged order: OID = !EOID.
                (order, !self.last_eoid, SlotContent::Velocity)
            }
        };
        let message = Message::Operator(operator::Repr {
            oid,
            clo: self.cancel,
            eisn: self.eisn,
            ic: self.ic,
            rit: self.rit(),
            order,
        });
        (emit(ADDR_OPERATOR, self.rov_address, message), content)
    }

    /// Takes a ROV frame received at `now`.
    pub fn receive(&mut self, now: SimTime, bytes: &[u8]) {
        let _ = now;
        let Ok(frame) = Frame::new_checked(bytes) else {
            return;
        };
        let Ok(repr) = MessageRepr::parse(&frame) else {
            return;
        };
        let Message::Rov(msg) = repr.message else {
            return;
        };
        if repr.src != self.rov_address {
            return;
        }
        if let Status::Basic(status) = msg.status {
            self.last_eoid = status.eoid;
            if let (Some(oid), Some(&(index, _))) = (self.head_oid, self.orders.front())
                && status.eoid != oid
            {
                self.orders.pop_front();
                self.head_oid = None;
                self.events.push(Event::OrderAcknowledged(index));
            }
            if status.loc {
                self.cancel = false;
            }
            self.last_status = Some(status);
        }
        if msg.ci {
            self.ic = true;
            self.bitmap = 0;
            self.count = None;
            return;
        }
        self.ic = false;
        if msg.trunk.is_empty() || msg.isn != self.eisn || msg.itsn > 63 {
            return;
        }
        let k = usize::from(msg.itsn);
        self.trunks[k] = msg.trunk;
        self.bitmap |= 1 << k;
        if msg.lt {
            self.count = Some(k + 1);
        }
        if let Some(n) = self.count {
            let all = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
            if self.bitmap & all == all {
                let stream: Vec<u8> = self.trunks[..n].concat();
                self.events.push(Event::ImageCompleted(stream));
                self.eisn = !self.eisn;
                self.bitmap = 0;
                self.count = None;
            }
        }
    }
}
