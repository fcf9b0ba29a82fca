//! `--telemetry`: the session's JSON Lines, one object a line for each thing that happens
//! (docs/tdma-console.md lists every line).

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::{Map, Value};

use rovlink_base::output::Dest;
use rovlink_cli::rows::{RowFormat, RowWriter};
use rovlink_rcp::autopilot::DriveEvent;
use rovlink_rcp::{Event, Role};
use rovlink_wire::operator::Order;
use rovlink_wire::{Message, MessageRepr};

/// Seconds between two telemetry lines for the same camera failure.
pub const CAMERA_REPEAT_S: f64 = 10.0;

/// The most orders remembered between their sending and their acknowledgement (to show the
/// order again when it is acknowledged).
const REMEMBERED_ORDERS: usize = 64;

/// `--telemetry`: one JSON object a line for each thing that happens, each with `type`,
/// `t_s` (session seconds) and `end` (`operator` or `rov`); see docs/tdma-console.md.
pub struct Telemetry {
    rows: RowWriter,
    /// Orders sent and not yet acknowledged, by number.
    sent: BTreeMap<u64, Order>,
    /// The last image progress: trunks received, trunks in all.
    progress: (usize, Option<usize>),
    /// The camera failure last written, when, and how many times it came again since.
    camera: Option<(String, f64, u64)>,
    /// In a multi-vehicle scenario: the vehicle the next lines are about.
    vehicle: Option<u8>,
    /// The other vehicles' `sent`, `progress` and `camera`, while one is current.
    others: BTreeMap<u8, VehicleLines>,
}

/// What [`Telemetry`] remembers of one vehicle's session between lines.
#[derive(Default)]
pub(crate) struct VehicleLines {
    sent: BTreeMap<u64, Order>,
    progress: (usize, Option<usize>),
    camera: Option<(String, f64, u64)>,
}

/// Session seconds as written: to the microsecond.
fn seconds(t_s: f64) -> Value {
    Value::from((t_s * 1e6).round() / 1e6)
}

/// An order in wire.md's JSON form (the `order` object of an operator message).
pub fn order_json(order: &Order) -> Value {
    let repr = MessageRepr {
        src: 0,
        dst: 0,
        message: Message::Operator(rovlink_wire::operator::Repr {
            oid: false,
            clo: false,
            eisn: false,
            ic: false,
            rit: 0,
            order: *order,
        }),
    };
    let mut fields = Map::new();
    rovlink_wire::json::write_fields(&repr, &mut fields);
    fields.remove("order").unwrap_or(Value::Null)
}

fn path_json(path: Option<&Path>) -> Value {
    path.map_or(Value::Null, |p| p.display().to_string().into())
}

impl Telemetry {
    /// Telemetry lines to `dest`; nothing is created until the first line.
    pub fn new(dest: Dest) -> Telemetry {
        Telemetry {
            rows: RowWriter::new(dest, RowFormat::Ndjson, &[]),
            sent: BTreeMap::new(),
            progress: (0, None),
            camera: None,
            vehicle: None,
            others: BTreeMap::new(),
        }
    }

    /// In a multi-vehicle scenario: every line from now on carries `"vehicle": address`, and
    /// is about that vehicle's orders and image.
    pub(crate) fn set_vehicle(&mut self, address: u8) {
        if self.vehicle == Some(address) {
            return;
        }
        let current = VehicleLines {
            sent: std::mem::take(&mut self.sent),
            progress: std::mem::take(&mut self.progress),
            camera: self.camera.take(),
        };
        if let Some(old) = self.vehicle {
            self.others.insert(old, current);
        }
        let next = self.others.remove(&address).unwrap_or_default();
        (self.sent, self.progress, self.camera) = (next.sent, next.progress, next.camera);
        self.vehicle = Some(address);
    }

    /// Completes the output (see [`RowWriter::finish`]).
    pub(crate) fn finish(self) -> Result<(), rovlink_base::io::IoError> {
        self.rows.finish()
    }

    /// A line's first fields.
    pub(crate) fn line(&self, kind: &str, t_s: f64, end: Role) -> Map<String, Value> {
        let mut line = Map::new();
        line.insert("type".into(), kind.into());
        line.insert("t_s".into(), seconds(t_s));
        line.insert("end".into(), end.name().into());
        if let Some(vehicle) = self.vehicle {
            line.insert("vehicle".into(), vehicle.into());
        }
        line
    }

    pub(crate) fn write(
        &mut self,
        line: Map<String, Value>,
    ) -> Result<(), rovlink_base::io::IoError> {
        self.rows.row(&Value::Object(line))
    }

