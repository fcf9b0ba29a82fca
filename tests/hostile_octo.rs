//! octo-delta as a hostile user runs it: empty, random and truncated inputs of every format for
//! every subcommand; every numeric flag at NaN, inf, 0, negative and huge; outputs that are
//! inputs; `/dev/full`; two outputs on standard output; SIGTERM and SIGINT in the middle of a
//! build; `| head -1`; and the issue's defects (a point whose squared distance underflows, a
//! survey of 2^32 scans). The contract: exit 0 or 2 (130/143 when interrupted), never a panic
//! or a signal death, never a hang; exit 2 is one line naming the file or the flag and leaves
//! no output file; an interrupted build leaves whole, valid outputs and no temporary file.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::Duration;

use crate::common::hostile::{
    Run, assert_contract, assert_whole_csv, garbage, head_one, lines_in, run, run_in, signal_once,
    temp_files,
};
use nix::sys::signal::Signal;
use rovlink_octo::{Pose, Scan};
use rovlink_scans::cloud::{PcdData, write_pcd, write_ply, write_xyz};

const OCTO: &str = env!("TOOL_EXE_octo-delta");
const LIMIT: Duration = Duration::from_secs(60);

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs octo-delta in `dir` with the contract's limit.
fn octo(dir: &Path, args: &[&str]) -> Run {
    run_in(dir, OCTO, args, b"", LIMIT)
}

fn ok(run: &Run, what: &str) {
    assert_contract(run, &[0], what);
}

/// Exit 2 with one line on stderr, prefixed with the tool's name and containing `needle`.
fn refused(run: &Run, needle: &str, what: &str) {
    assert_contract(run, &[2], what);
    let lines: Vec<&str> = run.stderr.lines().collect();
    assert_eq!(lines.len(), 1, "{what}: not one line: {:?}", run.stderr);
    assert!(
        lines[0].starts_with("octo-delta: ") && lines[0].contains(needle),
        "{what}: {:?} does not name {needle:?}",
        lines[0]
    );
}

fn a_scan() -> Scan {
    Scan {
        points: vec![[1.0, 0.0, -0.5], [0.5, 0.7, -1.0], [-0.3, 0.2, -2.0]],
        colors: Some(vec![[200, 10, 10], [10, 200, 10], [10, 10, 200]]),
        pose: Pose::IDENTITY,
    }
}

/// A 2-scan survey in `dir`, as `s.graph` and as `s.mcap`.
fn surveys(dir: &Path) {
    ok(
        &octo(dir, &["synth", "--scans", "2", "-o", "s.graph"]),
        "synth graph",
    );
    ok(
        &octo(dir, &["synth", "--scans", "2", "-o", "s.mcap"]),
        "synth mcap",
    );
}

/// Valid inputs of every kind in `dir`: clouds, a survey (.graph and .mcap), a stream, maps.
fn fixtures(dir: &Path) -> Vec<PathBuf> {
    let scan = a_scan();
    std::fs::write(dir.join("c.pcd"), write_pcd(&scan, PcdData::Binary)).unwrap();
    std::fs::write(dir.join("c.ply"), write_ply(&scan)).unwrap();
    std::fs::write(dir.join("c.xyz"), write_xyz(&scan)).unwrap();
    surveys(dir);
    ok(
        &octo(
            dir,
            &[
                "build", "s.graph", "-q", "-o", "s.odl", "--ot", "s.ot", "--bt", "s.bt",
            ],
        ),
        "build fixtures",
    );
    [
        "c.pcd", "c.ply", "c.xyz", "s.graph", "s.mcap", "s.odl", "s.ot", "s.bt",
    ]
    .iter()
    .map(|n| dir.join(n))
    .collect()
}

