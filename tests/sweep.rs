//! `--metrics` of every tool that produces figures, and `scripts/sweep` over GNU parallel and
//! Slurm: the issue's 20-run grid, resuming after deleted folders and after a signal, the job
//! array script, bad grids, only the toolkit's tools, foreign `--out` folders, control
//! characters in paths. Needs python3 and GNU parallel (installed by .ci/run), and matplotlib
//! for the plots.

use std::collections::BTreeSet;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::hostile::{Run, assert_contract, run_in};
use crate::common::tree;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use serde_json::Value;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");
const LINK_SIM: &str = env!("TOOL_EXE_link-sim");
const MODEM_BENCH: &str = env!("TOOL_EXE_modem-bench");
const RCP_DUMP: &str = env!("TOOL_EXE_rcp-dump");
const DEBT_ENCODE: &str = env!("TOOL_EXE_debt-encode");
const OCTO_DELTA: &str = env!("TOOL_EXE_octo-delta");
const LIMIT: Duration = Duration::from_secs(120);

/// Two short simulated sessions: one swept flag (--ber), one seed.
const TWO_RUNS_GRID: &str =
    r#"{"tool":"tdma-run","args":{"--sim":[null],"--duration":[10],"--ber":[0,0.0007]}}"#;

/// The issue's grid: 2 BERs x 2 IPGs x 5 seeds of a 120 s simulated session.
const TABLE4_GRID: &str = r#"{"tool":"tdma-run","args":{"--sim":[null],"--duration":[120],"--ber":[0,0.0007],"--ipg":[640,800]},"seeds":5}"#;

fn sweep_script() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scripts/sweep")
        .display()
        .to_string()
}

/// The folder of the tools under test (the debug build), for --tool-dir.
fn tool_dir() -> String {
    Path::new(TDMA_RUN).parent().unwrap().display().to_string()
}

/// python3's arguments for `scripts/sweep ARGS --tool-dir <the tools under test>`.
fn sweep_argv(args: &[&str]) -> Vec<String> {
    let mut all = vec![sweep_script()];
    all.extend(args.iter().map(|a| a.to_string()));
    all.extend(["--tool-dir".into(), tool_dir()]);
    all
}

fn sweep(dir: &Path, args: &[&str]) -> Run {
    let all = sweep_argv(args);
    let all: Vec<&str> = all.iter().map(String::as_str).collect();
    run_in(dir, "python3", &all, b"", LIMIT)
}

/// `scripts/sweep ARGS` as given (no --tool-dir added).
fn sweep_raw(dir: &Path, args: &[&str]) -> Run {
    let script = sweep_script();
    let mut all = vec![script.as_str()];
    all.extend_from_slice(args);
    run_in(dir, "python3", &all, b"", LIMIT)
}

/// Asserts a refusal: exit 2 and one line, `sweep: ...`, without a traceback.
fn assert_one_line_refusal(run: &Run, what: &str) -> String {
    assert_contract(run, &[2], what);
    let line = run.stderr.trim_end();
    assert!(
        line.starts_with("sweep: ") && !line.contains('\n') && !line.contains("Traceback"),
        "{what}: {line}"
    );
    line.to_string()
}

/// The names in `dir` (not recursive).
fn names(dir: &Path) -> BTreeSet<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

/// Runs `scripts/sweep ARGS --tool-dir <the tools under test>` in `dir`, polls the filesystem
/// (every 20 ms, for at most LIMIT) until `started` says the work has begun, then sends
/// `signal` once and waits (at most LIMIT) for the sweep to end. Unlike a fixed delay, this
/// does not depend on how long anything takes.
fn sweep_signalled_once_started(
    dir: &Path,
    args: &[&str],
    started: impl Fn() -> bool,
    signal: Signal,
) -> Run {
    let mut child = Command::new("python3")
        .args(sweep_argv(args))
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 starts");
    let mut err = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = err.read_to_string(&mut text);
        text
    });
    let begun = Instant::now();
    while !started() {
        if let Some(status) = child.try_wait().expect("try_wait") {
            panic!(
                "the sweep ended ({status}) before its work started: {}",
                reader.join().unwrap_or_default()
            );
        }
        if begun.elapsed() > LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "no sign of the work within {LIMIT:?}: {}",
                reader.join().unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    kill(Pid::from_raw(child.id() as i32), signal).expect("the sweep is there to signal");
    let signalled = Instant::now();
    let mut hung = false;
    let status = loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            break status;
        }
        if signalled.elapsed() > LIMIT {
            hung = true;
            let _ = child.kill();
            break child.wait().expect("wait");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    use std::os::unix::process::ExitStatusExt;
    Run {
        code: status.code(),
        signal: status.signal(),
        stdout: Vec::new(),
        stderr: reader.join().unwrap_or_default(),
        hung,
    }
}

/// The run id a run folder's path ends with (in the joblog, in pending.txt).
fn run_id_of(line: &str) -> String {
    line.rsplit('/').next().unwrap().to_string()
}

