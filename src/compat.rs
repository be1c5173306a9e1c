//! Does a model fit the data? What a model was trained on (dimension, field,
//! edge kinds, closed or not), compared with a graph and the field its data
//! state. `train`, `evaluate`, `replay`, `rollout` and the node refuse a
//! mismatch with the reason instead of predicting nonsense (a pendulum state
//! sent to a spring model, a 3D state to a 2D model, a closed-system model on
//! data under gravity).

use std::path::Path;

use crate::physics::{Field, SystemConfig, SystemKind};
use crate::system::{EdgeKind, Graph};

/// What a model was trained on, as far as its file tells (`None`: unknown,
/// not checked).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TrainedFor {
    /// The model, for messages.
    pub model: String,
    /// Spatial dimension.
    pub dim: Option<usize>,
    /// The field of the training data.
    pub field: Option<Field>,
    /// Whether the training data had springs, bars and anchors.
    pub edges: Option<EdgeKinds>,
    /// Whether the model assumes a closed system (no anchors, no field):
    /// MCGNODE without its body-force branch conserves momentum exactly.
    pub closed: Option<bool>,
    /// The edge kinds (rest length, stiffness) it was trained on, when it
    /// cannot read them as inputs (no edge physics): other edges are refused.
    pub edge_params: Option<Vec<crate::gnode::file::EdgeParams>>,
    /// The file records neither its training edges nor a system they follow
    /// from, and the model cannot read edges: graphs with particle edges are
    /// refused, naming the fix.
    pub edges_unrecorded: bool,
    /// The inputs it saw in training (`None`: its file stores no scales).
    pub range: Option<InputRange>,
}

/// The kinds of edge in a graph.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EdgeKinds {
    /// Springs between particles.
    pub springs: bool,
    /// Rigid bars (between particles or to anchors).
    pub bars: bool,
    /// Anchors (fixed points).
    pub anchors: bool,
}

impl EdgeKinds {
    /// The kinds present in `graph`.
    pub fn of(graph: &Graph) -> EdgeKinds {
        EdgeKinds {
            springs: graph.edges.iter().any(|e| e.kind == EdgeKind::Spring),
            bars: graph.edges.iter().any(|e| e.kind == EdgeKind::Bar),
            anchors: !graph.anchors.is_empty(),
        }
    }

    /// The kinds the simulator's system has.
    pub fn of_kind(kind: SystemKind) -> EdgeKinds {
        match kind {
            SystemKind::Spring
            | SystemKind::Peridynamic
            | SystemKind::CollidingLattices
            | SystemKind::HeldChain => EdgeKinds {
                springs: true,
                bars: false,
                anchors: false,
            },
            // Contacts are rebuilt from positions: not among the fixed kinds.
            SystemKind::SoftSpheres | SystemKind::PeriodicSpheres => EdgeKinds::default(),
            SystemKind::FallingChain => EdgeKinds {
                springs: false,
                bars: true,
                anchors: false,
            },
            SystemKind::Pendulum => EdgeKinds {
                springs: false,
                bars: true,
                anchors: true,
            },
        }
    }

    fn words(self) -> String {
        let mut w = vec![];
        if self.springs {
            w.push("springs");
        }
        if self.bars {
            w.push("rigid bars");
        }
        if self.anchors {
            w.push("anchors");
        }
        if w.is_empty() {
            "no edges".into()
        } else {
            w.join(", ")
        }
    }
}

impl TrainedFor {
    /// What a model file (GNODE family or baseline, JSON) says: `hyper.dim`
    /// or `trained_on.dim`, `trained_on.system_config` (its field and system
    /// kind), and an MCGNODE's `hyper.body_force`.
    pub fn from_model_json(model: &str, v: &serde_json::Value) -> TrainedFor {
        let t = &v["trained_on"];
        let dim = t["dim"]
            .as_u64()
            .or(v["hyper"]["dim"].as_u64())
            .map(|d| d as usize);
        let cfg: Option<SystemConfig> = t
            .get("system_config")
            .filter(|c| !c.is_null())
            .and_then(|c| serde_json::from_value(c.clone()).ok());
        let closed = match (
            v["hyper"]["variant"].as_str(),
            v["hyper"]["body_force"].as_bool(),
        ) {
            (Some("mcgnode"), Some(false)) => Some(true),
            _ => None,
        };
        let edge_physics = v["hyper"]["edge_physics"].as_bool().unwrap_or(false);
        // The edges it was trained on: as recorded, else (files written before
        // the record) those of the simulator's system it was trained on.
        let edge_params: Option<Vec<crate::gnode::file::EdgeParams>> = t
            .get("edge_params")
            .and_then(|e| serde_json::from_value(e.clone()).ok())
            .filter(|e: &Vec<_>| !e.is_empty())
            .or_else(|| {
                cfg.as_ref()
                    .map(|c| crate::gnode::file::EdgeParams::of(&c.graph()))
                    .filter(|e| !e.is_empty())
            })
            .filter(|_| !edge_physics);
        // NODE is not a graph model: it reads no edges, so none can mislead it.
        let graph_model = v["hyper"]["variant"].as_str() != Some("node");
        TrainedFor {
            model: model.to_string(),
            dim,
            field: cfg.as_ref().map(|c| c.field.normalized()),
            edges: cfg.as_ref().map(|c| EdgeKinds::of_kind(c.kind)),
            closed,
            edges_unrecorded: edge_params.is_none() && !edge_physics && graph_model,
            edge_params,
            range: InputRange::from_model_json(v),
        }
    }

