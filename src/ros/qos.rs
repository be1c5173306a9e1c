//! QoS profiles and ROS names, shared by every module that creates DDS
//! entities (one definition each, so topics and services stay compatible).

use crate::error::err;
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{Name, QosProfile};

use super::names::Names;
use super::params::NodeParams;

/// Topic QoS from the parameters: volatile, keep-last `qos_depth`.
pub fn topic_qos(p: &NodeParams) -> QosProfile {
    let q = QosProfile::publisher_default()
        .durability(Durability::Volatile)
        .history(History::KeepLast {
            depth: p.qos_depth as usize,
        });
    if p.qos_reliable {
        q.reliability_reliable(WhenFull::DEFAULT)
    } else {
        q.reliability_best_effort()
    }
}

/// `/clock` QoS: best-effort keep-last 1 (as rclpy's time source), which
/// matches reliable and best-effort publishers.
pub fn clock_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_best_effort()
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 1 })
}

/// Reliable, volatile, keep-last 10: what rclpy's default services, action
/// endpoints and subscribers match.
pub fn reliable_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

/// The ROS name `s` resolved for the node's `names` (namespace, node name,
/// remaps), or an error naming it.
pub fn ros_name(names: &Names, s: &str) -> crate::error::Result<Name> {
    let full = names.resolve(s)?;
    Name::parse(&full).map_err(|e| err!("invalid ROS name {full:?}: {e:?}"))
}
