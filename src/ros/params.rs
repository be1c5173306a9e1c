//! The node's parameters, declared once in one table (`node_params!`): the
//! [`NodeParams`] struct, its defaults, each parameter's [`Spec`] (kind,
//! description, run-time flag), typed access by name, the parameter-file
//! text of the values, and why parameters are refused ([`ParamError`]).
//! Reading files and `--set` is in [`super::param_load`], checking one value
//! in [`super::param_check`].

use std::path::PathBuf;

use super::topics;
use super::yaml::YamlError;

/// Why parameters were refused: each names the key, what was given and what
/// is expected.
#[derive(Debug, thiserror::Error)]
pub enum ParamError {
    /// The parameter file cannot be read.
    #[error("cannot read parameter file {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Something in the parameter file `path`.
    #[error("parameter file {}: {source}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What.
        source: Box<ParamError>,
    },
    /// Not YAML, or YAML that parameter files do not use.
    #[error(transparent)]
    Yaml(#[from] YamlError),
    /// The file's top level is not a mapping.
    #[error("expected a mapping at the top level")]
    NotAMapping,
    /// A `--params-file` without a section for this node.
    #[error("no section for this node ({0}); use `/**:`, its name or its fully qualified name")]
    NoSectionFor(String),
    /// No section at all.
    #[error("no `{NODE_NAME}: ros__parameters:` section")]
    NoSection,
    /// A section for another node.
    #[error(
        "section {0:?} is for another node; this node is {NODE_NAME:?} (use `{NODE_NAME}:` or `/**:`)"
    )]
    OtherNode(String),
    /// A node section that is not a mapping.
    #[error("{0}: expected `ros__parameters:` under it")]
    NoRosParameters(String),
    /// A key beside `ros__parameters`.
    #[error("{node}: unexpected key {key:?} (only ros__parameters)")]
    UnexpectedKey {
        /// The node section.
        node: String,
        /// The key.
        key: String,
    },
    /// A `--set` without `=`.
    #[error("--set {0:?}: expected key=value")]
    NotKeyValue(String),
    /// A refused `--set key=value`.
    #[error("--set {given:?}: {source}")]
    Override {
        /// The argument.
        given: String,
        /// Why.
        source: Box<ParamError>,
    },
    /// A key no parameter has.
    #[error("unknown parameter {0:?}; known parameters: {known}", known = known_parameters())]
    Unknown(String),
    /// A value of the wrong type.
    #[error("parameter {key:?} must be {want}, got {got}")]
    IllTyped {
        /// The parameter.
        key: String,
        /// What it takes.
        want: String,
        /// The value's YAML type and text.
        got: String,
    },
    /// A topic or service name that is not a ROS 2 name.
    #[error(
        "parameter {key:?}: {name:?} is not a ROS 2 name like /particle_state, particle_state \
         or ~/rollout (letters, digits, _)"
    )]
    BadName {
        /// The parameter.
        key: String,
        /// The name given.
        name: String,
    },
    /// An integer outside its range.
    #[error("parameter {key:?} = {value} is outside {lo}..={hi}")]
    OutOfRange {
        /// The parameter.
        key: String,
        /// The value given.
        value: i64,
        /// Smallest allowed.
        lo: u32,
        /// Largest allowed.
        hi: u32,
    },
    /// A double that is not finite, or not positive where it must be.
    #[error("parameter {key:?} = {value} must be finite and {want}")]
    NotPositive {
        /// The parameter.
        key: String,
        /// The value given.
        value: f64,
        /// "> 0" or ">= 0".
        want: &'static str,
    },
    /// A list longer than allowed.
    #[error("parameter {key:?} has {len} entries; at most {max}")]
    TooLong {
        /// The parameter.
        key: String,
        /// Entries given.
        len: usize,
        /// Most allowed.
        max: usize,
    },
    /// A list entry that is not finite and positive.
    #[error("parameter {key:?}: entry {value} must be finite and > 0")]
    BadEntry {
        /// The parameter.
        key: String,
        /// The entry.
        value: f64,
    },
    /// A parameter that cannot change while the node runs.
    #[error(
        "parameter {0} cannot change at run time (it shapes topics, services, QoS, files or the \
         model); restart the node with --set {0}=...; settable now: {settable}",
        settable = runtime_settable_names().join(", ")
    )]
    NotRuntime(String),
    /// A name that does not resolve.
    #[error(transparent)]
    Name(#[from] NameError),
    /// Parameters that are valid alone but not together.
    #[error("parameters {0}")]
    Together(String),
    /// No model to serve.
    #[error("no model: set the `model` parameter or pass --model")]
    NoModel,
    /// `ROS_DOMAIN_ID` is not a domain id.
    #[error("ROS_DOMAIN_ID={0:?} is not a domain id in 0..=232")]
    DomainId(String),
}