    /// Reads a model file's training description.
    pub fn from_model_file(path: &Path) -> crate::error::Result<TrainedFor> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| crate::error::err!("cannot read model file {}: {e}", path.display()))?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| crate::error::err!("model file {} is not JSON: {e}", path.display()))?;
        Ok(Self::from_model_json(&path.display().to_string(), &v))
    }

    /// The ground truth of a system kind: any graph, the system's field.
    pub fn truth(model: &str, field: Field) -> TrainedFor {
        TrainedFor {
            model: model.to_string(),
            field: Some(field),
            ..TrainedFor::default()
        }
    }

    /// Refuses a graph (and the field its data state, when known) the model
    /// was not trained for; the error says what differs.
    pub fn check(&self, graph: &Graph, field: Option<&Field>) -> Result<(), Mismatch> {
        let m = &self.model;
        if let Some(d) = self.dim {
            if d != graph.dim {
                return Err(Mismatch::Dimension {
                    model: m.clone(),
                    trained: d,
                    data: graph.dim,
                });
            }
        }
        let have = EdgeKinds::of(graph);
        if let Some(e) = self.edges {
            let new_kind = (have.springs && !e.springs) || (have.bars && !e.bars);
            if new_kind || have.anchors != e.anchors {
                return Err(Mismatch::Edges {
                    model: m.clone(),
                    trained: e.words(),
                    data: have.words(),
                });
            }
        }
        if let Some(known) = &self.edge_params {
            let words = |p: &crate::gnode::file::EdgeParams| {
                format!(
                    "{:?} (rest length {}, stiffness {})",
                    p.kind, p.rest_length, p.stiffness
                )
            };
            if let Some(p) = crate::gnode::file::EdgeParams::of(graph)
                .iter()
                .find(|p| !known.iter().any(|k| k.same(p)))
            {
                return Err(Mismatch::EdgeParams {
                    model: m.clone(),
                    trained: known.iter().map(words).collect::<Vec<_>>().join(", "),
                    data: words(p),
                });
            }
        }
        if self.edges_unrecorded && graph.particle_edges().next().is_some() {
            return Err(Mismatch::EdgesUnrecorded { model: m.clone() });
        }
        if self.closed == Some(true) && have.anchors {
            return Err(Mismatch::NotClosed {
                model: m.clone(),
                data: "have anchors".into(),
            });
        }
        if let Some(data) = field {
            if self.closed == Some(true) && !data.is_free() {
                return Err(Mismatch::NotClosed {
                    model: m.clone(),
                    data: format!("state {}", describe(data)),
                });
            }
            if let Some(trained) = &self.field {
                if trained.normalized() != data.normalized() {
                    return Err(Mismatch::Field {
                        model: m.clone(),
                        trained: describe(trained),
                        data: describe(data),
                    });
                }
            }
        }
        Ok(())
    }
}

/// How data differ from what a model was trained on; the message names both.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Mismatch {
    /// Another spatial dimension.
    #[error("model {model} was trained on {trained}D data; these are {data}D")]
    Dimension {
        /// The model.
        model: String,
        /// Its training data's dimension.
        trained: usize,
        /// The data's.
        data: usize,
    },
    /// Edge kinds (springs, bars, anchors) it was not trained on.
    #[error("model {model} was trained on a system with {trained}; these data have {data}")]
    Edges {
        /// The model.
        model: String,
        /// Its training data's edge kinds, in words.
        trained: String,
        /// The data's.
        data: String,
    },
    /// An edge (rest length, stiffness) it was not trained on and cannot read.
    #[error(
        "model {model} was trained on edges {trained}; these data have a {data}; a model \
         trained with --edge-physics reads each edge's rest length and stiffness"
    )]
    EdgeParams {
        /// The model.
        model: String,
        /// The edges it was trained on, in words.
        trained: String,
        /// The data's unknown edge.
        data: String,
    },
    /// A model file that records neither the edges it was trained on nor a
    /// system they follow from, and cannot read edges: any stiffness or rest
    /// length would be predicted as if it were the training one.
    #[error(
        "model {model} does not record the edges (rest lengths, stiffnesses) it was trained \
         on and cannot read them, so it would predict any edge as if it were a training one: \
         retrain it with this version (`mcgnode train` records them), or train with \
         --edge-physics so the model reads each edge"
    )]
    EdgesUnrecorded {
        /// The model.
        model: String,
    },
    /// A closed-system model on data with anchors or a field.
    #[error(
        "model {model} assumes a closed system (MCGNODE without its body-force branch); \
         these data {data}"
    )]
    NotClosed {
        /// The model.
        model: String,
        /// What the data have ("have anchors", "state gravity ...").
        data: String,
    },
    /// Another field than its training data's.
    #[error("model {model} was trained with {trained}; these data state {data}")]
    Field {
        /// The model.
        model: String,
        /// Its training data's field, in words.
        trained: String,
        /// The data's.
        data: String,
    },
}

