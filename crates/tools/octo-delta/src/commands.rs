//! octo-delta apply, dump, full and synth: each claims its outputs, reads its input if it has
//! one, and calls `rovlink_mapper::pipeline` (apply --mcap: `rovlink_mapper::view`).

use std::path::Path;

use anyhow::Result;
use rovlink_base::io::EXIT_OK;
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_cli::stop;
use rovlink_mapper::pipeline;
use rovlink_mapper::view;
use rovlink_octo::{files, graph};

use crate::flags::{ApplyArgs, DumpArgs, FullArgs, SynthArgs};

/// Claims the output of a one-input command, then reads the input: its bytes and the name its
/// errors carry.
fn claim_and_read(input: &Path, output: &Path, kind: Kind) -> Result<(Dest, Vec<u8>, String)> {
    let mut outs = Outputs::new();
    outs.input(Some(input));
    let dest = outs.claim("-o", output, kind)?;
    let (bytes, name) = pipeline::read_input(input)?;
    Ok((dest, bytes, name))
}

/// Runs `apply`; the process's exit code.
pub fn apply(a: &ApplyArgs) -> Result<u8> {
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

/// Runs `dump`; the process's exit code.
pub fn dump(a: &DumpArgs) -> Result<u8> {
    let (dest, bytes, name) = claim_and_read(&a.input, &a.output, Kind::Text)?;
    let mut out = dest.open()?;
    pipeline::dump(&bytes, &name, a.format, a.voxels, &mut out)?;
    out.finish()?;
    Ok(EXIT_OK)
}

/// Runs `full`; the process's exit code.
pub fn full(a: &FullArgs) -> Result<u8> {
    let (dest, bytes, name) = claim_and_read(&a.input, &a.output, Kind::Binary)?;
    dest.write_whole(&pipeline::full(&bytes, &name, a.view.coarse(), a.view.roi)?)?;
    Ok(EXIT_OK)
}

/// Runs `synth --pace`: the .graph written scan by scan, `pace_s` apart, each flushed.
fn synth_paced(a: &SynthArgs, pace_s: f64) -> Result<u8> {
    use std::io::Write;
    let params = a.params();
    params.validate()?;
    if a.mcap() {
        return Err(rovlink_base::UsageError("--pace writes a .graph, not MCAP".into()).into());
    }
    Outputs::new().claim("-o", &a.output, Kind::Binary)?;
    stop::install()?;
    let scans = rovlink_octo::synth::survey(&params);
    let name = a.output.display().to_string();
    let mut out: Box<dyn Write> = if rovlink_base::io::is_std(Some(&a.output)) {
        Box::new(std::io::stdout().lock())
    } else {
        Box::new(std::fs::File::create(&a.output).map_err(|source| {
            rovlink_base::io::IoError::Open {
                path: a.output.clone(),
                source,
            }
        })?)
    };
    let mut put = |bytes: &[u8]| -> Result<()> {
        out.write_all(bytes)
            .and_then(|()| out.flush())
            .map_err(|source| rovlink_base::io::IoError::Write {
                name: name.clone(),
                source,
            })?;
        Ok(())
    };
    put(&(scans.len() as u32).to_le_bytes())?;
    let started = std::time::Instant::now();
    for (k, scan) in scans.iter().enumerate() {
        let due = std::time::Duration::from_secs_f64(pace_s * k as f64);
        while started.elapsed() < due {
            if stop::requested() {
                return Ok(stop::code_or(EXIT_OK));
            }
            std::thread::sleep((due - started.elapsed()).min(std::time::Duration::from_millis(50)));
        }
        put(&graph::node_bytes(scan, k as u32))?;
    }
    put(&0u32.to_le_bytes())?;
    Ok(stop::code_or(EXIT_OK))
}

/// Runs `synth`; the process's exit code.
pub fn synth_cmd(a: &SynthArgs) -> Result<u8> {
    if let Some(pace_s) = a.pace {
        return synth_paced(a, pace_s);
    }
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
