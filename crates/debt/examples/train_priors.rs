//! Trains the coder's context priors ([`rovlink_debt::priors`]) on a corpus of pictures and
//! writes them as Rust source.
//!
//! Every picture is encoded at every budget: colour pictures in colour and in grey, grey ones
//! in grey, each also as a segmented stream (`--segments 4 --trunk-size 39`). Each stream's
//! context-coded decisions ([`rovlink_debt::decisions`]) give, per context, the sequence of
//! its first `--window` bits, weighted by 1000 / budget (a bit saved at budget B is worth about
//! 1/B of the quality gained, so the first bytes, which every budget shares, count most). A
//! segment's decisions count up to its part of the budget (the budget over the segments).
//! For each context the prior (probability, count) is the one that codes its sequences in the
//! fewest weighted bits through the coder's own adaptation ([`Context::with_prior`], then
//! [`Context::update`]): for each count 0..=5, a golden-section search over the probability
//! (the cost is convex in it). Contexts seen in fewer than `--min-streams` sequences keep one
//! half and count 0.
//!
//! `cargo run --release -p rovlink-debt --example train_priors -- [--budgets 300,...] [--window 256]
//! [--min-streams 8] [--out crates/debt/src/priors.rs] [--source TEXT] IMAGES...`
//!
//! `--source` is a line of text put in the table's doc (where the pictures came from).

use std::path::PathBuf;

use rovlink_debt::coder::{CONTEXTS, Decision};
use rovlink_debt::rangecoder::{Context, MARGIN_BITS};
use rovlink_debt::{self as debt, EncodeOptions, Segments, picture};

/// The sequences of one context: its bits in one stream, with the stream's weight.
type Sequences = Vec<(Vec<bool>, f64)>;

/// Cost in bits of a 0 at probability `p` of a 0 (in 1/32768), for every `p`.
fn cost_table() -> Vec<f64> {
    (0..=32768u32)
        .map(|p| -(f64::from(p.max(1)) / 32768.0).log2())
        .collect()
}

/// Weighted bits to code `sequences` from the prior (`p0`, `count`).
fn cost(sequences: &Sequences, p0: u16, count: u8, table: &[f64]) -> f64 {
    let mut total = 0.0;
    for (bits, weight) in sequences {
        let mut ctx = Context::with_prior(p0, count);
        let mut sum = 0.0;
        for &bit in bits {
            let p = ctx.p0() as usize;
            sum += if bit { table[32768 - p] } else { table[p] };
            ctx.update(bit);
        }
        total += weight * sum;
    }
    total
}

/// The best probability for `count`, by golden-section search on the integers (the cost is
/// convex in the prior's probability).
fn best_probability(sequences: &Sequences, count: u8, table: &[f64]) -> (u16, f64) {
    let f = |p: u32| cost(sequences, p as u16, count, table);
    let (mut lo, mut hi) = (32u32, 32736u32);
    let ratio = 0.618_033_988_75;
    let mut a = hi - ((f64::from(hi - lo) * ratio) as u32);
    let mut b = lo + ((f64::from(hi - lo) * ratio) as u32);
    let (mut fa, mut fb) = (f(a), f(b));
    while hi - lo > 8 {
        if fa <= fb {
            hi = b;
            b = a;
            fb = fa;
            a = hi - ((f64::from(hi - lo) * ratio) as u32);
            fa = f(a);
        } else {
            lo = a;
            a = b;
            fa = fb;
            b = lo + ((f64::from(hi - lo) * ratio) as u32);
            fb = f(b);
        }
    }
    (lo..=hi)
        .map(|p| (p as u16, f(p)))
        .fold(
            (16384, f64::INFINITY),
            |best, c| {
                if c.1 < best.1 { c } else { best }
            },
        )
}

/// Appends each context's first `window` decisions of `decisions` (those before `limit_bits`)
/// to its sequences, with `weight`.
fn gather(
    decisions: &[Decision],
    limit_bits: u64,
    window: usize,
    weight: f64,
    per_context: &mut [Sequences],
) {
    let mut seqs: Vec<Vec<bool>> = vec![Vec::new(); CONTEXTS];
    for d in decisions.iter().take_while(|d| d.at_bits < limit_bits) {
        let s = &mut seqs[usize::from(d.context)];
        if s.len() < window {
            s.push(d.bit);
        }
    }
    for (c, bits) in seqs.into_iter().enumerate() {
        if !bits.is_empty() {
            per_context[c].push((bits, weight));
        }
    }
}

/// `text`'s words in lines of at most `width` characters (a longer word alone on its line).
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = vec![String::new()];
    for word in text.split_whitespace() {
        let line = lines.last_mut().expect("one line at least");
        if !line.is_empty() && line.len() + 1 + word.len() > width {
            lines.push(word.to_string());
        } else {
            if !line.is_empty() {
                line.push(' ');
            }
            line.push_str(word);
        }
    }
    lines
}

fn list(text: Option<String>) -> Vec<usize> {
    text.unwrap_or_default()
        .split(',')
        .filter_map(|b| b.parse().ok())
        .collect()
}

