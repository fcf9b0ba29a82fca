//! The JSON Lines text form of frames: one message per line, the `Repr` fields by name, as
//! wire.md gives it. `rcp-pack` reads it; `rcp-dump --format ndjson` writes it.
//!
//! Beyond wire.md's two types, two forms keep every frame expressible so that a dump packs back
//! to the same bytes:
//! - a ROV message of a reserved status type: `"st"` is 1..=63 and `"status_raw"` holds every
//!   byte after the header in hex (no status fields, no trunk);
//! - an order of a reserved type: `"order":{"type":"unknown","ot":7,"body":"<18 hex digits>"}`;
//! - `{"type":"raw","src":1,"dst":0,"payload":"<hex>"}`: any payload, as it is.
//!
//! Every field the type needs is required, and a field the message's form does not have is
//! refused ([`JsonError::Unknown`]: a misspelt `"wyh"` is not silently a frame without it), but
//! for what `rcp-dump` adds ([`DUMP_FIELDS`]: `offset`, `t_s`, `error` and the security fields),
//! which is read and ignored, so that a dump packs back.
//!
//! Secured frames (docs/wire-extensions.md): `rcp-dump --key-file` adds `secured`,
//! `encrypted`, `ctr` (the verified counter) or `ctr_low` (the low bits carried) and `verdict`;
//! `rcp-pack --key-file` reads `ctr` ([`counter_field`]) to seal a frame with that counter and
//! ignores the rest.
//!
//! No-panic contract: [`parse_line`] returns a [`JsonError`] naming the field, what was
//! expected and what was found, on any text.

use serde_json::{Map, Value};

use super::message::{Message, MessageRepr};
use super::operator::{self, ImageOrder, Order, Roi, Velocity};
use super::rov::{self, BasicStatus, Status};
use super::{Error, Nav};

/// What was wrong with a JSON line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum JsonError {
    /// The line is not JSON.
    #[error("not valid JSON at column {column}: {message}")]
    Syntax {
        /// 1-based column of the error.
        column: usize,
        /// serde_json's description.
        message: String,
    },
    /// A required field is absent.
    #[error("field {field}: missing")]
    Missing {
        /// The field's path (`order.vx`).
        field: String,
    },
    /// A field holds the wrong kind of value or one out of range.
    #[error("field {field}: expected {expected}, found {found}")]
    BadValue {
        /// The field's path.
        field: String,
        /// What the field takes.
        expected: String,
        /// The value found, as JSON (shortened).
        found: String,
    },
    /// A field the message's form does not have (a misspelling, or another message's field).
    #[error("field {field}: unknown, expected one of {expected}")]
    Unknown {
        /// The field's path (`order.vxx`).
        field: String,
        /// The fields the message has, comma-separated.
        expected: String,
    },
    /// The message as a whole breaks a rule of the wire format.
    #[error("{0}")]
    Wire(#[from] Error),
}

/// The fields `rcp-dump` adds to a message's own: the stream `offset`, the `t_s` of a capture,
/// the `error` of a payload that is not a valid message, and what `--key-file` found
/// (`secured`, `encrypted`, `ctr` or `ctr_low`, `verdict`). [`parse_object`] takes them and
/// ignores them (`ctr` is read by [`parse_line_with_counter`]).
pub const DUMP_FIELDS: [&str; 8] = [
    "offset",
    "t_s",
    "error",
    "secured",
    "encrypted",
    "ctr",
    "ctr_low",
    "verdict",
];

/// Shortened JSON text of a value, for error messages.
pub fn show(value: &Value) -> String {
    let text = value.to_string();
    if text.chars().count() > 40 {
        format!("{}...", text.chars().take(37).collect::<String>())
    } else {
        text
    }
}

/// A JSON object being read, with the path prefix of its fields.
struct Fields<'a> {
    map: &'a Map<String, Value>,
    prefix: &'static str,
}

impl<'a> Fields<'a> {
    fn path(&self, key: &str) -> String {
        format!("{}{key}", self.prefix)
    }

    fn bad(&self, key: &str, expected: impl Into<String>, found: &Value) -> JsonError {
        JsonError::BadValue {
            field: self.path(key),
            expected: expected.into(),
            found: show(found),
        }
    }

