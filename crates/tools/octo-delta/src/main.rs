//! octo-delta: an OctoMap-compatible occupancy map built from point clouds, whose changes stream
//! over a narrow link (fine and coloured inside a region of interest, coarse outside). The work
//! is `rovlink_mapper::pipeline`'s; this binary parses, claims its outputs and reports.
#![forbid(unsafe_code)]

mod flags;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;
use flags::{ApplyArgs, BuildArgs, Cli, Command, DumpArgs, FullArgs, SynthArgs};
use rovlink_base::io::EXIT_OK;
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_cli::metrics;
use rovlink_cli::rows::{RowFormat, RowWriter};
use rovlink_cli::say;
use rovlink_cli::{UsageError, progress, stop};
use rovlink_mapper::pipeline::{self, Hooks, SinkError, StatsRow};
use rovlink_mapper::view;
use rovlink_octo::{files, transfer};

const TOOL: &str = "octo-delta";

fn main() -> ExitCode {
    let outcome = match rovlink_cli::parse::<Cli>(TOOL).command {
        Command::Build(a) => build(&a),
        Command::Apply(a) => apply(&a),
        Command::Dump(a) => dump(&a),
        Command::Full(a) => full(&a),
        Command::Synth(a) => synth_cmd(&a),
    };
    rovlink_cli::finish(TOOL, outcome)
}

/// Claims the output of a one-input command, then reads the input: its bytes and the name its
/// errors carry.
fn claim_and_read(input: &Path, output: &Path, kind: Kind) -> Result<(Dest, Vec<u8>, String)> {
    let mut outs = Outputs::new();
    outs.input(Some(input));
    let dest = outs.claim("-o", output, kind)?;
    let (bytes, name) = pipeline::read_input(input)?;
    Ok((dest, bytes, name))
}

fn build(a: &BuildArgs) -> Result<u8> {
    let cfg = a.config();
    cfg.validate()?;
    let link = a.link.as_deref().map(transfer::model_by_name).transpose();
    let link = link.map_err(|e| UsageError(format!("--link: {e}")))?;
    let mut outs = Outputs::new();
    // A bag's own files (a rosbag2 directory's .db3 files and metadata.yaml) are inputs too.
    let read = pipeline::input_files(&a.inputs, a.format);
    outs.inputs(read.iter().map(PathBuf::as_path));
    outs.input(a.link.as_deref().map(Path::new));
    let stream = outs.claim("-o", &a.output, Kind::Binary)?;
    let bt = outs.claim_opt("--bt", a.bt.as_deref(), Kind::Binary)?;
    let ot = outs.claim_opt("--ot", a.ot.as_deref(), Kind::Binary)?;
    let stats = outs.claim_opt("--stats", a.stats.as_deref(), Kind::Text)?;
    let arrivals = outs.claim_opt("--arrivals", a.arrivals.as_deref(), Kind::Text)?;
    let metrics_dest = outs.claim_opt("--metrics", a.metrics.as_deref(), Kind::Text)?;
    let mut metrics_out = metrics_dest.map(|d| d.open()).transpose()?;
    stop::install()?;
    let mut out = stream.open()?;
    let mut rows = stats.map(|d| RowWriter::new(d, RowFormat::Csv, &pipeline::STATS_COLUMNS));
    let bar = progress::bar(a.quiet, 0, flags::PROGRESS);
    let outcome = (|| -> Result<pipeline::Built> {
        let mut sink = |r: &StatsRow| -> Result<(), SinkError> {
            Ok(rows.as_mut().map_or(Ok(()), |w| w.row(r))?)
        };
        let mut show = progress::follow(&bar);
        let mut hooks = Hooks {
            stop: stop::flag(),
            stats: a.stats.is_some().then_some(&mut sink as _),
            progress: Some(&mut show),
        };
        let built = pipeline::build(&cfg, &a.inputs, &mut out, &stream.name(), &mut hooks)?;
        bar.finish_and_clear();
        // Every output holds what was done, also when a signal stopped the build. The two
        // map files are serialised and committed (written, synced, renamed) side by side; the
        // stream is committed once both are in place, so a failed map leaves no stream.
        std::thread::scope(|s| -> Result<()> {
            let tree = &built.tree;
            let ot_job = ot
                .as_ref()
                .map(|d| s.spawn(move || d.write_whole(&files::write_ot(tree))));
            let bt_done = bt.as_ref().map(|d| d.write_whole(&files::write_bt(tree)));
            let ot_done = ot_job.map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
            bt_done.transpose()?;
            ot_done.transpose()?;
            Ok(())
        })?;
        out.finish()?;
        Ok(built)
    })();
    // A failed run (bad input found late, a full disk) leaves no stats file either.
    if outcome.is_err()
        && let Some(rows) = rows.take()
    {
        rows.discard();
    }
    let built = outcome?;
    rows.map(RowWriter::finish).transpose()?;
    // Clouds left out of the map are said even with --quiet: the map lacks them.
    let messages = built.messages(a.quiet, stop::note().as_deref());
    messages.iter().for_each(|m| say!("{m}"));
    let mut figures = built.figures();
    if let Some(model) = link {
        let report = transfer::send_over(&model, &built.report.messages, a.scan_period, a.seed);
        figures["link"] = report.figures();
        if let Some(d) = arrivals {
            let w = RowWriter::new(d, RowFormat::Csv, &pipeline::ARRIVAL_COLUMNS);
            w.write_all(&pipeline::arrival_rows(&report))?;
        }
        if !a.quiet {
            report.lines().iter().for_each(|line| say!("{line}"));
        }
    }
    if let Some(mut out) = metrics_out.take() {
        metrics::write(&mut out, TOOL, a.link.is_some().then_some(a.seed), &figures)?;
        out.finish()?;
    }
    Ok(stop::code_or(EXIT_OK))
}

