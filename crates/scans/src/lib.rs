//! rovlink-scans: where the map's scans come from, each read exactly and never trusted.
//!
//! - [`cloud`]: point-cloud files (PCD, PLY, XYZ) and MCAP recordings of ROS 2
//!   `PointCloud2`, sniffed and read into [`rovlink_octo::Scan`]s;
//! - [`bag`]: MCAP and rosbag2 (sqlite3, MCAP storage) bags, their chunks and compression;
//! - [`ros`]: ROS 2 messages (CDR) read and written, and rigid transforms;
//! - [`tf`]: the TF buffer and pose tracks that give each scan its pose;
//! - [`recording`]: a recording's clouds matched with their poses;
//! - [`live`]: clouds matched with their poses as they arrive from a live topic.
//!
//! Parsers of untrusted bytes here never panic, on any input: they return a
//! [`rovlink_octo::ParseError`] that carries the byte offset where the input stopped making
//! sense.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod bag;
pub mod cloud;
pub mod live;
pub mod recording;
pub mod ros;
pub mod tf;
