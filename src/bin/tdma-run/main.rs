//! tdma-run: a whole teleoperation session, operator and ROV: both ends over a link model in
//! virtual time, or one end in real time over a serial port, pseudo-terminal or UDP.
//!
//! Every kind of session is the library's one driver ([`rovlink::rcp::driver`]): `single`
//! (one vehicle, simulated or one end in real time), `network` (`--scenario`), `realnet`
//! (`--routes`, one node in real time); `setup` is what they share.
#![forbid(unsafe_code)]

mod cli;
mod network;
mod realnet;
mod setup;
mod single;

use std::process::ExitCode;

use anyhow::Result;

use cli::Args;

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "tdma-run";

fn main() -> ExitCode {
    let args: Args = rovlink::cli::parse(TOOL);
    rovlink::cli::finish(TOOL, run(&args))
}

/// One of the three kinds of session the flags ask for.
fn run(args: &Args) -> Result<u8> {
    rovlink::cli::stop::install()?;
    if let Some(path) = &args.scenario {
        return network::run(args, path);
    }
    if let Some(path) = &args.routes {
        return realnet::run(args, path);
    }
    single::run(args)
}
