//! The quality of service of a topic, as ROS 2 names it: reliability, durability and history,
//! with the profiles ROS 2's own nodes use.

use rustdds::policy;
use rustdds::{QosPolicies, QosPolicyBuilder};

use crate::Ros2Error;

/// Whether lost samples are repaired.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reliability {
    /// Resent until acknowledged (ROS 2's default).
    Reliable,
    /// Sent once (ROS 2's sensor-data profile). A best-effort reader hears reliable writers
    /// too; a reliable reader does not hear best-effort writers.
    BestEffort,
}

impl Reliability {
    /// The names flags take: `reliable`, `best-effort`.
    pub const NAMES: [&'static str; 2] = ["reliable", "best-effort"];

    /// Parses a flag's value.
    pub fn from_name(name: &str) -> Result<Reliability, Ros2Error> {
        match name {
            "reliable" => Ok(Reliability::Reliable),
            "best-effort" | "best_effort" => Ok(Reliability::BestEffort),
            other => Err(Ros2Error::Qos(format!(
                "reliability: expected reliable or best-effort, found {other:?}"
            ))),
        }
    }
}

/// Whether a late reader gets what was written before it joined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Durability {
    /// Only what is written after it joined.
    Volatile,
    /// The writer's history too ("latched": maps, `/tf_static`). A transient-local reader
    /// hears only transient-local writers.
    TransientLocal,
}

/// How many samples are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum History {
    /// The last N.
    KeepLast(u16),
    /// Every one, within the resource limits.
    KeepAll,
}

/// A topic's quality of service.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Repaired or not.
    pub reliability: Reliability,
    /// Latched or not.
    pub durability: Durability,
    /// Samples kept.
    pub history: History,
}

impl Qos {
    /// ROS 2's default profile: reliable, volatile, keep-last 10.
    pub const DEFAULT: Qos = Qos {
        reliability: Reliability::Reliable,
        durability: Durability::Volatile,
        history: History::KeepLast(10),
    };
    /// ROS 2's sensor-data profile: best effort, volatile, keep-last 5.
    pub const SENSOR_DATA: Qos = Qos {
        reliability: Reliability::BestEffort,
        durability: Durability::Volatile,
        history: History::KeepLast(5),
    };
    /// What tf2 uses on `/tf`: reliable, volatile, keep-last 100.
    pub const TF: Qos = Qos {
        reliability: Reliability::Reliable,
        durability: Durability::Volatile,
        history: History::KeepLast(100),
    };
    /// What tf2 uses on `/tf_static`: reliable, transient-local, keep-last 100 (a late reader
    /// gets the static transforms).
    pub const TF_STATIC: Qos = Qos {
        reliability: Reliability::Reliable,
        durability: Durability::TransientLocal,
        history: History::KeepLast(100),
    };
    /// A map: reliable, transient-local, keep-last 1, so a late viewer gets the latest one (and
    /// the writer keeps only that one).
    pub const LATCHED: Qos = Qos {
        reliability: Reliability::Reliable,
        durability: Durability::TransientLocal,
        history: History::KeepLast(1),
    };

    /// This profile with another reliability.
    pub const fn with_reliability(self, reliability: Reliability) -> Qos {
        Qos {
            reliability,
            ..self
        }
    }

    /// The DDS policies.
    pub fn to_dds(self) -> QosPolicies {
        let reliability = match self.reliability {
            Reliability::Reliable => policy::Reliability::Reliable {
                max_blocking_time: rustdds::Duration::from_millis(100),
            },
            Reliability::BestEffort => policy::Reliability::BestEffort,
        };
        let durability = match self.durability {
            Durability::Volatile => policy::Durability::Volatile,
            Durability::TransientLocal => policy::Durability::TransientLocal,
        };
        let history = match self.history {
            History::KeepLast(depth) => policy::History::KeepLast {
                depth: i32::from(depth.max(1)),
            },
            History::KeepAll => policy::History::KeepAll,
        };
        let builder = QosPolicyBuilder::new()
            .reliability(reliability)
            .durability(durability)
            .history(history);
        match self.history {
            // RustDDS keeps every sample a writer without matched readers wrote, whatever its
            // depth (no reader has acknowledged them), up to its own backstop: the resource
            // limit makes keep-last N keep N, so a latched map costs one map of memory and a
            // late reader gets the latest one, not the first.
            History::KeepLast(depth) => builder
                .resource_limits(policy::ResourceLimits {
                    max_samples: i32::from(depth.max(1)),
                    max_instances: 1,
                    max_samples_per_instance: i32::from(depth.max(1)),
                })
                .build(),
            History::KeepAll => builder.build(),
        }
    }
}

impl std::fmt::Display for Qos {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = match self.reliability {
            Reliability::Reliable => "reliable",
            Reliability::BestEffort => "best-effort",
        };
        let d = match self.durability {
            Durability::Volatile => "volatile",
            Durability::TransientLocal => "transient-local",
        };
        match self.history {
            History::KeepLast(n) => write!(f, "{r}, {d}, keep-last {n}"),
            History::KeepAll => write!(f, "{r}, {d}, keep-all"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_say_what_they_are() {
        assert_eq!(
            Qos::LATCHED.to_string(),
            "reliable, transient-local, keep-last 1"
        );
        assert_eq!(
            Qos::SENSOR_DATA.to_string(),
            "best-effort, volatile, keep-last 5"
        );
        assert!(Qos::LATCHED.to_dds().is_reliable());
        assert!(!Qos::LATCHED.to_dds().is_volatile());
        assert!(Qos::DEFAULT.to_dds().is_volatile());
        assert_eq!(
            Reliability::from_name("best-effort").unwrap(),
            Reliability::BestEffort
        );
        assert!(Reliability::from_name("sometimes").is_err());
    }
}
