//! Where the operator's orders come from: a script played in time, or a live console (JSON
//! Lines on a pipe, a Foxglove client), all as [`OrderSource`]s the operator's harness drains.
//!
//! A source yields [`Live`] orders: the joystick state (kept until the next one), a high-level
//! order (queued, sent at the next free slot, resent until acknowledged) or a cancel. A
//! scripted source knows when its next order is due ([`OrderSource::next_at`]), so virtual
//! time jumps to it; a live one does not, and is drained at every slot.

use crate::config::{JoystickChange, Waypoint};
use crate::operator::Joystick;
use rovlink_link::SimTime;
use rovlink_wire::Nav;
use rovlink_wire::operator::Order;

/// One thing the operator does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Live {
    /// The joystick and the mode buttons, kept until the next.
    Joystick {
        /// Thrust, percent of full.
        joystick: Joystick,
        /// Asks to arm.
        arm: bool,
        /// Asks to disarm.
        disarm: bool,
        /// The navigation mode asked for.
        nav: Nav,
    },
    /// A high-level order (GoTo, ImageSettings, HoldHeading).
    Order(Order),
    /// Cancel the order in execution (CLO).
    Cancel,
}

impl Live {
    /// The joystick as the scripts give it: armed, manual.
    pub fn scripted_joystick(joystick: Joystick) -> Live {
        Live::Joystick {
            joystick,
            arm: true,
            disarm: false,
            nav: Nav::Manual,
        }
    }
}

/// Why a console line is not an order.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LiveError {
    /// Not JSON, a field missing or out of range (wire.md's order JSON).
    #[error(transparent)]
    Json(#[from] rovlink_wire::json::JsonError),
    /// An order type a console cannot give (`unknown`).
    #[error(
        "field type: expected velocity, goto, image_settings, hold_heading or cancel, found {0}"
    )]
    Kind(String),
}

impl Live {
    /// Reads one console line: an order object in wire.md's JSON form (the `order` of an
    /// operator message, e.g. `{"type":"goto","x_cm":300,"y_cm":0,"z_cm":50,"heading_deg":90}`)
    /// or `{"type":"cancel"}`. Other fields (such as `t_s`) are ignored.
    pub fn parse(line: &str) -> Result<Live, LiveError> {
        Live::from_object(&object_of(line)?)
    }

    /// [`Live::parse`] of an object already read.
    pub fn from_object(
        map: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<Live, LiveError> {
        match map.get("type").and_then(|t| t.as_str()) {
            Some("cancel") => return Ok(Live::Cancel),
            Some("velocity" | "goto" | "image_settings" | "hold_heading") | None => {}
            Some(_) => {
                let found = map
                    .get("type")
                    .map_or_else(String::new, rovlink_wire::json::show);
                return Err(LiveError::Kind(found));
            }
        }
        match rovlink_wire::json::parse_order(map)? {
            Order::Velocity(v) => {
                let [vx, vy, vz, vyaw] = v.axes().map(crate::operator::thrust_percent);
                Ok(Live::Joystick {
                    joystick: Joystick { vx, vy, vz, vyaw },
                    arm: v.arm,
                    disarm: v.disarm,
                    nav: v.nav,
                })
            }
            Order::Unknown { .. } => Err(LiveError::Kind("\"unknown\"".into())),
            order => Ok(Live::Order(order)),
        }
    }
}

/// A console line as a JSON object: the syntax error, or what it is when it is not an object.
pub fn object_of(
    line: &str,
) -> Result<serde_json::Map<String, serde_json::Value>, rovlink_wire::json::JsonError> {
    use rovlink_wire::json::JsonError;
    let value: serde_json::Value =
        rovlink_base::strict_json::from_str(line).map_err(|e| JsonError::Syntax {
            column: e.column(),
            message: e.to_string(),
        })?;
    match value {
        serde_json::Value::Object(map) => Ok(map),
        other => Err(JsonError::BadValue {
            field: "(line)".into(),
            expected: "a JSON object".into(),
            found: rovlink_wire::json::show(&other),
        }),
    }
}

/// Orders as they become due.
pub trait OrderSource: Send {
    /// The orders due at or before `now`, in the order they were given.
    fn poll(&mut self, now: SimTime) -> Vec<Live>;
    /// When the next order is due, if the source knows (a script); `None` for a live source
    /// or one that has nothing more.
    fn next_at(&self) -> Option<SimTime> {
        None
    }
    /// What went wrong since the last call (a bad line, skipped), one line each.
    fn take_warnings(&mut self) -> Vec<String> {
        Vec::new()
    }
    /// [`OrderSource::poll`], each order with the vehicle it names (a console line's
    /// `"vehicle": N`); `None` for the default vehicle. A source that names no vehicle keeps
    /// this default.
    fn poll_addressed(&mut self, now: SimTime) -> Vec<(Option<u8>, Live)> {
        self.poll(now)
            .into_iter()
            .map(|live| (None, live))
            .collect()
    }
}

/// A script: joystick changes and GoTo waypoints at their times.
pub struct Script {
    /// (time, vehicle named, order), sorted by time (stable: a joystick change before a
    /// waypoint at the same instant, as the sessions always played them).
    items: Vec<(SimTime, Option<u8>, Live)>,
    next: usize,
}

impl Script {
    /// The joystick changes and waypoints of a session, each at its time.
    pub fn new(script: &[JoystickChange], waypoints: &[Waypoint]) -> Script {
        let items: Vec<(SimTime, Live)> = script
            .iter()
            .map(|c| {
                (
                    SimTime::from_secs_f64(c.t_s),
                    Live::scripted_joystick(c.joystick),
                )
            })
            .chain(waypoints.iter().map(|w| {
                (
                    SimTime::from_secs_f64(w.t_s),
                    Live::Order(goto_order(w.position_m, w.heading_deg)),
                )
            }))
            .collect();
        Script::timed(items)
    }

