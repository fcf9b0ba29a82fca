//! octo-delta: an OctoMap-compatible occupancy map built from point clouds, whose changes stream
//! over a narrow link (fine and coloured inside a region of interest, coarse outside). The work
//! is `rovlink_mapper::pipeline`'s; this binary parses, claims its outputs and reports.
//!
//! `main` parses the flags, runs the subcommand ([`build_run`] for `build`, [`commands`] for
//! the others) and maps its outcome to the exit code.
#![forbid(unsafe_code)]

mod build_run;
mod commands;
mod flags;
mod map_run;
mod view_run;

use std::process::ExitCode;

use flags::{Cli, Command};

const TOOL: &str = "octo-delta";

fn main() -> ExitCode {
    let outcome = match rovlink_cli::parse::<Cli>(TOOL).command {
        Command::Build(a) => build_run::build(&a),
        Command::Apply(a) => commands::apply(&a),
        Command::Dump(a) => commands::dump(&a),
        Command::Full(a) => commands::full(&a),
        Command::Synth(a) => commands::synth_cmd(&a),
        Command::Map(a) => map_run::map(&a),
        Command::View(a) => view_run::view(&a),
    };
    rovlink_cli::finish(TOOL, outcome)
}