    fn get(&self, key: &str) -> Result<&'a Value, JsonError> {
        self.map.get(key).ok_or_else(|| JsonError::Missing {
            field: self.path(key),
        })
    }

    fn bool(&self, key: &str) -> Result<bool, JsonError> {
        let v = self.get(key)?;
        v.as_bool().ok_or_else(|| self.bad(key, "true or false", v))
    }

    fn int(&self, key: &str, min: i64, max: i64) -> Result<i64, JsonError> {
        let v = self.get(key)?;
        match v.as_i64() {
            Some(n) if (min..=max).contains(&n) => Ok(n),
            _ => Err(self.bad(key, format!("an integer {min}..={max}"), v)),
        }
    }

    fn bit(&self, key: &str) -> Result<bool, JsonError> {
        Ok(self.int(key, 0, 1)? == 1)
    }

    fn str(&self, key: &str) -> Result<&'a str, JsonError> {
        let v = self.get(key)?;
        v.as_str().ok_or_else(|| self.bad(key, "a string", v))
    }

    fn hex(&self, key: &str) -> Result<Vec<u8>, JsonError> {
        let v = self.get(key)?;
        let text = v.as_str().ok_or_else(|| self.bad(key, "a hex string", v))?;
        decode_hex(text).ok_or_else(|| self.bad(key, "an even number of hex digits", v))
    }

    fn nav(&self, key: &str) -> Result<Nav, JsonError> {
        let v = self.get(key)?;
        let expected = "manual, stabilize, depth_hold, hold_position, guided, or 5..=7";
        let nav = match v {
            Value::String(s) => Nav::from_name(s),
            Value::Number(n) => match n.as_u64() {
                Some(k @ 5..=7) => Some(Nav::Unknown(k as u8)),
                _ => None,
            },
            _ => None,
        };
        nav.ok_or_else(|| self.bad(key, expected, v))
    }

    fn why(&self, key: &str) -> Result<rov::Why, JsonError> {
        let v = self.get(key)?;
        let expected = "none, arm_refused, mode_refused, no_position, vehicle_silent, or 5..=31";
        let why = match v {
            Value::String(s) => rov::Why::from_name(s),
            Value::Number(n) => match n.as_u64() {
                Some(k @ 5..=31) => Some(rov::Why::Unknown(k as u8)),
                _ => None,
            },
            _ => None,
        };
        why.ok_or_else(|| self.bad(key, expected, v))
    }

    fn object(&self, key: &str) -> Result<Map<String, Value>, JsonError> {
        let v = self.get(key)?;
        v.as_object()
            .cloned()
            .ok_or_else(|| self.bad(key, "an object", v))
    }
}

/// Decodes lowercase or uppercase hex; `None` on an odd length or a non-hex digit
/// ([`rovlink_base::hex::decode`]).
pub fn decode_hex(text: &str) -> Option<Vec<u8>> {
    rovlink_base::hex::decode(text.as_bytes()).ok()
}

/// Encodes bytes as lowercase hex ([`rovlink_base::hex::encode`]).
pub fn encode_hex(bytes: &[u8]) -> String {
    rovlink_base::hex::encode(bytes)
}

/// Reads one JSON line into a frame value, checked with [`MessageRepr::validate`].
pub fn parse_line(line: &str) -> Result<MessageRepr, JsonError> {
    parse_object(&line_object(line)?)
}

/// Reads one JSON line into a frame value and the counter it asks for when it is sealed (the
/// optional field `ctr`, [`counter_field`]).
pub fn parse_line_with_counter(line: &str) -> Result<(MessageRepr, Option<u64>), JsonError> {
    let map = line_object(line)?;
    Ok((parse_object(&map)?, counter_field(&map)?))
}

/// The JSON object a line holds.
fn line_object(line: &str) -> Result<Map<String, Value>, JsonError> {
    let value: Value =
        rovlink_base::strict_json::from_str(line).map_err(|e| JsonError::Syntax {
            column: e.column(),
            message: e.to_string(),
        })?;
    match value {
        Value::Object(map) => Ok(map),
        other => Err(JsonError::BadValue {
            field: "(line)".into(),
            expected: "a JSON object".into(),
            found: show(&other),
        }),
    }
}

/// The highest frame counter of a secured frame (48 bits; docs/wire-extensions.md).
pub const MAX_COUNTER: u64 = (1 << 48) - 1;

/// The optional field `ctr` of a line: the counter a secured frame is sealed with (`rcp-pack
/// --key-file`) or was verified with (`rcp-dump --key-file`), 1..=[`MAX_COUNTER`].
pub fn counter_field(map: &Map<String, Value>) -> Result<Option<u64>, JsonError> {
    let f = Fields { map, prefix: "" };
    match map.get("ctr") {
        None => Ok(None),
        Some(_) => Ok(Some(f.int("ctr", 1, MAX_COUNTER as i64)? as u64)),
    }
}