/// The command reading `input` whose output `out` must not exist after an exit 2.
fn reader_of(input: &Path) -> Vec<String> {
    let ext = input.extension().unwrap().to_str().unwrap();
    let i = input.display().to_string();
    let v: Vec<&str> = match ext {
        "odl" => vec!["apply", &i, "-o", "out"],
        "ot" | "bt" => vec!["full", &i, "-o", "out"],
        _ => vec![
            "build", &i, "--origin", "0,0,0", "-o", "out", "--stats", "st.csv",
        ],
    };
    v.into_iter().map(String::from).collect()
}

#[test]
fn empty_random_and_truncated_inputs_are_errors_or_work() {
    let dir = tempfile::tempdir().unwrap();
    let files = fixtures(dir.path());
    let work = tempfile::tempdir().unwrap();
    for (k, file) in files.iter().enumerate() {
        let bytes = std::fs::read(file).unwrap();
        let name = file.file_name().unwrap().to_str().unwrap();
        let mut variants: Vec<(String, Vec<u8>)> = vec![
            ("empty".into(), Vec::new()),
            ("random".into(), garbage(700, k as u64 + 1)),
            ("random after the first bytes".into(), {
                let mut b = bytes[..bytes.len().min(24)].to_vec();
                b.extend(garbage(300, k as u64 + 50));
                b
            }),
        ];
        for cut in [1, bytes.len() / 3, bytes.len() / 2, bytes.len() - 1] {
            variants.push((format!("cut at {cut}"), bytes[..cut].to_vec()));
        }
        for (what, data) in variants {
            let input = work.path().join(name);
            std::fs::write(&input, &data).unwrap();
            let args = reader_of(&input);
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            for sub in [args.clone(), vec!["dump", s(&input)]] {
                let what = format!("{} {name} {what}", sub[0]);
                let r = octo(work.path(), &sub);
                assert_contract(&r, &[0, 2], &what);
                if r.code == Some(2) {
                    assert_eq!(r.stderr.lines().count(), 1, "{what}: {}", r.stderr);
                    assert!(!work.path().join("out").exists(), "{what}: left its output");
                    assert!(!work.path().join("st.csv").exists(), "{what}: left --stats");
                }
                let _ = std::fs::remove_file(work.path().join("out"));
                let _ = std::fs::remove_file(work.path().join("st.csv"));
            }
            assert!(temp_files(work.path()).is_empty());
        }
    }
    // No format to be found: named, exit 2.
    std::fs::write(work.path().join("x.bin"), garbage(100, 9)).unwrap();
    refused(
        &octo(work.path(), &["build", "x.bin", "-o", "out"]),
        "x.bin: unknown input format",
        "unknown format",
    );
    refused(
        &octo(work.path(), &["build", "missing.xyz", "-o", "out"]),
        "missing.xyz",
        "missing input",
    );
    assert!(!work.path().join("out").exists());
}