fn main() {
    let mut budgets = vec![300, 500, 1000, 2000, 4000, 8000, 16000];
    let mut window = 256;
    let mut min_streams = 8;
    let mut out = PathBuf::from("crates/debt/src/priors.rs");
    let mut source = String::from("(not given)");
    let mut images = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--budgets" => budgets = list(args.next()),
            "--window" => window = args.next().and_then(|s| s.parse().ok()).unwrap_or(256),
            "--min-streams" => min_streams = args.next().and_then(|s| s.parse().ok()).unwrap_or(8),
            "--out" => out = PathBuf::from(args.next().unwrap_or_default()),
            "--source" => source = args.next().unwrap_or_default(),
            _ => images.push(PathBuf::from(arg)),
        }
    }
    assert!(!images.is_empty(), "no training pictures given");
    let mut per_context: Vec<Sequences> = vec![Vec::new(); CONTEXTS];
    let mut names = Vec::new();
    let mut streams = 0;
    for path in &images {
        let img = picture::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        names.push(format!(
            "{name} ({}x{}x{})",
            img.width, img.height, img.channels
        ));
        let greys: &[bool] = if img.channels == 3 {
            &[false, true]
        } else {
            &[true]
        };
        for &gray in greys {
            for segments in [
                None,
                Some(Segments {
                    count: 4,
                    trunk_bytes: 39,
                }),
            ] {
                for &budget in &budgets {
                    let options = EncodeOptions {
                        bytes: budget,
                        gray,
                        segments,
                        ..EncodeOptions::default()
                    };
                    let parts = debt::decisions(&img, &options)
                        .unwrap_or_else(|e| panic!("{name} at {budget}: {e}"));
                    let weight = 1000.0 / budget as f64;
                    let share = 8 * budget as u64 / parts.len() as u64;
                    for part in &parts {
                        let limit = if parts.len() > 1 {
                            share.saturating_sub(u64::from(MARGIN_BITS))
                        } else {
                            u64::MAX
                        };
                        gather(part, limit, window, weight, &mut per_context);
                        streams += 1;
                    }
                }
            }
        }
        eprintln!("{name}: {streams} streams so far");
    }
    let table = cost_table();
    let mut priors = vec![(16384u16, 0u8); CONTEXTS];
    let (mut before, mut after) = (0.0, 0.0);
    for (c, sequences) in per_context.iter().enumerate() {
        let neutral = cost(sequences, 16384, 0, &table);
        before += neutral;
        if sequences.len() < min_streams {
            after += neutral;
            continue;
        }
        let mut best = (16384u16, 0u8, neutral);
        for count in 0..=5u8 {
            let (p, bits) = best_probability(sequences, count, &table);
            if bits < best.2 {
                best = (p, count, bits);
            }
        }
        priors[c] = (best.0, best.1);
        after += best.2;
    }
    let saving = 100.0 * (before - after) / before.max(1e-9);
    eprintln!(
        "{streams} streams; weighted bits over the window {before:.0} -> {after:.0} ({saving:.2} % fewer)"
    );
    let command = format!(
        "cargo run --release -p rovlink-debt --example train_priors -- --budgets {} --window {window} \
         --min-streams {min_streams} --out {} --source '{source}' {}",
        budgets
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(","),
        out.display(),
        images
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(" ")
    );
    let doc = format!(
        "The coder's context priors: the initial state of each of its {CONTEXTS} contexts, \
         trained by `examples/train_priors.rs` (a generated file: change the trainer and run it \
         again rather than edit this).\n\n\
         Trained on {} pictures: {}. Source: {source}. None of them is a test picture \
         (`../shared/testdata/images`).\n\n\
         Each picture encoded at {} bytes, colour pictures in colour and in grey, grey ones in \
         grey, plain and with 4 segments of 39-byte trunks ({streams} streams, a segment each); \
         per context, the first {window} decisions of each stream, weighted 1000 / budget; the \
         prior that codes them in the fewest bits through the coder's adaptation ({saving:.2} % \
         fewer than one half at count 0 over those decisions). Contexts seen in fewer than \
         {min_streams} streams stay at one half.\n\n\
         Regenerate (from the repository's root, the pictures in that order) with\n",
        names.len(),
        names.join(", "),
        budgets
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", "),
    );
    let mut text = String::new();
    for paragraph in doc.split("\n\n") {
        for line in wrap(paragraph, 96) {
            text.push_str(&format!("//! {line}\n").replace("//! \n", "//!\n"));
        }
        text.push_str("//!\n");
    }
    text.push_str(&format!("//! ```text\n//! {command}\n//! ```\n\n"));
    text.push_str("use super::coder::Prior;\n\n");
    text.push_str(
        "/// Initial state of each context, indexed as the coder's contexts: probability of a 0 in\n\
         /// 1/32768 and the count of symbols it stands for.\n\
         #[rustfmt::skip]\n\
         pub const PRIORS: &[Prior] = &[\n",
    );
    for row in priors.chunks(8) {
        let cells: Vec<String> = row.iter().map(|(p, c)| format!("({p}, {c})")).collect();
        text.push_str(&format!("    {},\n", cells.join(", ")));
    }
    text.push_str("];\n");
    std::fs::write(&out, text).unwrap_or_else(|e| panic!("{}: {e}", out.display()));
    eprintln!("wrote {}", out.display());
}