/// Reads a JSON object into a frame value, checked with [`MessageRepr::validate`]; a field the
/// message's form does not have is refused ([`JsonError::Unknown`]), but for [`DUMP_FIELDS`].
pub fn parse_object(map: &Map<String, Value>) -> Result<MessageRepr, JsonError> {
    let f = Fields { map, prefix: "" };
    let kind = f.str("type")?;
    let src = f.int("src", 0, 15)? as u8;
    let dst = f.int("dst", 0, 15)? as u8;
    let message = match kind {
        "rov" => Message::Rov(parse_rov(&f)?),
        "operator" => Message::Operator(parse_operator(&f)?),
        "raw" => Message::Raw(f.hex("payload")?),
        _ => return Err(f.bad("type", "rov, operator or raw", f.get("type")?)),
    };
    let repr = MessageRepr { src, dst, message };
    only_its_fields(map, &repr)?;
    repr.validate()?;
    Ok(repr)
}

/// Refuses a field of `map`, or of its `order`, that `repr`'s form as [`write_fields`] writes
/// it does not have, but for [`DUMP_FIELDS`] and what a form reads only at its default (a ST = 0
/// status's `position_known` and `why`, a reserved status's empty `trunk`).
fn only_its_fields(map: &Map<String, Value>, repr: &MessageRepr) -> Result<(), JsonError> {
    let mut form = Map::new();
    write_fields(repr, &mut form);
    let defaults: &[&str] = match &repr.message {
        Message::Rov(rov::Repr {
            status: Status::Basic(BasicStatus {
                extension: None, ..
            }),
            ..
        }) => &["position_known", "why"],
        Message::Rov(rov::Repr {
            status: Status::Unknown { .. },
            ..
        }) => &["trunk"],
        _ => &[],
    };
    let known = form
        .keys()
        .map(String::as_str)
        .chain(defaults.iter().copied());
    only_keys(map, known.collect(), &DUMP_FIELDS, "")?;
    match (map.get("order"), form.get("order")) {
        (Some(Value::Object(given)), Some(Value::Object(order))) => only_keys(
            given,
            order.keys().map(String::as_str).collect(),
            &[],
            "order.",
        ),
        _ => Ok(()),
    }
}

/// Refuses the first key of `given` that is neither `known` (listed in the error) nor
/// `ignored`; `at` prefixes its path.
fn only_keys(
    given: &Map<String, Value>,
    known: Vec<&str>,
    ignored: &[&str],
    at: &str,
) -> Result<(), JsonError> {
    match given
        .keys()
        .find(|k| !known.contains(&k.as_str()) && !ignored.contains(&k.as_str()))
    {
        Some(key) => Err(JsonError::Unknown {
            field: format!("{at}{key}"),
            expected: known.join(", "),
        }),
        None => Ok(()),
    }
}

fn parse_rov(f: &Fields<'_>) -> Result<rov::Repr, JsonError> {
    let st = f.int("st", 0, 63)? as u8;
    let (status, trunk) = if st <= rov::ST_EXTENDED {
        let extension = if st == rov::ST_EXTENDED {
            Some(rov::Extension {
                no_position: !f.bool("position_known")?,
                why: f.why("why")?,
            })
        } else {
            for key in ["position_known", "why"] {
                if let Some(value) = f.map.get(key) {
                    let default = if key == "why" {
                        Value::from("none")
                    } else {
                        Value::from(true)
                    };
                    if *value != default {
                        return Err(f.bad(
                            key,
                            "st 1 for a status with position_known false or a why (st 0 has neither)",
                            value,
                        ));
                    }
                }
            }
            None
        };
        let status = BasicStatus {
            rd: f.bool("rd")?,
            eoid: f.bit("eoid")?,
            loc: f.bool("loc")?,
            hh: f.bool("hh")?,
            arm: f.bool("arm")?,
            nav: f.nav("nav")?,
            x_cm: f.int("x_cm", i16::MIN.into(), i16::MAX.into())? as i16,
            y_cm: f.int("y_cm", i16::MIN.into(), i16::MAX.into())? as i16,
            z_cm: f.int("z_cm", i16::MIN.into(), i16::MAX.into())? as i16,
            roll_deg: f.int("roll_deg", 0, 359)? as u16,
            pitch_deg: f.int("pitch_deg", 0, 359)? as u16,
            yaw_deg: f.int("yaw_deg", 0, 359)? as u16,
            extension,
        };
        (Status::Basic(status), f.hex("trunk")?)
    } else {
        if let Some(trunk) = f.map.get("trunk").filter(|t| t.as_str() != Some("")) {
            return Err(f.bad(
                "trunk",
                "no trunk with a reserved status type (st 1..=63): status_raw holds every byte",
                trunk,
            ));
        }
        let raw = f.hex("status_raw")?;
        (Status::Unknown { st, raw }, Vec::new())
    };
    Ok(rov::Repr {
        ft: f.bool("ft")?,
        lt: f.bool("lt")?,
        isn: f.bit("isn")?,
        ci: f.bool("ci")?,
        itsn: f.int("itsn", 0, 63)? as u8,
        status,
        trunk,
    })
}