#[test]
fn every_numeric_flag_at_bad_values_is_refused_with_its_range() {
    let dir = tempfile::tempdir().unwrap();
    fixtures(dir.path());
    let build = ["build", "c.xyz", "--origin", "0,0,0", "-o", "out"];
    let link = ["--link", "satellite-up"];
    // (command, flag, values refused besides NaN, inf, -inf, 1e300, -1e300, -1)
    let cases: Vec<(Vec<&str>, &str, Vec<&str>)> = vec![
        (build.to_vec(), "--res", vec!["0", "1e-9", "5000"]),
        (build.to_vec(), "--max-range", vec!["0", "1e9"]),
        (
            build.to_vec(),
            "--coarse-depth",
            vec!["0", "17", "4294967296"],
        ),
        (build.to_vec(), "--coarse-res", vec!["0", "0.05", "1e7"]),
        (
            build.to_vec(),
            "--threads",
            vec!["0", "65", "18446744073709551616"],
        ),
        (
            build.to_vec(),
            "--max-cells",
            vec!["0", "1099511627777", "18446744073709551616"],
        ),
        (
            [&build[..], &link[..]].concat(),
            "--scan-period",
            vec!["1e6"],
        ),
        (
            [&build[..], &link[..]].concat(),
            "--seed",
            vec!["18446744073709551616"],
        ),
        (
            vec!["apply", "s.odl", "-o", "out"],
            "--messages",
            vec!["1e10"],
        ),
        (
            vec!["full", "s.ot", "-o", "out"],
            "--coarse-depth",
            vec!["0", "99"],
        ),
        (vec!["full", "s.ot", "-o", "out"], "--coarse-res", vec!["0"]),
        (
            vec!["synth", "-o", "out"],
            "--scans",
            vec!["0", "10001", "4294967296"],
        ),
        (
            vec!["synth", "-o", "out"],
            "--seed",
            vec!["18446744073709551616"],
        ),
    ];
    for (base, flag, extra) in cases {
        for value in ["NaN", "inf", "-inf", "1e300", "-1e300", "-1"]
            .into_iter()
            .chain(extra)
        {
            let mut args = base.clone();
            args.extend([flag, value]);
            let what = format!("{} {flag} {value}", base[0]);
            refused(&octo(dir.path(), &args), flag, &what);
            assert!(!dir.path().join("out").exists(), "{what}: left its output");
        }
    }
    // Points and boxes: each number checked, and the box's order.
    for (flag, value) in [
        ("--origin", "0,nan,0"),
        ("--origin", "1e300,0,0"),
        ("--origin", "0,0"),
        ("--roi", "0,0,0,1,1,inf"),
        ("--roi", "1,1,1,0,0,0"),
        ("--roi", "-1e30,0,0,1,1,1"),
    ] {
        let mut args = build.to_vec();
        args.retain(|a| *a != "--origin" && *a != "0,0,0");
        args.extend([flag, value]);
        refused(&octo(dir.path(), &args), flag, &format!("{flag} {value}"));
    }
    // Values at the edges of the ranges work.
    for (flag, value) in [
        ("--res", "0.0001"),
        ("--res", "1000"),
        ("--max-range", "100000"),
        ("--coarse-depth", "1"),
        ("--threads", "64"),
        ("--max-cells", "1099511627776"),
    ] {
        let mut args = build.to_vec();
        args.extend([flag, value, "-q"]);
        ok(&octo(dir.path(), &args), &format!("{flag} {value}"));
    }
}

/// A resolution far too fine for the scans' range (0.1 mm over metres: hundreds of millions of
/// cells a scan) is refused before any ray is cast, with one line naming the scan, its cells,
/// --res and --max-cells, and no output: before, it took every byte of memory (24 GB) until
/// the kernel killed it. On 1 and on 3 threads, coloured and plain (the live mapper's own test
/// is `a_scan_over_the_cell_budget_is_an_error_and_leaves_the_map_as_it_was`); --max-cells
/// below a sane scan's count refuses it as well, and above it builds.
#[test]
fn a_resolution_too_fine_for_the_range_is_refused_before_memory_runs_out() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    surveys(d);
    for input in ["s.graph", "s.mcap"] {
        for threads in ["1", "3"] {
            let what = format!("{input} --res 0.0001 --threads {threads}");
            let args = ["build", input, "--res", "0.0001", "--threads", threads];
            let run = octo(d, &[&args[..], &["-o", "out", "--ot", "out.ot"]].concat());
            refused(&run, "--max-cells", &what);
            assert!(
                run.stderr.contains("scan 0: ") && run.stderr.contains("--res 0.0001 m"),
                "{what}: {:?}",
                run.stderr
            );
            assert!(
                !d.join("out").exists() && !d.join("out.ot").exists(),
                "{what}: left output"
            );
        }
    }
    // The budget is the flag's: a sane scan's bound (about 8e5 cells at 0.1 m) over a low one.
    let low = octo(d, &["build", "s.graph", "--max-cells", "1000", "-o", "out"]);
    refused(&low, "more than the 1000 a scan may", "--max-cells 1000");
    ok(
        &octo(
            d,
            &[
                "build",
                "s.graph",
                "--max-cells",
                "5000000",
                "-q",
                "-o",
                "out",
            ],
        ),
        "--max-cells 5000000",
    );
}