crate::error::typed_errors!(ParamError);

fn known_parameters() -> String {
    SPECS.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
}

use super::resource_names::NameError;
pub use super::resource_names::NODE_NAME;

/// One parameter in the table: its name, kind, description, and whether it
/// can change while the node runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Spec {
    /// The parameter's name (its field's).
    pub name: &'static str,
    /// What it holds.
    pub kind: Kind,
    /// One line for parameter files, `--print-params` and `describe_parameters`.
    pub doc: &'static str,
    /// Settable at run time (through the ROS parameter services, e.g.
    /// rclpy's `set_parameters`), taking effect from the next incoming state
    /// or call. The others shape DDS endpoints, files or the loaded model and
    /// need a restart.
    pub runtime: bool,
}

/// A parameter's value, typed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ParamValue<'a> {
    /// Text (strings, names, choices).
    Str(&'a str),
    /// A flag.
    Bool(bool),
    /// An integer.
    Int(u32),
    /// A double.
    Double(f64),
    /// A list of doubles.
    Doubles(&'a [f64]),
}

/// Where a parameter's value lives, typed (for the setter).
pub(super) enum Slot<'a> {
    Str(&'a mut String),
    Bool(&'a mut bool),
    Int(&'a mut u32),
    Double(&'a mut f64),
    Doubles(&'a mut Vec<f64>),
}

macro_rules! slot_and_value {
    ($($t:ty => $v:ident),*) => {$(
        impl<'a> From<&'a mut $t> for Slot<'a> {
            fn from(x: &'a mut $t) -> Self {
                Slot::$v(x)
            }
        }
    )*};
}
slot_and_value!(String => Str, bool => Bool, u32 => Int, f64 => Double, Vec<f64> => Doubles);

impl<'a> From<&'a String> for ParamValue<'a> {
    fn from(x: &'a String) -> Self {
        ParamValue::Str(x)
    }
}
impl From<&bool> for ParamValue<'_> {
    fn from(x: &bool) -> Self {
        ParamValue::Bool(*x)
    }
}
impl From<&u32> for ParamValue<'_> {
    fn from(x: &u32) -> Self {
        ParamValue::Int(*x)
    }
}
impl From<&f64> for ParamValue<'_> {
    fn from(x: &f64) -> Self {
        ParamValue::Double(*x)
    }
}
impl<'a> From<&'a Vec<f64>> for ParamValue<'a> {
    fn from(x: &'a Vec<f64>) -> Self {
        ParamValue::Doubles(x)
    }
}

