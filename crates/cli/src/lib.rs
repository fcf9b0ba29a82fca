//! The command-line layer every tool is built on, and the only module that uses clap.
//!
//! Each binary parses its arguments with [`parse`], checks and claims its outputs through
//! [`output::Outputs`], runs a library pipeline and ends with [`finish`]. What the tools share
//! lives here once:
//! - [`value`]: range-checked parsers for every numeric flag (finite, signed as it must be,
//!   capped at what no real campaign reaches), comma lists and points, messages with units;
//! - [`output`]: `-` for standard output (one output at most), binary refused on a terminal,
//!   an output that is an input refused, outputs claimed before any work is done;
//! - [`rows`]: CSV and JSON Lines rows, one write per whole line, flushed;
//! - [`metrics`]: `--metrics`, a run's figures with every parameter and its seed, one line;
//! - [`stop`]: SIGINT/SIGTERM/SIGHUP as a flag library loops poll, and the exit codes 130/143;
//! - [`progress`]: a progress bar only on a terminal;
//! - [`model`] and [`port`]: the flag groups of link models and real modems;
//! - [`say!`](crate::say): one line on standard error, prefixed with the tool's name.
//!
//! Errors from here are [`UsageError`]s (exit code 2); [`finish`] maps any error to the
//! exit-code table of [`rovlink_base::io::exit_code`].
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod metrics;
pub mod model;
pub mod port;
pub mod progress;
pub mod rows;
pub mod stop;
pub mod value;

#[doc(hidden)]
pub use rovlink_base::io;
pub use rovlink_base::{UsageError, output};

/// Says one line on standard error, prefixed with the calling tool's `const TOOL: &str`;
/// never panics, even with standard error closed.
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::io::warn(TOOL, &format!($($arg)*))
    };
}

/// Parses the command line: `--help` and `--version` print and exit 0; any other problem is
/// one line on standard error (`tool: --ipg: expected 1 ms ..= 10 min, found 1e-9`), exit 2.
///
/// Negative numbers are values, never flags (`--x -5` reaches `--x`'s range check and says
/// what it expected), in every subcommand too.
pub fn parse<A: clap::Parser>(tool: &str) -> A {
    parse_with_matches(tool).0
}

/// [`parse`], also handing back clap's matches of the command line, for what the parsed
/// arguments cannot say: whether a flag with a default was given
/// ([`clap::ArgMatches::value_source`]).
pub fn parse_with_matches<A: clap::Parser>(tool: &str) -> (A, clap::ArgMatches) {
    match try_parse_with_matches_from::<A, _, _>(std::env::args_os()) {
        Ok(parsed) => parsed,
        Err(err) => exit_with(tool, err),
    }
}

/// [`parse`] without exiting, from any argument list (tests use it). The first successful parse
/// of a process records its parameters for [`metrics`].
pub fn try_parse_from<A, I, T>(args: I) -> Result<A, clap::Error>
where
    A: clap::Parser,
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    try_parse_with_matches_from(args).map(|(parsed, _)| parsed)
}

/// [`try_parse_from`], also handing back clap's matches of `args` (negative numbers taken as
/// values, see [`parse`]), whose parameters it records for [`metrics`].
fn try_parse_with_matches_from<A, I, T>(args: I) -> Result<(A, clap::ArgMatches), clap::Error>
where
    A: clap::Parser,
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    fn negatives(cmd: clap::Command) -> clap::Command {
        let names: Vec<String> = cmd
            .get_subcommands()
            .map(|s| s.get_name().to_string())
            .collect();
        let mut cmd = cmd.allow_negative_numbers(true);
        for name in names {
            cmd = cmd.mut_subcommand(name, negatives);
        }
        cmd
    }
    let cmd = negatives(A::command());
    let matches = cmd.clone().try_get_matches_from(args)?;
    metrics::record(&cmd, &matches);
    A::from_arg_matches(&matches).map(|parsed| (parsed, matches))
}

/// Prints a clap error as [`parse`] does and exits.
pub fn exit_with(tool: &str, err: clap::Error) -> ! {
    use clap::error::ErrorKind;
    if matches!(
        err.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        let _ = err.print();
        std::process::exit(
            if err.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand {
                2
            } else {
                0
            },
        );
    }
    rovlink_base::io::warn(tool, &one_line(&err));
    std::process::exit(i32::from(rovlink_base::io::EXIT_BAD_INPUT));
}

