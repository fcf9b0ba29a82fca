//! The operator's side of the protocol, the TDMA master: one message per inter-packet gap.
//!
//! Each slot carries the joystick state as a Velocity order, or the high-level order at the head
//! of the queue, resent with the same OID until the ROV's EOID toggles (the acknowledgement).
//! ROV replies feed the image reassembly: a bitmap of received trunks, RIT = the lowest missing
//! trunk, EISN toggled when the image is complete, IC when the ROV cancels an image.

use std::collections::VecDeque;

use crate::{Event, emit};
use rovlink_link::SimTime;
use rovlink_wire::frame::{ADDR_OPERATOR, Frame};
use rovlink_wire::operator::{self, Order, Velocity};
use rovlink_wire::rov::Status;
use rovlink_wire::{Message, MessageRepr, Nav};

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

/// A Velocity order's axis (-127..=127) as percent of full thrust (-100..=100).
pub fn thrust_percent(axis: i8) -> f64 {
    f64::from(axis) * 100.0 / 127.0
}

/// Percent of full thrust as a Velocity order's axis, clamped to -100..=100 % first.
pub fn thrust_axis(percent: f64) -> i8 {
    (percent.clamp(-100.0, 100.0) * 127.0 / 100.0).round() as i8
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
    /// The mode buttons sent with the joystick: arm, disarm, navigation mode.
    modes: (bool, bool, Nav),
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
    /// Images carry parity trunks ([`rovlink_debt::fec`]): an image is complete once its parity
    /// can recover what is missing.
    parity: bool,
    /// The latest ROV status seen.
    pub last_status: Option<rovlink_wire::rov::BasicStatus>,
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
            modes: (true, false, Nav::Manual),
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
            parity: false,
            last_status: None,
            events: Vec::new(),
        }
    }

    /// The same operator expecting images with parity trunks (`tdma-run --fec`): it completes
    /// an image as soon as the trunks it has recover the rest, and its RIT asks only while
    /// they do not.
    pub fn with_parity(mut self, parity: bool) -> Operator {
        self.parity = parity;
        self
    }

    /// The same operator with its first slot at `first` (a vehicle's place in a multi-vehicle
    /// cycle), then one every IPG.
    pub fn first_slot_at(mut self, first: SimTime) -> Operator {
        self.next_slot = first;
        self
    }

    /// Sets the joystick.
    pub fn set_joystick(&mut self, joystick: Joystick) {
        self.joystick = joystick;
    }

    /// Sets the mode buttons the Velocity orders carry (from the start: arm, manual).
    pub fn set_modes(&mut self, arm: bool, disarm: bool, nav: Nav) {
        self.modes = (arm, disarm, nav);
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
                let oid = match self.head_oid {
                    Some(oid) => oid,
                    None => {
                        self.events.push(Event::OrderSent { index, order });
                        *self.head_oid.insert(self.last_eoid)
                    }
                };
                (order, oid, SlotContent::Order(index))
            }
            None => {
                let order = Order::Velocity(Velocity {
                    vx: thrust_axis(self.joystick.vx),
                    vy: thrust_axis(self.joystick.vy),
                    vz: thrust_axis(self.joystick.vz),
                    vyaw: thrust_axis(self.joystick.vyaw),
                    arm: self.modes.0,
                    disarm: self.modes.1,
                    nav: self.modes.2,
                });
                // OID is ignored for Velocity, except with CLO: the ROV cancels only when OID
                // is its last announced EOID (so a CLO can never cancel a newer order).
                (order, self.last_eoid, SlotContent::Velocity)
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
        let mut shown = repr.clone();
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
            // Cancelled (LOC), or nothing left to cancel (RD): the request is done.
            if self.cancel && status.loc {
                self.events.push(Event::CancelConfirmed);
            }
            if status.loc || status.rd {
                self.cancel = false;
            }
            self.last_status = Some(status);
            if let Message::Rov(rov) = &mut shown.message {
                rov.trunk.clear();
            }
            self.events.push(Event::Status(shown));
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
        let new = self.bitmap & (1 << k) == 0 || (msg.lt && self.count.is_none());
        self.trunks[k] = msg.trunk;
        self.bitmap |= 1 << k;
        if msg.lt {
            self.count = Some(k + 1);
        }
        if new {
            let whole = usize::from(self.rit()).min(self.count.unwrap_or(64));
            let whole = if self.bitmap == u64::MAX { 64 } else { whole };
            self.events.push(Event::ImageProgress {
                trunks: self.bitmap.count_ones() as usize,
                of: self.count,
                prefix: self.trunks[..whole].concat(),
            });
        }
        if let Some(n) = self.count {
            let all = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
            let stream = if self.bitmap & all == all {
                Some(self.trunks[..n].concat())
            } else if new && self.parity {
                self.recovered(n)
            } else {
                None
            };
            if let Some(stream) = stream {
                self.events.push(Event::ImageCompleted(stream));
                self.eisn = !self.eisn;
                self.bitmap = 0;
                self.count = None;
            }
        }
    }

    /// The whole stream of an image of `n` trunks with some missing, when its parity recovers
    /// them (header included).
    fn recovered(&self, n: usize) -> Option<Vec<u8>> {
        let trunk = self.trunks[n - 1].len();
        let missing: Vec<usize> = (0..n).filter(|&i| self.bitmap & (1 << i) == 0).collect();
        // Fewer trunks than data trunks recover nothing: skip the decoding attempt.
        if trunk == 0 || missing.len() * 2 > n {
            return None;
        }
        let mut stream = Vec::with_capacity(n * trunk);
        for (i, t) in self.trunks[..n].iter().enumerate() {
            if self.bitmap & (1 << i) != 0 && t.len() == trunk {
                stream.extend_from_slice(t);
            } else {
                stream.resize(stream.len() + trunk, 0);
            }
        }
        rovlink_debt::fec::repair(&stream, trunk, &missing).whole()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ImageSettings;
    use crate::rov::{Rov, RovConfig};
    use rovlink_wire::operator::{ImageOrder, Roi};

    /// Both engines with nothing between them but `lose`, which drops the ROV's reply to slot k
    /// when it returns true.
    struct Pair {
        operator: Operator,
        rov: Rov,
        t: SimTime,
        events: Vec<Event>,
    }

    impl Pair {
        fn new(settings: ImageSettings) -> Pair {
            let cfg = RovConfig {
                settings,
                ..RovConfig::default()
            };
            Pair {
                operator: Operator::new(1, 640_000_000),
                rov: Rov::new(
                    cfg,
                    [1.0, 0.0, 0.0],
                    vec![crate::camera::builtin_picture(64, 48, 1)],
                ),
                t: SimTime::ZERO,
                events: Vec::new(),
            }
        }

        /// One slot; returns the ROV's reply as parsed.
        fn slot(&mut self, lose_reply: bool) -> rovlink_wire::rov::Repr {
            let (frame, _) = self.operator.poll(self.t);
            let reply = self.rov.receive(self.t, &frame).expect("the ROV answers");
            self.events.extend(self.rov.take_events());
            let t = self.t.after_secs(0.5);
            if !lose_reply {
                self.operator.receive(t, &reply);
                self.events.extend(self.operator.take_events());
            }
            self.t = self.t.after_secs(0.64);
            let frame = Frame::new_checked(&reply[..]).unwrap();
            match MessageRepr::parse(&frame).unwrap().message {
                Message::Rov(r) => r,
                other => panic!("{other:?}"),
            }
        }

        fn completed(&self) -> usize {
            self.events
                .iter()
                .filter(|e| matches!(e, Event::ImageCompleted(_)))
                .count()
        }
    }

    fn small() -> ImageSettings {
        ImageSettings {
            size_bytes: 390,
            ..ImageSettings::default()
        }
    }

    #[test]
    fn a_lost_trunk_is_asked_for_by_rit_and_resent() {
        let mut pair = Pair::new(small());
        // Ten trunks; the reply carrying trunk 3 is lost.
        let mut sent = Vec::new();
        for k in 0..10 {
            sent.push(pair.slot(k == 3).itsn);
        }
        assert_eq!(sent, (0..10).collect::<Vec<u8>>());
        assert_eq!(pair.completed(), 0);
        assert_eq!(pair.operator.rit(), 3);
        let resend = pair.slot(false);
        assert_eq!(
            resend.itsn, 3,
            "the first pass is over: RIT's trunk comes next"
        );
        assert_eq!(pair.completed(), 1);
        // The next image starts at trunk 0 with the ISN toggled.
        let next = pair.slot(false);
        assert_eq!((next.itsn, next.ft, next.isn), (0, true, true));
    }

    #[test]
    fn with_parity_lost_trunks_need_no_resend_and_the_header_comes_back() {
        // 1000 bytes rounded up to 26 trunks, 20 % parity: 5 parity trunks after 21 data
        // trunks.
        let settings = ImageSettings {
            size_bytes: 1000,
            fec_percent: 20,
            ..ImageSettings::default()
        };
        let mut pair = Pair::new(settings);
        pair.operator = Operator::new(1, 640_000_000).with_parity(true);
        let lost = [0, 7, 13, 21];
        let mut sent = Vec::new();
        for k in 0..26 {
            sent.push(pair.slot(lost.contains(&k)).itsn);
        }
        assert_eq!(sent, (0..26).collect::<Vec<u8>>());
        assert_eq!(
            pair.completed(),
            1,
            "complete at the last trunk, nothing resent"
        );
        let stream = pair
            .events
            .iter()
            .find_map(|e| match e {
                Event::ImageCompleted(s) => Some(s.clone()),
                _ => None,
            })
            .unwrap();
        assert_eq!(stream.len(), 26 * 39);
        let header = rovlink_debt::Header::read(&stream).unwrap();
        assert_eq!(header.fec.unwrap().parity_trunks, 5);
        assert!(rovlink_debt::decode(&stream).is_ok());
        // The next image starts at once.
        let next = pair.slot(false);
        assert_eq!((next.itsn, next.ft, next.isn), (0, true, true));
        // More lost than parity: RIT asks for the first missing trunk, and its resend
        // completes the image.
        let mut pair = Pair::new(settings);
        pair.operator = Operator::new(1, 640_000_000).with_parity(true);
        let lost = [2, 3, 4, 5, 6, 9];
        for k in 0..26 {
            pair.slot(lost.contains(&k));
        }
        assert_eq!(pair.completed(), 0);
        assert_eq!(pair.operator.rit(), 2);
        assert_eq!(pair.slot(false).itsn, 2);
        assert_eq!(pair.completed(), 1);
    }

    #[test]
    fn new_image_settings_cancel_the_image_in_flight_with_ci_and_ic() {
        let mut pair = Pair::new(small());
        for _ in 0..4 {
            pair.slot(false);
        }
        pair.operator.push_order(Order::ImageSettings(ImageOrder {
            roi: Roi {
                x0: 0,
                y0: 0,
                x1: 0,
                y1: 0,
            },
            roi_shift: 3,
            gray: true,
            scale: 0,
            size_bytes: 195,
            trunk_bytes: 39,
        }));
        let cancelled = pair.slot(false);
        assert!(cancelled.ci && cancelled.trunk.is_empty(), "{cancelled:?}");
        assert!(pair.events.contains(&Event::ImageCancelled));
        // The operator answers IC; the ROV starts the new 5-trunk image.
        let mut trunks = Vec::new();
        while pair.completed() == 0 {
            let r = pair.slot(false);
            assert!(!r.ci);
            trunks.push(r.itsn);
            assert!(trunks.len() < 10, "{trunks:?}");
        }
        assert_eq!(trunks, vec![0, 1, 2, 3, 4]);
        assert!(pair.events.iter().any(|e| matches!(
            e,
            Event::ImageStarted {
                trunks: 5,
                bytes: 195
            }
        )));
    }

    #[test]
    fn clo_cancels_the_order_in_execution_and_only_that() {
        let mut pair = Pair::new(small());
        pair.operator.push_order(Order::GoTo {
            x_cm: 400,
            y_cm: 0,
            z_cm: 0,
            heading_deg: 0,
        });
        let reply = pair.slot(false);
        let Status::Basic(status) = reply.status else {
            panic!()
        };
        assert!(
            !status.rd && status.eoid,
            "executing, EOID toggled: {status:?}"
        );
        assert!(pair.rov.pose(0.0).goal_m.is_some());
        pair.operator.cancel();
        let reply = pair.slot(false);
        let Status::Basic(status) = reply.status else {
            panic!()
        };
        assert!(status.loc && status.rd, "{status:?}");
        assert!(pair.events.contains(&Event::OrderCancelled));
        assert!(pair.rov.pose(0.0).goal_m.is_none());
        // The request is over: a later order runs uncancelled.
        pair.operator.push_order(Order::GoTo {
            x_cm: 200,
            y_cm: 0,
            z_cm: 0,
            heading_deg: 0,
        });
        pair.slot(false);
        pair.slot(false);
        assert!(pair.rov.pose(0.0).goal_m.is_some());
        assert_eq!(
            pair.events
                .iter()
                .filter(|e| matches!(e, Event::OrderCancelled))
                .count(),
            1
        );
    }

    #[test]
    fn a_clo_with_a_stale_oid_does_not_cancel() {
        let mut rov = Rov::new(RovConfig::default(), [0.0; 3], Vec::new());
        let goto = |oid, clo| {
            emit(
                ADDR_OPERATOR,
                1,
                Message::Operator(operator::Repr {
                    oid,
                    clo,
                    eisn: false,
                    ic: false,
                    rit: 0,
                    order: Order::GoTo {
                        x_cm: 300,
                        y_cm: 0,
                        z_cm: 0,
                        heading_deg: 0,
                    },
                }),
            )
        };
        // EOID starts at 0: the order with OID 0 runs and EOID becomes 1.
        rov.receive(SimTime::ZERO, &goto(false, false));
        assert!(rov.pose(0.0).goal_m.is_some());
        // A CLO carrying the old OID (0) refers to an earlier state: ignored.
        rov.receive(SimTime(1), &goto(false, true));
        assert!(rov.pose(0.0).goal_m.is_some());
        assert!(!rov.take_events().contains(&Event::OrderCancelled));
    }

    #[test]
    fn hold_heading_turns_heading_hold_on_and_off() {
        let mut pair = Pair::new(small());
        pair.operator.push_order(Order::HoldHeading {
            heading_deg: 90,
            enable: true,
        });
        let Status::Basic(on) = pair.slot(false).status else {
            panic!()
        };
        assert!(on.hh);
        pair.operator.push_order(Order::HoldHeading {
            heading_deg: 0,
            enable: false,
        });
        pair.slot(false);
        let Status::Basic(off) = pair.slot(false).status else {
            panic!()
        };
        assert!(!off.hh);
    }
}
