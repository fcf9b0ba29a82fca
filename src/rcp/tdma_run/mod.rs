//! tdma-run's sessions as library calls: [`run`] takes the parsed flags ([`Args`]) and runs the
//! kind of session they ask for, each a setup of the one driver ([`crate::rcp::driver`]):
//!
//! - [`single::run`]: one vehicle, both ends in virtual time, or one end in real time over a
//!   port (`--role`);
//! - [`network::run`]: a multi-vehicle scenario in virtual time (`--scenario`);
//! - [`realnet::run`]: one node of a real network, in real time (`--routes`).
//!
//! `setup` is what they share: the output claims (every output claimed before any work, so bad
//! usage leaves no file), the engines' parts, the exit codes. This is the application layer:
//! the only part of `rcp` that reads flags. Each returns the process's exit code; errors are
//! the caller's to print ([`crate::cli::finish`]).

mod args;
pub mod network;
pub mod realnet;
mod setup;
pub mod single;

pub use args::Args;

/// The tool's name, prefixed to everything it says on stderr.
pub const TOOL: &str = "tdma-run";

/// Runs the session the flags ask for; the process's exit code.
pub fn run(args: &Args) -> anyhow::Result<u8> {
    crate::cli::stop::install()?;
    if let Some(path) = &args.scenario {
        return network::run(args, path);
    }
    if let Some(path) = &args.routes {
        return realnet::run(args, path);
    }
    single::run(args)
}
