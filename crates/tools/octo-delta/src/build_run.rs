//! octo-delta build: claims every output, runs `rovlink_mapper::pipeline::build` with the
//! stop flag, the stats rows and the progress bar as hooks, commits the map files and the
//! stream, then sends the stream over `--link` and writes the metrics.

use std::path::{Path, PathBuf};

use anyhow::Result;
use rovlink_base::io::EXIT_OK;
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_cli::metrics;
use rovlink_cli::rows::{RowFormat, RowWriter};
use rovlink_cli::say;
use rovlink_cli::{UsageError, progress, stop};
use rovlink_mapper::pipeline::{self, Hooks, SinkError, StatsRow};
use rovlink_octo::{files, transfer};

use crate::TOOL;
use crate::flags::{self, BuildArgs};

/// Runs `build`; the process's exit code.
pub fn build(a: &BuildArgs) -> Result<u8> {
    let mut cfg = a.config();
    cfg.validate()?;
    let link = a.link.as_deref().map(transfer::model_by_name).transpose();
    let link = link.map_err(|e| UsageError(format!("--link: {e}")))?;
    let mut outs = Outputs::new();
    // A bag's own files (a rosbag2 directory's .db3 files and metadata.yaml) are inputs too.
    let read = pipeline::input_files(&a.inputs, a.map.format);
    outs.inputs(read.iter().map(PathBuf::as_path));
    outs.input(a.link.as_deref().map(Path::new));
    let stream = outs.claim("-o", &a.output, Kind::Binary)?;
    let bt = outs.claim_opt("--bt", a.bt.as_deref(), Kind::Binary)?;
    let ot = outs.claim_opt("--ot", a.ot.as_deref(), Kind::Binary)?;
    let stats = outs.claim_opt("--stats", a.stats.as_deref(), Kind::Text)?;
    let arrivals = outs.claim_opt("--arrivals", a.arrivals.as_deref(), Kind::Text)?;
    let metrics_dest = outs.claim_opt("--metrics", a.metrics.as_deref(), Kind::Text)?;
    let mut metrics_out = metrics_dest.map(|d| d.open()).transpose()?;
    // A bag is read in one pass when nothing is written before the build's end (every output
    // a file, committed only then) and every input can be read again (a file or a rosbag2
    // directory: not standard input, a FIFO or a live topic): one whose clouds one pass cannot
    // pose as two passes do is built again, in two.
    let rereadable = a.inputs.iter().all(|p| {
        !rovlink_base::io::is_std(Some(p))
            && std::fs::metadata(p).is_ok_and(|m| m.is_file() || m.is_dir())
    });
    // Written as the build goes, an output must be a regular file (or none yet), committed by a
    // rename at the end: not standard output, a FIFO or a device such as /dev/stdout.
    let at_end = |d: &Dest| {
        d.path()
            .is_some_and(|p| std::fs::metadata(p).map_or(true, |m| m.is_file()))
    };
    cfg.one_pass_bags = rereadable && at_end(&stream) && stats.as_ref().is_none_or(at_end);
    stop::install()?;
    let (built, rows) = loop {
        let mut out = stream.open()?;
        let mut rows = stats
            .clone()
            .map(|d| RowWriter::new(d, RowFormat::Csv, &pipeline::STATS_COLUMNS));
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
            // map files are serialised and committed (written, synced, renamed) side by side;
            // the stream is committed once both are in place, so a failed map leaves no stream.
            // The .ot on the build's threads (the same bytes), the .bt beside it; the stream
            // synced meanwhile (its commit, after theirs, then only renames it).
            let threads = cfg.thread_count();
            std::thread::scope(|s| -> Result<()> {
                let tree = &built.tree;
                let out = &mut out;
                let stream_sync = s.spawn(move || out.sync());
                let ot_job = ot.as_ref().map(|d| {
                    s.spawn(move || {
                        let pieces = files::write_ot_threads(tree, threads);
                        d.write_pieces(pieces.pieces())
                    })
                });
                let bt_done = bt.as_ref().map(|d| d.write_whole(&files::write_bt(tree)));
                let ot_done =
                    ot_job.map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
                let synced = stream_sync
                    .join()
                    .unwrap_or_else(|p| std::panic::resume_unwind(p));
                bt_done.transpose()?;
                ot_done.transpose()?;
                synced?;
                Ok(())
            })?;
            out.finish()?;
            Ok(built)
        })();
        bar.finish_and_clear();
        // A failed run (bad input found late, a full disk) leaves no stats file either.
        if outcome.is_err()
            && let Some(rows) = rows.take()
        {
            rows.discard();
        }
        match outcome {
            Err(e)
                if cfg.one_pass_bags
                    && e.downcast_ref::<pipeline::PipelineError>()
                        .is_some_and(pipeline::PipelineError::is_one_pass) =>
            {
                if !a.quiet {
                    say!("{e}; building again with every transform read first");
                }
                cfg.one_pass_bags = false;
            }
            outcome => break (outcome?, rows),
        }
    };
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