/// The one-line text of a clap error: `--flag: reason` for a bad value, clap's own first line
/// otherwise (without its `error: ` prefix).
pub fn one_line(err: &clap::Error) -> String {
    use clap::error::{ContextKind, ContextValue};
    if let Some(reason) = std::error::Error::source(err) {
        let flag = match err.get(ContextKind::InvalidArg) {
            Some(ContextValue::String(arg)) => arg.split(' ').next().unwrap_or(arg).to_string(),
            _ => String::new(),
        };
        return if flag.is_empty() {
            reason.to_string()
        } else {
            format!("{flag}: {reason}")
        };
    }
    let text = err.render().to_string();
    let first = text
        .lines()
        .find(|l| !l.trim().is_empty())
        .unwrap_or("bad usage");
    let first = first.strip_prefix("error: ").unwrap_or(first).trim();
    let mut line = first.to_string();
    // What clap lists under its first line (the required arguments missing, say) belongs to it.
    let listed: Vec<&str> = text
        .lines()
        .skip_while(|l| l.trim().is_empty())
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .map(str::trim)
        .collect();
    if !listed.is_empty() {
        line = format!("{} {}", line.trim_end_matches(':'), listed.join(", "));
    }
    // clap puts a suggestion or the usage on the following lines; keep a short usage hint.
    if let Some(usage) = text.lines().find(|l| l.starts_with("Usage: ")) {
        line.push_str(&format!(" ({})", usage.trim()));
    }
    line
}

/// Bad usage when an option that only applies together with `parent` was given without it
/// (clap's own `requires` is not enforced next to a positional argument that conflicts with
/// `parent`, hence this check).
pub fn only_with(
    parent_given: bool,
    parent: &str,
    options: &[(&str, bool)],
) -> Result<(), UsageError> {
    if parent_given {
        return Ok(());
    }
    match options.iter().find(|(_, given)| *given) {
        Some((flag, _)) => Err(UsageError(format!("{flag} only applies with {parent}"))),
        None => Ok(()),
    }
}

/// Ends a tool's `main`: maps its outcome to an exit code (0 ok, 1 a requested check failed,
/// 2 bad usage or input, a closed pipe downstream is 0) and prints the error in one line,
/// prefixed with the tool's name.
///
/// An error that ends a run after a signal asked it to stop still ends it as interrupted
/// (130, 143 or 129): the step that did not poll the flag (a decompression, an open, a large
/// read) found the error only after the user had stopped the run, so the stop is what the
/// exit code reports; the error is still printed, marked as such.
pub fn finish(tool: &str, outcome: anyhow::Result<u8>) -> std::process::ExitCode {
    match outcome {
        Err(err)
            if stop::requested()
                && rovlink_base::io::exit_code(err.as_ref()) != rovlink_base::io::EXIT_OK =>
        {
            let note = stop::note().unwrap_or_else(|| "interrupted".into());
            rovlink_base::io::warn(
                tool,
                &format!("{} ({note})", rovlink_base::io::error_text(err.as_ref())),
            );
            std::process::ExitCode::from(stop::code_or(rovlink_base::io::EXIT_BAD_INPUT))
        }
        outcome => rovlink_base::io::finish_main(tool, outcome),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser, Debug)]
    struct Tool {
        /// IPG.
        #[arg(long, value_name = "MS", value_parser = value::millis(1.0, 600_000.0))]
        ipg: Option<f64>,
        /// Count.
        #[arg(long, value_parser = value::count(1, value::MAX_COUNT))]
        count: Option<u64>,
    }

    #[test]
    fn value_errors_are_one_line_naming_the_flag() {
        let err = Tool::try_parse_from(["t", "--ipg", "1e-9"]).unwrap_err();
        assert_eq!(
            one_line(&err),
            "--ipg: expected 1 ms ..= 10 min, found 1e-9"
        );
        let err = try_parse_from::<Tool, _, _>(["t", "--count", "-5"]).unwrap_err();
        assert!(one_line(&err).starts_with("--count: expected a whole number"));
        let err = Tool::try_parse_from(["t", "--bogus"]).unwrap_err();
        let line = one_line(&err);
        assert!(line.contains("--bogus") && !line.contains('\n'), "{line}");
    }

    #[derive(Parser, Debug)]
    struct Needs {
        /// A.
        #[arg(long, requires = "b")]
        a: Option<u8>,
        /// B.
        #[arg(long)]
        b: Option<u8>,
    }

    #[test]
    fn missing_arguments_are_named() {
        let err = Needs::try_parse_from(["t", "--a", "1"]).unwrap_err();
        let line = one_line(&err);
        assert!(line.contains("not provided --b <B>"), "{line}");
        assert!(!line.contains('\n'), "{line}");
    }

    #[test]
    fn only_with_names_both_flags() {
        assert!(only_with(true, "--port", &[("--baud", true)]).is_ok());
        let err =
            only_with(false, "--port", &[("--idle-ms", false), ("--baud", true)]).unwrap_err();
        assert_eq!(err.0, "--baud only applies with --port");
    }
}
