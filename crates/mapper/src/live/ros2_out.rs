//! The operator's view on a ROS 2 graph: the map as `octomap_msgs/msg/Octomap` for RViz's
//! occupancy display (a binary `OcTree`, and on request the full `ColorOcTree`) and as a
//! coloured `sensor_msgs/msg/PointCloud2` of the occupied voxels' centres (what RViz and
//! Foxglove both draw), each reliable, transient-local, keep-last 1: a viewer started late gets
//! the latest map, and the writer keeps only that one.
//!
//! Publishing is paced: after the view changes, at most once per [`Ros2MapOptions::period_s`],
//! and once more at the end, so the last map on the graph is the view's final one.

use std::time::{Duration, Instant};

use crate::view::voxels::occupied_centres;
use rovlink_octo::files;
use rovlink_octo::tree::OcTree;
use rovlink_ros2::{Node, Qos, Ros2Error, Writer};
use rovlink_scans::ros::{self, ByteOrder, Header};

/// Where and how the view is published.
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2MapOptions {
    /// The domain id; `None`: `ROS_DOMAIN_ID`, else 0.
    pub domain: Option<u16>,
    /// The binary `OcTree` topic.
    pub octomap_topic: String,
    /// The full `ColorOcTree` (or `OcTree`) topic, when asked for.
    pub full_topic: Option<String>,
    /// The voxel-centre cloud topic.
    pub cloud_topic: String,
    /// `header.frame_id` of every message.
    pub frame_id: String,
    /// The least time between two publications, s.
    pub period_s: f64,
}

impl Default for Ros2MapOptions {
    fn default() -> Self {
        Ros2MapOptions {
            domain: None,
            octomap_topic: "/octo_delta/octomap".into(),
            full_topic: None,
            cloud_topic: "/octo_delta/voxels".into(),
            frame_id: "map".into(),
            period_s: 1.0,
        }
    }
}

/// What a publication put on the graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Published {
    /// Maps published (each topic counted once per publication).
    pub maps: u64,
    /// Bytes of the last binary Octomap message.
    pub octomap_bytes: usize,
    /// Points of the last voxel cloud.
    pub voxels: usize,
}

/// The view's publisher; see the [module documentation](self).
pub struct MapPublisher {
    _node: Node,
    octomap: Writer,
    full: Option<Writer>,
    cloud: Writer,
    options: Ros2MapOptions,
    last: Option<Instant>,
    dirty: bool,
    published: Published,
}

/// The `.bt` or `.ot` body (the file after its `data` line).
fn body(file: Vec<u8>) -> Vec<u8> {
    match files::read_header(&file) {
        Ok(h) => file.get(h.body_offset..).unwrap_or_default().to_vec(),
        Err(_) => Vec::new(),
    }
}

impl MapPublisher {
    /// Joins the domain and advertises the topics.
    pub fn start(options: Ros2MapOptions) -> Result<MapPublisher, Ros2Error> {
        let domain = rovlink_ros2::names::domain_id(options.domain)?;
        let node = Node::join(domain)?;
        let octomap = node.advertise(&options.octomap_topic, ros::OCTOMAP_SCHEMA, Qos::LATCHED)?;
        let full = match &options.full_topic {
            Some(t) => Some(node.advertise(t, ros::OCTOMAP_SCHEMA, Qos::LATCHED)?),
            None => None,
        };
        let cloud = node.advertise(&options.cloud_topic, ros::POINT_CLOUD2_SCHEMA, Qos::LATCHED)?;
        Ok(MapPublisher {
            _node: node,
            octomap,
            full,
            cloud,
            options,
            last: None,
            dirty: false,
            published: Published::default(),
        })
    }

    /// The domain joined and the topics, for the log.
    pub fn describe(&self) -> String {
        let mut topics = vec![self.octomap.topic(), self.cloud.topic()];
        if let Some(f) = &self.full {
            topics.push(f.topic());
        }
        format!(
            "ROS 2: the view on {} (frame {:?}; reliable, transient-local, keep-last 1)",
            topics.join(", "),
            self.options.frame_id
        )
    }

    /// What was published so far.
    pub fn published(&self) -> Published {
        self.published
    }

    /// The view changed.
    pub fn changed(&mut self) {
        self.dirty = true;
    }

    /// Publishes `tree` if it changed and the period has passed since the last publication;
    /// `stamp_ns` is the messages' stamp.
    pub fn tick(&mut self, tree: &OcTree, stamp_ns: i64, now: Instant) -> Result<(), Ros2Error> {
        let due = self.last.is_none_or(|t| {
            now.duration_since(t) >= Duration::from_secs_f64(self.options.period_s.max(0.0))
        });
        if self.dirty && due {
            self.publish(tree, stamp_ns)?;
            self.last = Some(now);
        }
        Ok(())
    }

    /// Publishes `tree` now if it changed since the last publication (the end of a run).
    pub fn flush(&mut self, tree: &OcTree, stamp_ns: i64) -> Result<(), Ros2Error> {
        if self.dirty {
            self.publish(tree, stamp_ns)?;
        }
        Ok(())
    }

    fn publish(&mut self, tree: &OcTree, stamp_ns: i64) -> Result<(), Ros2Error> {
        let header = Header {
            stamp_ns,
            frame_id: self.options.frame_id.clone(),
        };
        let res = tree.resolution_m();
        let bt = body(files::write_bt(tree));
        let m = ros::encode_octomap(&header, true, "OcTree", res, &bt, ByteOrder::Little);
        self.octomap.write(&m)?;
        self.published.octomap_bytes = m.len();
        if let Some(full) = &self.full {
            let ot = body(files::write_ot(tree));
            let id = files::tree_type(tree);
            full.write(&ros::encode_octomap(
                &header,
                false,
                id,
                res,
                &ot,
                ByteOrder::Little,
            ))?;
        }
        let centres = occupied_centres(tree);
        self.published.voxels = centres.points.len();
        self.cloud.write(&ros::encode_point_cloud2(
            &header,
            &centres,
            ByteOrder::Little,
        ))?;
        self.published.maps += 1;
        self.dirty = false;
        Ok(())
    }
}