fn run_ids(out: &Path) -> BTreeSet<String> {
    std::fs::read_dir(out.join("runs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

fn completed(out: &Path) -> BTreeSet<String> {
    run_ids(out)
        .into_iter()
        .filter(|id| out.join("runs").join(id).join("result.json").exists())
        .collect()
}

/// The runs GNU parallel's joblog lists (the run folder ends each command).
fn joblog_runs(out: &Path) -> BTreeSet<String> {
    let log = std::fs::read_to_string(out.join("joblog")).unwrap();
    log.lines().skip(1).map(run_id_of).collect()
}

fn csv_rows(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text
        .lines()
        .map(|l| l.split(',').map(str::to_string).collect());
    let header: Vec<String> = lines.next().unwrap();
    (header, lines.collect())
}

#[test]
fn the_table4_grid_runs_gathers_plots_and_redoes_exactly_the_deleted_runs() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("grid.json"), TABLE4_GRID).unwrap();
    let out = dir.path().join("out");
    let first = sweep(dir.path(), &["grid.json", "--out", "out", "--jobs", "2"]);
    assert_contract(&first, &[0], "first sweep");
    assert_eq!(completed(&out).len(), 20, "{}", first.stderr);
    assert_eq!(joblog_runs(&out).len(), 20);

    let (header, rows) = csv_rows(&out.join("results.csv"));
    assert_eq!(rows.len(), 20);
    assert_eq!(
        header[..6],
        ["run", "sim", "duration", "ber", "ipg", "seed"]
    );
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let combos: BTreeSet<(String, String, String)> = rows
        .iter()
        .map(|r| {
            (
                r[col("ber")].clone(),
                r[col("ipg")].clone(),
                r[col("seed")].clone(),
            )
        })
        .collect();
    assert_eq!(combos.len(), 20, "every (ber, ipg, seed) once");
    for row in &rows {
        let doc: Value = serde_json::from_str(
            &std::fs::read_to_string(out.join("runs").join(&row[0]).join("result.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(doc["tool"], "tdma-run");
        assert_eq!(doc["params"]["ber"].to_string(), row[col("ber")]);
        assert_eq!(doc["params"]["ipg"].to_string(), row[col("ipg")]);
        assert_eq!(doc["seed"].to_string(), row[col("seed")]);
        let throughput = &row[col("rov_to_operator.throughput_kbps")];
        assert_eq!(
            throughput,
            &doc["rov_to_operator"]["throughput_kbps"].to_string()
        );
    }
    for plot in ["ber.png", "ipg.png"] {
        let png = std::fs::read(out.join("plots").join(plot)).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{plot}");
    }

    let kept = completed(&out);
    let deleted: BTreeSet<String> = kept.iter().take(3).cloned().collect();
    let untouched = out
        .join("runs")
        .join(kept.iter().last().unwrap())
        .join("result.json");
    let before = std::fs::read(&untouched).unwrap();
    for id in &deleted {
        std::fs::remove_dir_all(out.join("runs").join(id)).unwrap();
    }
    let again = sweep(dir.path(), &["grid.json", "--out", "out", "--jobs", "2"]);
    assert_contract(&again, &[0], "second sweep");
    assert_eq!(joblog_runs(&out), deleted, "exactly the deleted runs again");
    assert_eq!(completed(&out), kept);
    assert_eq!(std::fs::read(&untouched).unwrap(), before);
    assert_eq!(csv_rows(&out.join("results.csv")).1.len(), 20);
    assert!(
        again.stderr.contains("17 complete, 3 to run"),
        "{}",
        again.stderr
    );
}

#[test]
fn slurm_writes_a_job_array_that_runs_its_share_and_gathers() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("grid.json"), TABLE4_GRID).unwrap();
    let out = dir.path().join("out");
    let args = [
        "grid.json",
        "--out",
        "out",
        "--slurm",
        "--runs-per-task",
        "4",
    ];
    let wrote = sweep(dir.path(), &args);
    assert_contract(&wrote, &[0], "--slurm");
    let script = out.join("sweep.sbatch");
    let text = std::fs::read_to_string(&script).unwrap();
    assert!(text.starts_with("#!/bin/bash\n"), "{text}");
    assert!(text.contains("\n#SBATCH --array=0-4\n"), "{text}");
    assert!(text.contains("SLURM_ARRAY_TASK_ID"), "{text}");
    let syntax = Command::new("bash")
        .arg("-n")
        .arg(&script)
        .status()
        .unwrap();
    assert!(syntax.success(), "bash -n refuses the script");
    assert!(completed(&out).is_empty(), "--slurm runs nothing here");

    // Task 1 of the array, as Slurm would start it: runs 4..8 of the pending list.
    let task = Command::new("bash")
        .arg(&script)
        .env("SLURM_ARRAY_TASK_ID", "1")
        .output()
        .unwrap();
    assert!(
        task.status.success(),
        "{}",
        String::from_utf8_lossy(&task.stderr)
    );
    let pending = std::fs::read_to_string(out.join("pending.txt")).unwrap();
    let share: BTreeSet<String> = pending.lines().skip(4).take(4).map(run_id_of).collect();
    assert_eq!(completed(&out), share);

    let gathered = sweep(dir.path(), &["grid.json", "--out", "out", "--gather-only"]);
    assert_contract(&gathered, &[0], "--gather-only");
    assert_eq!(csv_rows(&out.join("results.csv")).1.len(), 4);
    assert!(
        gathered.stderr.contains("4 of 20 runs complete"),
        "{}",
        gathered.stderr
    );
}

/// A joystick script for tdma-run: half a minute of slow surge.
const SCRIPT_CSV: &str = "t_s,vx,vy,vz,vyaw\n0,0.1,0,0,0\n30,0,0,0,0\n";

#[test]
fn a_signal_keeps_what_completed_and_the_next_sweep_resumes() {
    // No timing in this test. Three runs, one at a time in the grid's order: two short ones,
    // then one whose --script is a named pipe that nobody writes, so that run cannot end (its
    // tool waits for the pipe) until the signal stops it. The sign of that is the third run's
    // folder holding `stdout`: the sweep opens it just before it starts that run's tool, and,
    // with --jobs 1, only after the first two runs have completed (a run's result.json is in
    // place before GNU parallel starts the next). So whenever SIGTERM arrives after the sign,
    // exactly two runs are complete and the third is mid-run. Then the pipe is replaced by a
    // file of the same name (the same run: its id is its parameters), and the resume has only
    // that run to do, one that ends.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("a.csv"), SCRIPT_CSV).unwrap();
    std::fs::write(d.join("b.csv"), SCRIPT_CSV).unwrap();
    let pipe = d.join("pipe.csv");
    nix::unistd::mkfifo(&pipe, nix::sys::stat::Mode::S_IRWXU).unwrap();
    let grid = r#"{"tool":"tdma-run","args":{"--sim":[null],"--duration":[10],"--script":["a.csv","b.csv","pipe.csv"]}}"#;
    std::fs::write(d.join("grid.json"), grid).unwrap();
    let out = d.join("out");
    let runs_started = || {
        std::fs::read_dir(out.join("runs"))
            .map(|entries| {
                entries
                    .flatten()
                    .filter(|e| e.path().join("stdout").exists())
                    .count()
            })
            .unwrap_or(0)
    };
    let stopped = sweep_signalled_once_started(
        d,
        &["grid.json", "--out", "out", "--jobs", "1"],
        || runs_started() == 3,
        Signal::SIGTERM,
    );
    assert_contract(&stopped, &[143], "SIGTERM mid-sweep");
    assert!(
        stopped.stderr.contains("interrupted: 2 of 3 runs complete"),
        "{}",
        stopped.stderr
    );
    let done = completed(&out);
    assert!(done.len() < 3, "stopped before the end");
    assert_eq!(done.len(), 2, "the two runs before the one on the pipe");
    let missing: BTreeSet<String> = run_ids(&out).difference(&done).cloned().collect();
    let kept: Vec<Vec<u8>> = done
        .iter()
        .map(|id| std::fs::read(out.join("runs").join(id).join("result.json")).unwrap())
        .collect();
    // Nothing is left reading the pipe (a stray tool would finish the run behind our back):
    // opening it to write without waiting fails (ENXIO) once it has no reader. Polled, as the
    // killed tool's files close as the kernel ends it.
    let begun = Instant::now();
    loop {
        use std::os::unix::fs::OpenOptionsExt;
        match std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(nix::libc::O_NONBLOCK)
            .open(&pipe)
        {
            Err(e) if e.raw_os_error() == Some(nix::libc::ENXIO) => break,
            other => assert!(
                begun.elapsed() < LIMIT,
                "a run still reads the pipe: {other:?}"
            ),
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    std::fs::remove_file(&pipe).unwrap();
    std::fs::write(&pipe, SCRIPT_CSV).unwrap();

    let resumed = sweep(d, &["grid.json", "--out", "out", "--jobs", "2"]);
    assert_contract(&resumed, &[0], "resumed sweep");
    assert_eq!(completed(&out).len(), 3);
    assert_eq!(joblog_runs(&out), missing, "only what was missing");
    for (id, before) in done.iter().zip(&kept) {
        let after = std::fs::read(out.join("runs").join(id).join("result.json")).unwrap();
        assert_eq!(&after, before, "{id}: a completed run kept as it was");
    }
    assert!(
        resumed.stderr.contains("2 complete, 1 to run"),
        "{}",
        resumed.stderr
    );
}

#[test]
fn bad_grids_and_flags_are_one_line_exit_2_and_run_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, &str, &[&str])] = &[
        ("missing.json", "", &[]),
        ("g.json", "{\"tool\": \"tdma-run\",", &[]),
        ("g.json", "[1, 2]", &[]),
        ("g.json", r#"{"tool":"tdma-run","args":{"--ber":[]}}"#, &[]),
        ("g.json", r#"{"tool":"tdma-run","args":{"ber":[1]}}"#, &[]),
        (
            "g.json",
            r#"{"tool":"tdma-run","args":{"--ber":[NaN]}}"#,
            &[],
        ),
        ("g.json", r#"{"tool":"tdma-run","seeds":0}"#, &[]),
        ("g.json", r#"{"tool":"tdma-run","seeds":[1,1]}"#, &[]),
        ("g.json", r#"{"tool":"no-such-tool-here"}"#, &[]),
        (
            "g.json",
            r#"{"tool":"no-such-tool-here"}"#,
            &["--allow-any-tool"],
        ),
        ("g.json", r#"{"tool":"sh","args":{"-c":["true"]}}"#, &[]),
        ("g.json", r#"{"tool":"../tdma-run"}"#, &[]),
        (
            "g.json",
            r#"{"tool":"tdma-run","positional":["in\nput"]}"#,
            &[],
        ),
        (
            "g.json",
            r#"{"tool":"tdma-run","args":{"--model":["s\r100"]}}"#,
            &[],
        ),
        (
            "g.json",
            r#"{"tool":"tdma-run","args":{"--b\u007fer":[0]}}"#,
            &[],
        ),
        ("g.json", r#"{"tool":"tdma-run","extra":1}"#, &[]),
        (
            "g.json",
            r#"{"tool":"tdma-run","args":{"--ber":[1,2]},"seeds":100000}"#,
            &[],
        ),
        ("g.json", r#"{"tool":"tdma-run"}"#, &["--jobs", "0"]),
        ("g.json", r#"{"tool":"tdma-run"}"#, &["--submit"]),
        (
            "g.json",
            r#"{"tool":"tdma-run"}"#,
            &["--sshloginfile", "nope"],
        ),
    ];
    for (k, (name, grid, extra)) in cases.iter().enumerate() {
        if !grid.is_empty() {
            std::fs::write(dir.path().join(name), grid).unwrap();
        }
        // Half the cases in a folder below one that does not exist either.
        let out = if k % 2 == 0 {
            format!("out{k}")
        } else {
            format!("new{k}/out")
        };
        let mut args = vec![*name, "--out", &out];
        args.extend_from_slice(extra);
        let run = sweep(dir.path(), &args);
        assert_one_line_refusal(&run, &format!("{grid} {extra:?}"));
        let top = out.split('/').next().unwrap();
        assert!(
            !dir.path().join(top).exists(),
            "{grid} {extra:?}: {top} left behind"
        );
    }
    // Nothing is written into an existing sweep's folder either.
    std::fs::write(
        dir.path().join("ok.json"),
        r#"{"tool":"tdma-run","args":{"--sim":[null],"--duration":[10]}}"#,
    )
    .unwrap();
    let first = sweep(dir.path(), &["ok.json", "--out", "kept"]);
    assert_contract(&first, &[0], "a sweep to add to");
    let before = names(&dir.path().join("kept"));
    let runs_before = run_ids(&dir.path().join("kept"));
    let pending_before = std::fs::read(dir.path().join("kept/pending.txt")).unwrap();
    for grid in [
        r#"{"tool":"no-such-tool-here","args":{"--x":[1]}}"#,
        r#"{"tool":"tdma-run","args":{"--x":[1,2]},"seeds":100000}"#,
    ] {
        std::fs::write(dir.path().join("g.json"), grid).unwrap();
        let run = sweep(dir.path(), &["g.json", "--out", "kept"]);
        assert_one_line_refusal(&run, grid);
        assert_eq!(names(&dir.path().join("kept")), before, "{grid}");
        assert_eq!(run_ids(&dir.path().join("kept")), runs_before, "{grid}");
        assert_eq!(
            std::fs::read(dir.path().join("kept/pending.txt")).unwrap(),
            pending_before,
            "{grid}"
        );
    }
}

/// Issue 48: a key given twice is refused, naming it, where JSON would keep the last
/// (`"--duration":[5],"--duration":[6]` ran 6 alone); nothing is written.
#[test]
fn a_key_given_twice_in_a_grid_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (grid, key) in [
        (
            r#"{"tool":"tdma-run","args":{"--sim":[null],"--duration":[5],"--duration":[6]}}"#,
            "\"--duration\"",
        ),
        (r#"{"tool":"tdma-run","seeds":2,"seeds":3}"#, "\"seeds\""),
        (
            r#"{"tool":"tdma-run","args":{"--sim":[null]},"args":{"--duration":[5]}}"#,
            "\"args\"",
        ),
    ] {
        std::fs::write(d.join("g.json"), grid).unwrap();
        for extra in [&[][..], &["--list"], &["--gather-only"]] {
            let mut args = vec!["g.json", "--out", "out"];
            args.extend_from_slice(extra);
            let run = sweep(d, &args);
            let line = assert_one_line_refusal(&run, grid);
            assert!(
                line.contains(&format!("g.json: duplicate key {key}")),
                "{grid}: {line}"
            );
            assert!(run.stdout.is_empty(), "{grid} {extra:?}: it listed runs");
            assert!(!d.join("out").exists(), "{grid} {extra:?}: out written");
        }
    }
}

/// A flag holding '/' named its plot's path: `"--x/../../y"` would have written a plot outside
/// OUT. Refused before anything is written.
#[test]
fn a_flag_holding_a_slash_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let grid = r#"{"tool":"tdma-run","args":{"--sim":[null],"--x/../../y":[1,2]}}"#;
    std::fs::write(d.join("g.json"), grid).unwrap();
    let run = sweep(d, &["g.json", "--out", "out"]);
    let line = assert_one_line_refusal(&run, grid);
    assert!(
        line.contains("'--x/../../y': a flag may not hold '/'"),
        "{line}"
    );
    assert!(!d.join("out").exists(), "out written");
}

/// The toolkit's tools, as the sweep names them when it refuses another program.
const TOOLS: [&str; 8] = [
    "debt-encode",
    "debt-decode",
    "rcp-pack",
    "rcp-dump",
    "link-sim",
    "modem-bench",
    "tdma-run",
    "octo-delta",
];

#[test]
fn only_the_toolkits_tools_run_unless_allow_any_tool() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("CANARY"), "alive\n").unwrap();
    std::fs::write(
        d.join("grid.json"),
        r#"{"tool":"sh","args":{"-c":["rm -f CANARY"]}}"#,
    )
    .unwrap();
    let run = sweep(d, &["grid.json", "--out", "out"]);
    let line = assert_one_line_refusal(&run, "a grid naming sh");
    assert!(d.join("CANARY").exists(), "sh ran: {line}");
    assert!(!d.join("out").exists(), "{line}");
    assert!(line.contains("\"sh\""), "names the tool: {line}");
    for tool in TOOLS {
        assert!(line.contains(tool), "lists {tool}: {line}");
    }
    assert!(line.contains("--allow-any-tool"), "{line}");

    let help = sweep_raw(d, &["--help"]);
    assert_contract(&help, &[0], "--help");
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(text.contains("--allow-any-tool"), "{text}");

    // With the flag, any program runs: this one writes a metrics document where --metrics says.
    let grid = r#"{"tool":"sh","args":{"-c":["printf '{\"figure\":1}' > \"$1\""]}}"#;
    std::fs::write(d.join("any.json"), grid).unwrap();
    let run = sweep(d, &["any.json", "--out", "any", "--allow-any-tool"]);
    assert_contract(&run, &[0], "--allow-any-tool");
    let (header, rows) = csv_rows(&d.join("any/results.csv"));
    assert_eq!((header.last().unwrap().as_str(), rows.len()), ("figure", 1));
    assert!(d.join("CANARY").exists());

    // A run's params.json naming another program does not run without the flag either.
    let id = completed(&d.join("any")).into_iter().next().unwrap();
    let folder = d.join("any/runs").join(&id);
    std::fs::remove_file(folder.join("result.json")).unwrap();
    let one = Command::new("python3")
        .arg(sweep_script())
        .arg("--run-one")
        .arg(&folder)
        .env_remove("SWEEP_ALLOW_ANY_TOOL")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&one.stderr);
    assert_eq!(one.status.code(), Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("\"sh\""), "{err}");
    assert!(!folder.join("result.json").exists(), "it ran: {err}");
}

#[test]
fn an_existing_out_that_no_sweep_wrote_is_refused_unless_force() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("grid.json"), TWO_RUNS_GRID).unwrap();
    let mine = d.join("mine");
    std::fs::create_dir_all(mine.join("plots")).unwrap();
    let theirs = [
        ("results.csv", "precious\n"),
        ("joblog", "mine\n"),
        ("pending.txt", "mine\n"),
        ("notes.txt", "mine\n"),
        ("plots/ber.png", "mine\n"),
    ];
    for (name, text) in theirs {
        std::fs::write(mine.join(name), text).unwrap();
    }
    let untouched = |what: &str| {
        for (name, text) in theirs {
            assert_eq!(
                std::fs::read_to_string(mine.join(name)).unwrap(),
                text,
                "{what}: {name}"
            );
        }
    };
    let run = sweep(d, &["grid.json", "--out", "mine"]);
    let line = assert_one_line_refusal(&run, "a folder of someone else's files");
    assert!(line.contains("mine: "), "names the folder: {line}");
    assert!(
        line.contains("'joblog'"),
        "names a file it did not write: {line}"
    );
    assert!(line.contains("--force"), "{line}");
    untouched("refused");
    assert_eq!(
        names(&mine),
        ["joblog", "notes.txt", "pending.txt", "plots", "results.csv"]
            .map(String::from)
            .into(),
        "nothing added"
    );

    // --force writes into it: the sweep's names are replaced, the rest is left alone.
    let forced = sweep(d, &["grid.json", "--out", "mine", "--force"]);
    assert_contract(&forced, &[0], "--force");
    assert_eq!(csv_rows(&mine.join("results.csv")).1.len(), 2);
    assert_eq!(
        std::fs::read_to_string(mine.join("notes.txt")).unwrap(),
        "mine\n"
    );
    assert!(mine.join("sweep.json").exists());
    // A sweep's folder with a file no sweep writes is still refused, naming that file.
    let run = sweep(d, &["grid.json", "--out", "mine"]);
    let line = assert_one_line_refusal(&run, "a sweep's folder with notes.txt");
    assert!(line.contains("'notes.txt'"), "{line}");
    std::fs::remove_file(mine.join("notes.txt")).unwrap();
    let again = sweep(d, &["grid.json", "--out", "mine"]);
    assert_contract(&again, &[0], "the sweep's folder, resumed");
    assert!(
        again.stderr.contains("2 of 2 runs complete"),
        "{}",
        again.stderr
    );

    // An empty folder is taken as a new one.
    std::fs::create_dir(d.join("empty")).unwrap();
    let run = sweep(d, &["grid.json", "--out", "empty"]);
    assert_contract(&run, &[0], "an empty --out");
    assert_eq!(completed(&d.join("empty")).len(), 2);
}

/// Issue 48: GNU parallel wrote its joblog through a symbolic link `OUT/joblog` (a file
/// outside OUT overwritten), and the sweep wrote into linked `plots/` and `runs/`. A sweep
/// makes no link, so one under any name it writes or removes is refused, with --force or
/// without, naming it, before anything is written; nothing outside OUT changes.
#[test]
fn a_symbolic_link_where_the_sweep_writes_is_refused_even_with_force() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("grid.json"), TWO_RUNS_GRID).unwrap();
    let outside = d.join("outside");
    for folder in ["plots", "runs", "run"] {
        std::fs::create_dir_all(outside.join(folder)).unwrap();
        std::fs::write(outside.join(folder).join("kept"), "precious\n").unwrap();
    }
    for file in ["joblog", "results.csv", "ber.png"] {
        std::fs::write(outside.join(file), "precious\n").unwrap();
    }
    let before = tree(&outside);
    let refused = |out: &str, link: &str, args: &[&str]| {
        let mut all = vec!["grid.json", "--out", out];
        all.extend_from_slice(args);
        let run = sweep(d, &all);
        let line = assert_one_line_refusal(&run, &format!("{link} {args:?}"));
        assert!(
            line.contains(&format!("{out}/{link}: a symbolic link")),
            "names the link: {line}"
        );
        assert_eq!(tree(&outside), before, "{link} {args:?}: written through");
    };
    // In a folder of someone else's (with --force) and in a sweep's folder.
    for name in ["joblog", "plots", "runs", "results.csv"] {
        let mine = d.join("mine");
        std::fs::create_dir(&mine).unwrap();
        std::fs::write(mine.join("notes.txt"), "mine\n").unwrap();
        std::os::unix::fs::symlink(outside.join(name), mine.join(name)).unwrap();
        for args in [&["--force"][..], &[]] {
            refused("mine", name, args);
            assert_eq!(
                names(&mine),
                ["notes.txt", name].map(String::from).into(),
                "{name} {args:?}: something written"
            );
        }
        std::fs::remove_file(mine.join("notes.txt")).unwrap();
        std::fs::write(mine.join("sweep.json"), "{}\n").unwrap();
        refused("mine", name, &[]);
        std::fs::remove_dir_all(&mine).unwrap();
    }
    // A run's folder, or a plot, that is a link.
    let done = d.join("done");
    let first = sweep(d, &["grid.json", "--out", "done"]);
    assert_contract(&first, &[0], "a sweep's folder");
    let id = completed(&done).into_iter().next().unwrap();
    let run = done.join("runs").join(&id);
    std::fs::remove_dir_all(&run).unwrap();
    std::os::unix::fs::symlink(outside.join("run"), &run).unwrap();
    for args in [&["--force"][..], &[], &["--gather-only"]] {
        refused("done", &format!("runs/{id}"), args);
    }
    std::fs::remove_file(&run).unwrap();
    std::fs::create_dir_all(done.join("plots")).unwrap();
    let _ = std::fs::remove_file(done.join("plots/ber.png"));
    std::os::unix::fs::symlink(outside.join("ber.png"), done.join("plots/ber.png")).unwrap();
    refused("done", "plots/ber.png", &["--force"]);
    std::fs::remove_file(done.join("plots/ber.png")).unwrap();
    // Without the links, the same folder resumes: the removed run runs again.
    let again = sweep(d, &["grid.json", "--out", "done"]);
    assert_contract(&again, &[0], "resumed");
    assert_eq!(completed(&done).len(), 2);
    assert_eq!(tree(&outside), before);
}

#[test]
fn a_sweeps_folder_resumed_with_another_grid_reuses_the_shared_runs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out");
    let grid = |name: &str, args: &str| {
        let text = format!(r#"{{"tool":"tdma-run","args":{{"--sim":[null],{args}}}}}"#);
        std::fs::write(d.join(name), text).unwrap();
    };
    grid("a.json", r#""--duration":[10],"--ber":[0,0.0007]"#);
    grid("b.json", r#""--duration":[10],"--ber":[0,0.0007,0.001]"#);
    grid("c.json", r#""--duration":[10,20]"#);
    let first = sweep(d, &["a.json", "--out", "out"]);
    assert_contract(&first, &[0], "grid a");
    assert!(out.join("plots/ber.png").exists(), "{}", first.stderr);
    let a_runs = completed(&out);

    // b adds a BER: the two runs of a are reused, one runs.
    let second = sweep(d, &["b.json", "--out", "out"]);
    assert_contract(&second, &[0], "grid b in a's folder");
    assert!(second.stderr.contains("another grid"), "{}", second.stderr);
    assert_eq!(joblog_runs(&out).len(), 1, "only the new run");
    assert!(completed(&out).is_superset(&a_runs));
    assert_eq!(csv_rows(&out.join("results.csv")).1.len(), 3);
    let kept: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sweep.json")).unwrap()).unwrap();
    assert_eq!(kept["args"]["--ber"].as_array().unwrap().len(), 3, "{kept}");

    // c sweeps another parameter: its plots replace b's, all runs stay.
    let third = sweep(d, &["c.json", "--out", "out"]);
    assert_contract(&third, &[0], "grid c in the same folder");
    assert_eq!(csv_rows(&out.join("results.csv")).1.len(), 2);
    assert!(out.join("plots/duration.png").exists(), "{}", third.stderr);
    assert!(!out.join("plots/ber.png").exists(), "b's plot left");
    assert_eq!(run_ids(&out).len(), 5, "no run deleted");
    // sweep.json is itself a grid: the folder regathers from it.
    let regather = sweep(d, &["out/sweep.json", "--out", "out", "--gather-only"]);
    assert_contract(&regather, &[0], "--gather-only from sweep.json");
    assert!(
        !regather.stderr.contains("another grid"),
        "{}",
        regather.stderr
    );
}

#[test]
fn control_characters_in_paths_are_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let grid = r#"{"tool":"tdma-run","args":{"--sim":[null],"--duration":[10]}}"#;
    std::fs::write(d.join("grid.json"), grid).unwrap();
    std::fs::write(d.join("gr\tid.json"), grid).unwrap();
    let tools = tool_dir();
    let cases: &[(&[&str], &str, &str)] = &[
        (&["grid.json", "--out", "bad\nout"], "--out", "position 4"),
        (&["grid.json", "--out", "out\r"], "--out", "position 4"),
        (
            &["gr\tid.json", "--out", "out"],
            "grid's path",
            "position 3",
        ),
        (
            &["grid.json", "--out", "out", "--tool-dir", "to\u{7f}ols"],
            "--tool-dir",
            "position 3",
        ),
        (
            &["grid.json", "--out", "out", "--sshloginfile", "\u{1b}[1m"],
            "--sshloginfile",
            "position 1",
        ),
        (
            &["grid.json", "--out", "a/b\nc", "--tool-dir", &tools],
            "--out",
            "position 4",
        ),
    ];
    let before = names(d);
    for (args, names_what, at) in cases {
        let run = sweep_raw(d, args);
        let line = assert_one_line_refusal(&run, &format!("{args:?}"));
        assert!(line.contains(names_what), "{args:?}: {line}");
        assert!(line.contains(at), "{args:?}: {line}");
        assert!(line.contains("control character"), "{args:?}: {line}");
        assert_eq!(names(d), before, "{args:?}: wrote something");
    }
}

/// A `--metrics -` document: one line, the run's tool, seed and parameters, then figures.
fn metrics_line(stdout: &[u8], tool: &str) -> Value {
    let text = String::from_utf8(stdout.to_vec()).unwrap();
    assert_eq!(text.lines().count(), 1, "{text}");
    let doc: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(doc["tool"], tool);
    assert!(doc["params"].is_object(), "{doc}");
    assert!(doc.get("seed").is_some(), "{doc}");
    doc
}

#[test]
fn every_tool_with_figures_writes_one_line_with_its_parameters_and_seed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = |bin: &str, args: &[&str]| {
        let run = run_in(d, bin, args, b"", LIMIT);
        assert_contract(&run, &[0], &format!("{bin} {args:?}"));
        run
    };

    let out = run(
        TDMA_RUN,
        &[
            "--sim",
            "--duration",
            "60",
            "--seed",
            "7",
            "--ber",
            "7e-4",
            "--metrics",
            "-",
        ],
    );
    let doc = metrics_line(&out.stdout, "tdma-run");
    assert_eq!(
        (&doc["seed"], &doc["params"]["ber"]),
        (&Value::from(7), &Value::from(7e-4))
    );
    assert_eq!(
        (&doc["params"]["sim"], &doc["params"]["duration"]),
        (&Value::Bool(true), &Value::from(60))
    );
    assert!(
        doc["rov_to_operator"]["throughput_kbps"].is_number(),
        "{doc}"
    );
    let defaulted = run(TDMA_RUN, &["--sim", "--duration", "10", "--metrics", "-"]);
    assert_eq!(
        metrics_line(&defaulted.stdout, "tdma-run")["seed"],
        1,
        "the default seed"
    );

    std::fs::write(d.join("frames.bin"), b"").unwrap();
    let out = run(
        LINK_SIM,
        &[
            "--model",
            "s100",
            "--seed",
            "3",
            "frames.bin",
            "-o",
            "o.bin",
            "--metrics",
            "-",
        ],
    );
    let doc = metrics_line(&out.stdout, "link-sim");
    assert_eq!(
        (&doc["seed"], &doc["params"]["model"]),
        (&Value::from(3), &Value::from("s100"))
    );

    let out = run(
        MODEM_BENCH,
        &[
            "--sim",
            "s100",
            "--count",
            "20",
            "-o",
            "p.csv",
            "--metrics",
            "-",
        ],
    );
    let doc = metrics_line(&out.stdout, "modem-bench");
    assert_eq!(
        (&doc["count"], &doc["params"]["count"]),
        (&Value::from(20), &Value::from(20))
    );
    assert!(doc["seed"].is_u64(), "{doc}");

    std::fs::write(d.join("noise.bin"), crate::common::hostile::garbage(300, 5)).unwrap();
    let out = run(RCP_DUMP, &["noise.bin", "-o", "d.txt", "--metrics", "-"]);
    let doc = metrics_line(&out.stdout, "rcp-dump");
    assert_eq!(
        (&doc["seed"], &doc["bytes_in"]),
        (&Value::Null, &Value::from(300))
    );

    let picture = crate::common::testdata("kodim23-64x48.png");
    let picture = picture.to_str().unwrap();
    let out = run(
        DEBT_ENCODE,
        &[picture, "--bytes", "300", "-o", "s.debt", "--metrics", "-"],
    );
    let doc = metrics_line(&out.stdout, "debt-encode");
    assert_eq!(
        (&doc["bytes"], &doc["params"]["bytes"]),
        (&Value::from(300), &Value::from(300))
    );
    assert!(doc["psnr_rgb_db"].as_f64().unwrap() > 15.0, "{doc}");
    let out = run(
        DEBT_ENCODE,
        &[
            "--sweep",
            "200,400",
            picture,
            "--csv",
            "t.csv",
            "--metrics",
            "-",
        ],
    );
    let doc = metrics_line(&out.stdout, "debt-encode");
    assert_eq!(doc["trials"], 2);
    assert!(
        doc["budgets"]["400"]["psnr_rgb_db"].as_f64()
            > doc["budgets"]["200"]["psnr_rgb_db"].as_f64(),
        "{doc}"
    );

    let graph = crate::common::testdata("maps/spherical_scan.graph");
    let out = run(
        OCTO_DELTA,
        &[
            "build",
            graph.to_str().unwrap(),
            "--res",
            "0.5",
            "-o",
            "d.odl",
            "--quiet",
            "--link",
            "s100",
            "--metrics",
            "-",
        ],
    );
    let doc = metrics_line(&out.stdout, "octo-delta");
    assert_eq!(
        (&doc["params"]["subcommand"], &doc["params"]["res"]),
        (&Value::from("build"), &Value::from(0.5))
    );
    assert_eq!(doc["seed"], 1);
    assert!(doc["stream_bytes"].as_u64().unwrap() > 0, "{doc}");
    assert!(doc["link"]["latency_median_s"].is_number(), "{doc}");
}

#[test]
fn a_failed_run_leaves_no_result_and_the_sweep_says_so() {
    let dir = tempfile::tempdir().unwrap();
    // --ipg 0.5 ms is below tdma-run's range: every run fails with exit 2.
    let grid = r#"{"tool":"tdma-run","args":{"--sim":[null],"--duration":[10],"--ipg":[640,0.5]}}"#;
    std::fs::write(dir.path().join("grid.json"), grid).unwrap();
    let out: PathBuf = dir.path().join("out");
    let run = sweep(dir.path(), &["grid.json", "--out", "out", "--jobs", "2"]);
    assert_contract(&run, &[1], "a sweep with a failing run");
    assert_eq!(completed(&out).len(), 1);
    assert_eq!(csv_rows(&out.join("results.csv")).1.len(), 1);
    assert!(
        run.stderr.contains("1 runs did not complete"),
        "{}",
        run.stderr
    );
    let failed: Vec<String> = run_ids(&out)
        .difference(&completed(&out))
        .cloned()
        .collect();
    let stderr = std::fs::read_to_string(out.join("runs").join(&failed[0]).join("stderr")).unwrap();
    assert!(stderr.contains("--ipg"), "{stderr}");
}