fn thrust(f: &Fields<'_>, key: &str) -> Result<i8, JsonError> {
    Ok(f.int(key, -127, 127)? as i8)
}

fn heading(f: &Fields<'_>) -> Result<u16, JsonError> {
    Ok(f.int("heading_deg", 0, 359)? as u16)
}

/// Reads an order object (the `order` of an operator message in wire.md's JSON form:
/// `{"type":"goto","x_cm":...}`); errors name the field as it is in the object.
pub fn parse_order(map: &Map<String, Value>) -> Result<Order, JsonError> {
    order_fields(&Fields { map, prefix: "" })
}

fn parse_operator(f: &Fields<'_>) -> Result<operator::Repr, JsonError> {
    let order_map = f.object("order")?;
    let order = order_fields(&Fields {
        map: &order_map,
        prefix: "order.",
    })?;
    Ok(operator::Repr {
        oid: f.bit("oid")?,
        clo: f.bool("clo")?,
        eisn: f.bit("eisn")?,
        ic: f.bool("ic")?,
        rit: f.int("rit", 0, 63)? as u8,
        order,
    })
}

fn order_fields(o: &Fields<'_>) -> Result<Order, JsonError> {
    let order = match o.str("type")? {
        "velocity" => Order::Velocity(Velocity {
            vx: thrust(o, "vx")?,
            vy: thrust(o, "vy")?,
            vz: thrust(o, "vz")?,
            vyaw: thrust(o, "vyaw")?,
            arm: o.bool("arm")?,
            disarm: o.bool("disarm")?,
            nav: o.nav("nav")?,
        }),
        "goto" => Order::GoTo {
            x_cm: o.int("x_cm", i16::MIN.into(), i16::MAX.into())? as i16,
            y_cm: o.int("y_cm", i16::MIN.into(), i16::MAX.into())? as i16,
            z_cm: o.int("z_cm", i16::MIN.into(), i16::MAX.into())? as i16,
            heading_deg: heading(o)?,
        },
        "image_settings" => {
            let roi_value = o.get("roi")?;
            let roi = roi_value
                .as_array()
                .filter(|a| a.len() == 4)
                .and_then(|a| {
                    let c: Option<Vec<u16>> = a
                        .iter()
                        .map(|v| v.as_u64().filter(|&n| n <= 1023).map(|n| n as u16))
                        .collect();
                    c.map(|c| Roi::from_array([c[0], c[1], c[2], c[3]]))
                })
                .ok_or_else(|| o.bad("roi", "[x0, y0, x1, y1], each 0..=1023", roi_value))?;
            Order::ImageSettings(ImageOrder {
                roi,
                roi_shift: o.int("roi_shift", 0, 15)? as u8,
                gray: o.bool("gray")?,
                scale: o.int("scale", 0, 3)? as u8,
                size_bytes: o.int("size_bytes", 0, u16::MAX.into())? as u16,
                trunk_bytes: o.int("trunk_bytes", 0, u8::MAX.into())? as u8,
            })
        }
        "hold_heading" => Order::HoldHeading {
            heading_deg: heading(o)?,
            enable: o.bool("enable")?,
        },
        "unknown" => {
            let ot = o.int("ot", 4, 15)? as u8;
            let bytes = o.hex("body")?;
            let body = <[u8; operator::BODY_BYTES]>::try_from(bytes.as_slice()).map_err(|_| {
                o.bad(
                    "body",
                    "18 hex digits (9 bytes)",
                    o.get("body").unwrap_or(&Value::Null),
                )
            })?;
            Order::Unknown { ot, body }
        }
        _ => {
            return Err(o.bad(
                "type",
                "velocity, goto, image_settings, hold_heading or unknown",
                o.get("type")?,
            ));
        }
    };
    Ok(order)
}

