//! rcp-pack: RCP messages as JSON Lines -> link frames (bytes), or a file cut into image trunks;
//! sealed (tagged, and encrypted if asked) with a key file; a new key file.
#![forbid(unsafe_code)]

mod flags;

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use flags::Args;
use rovlink_base::io::StopReader;
use rovlink_base::io::{EXIT_BAD_INPUT, EXIT_OK, Output};
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_cli::say;
use rovlink_cli::{only_with, stop};
use rovlink_security::KeyRing;
use rovlink_security::stream::Sealer;
use rovlink_wire::MessageRepr;
use rovlink_wire::pack::{self, Line, Lines};

/// The tool's name, prefixed to everything it says on stderr.
const TOOL: &str = "rcp-pack";

/// The sealer of --key-file, if given.
fn sealer(args: &Args) -> Result<Option<Sealer>> {
    let Some(path) = &args.key_file else {
        return Ok(None);
    };
    let ring = KeyRing::load(path).context("--key-file")?;
    Ok(Some(
        Sealer::new(ring, args.encrypt, args.counter.unwrap_or(1)).context("--counter")?,
    ))
}

/// A message's frame as written: sealed with counter `ctr` (or its pair's next) when there is
/// a sealer, a line of hex when asked; `at` names the input line in what is said.
fn frame_out(
    repr: &MessageRepr,
    ctr: Option<u64>,
    sealer: Option<&mut Sealer>,
    hex: bool,
    at: &str,
) -> Result<Vec<u8>> {
    let Some(sealer) = sealer else {
        return Ok(pack::frame(repr, hex)?);
    };
    let sealed = sealer.seal(&pack::frame(repr, false)?, ctr)?;
    if let Some(highest) = sealed.not_above {
        let shared = if sealer.encrypts() {
            "; encrypted, the two share keystream"
        } else {
            ""
        };
        say!(
            "{at}: counter {} of {}>{} is not above {highest}, sealed before: a receiver refuses \
             this frame as a replay{shared}",
            sealed.counter,
            repr.src,
            repr.dst
        );
    }
    if hex {
        let mut line = rovlink_wire::json::encode_hex(&sealed.bytes);
        line.push('\n');
        return Ok(line.into_bytes());
    }
    Ok(sealed.bytes)
}

fn pack_lines(args: &Args, out: &mut Output) -> Result<u8> {
    // Read on a thread of its own, so that a signal ends a run on a quiet pipe.
    stop::install()?;
    let name = rovlink_base::io::display_name(args.input.as_deref(), "<stdin>");
    if let Some(path) = args
        .input
        .as_deref()
        .filter(|p| !rovlink_base::io::is_std(Some(p)))
    {
        std::fs::metadata(path).map_err(|source| rovlink_base::io::IoError::Open {
            path: path.to_path_buf(),
            source,
        })?;
    }
    let mut sealer = sealer(args)?;
    let input = std::io::BufReader::new(StopReader::open(args.input.as_deref(), stop::flag()));
    let lines = match sealer {
        Some(_) => Lines::with_counters(input),
        None => Lines::new(input),
    };
    let (mut bad, mut frames) = (0usize, 0usize);
    for (number, parsed) in lines {
        match parsed {
            Err(_) if stop::requested() => break,
            Ok(Line { repr, ctr }) => {
                let at = format!("{name}:{number}");
                match frame_out(&repr, ctr, sealer.as_mut(), args.hex, &at) {
                    Ok(bytes) => {
                        out.write_bytes(&bytes)?;
                        frames += 1;
                    }
                    Err(e) if args.keep_going => {
                        say!("{at}: {e:#} (line skipped)");
                        bad += 1;
                    }
                    Err(e) => bail!("{at}: {e:#}"),
                }
            }
            Err(e) if args.keep_going && !e.is_fatal() => {
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

fn pack_image(args: &Args, path: &Path, dest: &Dest) -> Result<u8> {
    let name = path.display().to_string();
    // Read up to a bound: a file longer than any image's trunks is refused, not held whole.
    let data = match rovlink_base::io::read_at_most(path, pack::MAX_IMAGE_BYTES as u64) {
        Err(e) if e.kind() == std::io::ErrorKind::InvalidData => {
            Err(pack::ImageError::TooLarge).with_context(|| name.clone())?
        }
        read => read.with_context(|| format!("{name}: cannot read"))?,
    };
    let trunk = args.trunk.unwrap_or(39) as usize;
    let (src, dst, isn) = (
        args.src.unwrap_or(1) as u8,
        args.dst.unwrap_or(0) as u8,
        args.isn == Some(1),
    );
    let messages =
        pack::image_messages(&data, trunk, src, dst, isn).with_context(|| name.clone())?;
    let mut sealer = sealer(args)?;
    let mut frames = Vec::with_capacity(messages.len());
    for (itsn, repr) in messages.iter().enumerate() {
        let at = format!("{name}: trunk {itsn}");
        frames.push(frame_out(repr, None, sealer.as_mut(), args.hex, &at).context(at)?);
    }
    // Opened only now: a signal while a pipe is read leaves no temporary file behind.
    let mut out = dest.open()?;
    for frame in &frames {
        out.write_bytes(frame)?;
    }
    out.finish()?;
    Ok(EXIT_OK)
}

/// --new-key: a new key file, said on stderr (never the key).
fn new_key(path: &Path, bits: usize) -> Result<u8> {
    rovlink_security::key::write_new_key_file(path, bits).context("--new-key")?;
    say!(
        "wrote {}: a new {bits}-bit frame key for every vehicle (`* KEY`), mode 0600; copy it \
         to each end over a trusted path",
        path.display()
    );
    Ok(EXIT_OK)
}

fn run(args: &Args) -> Result<u8> {
    only_with(
        args.new_key.is_some(),
        "--new-key FILE",
        &[("--key-bits", args.key_bits.is_some())],
    )?;
    only_with(
        args.key_file.is_some(),
        "--key-file FILE",
        &[
            ("--encrypt", args.encrypt),
            ("--counter", args.counter.is_some()),
        ],
    )?;
    if let Some(path) = &args.new_key {
        return new_key(path, args.key_bits.unwrap_or(128));
    }
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
    match &args.image {
        Some(path) => pack_image(args, path, &dest),
        None => {
            let mut out = dest.open()?;
            let code = pack_lines(args, &mut out)?;
            // Written whole or not at all: a stopped run leaves no file.
            if let Some(note) = stop::note() {
                say!("{note}: nothing written");
                return Ok(stop::code_or(code));
            }
            out.finish()?;
            Ok(code)
        }
    }
}

fn main() -> ExitCode {
    let args: Args = rovlink_cli::parse(TOOL);
    rovlink_cli::finish(TOOL, run(&args))
}