/// Declares every parameter once: its field (with its documentation, type
/// and default) and its [`Spec`]; the struct, its `Default`, [`SPECS`] and
/// the typed accessors by name are generated from it, so no parameter's name
/// is written twice.
macro_rules! node_params {
    ($(
        $(#[$meta:meta])*
        $name:ident: $ty:ty = $default:expr, $kind:expr, $when:ident, $doc:literal;
    )*) => {
        /// Everything the node can be configured with.
        #[derive(Clone, Debug, PartialEq)]
        pub struct NodeParams {
            $($(#[$meta])* pub $name: $ty,)*
        }

        impl Default for NodeParams {
            fn default() -> Self {
                NodeParams {
                    $($name: $default,)*
                }
            }
        }

        /// Every parameter, in file order: the one table the parameter file,
        /// `--set`, `--print-params` and the node's declared ROS parameters
        /// (with descriptions, ranges and read-only flags) all come from.
        pub const SPECS: &[Spec] = &[$(Spec {
            name: stringify!($name),
            kind: $kind,
            doc: $doc,
            runtime: node_params!(@when $when),
        },)*];

        impl NodeParams {
            /// The value of parameter `key`, typed (`None`: no such parameter).
            pub fn value(&self, key: &str) -> Option<ParamValue<'_>> {
                match key {
                    $(stringify!($name) => Some(ParamValue::from(&self.$name)),)*
                    _ => None,
                }
            }

            pub(super) fn slot(&mut self, key: &str) -> Option<Slot<'_>> {
                match key {
                    $(stringify!($name) => Some(Slot::from(&mut self.$name)),)*
                    _ => None,
                }
            }
        }
    };
    (@when runtime) => { true };
    (@when restart) => { false };
}

node_params! {
    /// Model to serve: `truth:spring`, `truth:pendulum`, or a trained model file.
    model: String = "truth:spring".into(), Kind::Str, restart,
        "model to serve: truth:spring, truth:pendulum or a model file";
    /// Topic the node reads `ParticleState` from.
    input_topic: String = topics::INPUT_TOPIC.into(), Kind::Topic, restart,
        "topic of incoming ParticleState messages";
    /// Topic of `geometry_msgs/PoseArray` tracker input (empty: none).
    pose_array_topic: String = String::new(), Kind::OptTopic, restart,
        "topic of geometry_msgs/PoseArray tracker input, one pose per particle of \
         input_template (positions only; velocities from velocity_smoother); empty = off";
    /// Topic of `sensor_msgs/PointCloud2` tracker input (empty: none).
    point_cloud_topic: String = String::new(), Kind::OptTopic, restart,
        "topic of sensor_msgs/PointCloud2 tracker input, one point per particle of \
         input_template (x, y, z FLOAT32/FLOAT64 fields by name, any point_step, organised \
         or not, either byte order); empty = off";
    /// The particles behind PoseArray/PointCloud2 input: a bag (its first
    /// state) or a YAML file of ParticleState fields.
    input_template: String = String::new(), Kind::Str, restart,
        "what PoseArray and PointCloud2 input cannot say (types, masses, graph, kinematic \
         flags, field): a bag (its first state) or a .yaml file of ParticleState fields; \
         needed with pose_array_topic or point_cloud_topic";
    /// The frame PoseArray/PointCloud2 input must be in.
    frame_id: String = crate::data::msg::FRAME_ID.into(), Kind::Str, runtime,
        "header.frame_id PoseArray and PointCloud2 input must carry (no tf2 lookup: \
         messages in other frames are refused, naming both)";
    /// Topic of the predicted trajectories.
    trajectory_topic: String = topics::TRAJECTORY_TOPIC.into(), Kind::Topic, restart,
        "topic of PredictedTrajectory messages";
    /// Topic of the predicted forces.
    forces_topic: String = topics::FORCES_TOPIC.into(), Kind::Topic, restart,
        "topic of ParticleForces messages";
    /// Topic of the periodic `NodeDiagnostics`.
    diagnostics_topic: String = topics::DIAGNOSTICS_TOPIC.into(), Kind::Topic, restart,
        "topic of NodeDiagnostics messages";
    /// Name of the Rollout service.
    rollout_service: String = topics::ROLLOUT_SERVICE.into(), Kind::Topic, restart,
        "name of the Rollout service";
    /// Steps predicted for each incoming state.
    horizon: u32 = 100, Kind::Int(1, 100_000), runtime,
        "steps predicted per incoming state";
    /// Time step of predictions, seconds.
    dt: f64 = 0.001, Kind::Double(true), runtime,
        "time step of predictions, seconds";
    /// Integration steps per prediction step: the model is integrated with
    /// `dt / substeps` (e.g. the training data's simulator step) and every
    /// `substeps`-th state is published.
    substeps: u32 = 1, Kind::Int(1, 1_000_000), runtime,
        "integration steps per prediction step (the model is integrated with dt / substeps)";
    /// Folder for models trained by the node; empty: `<record_dir>/models`,
    /// or a temporary folder when not recording.
    model_dir: String = String::new(), Kind::Str, restart,
        "folder for models trained by the node (empty: <record_dir>/models, or a temporary folder)";
    /// Reliable (true) or best-effort (false) QoS on the topics.
    qos_reliable: bool = true, Kind::Bool, restart,
        "reliable (true) or best-effort (false) topics";
    /// Keep-last history depth of the topics.
    qos_depth: u32 = 10, Kind::Int(1, 10_000), restart,
        "keep-last history depth";
    /// QoS of the input subscriptions (ParticleState, PoseArray,
    /// PointCloud2); the outputs keep `qos_reliable`/`qos_depth`.
    input_qos: String = "topics".into(), Kind::Choice(INPUT_QOS), restart,
        "QoS of the input subscriptions (ParticleState, PoseArray, PointCloud2): topics = as \
         qos_reliable and qos_depth; reliable = reliable, keep-last input_qos_depth (hears \
         reliable publishers only); best_effort = best effort, keep-last input_qos_depth; \
         sensor_data = best effort, keep-last 5 (SensorDataQoS); best effort hears both";
    /// Keep-last depth of the input subscriptions with `input_qos` =
    /// `reliable` or `best_effort`.
    input_qos_depth: u32 = 10, Kind::Int(1, 10_000), restart,
        "keep-last depth of the input subscriptions when input_qos is reliable or best_effort";
    /// Stamp diagnostics, swaps and recordings with `/clock` (bag playback)
    /// instead of the system clock; read at start.
    use_sim_time: bool = false, Kind::Bool, restart,
        "stamp diagnostics, swaps and recordings with /clock (bag playback); read at start";
    /// Seconds between diagnostics messages.
    diagnostics_period: f64 = 1.0, Kind::Double(true), restart,
        "seconds between diagnostics messages";
    /// Minimum seconds between two warnings about malformed input.
    warn_period: f64 = 5.0, Kind::Double(false), runtime,
        "seconds between malformed-input warnings";
    /// Largest `steps` the Rollout service accepts.
    max_rollout_steps: u32 = 10_000, Kind::Int(1, 1_000_000), runtime,
        "largest steps of a Rollout call";
    /// Largest state (particles) the node accepts on its input topic and in
    /// Rollout calls; larger ones are rejected with the reason.
    max_particles: u32 = 10_000, Kind::Int(1, 10_000_000), runtime,
        "largest state accepted (particles); larger states are rejected with the reason";
    /// Folder to record MCAP bags into; empty disables recording.
    record_dir: String = String::new(), Kind::Str, restart,
        "folder for MCAP recordings; empty = no recording";
    /// Start a new bag after this many megabytes (0 = no size limit).
    record_split_mb: u32 = 0, Kind::Int(0, 1_000_000), restart,
        "split bags after this many MB (0 = never)";
    /// Start a new bag after this many seconds (0 = no duration limit).
    record_split_seconds: f64 = 0.0, Kind::Double(false), restart,
        "split bags after this many seconds (0 = never)";
    /// Finish the open MCAP chunk once its oldest message has waited this
    /// long (checked at each write and on a timer), so a killed node loses at
    /// most this much; 0 = after every message.
    record_flush_seconds: f64 = 0.25, Kind::Double(false), restart,
        "finish the recording's open chunk once its oldest message is this many seconds old \
         (a killed node loses at most that much; 0 = after every message)";
    /// Lead times (seconds) at which live accuracy compares incoming states
    /// with what was predicted for them; empty disables live accuracy.
    accuracy_lead_times: Vec<f64> = Vec::new(), Kind::Doubles(16), runtime,
        "live accuracy: lead times (s) at which incoming states are compared with their \
         predictions, each within horizon * dt; [] = off";
    /// Comparisons averaged into the running RE and EE per lead time.
    accuracy_window: u32 = 10, Kind::Int(1, 100_000), runtime,
        "live accuracy: comparisons averaged into the running RE and EE";
    /// Predictions kept waiting for their moment (bounds memory).
    accuracy_max_pending: u32 = 10_000, Kind::Int(1, 10_000_000), runtime,
        "live accuracy: predictions kept waiting for their moment (bounds memory)";
    /// Drift alarm: WARN when a running RE exceeds this (0 = never).
    accuracy_warn_re: f64 = 0.01, Kind::Double(false), runtime,
        "drift alarm: WARN when a running RE exceeds this (0 = never)";
    /// Drift alarm: ERROR when a running RE exceeds this (0 = never).
    accuracy_error_re: f64 = 0.05, Kind::Double(false), runtime,
        "drift alarm: ERROR when a running RE exceeds this (0 = never)";
    /// Spread alarm: WARN when an ensemble's latest prediction has a particle
    /// spread above this (positions' units), before any error is observed.
    spread_warn: f64 = 0.0, Kind::Double(false), runtime,
        "spread alarm: WARN on /diagnostics when an ensemble's (train --ensemble K) latest \
         prediction has a particle spread above this, in the positions' units (0 = never)";
    /// Retrain when the spread alarm is raised, as on a drift alarm.
    spread_retrain: bool = false, Kind::Bool, runtime,
        "on a spread alarm (spread_warn), retrain as on a drift alarm (accuracy_retrain_after, \
         accuracy_retrain_epochs; needs record_dir), before any error is observed";
    /// Weight of the Plan service's and action's risk term: this × the sum
    /// over control steps of the free particles' mean ensemble spread along
    /// each candidate's rollout; a single model refuses a weight above 0.
    plan_risk: f64 = 0.0, Kind::Double(false), runtime,
        "Plan service and action: weight of the risk term, this x the sum over control steps \
         of the free particles' mean spread along each candidate's rollout (needs an ensemble, \
         train --ensemble K; 0 = none)";
    /// Retrain when the drift alarm is raised: warm-start the served model on
    /// what is recorded after the alarm, swapped in only if it beats the old
    /// one on the most recent (held-out) recording.
    accuracy_retrain: bool = false, Kind::Bool, runtime,
        "on a drift alarm, warm-start the served model on what is recorded next (needs \
         record_dir); swapped in only if it beats the old model on held-out recent data";
    /// Seconds recorded after the alarm before retraining.
    accuracy_retrain_after: f64 = 5.0, Kind::Double(true), runtime,
        "seconds recorded after a drift alarm before retraining (bags split by \
         record_split_seconds; the last is held out)";
    /// Epochs of a retraining.
    accuracy_retrain_epochs: u32 = 3000, Kind::Int(1, 1_000_000), runtime,
        "epochs of a retraining after a drift alarm";
    /// Publish (and record) a MarkerArray of predictions for RViz/Foxglove.
    markers: bool = true, Kind::Bool, runtime,
        "publish and record a visualization_msgs/MarkerArray of predictions (particles, \
         edges, predicted paths, forces) for RViz and Foxglove";
    /// Topic of the MarkerArray.
    markers_topic: String = topics::MARKERS_TOPIC.into(), Kind::Topic, restart,
        "topic of the MarkerArray";
    /// Minimum seconds between two MarkerArrays (0: one per prediction).
    markers_period: f64 = 0.1, Kind::Double(false), runtime,
        "minimum seconds between two MarkerArrays (0 = one per prediction)";
    /// An input more than this many training scales out (velocity, position
    /// when the model reads it, edge vector, edge parameters) counts as
    /// `out_of_range` (0: never checked).
    out_of_range_sigmas: f64 = crate::compat::OUT_OF_RANGE_SIGMAS, Kind::Double(false), runtime,
        "a state with an input (velocity, position, edge vector, edge parameter) more than \
         this many training scales out counts as out_of_range in the diagnostics and is \
         warned about (0 = never checked)";
    /// Refuse out-of-range states (counted as rejected too) instead of
    /// predicting them with a warning.
    out_of_range_refuse: bool = false, Kind::Bool, runtime,
        "refuse out-of-range states (counted as rejected) instead of predicting them with a \
         warning";
    /// Start as an unconfigured managed node (predict only after configure
    /// and activate through the lifecycle services); read at start.
    lifecycle: bool = false, Kind::Bool, restart,
        "start as an unconfigured managed node: predict only after configure and activate \
         (lifecycle_msgs services /mcgnode/change_state ...); false: start active. Read at start";
    /// Velocity estimate of position-only streams: "none" (three-point
    /// difference at the newest state), "poly" (local polynomial fit) or
    /// "model" (fitted through the served model's rollout).
    velocity_smoother: String = "none".into(), Kind::Choice(crate::data::stream::SMOOTHERS), runtime,
        "velocities of position-only states (empty velocities): none = three-point difference \
         at the newest state (3 states of warm-up); poly = least-squares polynomial over the \
         last smoother_window states, evaluated at the newest stamp (no lag; averages tracker \
         noise); model = the start of the last smoother_window states fitted through the \
         served model's rollout (GNODE family, no kinematic particles)";
    /// States in a poly or model smoother's fit (also its warm-up).
    smoother_window: u32 = 15, Kind::Int(3, 1000), runtime,
        "poly and model smoothers: states in the fit, also its warm-up (poly: at least \
         smoother_order + 2; model: at least 4)";
    /// Degree of a poly smoother's polynomial.
    smoother_order: u32 = 2, Kind::Int(1, 4), runtime,
        "poly smoother: degree of the polynomial";
    /// Wall time one model-smoother fit may take (seconds).
    smoother_budget: f64 = 0.004, Kind::Double(true), runtime,
        "model smoother: seconds one fit may take (it starts no iteration that would pass it \
         and keeps its best state; at most 8 iterations)";
    /// A gap longer than this (seconds) between two states of a stream
    /// starts its history over (0: never).
    input_max_gap: f64 = 0.5, Kind::Double(false), runtime,
        "seconds between two states of a stream beyond which its history starts over (0 = \
         never)";
    /// Input streams (trajectory ids) followed at once; the least recently
    /// seen is dropped first.
    input_max_streams: u32 = 64, Kind::Int(1, 100_000), runtime,
        "input streams (trajectory ids) followed at once for velocities and live accuracy; \
         the least recently seen is dropped";
}

/// The words `input_qos` takes (see [`super::qos::input_qos`]).
pub const INPUT_QOS: &[&str] = &["topics", "reliable", "best_effort", "sensor_data"];

/// What a parameter holds, for type checking and messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Any text.
    Str,
    /// A ROS 2 name: absolute, relative to the namespace, or private (`~/`).
    Topic,
    /// A ROS 2 name as [`Kind::Topic`], or empty (off).
    OptTopic,
    /// `true` or `false`.
    Bool,
    /// An integer in `lo..=hi`.
    Int(u32, u32),
    /// A finite double, strictly positive when `true`, else ≥ 0.
    Double(bool),
    /// A list of at most this many finite doubles > 0.
    Doubles(usize),
    /// One of these words.
    Choice(&'static [&'static str]),
}

