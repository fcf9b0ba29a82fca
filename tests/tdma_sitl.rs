//! `tdma-run --role rov --vehicle mavlink:...` against the real ArduSub: ArduPilot's ArduSub
//! built for SITL (`../shared/peers/ardusub/`, see its SOURCE.md), the operator's orders through
//! a FIFO, the acoustic link emulated by `link-sim --model s100 --pty`, the autopilot's own
//! reports read from its second MAVLink port (SERIAL1) by `tests/mavlink/sitl_watch.py`.
//!
//! A third session is signed: the key goes into SITL with `scripts/mavlink-setup-signing.py`
//! over SERIAL0 (the port ArduPilot trusts unsigned, its USB), the ROV end talks to SERIAL1
//! over UDP (`--serial1 udpclient:...` to its `udpin:`) with `--mavlink-key-file`, the watcher
//! listens on SERIAL0, and an attacker without the key speaks on SERIAL2 and to the ROV end's
//! UDP port.
//!
//! SITL runs in real time and its EKF has a position only about 40 s after boot, so these tests
//! take about two minutes; the sessions run side by side on SITL instances of their own
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

/// A signed session's setup: the key file, and the UDP port the ROV end listens on
/// (`udpin:`) for SITL's SERIAL1 (`--serial1 udpclient:127.0.0.1:PORT`).
struct Signed {
    key: PathBuf,
    udp_port: u16,
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
    /// A signed session's UDP port, where the ROV end listens for SITL.
    udp_port: Option<u16>,
}

impl Session {
    fn start(first_instance: u32, extra_parameters: Option<&str>) -> Session {
        Session::start_with(first_instance, extra_parameters, false)
    }

