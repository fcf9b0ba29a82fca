//! rovlink-field: what connects a session to the world around it, above the engines of
//! `rovlink-rcp`:
//!
//! - [`foxglove`] and [`foxglove_gate`]: the live Foxglove WebSocket view of a session;
//! - [`foxglove_map`]: the live Foxglove view of octo-delta's map, behind the same gate;
//! - [`mcap_log`] and [`net_mcap`]: a session's MCAP log, single vehicle and network;
//! - [`mavlink`]: the ROV end driving an ArduSub autopilot over MAVLink 2;
//! - [`console`]: the operator's orders as JSON Lines from a console or a FIFO;
//! - [`ros2_session`]: the session on a ROS 2 graph (published; orders with control);
//! - [`ros2_camera`]: the ROV's camera from a ROS 2 image topic;
//! - [`ros2_vehicle`]: the ROV end driving a vehicle whose stack speaks ROS 2.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod console;
pub mod foxglove;
pub mod foxglove_gate;
pub mod foxglove_map;
mod foxglove_server;
pub mod mavlink;
pub mod mcap_log;
pub mod net_mcap;
pub mod ros2_camera;
pub mod ros2_session;
pub mod ros2_vehicle;