impl NodeParams {
    /// The timing of the node's predictions: `horizon` states `dt` apart,
    /// integrated with `dt / substeps`.
    pub fn timing(&self) -> crate::dynamics::Timing {
        crate::dynamics::Timing::new(self.dt, self.substeps as usize, self.horizon as usize)
    }

    /// The model smoother's bounds on one fit: at most 8 iterations and
    /// `smoother_budget`, integrated at the node's step.
    pub fn fit_options(&self) -> crate::estimate::FitOptions {
        crate::estimate::FitOptions {
            budget: std::time::Duration::from_secs_f64(self.smoother_budget),
            ..crate::estimate::FitOptions::with_dt(self.timing().step())
        }
    }

    /// The parameters as a ROS 2 parameter file (what `serve --print-params` prints).
    pub fn to_yaml(&self) -> String {
        let mut s = format!("{NODE_NAME}:\n  ros__parameters:\n");
        for Spec { name, doc, .. } in SPECS {
            s.push_str(&format!(
                "    # {doc}\n    {name}: {}\n",
                self.value_text(name)
            ));
        }
        s
    }

    /// The value of `key` as parameter-file text (strings quoted).
    pub fn value_text(&self, key: &str) -> String {
        match spec(key).map(|s| s.kind) {
            Some(Kind::Str | Kind::Topic | Kind::OptTopic | Kind::Choice(_)) => {
                format!("{:?}", self.raw_value(key))
            }
            _ => self.raw_value(key),
        }
    }