fn why_value(why: rov::Why) -> Value {
    match why.name() {
        Some(name) => Value::from(name),
        None => Value::from(why.bits()),
    }
}

fn nav_value(nav: Nav) -> Value {
    match nav.name() {
        Some(name) => Value::from(name),
        None => Value::from(nav.bits()),
    }
}

/// Appends a frame's fields, in wire.md's order, to a JSON object (which may already hold
/// fields such as an offset).
pub fn write_fields(repr: &MessageRepr, out: &mut Map<String, Value>) {
    out.insert("type".into(), repr.message.type_name().into());
    out.insert("src".into(), repr.src.into());
    out.insert("dst".into(), repr.dst.into());
    match &repr.message {
        Message::Rov(r) => {
            out.insert("ft".into(), r.ft.into());
            out.insert("lt".into(), r.lt.into());
            out.insert("st".into(), r.status.st().into());
            out.insert("isn".into(), u8::from(r.isn).into());
            out.insert("ci".into(), r.ci.into());
            out.insert("itsn".into(), r.itsn.into());
            match &r.status {
                Status::Basic(s) => {
                    out.insert("rd".into(), s.rd.into());
                    out.insert("eoid".into(), u8::from(s.eoid).into());
                    out.insert("loc".into(), s.loc.into());
                    out.insert("hh".into(), s.hh.into());
                    out.insert("arm".into(), s.arm.into());
                    out.insert("nav".into(), nav_value(s.nav));
                    out.insert("x_cm".into(), s.x_cm.into());
                    out.insert("y_cm".into(), s.y_cm.into());
                    out.insert("z_cm".into(), s.z_cm.into());
                    out.insert("roll_deg".into(), s.roll_deg.into());
                    out.insert("pitch_deg".into(), s.pitch_deg.into());
                    out.insert("yaw_deg".into(), s.yaw_deg.into());
                    if s.extension.is_some() {
                        out.insert("position_known".into(), s.position_known().into());
                        out.insert("why".into(), why_value(s.why()));
                    }
                    out.insert("trunk".into(), encode_hex(&r.trunk).into());
                }
                Status::Unknown { raw, .. } => {
                    out.insert("status_raw".into(), encode_hex(raw).into());
                }
            }
        }
        Message::Operator(o) => {
            out.insert("oid".into(), u8::from(o.oid).into());
            out.insert("clo".into(), o.clo.into());
            out.insert("eisn".into(), u8::from(o.eisn).into());
            out.insert("ic".into(), o.ic.into());
            out.insert("rit".into(), o.rit.into());
            out.insert("order".into(), Value::Object(order_object(&o.order)));
        }
        Message::Raw(payload) => {
            out.insert("payload".into(), encode_hex(payload).into());
        }
    }
}

fn order_object(order: &Order) -> Map<String, Value> {
    let mut m = Map::new();
    m.insert("type".into(), order.name().into());
    match *order {
        Order::Velocity(v) => {
            for (name, axis) in ["vx", "vy", "vz", "vyaw"].into_iter().zip(v.axes()) {
                m.insert(name.into(), axis.into());
            }
            m.insert("arm".into(), v.arm.into());
            m.insert("disarm".into(), v.disarm.into());
            m.insert("nav".into(), nav_value(v.nav));
        }
        Order::GoTo {
            x_cm,
            y_cm,
            z_cm,
            heading_deg,
        } => {
            m.insert("x_cm".into(), x_cm.into());
            m.insert("y_cm".into(), y_cm.into());
            m.insert("z_cm".into(), z_cm.into());
            m.insert("heading_deg".into(), heading_deg.into());
        }
        Order::ImageSettings(image) => {
            m.insert("roi".into(), image.roi.to_array().to_vec().into());
            m.insert("roi_shift".into(), image.roi_shift.into());
            m.insert("gray".into(), image.gray.into());
            m.insert("scale".into(), image.scale.into());
            m.insert("size_bytes".into(), image.size_bytes.into());
            m.insert("trunk_bytes".into(), image.trunk_bytes.into());
        }
        Order::HoldHeading {
            heading_deg,
            enable,
        } => {
            m.insert("heading_deg".into(), heading_deg.into());
            m.insert("enable".into(), enable.into());
        }
        Order::Unknown { ot, body } => {
            m.insert("ot".into(), ot.into());
            m.insert("body".into(), encode_hex(&body).into());
        }
    }
    m
}

