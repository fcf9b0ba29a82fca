//! `ros2:TOPIC` inputs: the clouds of a live ROS 2 topic, posed by `/tf` + `/tf_static` (or a
//! pose topic) as they arrive, read until the build is stopped (SIGINT/SIGTERM).
//!
//! The node joins the domain ([`Ros2Input::domain`], else `ROS_DOMAIN_ID`, else 0) and
//! subscribes to the cloud topic (`sensor_msgs/msg/PointCloud2`, reliability
//! [`Ros2Input::reliability`], keep-last 10), and to `/tf` (reliable, keep-last 100) and
//! `/tf_static` (reliable, transient-local: the static transforms published before it joined
//! come too), or to `--pose-topic` (PoseStamped, TransformStamped or Odometry, the type
//! [`Ros2Input::pose_type`]). Posing is [`LivePoser`]'s: the bag reader's code, live.

use std::collections::{BTreeMap, VecDeque};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::PipelineError;
use rovlink_ros2::{Node, Qos, Reader, Reliability};
use rovlink_scans::live::{LiveOptions, LivePoseSource, LivePoser};
use rovlink_scans::recording::Item;
use rovlink_scans::ros;

/// What names a live input: `ros2:/cloud`.
pub const PREFIX: &str = "ros2:";

/// The largest cloud taken from a topic, bytes (larger ones are dropped and counted).
pub const MAX_CLOUD_BYTES: usize = 256 << 20;

/// The most distinct problem lines said; after that they are only counted.
const MAX_PROBLEM_LINES: usize = 32;

/// How a `ros2:` input joins the graph.
#[derive(Debug, Clone)]
pub struct Ros2Input {
    /// The domain id; `None`: `ROS_DOMAIN_ID`, else 0.
    pub domain: Option<u16>,
    /// The cloud topic's reliability (`best-effort` hears sensor-data publishers too).
    pub reliability: Reliability,
    /// The pose topic's type, when `--pose-topic` names one (PoseStamped by default).
    pub pose_type: String,
    /// How long a cloud waits for its transforms, s.
    pub tf_wait_s: f64,
    /// Where problem lines go (one per distinct problem).
    pub warn: fn(&str),
}

impl Default for Ros2Input {
    fn default() -> Self {
        Ros2Input {
            domain: None,
            reliability: Reliability::Reliable,
            pose_type: ros::POSE_STAMPED_SCHEMA.to_string(),
            tf_wait_s: 1.0,
            warn: |line| eprintln!("{line}"),
        }
    }
}

/// The topic of a `ros2:TOPIC` input, `None` for any other path.
pub fn topic_of(path: &Path) -> Option<&str> {
    path.to_str()?.strip_prefix(PREFIX)
}

/// A live topic's scans, in the order the clouds came.
pub(crate) struct Ros2Scans<'a> {
    name: String,
    node: Node,
    clouds: Reader,
    tf: Option<Reader>,
    tf_static: Option<Reader>,
    poses: Option<Reader>,
    poser: LivePoser,
    ready: VecDeque<Item>,
    stop: &'a AtomicBool,
    started: Instant,
    problems: BTreeMap<String, u64>,
    warn: fn(&str),
    too_big_said: u64,
}

fn pipeline_error(name: &str, e: impl std::fmt::Display) -> PipelineError {
    PipelineError::Live(format!("{name}: {e}"))
}