    /// A line of `kind` with its `state` and further fields.
    fn state(
        &mut self,
        kind: &str,
        t_s: f64,
        end: Role,
        state: &str,
        fields: impl IntoIterator<Item = (&'static str, Value)>,
    ) -> Result<(), rovlink_base::io::IoError> {
        let mut line = self.line(kind, t_s, end);
        line.insert("state".into(), state.into());
        for (key, value) in fields {
            line.insert(key.into(), value);
        }
        self.write(line)
    }

    /// The image just completed, written to `file` (none without `--images-out`).
    pub(crate) fn image_complete(
        &mut self,
        t_s: f64,
        file: Option<&Path>,
    ) -> Result<(), rovlink_base::io::IoError> {
        let (trunks, of) = std::mem::take(&mut self.progress);
        let of = of
            .or((trunks > 0).then_some(trunks))
            .map_or(Value::Null, Value::from);
        let fields = [
            ("trunks", of.clone()),
            ("of", of),
            ("file", path_json(file)),
        ];
        self.state("image", t_s, Role::Operator, "complete", fields)
    }

    /// The line for `event` of `end`, if it has one; `file` is the preview written for an
    /// image in progress.
    pub(crate) fn event(
        &mut self,
        end: Role,
        t_s: f64,
        event: &Event,
        file: Option<&Path>,
    ) -> Result<(), rovlink_base::io::IoError> {
        match event {
            Event::Status(repr) => {
                let mut line = self.line("rov", t_s, end);
                rovlink_wire::json::write_fields(repr, &mut line);
                line.shift_remove("trunk");
                self.write(line)
            }
            Event::OrderSent { index, order } => {
                if self.sent.len() >= REMEMBERED_ORDERS {
                    self.sent.pop_first();
                }
                self.sent.insert(*index, *order);
                let fields = [("index", (*index).into()), ("order", order_json(order))];
                self.state("order", t_s, end, "sent", fields)
            }
            Event::OrderAcknowledged(index) => {
                let order = self.sent.remove(index);
                let fields = [
                    ("index", (*index).into()),
                    ("order", order.as_ref().map_or(Value::Null, order_json)),
                ];
                self.state("order", t_s, end, "acknowledged", fields)
            }
            Event::OrderExecuted(order) => self.state(
                "order",
                t_s,
                end,
                "executed",
                [("order", order_json(order))],
            ),
            Event::CancelConfirmed | Event::OrderCancelled => {
                self.state("order", t_s, end, "cancelled", [])
            }
            Event::ImageProgress { trunks, of, .. } => {
                self.progress = (*trunks, *of);
                let fields = [
                    ("trunks", (*trunks).into()),
                    ("of", of.map_or(Value::Null, Value::from)),
                    ("file", path_json(file)),
                ];
                self.state("image", t_s, end, "progress", fields)
            }
            Event::ImageStarted { trunks, bytes } => {
                self.camera = None;
                let fields = [("trunks", (*trunks).into()), ("bytes", (*bytes).into())];
                self.state("image", t_s, end, "started", fields)
            }
            Event::ImageCancelled => self.state("image", t_s, end, "cancelled", []),
            // Written by [`Observer::image`], which knows the file.
            Event::ImageCompleted(_) => Ok(()),
            Event::AnswersLost | Event::LinkLost => self.state("link", t_s, end, "lost", []),
            Event::AnswersBack | Event::LinkRecovered => {
                self.state("link", t_s, end, "recovered", [])
            }
            Event::Vehicle(drive) => self.vehicle(end, t_s, drive),
            Event::CameraFailed(error) => self.camera_failed(end, t_s, error),
        }
    }

    fn vehicle(
        &mut self,
        end: Role,
        t_s: f64,
        event: &DriveEvent,
    ) -> Result<(), rovlink_base::io::IoError> {
        match event {
            DriveEvent::Silent { silent_s } => self.state(
                "vehicle",
                t_s,
                end,
                "silent",
                [("silent_s", seconds(*silent_s))],
            ),
            DriveEvent::Heard => self.state("vehicle", t_s, end, "heard", []),
            DriveEvent::CommandAck {
                command,
                result,
                accepted,
            } => {
                let fields = [
                    ("command", command.as_str().into()),
                    ("result", result.as_str().into()),
                    ("accepted", (*accepted).into()),
                ];
                self.state("vehicle", t_s, end, "command_ack", fields)
            }
            DriveEvent::Refused { why, reason } => {
                let fields = [
                    ("why", why.to_string().into()),
                    ("reason", reason.as_str().into()),
                ];
                self.state("vehicle", t_s, end, "refused", fields)
            }
            DriveEvent::Note(text) => self.state(
                "vehicle",
                t_s,
                end,
                "note",
                [("text", text.as_str().into())],
            ),
            // Counted in the metrics; the drive's note said it once per source.
            DriveEvent::MessagesRefused { .. } => Ok(()),
        }
    }

    /// A camera failure: written when it is new, then at most every [`CAMERA_REPEAT_S`] with
    /// how many times it came again meanwhile (a failing camera fails at every slot).
    fn camera_failed(
        &mut self,
        end: Role,
        t_s: f64,
        error: &str,
    ) -> Result<(), rovlink_base::io::IoError> {
        let repeated = match &mut self.camera {
            Some((last, at_s, count)) if last == error => {
                *count += 1;
                if t_s - *at_s < CAMERA_REPEAT_S {
                    return Ok(());
                }
                *count
            }
            _ => 0,
        };
        self.camera = Some((error.to_string(), t_s, 0));
        let fields = [("error", error.into()), ("repeated", repeated.into())];
        self.state("camera", t_s, end, "failed", fields)
    }
}
