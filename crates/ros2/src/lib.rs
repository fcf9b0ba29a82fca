//! The toolkit on a live ROS 2 graph, with no ROS installation: messages published and taken
//! over DDS under ROS 2's wire names, so ROS 2 nodes (Humble, Jazzy; RViz, `ros2 topic`,
//! Foxglove's ROS 2 bridge) see the topics as their own.
//!
//! # What ROS 2 puts on the wire
//!
//! A ROS 2 topic `/cloud` of type `sensor_msgs/msg/PointCloud2` is the DDS topic `rt/cloud` of
//! type `sensor_msgs::msg::dds_::PointCloud2_` ([`names`]), each sample plain CDR (XCDR1), the
//! bytes a bag stores for the same message. This crate moves those bytes and nothing else
//! ([`raw`]): the messages are decoded and encoded by `rovlink_scans::ros`, the code (fuzzed)
//! that reads bags, so a live topic and a bag of it give the same scans, poses and maps.
//!
//! # Why RustDDS, directly
//!
//! Measured for issue 47 against the alternatives (`docs/ros2.md` has the figures): RustDDS
//! 0.15 (pure Rust, the DDS under `ros2-client`) interoperates with Cyclone DDS and Fast DDS;
//! `ros2-client` 0.12 adds a node graph, services and actions on top, and typed messages
//! through serde, where the toolkit already has its own decoders for every type it reads; the
//! others need a ROS installation (`r2r`, `rclrs`) or a router process (zenoh). Topics are all
//! the toolkit needs; raw bytes let one decoder serve bags and live topics.
//!
//! # What it does not do
//!
//! No DDS Security: plain DDS authenticates nobody, so every topic that can move a vehicle is
//! off unless the operator enables control, as the Foxglove view's orders are. No services,
//! actions or parameters; no `ros2 node list` entry (topics are discovered by DDS endpoint
//! discovery, which is what `ros2 topic` and RViz use).
//!
//! # Where things are
//!
//! - `names.rs`: topic and type names, the domain id;
//! - `qos.rs`: reliability, durability, history, and ROS 2's profiles;
//! - `raw.rs`: CDR bytes to and from RustDDS;
//! - `node.rs`: the participant, its readers and writers.

pub mod cdr;
pub mod msgs;
pub mod names;
pub mod node;
pub mod qos;
pub mod raw;

pub use node::{Node, Reader, Received, Writer};
pub use qos::{Durability, History, Qos, Reliability};

/// What went wrong on the ROS 2 side.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// A domain id out of range or unreadable (flag or `ROS_DOMAIN_ID`).
    #[error("{0}")]
    Domain(String),
    /// A topic or type name ROS 2 would refuse.
    #[error("{0}")]
    Name(String),
    /// A QoS setting not understood.
    #[error("{0}")]
    Qos(String),
    /// DDS refused (joining, creating an endpoint, writing).
    #[error("{0}")]
    Dds(String),
}
