//! The ROS 2 node (`mcgnode serve`, whose options are in `cli/serve.rs`):
//! subscribes to `ParticleState`, publishes a predicted trajectory and the
//! forces for each state, serves Rollout, and publishes diagnostics. Built on
//! ros2-client (pure Rust DDS), interoperable with rclpy; see scripts/ros/
//! for rclpy stand-ins of the ros2 CLI.
//!
//! - `params` (+ `yaml`): the parameter table (`node_params!`: the
//!   struct, defaults, kinds, descriptions, run-time flags) and why
//!   parameters are refused; `param_load`: the ROS 2 parameter file,
//!   `--set` overrides and `--ros-args`; `param_check`: checking one value
//!   against its kind; `param_server`: the parameters as ROS parameters
//!   (declarations, descriptions, run-time changes validated and applied);
//! - [`wire`]: the wire structs of every interface, each with its ROS type
//!   name, one file per family;
//! - `resource_names`: ROS 2 names and `--ros-args` as rcl reads them (namespace,
//!   node name, remaps);
//! - `tracker`: PoseArray and PointCloud2 decoded into positions and
//!   checked (no DDS); `tracker_input`: the template they fill and the
//!   tasks that take them;
//! - `input`: an incoming state parsed once, with the velocities of
//!   position-only streams estimated from their history (no DDS);
//! - `predict`: input checks and building the outputs (no ROS);
//! - `accuracy`: live accuracy, comparing incoming states with what was
//!   predicted for them, and the drift alarm (no DDS);
//! - `record`: MCAP recording of states, predictions and forces;
//! - `markers`: the MarkerArray of a prediction (RViz, Foxglove);
//! - `handles`: what the tasks share: parameters, model, diagnostics,
//!   recorder, each a handle of its own;
//! - `qos`: QoS profiles, ROS names, and topics and servers created by
//!   their wire type;
//! - `node`: the node's wiring (DDS participant, handles, endpoints,
//!   tasks, shutdown); it wires the modules below, none of which imports it;
//! - `endpoints`: the node's own topics and servers and the tasks that
//!   serve them (services included); `input_loop`: each incoming state
//!   predicted and published; `diagnostics`: the periodic diagnostics and
//!   the start and shutdown reports;
//! - `trainer`: what every training shares (the handles, one training at
//!   a time, the errors); `training`: the training job; `model_swap`:
//!   saving, loading and atomic model swaps announced on
//!   `/mcgnode/model_swap`; `training_services`: the Train and LoadModel
//!   services' work; `drift_retraining`: retraining after a drift alarm;
//! - `action`: the Train action (per-epoch feedback, cancel), on top of
//!   `training`;
//! - `plan`: the Plan service's work (search, refine, the plan's kinematic
//!   motion; no DDS), `calls`: every service's work on the node's handles,
//!   and `plan_action`: the Plan action (per-round feedback, cancel);
//! - `topics`: every topic, service and action name;
//! - `clock`: system or simulated (`/clock`) time;
//! - `service`: the one loop serving every service;
//! - `lifecycle`: the managed-node states and transitions (no DDS), and
//!   `lifecycle_services`: the `lifecycle_msgs` services over them.
//!
//! No circle of imports joins these files (tests/structure.rs).

pub(crate) mod accuracy;
pub(crate) mod action;
pub(crate) mod calls;
pub(crate) mod clock;
pub(crate) mod diagnostics;
pub(crate) mod drift_retraining;
pub(crate) mod endpoints;
pub(crate) mod handles;
pub(crate) mod input;
pub(crate) mod input_loop;
pub(crate) mod lifecycle;
pub(crate) mod lifecycle_services;
pub(crate) mod markers;
pub(crate) mod model_swap;
pub(crate) mod node;
pub(crate) mod param_check;
pub(crate) mod param_load;
pub(crate) mod param_server;
pub(crate) mod params;
pub(crate) mod plan;
pub(crate) mod plan_action;
pub(crate) mod predict;
pub(crate) mod qos;
pub(crate) mod record;
pub(crate) mod resource_names;
pub(crate) mod service;
pub(crate) mod smoother;
pub(crate) mod topics;
pub(crate) mod tracker;
pub(crate) mod tracker_input;
pub(crate) mod trainer;
pub(crate) mod training;
pub(crate) mod training_services;
pub mod wire;
pub(crate) mod yaml;

// The surface a library user needs: serving, the parameters, and the
// node's ROS-free halves (parsing an input, predicting it, recording).
pub use accuracy::{Level, Tracker};
pub use calls::{rollout_response, RolloutLimits};
pub use input::{Accepted, Input, Inputs};
pub use markers::prediction_markers;
pub use node::serve;
pub use params::{NodeParams, ParamError, NODE_NAME};
pub use plan::{plan_response, PlanSettings};
pub use predict::{predict, predict_into, predict_served, PredictError, Prediction};
pub use record::Recorder;

/// The DDS domain from `ROS_DOMAIN_ID` (0 when unset), which ros2-client does
/// not read by itself.
pub fn domain_id_from_env() -> Result<u16, ParamError> {
    match std::env::var("ROS_DOMAIN_ID") {
        Err(_) => Ok(0),
        Ok(s) if s.trim().is_empty() => Ok(0),
        Ok(s) => s
            .trim()
            .parse::<u16>()
            .ok()
            .filter(|d| *d <= 232)
            .ok_or(ParamError::DomainId(s)),
    }
}
