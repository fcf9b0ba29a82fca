//! ROS 2 names on the DDS wire: topics (`/cloud` is DDS topic `rt/cloud`), message types
//! (`sensor_msgs/msg/PointCloud2` is DDS type `sensor_msgs::msg::dds_::PointCloud2_`) and the
//! domain id (`ROS_DOMAIN_ID`).

use crate::Ros2Error;

/// The largest domain id ROS 2 allows on Linux (the RTPS port arithmetic with the default
/// participant count leaves room for 0..=232).
pub const MAX_DOMAIN_ID: u16 = 232;

/// The longest topic name accepted, in bytes (DDS implementations cap names at 256 with the
/// `rt/` prefix).
pub const MAX_TOPIC_BYTES: usize = 247;

/// The domain to join: `flag` when given, else `ROS_DOMAIN_ID` when set, else 0, as ROS 2's
/// nodes choose. A value that is not a number in 0..=232 is an error naming where it came from.
pub fn domain_id(flag: Option<u16>) -> Result<u16, Ros2Error> {
    domain_id_from(flag, std::env::var("ROS_DOMAIN_ID").ok().as_deref())
}

/// [`domain_id`] with the environment's value given (for tests).
pub fn domain_id_from(flag: Option<u16>, env: Option<&str>) -> Result<u16, Ros2Error> {
    let (value, from) = match (flag, env) {
        (Some(id), _) => (Some(id), "--ros2-domain"),
        (None, Some(text)) if !text.trim().is_empty() => {
            let id = text.trim().parse::<u16>().ok();
            if id.is_none() {
                return Err(Ros2Error::Domain(format!(
                    "ROS_DOMAIN_ID: expected a number 0..={MAX_DOMAIN_ID}, found {text:?}"
                )));
            }
            (id, "ROS_DOMAIN_ID")
        }
        _ => (Some(0), "the default"),
    };
    match value {
        Some(id) if id <= MAX_DOMAIN_ID => Ok(id),
        other => Err(Ros2Error::Domain(format!(
            "{from}: expected a domain id 0..={MAX_DOMAIN_ID}, found {}",
            other.unwrap_or_default()
        ))),
    }
}

/// The absolute ROS 2 name of a topic (`cloud` and `/cloud` are both `/cloud`: nodes here have
/// no namespace), checked against ROS 2's rules: tokens of letters, digits and underscores
/// separated by single slashes, no token starting with a digit, no trailing slash.
pub fn topic_name(name: &str) -> Result<String, Ros2Error> {
    let bad = |why: &str| Ros2Error::Name(format!("topic {name:?}: {why}"));
    let body = name.strip_prefix('/').unwrap_or(name);
    if body.is_empty() {
        return Err(bad("expected a name such as /cloud, found nothing"));
    }
    if body.len() > MAX_TOPIC_BYTES {
        return Err(bad(&format!(
            "expected at most {MAX_TOPIC_BYTES} bytes, found {}",
            body.len()
        )));
    }
    for token in body.split('/') {
        if token.is_empty() {
            return Err(bad("expected no empty token (// or a trailing /)"));
        }
        if let Some(c) = token
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || *c == '_'))
        {
            return Err(bad(&format!(
                "expected letters, digits, _ and /, found {c:?}"
            )));
        }
        if token.starts_with(|c: char| c.is_ascii_digit()) {
            return Err(bad(&format!(
                "expected no token starting with a digit, found {token:?}"
            )));
        }
    }
    Ok(format!("/{body}"))
}

/// The DDS topic of a ROS 2 topic: `rt` and its absolute name (`/cloud` -> `rt/cloud`).
pub fn dds_topic(name: &str) -> Result<String, Ros2Error> {
    Ok(format!("rt{}", topic_name(name)?))
}

/// The DDS type name of a ROS 2 message type: `pkg/msg/Type` -> `pkg::msg::dds_::Type_`.
pub fn dds_type(ros_type: &str) -> Result<String, Ros2Error> {
    let parts: Vec<&str> = ros_type.split('/').collect();
    let ok = |s: &str| !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    match parts.as_slice() {
        [pkg, "msg", name] if ok(pkg) && ok(name) => Ok(format!("{pkg}::msg::dds_::{name}_")),
        _ => Err(Ros2Error::Name(format!(
            "message type {ros_type:?}: expected package/msg/Type"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_map_to_the_ros2_wire_names() {
        assert_eq!(dds_topic("/cloud").unwrap(), "rt/cloud");
        assert_eq!(dds_topic("tf_static").unwrap(), "rt/tf_static");
        assert_eq!(
            dds_topic("/rov/camera/image").unwrap(),
            "rt/rov/camera/image"
        );
        assert_eq!(
            dds_type("sensor_msgs/msg/PointCloud2").unwrap(),
            "sensor_msgs::msg::dds_::PointCloud2_"
        );
        assert_eq!(
            dds_type("octomap_msgs/msg/Octomap").unwrap(),
            "octomap_msgs::msg::dds_::Octomap_"
        );
    }

    #[test]
    fn bad_names_are_refused_with_the_reason() {
        for bad in ["", "/", "//a", "a/", "a//b", "/9lives", "a b", "a-b", "é"] {
            let e = topic_name(bad).unwrap_err().to_string();
            assert!(e.contains(&format!("{bad:?}")), "{e}");
        }
        assert!(topic_name(&"a".repeat(300)).is_err());
        assert!(dds_type("sensor_msgs/PointCloud2").is_err());
        assert!(dds_type("a/srv/B").is_err());
    }

    #[test]
    fn the_domain_is_the_flag_then_the_environment_then_0() {
        assert_eq!(domain_id_from(Some(7), Some("9")).unwrap(), 7);
        assert_eq!(domain_id_from(None, Some(" 9 ")).unwrap(), 9);
        assert_eq!(domain_id_from(None, None).unwrap(), 0);
        assert_eq!(domain_id_from(None, Some("")).unwrap(), 0);
        let e = domain_id_from(None, Some("x")).unwrap_err().to_string();
        assert!(e.contains("ROS_DOMAIN_ID") && e.contains("\"x\""), "{e}");
        let e = domain_id_from(Some(233), None).unwrap_err().to_string();
        assert!(e.contains("--ros2-domain") && e.contains("233"), "{e}");
    }
}