    /// The value of `key` as text, strings unquoted ("" for an unknown key).
    pub fn raw_value(&self, key: &str) -> String {
        match self.value(key) {
            Some(ParamValue::Str(x)) => x.to_string(),
            Some(ParamValue::Bool(x)) => x.to_string(),
            Some(ParamValue::Int(x)) => x.to_string(),
            Some(ParamValue::Double(x)) => format!("{x:?}"),
            Some(ParamValue::Doubles(xs)) => {
                let xs: Vec<String> = xs.iter().map(|x| format!("{x:?}")).collect();
                format!("[{}]", xs.join(", "))
            }
            None => String::new(),
        }
    }
}

/// The table's entry for `key`.
pub fn spec(key: &str) -> Option<&'static Spec> {
    SPECS.iter().find(|s| s.name == key)
}

/// Whether parameter `key` can change while the node runs ([`Spec::runtime`]).
pub fn runtime_settable(key: &str) -> bool {
    spec(key).is_some_and(|s| s.runtime)
}

/// The names of the parameters settable at run time, in table order.
pub fn runtime_settable_names() -> Vec<&'static str> {
    SPECS.iter().filter(|s| s.runtime).map(|s| s.name).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each kind in the table fits its field's type, so `set` stores every
    /// checked value (a mismatch would be dropped by `put`).
    #[test]
    fn every_kind_fits_its_field() {
        let p = NodeParams::default();
        for Spec { name, kind, .. } in SPECS {
            let fits = matches!(
                (kind, p.value(name)),
                (
                    Kind::Str | Kind::Topic | Kind::OptTopic | Kind::Choice(_),
                    Some(ParamValue::Str(_))
                ) | (Kind::Bool, Some(ParamValue::Bool(_)))
                    | (Kind::Int(..), Some(ParamValue::Int(_)))
                    | (Kind::Double(_), Some(ParamValue::Double(_)))
                    | (Kind::Doubles(_), Some(ParamValue::Doubles(_)))
            );
            assert!(fits, "{name}: {kind:?} does not fit {:?}", p.value(name));
        }
        assert!(p.value("horizn").is_none());
        let names: std::collections::BTreeSet<_> = SPECS.iter().map(|s| s.name).collect();
        assert_eq!(names.len(), SPECS.len(), "a name twice in the table");
    }
}
