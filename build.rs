//! Tells the process tests (tests/tools.rs) where the tools are: `TOOL_EXE_<name>` is the path
//! of each tool in this build's profile directory, and `REPO_ROOT` is the workspace root. The
//! tools are packages of their own (so that each builds with only what it uses); build them
//! first (`cargo build --workspace`, as `scripts/test` does). A test that finds a tool missing
//! says so.

use std::path::PathBuf;

const TOOLS: [&str; 8] = [
    "debt-encode",
    "debt-decode",
    "rcp-pack",
    "rcp-dump",
    "link-sim",
    "modem-bench",
    "tdma-run",
    "octo-delta",
];

fn main() {
    // OUT_DIR is <target>/<profile>/build/<package>-<hash>/out; the tools are in <target>/<profile>.
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let profile_dir = out
        .ancestors()
        .nth(3)
        .expect("OUT_DIR is <target>/<profile>/build/<package>/out")
        .to_path_buf();
    for tool in TOOLS {
        let path = profile_dir.join(tool);
        println!("cargo:rustc-env=TOOL_EXE_{tool}={}", path.display());
    }
    let root = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    println!("cargo:rustc-env=REPO_ROOT={root}");
    println!("cargo:rerun-if-changed=build.rs");
}