/// A field in words.
fn describe(f: &Field) -> String {
    if f.is_free() {
        "no field (gravity, drag and force all 0)".into()
    } else {
        format!(
            "gravity {}, drag {}, force {:?}",
            f.gravity, f.drag, f.force
        )
    }
}

/// The last few systems a [`TrainedFor::check`] passed for (each a graph, a
/// field and a key naming the model), so that a stream of states of one
/// system is checked once, not once per state, even between another
/// stream's: the next state of a system passed costs a comparison. Any
/// other graph, field or key is checked in full.
#[derive(Debug, Default)]
pub struct Passed {
    last: std::sync::Mutex<Vec<(u64, Graph, Option<Field>)>>,
    full: std::sync::atomic::AtomicU64,
}

impl Passed {
    /// Systems remembered (a node's streams, as the kernel's workspaces).
    const SYSTEMS: usize = 4;

    /// [`TrainedFor::check`] of `graph` and `field` for the model `key`
    /// names, skipped when one of the last that passed was the same.
    pub fn check(
        &self,
        key: u64,
        trained: &TrainedFor,
        graph: &Graph,
        field: Option<&Field>,
    ) -> Result<(), Mismatch> {
        let same = |(k, g, f): &(u64, Graph, Option<Field>)| {
            *k == key && g == graph && f.as_ref() == field
        };
        if self.last.lock().is_ok_and(|l| l.iter().any(same)) {
            return Ok(());
        }
        self.full.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        trained.check(graph, field)?;
        if let Ok(mut l) = self.last.lock() {
            l.insert(0, (key, graph.clone(), field.cloned()));
            l.truncate(Self::SYSTEMS);
        }
        Ok(())
    }

    /// How many checks ran in full.
    pub fn full_checks(&self) -> u64 {
        self.full.load(std::sync::atomic::Ordering::Relaxed)
    }
}

/// Checks every distinct graph of a bag (and the field its data state, when
/// known) against what a model was trained on; the error names the trajectory.
pub fn check_bag(
    trained: &TrainedFor,
    bag: &crate::data::Bag,
    field: Option<&Field>,
) -> crate::error::Result<()> {
    let mut seen: Vec<&Graph> = vec![];
    for tr in &bag.trajectories {
        if seen.contains(&&tr.graph) {
            continue;
        }
        trained
            .check(&tr.graph, field)
            .map_err(|e| crate::error::err!("trajectory {}: {e}", tr.id))?;
        seen.push(&tr.graph);
    }
    Ok(())
}

/// Training scales beyond which an input counts as out of range, by default.
pub const OUT_OF_RANGE_SIGMAS: f64 = 10.0;

/// Training scales beyond which an input is refused whatever
/// `out_of_range_refuse` says: no model extrapolates that far meaningfully.
pub const ABSURD_SIGMAS: f64 = 1e6;

/// Largest position or velocity component predicted from, in any model's
/// units: beyond it squares and products of coordinates overflow.
pub const ABSURD_MAGNITUDE: f64 = 1e100;

/// Largest drift of a momentum-conserving model's predicted total momentum
/// from its input's, relative to the states' momentum scale (the larger of
/// the input's and each predicted state's sum of |m v|): pairwise forces
/// keep it to round-off (about 1e-13 over a 100-step prediction), so a
/// larger drift is a prediction broken by overflow or lost precision.
pub const CONSERVATION_TOLERANCE: f64 = 1e-6;

/// The range of inputs a model saw in training, from the scales its file
/// stores ([`crate::gnode::Norm`]: RMS position about the mean, velocity,
/// edge vector, stiffness): an input many scales beyond them is outside
/// anything it learned from, and its prediction is an extrapolation.
#[derive(Clone, Debug, PartialEq)]
pub struct InputRange {
    /// The training scales.
    pub norm: crate::gnode::Norm,
    /// The model reads absolute positions (GNODE-style node inputs, or a
    /// body-force branch); otherwise only differences, and positions are
    /// not checked.
    pub reads_positions: bool,
    /// The model reads each edge's rest length and stiffness.
    pub edge_physics: bool,
}

