//! Every topic, service and action name of the node, as given to
//! [`super::resource_names`] to resolve: `~/x` under the node's name, `x` in its
//! namespace, `/x` absolute. Those a parameter can change are the defaults
//! of the parameter table ([`super::params`]).

/// Where states come from (parameter `input_topic`).
pub const INPUT_TOPIC: &str = "particle_state";
/// Predicted trajectories (parameter `trajectory_topic`).
pub const TRAJECTORY_TOPIC: &str = "~/predicted_trajectory";
/// Predicted forces (parameter `forces_topic`).
pub const FORCES_TOPIC: &str = "~/predicted_forces";
/// The node's own diagnostics (parameter `diagnostics_topic`).
pub const DIAGNOSTICS_TOPIC: &str = "~/diagnostics";
/// RViz/Foxglove markers of each prediction (parameter `markers_topic`).
pub const MARKERS_TOPIC: &str = "~/markers";
/// The Rollout service (parameter `rollout_service`).
pub const ROLLOUT_SERVICE: &str = "~/rollout";
/// Live accuracy per lead time.
pub const LIVE_ACCURACY_TOPIC: &str = "~/live_accuracy";
/// The standard diagnostics topic, which `rqt_runtime_monitor` reads.
pub const STANDARD_DIAGNOSTICS_TOPIC: &str = "/diagnostics";
/// Simulated time, with `use_sim_time`.
pub const CLOCK_TOPIC: &str = "/clock";
/// The Replay service.
pub const REPLAY_SERVICE: &str = "~/replay";
/// The Plan service.
pub const PLAN_SERVICE: &str = "~/plan";
/// The Train service.
pub const TRAIN_SERVICE: &str = "~/train";
/// The LoadModel service.
pub const LOAD_MODEL_SERVICE: &str = "~/load_model";
/// Every model swap, announced (`mcgnode_msgs/msg/ModelSwap`).
pub const MODEL_SWAP_TOPIC: &str = "~/model_swap";
/// The Train action.
pub const TRAIN_ACTION: &str = "~/train_action";
/// The Plan action.
pub const PLAN_ACTION: &str = "~/plan_action";

/// The managed-node services and topic, named as rclcpp names them.
pub mod lifecycle {
    /// `lifecycle_msgs/srv/ChangeState`.
    pub const CHANGE_STATE: &str = "~/change_state";
    /// `lifecycle_msgs/srv/GetState`.
    pub const GET_STATE: &str = "~/get_state";
    /// `lifecycle_msgs/srv/GetAvailableStates`.
    pub const GET_AVAILABLE_STATES: &str = "~/get_available_states";
    /// `lifecycle_msgs/srv/GetAvailableTransitions`.
    pub const GET_AVAILABLE_TRANSITIONS: &str = "~/get_available_transitions";
    /// The whole graph, with the GetAvailableTransitions type.
    pub const GET_TRANSITION_GRAPH: &str = "~/get_transition_graph";
    /// Each transition taken (`lifecycle_msgs/msg/TransitionEvent`).
    pub const TRANSITION_EVENT: &str = "~/transition_event";
}
