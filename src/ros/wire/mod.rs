//! The wire types of every interface the node speaks, one file per family:
//! plain serde structs with the fields in .msg order (what CDR needs), each
//! carrying its ROS type name ([`RosType`]), and the services and the actions
//! that pair them ([`RosService`], [`RosAction`]). Type names are spelled
//! here only.
//!
//! - [`mcgnode`], our messages (msg/*.msg);
//! - [`services`], our services (msg/*.srv);
//! - [`action`], our Train and Plan actions;
//! - [`diagnostics`], `diagnostic_msgs`;
//! - [`lifecycle`], `lifecycle_msgs`;
//! - [`markers`], `visualization_msgs/MarkerArray` and its parts;
//! - [`clock`], `rosgraph_msgs/Clock`;
//! - [`tracker`], `geometry_msgs/PoseArray` and `sensor_msgs/PointCloud2`;
//! - [`state`], the type names of ParticleState and its parts, whose structs
//!   live in [`crate::data::msg`] because the library reads bags without ROS.

use ros2_client::{ActionTypeName, Message, MessageTypeName, ServiceTypeName};

/// A ROS message type: a wire struct and its name.
pub trait RosType: Message + Clone + 'static {
    /// Its package (`mcgnode_msgs`).
    const PACKAGE: &'static str;
    /// Its name in the package (`ParticleState`, `Rollout_Request`).
    const NAME: &'static str;
    /// `package/msg/Name` (`srv`, `action` for the parts of those): the name
    /// DDS, rosbag2 and MCAP channels know it by.
    const TYPE_NAME: &'static str;
    /// `package/Name`: how a ros2msg schema names it in a dependency block.
    const SCHEMA_NAME: &'static str;

    /// Its name for ros2-client's topics.
    fn message_type_name() -> MessageTypeName {
        MessageTypeName::new(Self::PACKAGE, Self::NAME)
    }
}

/// A ROS service type: its request and response messages and its name.
pub trait RosService {
    /// The request.
    type Request: RosType;
    /// The response.
    type Response: RosType;
    /// Its package.
    const PACKAGE: &'static str;
    /// Its name in the package (`Rollout`).
    const NAME: &'static str;
    /// `package/srv/Name`.
    const TYPE_NAME: &'static str;

    /// Its name for ros2-client's servers.
    fn service_type_name() -> ServiceTypeName {
        ServiceTypeName::new(Self::PACKAGE, Self::NAME)
    }
}

/// A ROS action type: its goal, result and feedback messages and its name.
pub trait RosAction {
    /// The goal.
    type Goal: RosType;
    /// The result.
    type Result: RosType;
    /// The feedback.
    type Feedback: RosType;
    /// Its package.
    const PACKAGE: &'static str;
    /// Its name in the package (`Train`).
    const NAME: &'static str;
    /// `package/action/Name`.
    const TYPE_NAME: &'static str;

    /// Its name for ros2-client's action servers.
    fn action_type_name() -> ActionTypeName {
        ActionTypeName::new(Self::PACKAGE, Self::NAME)
    }
}

/// [`RosType`] (and ros2-client's `Message`) for wire structs of one package:
/// `ros_types!("pkg" / "msg": Struct = "Name", ...)`.
macro_rules! ros_types {
    ($pkg:literal / $kind:literal: $($t:ty = $name:expr),* $(,)?) => {$(
        impl ros2_client::Message for $t {}
        impl $crate::ros::wire::RosType for $t {
            const PACKAGE: &'static str = $pkg;
            const NAME: &'static str = $name;
            const TYPE_NAME: &'static str = concat!($pkg, "/", $kind, "/", $name);
            const SCHEMA_NAME: &'static str = concat!($pkg, "/", $name);
        }
    )*};
}

/// A unit struct per service, pairing its request and response (which get
/// their [`RosType`] as `Name_Request`, `Name_Response`):
/// `ros_services!("pkg": /// doc
/// Service(Request, Response) = "Name", ...)`.
macro_rules! ros_services {
    ($pkg:literal: $($(#[$doc:meta])* $s:ident($req:ty, $resp:ty) = $name:literal),* $(,)?) => {$(
        $(#[$doc])*
        #[derive(Clone, Copy, Debug)]
        pub struct $s;
        impl $crate::ros::wire::RosService for $s {
            type Request = $req;
            type Response = $resp;
            const PACKAGE: &'static str = $pkg;
            const NAME: &'static str = $name;
            const TYPE_NAME: &'static str = concat!($pkg, "/srv/", $name);
        }
        ros_types!($pkg / "srv":
            $req = concat!($name, "_Request"),
            $resp = concat!($name, "_Response"),
        );
    )*};
}

/// A unit struct for an action, pairing its goal, result and feedback (which
/// get their [`RosType`] as `Name_Goal`, `Name_Result`, `Name_Feedback`).
macro_rules! ros_action {
    ($pkg:literal: $(#[$doc:meta])* $a:ident($goal:ty, $result:ty, $feedback:ty) = $name:literal) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug)]
        pub struct $a;
        impl $crate::ros::wire::RosAction for $a {
            type Goal = $goal;
            type Result = $result;
            type Feedback = $feedback;
            const PACKAGE: &'static str = $pkg;
            const NAME: &'static str = $name;
            const TYPE_NAME: &'static str = concat!($pkg, "/action/", $name);
        }
        ros_types!($pkg / "action":
            $goal = concat!($name, "_Goal"),
            $result = concat!($name, "_Result"),
            $feedback = concat!($name, "_Feedback"),
        );
    };
}

pub mod action;
pub mod clock;
pub mod diagnostics;
pub mod lifecycle;
pub mod markers;
pub mod mcgnode;
pub mod services;
pub mod state;
pub mod tracker;

pub use action::{
    PlanAction, PlanFeedback, PlanGoal, PlanResult, TrainAction, TrainFeedback, TrainGoal,
    TrainResult,
};
pub use clock::ClockMsg;
pub use diagnostics::{
    DiagnosticArray, DiagnosticStatus, KeyValue, DIAGNOSTIC_ERROR, DIAGNOSTIC_OK, DIAGNOSTIC_STALE,
    DIAGNOSTIC_WARN,
};
pub use lifecycle::{
    ChangeState, ChangeStateRequest, ChangeStateResponse, GetAvailableStates,
    GetAvailableStatesRequest, GetAvailableStatesResponse, GetAvailableTransitions,
    GetAvailableTransitionsRequest, GetAvailableTransitionsResponse, GetState, GetStateRequest,
    GetStateResponse, StateMsg, TransitionDescription, TransitionEvent, TransitionMsg,
};
pub use markers::{marker_array_schema, ColorRgba, Marker, MarkerArray};
pub use mcgnode::{LiveAccuracy, ModelSwap, NodeDiagnostics, ParticleForces, PredictedTrajectory};
pub use services::{
    LoadModel, LoadModelRequest, LoadModelResponse, Plan, PlanRequest, PlanResponse, Replay,
    ReplayRequest, ReplayResponse, Rollout, RolloutRequest, RolloutResponse, Train, TrainRequest,
    TrainResponse,
};
pub use tracker::{PointCloud2, PointField, Pose, PoseArray};