/// One frame as a JSON line (no trailing newline), exactly in wire.md's form.
pub fn to_line(repr: &MessageRepr) -> String {
    let mut map = Map::new();
    write_fields(repr, &mut map);
    Value::Object(map).to_string()
}

/// The columns of the CSV form: every field of every message type in wire.md's order, flattened
/// (an order's `type` becomes the `order` column; status version 1's `position_known` and `why`
/// follow `yaw_deg`, as in the JSON form), plus `offset`, `t_s` and `error` that dumps add. A
/// field the frame does not carry is an empty cell.
pub const CSV_COLUMNS: [&str; 50] = [
    "offset",
    "t_s",
    "type",
    "src",
    "dst",
    "ft",
    "lt",
    "st",
    "isn",
    "ci",
    "itsn",
    "rd",
    "eoid",
    "loc",
    "hh",
    "arm",
    "nav",
    "x_cm",
    "y_cm",
    "z_cm",
    "roll_deg",
    "pitch_deg",
    "yaw_deg",
    "position_known",
    "why",
    "trunk",
    "status_raw",
    "oid",
    "clo",
    "eisn",
    "ic",
    "rit",
    "order",
    "vx",
    "vy",
    "vz",
    "vyaw",
    "disarm",
    "heading_deg",
    "roi",
    "roi_shift",
    "gray",
    "scale",
    "size_bytes",
    "trunk_bytes",
    "enable",
    "ot",
    "body",
    "payload",
    "error",
];

/// The columns a dump with a key file adds after [`CSV_COLUMNS`]: what it found of each frame's
/// security (`rcp-dump --key-file`).
pub const CSV_SECURITY_COLUMNS: [&str; 5] = ["secured", "encrypted", "ctr", "ctr_low", "verdict"];

/// Flattens a JSON object of [`write_fields`] (plus any extra fields) into one CSV record in
/// [`CSV_COLUMNS`] order; absent fields are empty, arrays are space-separated.
pub fn csv_record(map: &Map<String, Value>) -> Vec<String> {
    csv_record_in(map, &CSV_COLUMNS)
}

