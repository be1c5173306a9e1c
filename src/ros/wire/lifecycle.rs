//! `lifecycle_msgs`: the managed-node messages and services (the state
//! machine over them is `crate::ros::lifecycle`).

use serde::{Deserialize, Serialize};

ros_types!("lifecycle_msgs" / "msg":
    StateMsg = "State",
    TransitionMsg = "Transition",
    TransitionDescription = "TransitionDescription",
    TransitionEvent = "TransitionEvent",
);

ros_services!("lifecycle_msgs":
    /// `lifecycle_msgs/srv/ChangeState`.
    ChangeState(ChangeStateRequest, ChangeStateResponse) = "ChangeState",
    /// `lifecycle_msgs/srv/GetState`.
    GetState(GetStateRequest, GetStateResponse) = "GetState",
    /// `lifecycle_msgs/srv/GetAvailableStates`.
    GetAvailableStates(GetAvailableStatesRequest, GetAvailableStatesResponse) = "GetAvailableStates",
    /// `lifecycle_msgs/srv/GetAvailableTransitions` (also the type of
    /// `get_transition_graph`, as rclcpp serves it).
    GetAvailableTransitions(GetAvailableTransitionsRequest, GetAvailableTransitionsResponse) = "GetAvailableTransitions",
);

/// Requests with no fields: CDR carries one placeholder byte, as rosidl
/// generates.
macro_rules! empty_requests {
    ($($t:ident = $doc:literal),*) => {$(
        #[doc = $doc]
        #[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
        pub struct $t {
            /// rosidl's `structure_needs_at_least_one_member`.
            pub structure_needs_at_least_one_member: u8,
        }
    )*};
}
empty_requests!(
    GetStateRequest = "`lifecycle_msgs/srv/GetState` request (empty).",
    GetAvailableStatesRequest = "`lifecycle_msgs/srv/GetAvailableStates` request (empty).",
    GetAvailableTransitionsRequest =
        "`lifecycle_msgs/srv/GetAvailableTransitions` request (empty)."
);

/// `lifecycle_msgs/msg/State`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StateMsg {
    /// `PRIMARY_STATE_*` id.
    pub id: u8,
    /// Its label (`unconfigured`, `inactive`, `active`, `finalized`).
    pub label: String,
}

/// `lifecycle_msgs/msg/Transition`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TransitionMsg {
    /// `TRANSITION_*` id (0: pick by label).
    pub id: u8,
    /// Its label (`configure`, `cleanup`, `activate`, `deactivate`, `shutdown`).
    pub label: String,
}

/// `lifecycle_msgs/msg/TransitionDescription`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TransitionDescription {
    /// The transition.
    pub transition: TransitionMsg,
    /// Where it starts.
    pub start_state: StateMsg,
    /// Where it ends.
    pub goal_state: StateMsg,
}

/// `lifecycle_msgs/msg/TransitionEvent`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TransitionEvent {
    /// Nanoseconds since the epoch (the node's clock).
    pub timestamp: u64,
    /// The transition taken.
    pub transition: TransitionMsg,
    /// From.
    pub start_state: StateMsg,
    /// To.
    pub goal_state: StateMsg,
}

/// `lifecycle_msgs/srv/ChangeState` request.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChangeStateRequest {
    /// The transition asked for.
    pub transition: TransitionMsg,
}

/// `lifecycle_msgs/srv/ChangeState` response.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChangeStateResponse {
    /// Whether the transition was taken.
    pub success: bool,
}

/// `lifecycle_msgs/srv/GetState` response.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GetStateResponse {
    /// The state now.
    pub current_state: StateMsg,
}

/// `lifecycle_msgs/srv/GetAvailableStates` response.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GetAvailableStatesResponse {
    /// Every primary state.
    pub available_states: Vec<StateMsg>,
}

/// `lifecycle_msgs/srv/GetAvailableTransitions` response (also what `get_transition_graph` answers).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GetAvailableTransitionsResponse {
    /// Transitions from the state now (or every transition, for the graph).
    pub available_transitions: Vec<TransitionDescription>,
}
