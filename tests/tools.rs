//! The process tests: every tool built, run through pipes, files, ports and
//! pseudo-terminals, against the real peers. One test binary, one module per area
//! (ripgrep's layout); the tools are found beside it (`build.rs`).

mod cli_debt;
mod cli_link;
mod cli_modem;
mod cli_octo;
mod cli_rcp;
mod cli_tdma;
mod common;
mod crate_graph;
mod foxglove_live;
mod foxglove_schemas;
mod foxglove_stock;
mod golden_sessions;
mod hostile_debt_rcp;
mod hostile_flags;
mod hostile_link_modem;
mod hostile_octo;
mod hostile_octo_bags;
mod hostile_tdma;
mod hostile_tdma_field;
mod hostile_tdma_network;
mod octo_bags;
mod octo_live;
mod octo_view;
mod octomap_color;
mod ros2_live;
mod serial_pty;
mod sweep;
mod tdma_console;
mod tdma_mavlink;
mod tdma_network;
mod tdma_network_pty;
mod tdma_pace;
mod tdma_secure;
mod tdma_sitl;

/// The tools these tests run are packages of their own, built by `cargo build --workspace`
/// (`scripts/test` does it first), not by `cargo test`: each must be there. (Whether each is as
/// new as its sources is cargo's to know; run the tests through `scripts/test`, or build first.)
#[test]
fn the_tools_are_built() {
    let tools = [
        env!("TOOL_EXE_debt-encode"),
        env!("TOOL_EXE_debt-decode"),
        env!("TOOL_EXE_rcp-pack"),
        env!("TOOL_EXE_rcp-dump"),
        env!("TOOL_EXE_link-sim"),
        env!("TOOL_EXE_modem-bench"),
        env!("TOOL_EXE_tdma-run"),
        env!("TOOL_EXE_octo-delta"),
    ];
    for tool in tools {
        assert!(
            std::path::Path::new(tool).is_file(),
            "{tool} is missing: build the tools first (cargo build --workspace, as scripts/test does)"
        );
    }
}
