//! debt-encode: an image file -> a DEBT stream of exactly the bytes asked.
#![forbid(unsafe_code)]

mod flags;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Result, bail};
use flags::Args;
use rovlink_base::io::EXIT_OK;
use rovlink_base::output::{Kind, Outputs};
use rovlink_cli::metrics;
use rovlink_cli::rows::{RowFormat, RowWriter};
use rovlink_cli::say;
use rovlink_cli::{progress, stop};
use rovlink_debt::{self as debt, picture, trial};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "debt-encode";

/// The --sweep progress bar (shown on a terminal only).
const PROGRESS: &str = "{pos}/{len} trials [{bar:30}] {msg}";

/// Checks the ROI against a picture's size.
fn check_roi(args: &Args, (width, height): (usize, usize), name: &str) -> Result<()> {
    match args.roi {
        Some(r) if r.x1 > width || r.y1 > height => bail!(
            "--roi {},{},{},{} reaches outside the {width}x{height} image {name}",
            r.x0,
            r.y0,
            r.x1,
            r.y1
        ),
        _ => Ok(()),
    }
}

/// Reads a picture (`None` or `-`: standard input) and checks the ROI against it.
fn load(args: &Args, input: Option<&Path>) -> Result<(debt::Image, String)> {
    let (img, name) = match input.filter(|p| p.as_os_str() != "-") {
        Some(path) => (picture::open(path)?, path.display().to_string()),
        None => (
            picture::read("<stdin>", std::io::stdin().lock())?,
            "<stdin>".into(),
        ),
    };
    check_roi(args, (img.width, img.height), &name)?;
    Ok((img, name))
}

/// Compression trials: one CSV row per image and budget, until done or a signal. Every picture
/// is listed and checked from its header first (a directory's pictures are inputs too), and a
/// picture that fails later takes the rows written with it: exit 2 leaves no file.
fn sweep(args: &Args, budgets: &[u64], outs: &mut Outputs) -> Result<u8> {
    let stdin = [PathBuf::from("-")];
    let pictures = picture::list(match args.inputs.is_empty() {
        true => &stdin,
        false => &args.inputs,
    })?;
    for (path, size) in &pictures {
        outs.input(Some(path));
        size.map_or(Ok(()), |size| {
            check_roi(args, size, &path.display().to_string())
        })?;
    }
    let csv = args.csv.as_deref().unwrap_or(Path::new("-"));
    let mut rows = RowWriter::new(
        outs.claim("--csv", csv, Kind::Text)?,
        RowFormat::Csv,
        &trial::COLUMNS,
    );
    let metrics_dest = outs.claim_opt("--metrics", args.metrics.as_deref(), Kind::Text)?;
    let mut metrics_out = metrics_dest.map(|d| d.open()).transpose()?;
    let mut trials = Vec::new();
    stop::install()?;
    let bar = progress::bar(false, (pictures.len() * budgets.len()) as u64, PROGRESS);
    let outcome = (|| -> Result<()> {
        for (path, _) in &pictures {
            let (img, name) = load(args, Some(path))?;
            bar.set_message(name.clone());
            for &budget in budgets {
                if stop::requested() {
                    return Ok(());
                }
                let trial = trial::run(&name, &img, &args.options(budget));
                let trial = trial.map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
                rows.row(&trial)?;
                trials.push(trial);
                bar.inc(1);
            }
        }
        Ok(())
    })();
    bar.finish_and_clear();
    // Only a regular file the rows created is removed (never a device, a pipe or a symlink).
    if outcome.is_err()
        && let Some(path) = rows.dest().path().filter(|_| rows.rows() > 0)
        && std::fs::symlink_metadata(path).is_ok_and(|m| m.is_file())
    {
        let _ = std::fs::remove_file(path);
    }
    outcome?;
    let done = rows.rows();
    rows.finish()?;
    if let Some(out) = metrics_out.as_mut() {
        let mut figures = trial::summary(&trials);
        if let Some(signal) = stop::signal_name() {
            figures["interrupted"] = signal.into();
        }
        metrics::write(out, TOOL, None, &figures)?;
    }
    metrics_out.map(|out| out.finish()).transpose()?;
    if let Some(note) = stop::note() {
        say!("{done} trials written ({note})");
    }
    Ok(stop::code_or(EXIT_OK))
}

fn run(args: &Args) -> Result<u8> {
    let mut outs = Outputs::new();
    outs.inputs(args.inputs.iter().map(PathBuf::as_path));
    rovlink_cli::only_with(
        args.sweep.is_some(),
        "--sweep",
        &[("--csv", args.csv.is_some())],
    )?;
    if let Some(budgets) = &args.sweep {
        return sweep(args, budgets, &mut outs);
    }
    if args.inputs.len() > 1 {
        bail!(
            "one input image at a time (several only with --sweep), found {}",
            args.inputs.len()
        );
    }
    let output = args.output.as_deref().unwrap_or(Path::new("-"));
    let dest = outs.claim("-o", output, Kind::Binary)?;
    let metrics_dest = outs.claim_opt("--metrics", args.metrics.as_deref(), Kind::Text)?;
    let (img, name) = load(args, args.inputs.first().map(PathBuf::as_path))?;
    let options = args.options(args.bytes.unwrap_or_default());
    let started = std::time::Instant::now();
    let stream = debt::encode(&img, &options).map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    let encode_ms = started.elapsed().as_secs_f64() * 1e3;
    let figures = (metrics_dest.as_ref())
        .map(|_| trial::measure(&name, &img, &options, &stream, encode_ms).map(|t| t.figures()))
        .transpose()
        .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    // Opened only now: a signal while a pipe is read leaves no temporary file behind.
    let mut out = dest.open()?;
    out.write_bytes(&stream)?;
    let mut metrics_out = metrics_dest.map(|d| d.open()).transpose()?;
    if let (Some(file), Some(figures)) = (metrics_out.as_mut(), figures) {
        metrics::write(file, TOOL, None, &figures)?;
    }
    out.finish()?;
    metrics_out.map(|out| out.finish()).transpose()?;
    Ok(EXIT_OK)
}

fn main() -> ExitCode {
    let args: Args = rovlink_cli::parse(TOOL);
    rovlink_cli::finish(TOOL, run(&args))
}