impl<'a> Ros2Scans<'a> {
    /// Joins the graph and subscribes.
    pub(crate) fn open(
        topic: &str,
        input: &Ros2Input,
        pose_topic: Option<&str>,
        fixed_frame: Option<String>,
        stop: &'a AtomicBool,
    ) -> Result<Ros2Scans<'a>, PipelineError> {
        let name = format!("{PREFIX}{topic}");
        let bad = |e: String| pipeline_error(&name, e);
        if !(input.tf_wait_s.is_finite() && (0.0..=3600.0).contains(&input.tf_wait_s)) {
            return Err(bad(format!(
                "--ros2-tf-wait: expected 0 ..= 3600 s, found {}",
                input.tf_wait_s
            )));
        }
        let domain =
            rovlink_ros2::names::domain_id(input.domain).map_err(|e| bad(e.to_string()))?;
        let mut node = Node::join(domain).map_err(|e| bad(e.to_string()))?;
        let cloud_qos = Qos::DEFAULT.with_reliability(input.reliability);
        let clouds = node
            .subscribe(topic, ros::POINT_CLOUD2_SCHEMA, cloud_qos, MAX_CLOUD_BYTES)
            .map_err(|e| bad(e.to_string()))?;
        let (source, tf, tf_static, poses) = match pose_topic {
            Some(p) => {
                let schema = input.pose_type.clone();
                if !rovlink_scans::recording::is_pose_type(&schema) {
                    return Err(bad(format!(
                        "--ros2-pose-type: expected {}, found {schema:?}",
                        rovlink_scans::recording::pose_type_names()
                    )));
                }
                let reader = node
                    .subscribe(p, &schema, Qos::TF, 1 << 20)
                    .map_err(|e| bad(e.to_string()))?;
                let source = LivePoseSource::Track {
                    topic: reader.topic().to_string(),
                    schema,
                };
                (source, None, None, Some(reader))
            }
            None => {
                let tf = node
                    .subscribe("/tf", ros::TF_MESSAGE_SCHEMA, Qos::TF, 16 << 20)
                    .map_err(|e| bad(e.to_string()))?;
                let tf_static = node
                    .subscribe(
                        "/tf_static",
                        ros::TF_MESSAGE_SCHEMA,
                        Qos::TF_STATIC,
                        16 << 20,
                    )
                    .map_err(|e| bad(e.to_string()))?;
                (LivePoseSource::Tf, Some(tf), Some(tf_static), None)
            }
        };
        let poser = LivePoser::new(LiveOptions {
            source,
            fixed_frame,
            wait_ns: (input.tf_wait_s * 1e9) as i64,
            ..LiveOptions::default()
        });
        Ok(Ros2Scans {
            name,
            node,
            clouds,
            tf,
            tf_static,
            poses,
            poser,
            ready: VecDeque::new(),
            stop,
            started: Instant::now(),
            problems: BTreeMap::new(),
            warn: input.warn,
            too_big_said: 0,
        })
    }

    fn now_ns(&self) -> i64 {
        i64::try_from(self.started.elapsed().as_nanos()).unwrap_or(i64::MAX)
    }

    /// Says a problem the first time it is seen; counts it after.
    fn problem(&mut self, line: String) {
        let distinct = self.problems.len();
        match self.problems.get_mut(&line) {
            Some(n) => *n += 1,
            None if distinct < MAX_PROBLEM_LINES => {
                (self.warn)(&format!("{}: {line}", self.name));
                self.problems.insert(line, 1);
            }
            None => {
                *self.problems.entry("(other problems)".into()).or_default() += 1;
            }
        }
    }

    /// Takes everything the readers have, transforms first.
    fn pump(&mut self) -> Result<(), PipelineError> {
        let mut lines = Vec::new();
        for (reader, is_static) in [(&mut self.tf_static, true), (&mut self.tf, false)] {
            let Some(reader) = reader else { continue };
            while let Some(m) = reader.take().map_err(|e| pipeline_error(&self.name, e))? {
                lines.extend(self.poser.tf(&m.message, is_static));
            }
        }
        if let Some(reader) = &mut self.poses {
            while let Some(m) = reader.take().map_err(|e| pipeline_error(&self.name, e))? {
                lines.extend(self.poser.pose(&m.message));
            }
        }
        let now = self.now_ns();
        while let Some(m) = self
            .clouds
            .take()
            .map_err(|e| pipeline_error(&self.name, e))?
        {
            match self.poser.cloud(&m.message, now) {
                Ok(Some(dropped)) => self.ready.push_back(dropped),
                Ok(None) => {}
                Err(line) => lines.push(line),
            }
        }
        let too_big = self.clouds.too_big();
        if too_big > self.too_big_said {
            self.too_big_said = too_big;
            lines.push(format!(
                "clouds over {MAX_CLOUD_BYTES} bytes dropped ({too_big} so far)"
            ));
        }
        for line in lines {
            self.problem(line);
        }
        let now = self.now_ns();
        self.ready.extend(self.poser.ready(now));
        Ok(())
    }
}

impl Iterator for Ros2Scans<'_> {
    type Item = Result<Item, PipelineError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(item) = self.ready.pop_front() {
                return Some(Ok(item));
            }
            if self.stop.load(Ordering::Relaxed) {
                return None;
            }
            if let Err(e) = self.pump() {
                return Some(Err(e));
            }
            if self.ready.is_empty() {
                self.node.wait(Duration::from_millis(50));
            }
        }
    }
}
