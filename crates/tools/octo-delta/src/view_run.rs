//! octo-delta view: claims its outputs, opens the link, and applies the mapper's stream as it
//! arrives; shows it on Foxglove (`--foxglove`), records it (`--mcap`), takes the operator's
//! requests from `--orders` and, with control, from Foxglove; at exit (a signal,
//! `--exit-after-scan`, the link closing) writes the view's `.ot`, the arrivals and the metrics.

use std::io::BufRead;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{RecvTimeoutError, SyncSender};
use std::time::{Duration, Instant, SystemTime};

use anyhow::Result;
use rovlink_base::UsageError;
use rovlink_base::io::EXIT_OK;
use rovlink_base::output::{Dest, Kind, Outputs};
use rovlink_cli::rows::{RowFormat, RowWriter};
use rovlink_cli::{metrics, say, stop};
use rovlink_field::foxglove_map::{self, LogLevel, MapView};
use rovlink_field::mcap_log::{JsonMcapFile, Topic, log_json, pose_json, timestamp_json};
use rovlink_maplink::Request;
use rovlink_mapper::live::carrier::{Carried, Carrier};
use rovlink_mapper::live::ros2_out::{MapPublisher, Ros2MapOptions};
use rovlink_mapper::live::rto_of;
use rovlink_mapper::live::viewer::{LogKind, ViewOutput, Viewer};
use rovlink_mapper::view::{SCENE_UPDATE_SCHEMA, SCHEMA_NAME};
use rovlink_octo::files;

use crate::TOOL;
use crate::flags::ViewRunArgs;
use crate::map_run::{link_model, random_u32};

/// What the view's loop waits on.
enum Event {
    Carried(Carried),
    /// A line of --orders: its number and what it asks.
    Order(usize, Result<Order, String>),
}

/// An order of the console.
enum Order {
    Request(Request),
    Save,
}

/// An --orders line.
fn order(line: &str) -> Result<Order, String> {
    let v: serde_json::Value = serde_json::from_str(line).map_err(|e| format!("not JSON: {e}"))?;
    let o = v.as_object().ok_or("expected a JSON object")?;
    if o.get("type").and_then(|t| t.as_str()) == Some("save") {
        return Ok(Order::Save);
    }
    Request::from_json(o)
        .map(Order::Request)
        .map_err(|e| e.to_string())
}

/// The longest --orders line read.
const MAX_ORDER_LINE: usize = 4096;