    /// Orders at given times (a test's, or a file's lines with their `t_s`).
    pub fn timed(items: Vec<(SimTime, Live)>) -> Script {
        Script::addressed(items.into_iter().map(|(t, live)| (t, None, live)).collect())
    }

    /// Orders at given times, each with the vehicle it names (`None`: the default one).
    pub fn addressed(mut items: Vec<(SimTime, Option<u8>, Live)>) -> Script {
        items.sort_by_key(|(t, _, _)| *t);
        Script { items, next: 0 }
    }
}

impl OrderSource for Script {
    fn poll(&mut self, now: SimTime) -> Vec<Live> {
        self.poll_addressed(now)
            .into_iter()
            .map(|(_, live)| live)
            .collect()
    }

    fn next_at(&self) -> Option<SimTime> {
        self.items.get(self.next).map(|(t, _, _)| *t)
    }

    fn poll_addressed(&mut self, now: SimTime) -> Vec<(Option<u8>, Live)> {
        let start = self.next;
        while self.items.get(self.next).is_some_and(|(t, _, _)| *t <= now) {
            self.next += 1;
        }
        self.items[start..self.next]
            .iter()
            .map(|(_, vehicle, live)| (*vehicle, *live))
            .collect()
    }
}

/// The operator's sources shared by several vehicles: [`split_by_vehicle`]'s state.
struct Shared {
    sources: Vec<Box<dyn OrderSource>>,
    vehicles: Vec<u8>,
    /// Orders taken from the sources, not yet polled by their vehicle's tap, per vehicle.
    queues: Vec<Vec<Live>>,
    warnings: Vec<String>,
}

impl Shared {
    /// Drains every source due by `now` into the vehicles' queues.
    fn drain(&mut self, now: SimTime) {
        for source in &mut self.sources {
            self.warnings.extend(source.take_warnings());
            for (vehicle, live) in source.poll_addressed(now) {
                let target = match vehicle {
                    None => Some(0),
                    Some(v) => self.vehicles.iter().position(|&w| w == v),
                };
                match target.and_then(|k| self.queues.get_mut(k)) {
                    Some(queue) => queue.push(live),
                    None if self.warnings.len() < MAX_SPLIT_WARNINGS => {
                        self.warnings.push(format!(
                            "an order for vehicle {}: expected one of {:?}, dropped",
                            vehicle.unwrap_or(0),
                            self.vehicles
                        ));
                    }
                    None => {}
                }
            }
        }
    }
}

/// The most warnings [`split_by_vehicle`] keeps between two takes of its own (orders for a
/// vehicle not in the network).
const MAX_SPLIT_WARNINGS: usize = 1000;

/// One vehicle's view of the shared sources.
struct Tap {
    shared: std::sync::Arc<std::sync::Mutex<Shared>>,
    index: usize,
}

impl Tap {
    fn shared(&self) -> std::sync::MutexGuard<'_, Shared> {
        self.shared
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl OrderSource for Tap {
    fn poll(&mut self, now: SimTime) -> Vec<Live> {
        let index = self.index;
        let mut shared = self.shared();
        shared.drain(now);
        shared
            .queues
            .get_mut(index)
            .map(std::mem::take)
            .unwrap_or_default()
    }

    fn next_at(&self) -> Option<SimTime> {
        self.shared()
            .sources
            .iter()
            .filter_map(|s| s.next_at())
            .min()
    }

    fn take_warnings(&mut self) -> Vec<String> {
        // The first vehicle's end says them, once.
        if self.index == 0 {
            std::mem::take(&mut self.shared().warnings)
        } else {
            Vec::new()
        }
    }
}

/// The operator's order sources shared among `vehicles` (one source each, in the order of
/// `vehicles`): an order naming a vehicle (`"vehicle": N`) goes to that vehicle's source, one
/// naming none to the first vehicle's; one naming a vehicle not in `vehicles` is dropped with
/// a warning. Every source is drained whenever any vehicle's source is polled, so the orders
/// keep their order per vehicle.
pub fn split_by_vehicle(
    sources: Vec<Box<dyn OrderSource>>,
    vehicles: &[u8],
) -> Vec<Box<dyn OrderSource>> {
    let shared = std::sync::Arc::new(std::sync::Mutex::new(Shared {
        sources,
        vehicles: vehicles.to_vec(),
        queues: vec![Vec::new(); vehicles.len()],
        warnings: Vec::new(),
    }));
    (0..vehicles.len())
        .map(|index| {
            Box::new(Tap {
                shared: shared.clone(),
                index,
            }) as Box<dyn OrderSource>
        })
        .collect()
}

/// A GoTo order for a waypoint (centimetres and whole degrees on the wire).
fn goto_order(position_m: [f64; 3], heading_deg: f64) -> Order {
    let cm = |m: f64| (m * 100.0).round().clamp(-32768.0, 32767.0) as i16;
    Order::GoTo {
        x_cm: cm(position_m[0]),
        y_cm: cm(position_m[1]),
        z_cm: cm(position_m[2]),
        heading_deg: (heading_deg.rem_euclid(360.0).round() as u16) % 360,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn console_lines_parse_as_wire_md_orders() {
        let live = Live::parse(
            r#"{"type":"velocity","vx":64,"vy":0,"vz":0,"vyaw":-127,"arm":true,"disarm":false,"nav":"depth_hold"}"#,
        )
        .unwrap();
        let Live::Joystick {
            joystick, arm, nav, ..
        } = live
        else {
            panic!("{live:?}");
        };
        assert!((joystick.vx - 50.39).abs() < 0.01 && joystick.vyaw == -100.0);
        assert!(arm && nav == Nav::DepthHold);
        assert_eq!(
            Live::parse(r#"{"type":"goto","x_cm":300,"y_cm":-20,"z_cm":50,"heading_deg":90}"#),
            Ok(Live::Order(Order::GoTo {
                x_cm: 300,
                y_cm: -20,
                z_cm: 50,
                heading_deg: 90
            }))
        );
        assert_eq!(
            Live::parse(r#"{"type":"cancel","t_s":3}"#),
            Ok(Live::Cancel)
        );
        let error = Live::parse(r#"{"type":"goto","x_cm":300,"y_cm":0,"z_cm":0}"#).unwrap_err();
        assert_eq!(error.to_string(), "field heading_deg: missing");
        let error = Live::parse("[1]").unwrap_err();
        assert!(
            error.to_string().contains("expected a JSON object"),
            "{error}"
        );
        assert!(Live::parse(r#"{"type":"unknown","ot":5,"body":"000000000000000000"}"#).is_err());
        let error = Live::parse(r#"{"type":"cancel","t_s":3,"t_s":4}"#).unwrap_err();
        assert!(
            error.to_string().contains("duplicate key \"t_s\""),
            "{error}"
        );
    }

    #[test]
    fn a_script_yields_each_order_once_at_its_time() {
        let mut script = Script::timed(vec![
            (SimTime::from_secs_f64(2.0), Live::Cancel),
            (
                SimTime::from_secs_f64(1.0),
                Live::Order(Order::HoldHeading {
                    heading_deg: 1,
                    enable: true,
                }),
            ),
        ]);
        assert_eq!(script.next_at(), Some(SimTime::from_secs_f64(1.0)));
        assert!(script.poll(SimTime::from_secs_f64(0.5)).is_empty());
        assert_eq!(script.poll(SimTime::from_secs_f64(5.0)).len(), 2);
        assert!(script.poll(SimTime::from_secs_f64(6.0)).is_empty());
        assert_eq!(script.next_at(), None);
    }

    #[test]
    fn split_sources_give_each_vehicle_its_orders_in_order_and_drop_unknown_ones() {
        let hold = |heading_deg| {
            Live::Order(Order::HoldHeading {
                heading_deg,
                enable: true,
            })
        };
        let at = SimTime::from_secs_f64;
        let script = Script::addressed(vec![
            (at(1.0), None, hold(1)),
            (at(1.0), Some(2), hold(2)),
            (at(2.0), Some(2), hold(3)),
            (at(2.0), Some(7), hold(4)),
            (at(3.0), Some(1), Live::Cancel),
        ]);
        let mut taps = split_by_vehicle(vec![Box::new(script)], &[1, 2]);
        let [first, second] = &mut taps[..] else {
            panic!("two taps");
        };
        assert_eq!(first.next_at(), Some(at(1.0)));
        // Vehicle 2's tap drains the source: vehicle 1's order waits in its queue.
        assert_eq!(second.poll(at(2.0)), [hold(2), hold(3)]);
        assert_eq!(first.poll(at(2.0)), [hold(1)]);
        let warnings = first.take_warnings();
        assert_eq!(
            warnings,
            ["an order for vehicle 7: expected one of [1, 2], dropped"]
        );
        assert!(second.take_warnings().is_empty());
        assert!(second.poll(at(9.0)).is_empty());
        assert_eq!(first.poll(at(9.0)), [Live::Cancel]);
        assert_eq!(first.next_at(), None);
    }
}
