//! rcp-pack: RCP messages as JSON Lines -> link frames (bytes), or a file cut into image trunks.
#![forbid(unsafe_code)]

mod cli;

use std::io::{BufRead, Read};
use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use cli::Args;
use rovlink::cli::only_with;
use rovlink::cli::output::{Kind, Outputs};
use rovlink::io::{EXIT_BAD_INPUT, EXIT_OK, Input, Output};
use rovlink::say;
use rovlink::wire::{Message, MessageRepr, frame, json, rov};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "rcp-pack";

/// The longest input line read: far above any message's JSON.
const MAX_LINE_BYTES: usize = 64 * 1024;

/// Writes one message's frame in the chosen form.
fn put(out: &mut Output, repr: &MessageRepr, hex: bool) -> Result<()> {
    let mut bytes = Vec::with_capacity(frame::MAX_FRAME_BYTES);
    repr.emit_to_vec(&mut bytes)?;
    if hex {
        let mut line = json::encode_hex(&bytes);
        line.push('\n');
        out.write_bytes(line.as_bytes())?;
    } else {
        out.write_bytes(&bytes)?;
    }
    Ok(())
}

fn pack_lines(args: &Args, out: &mut Output) -> Result<u8> {
    let mut input = Input::open(args.input.as_deref())?;
    let name = input.name.clone();
    let mut reader = std::io::BufReader::new(input.reader());
    let (mut bad, mut frames) = (0usize, 0usize);
    let mut line = Vec::new();
    for number in 1.. {
        line.clear();
        // A line is read up to a bound, so that a stream without newlines is not held whole.
        (&mut reader)
            .take(MAX_LINE_BYTES as u64 + 1)
            .read_until(b'\n', &mut line)
            .with_context(|| format!("{name}: read failed"))?;
        if line.is_empty() {
            break;
        }
        if line.len() > MAX_LINE_BYTES && line.last() != Some(&b'\n') {
            bail!("{name}:{number}: longer than {MAX_LINE_BYTES} bytes: not a message");
        }
        let parsed = std::str::from_utf8(&line)
            .map_err(|e| anyhow::anyhow!("not UTF-8 at byte {}", e.valid_up_to()))
            .and_then(|text| match text.trim() {
                "" => Ok(None),
                text => Ok(Some(json::parse_line(text)?)),
            });
        match parsed {
            Ok(None) => {}
            Ok(Some(repr)) => {
                put(out, &repr, args.hex)?;
                frames += 1;
            }
            Err(e) if args.keep_going => {
                say!("{name}:{number}: {e} (line skipped)");
                bad += 1;
            }
            Err(e) => bail!("{name}:{number}: {e}"),
        }
    }
    if bad > 0 {
        say!("{name}: {frames} frames packed, {bad} bad lines skipped");
        return Ok(EXIT_BAD_INPUT);
    }
    Ok(EXIT_OK)
}

fn pack_image(args: &Args, path: &Path, out: &mut Output) -> Result<u8> {
    let mut input = Input::open(Some(path))?;
    let most = rovlink::rcp::MAX_TRUNKS * rov::MAX_TRUNK_BYTES;
    let mut data = Vec::new();
    (input.reader().take(most as u64 + 1).read_to_end(&mut data))
        .with_context(|| format!("{}: read failed", input.name))?;
    let trunk = args.trunk.unwrap_or(39) as usize;
    if data.is_empty() {
        bail!("{}: empty file, nothing to cut into trunks", input.name);
    }
    if data.len() > most {
        bail!(
            "{}: more than {most} bytes: not even 64 trunks of {} bytes hold it",
            input.name,
            rov::MAX_TRUNK_BYTES
        );
    }
    let trunks = rovlink::rcp::cut_trunks(&data, trunk).map_err(|smallest| {
        anyhow::anyhow!(
            "{}: {} bytes need {} trunks of {trunk} bytes, at most {} fit (ITSN is 6 bits); \
             use --trunk {smallest} or more",
            input.name,
            data.len(),
            data.len().div_ceil(trunk),
            rovlink::rcp::MAX_TRUNKS
        )
    })?;
    let last = trunks.len() - 1;
    for (itsn, piece) in trunks.into_iter().enumerate() {
        let message = Message::Rov(rov::Repr {
            ft: itsn == 0,
            lt: itsn == last,
            isn: args.isn == Some(1),
            ci: false,
            itsn: itsn as u8,
            status: rov::Status::Basic(rov::BasicStatus::default()),
            trunk: piece.to_vec(),
        });
        let (src, dst) = (args.src.unwrap_or(1), args.dst.unwrap_or(0));
        put(out, &MessageRepr { src, dst, message }, args.hex)?;
    }
    Ok(EXIT_OK)
}

fn run(args: &Args) -> Result<u8> {
    only_with(
        args.image.is_some(),
        "--image FILE",
        &[
            ("--trunk", args.trunk.is_some()),
            ("--src", args.src.is_some()),
            ("--dst", args.dst.is_some()),
            ("--isn", args.isn.is_some()),
        ],
    )?;
    let mut outs = Outputs::new();
    outs.input(args.input.as_deref());
    outs.input(args.image.as_deref());
    let kind = if args.hex { Kind::Text } else { Kind::Binary };
    let dest = outs.claim("-o", args.output.as_deref().unwrap_or(Path::new("-")), kind)?;
    let mut out = dest.open()?;
    let code = match &args.image {
        Some(path) => pack_image(args, path, &mut out)?,
        None => pack_lines(args, &mut out)?,
    };
    out.finish()?;
    Ok(code)
}

fn main() -> ExitCode {
    let args: Args = rovlink::cli::parse(TOOL);
    rovlink::cli::finish(TOOL, run(&args))
}
