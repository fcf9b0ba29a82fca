//! `--metrics`: a run's figures as one JSON object on one line that also carries every
//! parameter of the run and its seed, so that the documents of many runs concatenate (JSON
//! Lines) and a sweep (`scripts/sweep`) can tell from each what produced it.
//!
//! The parameters are recorded by [`crate::parse`] from clap's matches, so that no tool
//! lists its flags twice: every argument of the command line (and of its subcommand) with the
//! value it was given or its default, keyed by its long name (`ber` for `--ber`) or, for a
//! positional argument, its id; an argument neither given nor defaulted is `null`. A value
//! that reads as a JSON number becomes a number, `true`/`false` a boolean, anything else stays
//! text; an argument that takes several values is a list, also when given one.
//!
//! The document is `{"tool", "version", "seed", "params", ...figures}`: the figures' own
//! top-level fields follow, unchanged, so readers of a tool's earlier metrics keep working.
//! `seed` is the seed the run used (given or default), `null` for a tool without randomness.

use std::sync::OnceLock;

use serde_json::{Map, Value};

use rovlink_base::io::{IoError, Output};

/// The parameters [`crate::parse`] recorded for this process.
static PARAMS: OnceLock<Map<String, Value>> = OnceLock::new();

/// Records the parameters of `matches` (parsed by `cmd`) for this process's [`document`]s;
/// the first record stands.
pub(crate) fn record(cmd: &clap::Command, matches: &clap::ArgMatches) {
    let _ = PARAMS.set(params_of(cmd, matches));
}

/// The parameters of a parsed command line, as the module doc describes (a subcommand's name
/// under `subcommand`, its arguments beside the command's own).
pub fn params_of(cmd: &clap::Command, matches: &clap::ArgMatches) -> Map<String, Value> {
    let mut params = Map::new();
    for arg in cmd.get_arguments() {
        let id = arg.get_id().as_str();
        if matches!(id, "help" | "version") {
            continue;
        }
        let key = arg.get_long().unwrap_or(id).to_string();
        let value = match matches.try_get_raw(id) {
            Ok(Some(raw)) => {
                let values: Vec<Value> = raw.map(|v| typed(&v.to_string_lossy())).collect();
                let many = matches!(arg.get_action(), clap::ArgAction::Append)
                    || arg.get_num_args().is_some_and(|n| n.max_values() > 1);
                match <[Value; 1]>::try_from(values) {
                    Ok([one]) if !many => one,
                    Ok([one]) => Value::Array(vec![one]),
                    Err(values) => Value::Array(values),
                }
            }
            _ => Value::Null,
        };
        params.insert(key, value);
    }
    if let Some((name, sub_matches)) = matches.subcommand()
        && let Some(sub) = cmd.find_subcommand(name)
    {
        params.insert("subcommand".into(), Value::String(name.to_string()));
        params.extend(params_of(sub, sub_matches));
    }
    params
}

/// A command-line value as JSON: a number when it reads as one, a boolean for `true`/`false`,
/// else the text.
fn typed(text: &str) -> Value {
    match text {
        "true" => Value::Bool(true),
        "false" => Value::Bool(false),
        _ => match serde_json::from_str::<serde_json::Number>(text) {
            Ok(number) => Value::Number(number),
            Err(_) => Value::String(text.to_string()),
        },
    }
}

/// The metrics document of this run: `tool`, `version`, `seed`, `params` (as recorded by
/// [`crate::parse`], empty when nothing was recorded), then the figures' fields (figures
/// that are not a JSON object go under `figures`).
pub fn document(tool: &str, seed: Option<u64>, figures: Value) -> Value {
    let mut doc = Map::new();
    doc.insert("tool".into(), Value::String(tool.to_string()));
    doc.insert(
        "version".into(),
        Value::String(env!("CARGO_PKG_VERSION").to_string()),
    );
    doc.insert("seed".into(), seed.map_or(Value::Null, Value::from));
    doc.insert(
        "params".into(),
        Value::Object(PARAMS.get().cloned().unwrap_or_default()),
    );
    match figures {
        Value::Object(fields) => {
            for (key, value) in fields {
                doc.entry(key).or_insert(value);
            }
        }
        other => {
            doc.insert("figures".into(), other);
        }
    }
    Value::Object(doc)
}

/// Writes this run's [`document`] to `out` as one line and flushes it.
pub fn write(
    out: &mut Output,
    tool: &str,
    seed: Option<u64>,
    figures: &impl serde::Serialize,
) -> Result<(), IoError> {
    let as_io = |e: serde_json::Error| IoError::Write {
        name: out.name(),
        source: std::io::Error::other(e),
    };
    let figures = serde_json::to_value(figures).map_err(as_io)?;
    let mut line = serde_json::to_string(&document(tool, seed, figures)).map_err(as_io)?;
    line.push('\n');
    out.write_bytes(line.as_bytes())?;
    out.flush_named()
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

    #[derive(Parser, Debug)]
    struct Tool {
        /// Input.
        input: Option<String>,
        /// BER.
        #[arg(long, default_value_t = 0.0)]
        ber: f64,
        /// Seed.
        #[arg(long)]
        seed: Option<u64>,
        /// A bare flag.
        #[arg(long)]
        sim: bool,
        /// Names.
        #[arg(long, num_args = 1..)]
        names: Vec<String>,
        /// Subcommand.
        #[command(subcommand)]
        cmd: Option<Cmd>,
    }

    #[derive(Subcommand, Debug)]
    enum Cmd {
        /// Build.
        Build {
            /// Resolution.
            #[arg(long, default_value = "0.1")]
            res: String,
        },
    }

    fn params(args: &[&str]) -> Value {
        let cmd = Tool::command();
        let matches = cmd.clone().try_get_matches_from(args).unwrap();
        Tool::from_arg_matches(&matches).unwrap();
        Value::Object(params_of(&cmd, &matches))
    }

    #[test]
    fn every_argument_is_recorded_given_or_default() {
        let p = params(&["t", "in.png", "--ber", "7e-4", "--sim", "--names", "a", "2"]);
        assert_eq!(
            p,
            serde_json::json!({
                "input": "in.png", "ber": 7e-4, "seed": null, "sim": true, "names": ["a", 2]
            })
        );
        let p = params(&["t", "--names", "one"]);
        assert_eq!(p["names"], serde_json::json!(["one"]));
        let p = params(&["t", "--seed", "18446744073709551615", "build"]);
        assert_eq!(p["seed"], serde_json::json!(u64::MAX));
        assert_eq!(
            (&p["sim"], &p["ber"]),
            (&Value::Bool(false), &Value::from(0))
        );
        assert_eq!(
            (&p["subcommand"], &p["res"]),
            (&Value::from("build"), &Value::from(0.1))
        );
    }

    #[test]
    fn figures_follow_the_run_header_unchanged() {
        let doc = document(
            "t",
            Some(5),
            serde_json::json!({"delay_ms": 1.5, "tool": "x"}),
        );
        let keys: Vec<&String> = doc.as_object().unwrap().keys().collect();
        assert_eq!(keys, ["tool", "version", "seed", "params", "delay_ms"]);
        assert_eq!(
            (&doc["tool"], &doc["seed"]),
            (&Value::from("t"), &Value::from(5))
        );
        let doc = document("t", None, serde_json::json!([1, 2]));
        assert_eq!(
            (&doc["seed"], &doc["figures"]),
            (&Value::Null, &serde_json::json!([1, 2]))
        );
    }
}
