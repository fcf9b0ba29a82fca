//! `tdma-run --role rov --vehicle mavlink:...` against the real ArduSub: ArduPilot's ArduSub
//! built for SITL (`../shared/peers/ardusub/`, see its SOURCE.md), the operator's orders through
//! a FIFO, the acoustic link emulated by `link-sim --model s100 --pty`, the autopilot's own
//! reports read from its second MAVLink port (SERIAL1) by `tests/mavlink/sitl_watch.py`.
//!
//! SITL runs in real time and its EKF has a position only about 40 s after boot, so these tests
//! take about two minutes; the two sessions run side by side on SITL instances of their own
//! (numbers derived from the test's PID). SITL is killed by its PID whatever happens.
//!
//! The SITL directory: `ROVLINK_ARDUSUB_DIR`, else `CARGO_MANIFEST_DIR/../shared/peers/ardusub`,
//! else `/work/shared/peers/ardusub`; without one the tests fail, saying so. With
//! `ROVLINK_SITL_REPORT=FILE` the session writes its figures there as JSON
//! (`scripts/ardusub-sitl.sh` prints them).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crate::common::Reaped as Guard;
use serde_json::Value;

const TDMA_RUN: &str = env!("TOOL_EXE_tdma-run");

/// The bound on a wait for a sign that only a hang exceeds (SITL boots in a few seconds and
/// has its position at about 40 s of its own time).
const LIMIT: Duration = Duration::from_secs(150);

fn sitl_dir() -> PathBuf {
    let candidates: Vec<PathBuf> = std::env::var_os("ROVLINK_ARDUSUB_DIR")
        .map(PathBuf::from)
        .into_iter()
        .chain([
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/peers/ardusub"),
            PathBuf::from("/work/shared/peers/ardusub"),
        ])
        .collect();
    candidates
        .iter()
        .find(|dir| dir.join("run-sitl.sh").is_file() && dir.join("ardusub").is_file())
        .cloned()
        .unwrap_or_else(|| {
            panic!(
                "no ArduSub SITL: none of {candidates:?} holds run-sitl.sh and ardusub \
                 (set ROVLINK_ARDUSUB_DIR to the prebuilt SITL's directory)"
            )
        })
}

fn wall_s() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

/// An ArduSub SITL started by `run-sitl.sh`, killed by its PID when dropped.
struct Sitl {
    pid: i32,
    instance: u32,
}

impl Sitl {
    /// Starts SITL in `work` on the first free instance from `first` on (every second number:
    /// the other test takes the others), with `extra` arguments for ardusub.
    fn start(work: &Path, first: u32, extra: &[String]) -> Sitl {
        let dir = sitl_dir();
        let mut said = String::new();
        for instance in (first..first + 20).step_by(2) {
            let out = Command::new(dir.join("run-sitl.sh"))
                .args(extra)
                .env("INSTANCE", instance.to_string())
                .env("SITL_DIR", work.join(format!("sitl-{instance}")))
                .stdin(Stdio::null())
                .output()
                .expect("run-sitl.sh runs");
            let stdout = String::from_utf8_lossy(&out.stdout);
            let stderr = String::from_utf8_lossy(&out.stderr);
            if out.status.success() {
                let pid = stdout.lines().last().and_then(|l| l.trim().parse().ok());
                let pid = pid.unwrap_or_else(|| panic!("run-sitl.sh gave no PID: {stdout}"));
                return Sitl { pid, instance };
            }
            if !stderr.contains("already in use") {
                panic!("run-sitl.sh failed ({}): {stderr}", out.status);
            }
            said.push_str(&stderr);
        }
        panic!("no free SITL instance: {said}");
    }

    fn port(&self, serial: u32) -> u32 {
        5760 + 10 * self.instance + serial
    }
}

impl Drop for Sitl {
    fn drop(&mut self) {
        use nix::sys::signal::{Signal, kill};
        use nix::unistd::Pid;
        let pid = Pid::from_raw(self.pid);
        let _ = kill(pid, Signal::SIGTERM);
        let until = Instant::now() + Duration::from_secs(5);
        while kill(pid, None).is_ok() && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = kill(pid, Signal::SIGKILL);
    }
}

