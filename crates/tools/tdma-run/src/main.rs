//! tdma-run: a whole teleoperation session, operator and ROV: both ends over a link model in
//! virtual time, or one end in real time over a serial port, pseudo-terminal or UDP.
//!
//! [`run`] takes the parsed flags ([`flags::Args`]) and runs the kind of session they ask for,
//! each a setup of the one driver (`rovlink_rcp::driver`):
//!
//! - [`single::run`]: one vehicle, both ends in virtual time, or one end in real time over a
//!   port (`--role`);
//! - [`scenario_run::run`]: a multi-vehicle scenario in virtual time (`--scenario`);
//! - [`node_run::run`]: one node of a real network, in real time (`--routes`).
//!
//! `setup` is what they share: the output claims (every output claimed before any work, so bad
//! usage leaves no file), the engines' parts, the exit codes; `outputs` writes the session's
//! files. Each returns the process's exit code; errors are printed by `rovlink_cli::finish`.
#![forbid(unsafe_code)]

mod flags;
mod node_run;
mod outputs;
mod scenario_run;
mod setup;
mod single;

use std::process::ExitCode;

use flags::Args;

/// The tool's name, prefixed to everything it says on stderr.
pub const TOOL: &str = "tdma-run";

fn main() -> ExitCode {
    let args = Args::from_command_line();
    rovlink_cli::finish(TOOL, run(&args))
}

/// Runs the session the flags ask for; the process's exit code.
fn run(args: &Args) -> anyhow::Result<u8> {
    if let Some(path) = &args.new_foxglove_token {
        return setup::new_foxglove_token(path);
    }
    rovlink_cli::stop::install()?;
    if args.ros2 && (args.scenario.is_some() || args.routes.is_some()) {
        return Err(rovlink_base::UsageError(
            "--ros2 publishes a single session (an operator end or a simulation): not with \
             --scenario or --routes"
                .into(),
        )
        .into());
    }
    if let Some(path) = &args.scenario {
        return scenario_run::run(args, path);
    }
    if let Some(path) = &args.routes {
        return node_run::run(args, path);
    }
    single::run(args)
}
