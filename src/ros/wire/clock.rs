//! `rosgraph_msgs/Clock`: simulated time, as a bag player publishes it.

use serde::{Deserialize, Serialize};

use crate::data::msg::Time;

ros_types!("rosgraph_msgs" / "msg": ClockMsg = "Clock");

/// `rosgraph_msgs/msg/Clock`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ClockMsg {
    /// The simulated time.
    pub clock: Time,
}