#[test]
fn outputs_that_are_inputs_are_refused_and_the_input_is_untouched() {
    let dir = tempfile::tempdir().unwrap();
    fixtures(dir.path());
    let d = dir.path();
    std::os::unix::fs::symlink(d.join("c.xyz"), d.join("link.xyz")).unwrap();
    let model = rovlink_link::Model::preset("satellite-up").unwrap();
    std::fs::write(d.join("model.json"), model.to_json()).unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["build", "c.xyz", "-o", "c.xyz"], "c.xyz"),
        (
            vec!["build", "c.xyz", "-o", "x.odl", "--bt", "c.xyz"],
            "c.xyz",
        ),
        (
            vec!["build", "c.xyz", "-o", "x.odl", "--ot", "./c.xyz"],
            "c.xyz",
        ),
        (
            vec!["build", "c.xyz", "-o", "x.odl", "--stats", "link.xyz"],
            "c.xyz",
        ),
        (
            vec!["build", "s.graph", "c.xyz", "-o", "s.graph"],
            "s.graph",
        ),
        (
            vec![
                "build",
                "c.xyz",
                "-o",
                "x.odl",
                "--link",
                "model.json",
                "--arrivals",
                "model.json",
            ],
            "model.json",
        ),
        (vec!["apply", "s.odl", "-o", "s.odl"], "s.odl"),
        (vec!["full", "s.ot", "-o", "s.ot"], "s.ot"),
        (vec!["full", "s.bt", "-o", "s.bt"], "s.bt"),
        (vec!["dump", "s.odl", "-o", "s.odl"], "s.odl"),
    ];
    for (args, input) in cases {
        let before = std::fs::read(d.join(input)).unwrap();
        let what = args.join(" ");
        refused(&octo(d, &args), "refusing to overwrite an input", &what);
        assert_eq!(std::fs::read(d.join(input)).unwrap(), before, "{what}");
        assert!(!d.join("x.odl").exists(), "{what}: left -o behind");
    }
    // Two outputs on one file, two on standard output.
    refused(
        &octo(d, &["build", "c.xyz", "-o", "a.odl", "--bt", "a.odl"]),
        "also the output of -o",
        "-o = --bt",
    );
    refused(
        &octo(d, &["build", "c.xyz", "--stats", "-"]),
        "both write to standard output",
        "-o and --stats on stdout",
    );
    assert!(!d.join("a.odl").exists());
}

#[test]
fn side_outputs_go_to_standard_output_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    fixtures(dir.path());
    let r = octo(
        dir.path(),
        &["build", "s.graph", "-q", "-o", "x.odl", "--stats", "-"],
    );
    ok(&r, "--stats -");
    let text = String::from_utf8(r.stdout).unwrap();
    assert!(text.starts_with("scan,points,delta_bytes,"), "{text}");
    assert_eq!(text.lines().count(), 3, "header and two scans: {text}");
    assert!(!dir.path().join("-").exists(), "a file named -");
}

#[test]
fn a_full_disk_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    fixtures(dir.path());
    for args in [
        vec!["build", "s.graph", "-q", "-o", "/dev/full"],
        vec!["build", "s.graph", "-q", "-o", "x.odl", "--bt", "/dev/full"],
        vec![
            "build",
            "s.graph",
            "-q",
            "-o",
            "x.odl",
            "--stats",
            "/dev/full",
        ],
        vec!["apply", "s.odl", "-o", "/dev/full"],
        vec!["full", "s.ot", "-o", "/dev/full"],
        vec!["dump", "s.odl", "-o", "/dev/full"],
        vec!["synth", "--scans", "1", "-o", "/dev/full"],
    ] {
        let what = args.join(" ");
        refused(&octo(dir.path(), &args), "/dev/full", &what);
        assert!(!dir.path().join("x.odl").exists(), "{what}: left -o behind");
        assert!(temp_files(dir.path()).is_empty(), "{what}");
    }
}

