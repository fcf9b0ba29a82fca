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
mod octo_view;
mod octomap_color;
mod serial_pty;
mod sweep;
mod tdma_console;
mod tdma_mavlink;
mod tdma_network;
mod tdma_network_pty;
mod tdma_pace;
mod tdma_sitl;
