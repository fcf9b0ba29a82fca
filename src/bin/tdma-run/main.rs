//! tdma-run: a whole teleoperation session, operator and ROV: both ends over a link model in
//! virtual time, or one end in real time over a serial port, pseudo-terminal or UDP.
//!
//! The flags and every kind of session are library calls ([`rovlink::rcp::tdma_run`]); this
//! maps their outcome to an exit code.
#![forbid(unsafe_code)]

use std::process::ExitCode;

use rovlink::rcp::tdma_run::{self, Args, TOOL};

fn main() -> ExitCode {
    let args: Args = rovlink::cli::parse(TOOL);
    rovlink::cli::finish(TOOL, tdma_run::run(&args))
}