#[test]
fn closed_pipes_downstream_are_success() {
    let dir = tempfile::tempdir().unwrap();
    fixtures(dir.path());
    let odl = dir.path().join("s.odl");
    let graph = dir.path().join("s.graph");
    for args in [
        vec!["dump", s(&odl), "--voxels"],
        vec!["dump", s(&odl), "--format", "ndjson", "--voxels"],
        vec!["synth", "--scans", "3"],
        vec!["build", s(&graph), "-q"],
    ] {
        let r = head_one(OCTO, &args, b"", LIMIT);
        let what = format!("{} | head -1", args.join(" "));
        assert_contract(&r, &[0], &what);
        assert_eq!(r.stderr, "", "{what}");
    }
}

/// Starts a long build (the survey many times over) in `dir`, sends `signal` once the build
/// catches it and the stats file has two rows, and returns the run.
fn interrupted_build(dir: &Path, signal: Signal) -> (Option<i32>, String) {
    ok(
        &octo(dir, &["synth", "--scans", "6", "-o", "long.graph"]),
        "synth",
    );
    let mut args = vec!["build"];
    args.extend(std::iter::repeat_n("long.graph", 200));
    args.extend([
        "-o",
        "i.odl",
        "--stats",
        "i.csv",
        "--bt",
        "i.bt",
        "--ot",
        "i.ot",
        "--threads",
        "1",
    ]);
    let mut child = Command::new(OCTO)
        .args(&args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let said = std::thread::spawn(move || std::io::read_to_string(stderr).unwrap_or_default());
    let stats = dir.join("i.csv");
    signal_once(&mut child, signal, &|| lines_in(&stats) >= 3, LIMIT);
    let status = crate::common::wait_for_exit(&mut child, LIMIT);
    (status.code(), said.join().unwrap())
}

/// True if a thread of process `pid` is blocked reading a pipe (its `wchan` in /proc names
/// the kernel's pipe read: `pipe_read`, `anon_pipe_read`, `pipe_wait` by kernel version). A
/// pipe read blocks only on an empty pipe.
fn blocked_reading_a_pipe(pid: u32) -> bool {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return false;
    };
    tasks.flatten().any(|task| {
        std::fs::read_to_string(task.path().join("wchan")).is_ok_and(|w| w.contains("pipe"))
    })
}

/// Runs octo-delta with `args` in `dir`, reading the named pipe `dir/fifo` (created here)
/// whose writer sends `bytes` and then stays open and silent, as a live producer does. Sends
/// SIGTERM once the tool catches it, all the bytes are written and the tool waits on the empty
/// pipe (no guess at how long it takes to get there); fails the test if it has not ended
/// within LIMIT of that. Returns the exit status and standard error.
fn signalled_while_reading_a_silent_pipe(
    dir: &Path,
    fifo: &str,
    args: &[&str],
    bytes: &[u8],
) -> (ExitStatus, String) {
    signalled_once_a_silent_pipe_is_read(dir, fifo, args, bytes, &|pid| blocked_reading_a_pipe(pid))
}

/// [`signalled_while_reading_a_silent_pipe`], the signal sent once all the bytes are written
/// and `ready(pid)` holds.
fn signalled_once_a_silent_pipe_is_read(
    dir: &Path,
    fifo: &str,
    args: &[&str],
    bytes: &[u8],
    ready: &dyn Fn(u32) -> bool,
) -> (ExitStatus, String) {
    let fifo = dir.join(fifo);
    let _ = std::fs::remove_file(&fifo);
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).expect("mkfifo");
    let mut child = Command::new(OCTO)
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("binary starts");
    let stderr = child.stderr.take().unwrap();
    let said = std::thread::spawn(move || std::io::read_to_string(stderr).unwrap_or_default());
    // Read and write: opening does not wait for the reader, and the pipe never ends. Written
    // aside: more than a pipe holds waits for the tool to read it.
    let mut writer = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&fifo)
        .expect("the pipe opens");
    let bytes = bytes.to_vec();
    let writing = std::thread::spawn(move || {
        writer.write_all(&bytes).expect("the pipe takes the bytes");
        writer
    });
    let pid = child.id();
    let waiting = || writing.is_finished() && ready(pid);
    signal_once(&mut child, Signal::SIGTERM, &waiting, LIMIT);
    let status = crate::common::wait_for_exit(&mut child, LIMIT);
    drop(writing.join().unwrap());
    (status, said.join().unwrap())
}

