//! The ROS 2 node (`mcgnode serve`, whose options are in `cli/serve.rs`):
//! subscribes to `ParticleState`, publishes a predicted trajectory and the
//! forces for each state, serves Rollout, and publishes diagnostics. Built on
//! ros2-client (pure Rust DDS), interoperable with rclpy; see scripts/ros/
//! for rclpy stand-ins of the ros2 CLI.
//!
//! - [`params`] (+ [`yaml`]): the parameter table (`node_params!`: the
//!   struct, defaults, kinds, descriptions, run-time flags) and why
//!   parameters are refused; [`param_load`]: the ROS 2 parameter file,
//!   `--set` overrides and `--ros-args`; [`param_check`]: checking one value
//!   against its kind; [`param_server`]: the parameters as ROS parameters
//!   (declarations, descriptions, run-time changes validated and applied);
//! - [`wire`]: the wire structs of every interface, each with its ROS type
//!   name, one file per family;
//! - [`resource_names`]: ROS 2 names and `--ros-args` as rcl reads them (namespace,
//!   node name, remaps);
//! - [`input`]: an incoming state parsed once, with the velocities of
//!   position-only streams estimated from their history (no DDS);
//! - [`predict`]: input checks and building the outputs (no ROS);
//! - [`accuracy`]: live accuracy, comparing incoming states with what was
//!   predicted for them, and the drift alarm (no DDS);
//! - [`record`]: MCAP recording of states, predictions and forces;
//! - [`markers`]: the MarkerArray of a prediction (RViz, Foxglove);
//! - [`handles`]: what the tasks share: parameters, model, diagnostics,
//!   recorder, each a handle of its own;
//! - [`qos`]: QoS profiles, ROS names, and topics and servers created by
//!   their wire type;
//! - [`node`]: the node's wiring (DDS participant, handles, endpoints,
//!   tasks, shutdown); it wires the modules below, none of which imports it;
//! - [`endpoints`]: the node's own topics and servers and the tasks that
//!   serve them (services included); [`input_loop`]: each incoming state
//!   predicted and published; [`diagnostics`]: the periodic diagnostics and
//!   the start and shutdown reports;
//! - [`trainer`]: what every training shares (the handles, one training at
//!   a time, the errors); [`training`]: the training job; [`model_swap`]:
//!   saving, loading and atomic model swaps announced on
//!   `/mcgnode/model_swap`; [`training_services`]: the Train and LoadModel
//!   services' work; [`drift_retraining`]: retraining after a drift alarm;
//! - [`action`]: the Train action (per-epoch feedback, cancel), on top of
//!   [`training`];
//! - [`plan`]: the Plan service's work (search, refine, the plan's kinematic
//!   motion; no DDS), [`calls`]: every service's work on the node's handles,
//!   and [`plan_action`]: the Plan action (per-round feedback, cancel);
//! - [`topics`]: every topic, service and action name;
//! - [`clock`]: system or simulated (`/clock`) time;
//! - [`service`]: the one loop serving every service;
//! - [`lifecycle`]: the managed-node states and transitions (no DDS), and
//!   [`lifecycle_services`]: the `lifecycle_msgs` services over them.
//!
//! No circle of imports joins these files (tests/structure.rs).

pub mod accuracy;
pub mod action;
pub mod calls;
pub mod clock;
pub mod diagnostics;
pub mod drift_retraining;
pub mod endpoints;
pub mod handles;
pub mod input;
pub mod input_loop;
pub mod lifecycle;
pub mod lifecycle_services;
pub mod markers;
pub mod model_swap;
pub mod node;
pub mod param_check;
pub mod param_load;
pub mod param_server;
pub mod params;
pub mod plan;
pub mod plan_action;
pub mod predict;
pub mod qos;
pub mod record;
pub mod resource_names;
pub mod service;
pub mod topics;
pub mod trainer;
pub mod training;
pub mod training_services;
pub mod wire;
pub mod yaml;

pub use node::serve;
pub use params::{NodeParams, ParamError};

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
