//! debt-encode: an image file -> a DEBT stream of exactly the bytes asked.
#![forbid(unsafe_code)]

mod cli;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Result, bail};
use cli::Args;
use rovlink::cli::output::{Kind, Outputs};
use rovlink::cli::rows::{RowFormat, RowWriter};
use rovlink::cli::{progress, stop};
use rovlink::debt::{self, picture, trial};
use rovlink::io::EXIT_OK;
use rovlink::say;

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "debt-encode";

/// Reads a picture (`None` or `-`: standard input) and checks the ROI against it.
fn load(args: &Args, input: Option<&Path>) -> Result<(debt::Image, String)> {
    let (img, name) = match input.filter(|p| p.as_os_str() != "-") {
        Some(path) => (picture::open(path)?, path.display().to_string()),
        None => (
            picture::read("<stdin>", std::io::stdin().lock())?,
            "<stdin>".into(),
        ),
    };
    if let Some(r) = args.roi
        && (r.x1 > img.width || r.y1 > img.height)
    {
        bail!(
            "--roi {},{},{},{} reaches outside the {}x{} image {name}",
            r.x0,
            r.y0,
            r.x1,
            r.y1,
            img.width,
            img.height
        );
    }
    Ok((img, name))
}

/// Compression trials: one CSV row per image and budget, until done or a signal.
fn sweep(args: &Args, budgets: &[u64], outs: &mut Outputs) -> Result<u8> {
    let csv = args.csv.as_deref().unwrap_or(Path::new("-"));
    let mut rows = RowWriter::new(
        outs.claim("--csv", csv, Kind::Text)?,
        RowFormat::Csv,
        &trial::COLUMNS,
    );
    stop::install()?;
    // A directory stands for the pictures in it (files that are not pictures are skipped).
    let mut inputs: Vec<(Option<PathBuf>, bool)> = Vec::new();
    for path in &args.inputs {
        match path.is_dir() {
            true => inputs.extend(
                picture::files_in(path)?
                    .into_iter()
                    .map(|f| (Some(f), true)),
            ),
            false => inputs.push((Some(path.clone()), false)),
        }
    }
    if args.inputs.is_empty() {
        inputs.push((None, false));
    }
    let total = (inputs.len() * budgets.len()) as u64;
    let bar = progress::bar(false, total, "{pos}/{len} trials [{bar:30}] {msg}");
    'images: for (input, in_dir) in &inputs {
        let (img, name) = match load(args, input.as_deref()) {
            Err(e)
                if *in_dir
                    && matches!(e.downcast_ref(), Some(picture::PictureError::Format { .. })) =>
            {
                continue;
            }
            loaded => loaded?,
        };
        bar.set_message(name.clone());
        for &budget in budgets {
            if stop::requested() {
                break 'images;
            }
            rows.row(
                &debt::trial::run(&name, &img, &args.options(budget))
                    .map_err(|e| anyhow::anyhow!("{name}: {e}"))?,
            )?;
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    let done = rows.rows();
    rows.finish()?;
    if let Some(note) = stop::note() {
        say!("{done} trials written ({note})");
    }
    Ok(stop::code_or(EXIT_OK))
}

fn run(args: &Args) -> Result<u8> {
    let mut outs = Outputs::new();
    outs.inputs(args.inputs.iter().map(PathBuf::as_path));
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
    let mut out = outs.claim("-o", output, Kind::Binary)?.open()?;
    let (img, name) = load(args, args.inputs.first().map(PathBuf::as_path))?;
    let bytes = args.bytes.unwrap_or_default();
    let stream =
        debt::encode(&img, &args.options(bytes)).map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    out.write_bytes(&stream)?;
    out.finish()?;
    Ok(EXIT_OK)
}

fn main() -> ExitCode {
    let args: Args = rovlink::cli::parse(TOOL);
    rovlink::cli::finish(TOOL, run(&args))
}