/// Reads --orders lines until the end (a FIFO kept open for writing never ends) or the loop
/// is gone.
fn read_orders(file: std::fs::File, tx: SyncSender<Event>) {
    let mut r = std::io::BufReader::new(file);
    let mut n = 0;
    loop {
        let mut line = Vec::new();
        let got =
            std::io::Read::take(&mut r, MAX_ORDER_LINE as u64 + 1).read_until(b'\n', &mut line);
        match got {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
        n += 1;
        let text = String::from_utf8_lossy(&line);
        let text = text.trim();
        if text.is_empty() {
            continue;
        }
        let o = if line.len() > MAX_ORDER_LINE {
            // The rest of an overlong line is skipped with it.
            let _ = r.read_until(b'\n', &mut Vec::new());
            Err(format!("longer than {MAX_ORDER_LINE} bytes"))
        } else {
            order(text)
        };
        if tx.send(Event::Order(n, o)).is_err() {
            return;
        }
    }
}

fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// The view's sinks for what changes on screen.
struct Screens {
    foxglove: Option<MapView>,
    mcap: Option<(JsonMcapFile, [u16; 3])>,
    quiet: bool,
}

impl Screens {
    fn show(&mut self, out: ViewOutput, t_ns: u64) {
        match out {
            ViewOutput::Scene(update) => {
                let wanted = self
                    .foxglove
                    .as_ref()
                    .is_some_and(MapView::scene_subscribed);
                if !wanted && self.mcap.is_none() {
                    return;
                }
                let json = match serde_json::to_string(&update) {
                    Ok(j) => j,
                    Err(_) => return,
                };
                if let Some(f) = self.foxglove.as_ref().filter(|_| wanted) {
                    f.publish_scene(t_ns, json.as_bytes());
                }
                if let Some((m, ch)) = self.mcap.as_mut() {
                    m.write(ch[0], t_ns, &json);
                }
            }
            ViewOutput::Pose(p, q) => {
                if let Some(f) = &self.foxglove {
                    f.publish_pose(t_ns, p, q);
                }
                if let Some((m, ch)) = self.mcap.as_mut() {
                    let json = pose_json(&timestamp_json(t_ns), foxglove_map::MAP_FRAME, p, q);
                    m.write(ch[1], t_ns, &json.to_string());
                }
            }
            ViewOutput::Log(kind, text) => self.log(t_ns, kind, &text),
        }
    }

    fn log(&mut self, t_ns: u64, kind: LogKind, text: &str) {
        let level = match kind {
            LogKind::Info => LogLevel::Info,
            LogKind::Warning => LogLevel::Warning,
        };
        if kind == LogKind::Warning || !self.quiet {
            say!("{text}");
        }
        if let Some(f) = &self.foxglove {
            f.log(t_ns, level, text);
        }
        if let Some((m, ch)) = self.mcap.as_mut() {
            let json = log_json(&timestamp_json(t_ns), level.foxglove(), TOOL, text);
            m.write(ch[2], t_ns, &json.to_string());
        }
    }
}

/// Writes the view as `.ot` (an empty map before the first sync is not written: said).
fn save(viewer: &Viewer, dest: &Dest) -> Result<bool> {
    match viewer.view() {
        Some(v) => {
            dest.write_whole(&files::write_ot(v))?;
            Ok(true)
        }
        None => Ok(false),
    }
}

/// p50, p95 and max of `v` (nearest rank, as every figure of the toolkit), none when empty.
fn quantiles(mut v: Vec<f64>) -> serde_json::Value {
    v.sort_by(f64::total_cmp);
    let at = |q: f64| rovlink_base::stats::quantile_sorted(&v, q);
    match at(1.0) {
        None => serde_json::Value::Null,
        Some(max) => {
            serde_json::json!({"p50": at(0.5), "p95": at(0.95), "max": max, "n": v.len()})
        }
    }
}

/// Runs `view`; the process's exit code.
pub fn view(a: &ViewRunArgs) -> Result<u8> {
    let model = link_model(&a.link)?;
    let rto = a
        .link
        .rto_ms
        .map_or_else(|| rto_of(&model), |ms| Duration::from_secs_f64(ms / 1e3));
    let mut outs = Outputs::new();
    outs.input(a.orders.as_deref());
    let ot = outs.claim_opt("-o", a.output.as_deref(), Kind::Binary)?;
    let mcap_dest = outs.claim_opt("--mcap", a.mcap.as_deref(), Kind::Binary)?;
    let arrivals = outs.claim_opt("--arrivals", a.arrivals.as_deref(), Kind::Text)?;
    let metrics_dest = outs.claim_opt("--metrics", a.metrics.as_deref(), Kind::Text)?;
    let orders = a
        .orders
        .as_deref()
        .map(|p| rovlink_base::secret::open_command_source(p, true))
        .transpose()
        .map_err(|e| UsageError(format!("--orders {e}")))?;
    let foxglove = match &a.foxglove {
        None => None,
        Some(addr) => {
            let tls = a
                .foxglove_tls_cert
                .as_deref()
                .zip(a.foxglove_tls_key.as_deref());
            let policy = rovlink_field::foxglove_gate::policy_from_flags(
                a.foxglove_token_file.as_deref(),
                &a.foxglove_origin,
                a.foxglove_insecure,
                tls,
            )
            .map_err(UsageError)?;
            let view =
                foxglove_map::start_map(addr, "octo-delta view", &policy, SCENE_UPDATE_SCHEMA)
                    .map_err(|e| UsageError(format!("--foxglove {e}")))?;
            say!(
                "Foxglove: {}://{} ({})",
                view.scheme(),
                view.addr(),
                if policy.token.is_some() {
                    "requests from clients whose URL carries ?token=; the others view"
                } else {
                    "view-only; requests need --foxglove-token-file"
                }
            );
            Some(view)
        }
    };
    let mcap = match &mcap_dest {
        None => None,
        Some(d) => {
            let mut f = JsonMcapFile::create(d)?;
            let scene = f.channel(SCHEMA_NAME, SCENE_UPDATE_SCHEMA, foxglove_map::SCENE_TOPIC)?;
            let pose = f.channel(
                Topic::Pose.schema_name(),
                Topic::Pose.schema(),
                foxglove_map::POSE_TOPIC,
            )?;
            let log = f.channel(
                Topic::Log.schema_name(),
                Topic::Log.schema(),
                foxglove_map::LOG_TOPIC,
            )?;
            Some((f, [scene, pose, log]))
        }
    };
    stop::install()?;
    let (tx, rx) = std::sync::mpsc::sync_channel(256);
    if let Some((file, _)) = orders {
        let tx = tx.clone();
        std::thread::spawn(move || read_orders(file, tx));
    }
    let to_loop = tx.clone();
    let hand = Box::new(move |c| to_loop.send(Event::Carried(c)).is_ok());
    let quit_reader = Arc::new(AtomicBool::new(false));
    let mut carrier = Carrier::open(
        &a.link.port,
        a.link.baud as u32,
        0,
        a.mapper_address as u8,
        Arc::clone(&quit_reader),
        hand,
    )
    .map_err(|e| UsageError(format!("--port {e}")))?;
    drop(tx);
    let mut screens = Screens {
        foxglove,
        mcap,
        quiet: a.quiet,
    };
    let start = Instant::now();
    let start_unix = unix_now();
    let t_ns = |now: Duration| ((start_unix + now.as_secs_f64()) * 1e9) as u64;
    let mut viewer = Viewer::new(
        rto,
        random_u32()?,
        start_unix,
        screens.foxglove.is_some() || screens.mcap.is_some(),
    );
    viewer.want_resync(Duration::ZERO);
    let mut ros2 = match a.ros2.ros2 {
        false => None,
        true => {
            let p = MapPublisher::start(Ros2MapOptions {
                domain: a.ros2.ros2_domain.map(|d| d as u16),
                octomap_topic: a.ros2.ros2_octomap_topic.clone(),
                full_topic: a.ros2.ros2_full_topic.clone(),
                cloud_topic: a.ros2.ros2_voxels_topic.clone(),
                frame_id: a.ros2.ros2_frame.clone(),
                period_s: a.ros2.ros2_period,
            })
            .map_err(|e| UsageError(format!("--ros2: {e}")))?;
            screens.log(t_ns(Duration::ZERO), LogKind::Info, &p.describe());
            Some(p)
        }
    };
    let mut rows_published = 0;
    screens.log(
        t_ns(Duration::ZERO),
        LogKind::Info,
        &format!(
            "viewing the map from {} (mapper address {}); resend after {} ms",
            carrier.name,
            a.mapper_address,
            rto.as_millis()
        ),
    );
    let mut closed = None;
    loop {
        let now = start.elapsed();
        while let Some(seg) = viewer.poll(now) {
            if let Err(e) = carrier.send(&seg) {
                closed = Some(format!("{}: write failed: {e}", carrier.name));
                break;
            }
        }
        for out in viewer.take_outputs() {
            screens.show(out, t_ns(now));
        }
        if let Some(p) = ros2.as_mut() {
            if viewer.rows().len() != rows_published {
                rows_published = viewer.rows().len();
                p.changed();
            }
            if let Some(v) = viewer.view()
                && let Err(e) = p.tick(v, t_ns(now) as i64, Instant::now())
            {
                screens.log(t_ns(now), LogKind::Warning, &format!("ROS 2: {e}"));
            }
        }
        if let Some(f) = &screens.foxglove {
            if f.take_snapshot_wanted()
                && let Some(snap) = viewer.snapshot(t_ns(now))
                && let Ok(json) = serde_json::to_vec(&snap)
            {
                f.send_snapshot(t_ns(now), &json);
            }
            let requests = f.take_requests();
            let warnings = f.take_warnings();
            for o in requests {
                match Request::from_json(&o) {
                    Ok(r) => {
                        if viewer.request(r, now).is_none() {
                            screens.log(
                                t_ns(now),
                                LogKind::Warning,
                                "Foxglove request refused: too many requests waiting",
                            );
                        }
                    }
                    Err(e) => screens.log(
                        t_ns(now),
                        LogKind::Warning,
                        &format!("Foxglove request refused: {e}"),
                    ),
                }
            }
            for w in warnings {
                screens.log(t_ns(now), LogKind::Warning, &w);
            }
        }
        if closed.is_some() || stop::requested() {
            break;
        }
        if let Some(n) = a.exit_after_scan
            && viewer
                .rows()
                .last()
                .is_some_and(|r| r.scan as u64 >= n && r.kind == "delta")
        {
            break;
        }
        let wait = viewer
            .next_deadline()
            .map_or(Duration::from_millis(100), |t| t.saturating_sub(now))
            .min(Duration::from_millis(100));
        match rx.recv_timeout(wait) {
            Ok(Event::Carried(Carried::Segment(b))) => viewer.on_segment(&b, start.elapsed()),
            Ok(Event::Carried(Carried::Closed(why))) => {
                closed = Some(format!("{}: {why}", carrier.name))
            }
            Ok(Event::Order(n, Ok(Order::Request(r)))) => match viewer.request(r, now) {
                Some(id) => screens.log(
                    t_ns(now),
                    LogKind::Info,
                    &format!("request {id}: {}", r.to_json()),
                ),
                None => screens.log(
                    t_ns(now),
                    LogKind::Warning,
                    &format!("--orders line {n}: refused: too many requests waiting"),
                ),
            },
            Ok(Event::Order(n, Ok(Order::Save))) => match &ot {
                Some(d) => match save(&viewer, d)? {
                    true => screens.log(
                        t_ns(now),
                        LogKind::Info,
                        &format!("view written to {}", d.name()),
                    ),
                    false => {
                        screens.log(t_ns(now), LogKind::Warning, "no view yet: nothing written")
                    }
                },
                None => screens.log(
                    t_ns(now),
                    LogKind::Warning,
                    &format!("--orders line {n}: save: no -o given"),
                ),
            },
            Ok(Event::Order(n, Err(e))) => screens.log(
                t_ns(now),
                LogKind::Warning,
                &format!("--orders line {n}: {e}"),
            ),
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    if closed.is_none()
        && let Some(ack) = viewer.final_ack()
    {
        // Three copies: the mapper learns that this view has everything even if one or two
        // are lost (a mapper with --exit-when-done waits for it).
        for _ in 0..3 {
            let _ = carrier.send(&ack);
        }
    }
    quit_reader.store(true, Ordering::Relaxed);
    let end = start.elapsed();
    if let Some(p) = ros2.as_mut()
        && let Some(v) = viewer.view()
        && let Err(e) = p.flush(v, t_ns(end) as i64)
    {
        say!("ROS 2: {e}");
    }
    if let Some(d) = &ot
        && !save(&viewer, d)?
    {
        say!("no view was received: -o {} not written", d.name());
    }
    if let Some((f, _)) = screens.mcap.take() {
        f.finish()?;
    }
    if let Some(f) = screens.foxglove.take() {
        f.stop();
    }
    if let Some(d) = arrivals {
        let w = RowWriter::new(
            d,
            RowFormat::Csv,
            &[
                "scan",
                "kind",
                "bytes",
                "t_ready_s",
                "t_shown_s",
                "latency_s",
            ],
        );
        w.write_all(viewer.rows())?;
    }
    let latencies: Vec<f64> = viewer.rows().iter().filter_map(|r| r.latency_s).collect();
    let figures = serde_json::json!({
        "messages": viewer.counters().messages,
        "latency_s": quantiles(latencies),
        "view": viewer.counters(),
        "transport": {
            "segments": viewer.transport().segments,
            "duplicates": viewer.transport().duplicates,
            "dropped": viewer.transport().dropped,
            "malformed": viewer.transport().malformed,
            "acks": viewer.transport().acks,
            "requests_sent": viewer.transport().requests_sent,
            "broken_records": viewer.transport().broken_records,
            "rto_ms": rto.as_secs_f64() * 1e3,
        },
        "carrier": carrier.counters(),
        "requests": viewer.requests(),
        "elapsed_s": end.as_secs_f64(),
        "closed": closed,
        "ros2": ros2.as_ref().map(|p| {
            let d = p.published();
            serde_json::json!({
                "maps": d.maps,
                "octomap_bytes": d.octomap_bytes,
                "voxels": d.voxels,
            })
        }),
    });
    if let Some(d) = metrics_dest {
        let mut out = d.open()?;
        metrics::write(&mut out, TOOL, None, &figures)?;
        out.finish()?;
    }
    if let Some(why) = closed {
        say!("link closed: {why}");
        return Ok(1);
    }
    Ok(stop::code_or(EXIT_OK))
}