/// The JSON lines of `path` so far (a line being written is left for the next read).
fn lines(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// Polls `sign` every 100 ms until it gives a value; fails after `limit` with `what` and
/// `context()`.
fn wait_for<T>(
    what: &str,
    limit: Duration,
    mut sign: impl FnMut() -> Option<T>,
    context: impl Fn() -> String,
) -> T {
    let until = Instant::now() + limit;
    loop {
        if let Some(value) = sign() {
            return value;
        }
        assert!(
            Instant::now() < until,
            "{what}: not within {limit:?}\n{}",
            context()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A session: SITL, its watcher, link-sim, the ROV end and the operator end with a FIFO for
/// orders. Everything stops when it is dropped.
struct Session {
    dir: tempfile::TempDir,
    fifo: Option<std::fs::File>,
    operator: Guard,
    rov: Guard,
    _link: Guard,
    _watch: Guard,
    /// When the operator started (its telemetry's t_s counts from there), wall s.
    operator_t0: f64,
    sitl: Sitl,
}

impl Session {
    fn start(first_instance: u32, extra_parameters: Option<&str>) -> Session {
        let dir = tempfile::tempdir().unwrap();
        let mut extra = Vec::new();
        if let Some(parameters) = extra_parameters {
            let file = dir.path().join("extra.parm");
            std::fs::write(&file, parameters).unwrap();
            let defaults = sitl_dir().join("sub.parm");
            extra = vec![
                "--defaults".to_string(),
                format!("{},{}", defaults.display(), file.display()),
            ];
        }
        let sitl = Sitl::start(dir.path(), first_instance, &extra);
        let path = |name: &str| dir.path().join(name);
        let watch = Guard(
            Command::new("python3")
                .arg(concat!(
                    env!("CARGO_MANIFEST_DIR"),
                    "/tests/mavlink/sitl_watch.py"
                ))
                .args(["--connect", &format!("tcp:127.0.0.1:{}", sitl.port(2))])
                .arg("--out")
                .arg(path("watch.jsonl"))
                .stdout(Stdio::null())
                .spawn()
                .expect("python3 runs"),
        );
        let (link, a, b) = crate::common::link_sim_pty(&crate::common::TEST_S100);
        let mut rov = Command::new(TDMA_RUN)
            .args(["--role", "rov", "--port", &b, "--duration", "600"])
            .args([
                "--vehicle",
                &format!("mavlink:tcpout:127.0.0.1:{}", sitl.port(0)),
            ])
            .args(["--image-size", "400"])
            .arg("--metrics")
            .arg(path("rov.json"))
            .arg("--telemetry")
            .arg(path("rov.jsonl"))
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stderr = rov.stderr.take().unwrap();
        let rov = Guard(rov);
        let (tx, rx) = std::sync::mpsc::channel();
        let rov_log = path("rov.err");
        std::thread::spawn(move || {
            use std::io::BufRead;
            let mut log = std::fs::File::create(rov_log).unwrap();
            for line in std::io::BufReader::new(stderr)
                .lines()
                .map_while(Result::ok)
            {
                let _ = writeln!(log, "{line}");
                if line.contains("ROV: answering every slot") {
                    let _ = tx.send(());
                }
            }
        });
        assert!(
            rx.recv_timeout(Duration::from_secs(30)).is_ok(),
            "the ROV end never answered"
        );
        nix::unistd::mkfifo(&path("orders"), nix::sys::stat::Mode::S_IRWXU).unwrap();
        let mut operator = Command::new(TDMA_RUN)
            .args(["--role", "operator", "--port", &a, "--duration", "600"])
            .args(["--image-size", "400"])
            .arg("--orders")
            .arg(path("orders"))
            .arg("--telemetry")
            .arg(path("op.jsonl"))
            .arg("--metrics")
            .arg(path("op.json"))
            .stderr(std::fs::File::create(path("op.err")).unwrap())
            .spawn()
            .unwrap();
        let fifo = crate::common::fifo_writer(path("orders"), &mut operator, LIMIT);
        // The operator's clock: its telemetry's t_s against the wall clock, from the line
        // that appears first (read every 20 ms, so within a few tens of milliseconds).
        let until = Instant::now() + LIMIT;
        let operator_t0 = loop {
            if let Some(t_s) = lines(&path("op.jsonl"))
                .last()
                .and_then(|l| l["t_s"].as_f64())
            {
                break wall_s() - t_s;
            }
            assert!(Instant::now() < until, "the operator wrote no telemetry");
            std::thread::sleep(Duration::from_millis(20));
        };
        Session {
            dir,
            fifo: Some(fifo),
            operator: Guard(operator),
            rov,
            _link: link,
            _watch: watch,
            operator_t0,
            sitl,
        }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    fn order(&mut self, line: &str) {
        let fifo = self.fifo.as_mut().unwrap();
        writeln!(fifo, "{line}").unwrap();
        fifo.flush().unwrap();
    }

    fn watched(&self, kind: &str) -> Vec<Value> {
        lines(&self.path("watch.jsonl"))
            .into_iter()
            .filter(|l| l["type"] == kind)
            .collect()
    }

    /// The operator's statuses: (wall s, the status line).
    fn statuses(&self) -> Vec<(f64, Value)> {
        lines(&self.path("op.jsonl"))
            .into_iter()
            .filter(|l| l["type"] == "rov")
            .map(|l| (self.operator_t0 + l["t_s"].as_f64().unwrap(), l))
            .collect()
    }

    /// What went on, for a failure's message.
    fn story(&self) -> String {
        let tail = |name: &str, n: usize| {
            let text = std::fs::read_to_string(self.path(name)).unwrap_or_default();
            let all: Vec<&str> = text.lines().collect();
            all[all.len().saturating_sub(n)..].join("\n")
        };
        format!(
            "SITL instance {} pid {}\n-- autopilot modes and texts:\n{}\n-- ROV stderr:\n{}\n-- ROV telemetry:\n{}\n-- operator stderr:\n{}\n-- operator's last statuses:\n{}",
            self.sitl.instance,
            self.sitl.pid,
            self.watched("mode")
                .iter()
                .chain(self.watched("text").iter())
                .map(Value::to_string)
                .collect::<Vec<_>>()
                .join("\n"),
            tail("rov.err", 20),
            tail("rov.jsonl", 30),
            tail("op.err", 10),
            self.statuses()
                .iter()
                .rev()
                .take(3)
                .map(|(_, s)| s.to_string())
                .collect::<Vec<_>>()
                .join("\n"),
        )
    }

    /// Ends both tdma-run ends with SIGTERM (they write their metrics) and returns them.
    fn finish(mut self) -> (Value, Value) {
        use nix::sys::signal::{Signal, kill};
        use nix::unistd::Pid;
        drop(self.fifo.take());
        for child in [&mut self.operator.0, &mut self.rov.0] {
            let _ = kill(Pid::from_raw(child.id() as i32), Signal::SIGTERM);
            crate::common::wait_for_exit(child, Duration::from_secs(30));
        }
        let read = |name: &str| -> Value {
            let text = std::fs::read_to_string(self.path(name))
                .unwrap_or_else(|e| panic!("{name}: {e}\n{}", self.story()));
            serde_json::from_str(&text).unwrap()
        };
        (read("op.json"), read("rov.json"))
    }
}

fn velocity(vx: i8, nav: &str) -> String {
    format!(
        r#"{{"type":"velocity","vx":{vx},"vy":0,"vz":0,"vyaw":0,"arm":true,"disarm":false,"nav":"{nav}"}}"#
    )
}

fn xyz(line: &Value) -> [f64; 3] {
    ["x", "y", "z"].map(|k| line[k].as_f64().unwrap())
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

/// The SITL instances of this test process: two neighbours from its PID, unlikely to be
/// another run's.
fn first_instance() -> u32 {
    20 + (std::process::id() % 30) * 2
}

#[test]
fn a_goto_on_the_real_ardusub_is_reached_and_held_and_the_pose_is_the_autopilots() {
    let started = Instant::now();
    let mut s = Session::start(first_instance(), None);
    let target = [3.0, 1.0, 1.0];
    // Arm in stabilize, sticks neutral: armed, in ALT_HOLD (stick modes hold depth).
    s.order(&velocity(0, "stabilize"));
    let armed_at = wait_for(
        "armed",
        LIMIT,
        || {
            s.watched("mode")
                .iter()
                .find(|m| m["armed"] == true)
                .map(|m| m["t"].as_f64().unwrap())
        },
        || s.story(),
    );
    // Half forward stick for 14 s: it moves along its heading (SITL's own truth, SIMSTATE,
    // since the EKF may have no position yet).
    s.order(&velocity(64, "stabilize"));
    let stick_from = wall_s();
    std::thread::sleep(Duration::from_secs(14));
    s.order(&velocity(0, "stabilize"));
    let stick_to = wall_s();
    let sims = s.watched("sim");
    let at = |t: f64| {
        sims.iter()
            .rfind(|l| l["t"].as_f64().unwrap() <= t)
            .unwrap_or_else(|| panic!("no SIMSTATE before {t}\n{}", s.story()))
            .clone()
    };
    // From 3 s in (the vehicle has come up to speed) to the end of the stick.
    let (from, to) = (at(stick_from + 3.0), at(stick_to));
    let moved = [
        to["n"].as_f64().unwrap() - from["n"].as_f64().unwrap(),
        to["e"].as_f64().unwrap() - from["e"].as_f64().unwrap(),
    ];
    // The heading from ATTITUDE (SIMSTATE's yaw is not in the unit its definition says): its
    // mean over the same stretch (the vehicle may turn a little while it goes), as the mean of
    // the unit vectors.
    let (from_t, to_t) = (from["t"].as_f64().unwrap(), to["t"].as_f64().unwrap());
    let (sum_cos, sum_sin) = s
        .watched("att")
        .iter()
        .filter(|l| (from_t..=to_t).contains(&l["t"].as_f64().unwrap()))
        .map(|l| l["yaw_deg"].as_f64().unwrap().to_radians())
        .fold((0.0, 0.0), |(c, n), yaw| (c + yaw.cos(), n + yaw.sin()));
    assert!(
        sum_cos != 0.0 || sum_sin != 0.0,
        "no ATTITUDE while the stick was held\n{}",
        s.story()
    );
    let heading = sum_sin.atan2(sum_cos);
    let along = moved[0] * heading.cos() + moved[1] * heading.sin();
    let across = -moved[0] * heading.sin() + moved[1] * heading.cos();
    let dt_s = to["t"].as_f64().unwrap() - from["t"].as_f64().unwrap();
    let forward_mps = along / dt_s;
    // Within 35 degrees of the heading: before the EKF has a GPS position it knows no
    // magnetic declination (about 12 degrees east at SITL's home near Los Angeles), so
    // ATTITUDE's heading and SITL's true track differ by about that much, and more while the
    // yaw estimate settles (3-13 degrees seen, once 29.5 on a loaded machine). Sideways or
    // backwards (90 degrees and more) still fails.
    assert!(
        along > 1.0 && across.abs() < 35f64.to_radians().tan() * along,
        "the forward stick moved it {moved:?} m (along its heading {along:.2}, across {across:.2})\n{}",
        s.story()
    );
    // The GoTo once the ROV has a position (the status no longer says NP): before that it
    // would be refused at once (the other test).
    let position_at = wait_for(
        "a position in the operator's status",
        LIMIT,
        || {
            s.statuses()
                .last()
                .filter(|(_, st)| st["position_known"] != false)
                .map(|(t, _)| *t)
        },
        || s.story(),
    );
    s.order(r#"{"type":"goto","x_cm":300,"y_cm":100,"z_cm":100,"heading_deg":0}"#);
    let goto_at = wall_s();
    let error_at = |p: &Value| distance(xyz(p), target);
    // Reached: within the ROV's own arrival bound, 0.3 m (depth included), from which on it
    // holds; then held within 0.5 m for 15 s.
    let arrived_at = wait_for(
        "the GoTo reached within 0.3 m",
        LIMIT,
        || {
            s.watched("pos")
                .iter()
                .find(|p| p["t"].as_f64().unwrap() > goto_at && error_at(p) <= 0.3)
                .map(|p| p["t"].as_f64().unwrap())
        },
        || s.story(),
    );
    let hold_to = arrived_at + 15.0;
    wait_for(
        "15 s of positions after the GoTo was reached",
        LIMIT,
        || {
            s.watched("pos")
                .last()
                .filter(|p| p["t"].as_f64().unwrap() >= hold_to)
                .map(|_| ())
        },
        || s.story(),
    );
    let positions = s.watched("pos");
    let held: Vec<&Value> = positions
        .iter()
        .filter(|p| (arrived_at..=hold_to).contains(&p["t"].as_f64().unwrap()))
        .collect();
    let hold_error_m = held.iter().map(|p| error_at(p)).fold(0.0, f64::max);
    let within_05_at = positions
        .iter()
        .find(|p| p["t"].as_f64().unwrap() > goto_at && error_at(p) <= 0.5)
        .map_or(arrived_at, |p| p["t"].as_f64().unwrap());
    let final_error_m = positions.last().map(error_at);
    // The operator's pose against the autopilot's at the same time, over the hold (the
    // vehicle nearly still: a status is up to a slot and the link's delay old).
    let statuses = s.statuses();
    let pose_errors: Vec<f64> = statuses
        .iter()
        .filter(|(t, _)| (arrived_at + 3.0..=hold_to).contains(t))
        .filter_map(|(t, st)| {
            let theirs = positions.iter().rfind(|p| p["t"].as_f64().unwrap() <= *t)?;
            let ours = ["x_cm", "y_cm", "z_cm"].map(|k| st[k].as_f64().unwrap() / 100.0);
            Some(distance(ours, xyz(theirs)))
        })
        .collect();
    let pose_error_m = pose_errors.iter().copied().fold(0.0, f64::max);
    let last_status = statuses.last().map(|(_, st)| st.clone()).unwrap();
    let modes: Vec<Value> = s.watched("mode");
    let figures = serde_json::json!({
        "sitl_instance": s.sitl.instance,
        "mode_timeline": modes.iter().map(|m| serde_json::json!({
            "t_s": (m["t"].as_f64().unwrap() - s.operator_t0),
            "armed": m["armed"], "mode": m["mode"]})).collect::<Vec<_>>(),
        "armed_after_operator_start_s": armed_at - s.operator_t0,
        "forward_speed_mps": forward_mps,
        "forward_moved_m": [along, across],
        "position_after_operator_start_s": position_at - s.operator_t0,
        "goto_to_within_0_5_m_s": within_05_at - goto_at,
        "goto_to_within_0_3_m_s": arrived_at - goto_at,
        "goto_distance_m": positions.iter().rfind(|p| p["t"].as_f64().unwrap() <= goto_at).map(error_at),
        "hold_error_max_m": hold_error_m,
        "hold_samples": held.len(),
        "final_error_m": final_error_m,
        "pose_error_max_m": pose_error_m,
        "pose_samples": pose_errors.len(),
        "last_status": last_status,
        "test_s": started.elapsed().as_secs_f64(),
    });
    eprintln!("SITL session: {figures:#}");
    if let Some(report) = std::env::var_os("ROVLINK_SITL_REPORT") {
        std::fs::write(report, format!("{figures:#}\n")).unwrap();
    }
    assert!(
        modes.iter().any(|m| m["mode"] == 2) && modes.iter().any(|m| m["mode"] == 4),
        "ALT_HOLD (2) for the sticks and GUIDED (4) for the GoTo: {modes:?}"
    );
    assert!(
        hold_error_m <= 0.5 && held.len() >= 10,
        "held within {hold_error_m:.2} m ({} samples)\n{}",
        held.len(),
        s.story()
    );
    assert!(
        pose_errors.len() >= 5 && pose_error_m <= 0.3,
        "the operator's pose {pose_error_m:.2} m from the autopilot's ({} statuses)\n{}",
        pose_errors.len(),
        s.story()
    );
    // Still held when the session ends: GUIDED, armed, no order in execution.
    assert_eq!(last_status["nav"], "guided", "{last_status}");
    assert_eq!(last_status["arm"], true, "{last_status}");
    assert_eq!(last_status["rd"], true, "{last_status}");
    let s_rov_telemetry = s.path("rov.jsonl");
    let keep = tempfile::tempdir().unwrap();
    std::fs::copy(&s_rov_telemetry, keep.path().join("rov.jsonl")).unwrap();
    let s_rov_telemetry = keep.path().join("rov.jsonl");
    let (op, rov) = s.finish();
    assert_eq!(rov["orders_executed"], 1, "{rov}");
    assert_eq!(op["orders_acknowledged"], 1, "{op}");
    // Refusals there may be (SITL refuses ALT_HOLD for its first moments, "need alt
    // estimate", and arming in its first second), but none of a GoTo.
    let refusals: Vec<Value> = lines(&s_rov_telemetry)
        .into_iter()
        .filter(|l| l["state"] == "refused")
        .collect();
    assert!(
        refusals
            .iter()
            .all(|l| l["why"] == "mode_refused" || l["why"] == "arm_refused"),
        "{refusals:?}"
    );
}

#[test]
fn without_a_position_source_a_goto_is_refused_at_once_and_the_sticks_still_work() {
    let mut s = Session::start(first_instance() + 1, Some("GPS1_TYPE 0\n"));
    s.order(&velocity(0, "stabilize"));
    wait_for(
        "armed",
        LIMIT,
        || {
            s.watched("mode")
                .iter()
                .find(|m| m["armed"] == true)
                .map(|_| ())
        },
        || s.story(),
    );
    // Past the time a GPS gives SITL a position (about 40 s after boot): still none.
    wait_for(
        "50 s of SITL's time",
        LIMIT,
        || {
            s.watched("boot")
                .last()
                .filter(|b| b["boot_s"].as_f64().unwrap() >= 50.0)
                .map(|_| ())
        },
        || s.story(),
    );
    assert!(
        s.watched("pos").is_empty(),
        "LOCAL_POSITION_NED without GPS"
    );
    // The sticks work: half forward for 4 s moves it (SITL's truth).
    let before = s.watched("sim").last().cloned().unwrap();
    s.order(&velocity(64, "stabilize"));
    std::thread::sleep(Duration::from_secs(4));
    s.order(&velocity(0, "stabilize"));
    let after = wait_for(
        "a SIMSTATE after the stick",
        LIMIT,
        || {
            s.watched("sim")
                .last()
                .filter(|l| l["t"].as_f64().unwrap() > before["t"].as_f64().unwrap() + 4.0)
                .cloned()
        },
        || s.story(),
    );
    let moved = (after["n"].as_f64().unwrap() - before["n"].as_f64().unwrap())
        .hypot(after["e"].as_f64().unwrap() - before["e"].as_f64().unwrap());
    assert!(moved > 0.5, "moved {moved} m\n{}", s.story());
    // The GoTo: refused at once, with the reason, in the operator's status.
    s.order(r#"{"type":"goto","x_cm":300,"y_cm":100,"z_cm":100,"heading_deg":0}"#);
    // Only a GoTo (or backtracking) makes the ROV say no_position.
    let refused = wait_for(
        "a status saying why the GoTo cannot run",
        LIMIT,
        || {
            s.statuses()
                .into_iter()
                .find(|(_, st)| st["why"] == "no_position")
        },
        || s.story(),
    );
    let status = &refused.1;
    assert_eq!(status["st"], 1, "{status}");
    assert_eq!(status["position_known"], false, "{status}");
    assert_eq!(status["rd"], true, "nothing is left pending: {status}");
    assert_eq!(status["arm"], true, "{status}");
    assert_eq!(status["nav"], "depth_hold", "{status}");
    assert!(
        ["x_cm", "y_cm", "z_cm"].iter().all(|k| status[k] == 0),
        "{status}"
    );
    let rov_said = lines(&s.path("rov.jsonl"));
    assert!(
        rov_said.iter().any(|l| l["state"] == "refused"
            && l["why"] == "no_position"
            && l["reason"]
                .as_str()
                .unwrap()
                .contains("no position estimate")),
        "{}",
        s.story()
    );
    assert!(
        s.watched("mode").iter().all(|m| m["mode"] != 4),
        "GUIDED was never asked for\n{}",
        s.story()
    );
    let (op, rov) = s.finish();
    assert_eq!(op["orders_acknowledged"], 1, "{op}");
    assert_eq!(rov["orders_executed"], 0, "{rov}");
    assert!(rov["refusals"].as_u64().unwrap() >= 1, "{rov}");
    assert!(op["refusals"].as_u64().unwrap() >= 1, "{op}");
    assert!(
        op["statuses_without_position"].as_u64().unwrap() > 10,
        "{op}"
    );
}
