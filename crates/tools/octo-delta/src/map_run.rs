//! octo-delta map: claims its outputs, opens the link, runs `rovlink_mapper::live::mapper`
//! until the inputs are done and acknowledged (with --exit-when-done), a signal, or the link
//! closing; then writes the map files (also when stopped), the stats and the metrics.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::Result;
use rovlink_base::UsageError;
use rovlink_base::io::EXIT_OK;
use rovlink_base::output::{Kind, Outputs};
use rovlink_cli::rows::{RowFormat, RowWriter};
use rovlink_cli::{metrics, say, stop};
use rovlink_mapper::live::carrier::Carrier;
use rovlink_mapper::live::mapper::{self, MapperEvent, MapperHooks, MapperSetup, ScanRow};
use rovlink_mapper::live::{default_backlog_bytes, outbox_config};
use rovlink_mapper::pipeline;
use rovlink_octo::{files, transfer};

use crate::TOOL;
use crate::flags::{LinkArgs, MapArgs};

/// Events the loop waits on at most (scans read ahead, segments not yet looked at).
const QUEUE: usize = 64;

/// The model of `--model` and the transport over it.
pub fn link_model(link: &LinkArgs) -> Result<rovlink_link::Model> {
    transfer::model_by_name(&link.model)
        .map_err(|e| UsageError(format!("--model {}: {e}", link.model)).into())
}