fn apply(a: &ApplyArgs) -> Result<u8> {
    let mut outs = Outputs::new();
    outs.input(Some(&a.input));
    outs.input(a.arrivals.as_deref());
    let ot = outs.claim_opt("-o", a.output.as_deref(), Kind::Binary)?;
    let mcap = outs.claim_opt("--mcap", a.mcap.as_deref(), Kind::Binary)?;
    let (bytes, name) = pipeline::read_input(&a.input)?;
    let messages = a.messages.map_or(usize::MAX, |n| n as usize);
    let Some(mcap) = mcap else {
        let view = pipeline::apply(&bytes, &name, messages)?;
        ot.map(|d| d.write_whole(&files::write_ot(&view)))
            .transpose()?;
        return Ok(EXIT_OK);
    };
    let arrivals = a.arrivals.as_deref().map(pipeline::read_input);
    let arrivals = arrivals.transpose()?;
    let timing = view::Timing::new(arrivals.as_ref(), a.scan_period);
    let mut out = mcap.open()?;
    let (view, _) = view::apply_with_view(&bytes, &name, messages, timing, &mut out, &mcap.name())?;
    // The .ot first: a failure there leaves no MCAP either (it is committed last).
    ot.map(|d| d.write_whole(&files::write_ot(&view)))
        .transpose()?;
    out.finish()?;
    Ok(EXIT_OK)
}

fn dump(a: &DumpArgs) -> Result<u8> {
    let (dest, bytes, name) = claim_and_read(&a.input, &a.output, Kind::Text)?;
    let mut out = dest.open()?;
    pipeline::dump(&bytes, &name, a.format, a.voxels, &mut out)?;
    out.finish()?;
    Ok(EXIT_OK)
}

fn full(a: &FullArgs) -> Result<u8> {
    let (dest, bytes, name) = claim_and_read(&a.input, &a.output, Kind::Binary)?;
    dest.write_whole(&pipeline::full(&bytes, &name, a.view.coarse(), a.view.roi)?)?;
    Ok(EXIT_OK)
}

fn synth_cmd(a: &SynthArgs) -> Result<u8> {
    let params = a.params();
    params.validate()?;
    let dest = Outputs::new().claim("-o", &a.output, Kind::Binary)?;
    stop::install()?;
    let bytes = pipeline::synth(&params, a.mcap())?;
    // The survey is made whole before anything is written: a stopped run writes nothing.
    if !stop::requested() {
        dest.write_whole(&bytes)?;
    }
    Ok(stop::code_or(EXIT_OK))
}
