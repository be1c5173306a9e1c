//! `diagnostic_msgs`: the standard `/diagnostics` messages.

use serde::{Deserialize, Serialize};

use crate::data::msg::Header;

ros_types!("diagnostic_msgs" / "msg":
    KeyValue = "KeyValue",
    DiagnosticStatus = "DiagnosticStatus",
    DiagnosticArray = "DiagnosticArray",
);

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyValue {
    /// What is measured.
    pub key: String,
    /// Its value, as text.
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// [`DIAGNOSTIC_OK`], [`DIAGNOSTIC_WARN`], [`DIAGNOSTIC_ERROR`] or
    /// [`DIAGNOSTIC_STALE`].
    pub level: u8,
    /// Name of the component (`mcgnode: predictions`).
    pub name: String,
    /// Summary of the status.
    pub message: String,
    /// Hardware the status is about (the node's name here).
    pub hardware_id: String,
    /// Counters and details.
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/msg/DiagnosticArray`, the standard `/diagnostics` message.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamped with the node's clock.
    pub header: Header,
    /// One status per component.
    pub status: Vec<DiagnosticStatus>,
}

/// `DiagnosticStatus.level`: all is well.
pub const DIAGNOSTIC_OK: u8 = 0;
/// `DiagnosticStatus.level`: something needs attention.
pub const DIAGNOSTIC_WARN: u8 = 1;
/// `DiagnosticStatus.level`: something failed.
pub const DIAGNOSTIC_ERROR: u8 = 2;
/// `DiagnosticStatus.level`: no recent information.
pub const DIAGNOSTIC_STALE: u8 = 3;
