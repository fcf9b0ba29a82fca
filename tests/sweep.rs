//! `--metrics` of every tool that produces figures, and `scripts/sweep` over GNU parallel and
//! Slurm: the issue's 20-run grid, resuming after deleted folders and after a signal, the job
//! array script, bad grids. Needs python3 and GNU parallel (installed by .ci/run), and
//! matplotlib for the plots.

mod common;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use common::hostile::{assert_contract, run_in, run_signalled};
use nix::sys::signal::Signal;
use serde_json::Value;

const TDMA_RUN: &str = env!("CARGO_BIN_EXE_tdma-run");
const LINK_SIM: &str = env!("CARGO_BIN_EXE_link-sim");
const MODEM_BENCH: &str = env!("CARGO_BIN_EXE_modem-bench");
const RCP_DUMP: &str = env!("CARGO_BIN_EXE_rcp-dump");
const DEBT_ENCODE: &str = env!("CARGO_BIN_EXE_debt-encode");
const OCTO_DELTA: &str = env!("CARGO_BIN_EXE_octo-delta");
const LIMIT: Duration = Duration::from_secs(120);

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

fn sweep(dir: &Path, args: &[&str]) -> common::hostile::Run {
    let all = sweep_argv(args);
    let all: Vec<&str> = all.iter().map(String::as_str).collect();
    run_in(dir, "python3", &all, b"", LIMIT)
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

#[test]
fn a_signal_keeps_what_completed_and_the_next_sweep_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let grid = r#"{"tool":"tdma-run","args":{"--sim":[null],"--duration":[1800]},"seeds":3}"#;
    std::fs::write(dir.path().join("grid.json"), grid).unwrap();
    let out = dir.path().join("out");
    let args = sweep_argv(&["grid.json", "--out", "out", "--jobs", "1"]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let stopped = run_signalled(
        dir.path(),
        "python3",
        &args,
        Duration::from_millis(1500),
        Signal::SIGTERM,
        LIMIT,
    );
    assert_contract(&stopped, &[143], "SIGTERM mid-sweep");
    let done = completed(&out);
    assert!(done.len() < 3, "stopped before the end");
    let resumed = sweep(dir.path(), &["grid.json", "--out", "out", "--jobs", "2"]);
    assert_contract(&resumed, &[0], "resumed sweep");
    assert_eq!(completed(&out).len(), 3);
    assert_eq!(
        joblog_runs(&out).len(),
        3 - done.len(),
        "only what was missing"
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
        ("g.json", r#"{"tool":"../tdma-run"}"#, &[]),
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
        let out = format!("out{k}");
        let mut args = vec![*name, "--out", &out];
        args.extend_from_slice(extra);
        let run = sweep(dir.path(), &args);
        assert_contract(&run, &[2], &format!("{grid} {extra:?}"));
        let line = run.stderr.trim_end();
        assert!(
            line.starts_with("sweep: ") && !line.contains('\n') && !line.contains("Traceback"),
            "{grid}: {line}"
        );
        assert!(
            !dir.path().join(&out).join("results.csv").exists(),
            "{grid}: gathered"
        );
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

    std::fs::write(d.join("noise.bin"), common::hostile::garbage(300, 5)).unwrap();
    let out = run(RCP_DUMP, &["noise.bin", "-o", "d.txt", "--metrics", "-"]);
    let doc = metrics_line(&out.stdout, "rcp-dump");
    assert_eq!(
        (&doc["seed"], &doc["bytes_in"]),
        (&Value::Null, &Value::from(300))
    );

    let picture = common::testdata("kodim23-64x48.png");
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

    let graph = common::testdata("maps/spherical_scan.graph");
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
