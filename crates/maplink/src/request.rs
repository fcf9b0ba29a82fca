//! What the operator asks the mapper, as request bytes (after a request segment's id) and as
//! JSON Lines (the view's `--orders` console and Foxglove's `/octo_delta/requests`):
//!
//! | kind | bytes after it | JSON |
//! |---|---|---|
//! | 1 resync | | `{"type":"resync"}` |
//! | 2 full map | | `{"type":"full"}` |
//! | 3 full map inside a box | 6 x f64 (x0, y0, z0, x1, y1, z1, m) | `{"type":"full","box":[x0,y0,z0,x1,y1,z1]}` |
//! | 4 set the ROI | 6 x f64 | `{"type":"roi","box":[x0,y0,z0,x1,y1,z1]}` |
//! | 5 no ROI (everything fine) | | `{"type":"roi","box":null}` |
//! | 6 coarse depth | u8, 1..=16 | `{"type":"coarse_depth","depth":12}` |
//!
//! A box must be finite with x0 <= x1, y0 <= y1, z0 <= z1 (checked here); whether it is
//! usable (within the map's coordinates) is the mapper's to say, in its reply.

use serde_json::{Map, Value};

/// An axis-aligned box, metres: lower corner then upper corner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxM {
    /// x0, y0, z0.
    pub min_m: [f64; 3],
    /// x1, y1, z1.
    pub max_m: [f64; 3],
}

impl BoxM {
    /// A box from six numbers, checked: finite, each lower bound at most its upper one.
    pub fn new(v: [f64; 6]) -> Result<BoxM, RequestError> {
        if v.iter().any(|x| !x.is_finite()) || (0..3).any(|i| v[i] > v[i + 3]) {
            return Err(RequestError::NotABox(v));
        }
        Ok(BoxM {
            min_m: [v[0], v[1], v[2]],
            max_m: [v[3], v[4], v[5]],
        })
    }
}

/// A request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Request {
    /// Start the stream again from the mapper's view of the operator's map (a restarted view).
    Resync,
    /// Send the whole map (as the map is now: colours updated).
    Full,
    /// Send the map inside a box.
    FullBox(BoxM),
    /// Move the region of interest (`None`: everything fine).
    Roi(Option<BoxM>),
    /// Change the depth of the coarse voxels (1..=16).
    CoarseDepth(u8),
}

/// Why request bytes or JSON were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RequestError {
    /// No kind byte.
    #[error("empty request")]
    Empty,
    /// A kind this version does not have.
    #[error("request kind {0}: expected 1..=6")]
    Kind(u8),
    /// The bytes after the kind are not the kind's.
    #[error("request kind {kind}: expected {expected} bytes after the kind, found {found}")]
    Length {
        /// The kind.
        kind: u8,
        /// Bytes it takes.
        expected: usize,
        /// Bytes found.
        found: usize,
    },
    /// Not a box.
    #[error("box {0:?}: expected six finite numbers with x0 <= x1, y0 <= y1, z0 <= z1")]
    NotABox([f64; 6]),
    /// A coarse depth out of range.
    #[error("coarse depth {0}: expected 1..=16")]
    Depth(u64),
    /// JSON that is not a request.
    #[error("{0}")]
    Json(String),
}

fn get_box(bytes: &[u8]) -> Result<BoxM, RequestError> {
    let mut v = [0.0f64; 6];
    for (x, c) in v.iter_mut().zip(bytes.chunks_exact(8)) {
        let mut a = [0u8; 8];
        a.copy_from_slice(c);
        *x = f64::from_le_bytes(a);
    }
    BoxM::new(v)
}

impl Request {
    /// The request's kind byte.
    pub fn kind(&self) -> u8 {
        match self {
            Request::Resync => 1,
            Request::Full => 2,
            Request::FullBox(_) => 3,
            Request::Roi(Some(_)) => 4,
            Request::Roi(None) => 5,
            Request::CoarseDepth(_) => 6,
        }
    }

