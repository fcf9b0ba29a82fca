//! JSON as every file and line the toolkit reads is parsed: an object that names a key twice is
//! refused.
//!
//! `serde_json` keeps the last of two equal keys, so `{"routes": {"0": {"2": 1}, "0": {"2":
//! 2}}}` would silently mean the second route. The readers already refuse unknown keys so that
//! a typo is not ignored; a repeated key is the same kind of mistake (an edit that pasted a
//! block twice), so [`from_str`] refuses it too, naming the key, where it is (a path such as
//! `routes."0"`) and, through `serde_json`'s error, the line and column of the repeat.
//!
//! Contract: never panics, on any text; nesting is bounded by `serde_json`'s recursion limit.

use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use serde_json::{Map, Value};

/// Parses `text` as one JSON value, refusing any object with a repeated key. The error is
/// `serde_json`'s, so `line()`, `column()` and `to_string()` say where.
pub fn from_str(text: &str) -> Result<Value, serde_json::Error> {
    let mut de = serde_json::Deserializer::from_str(text);
    let value = Strict { path: "" }.deserialize(&mut de)?;
    de.end()?;
    Ok(value)
}

/// [`from_str`] on bytes (which must be UTF-8 JSON).
pub fn from_slice(bytes: &[u8]) -> Result<Value, serde_json::Error> {
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let value = Strict { path: "" }.deserialize(&mut de)?;
    de.end()?;
    Ok(value)
}

/// Deserializes one value at `path` (empty at the top).
struct Strict<'p> {
    path: &'p str,
}

impl<'de> DeserializeSeed<'de> for Strict<'_> {
    type Value = Value;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Value, D::Error> {
        deserializer.deserialize_any(self)
    }
}

impl Strict<'_> {
    fn child(&self, key: &str) -> String {
        let key = if !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            if key.chars().all(|c| c.is_ascii_digit()) {
                format!("{key:?}")
            } else {
                key.to_string()
            }
        } else {
            format!("{key:?}")
        };
        if self.path.is_empty() {
            key
        } else {
            format!("{}.{key}", self.path)
        }
    }
}

impl<'de> Visitor<'de> for Strict<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a JSON value")
    }

    fn visit_bool<E>(self, v: bool) -> Result<Value, E> {
        Ok(Value::Bool(v))
    }

    fn visit_i64<E>(self, v: i64) -> Result<Value, E> {
        Ok(Value::from(v))
    }

    fn visit_u64<E>(self, v: u64) -> Result<Value, E> {
        Ok(Value::from(v))
    }

    fn visit_f64<E>(self, v: f64) -> Result<Value, E> {
        // serde_json never hands a non-finite number; `Null` would be its own choice too.
        Ok(serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number))
    }

    fn visit_str<E>(self, v: &str) -> Result<Value, E> {
        Ok(Value::String(v.to_string()))
    }

    fn visit_string<E>(self, v: String) -> Result<Value, E> {
        Ok(Value::String(v))
    }

    fn visit_unit<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }

    fn visit_none<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut items = Vec::new();
        loop {
            let path = format!("{}[{}]", self.path, items.len());
            match seq.next_element_seed(Strict { path: &path })? {
                Some(item) => items.push(item),
                None => return Ok(Value::Array(items)),
            }
        }
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let mut out = Map::new();
        while let Some(key) = map.next_key::<String>()? {
            let path = self.child(&key);
            if out.contains_key(&key) {
                return Err(de::Error::custom(format_args!(
                    "duplicate key {key:?} (at {path}): expected each key once"
                )));
            }
            let value = map.next_value_seed(Strict { path: &path })?;
            out.insert(key, value);
        }
        Ok(Value::Object(out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_values_as_serde_json() {
        for text in [
            r#"{"a": [1, -2, 3.5, 1e300, true, null, "x"], "b": {"c": {}}, "d": []}"#,
            "18446744073709551615",
            "-9223372036854775808",
            r#""\u00e9""#,
            "  [ ]  ",
        ] {
            let ours = from_str(text).unwrap();
            let theirs: Value = serde_json::from_str(text).unwrap();
            assert_eq!(ours, theirs, "{text}");
            assert_eq!(from_slice(text.as_bytes()).unwrap(), theirs);
        }
    }

    #[test]
    fn a_repeated_key_is_refused_with_its_path_and_line() {
        let text = "{\"routes\": {\"0\": {\"2\": 1},\n \"0\": {\"2\": 2}}}";
        let err = from_str(text).unwrap_err();
        assert_eq!(
            err.to_string(),
            "duplicate key \"0\" (at routes.\"0\"): expected each key once at line 2 column 4"
        );
        let err = from_str(r#"[{"a": 1}, {"b": [{"x y": 1, "x y": 1}]}]"#).unwrap_err();
        assert!(err.to_string().contains("(at [1].b[0].\"x y\")"), "{err}");
        // Equal keys in different objects are fine.
        assert!(from_str(r#"{"a": {"k": 1}, "b": {"k": 1}}"#).is_ok());
    }

    #[test]
    fn syntax_errors_and_trailing_text_are_serde_json_s() {
        for text in ["", "{", "[1,]", "{} x", "nul", "\"\\ud800\""] {
            let err = from_str(text).unwrap_err();
            let theirs = serde_json::from_str::<Value>(text).unwrap_err();
            assert_eq!(err.to_string(), theirs.to_string(), "{text:?}");
        }
    }
}