    /// A session as [`Session::start`]; `signed`: the ROV end talks to SITL's SERIAL1 over
    /// UDP (`udpin:`), signed with a key loaded into SITL first with
    /// `scripts/mavlink-setup-signing.py` over SERIAL0, where the watcher then listens.
    fn start_with(first_instance: u32, extra_parameters: Option<&str>, signed: bool) -> Session {
        let dir = tempfile::tempdir().unwrap();
        let signed = signed.then(|| Signed {
            key: crate::tdma_mavlink::key_file(
                dir.path(),
                std::array::from_fn(|k| (k as u8) ^ (std::process::id() as u8)),
            ),
            udp_port: crate::tdma_mavlink::free_udp_port(),
        });
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
        if let Some(signed) = &signed {
            extra.push("--serial1".to_string());
            extra.push(format!("udpclient:127.0.0.1:{}", signed.udp_port));
        }
        let sitl = Sitl::start(dir.path(), first_instance, &extra);
        let path = |name: &str| dir.path().join(name);
        // The key goes in over SERIAL0 (SITL's USB, the link ArduPilot trusts unsigned), as
        // before a dive over the tether; the script waits for a HEARTBEAT signed with it.
        let mut watch_port = sitl.port(2);
        if let Some(signed) = &signed {
            let out = Command::new("python3")
                .arg(concat!(
                    env!("CARGO_MANIFEST_DIR"),
                    "/scripts/mavlink-setup-signing.py"
                ))
                .args(["--connect", &format!("tcp:127.0.0.1:{}", sitl.port(0))])
                .arg("--key-file")
                .arg(&signed.key)
                .args(["--timeout", "60"])
                .stdin(Stdio::null())
                .output()
                .expect("python3 runs");
            let said = String::from_utf8_lossy(&out.stderr);
            assert!(out.status.success(), "mavlink-setup-signing.py: {said}");
            eprintln!("{}", said.trim());
            watch_port = sitl.port(0);
        }
        let watch = Guard(
            Command::new("python3")
                .arg(concat!(
                    env!("CARGO_MANIFEST_DIR"),
                    "/tests/mavlink/sitl_watch.py"
                ))
                .args(["--connect", &format!("tcp:127.0.0.1:{watch_port}")])
                .arg("--out")
                .arg(path("watch.jsonl"))
                .stdout(Stdio::null())
                .spawn()
                .expect("python3 runs"),
        );
        let (link, a, b) = crate::common::link_sim_pty(&crate::common::TEST_S100);
        let mut rov = Command::new(TDMA_RUN);
        rov.args(["--role", "rov", "--port", &b, "--duration", "600"]);
        match &signed {
            Some(signed) => rov
                .args([
                    "--vehicle",
                    &format!("mavlink:udpin:127.0.0.1:{}", signed.udp_port),
                ])
                .arg("--mavlink-key-file")
                .arg(&signed.key),
            None => rov.args([
                "--vehicle",
                &format!("mavlink:tcpout:127.0.0.1:{}", sitl.port(0)),
            ]),
        };
        let mut rov = rov
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
            udp_port: signed.as_ref().map(|s| s.udp_port),
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

    /// Arms in stabilize with neutral sticks; returns when SITL reported it armed (wall s).
    fn arm(&mut self) -> f64 {
        self.order(&velocity(0, "stabilize"));
        wait_for(
            "armed",
            LIMIT,
            || {
                self.watched("mode")
                    .iter()
                    .find(|m| m["armed"] == true)
                    .map(|m| m["t"].as_f64().unwrap())
            },
            || self.story(),
        )
    }

    /// Waits until the operator's status has a position (no longer NP); returns when (wall s).
    fn position_known(&self) -> f64 {
        wait_for(
            "a position in the operator's status",
            LIMIT,
            || {
                self.statuses()
                    .last()
                    .filter(|(_, st)| st["position_known"] != false)
                    .map(|(t, _)| *t)
            },
            || self.story(),
        )
    }

    /// Sends the GoTo to [`GOTO_TARGET`] and waits until SITL's LOCAL_POSITION_NED is within
    /// 0.3 m of it (the ROV's arrival bound); returns when it was sent and when reached (wall
    /// s).
    fn goto_reached(&mut self) -> (f64, f64) {
        self.order(r#"{"type":"goto","x_cm":300,"y_cm":100,"z_cm":100,"heading_deg":0}"#);
        let goto_at = wall_s();
        let arrived_at = wait_for(
            "the GoTo reached within 0.3 m",
            LIMIT,
            || {
                self.watched("pos")
                    .iter()
                    .find(|p| {
                        p["t"].as_f64().unwrap() > goto_at && distance(xyz(p), GOTO_TARGET) <= 0.3
                    })
                    .map(|p| p["t"].as_f64().unwrap())
            },
            || self.story(),
        );
        (goto_at, arrived_at)
    }

    /// Half a stick forward for `seconds`, then neutral: how far SITL's truth (SIMSTATE) says
    /// the vehicle went, m.
    fn half_stick_moves(&mut self, seconds: u64) -> f64 {
        let before = self.watched("sim").last().cloned().unwrap();
        self.order(&velocity(64, "stabilize"));
        std::thread::sleep(Duration::from_secs(seconds));
        self.order(&velocity(0, "stabilize"));
        let after = wait_for(
            "a SIMSTATE after the stick",
            LIMIT,
            || {
                self.watched("sim")
                    .last()
                    .filter(|l| {
                        l["t"].as_f64().unwrap() > before["t"].as_f64().unwrap() + seconds as f64
                    })
                    .cloned()
            },
            || self.story(),
        );
        (after["n"].as_f64().unwrap() - before["n"].as_f64().unwrap())
            .hypot(after["e"].as_f64().unwrap() - before["e"].as_f64().unwrap())
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

/// The GoTo of the sessions, NED m.
const GOTO_TARGET: [f64; 3] = [3.0, 1.0, 1.0];

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
    let target = GOTO_TARGET;
    // Arm in stabilize, sticks neutral: armed, in ALT_HOLD (stick modes hold depth).
    let armed_at = s.arm();
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
    let position_at = s.position_known();
    // Reached: within the ROV's own arrival bound, 0.3 m (depth included), from which on it
    // holds; then held within 0.5 m for 15 s.
    let (goto_at, arrived_at) = s.goto_reached();
    let error_at = |p: &Value| distance(xyz(p), target);
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
    s.arm();
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
    let moved = s.half_stick_moves(4);
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

/// What a spoofer heard on its own connection to SITL: the COMMAND_ACKs (answers to its own
/// commands), by command id, and how many messages came at all.
#[derive(Default)]
struct Heard {
    acks: Vec<u32>,
    messages: u64,
}

/// A spoofer on SITL's SERIAL2 (TCP), speaking as the GCS (system 255 component 190) without
/// the key; what SITL sends it is read aside into `heard`.
struct Spoofer {
    stream: std::net::TcpStream,
    heard: std::sync::Arc<std::sync::Mutex<Heard>>,
    sequence: u8,
}

impl Spoofer {
    fn connect(port: u32) -> Spoofer {
        use mavlink::dialects::ardupilotmega::MavMessage;
        let stream = std::net::TcpStream::connect(("127.0.0.1", port as u16)).unwrap();
        let heard = std::sync::Arc::new(std::sync::Mutex::new(Heard::default()));
        let (reading, into) = (stream.try_clone().unwrap(), std::sync::Arc::clone(&heard));
        std::thread::spawn(move || {
            let mut reader = mavlink::MavlinkReader::new(reading);
            loop {
                match reader.read_any_message::<MavMessage>() {
                    Ok((_, message)) => {
                        let mut heard = into.lock().unwrap();
                        heard.messages += 1;
                        // ArduPilot answers a command on the port it came in by.
                        if let MavMessage::COMMAND_ACK(ack) = message {
                            heard.acks.push(ack.command as u32);
                        }
                    }
                    Err(mavlink::error::MessageReadError::Io(_)) => return,
                    Err(_) => {}
                }
            }
        });
        Spoofer {
            stream,
            heard,
            sequence: 0,
        }
    }

    /// Sends `message` as the GCS, signed with `signing` when given.
    fn send(
        &mut self,
        message: &mavlink::dialects::ardupilotmega::MavMessage,
        signing: Option<&mavlink::SigningData>,
    ) {
        let header = mavlink::MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: self.sequence,
        };
        self.sequence = self.sequence.wrapping_add(1);
        mavlink::write_versioned_msg_signed(
            &mut self.stream,
            mavlink::MavlinkVersion::V2,
            header,
            message,
            signing,
        )
        .unwrap();
    }
}

fn command(
    command: mavlink::dialects::ardupilotmega::MavCmd,
    params: [f32; 2],
) -> mavlink::dialects::ardupilotmega::MavMessage {
    use mavlink::dialects::ardupilotmega::{COMMAND_LONG_DATA, MavMessage};
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: params[0],
        param2: params[1],
        command,
        target_system: 1,
        target_component: 1,
        ..COMMAND_LONG_DATA::DEFAULT
    })
}

#[test]
fn a_signed_session_on_the_real_ardusub_works_and_unsigned_commands_are_ignored_by_both() {
    use mavlink::dialects::ardupilotmega::{MANUAL_CONTROL_DATA, MavCmd, MavMessage};
    let mut s = Session::start_with(first_instance() + 101, None, true);
    // Armed, sticks, a GoTo: as in the unsigned session, through the signed link.
    s.arm();
    let moved = s.half_stick_moves(5);
    assert!(moved > 0.5, "the stick moved it {moved} m\n{}", s.story());
    s.position_known();
    let target = GOTO_TARGET;
    let (goto_at, arrived_at) = s.goto_reached();
    // The attack, for 8 s while the vehicle holds its GoTo: on SITL's SERIAL2, as the GCS
    // (255) but unsigned, a forced disarm, MANUAL and full reverse sticks; on the ROV end's
    // UDP port, from another port, a disarmed system 1 at (40, 40, 4).
    let mut spoofer = Spoofer::connect(s.sitl.port(3));
    let udp = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let udp_port = s.udp_port.unwrap();
    let frames = crate::tdma_mavlink::spoofed_frames();
    let spoof_from = wall_s();
    for k in 0..80 {
        let reverse = MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
            x: -1000,
            z: 500,
            target: 1,
            ..MANUAL_CONTROL_DATA::DEFAULT
        });
        spoofer.send(&reverse, None);
        if k % 5 == 0 {
            let disarm = command(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0, 21196.0]);
            spoofer.send(&disarm, None);
            spoofer.send(&command(MavCmd::MAV_CMD_DO_SET_MODE, [1.0, 19.0]), None);
        }
        for frame in &frames {
            udp.send_to(frame, ("127.0.0.1", udp_port)).unwrap();
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let spoof_to = wall_s();
    // The spoofer's link works: SITL talks to it, and a command signed with the key (a
    // harmless one: send a HEARTBEAT) is answered, where none of the unsigned ones was.
    let key_text = std::fs::read_to_string(s.dir.path().join("mavlink.key")).unwrap();
    let key: [u8; 32] =
        std::array::from_fn(|k| u8::from_str_radix(&key_text[2 * k..2 * k + 2], 16).unwrap());
    let signing =
        mavlink::SigningData::from_config(mavlink::SigningConfig::new(key, 1, true, false));
    let request = command(MavCmd::MAV_CMD_REQUEST_MESSAGE, [0.0, 0.0]);
    wait_for(
        "an answer to the signed command",
        LIMIT,
        || {
            spoofer.send(&request, Some(&signing));
            let heard = spoofer.heard.lock().unwrap();
            heard
                .acks
                .contains(&(MavCmd::MAV_CMD_REQUEST_MESSAGE as u32))
                .then_some(())
        },
        || s.story(),
    );
    {
        let heard = spoofer.heard.lock().unwrap();
        assert!(heard.messages > 10, "SITL never spoke to the spoofer");
        let answered: Vec<&u32> = heard
            .acks
            .iter()
            .filter(|&&c| c != MavCmd::MAV_CMD_REQUEST_MESSAGE as u32)
            .collect();
        assert!(
            answered.is_empty(),
            "unsigned commands answered: {answered:?}"
        );
    }
    // ArduSub stayed armed in GUIDED and held its place through the attack (2 s more for
    // what was in flight).
    wait_for(
        "2 s of positions after the attack",
        LIMIT,
        || {
            s.watched("pos")
                .last()
                .filter(|p| p["t"].as_f64().unwrap() >= spoof_to + 2.0)
                .map(|_| ())
        },
        || s.story(),
    );
    let modes = s.watched("mode");
    let last_mode = modes
        .iter()
        .rfind(|m| m["t"].as_f64().unwrap() <= arrived_at);
    assert!(
        modes
            .iter()
            .filter(|m| m["t"].as_f64().unwrap() > arrived_at)
            .chain(last_mode)
            .all(|m| m["armed"] == true && m["mode"] == 4),
        "the attack changed the arm state or mode: {modes:?}\n{}",
        s.story()
    );
    let held: Vec<f64> = s
        .watched("pos")
        .iter()
        .filter(|p| (spoof_from..=spoof_to + 2.0).contains(&p["t"].as_f64().unwrap()))
        .map(|p| distance(xyz(p), target))
        .collect();
    let worst = held.iter().copied().fold(0.0, f64::max);
    assert!(
        held.len() >= 10 && worst <= 0.5,
        "held within {worst:.2} m ({} positions) under the attack\n{}",
        held.len(),
        s.story()
    );
    // And the operator never saw the spoofer's vehicle.
    let statuses = s.statuses();
    assert!(
        statuses.iter().all(|(_, st)| {
            let ours = ["x_cm", "y_cm", "z_cm"].map(|k| st[k].as_f64().unwrap() / 100.0);
            distance(ours, [40.0, 40.0, 4.0]) > 30.0
        }),
        "the spoofer's position reached the operator\n{}",
        s.story()
    );
    let last = statuses.last().map(|(_, st)| st.clone()).unwrap();
    assert_eq!(last["arm"], true, "{last}");
    assert_eq!(last["nav"], "guided", "{last}");
    eprintln!(
        "signed SITL session: moved {moved:.2} m on the stick; GoTo reached {:.1} s after it \
         was sent; held within {worst:.2} m ({} positions) through 8 s of unsigned disarm, \
         MANUAL and full-reverse commands; {} messages from SITL on the spoofer's port, no \
         answer to an unsigned command",
        arrived_at - goto_at,
        held.len(),
        spoofer.heard.lock().unwrap().messages
    );
    // What the ROV end said (its stderr file goes with the session).
    let said = std::fs::read_to_string(s.path("rov.err")).unwrap();
    let (op, rov) = s.finish();
    assert_eq!(op["orders_acknowledged"], 1, "{op}");
    assert_eq!(rov["orders_executed"], 1, "{rov}");
    let refused = &rov["mavlink_refused"];
    assert!(refused["other_address"].as_u64().unwrap_or(0) > 0, "{rov}");
    // Everything SITL sent was signed with the key and new.
    for reason in ["unsigned", "bad_signature", "replayed", "other_system"] {
        assert!(refused.get(reason).is_none(), "{reason}: {rov}");
    }
    assert!(
        said.contains("signed: only messages signed with the key are used"),
        "{said}"
    );
    let refusal_lines = said
        .lines()
        .filter(|l| l.contains("mavlink: refused"))
        .count();
    assert_eq!(refusal_lines, 1, "{said}");
}