    /// The request's name in messages and JSON.
    pub fn name(&self) -> &'static str {
        match self {
            Request::Resync => "resync",
            Request::Full | Request::FullBox(_) => "full",
            Request::Roi(_) => "roi",
            Request::CoarseDepth(_) => "coarse_depth",
        }
    }

    /// Parses request bytes (a request segment's after its id).
    pub fn parse(bytes: &[u8]) -> Result<Request, RequestError> {
        let (&kind, body) = bytes.split_first().ok_or(RequestError::Empty)?;
        let expected = match kind {
            1 | 2 | 5 => 0,
            3 | 4 => 48,
            6 => 1,
            other => return Err(RequestError::Kind(other)),
        };
        if body.len() != expected {
            return Err(RequestError::Length {
                kind,
                expected,
                found: body.len(),
            });
        }
        Ok(match kind {
            1 => Request::Resync,
            2 => Request::Full,
            3 => Request::FullBox(get_box(body)?),
            4 => Request::Roi(Some(get_box(body)?)),
            5 => Request::Roi(None),
            _ => {
                let d = body[0];
                if !(1..=16).contains(&d) {
                    return Err(RequestError::Depth(d as u64));
                }
                Request::CoarseDepth(d)
            }
        })
    }

    /// Appends the request's bytes.
    pub fn emit(&self, out: &mut Vec<u8>) {
        out.push(self.kind());
        match self {
            Request::FullBox(b) | Request::Roi(Some(b)) => {
                for v in b.min_m.iter().chain(&b.max_m) {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
            Request::CoarseDepth(d) => out.push(*d),
            Request::Resync | Request::Full | Request::Roi(None) => {}
        }
    }

    /// A request from its JSON object (see the module's table); the error names the field.
    pub fn from_json(o: &Map<String, Value>) -> Result<Request, RequestError> {
        let bad = |s: String| RequestError::Json(s);
        let kind = o
            .get("type")
            .and_then(Value::as_str)
            .ok_or_else(|| bad("\"type\": expected a string".into()))?;
        let allowed: &[&str] = match kind {
            "resync" => &["type"],
            "full" | "roi" => &["type", "box"],
            "coarse_depth" => &["type", "depth"],
            other => {
                return Err(bad(format!(
                    "\"type\": expected resync, full, roi or coarse_depth, found {other:?}"
                )));
            }
        };
        if let Some(k) = o.keys().find(|k| !allowed.contains(&k.as_str())) {
            return Err(bad(format!("{kind}: unknown field {k:?}")));
        }
        let boxed = || -> Result<Option<BoxM>, RequestError> {
            match o.get("box") {
                None | Some(Value::Null) => Ok(None),
                Some(Value::Array(a)) if a.len() == 6 => {
                    let mut v = [0.0f64; 6];
                    for (x, e) in v.iter_mut().zip(a) {
                        *x = e.as_f64().ok_or_else(|| {
                            bad(format!("\"box\": expected six numbers, found {e}"))
                        })?;
                    }
                    BoxM::new(v).map(Some)
                }
                Some(other) => Err(bad(format!(
                    "\"box\": expected [x0,y0,z0,x1,y1,z1] or null, found {other}"
                ))),
            }
        };
        Ok(match kind {
            "resync" => Request::Resync,
            "full" => boxed()?.map_or(Request::Full, Request::FullBox),
            "roi" => {
                if !o.contains_key("box") {
                    return Err(bad("roi: \"box\" is required ([x0,..,z1] or null)".into()));
                }
                Request::Roi(boxed()?)
            }
            _ => {
                let d = o
                    .get("depth")
                    .and_then(Value::as_u64)
                    .ok_or_else(|| bad("\"depth\": expected a whole number 1..=16".to_string()))?;
                if !(1..=16).contains(&d) {
                    return Err(RequestError::Depth(d));
                }
                Request::CoarseDepth(d as u8)
            }
        })
    }

    /// The request's JSON object.
    pub fn to_json(&self) -> Value {
        let b = |b: &BoxM| {
            Value::from(
                b.min_m
                    .iter()
                    .chain(&b.max_m)
                    .map(|&v| Value::from(v))
                    .collect::<Vec<_>>(),
            )
        };
        match self {
            Request::Resync => serde_json::json!({"type": "resync"}),
            Request::Full => serde_json::json!({"type": "full"}),
            Request::FullBox(x) => serde_json::json!({"type": "full", "box": b(x)}),
            Request::Roi(x) => {
                serde_json::json!({"type": "roi", "box": x.as_ref().map_or(Value::Null, b)})
            }
            Request::CoarseDepth(d) => serde_json::json!({"type": "coarse_depth", "depth": d}),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn json(text: &str) -> Result<Request, String> {
        let v: Value = serde_json::from_str(text).unwrap();
        Request::from_json(v.as_object().unwrap()).map_err(|e| e.to_string())
    }

    #[test]
    fn json_and_bytes_round_trip() {
        for text in [
            r#"{"type":"resync"}"#,
            r#"{"type":"full"}"#,
            r#"{"type":"full","box":[-1.0,-2.0,-3.0,1.0,2.0,3.5]}"#,
            r#"{"type":"roi","box":[0.0,0.0,0.0,0.0,0.0,0.0]}"#,
            r#"{"type":"roi","box":null}"#,
            r#"{"type":"coarse_depth","depth":12}"#,
        ] {
            let r = json(text).unwrap();
            assert_eq!(r.to_json().to_string(), text);
            let mut b = Vec::new();
            r.emit(&mut b);
            assert_eq!(Request::parse(&b).unwrap(), r);
        }
    }

    #[test]
    fn bad_requests_name_the_field() {
        assert_eq!(
            json(r#"{"type":"roi","box":[1e300,0,0,0,0,0]}"#).unwrap_err(),
            "box [1e300, 0.0, 0.0, 0.0, 0.0, 0.0]: expected six finite numbers with x0 <= x1, y0 <= y1, z0 <= z1"
        );
        assert_eq!(
            json(r#"{"type":"roi"}"#).unwrap_err(),
            "roi: \"box\" is required ([x0,..,z1] or null)"
        );
        assert_eq!(
            json(r#"{"type":"coarse_depth","depth":17}"#).unwrap_err(),
            "coarse depth 17: expected 1..=16"
        );
        assert_eq!(
            json(r#"{"type":"full","bx":1}"#).unwrap_err(),
            "full: unknown field \"bx\""
        );
        assert_eq!(
            json(r#"{"type":"goto"}"#).unwrap_err(),
            "\"type\": expected resync, full, roi or coarse_depth, found \"goto\""
        );
        assert_eq!(
            Request::parse(&[3, 0]).unwrap_err().to_string(),
            "request kind 3: expected 48 bytes after the kind, found 1"
        );
        assert_eq!(
            Request::parse(&[9]).unwrap_err().to_string(),
            "request kind 9: expected 1..=6"
        );
        let mut nan = vec![4];
        for v in [f64::NAN, 0.0, 0.0, 1.0, 1.0, 1.0] {
            nan.extend_from_slice(&v.to_le_bytes());
        }
        assert!(matches!(
            Request::parse(&nan),
            Err(RequestError::NotABox(_))
        ));
    }
}
