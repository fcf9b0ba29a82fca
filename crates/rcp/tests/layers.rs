//! The import graph of `src/rcp/` has no arrow going back up (docs/architecture.md): each
//! module belongs to one layer and uses only its own layer and those below; `wire` uses
//! nothing of `rcp`; only the application layer uses the `cli` module.
//!
//! An import is any `super::NAME` or `rovlink_rcp::NAME` outside the module's tests, doc links
//! included (a link up is a reader's arrow up too). A new module of `rcp` must be given its
//! layer here.

use std::path::Path;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// The layers of `rcp`, bottom first.
const LAYERS: [(&str, &[&str]); 5] = [
    ("vocabulary", &["rules", "report"]),
    (
        "engines",
        &[
            "operator", "rov", "drive", "orders", "script", "routing", "scenario", "harness",
            "camera", "config",
        ],
    ),
    ("driver", &["driver"]),
    ("sessions", &["network", "session", "realtime", "realnet"]),
    (
        "application",
        &[
            "outputs",
            "mcap_log",
            "net_mcap",
            "foxglove",
            "foxglove_gate",
            "console",
            "mavlink",
            "tdma_run",
        ],
    ),
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

/// The `rcp` modules `text` names through `prefix` (`super::`, `rovlink_rcp::`).
fn named(text: &str, prefix: &str) -> Vec<String> {
    text.match_indices(prefix)
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
    let dir = Path::new(ROOT).join("src/rcp");
    let mut back = Vec::new();
    for (module, path, depth) in sources(&dir) {
        if module == "mod" {
            continue;
        }
        let Some(own) = layer_of(&module) else {
            panic!("src/rcp/{module}.rs has no layer in tests/layers.rs");
        };
        let mut text = code(&path);
        if depth > 0 {
            // Inside a module's folder, `super::super::` is rcp and `super::` the module itself.
            text = text.replace("super::super::", "rovlink_rcp::");
            text = text.replace("super::", "self::");
        }
        let mut used = named(&text, "super::");
        used.extend(named(&text, "rovlink_rcp::"));
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
        if own + 1 < LAYERS.len() && text.contains("rovlink_cli") {
            back.push(format!("{module} ({}) uses rovlink_cli", LAYERS[own].0));
        }
    }
    assert!(
        back.is_empty(),
        "imports going back up:\n{}",
        back.join("\n")
    );
}

#[test]
fn wire_uses_nothing_of_rcp_and_the_library_below_the_application_uses_no_cli() {
    let mut found = Vec::new();
    for (module, path, _) in sources(&Path::new(ROOT).join("src/wire")) {
        if code(&path).contains("rovlink_rcp") {
            found.push(format!("wire/{module} uses rovlink_rcp"));
        }
    }
    for top in ["debt", "link", "gll", "octo", "wire"] {
        let dir = Path::new(ROOT).join("src").join(top);
        if !dir.is_dir() {
            continue;
        }
        for (module, path, _) in sources(&dir) {
            if code(&path).contains("rovlink_cli") {
                found.push(format!("{top}/{module} uses rovlink_cli"));
            }
        }
    }
    assert!(found.is_empty(), "{}", found.join("\n"));
}
