//! The import graph inside `rovlink-rcp` has no arrow going back up (docs/architecture.md):
//! each module belongs to one layer and uses only its own layer and those below. Between
//! crates the compiler keeps the layers (`rovlink-rcp` cannot name the field adapters, the
//! tools or the command-line layer: it does not depend on them); inside this crate this test
//! does.
//!
//! An import is any `super::NAME` or `crate::NAME` outside the module's tests, doc links
//! included (a link up is a reader's arrow up too). A new module of `rcp` must be given its
//! layer here.

use std::path::Path;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// The layers of `rcp`, bottom first.
const LAYERS: [(&str, &[&str]); 4] = [
    ("vocabulary", &["rules", "report", "vehicle", "trunk_cache"]),
    (
        "engines",
        &[
            "operator",
            "rov",
            "autopilot",
            "orders",
            "script",
            "routing",
            "scenario",
            "harness",
            "camera",
            "config",
            "secure",
        ],
    ),
    ("driver", &["driver"]),
    ("sessions", &["network", "session", "realtime", "realnet"]),
];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS
        .iter()
        .position(|(_, modules)| modules.contains(&module))
}

/// The text of a source file without its `#[cfg(test)]` module.
fn code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    match text.find("#[cfg(test)]") {
        Some(at) => text[..at].to_string(),
        None => text,
    }
}

/// The `rcp` modules `text` names through `prefix` (`super::`, `crate::`).
fn named(text: &str, prefix: &str) -> Vec<String> {
    text.match_indices(prefix)
        .filter(|(at, _)| {
            // `rovlink_rcp::crate::` cannot occur; skip `$crate::` and `some_crate::`.
            !text[..*at].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_' || c == '$')
        })
        .map(|(at, _)| {
            text[at + prefix.len()..]
                .chars()
                .take_while(|c| c.is_ascii_lowercase() || *c == '_')
                .collect::<String>()
        })
        .filter(|name| !name.is_empty())
        .collect()
}

/// Every `.rs` file under `dir`, with its module name and its depth below `dir` (the files of a
/// folder `dir/m/` are module `m`'s).
fn sources(dir: &Path) -> Vec<(String, std::path::PathBuf, usize)> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            let name = path.file_name().unwrap().to_str().unwrap().to_string();
            for (_, file, depth) in sources(&path) {
                out.push((name.clone(), file, depth + 1));
            }
        } else if path.extension().is_some_and(|e| e == "rs") {
            let name = path.file_stem().unwrap().to_str().unwrap().to_string();
            out.push((name, path, 0));
        }
    }
    out
}

#[test]
fn no_import_in_rcp_goes_back_up() {
    let dir = Path::new(ROOT).join("src");
    let mut back = Vec::new();
    for (module, path, depth) in sources(&dir) {
        if module == "lib" {
            continue;
        }
        let Some(own) = layer_of(&module) else {
            panic!("src/{module}.rs has no layer in tests/layers.rs");
        };
        let mut text = code(&path);
        if depth > 0 {
            // Inside a module's folder, `super::super::` is the crate and `super::` the module.
            text = text.replace("super::super::", "crate::");
            text = text.replace("super::", "self::");
        }
        let mut used = named(&text, "super::");
        used.extend(named(&text, "crate::"));
        used.sort();
        used.dedup();
        for dep in used {
            if let Some(theirs) = layer_of(&dep)
                && theirs > own
            {
                back.push(format!(
                    "{module} ({}) -> {dep} ({})",
                    LAYERS[own].0, LAYERS[theirs].0
                ));
            }
        }
    }
    assert!(
        back.is_empty(),
        "imports going back up:\n{}",
        back.join("\n")
    );
}

/// The test sees an arrow back up when there is one (it can fail).
#[test]
fn an_arrow_back_up_is_seen() {
    let text = "use crate::session::Session;\nuse super::driver::Air;\nuse rovlink_wire::x;";
    let mut used = named(text, "crate::");
    used.extend(named(text, "super::"));
    assert_eq!(used, ["session", "driver"]);
    assert!(layer_of("session") > layer_of("rov"));
}
