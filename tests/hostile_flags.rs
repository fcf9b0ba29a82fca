//! Every numeric flag of every tool, found in its own `--help`, tried at NaN, inf and ±1e300
//! (always bad usage: exit 2, one line naming the flag, no output file left) and at 0, -1 and
//! 2^64 (whatever the flag allows, the run ends by itself with 0, 1 or 2 and never panics).
//! A flag added later is swept without touching this file.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::common::hostile::{Run, assert_contract, run_in};
use crate::common::testdata;

/// Value names that are not numbers (paths, names, choices).
const NOT_NUMERIC: [&str; 18] = [
    "FILE",
    "DEV",
    "NS",
    "TYPE",
    "NAME",
    "ADDR:PORT",
    "SHAPE",
    "MODE",
    "DIALECT",
    "BOOL",
    "ROLE",
    "FORMAT",
    "DIR|FILE",
    "DIR",
    "MODEL",
    "TOPIC",
    "FRAME",
    "CMD",
];

/// One way to run a tool: its binary, its subcommand (if any) and arguments that make a
/// short, successful run in a scratch directory.
struct Case {
    bin: &'static str,
    sub: Option<&'static str>,
    base: Vec<String>,
    stdin: Vec<u8>,
    /// Output files `base` writes (relative to the scratch directory).
    outputs: Vec<&'static str>,
}

/// The numeric flags of a command, from its `--help`: `(flag, value name)`.
fn numeric_flags(bin: &str, sub: Option<&str>) -> Vec<(String, String)> {
    let mut cmd = Command::new(bin);
    if let Some(sub) = sub {
        cmd.arg(sub);
    }
    let help = cmd.arg("--help").output().expect("--help runs");
    assert!(help.status.success(), "{bin} --help failed");
    let text = String::from_utf8_lossy(&help.stdout);
    let mut flags = Vec::new();
    let mut seen = BTreeSet::new();
    for line in text.lines() {
        let line = line.trim_start();
        let line = match line.split_once(", ") {
            Some((short, rest)) if short.len() == 2 && short.starts_with('-') => rest,
            _ => line,
        };
        let Some(rest) = line.strip_prefix("--") else {
            continue;
        };
        let Some((name, rest)) = rest.split_once(" <") else {
            continue;
        };
        let Some((value, _)) = rest.split_once('>') else {
            continue;
        };
        if NOT_NUMERIC.contains(&value) || value.contains("FILE") || value.contains("TOPIC") {
            continue;
        }
        if seen.insert(name.to_string()) {
            flags.push((format!("--{name}"), value.to_string()));
        }
    }
    flags
}

fn scratch() -> tempfile::TempDir {
    tempfile::tempdir().expect("scratch directory")
}

/// `base` with `flag` set to `value` (replacing the flag's own value if `base` has it).
fn with_flag(base: &[String], flag: &str, value: &str) -> Vec<String> {
    let mut args = base.to_vec();
    if let Some(i) = args.iter().position(|a| a == flag) {
        if i + 1 < args.len() {
            args.remove(i + 1);
        }
        args.remove(i);
    }
    args.push(flag.to_string());
    args.push(value.to_string());
    args
}

fn run_case(case: &Case, args: &[String], dir: &Path) -> Run {
    let mut all: Vec<&str> = case.sub.iter().copied().collect();
    all.extend(args.iter().map(String::as_str));
    run_in(dir, case.bin, &all, &case.stdin, Duration::from_secs(30))
}

fn cases(fixtures: &Path) -> Vec<Case> {
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    let p = |p: PathBuf| p.display().to_string();
    let frames = std::fs::read(testdata("noisy.bin")).expect("noisy.bin");
    let jsonl = std::fs::read(testdata("wire-vectors.jsonl")).expect("vectors");
    let png = p(testdata("kodim23-64x48.png"));
    let debt = p(fixtures.join("x.debt"));
    let odl = p(fixtures.join("x.odl"));
    let ot = p(fixtures.join("x.ot"));
    let xyz = p(fixtures.join("x.xyz"));
    vec![
        Case {
            bin: env!("TOOL_EXE_rcp-pack"),
            sub: None,
            base: s(&["-o", "out.bin"]),
            stdin: jsonl,
            outputs: vec!["out.bin"],
        },
        Case {
            bin: env!("TOOL_EXE_rcp-dump"),
            sub: None,
            base: s(&["-o", "out.txt"]),
            stdin: frames.clone(),
            outputs: vec!["out.txt"],
        },
        Case {
            bin: env!("TOOL_EXE_debt-encode"),
            sub: None,
            base: s(&[&png, "-b", "300", "--roi", "0,0,32,24", "-o", "out.debt"]),
            stdin: Vec::new(),
            outputs: vec!["out.debt"],
        },
        Case {
            bin: env!("TOOL_EXE_debt-decode"),
            sub: None,
            base: s(&[&debt, "-o", "out.png"]),
            stdin: Vec::new(),
            outputs: vec!["out.png"],
        },
        Case {
            bin: env!("TOOL_EXE_link-sim"),
            sub: None,
            base: s(&["--trace", "trace.csv"]),
            stdin: frames,
            outputs: vec!["trace.csv"],
        },
        Case {
            bin: env!("TOOL_EXE_modem-bench"),
            sub: None,
            base: s(&["--sim", "s100", "--count", "20", "-o", "p.csv"]),
            stdin: Vec::new(),
            outputs: vec!["p.csv"],
        },
        Case {
            bin: env!("TOOL_EXE_tdma-run"),
            sub: None,
            base: s(&["--duration", "5", "--metrics", "m.json"]),
            stdin: Vec::new(),
            outputs: vec!["m.json"],
        },
        Case {
            bin: env!("TOOL_EXE_octo-delta"),
            sub: Some("build"),
            base: s(&[&xyz, "--origin", "0,0,0", "-o", "out.odl"]),
            stdin: Vec::new(),
            outputs: vec!["out.odl"],
        },
        Case {
            bin: env!("TOOL_EXE_octo-delta"),
            sub: Some("apply"),
            base: s(&[&odl, "-o", "view.ot"]),
            stdin: Vec::new(),
            outputs: vec!["view.ot"],
        },
        Case {
            bin: env!("TOOL_EXE_octo-delta"),
            sub: Some("full"),
            base: s(&[&ot, "-o", "full.odl"]),
            stdin: Vec::new(),
            outputs: vec!["full.odl"],
        },
        Case {
            bin: env!("TOOL_EXE_octo-delta"),
            sub: Some("dump"),
            base: s(&[&odl]),
            stdin: Vec::new(),
            outputs: vec![],
        },
        Case {
            bin: env!("TOOL_EXE_octo-delta"),
            sub: Some("synth"),
            base: s(&["--scans", "1", "-o", "s.graph"]),
            stdin: Vec::new(),
            outputs: vec!["s.graph"],
        },
    ]
}

