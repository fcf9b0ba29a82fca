//! The crate graph as the workspace promises it (docs/architecture.md), read from `cargo tree`:
//! a tool or a library pulls in only what its layer needs.

use std::process::Command;

/// The packages `package` builds with (normal dependencies, the whole tree), one name a line.
fn tree(package: &str) -> Vec<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args([
            "tree",
            "--offline",
            "--locked",
            "-e",
            "normal",
            "--prefix",
            "none",
        ])
        .args(["--format", "{p}", "-p", package])
        .current_dir(env!("REPO_ROOT"))
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "cargo tree -p {package}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut names: Vec<String> = String::from_utf8(out.stdout)
        .expect("UTF-8")
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect();
    names.sort();
    names.dedup();
    names
}

/// `package` builds without any of `absent`, and with every one of `present`.
fn check(package: &str, absent: &[&str], present: &[&str]) {
    let names = tree(package);
    for a in absent {
        assert!(
            !names.iter().any(|n| n == a),
            "{package} builds with {a}: {names:?}"
        );
    }
    for p in present {
        assert!(
            names.iter().any(|n| n == p),
            "{package} builds without {p}: {names:?}"
        );
    }
}

/// What the field adapters and the map's readers bring: an async runtime, the Foxglove SDK,
/// MAVLink, SQLite compiled from C, zstd.
const HEAVY: [&str; 5] = ["tokio", "foxglove", "mavlink", "rusqlite", "zstd"];

#[test]
fn the_codec_tools_build_without_the_heavy_crates() {
    for tool in ["debt-encode", "debt-decode"] {
        check(tool, &HEAVY, &["rovlink-debt", "rovlink-cli", "clap"]);
    }
    check("rcp-pack", &HEAVY, &["rovlink-wire"]);
}

#[test]
fn the_engines_have_no_flags_and_no_async_runtime() {
    check(
        "rovlink-rcp",
        &[
            "clap",
            "rovlink-cli",
            "rovlink-field",
            "tokio",
            "foxglove",
            "mavlink",
        ],
        &["rovlink-wire", "rovlink-link", "rovlink-debt"],
    );
    for lib in [
        "rovlink-base",
        "rovlink-wire",
        "rovlink-debt",
        "rovlink-link",
        "rovlink-octo",
    ] {
        check(lib, &["clap", "rovlink-cli", "tokio", "rusqlite"], &[]);
    }
}

#[test]
fn the_field_adapters_are_the_live_tools_and_only_octo_delta_has_the_bag_readers() {
    check(
        "tdma-run",
        &["rusqlite"],
        &["rovlink-field", "tokio", "mavlink"],
    );
    // octo-delta's live view serves Foxglove (rovlink-field's foxglove_map, on tokio).
    check(
        "octo-delta",
        &[],
        &[
            "rovlink-scans",
            "rusqlite",
            "rovlink-field",
            "rovlink-maplink",
        ],
    );
    for tool in ["link-sim", "modem-bench", "rcp-pack", "rcp-dump"] {
        check(tool, &["rovlink-field", "tokio"], &[]);
    }
}

#[test]
fn only_the_tools_on_a_ros2_graph_link_the_dds() {
    check("octo-delta", &[], &["rovlink-ros2", "rustdds"]);
    check("tdma-run", &[], &["rovlink-ros2", "rustdds"]);
    check(
        "rovlink-ros2",
        &["rovlink-scans", "rovlink-octo", "tokio"],
        &["rustdds"],
    );
    for tool in [
        "debt-encode",
        "debt-decode",
        "rcp-pack",
        "rcp-dump",
        "link-sim",
        "modem-bench",
    ] {
        check(tool, &["rovlink-ros2", "rustdds"], &[]);
    }
}