/// A random 32-bit number (an epoch, the first request id).
pub fn random_u32() -> Result<u32> {
    let b = rovlink_base::secret::random_bytes(4)?;
    Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// Runs `map`; the process's exit code.
pub fn map(a: &MapArgs) -> Result<u8> {
    let cfg = a.map.config();
    cfg.validate()?;
    let model = link_model(&a.link)?;
    let rto = a.link.rto_ms.map(|ms| Duration::from_secs_f64(ms / 1e3));
    let transport = outbox_config(&model, a.rate, rto);
    let mut outs = Outputs::new();
    let read = pipeline::input_files(&a.inputs, a.map.format);
    outs.inputs(read.iter().map(PathBuf::as_path));
    let bt = outs.claim_opt("--bt", a.bt.as_deref(), Kind::Binary)?;
    let ot = outs.claim_opt("--ot", a.ot.as_deref(), Kind::Binary)?;
    let stats = outs.claim_opt("--stats", a.stats.as_deref(), Kind::Text)?;
    let metrics_dest = outs.claim_opt("--metrics", a.metrics.as_deref(), Kind::Text)?;
    stop::install()?;
    let (tx, rx) = std::sync::mpsc::sync_channel(QUEUE);
    let to_carrier = tx.clone();
    let hand = Box::new(move |c| to_carrier.send(MapperEvent::Carried(c)).is_ok());
    let quit_reader = Arc::new(AtomicBool::new(false));
    let mut carrier = Carrier::open(
        &a.link.port,
        a.link.baud as u32,
        a.address as u8,
        0,
        Arc::clone(&quit_reader),
        hand,
    )
    .map_err(|e| UsageError(format!("--port {e}")))?;
    if !a.quiet {
        say!(
            "mapping onto {} (address {} to the operator 0): {:.0} bit/s shaped, resend after {} ms; the map link is not authenticated (it moves no vehicle)",
            carrier.name,
            a.address,
            transport.rate_bps,
            transport.rto.as_millis()
        );
    }
    let epoch = random_u32()?;
    let setup = MapperSetup {
        cfg,
        inputs: a.inputs.clone(),
        follow: a.follow,
        outbox: transport,
        epoch,
        backlog_bytes: a
            .backlog_bytes
            .map_or(default_backlog_bytes(&transport), |b| b as usize),
        exit_when_done: a.exit_when_done,
        linger: Duration::from_secs_f64(a.linger),
    };
    let mut rows = stats.map(|d| RowWriter::new(d, RowFormat::Csv, &mapper::SCAN_COLUMNS));
    let mut row_error = None;
    let quiet = a.quiet;
    let mut said = std::collections::HashSet::new();
    let mut say_once = |line: String| {
        let key: String = line.chars().take(24).collect();
        if said.insert(key) || !quiet {
            say!("{line}");
        }
    };
    let mut on_scan = |row: &ScanRow| {
        if !quiet {
            say!(
                "mapped scan {}: {} points, message {} bytes ({} on the link)",
                row.scan,
                row.points,
                row.message_bytes,
                row.link_bytes
            );
        }
        if let Some(w) = rows.as_mut()
            && let Err(e) = w.row(row)
        {
            row_error.get_or_insert(e);
        }
    };
    let mut hooks = MapperHooks {
        stop: stop::flag(),
        say: &mut say_once,
        scan: &mut on_scan,
        full_sizes: a.stats.is_some(),
    };
    let outcome = mapper::run(setup, &mut carrier, tx, rx, &mut hooks);
    quit_reader.store(true, std::sync::atomic::Ordering::Relaxed);
    let run = outcome?;
    // The map files first, whole, also when stopped: what was mapped is kept.
    let tree = run.state.tree();
    std::thread::scope(|s| -> Result<()> {
        let ot_job = ot
            .as_ref()
            .map(|d| s.spawn(|| d.write_whole(&files::write_ot(&tree))));
        let bt_done = bt.as_ref().map(|d| d.write_whole(&files::write_bt(&tree)));
        let ot_done = ot_job.map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
        bt_done.transpose()?;
        ot_done.transpose()?;
        Ok(())
    })?;
    if let Some(e) = row_error {
        return Err(e.into());
    }
    rows.map(RowWriter::finish).transpose()?;
    let link_s = run.elapsed_s.max(1e-9);
    let figures = serde_json::json!({
        "scans": run.rows.len(),
        "points": run.rows.iter().map(|r| r.points).sum::<usize>(),
        "message_bytes_total": run.rows.iter().map(|r| r.message_bytes).sum::<usize>(),
        "elapsed_s": run.elapsed_s,
        "epoch": format!("{epoch:08x}"),
        "transport": {
            "rate_bps": transport.rate_bps,
            "rto_ms": transport.rto.as_secs_f64() * 1e3,
            "segments": run.outbox.segments,
            "resends": run.outbox.resends,
            "replies": run.outbox.replies,
            "link_bytes": run.outbox.link_bytes,
            "link_use_of_rate": run.outbox.link_bytes as f64 * 8.0 / link_s / transport.rate_bps,
            "acks": run.outbox.acks,
            "stale_acks": run.outbox.stale_acks,
            "restarts": run.outbox.restarts,
            "backlog_replacements": run.backlog_replacements,
            "all_acknowledged": run.all_acknowledged,
        },
        "carrier": run.carrier,
        "malformed_segments": run.malformed,
        "requests": run.requests,
        "interrupted": run.interrupted,
        "closed": run.closed,
    });
    if let Some(d) = metrics_dest {
        let mut out = d.open()?;
        metrics::write(&mut out, TOOL, None, &figures)?;
        out.finish()?;
    }
    if let Some(why) = &run.closed {
        say!("link closed: {why}; the map files hold every scan mapped");
    }
    let feed = match run.feed {
        Some(Err(e)) => return Err(e.into()),
        Some(Ok(f)) => Some(f),
        None => None,
    };
    for (reason, n) in feed.iter().flat_map(|f| &f.skipped) {
        say!("warning: {n} cloud(s) skipped: {reason}");
    }
    if !a.quiet {
        say!(
            "{} scans mapped; {} segments sent, {} resent, {} bytes on the link ({:.0}% of the shaped rate over {:.1} s); {} requests answered{}",
            run.rows.len(),
            run.outbox.segments,
            run.outbox.resends,
            run.outbox.link_bytes,
            run.outbox.link_bytes as f64 * 8.0 / link_s / transport.rate_bps * 100.0,
            run.elapsed_s,
            run.requests.len(),
            if run.all_acknowledged {
                "; all acknowledged"
            } else {
                "; not all acknowledged"
            }
        );
    }
    // The operator does not have everything: said above, and the exit code says it too.
    if run.closed.is_some() || (a.exit_when_done && !run.all_acknowledged && !run.interrupted) {
        return Ok(1);
    }
    Ok(stop::code_or(EXIT_OK))
}