/// Inputs the cases read: a DEBT stream, a tiny cloud, its delta stream and map.
fn make_fixtures(dir: &Path) {
    let ok = |out: std::process::Output, what: &str| {
        assert!(
            out.status.success(),
            "{what}: {}",
            String::from_utf8_lossy(&out.stderr)
        )
    };
    let png = testdata("kodim23-64x48.png");
    ok(
        Command::new(env!("TOOL_EXE_debt-encode"))
            .arg(&png)
            .args(["-b", "300", "-o"])
            .arg(dir.join("x.debt"))
            .output()
            .unwrap(),
        "debt-encode",
    );
    std::fs::write(dir.join("x.xyz"), "1 0 0\n0 1 0\n0.5 0.5 0.2\n").unwrap();
    ok(
        Command::new(env!("TOOL_EXE_octo-delta"))
            .arg("build")
            .arg(dir.join("x.xyz"))
            .args(["--origin", "0,0,0", "-o"])
            .arg(dir.join("x.odl"))
            .arg("--ot")
            .arg(dir.join("x.ot"))
            .output()
            .unwrap(),
        "octo-delta build",
    );
}

#[test]
fn every_numeric_flag_is_range_checked() {
    let fixtures = scratch();
    make_fixtures(fixtures.path());
    let cases = cases(fixtures.path());
    let mut jobs = Vec::new();
    for case in &cases {
        for (flag, value_name) in numeric_flags(case.bin, case.sub) {
            jobs.push((case, flag, value_name));
        }
    }
    assert!(jobs.len() > 60, "only {} numeric flags found", jobs.len());
    let failures = std::sync::Mutex::new(Vec::<String>::new());
    let next = std::sync::atomic::AtomicUsize::new(0);
    std::thread::scope(|scope| {
        for _ in 0..4 {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                    let Some((case, flag, value_name)) = jobs.get(i) else {
                        break;
                    };
                    let tool = format!(
                        "{} {}",
                        Path::new(case.bin).file_name().unwrap().to_string_lossy(),
                        case.sub.unwrap_or("")
                    );
                    for value in [
                        "NaN",
                        "inf",
                        "1e300",
                        "-1e300",
                        "0",
                        "-1",
                        "18446744073709551616",
                    ] {
                        let dir = scratch();
                        let args = with_flag(&case.base, flag, value);
                        let run = run_case(case, &args, dir.path());
                        let what = format!("{tool} {flag} {value} (<{value_name}>)");
                        let strict = ["NaN", "inf", "1e300", "-1e300"].contains(&value);
                        let outcome = std::panic::catch_unwind(|| {
                            assert_contract(&run, &[0, 1, 2], &what);
                            if strict {
                                assert_eq!(
                                    run.code,
                                    Some(2),
                                    "{what}: accepted; stderr: {}",
                                    run.stderr
                                );
                                let lines: Vec<_> = run.stderr.lines().collect();
                                assert!(
                                    lines.len() == 1 && lines[0].contains(flag.as_str()),
                                    "{what}: the error is not one line naming the flag: {:?}",
                                    run.stderr
                                );
                            }
                            if run.code == Some(2) {
                                for out in &case.outputs {
                                    assert!(
                                        !dir.path().join(out).exists(),
                                        "{what}: exit 2 left {out} behind"
                                    );
                                }
                            }
                        });
                        if let Err(e) = outcome {
                            let text = e
                                .downcast_ref::<String>()
                                .cloned()
                                .unwrap_or_else(|| "failed".into());
                            failures.lock().unwrap().push(text);
                        }
                    }
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
    assert!(
        failures.is_empty(),
        "{} of {} flag values broke the contract:\n{}",
        failures.len(),
        jobs.len() * 7,
        failures.join("\n")
    );
}