#[test]
fn a_signal_stops_a_build_with_whole_valid_outputs() {
    for (signal, code, name) in [
        (Signal::SIGTERM, 143, "SIGTERM"),
        (Signal::SIGINT, 130, "SIGINT"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let (got, stderr) = interrupted_build(d, signal);
        assert_eq!(got, Some(code), "{name}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(
            stderr.contains(&format!("interrupted by {name}")),
            "{stderr}"
        );
        assert!(temp_files(d).is_empty(), "{name}: temp files left");
        // Whole rows, one per message in the stream, and the stream decodes.
        assert_whole_csv(&d.join("i.csv"));
        let rows = std::fs::read_to_string(d.join("i.csv"))
            .unwrap()
            .lines()
            .count()
            - 1;
        let dump = octo(d, &["dump", "i.odl", "--format", "csv"]);
        ok(&dump, "dump of the interrupted stream");
        let messages = String::from_utf8(dump.stdout).unwrap().lines().count() - 1;
        assert_eq!(messages, rows, "{name}: messages vs stats rows");
        assert!((2..1200).contains(&rows), "{rows} rows");
        // The maps are the map so far, and read back.
        ok(
            &octo(d, &["full", "i.ot", "-o", "f1.odl"]),
            "full of the .ot",
        );
        ok(
            &octo(d, &["full", "i.bt", "-o", "f2.odl"]),
            "full of the .bt",
        );
        // The summary counts as many scans as the stream holds.
        assert!(stderr.contains(&format!("after {rows} scans")), "{stderr}");
    }
}

#[test]
fn issue_14_defects_are_fixed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The squared distance of this point from the origin underflows to 0 in f32: it hung.
    std::fs::write(d.join("t.xyz"), "-1e-30 -1e-30 -1e-30\n").unwrap();
    let r = run_in(
        d,
        OCTO,
        &["build", "t.xyz", "--origin", "0,0,0", "-o", "t.odl"],
        b"",
        Duration::from_secs(20),
    );
    ok(&r, "the underflowing point");
    assert!(r.stderr.contains("1 scans, 1 points"), "{}", r.stderr);
    ok(&octo(d, &["apply", "t.odl", "-o", "t.ot"]), "apply");
    // 2^32 scans aborted allocating 72 GB.
    let r = octo(d, &["synth", "--scans", "4294967296", "-o", "x.graph"]);
    refused(
        &r,
        "--scans: expected 1 ..= 10000 scans, found 4294967296",
        "2^32 scans",
    );
    assert!(!d.join("x.graph").exists());
    // Subnormal, huge and origin points of every kind, through a whole build.
    std::fs::write(
        d.join("odd.xyz"),
        "0 0 0\n1e-45 -1e-45 1e-45\n1e-38 0 0\n3e38 3e38 3e38\n-3.4e38 0 0\n1e-30 1e-30 1e-30\n",
    )
    .unwrap();
    for res in ["0.0001", "0.1", "1000"] {
        let r = run(
            OCTO,
            &[
                "build",
                s(&d.join("odd.xyz")),
                "--res",
                res,
                "--origin",
                "0,0,0",
                "-o",
                "-",
            ],
            b"",
            Duration::from_secs(20),
        );
        assert_contract(&r, &[0], &format!("odd points at {res} m"));
    }
}