/// [`csv_record`] with the columns `columns` (such as [`CSV_COLUMNS`] then
/// [`CSV_SECURITY_COLUMNS`]).
pub fn csv_record_in(map: &Map<String, Value>, columns: &[&str]) -> Vec<String> {
    let mut flat: Map<String, Value> = Map::new();
    for (key, value) in map {
        match (key.as_str(), value) {
            ("order", Value::Object(order)) => {
                for (k, v) in order {
                    let k = if k == "type" { "order" } else { k.as_str() };
                    flat.insert(k.to_string(), v.clone());
                }
            }
            _ => {
                flat.insert(key.clone(), value.clone());
            }
        }
    }
    let cell = |v: &Value| match v {
        Value::String(s) => s.clone(),
        Value::Array(items) => items
            .iter()
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(" "),
        Value::Null => String::new(),
        other => other.to_string(),
    };
    columns
        .iter()
        .map(|c| flat.get(*c).map(cell).unwrap_or_default())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// wire.md's five lines and the frames they pack to.
    pub(crate) const VECTORS: [(&str, &str); 5] = [
        (
            r#"{"type":"rov","src":1,"dst":0,"ft":true,"lt":false,"st":0,"isn":1,"ci":false,"itsn":0,"rd":true,"eoid":1,"loc":false,"hh":true,"arm":true,"nav":"guided","x_cm":-250,"y_cm":1200,"z_cm":455,"roll_deg":359,"pitch_deg":1,"yaw_deg":180,"trunk":"00010203"}"#,
            "5510118080dcff0604b001c702d00367000102032fde",
        ),
        (
            r#"{"type":"operator","src":0,"dst":1,"oid":1,"clo":false,"eisn":0,"ic":false,"rit":5,"order":{"type":"velocity","vx":100,"vy":-20,"vz":0,"vyaw":-127,"arm":true,"disarm":false,"nav":"stabilize"}}"#,
            "55010b800564ec008181000000000ccb",
        ),
        (
            r#"{"type":"operator","src":0,"dst":2,"oid":0,"clo":true,"eisn":1,"ic":true,"rit":63,"order":{"type":"goto","x_cm":-250,"y_cm":1200,"z_cm":310,"heading_deg":359}}"#,
            "55020b44ffff0604b00136016700de57",
        ),
        (
            r#"{"type":"operator","src":0,"dst":1,"oid":1,"clo":false,"eisn":1,"ic":false,"rit":0,"order":{"type":"image_settings","roi":[100,80,420,300],"roi_shift":3,"gray":true,"scale":1,"size_bytes":2000,"trunk_bytes":39}}"#,
            "55010b8880190506912c3907d027ffca",
        ),
        (
            r#"{"type":"operator","src":0,"dst":3,"oid":0,"clo":false,"eisn":0,"ic":false,"rit":12,"order":{"type":"hold_heading","heading_deg":270,"enable":true}}"#,
            "55030b0c0c010e800000000000001bee",
        ),
    ];

    #[test]
    fn vectors_pack_to_the_spec_bytes_and_back() {
        for (line, hex) in VECTORS {
            let repr = parse_line(line).unwrap();
            let mut bytes = Vec::new();
            repr.emit_to_vec(&mut bytes).unwrap();
            assert_eq!(encode_hex(&bytes), hex, "{line}");
            let frame = super::super::frame::Frame::new_checked(&bytes[..]).unwrap();
            let back = MessageRepr::parse(&frame).unwrap();
            assert_eq!(back, repr);
            assert_eq!(to_line(&back), line);
        }
    }

    #[test]
    fn errors_name_the_field() {
        let err = |line: &str| parse_line(line).unwrap_err().to_string();
        let base = VECTORS[0].0;
        assert!(
            err(&base.replace(r#""rd":true,"#, r#""rd":true,"rd":false,"#))
                .contains("duplicate key \"rd\""),
            "a repeated field is refused"
        );
        assert_eq!(
            err(&base.replace(r#""x_cm":-250"#, r#""x_cm":40000"#)),
            "field x_cm: expected an integer -32768..=32767, found 40000"
        );
        assert_eq!(err(&base.replace(r#""rd":true,"#, "")), "field rd: missing");
        assert_eq!(
            err(&base.replace(r#""nav":"guided""#, r#""nav":"fly""#)),
            "field nav: expected manual, stabilize, depth_hold, hold_position, guided, or 5..=7, found \"fly\""
        );
        assert_eq!(
            err(&base.replace(r#""trunk":"00010203""#, r#""trunk":"0g""#)),
            "field trunk: expected an even number of hex digits, found \"0g\""
        );
        assert_eq!(
            err(&base.replace(r#""src":1"#, r#""src":0"#)),
            "address: rov messages need src 1..=15, found src 0"
        );
        assert_eq!(
            err(&VECTORS[1].0.replace(r#""vyaw":-127"#, r#""vyaw":-128"#)),
            "field order.vyaw: expected an integer -127..=127, found -128"
        );
        assert!(err("{").starts_with("not valid JSON at column 1"));
        let reserved = r#"{"type":"rov","src":1,"dst":0,"ft":false,"lt":false,"st":5,"isn":0,"ci":false,"itsn":0,"status_raw":"0102","trunk":"ffff"}"#;
        assert_eq!(
            err(reserved),
            "field trunk: expected no trunk with a reserved status type (st 1..=63): status_raw holds every byte, found \"ffff\""
        );
        assert!(parse_line(&reserved.replace(r#","trunk":"ffff""#, "")).is_ok());
        assert_eq!(
            err("[1]"),
            "field (line): expected a JSON object, found [1]"
        );
    }

    #[test]
    fn a_field_the_form_does_not_have_is_refused_naming_it() {
        let err = |line: &str| parse_line(line).unwrap_err().to_string();
        let base = VECTORS[0].0;
        // Issue 48: misspelt status version 1 fields packed a plain ST = 0 frame.
        let typo = base.replace(
            r#""trunk""#,
            r#""wyh":"no_position","positon_known":false,"trunk""#,
        );
        assert_eq!(
            err(&typo),
            "field wyh: unknown, expected one of type, src, dst, ft, lt, st, isn, ci, itsn, rd, \
             eoid, loc, hh, arm, nav, x_cm, y_cm, z_cm, roll_deg, pitch_deg, yaw_deg, trunk, \
             position_known, why"
        );
        assert_eq!(
            err(&VECTORS[2]
                .0
                .replace(r#""heading_deg":359"#, r#""heading_deg":359,"heading":1"#)),
            "field order.heading: unknown, expected one of type, x_cm, y_cm, z_cm, heading_deg"
        );
        assert!(
            err(&VECTORS[1]
                .0
                .replace(r#""rit":5"#, r#""rit":5,"trunk":"00""#))
            .starts_with("field trunk: unknown, expected one of type, src, dst, oid, "),
        );
        let reserved = r#"{"type":"rov","src":1,"dst":0,"ft":false,"lt":false,"st":5,"isn":0,"ci":false,"itsn":0,"status_raw":"0102","rd":true}"#;
        assert_eq!(
            err(reserved),
            "field rd: unknown, expected one of type, src, dst, ft, lt, st, isn, ci, itsn, \
             status_raw, trunk"
        );
        assert!(
            err(r#"{"type":"raw","src":1,"dst":0,"payload":"00","order":{}}"#)
                .starts_with("field order: unknown"),
        );
        // What rcp-dump adds is read and ignored, and so are ST = 0's fields at their defaults.
        let dumped = r#"{"offset":5,"t_s":1.5,"secured":true,"encrypted":false,"ctr":7,"ctr_low":7,"verdict":"ok","error":"x","#;
        for (line, _) in VECTORS {
            let with = line.replacen('{', dumped, 1);
            assert_eq!(
                parse_line(&with).unwrap(),
                parse_line(line).unwrap(),
                "{with}"
            );
        }
        let defaults = base.replace(
            r#""trunk""#,
            r#""position_known":true,"why":"none","trunk""#,
        );
        assert_eq!(parse_line(&defaults).unwrap(), parse_line(base).unwrap());
        // An order alone (the console's, `--orders`) still takes other fields, such as t_s.
        let order = r#"{"t_s":2,"type":"hold_heading","heading_deg":270,"enable":true}"#;
        let order: Map<String, Value> = serde_json::from_str(order).unwrap();
        assert!(parse_order(&order).is_ok());
    }

    /// docs/wire-extensions.md's status version 1 vector (ST = 1: no position, WHY
    /// no_position).
    const STATUS_V1: &str = r#"{"type":"rov","src":1,"dst":0,"ft":true,"lt":false,"st":1,"isn":1,"ci":false,"itsn":0,"rd":true,"eoid":1,"loc":false,"hh":true,"arm":true,"nav":"guided","x_cm":0,"y_cm":0,"z_cm":0,"roll_deg":359,"pitch_deg":1,"yaw_deg":180,"position_known":false,"why":"no_position","trunk":"00010203"}"#;

    #[test]
    fn every_field_is_a_csv_column() {
        let known = STATUS_V1
            .replace(r#""position_known":false"#, r#""position_known":true"#)
            .replace(r#""why":"no_position""#, r#""why":"none""#);
        let lines = VECTORS.map(|(line, _)| line.to_string());
        for line in lines.iter().chain([&STATUS_V1.to_string(), &known]) {
            let mut map = Map::new();
            write_fields(&parse_line(line).unwrap(), &mut map);
            let row = csv_record(&map);
            for (key, value) in &map {
                let values: Vec<(&str, &Value)> = match value {
                    Value::Object(order) => order
                        .iter()
                        .map(|(k, v)| (if k == "type" { "order" } else { k.as_str() }, v))
                        .collect(),
                    _ => vec![(key.as_str(), value)],
                };
                for (column, value) in values {
                    let at = CSV_COLUMNS.iter().position(|c| *c == column);
                    let at = at.unwrap_or_else(|| panic!("{line}: no column {column}"));
                    assert!(!row[at].is_empty() || value == "", "{line}: {column} empty");
                }
            }
        }
        let row = |line: &str| {
            let mut map = Map::new();
            write_fields(&parse_line(line).unwrap(), &mut map);
            let row = csv_record(&map);
            let at = |c: &str| CSV_COLUMNS.iter().position(|k| *k == c).unwrap();
            (row[at("position_known")].clone(), row[at("why")].clone())
        };
        assert_eq!(row(STATUS_V1), ("false".into(), "no_position".into()));
        assert_eq!(row(&known), ("true".into(), "none".into()));
        // ST = 0 carries neither: empty cells.
        assert_eq!(row(VECTORS[0].0), (String::new(), String::new()));
    }

    #[test]
    fn hex_round_trip() {
        assert_eq!(decode_hex("00ffA5"), Some(vec![0, 255, 0xa5]));
        assert_eq!(decode_hex("0"), None);
        assert_eq!(encode_hex(&[0, 255, 0xa5]), "00ffa5");
    }
}