/// An input outside a model's training range.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error(
    "{what} {value:.3e} is {times:.3e} training scales (scale {scale:.3e}; the limit is {limit}): \
     outside anything the model was trained on"
)]
pub struct OutOfRange {
    /// Which input ("velocity component of particle 3", ...).
    pub what: String,
    /// Its value.
    pub value: f64,
    /// The training scale it is measured in.
    pub scale: f64,
    /// `value / scale`.
    pub times: f64,
    /// The limit, in training scales.
    pub limit: f64,
}

impl InputRange {
    /// The range a model file states (`None`: no scales stored, as in files
    /// trained with --no-normalize or before scales existed, and baselines).
    pub fn from_model_json(v: &serde_json::Value) -> Option<InputRange> {
        let hyper: crate::gnode::Hyper = serde_json::from_value(v["hyper"].clone()).ok()?;
        let norm = hyper.norm.clone()?;
        let arch = crate::gnode::Arch::new(&hyper);
        let reads_positions = arch.node_input == crate::gnode::arch::NodeInput::Full
            || arch
                .mlps
                .iter()
                .any(|(b, _)| *b == crate::gnode::arch::Block::GlobalEmbed);
        Some(InputRange {
            norm,
            reads_positions,
            edge_physics: hyper.edge_physics,
        })
    }

    /// The first input of `state` on `graph` more than `limit` training
    /// scales out, if any (`limit` ≤ 0: none is checked). Non-finite inputs
    /// count as infinitely far.
    pub fn check(
        &self,
        graph: &Graph,
        state: &crate::system::State,
        limit: f64,
    ) -> Option<OutOfRange> {
        if limit.is_nan() || limit <= 0.0 {
            return None;
        }
        let d = graph.dim.max(1);
        let n = &self.norm;
        // The description is built only for the input reported: the node
        // checks every state, and most are in range.
        let far = |value: f64, scale: f64, what: &dyn Fn() -> String| {
            let times = (value / scale).abs();
            // NaN compares false: a non-finite input is never in range.
            let inside = times <= limit;
            (!inside).then(|| OutOfRange {
                what: what(),
                value,
                scale,
                times,
                limit,
            })
        };
        for (k, &x) in state.v.iter().enumerate() {
            let what = || format!("velocity component of particle {}", k / d);
            if let Some(o) = far(x, n.v_scale, &what) {
                return Some(o);
            }
        }
        if self.reads_positions {
            for (k, &x) in state.q.iter().enumerate() {
                let mean = n.q_mean.get(k % d).copied().unwrap_or(0.0);
                let what = || {
                    format!(
                        "position component of particle {} (about the training mean)",
                        k / d
                    )
                };
                if let Some(o) = far(x - mean, n.q_scale, &what) {
                    return Some(o);
                }
            }
        }
        for (i, (a, b, e)) in graph.particle_edges().enumerate() {
            for c in 0..d {
                let w = state.q.get(a * d + c).copied().unwrap_or(0.0)
                    - state.q.get(b * d + c).copied().unwrap_or(0.0);
                let what = || format!("edge vector component of edge {i} ({a}-{b})");
                if let Some(o) = far(w, n.w_scale, &what) {
                    return Some(o);
                }
            }
            if !self.edge_physics {
                continue;
            }
            if e.kind == EdgeKind::Spring {
                if e.stiffness <= 0.0 {
                    return Some(OutOfRange {
                        what: format!("stiffness of edge {i} ({a}-{b}), not positive,"),
                        value: e.stiffness,
                        scale: n.k_scale,
                        times: e.stiffness / n.k_scale,
                        limit,
                    });
                }
                let what = || format!("stiffness of edge {i} ({a}-{b})");
                if let Some(o) = far(e.stiffness, n.k_scale, &what) {
                    return Some(o);
                }
            }
            let what = || format!("rest length of edge {i} ({a}-{b})");
            if let Some(o) = far(e.rest_length, n.w_scale, &what) {
                return Some(o);
            }
        }
        None
    }
}

/// How many states of a bag lie outside a model's training range, with the
/// first one's trajectory, step and reason.
pub fn count_out_of_range(
    range: &InputRange,
    bag: &crate::data::Bag,
    limit: f64,
) -> (usize, usize, Option<String>) {
    let (mut count, mut total, mut first) = (0, 0, None);
    for tr in &bag.trajectories {
        for (k, s) in tr.samples.iter().enumerate() {
            total += 1;
            if let Some(o) = range.check(&tr.graph, &s.state, limit) {
                count += 1;
                first.get_or_insert_with(|| format!("trajectory {}, state {k}: {o}", tr.id));
            }
        }
    }
    (count, total, first)
}