#[test]
fn a_signal_stops_a_build_reading_a_silent_pipe() {
    let dir = tempfile::tempdir().unwrap();
    let graph = dir.path().join("survey.graph");
    ok(
        &octo(dir.path(), &["synth", "--scans", "3", "-o", s(&graph)]),
        "synth",
    );
    let survey = std::fs::read(&graph).unwrap();
    for (format, bytes) in [
        ("xyz", &b"1 1 1\n2 2 2\n"[..]),
        ("graph", &survey[..600_000]),
    ] {
        let args = [
            "build",
            "scans.graph",
            "--format",
            format,
            "--origin",
            "0,0,0",
            "-q",
            "-o",
            "out.odl",
            "--stats",
            "out.csv",
            "--ot",
            "out.ot",
        ];
        let (status, err) =
            signalled_while_reading_a_silent_pipe(dir.path(), "scans.graph", &args, bytes);
        assert_eq!(status.code(), Some(143), "{format}: {err}");
        assert!(err.contains("interrupted by SIGTERM"), "{format}: {err}");
        assert!(
            temp_files(dir.path()).is_empty(),
            "{format}: temporary file left"
        );
        assert_whole_csv(&dir.path().join("out.csv"));
        ok(
            &octo(dir.path(), &["dump", "out.odl"]),
            "dump of the stopped stream",
        );
        ok(
            &octo(dir.path(), &["full", "out.ot", "-o", "full.odl"]),
            "the stopped map reads",
        );
    }
}

/// Issue 48, defect 4: with 2 threads or more, whole scans received from a quiet pipe waited
/// for the next scan before going into the map (10 scans: 1 thread wrote 10 messages, 2 threads
/// 2, 3 or 4 none). Every thread count now writes each scan's message and stats row as soon as
/// the scan is whole: the test waits for the tenth row (no timer), then stops the build.
#[test]
fn every_thread_count_builds_each_scan_of_a_quiet_pipe_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let scans: Vec<Scan> = (0..12)
        .map(|k| Scan {
            points: (0..200)
                .map(|i| {
                    [
                        1.0 + (i % 20) as f32 * 0.1,
                        (i / 20) as f32 * 0.1,
                        k as f32 * 0.3,
                    ]
                })
                .collect(),
            colors: None,
            pose: Pose::IDENTITY,
        })
        .collect();
    let graph = rovlink_octo::graph::write(&scans);
    // The node count and the first ten nodes: u32 points, 28 bytes a point, a 68-byte pose,
    // a u32 id.
    let ten = 4 + 10 * (4 + 200 * 28 + 28 + 36 + 4);
    for threads in ["1", "2", "3", "4"] {
        let d = dir.path().join(format!("t{threads}"));
        std::fs::create_dir(&d).unwrap();
        let args = [
            "build",
            "scans.graph",
            "--threads",
            threads,
            "-q",
            "-o",
            "out.odl",
            "--stats",
            "out.csv",
            "--ot",
            "out.ot",
        ];
        let stats = d.join("out.csv");
        // The header and ten rows, while the pipe is still open and quiet.
        let (status, err) =
            signalled_once_a_silent_pipe_is_read(&d, "scans.graph", &args, &graph[..ten], &|_| {
                lines_in(&stats) >= 11
            });
        assert_eq!(status.code(), Some(143), "{threads} threads: {err}");
        assert!(err.contains("after 10 scans"), "{threads} threads: {err}");
        let dump = octo(&d, &["dump", "out.odl", "--format", "csv"]);
        ok(&dump, "dump of the stopped stream");
        let messages = String::from_utf8(dump.stdout).unwrap().lines().count() - 1;
        assert_eq!(messages, 10, "{threads} threads: messages in the stream");
        ok(
            &octo(&d, &["full", "out.ot", "-o", "full.odl"]),
            "the map reads",
        );
    }
}
