//! The model family and its hyperparameters. Each graph variant adds one
//! inductive bias to the previous one (paper, appendix "Graph Architectures"):
//! GNODE → CGNODE (+ constrained equation of motion, learnable masses) →
//! CDGNODE (+ decoupled body forces) → MCGNODE (+ pairwise forces, Newton's third law).

use serde::{Deserialize, Serialize};

/// A model of the family.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Variant {
    /// Neural ODE: an MLP over the flattened state (fixed particle count).
    Node,
    /// Graph neural ODE: message passing, node outputs are accelerations.
    Gnode,
    /// Constrained GNODE: node outputs are forces, q̈ from the constrained equation.
    Cgnode,
    /// Constrained and decoupled: body forces from (type, q, q̇) outside message passing.
    Cdgnode,
    /// Momentum-conserving: forces predicted per edge with f_ji = −f_ij.
    Mcgnode,
}

/// The inductive biases a variant switches on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Biases {
    /// Graph network (inductive over system size).
    pub graph: bool,
    /// Forces + constrained equation of motion with learnable diagonal mass.
    pub constrained: bool,
    /// Node position/velocity only in a separate body-force branch.
    pub decoupled: bool,
    /// Pairwise, antisymmetric edge forces.
    pub pairwise: bool,
}

impl Variant {
    /// All variants, in the order of the paper.
    pub const ALL: [Variant; 5] = [
        Variant::Node,
        Variant::Gnode,
        Variant::Cgnode,
        Variant::Cdgnode,
        Variant::Mcgnode,
    ];

    /// The biases of this variant: each one is the previous plus one.
    pub fn biases(self) -> Biases {
        let rank = Self::ALL.iter().position(|v| *v == self).unwrap_or(0);
        Biases {
            graph: rank >= 1,
            constrained: rank >= 2,
            decoupled: rank >= 3,
            pairwise: rank >= 4,
        }
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Node => "node",
            Variant::Gnode => "gnode",
            Variant::Cgnode => "cgnode",
            Variant::Cdgnode => "cdgnode",
            Variant::Mcgnode => "mcgnode",
        }
    }
}

impl crate::names::Named for Variant {
    const ALL: &'static [Self] = &Variant::ALL;
    const WHAT: &'static str = "model";

    fn name(self) -> &'static str {
        Variant::name(self)
    }
}

crate::impl_named!(Variant);

/// Message and edge-update functions of a message-passing round.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MessageFn {
    /// One linear map (the paper's equations).
    Linear,
    /// An MLP with the graph MLPs' hidden layers (the authors' code).
    Mlp,
}

/// What the edge update W_E reads from the two end nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EdgeInput {
    /// h_i ‖ h_j (the paper's equation).
    Concat,
    /// h_i ⊙ h_j (the authors' code).
    Product,
}

/// Architecture presets.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ArchPreset {
    /// What the authors' code ran, behind the paper's numbers: two hidden
    /// layers per MLP, MLP message functions, h_i ⊙ h_j in the edge update
    /// (the default).
    #[default]
    Authors,
    /// The paper's text: one hidden layer, linear message functions, h_i ‖ h_j.
    Paper,
}

impl ArchPreset {
    /// (hidden layers, message functions, edge-update input) of the preset.
    pub fn settings(self) -> (usize, MessageFn, EdgeInput) {
        match self {
            ArchPreset::Authors => (2, MessageFn::Mlp, EdgeInput::Product),
            ArchPreset::Paper => (1, MessageFn::Linear, EdgeInput::Concat),
        }
    }
}

/// Input and output scales from the training split (GNS-style
/// normalisation): node inputs are ((q − μ_q)/σ_q, q̇/σ_v), edge inputs
/// (q_i − q_j)/σ_w, and the network's outputs (accelerations or forces) are
/// multiplied by σ_a. Scalars (one per quantity, not per axis) keep the
/// models' symmetries: edge inputs and pairwise forces stay antisymmetric.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Norm {
    /// Mean position per axis.
    pub q_mean: Vec<f64>,
    /// Position scale.
    pub q_scale: f64,
    /// Velocity scale.
    pub v_scale: f64,
    /// Edge-vector scale.
    pub w_scale: f64,
    /// Output scale (accelerations; forces for constrained variants).
    pub out_scale: f64,
    /// Edge-stiffness scale (edge-physics inputs; rest lengths use `w_scale`).
    #[serde(default = "one_f64")]
    pub k_scale: f64,
}

fn one_f64() -> f64 {
    1.0
}

impl Norm {
    /// No scaling.
    pub fn identity(dim: usize) -> Self {
        Self {
            q_mean: vec![0.0; dim],
            q_scale: 1.0,
            v_scale: 1.0,
            w_scale: 1.0,
            out_scale: 1.0,
            k_scale: 1.0,
        }
    }

    /// Statistics of states (on `graph`'s particle edges, and its contact
    /// edges at each state) and their target accelerations; velocities and
    /// accelerations of the free particles only (kinematic ones are given).
    /// A zero or non-finite spread gives scale 1.
    pub fn from_data(
        graph: &crate::system::Graph,
        states: &[&crate::system::State],
        targets: &[&[f64]],
    ) -> Self {
        let d = graph.dim;
        let scale = |sum2: f64, count: usize| {
            let s = (sum2 / count.max(1) as f64).sqrt();
            if s.is_finite() && s > 0.0 {
                s
            } else {
                1.0
            }
        };
        let mut q_mean = vec![0.0; d];
        let mut count = 0usize;
        for s in states {
            for (i, x) in s.q.iter().enumerate() {
                q_mean[i % d] += x;
            }
            count += s.q.len() / d;
        }
        q_mean.iter_mut().for_each(|m| *m /= count.max(1) as f64);
        let (mut q2, mut v2, mut w2, mut a2) = (0.0, 0.0, 0.0, 0.0);
        let mut edges = 0usize;
        let mut search = crate::physics::neighbors::NeighborSearch::new(graph);
        for s in states {
            for (i, x) in s.q.iter().enumerate() {
                q2 += (x - q_mean[i % d]).powi(2);
            }
            // Velocities of the free particles: kinematic walls at rest would
            // shrink the scale below the speeds the model must read.
            v2 += (0..s.v.len())
                .filter(|f| !graph.is_kinematic(f / d))
                .map(|f| s.v[f] * s.v[f])
                .sum::<f64>();
            for (a, b, _) in graph.particle_edges() {
                for c in 0..d {
                    w2 += (s.q[a * d + c] - s.q[b * d + c]).powi(2);
                }
                edges += 1;
            }
            // Contact edges are edges too: a box of soft spheres has no other.
            if graph.has_contacts() {
                for &(a, b) in search.search(&s.q, d, graph.interaction_radius) {
                    for c in 0..d {
                        w2 += (s.q[a * d + c] - s.q[b * d + c]).powi(2);
                    }
                    edges += 1;
                }
            }
        }
        // Kinematic particles' accelerations are given, never predicted.
        let free = |f: &usize| !graph.is_kinematic(f / d);
        let mut outputs = 0usize;
        for t in targets {
            a2 += (0..t.len()).filter(free).map(|f| t[f] * t[f]).sum::<f64>();
            outputs += (0..t.len()).filter(free).count();
        }
        let n = states.iter().map(|s| s.q.len()).sum::<usize>();
        let n_free = states.len() * (graph.n() - graph.n_kinematic()) * d;
        Self {
            q_mean,
            q_scale: scale(q2, n),
            v_scale: scale(v2, n_free),
            w_scale: scale(w2, edges * d),
            out_scale: scale(a2, outputs),
            k_scale: scale(
                graph
                    .particle_edges()
                    .map(|(_, _, e)| e.stiffness.powi(2))
                    .sum(),
                graph.particle_edges().count(),
            ),
        }
    }
}

fn one() -> usize {
    1
}

/// Serde's test for leaving a radius of 0 out, so that models without
/// contacts write the same file as before the field existed.
#[allow(clippy::trivially_copy_pass_by_ref)] // serde passes a reference
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

fn linear() -> MessageFn {
    MessageFn::Linear
}

fn concat() -> EdgeInput {
    EdgeInput::Concat
}

/// Architecture hyperparameters (the authors' code by default; model files
/// written before these settings existed load as the paper-text variant they
/// were trained with).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hyper {
    /// Which model.
    pub variant: Variant,
    /// Spatial dimension of the systems it models.
    pub dim: usize,
    /// Number of particle types (one-hot width).
    pub types: usize,
    /// Hidden units of each graph MLP (paper: 5).
    pub hidden: usize,
    /// Node and edge embedding width (paper: 5).
    pub embed: usize,
    /// Message-passing rounds (paper: 1).
    pub rounds: usize,
    /// MCGNODE: learn a body-force branch (external fields). Off for closed
    /// systems, so that momentum is conserved exactly (the paper's theorem).
    pub body_force: bool,
    /// NODE: hidden units per layer (paper: 16) and hidden layers (paper: 2).
    pub node_hidden: usize,
    /// NODE: number of hidden layers.
    pub node_layers: usize,
    /// NODE only: the fixed particle count it was built for.
    pub particles: usize,
    /// Hidden layers of each graph MLP (authors' code: 2; paper text: 1).
    #[serde(default = "one")]
    pub hidden_layers: usize,
    /// Message and edge-update functions.
    #[serde(default = "linear")]
    pub message: MessageFn,
    /// What the edge update reads from its end nodes.
    #[serde(default = "concat")]
    pub edge_input: EdgeInput,
    /// Per-block hidden sizes overriding `hidden` × `hidden_layers`, keyed by
    /// the block's weight prefix (e.g. `edge_out` → [16, 16]).
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub block_hidden: std::collections::BTreeMap<String, Vec<usize>>,
    /// Edges read their rest length and stiffness besides q_i − q_j, so one
    /// model serves springs of several kinds (off: a model refuses graphs whose
    /// edges differ from those it was trained on).
    #[serde(default)]
    pub edge_physics: bool,
    /// Contacts: pairs of particles closer than this interact through edges
    /// found at each state, which the model reads as contacts (an edge input);
    /// 0 (and absent from files written before it existed): fixed edges only.
    /// A model serves only graphs of its radius.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub interaction_radius: f64,
    /// Input and output scales (none: unscaled, as in files written before
    /// normalisation existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub norm: Option<Norm>,
}

impl Hyper {
    /// Hidden units of each graph MLP in the paper (appendix): the width
    /// every graph MLP gets unless a recipe or the user widens it.
    pub const PAPER_HIDDEN: usize = 5;
    /// Node and edge embedding width in the paper.
    pub const PAPER_EMBED: usize = 5;
    /// Message-passing rounds in the paper.
    pub const PAPER_ROUNDS: usize = 1;

    /// Applies an architecture preset.
    pub fn with_preset(mut self, preset: ArchPreset) -> Self {
        (self.hidden_layers, self.message, self.edge_input) = preset.settings();
        self
    }

    /// Defaults for a variant: the paper's sizes with the authors' architecture
    /// ([`ArchPreset::Authors`]).
    pub fn new(variant: Variant, dim: usize, types: usize, particles: usize) -> Self {
        let (hidden_layers, message, edge_input) = ArchPreset::default().settings();
        Self {
            variant,
            dim,
            types: types.max(1),
            hidden: Self::PAPER_HIDDEN,
            embed: Self::PAPER_EMBED,
            rounds: Self::PAPER_ROUNDS,
            body_force: true,
            node_hidden: 16,
            node_layers: 2,
            particles,
            hidden_layers,
            message,
            edge_input,
            block_hidden: Default::default(),
            edge_physics: false,
            interaction_radius: 0.0,
            norm: None,
        }
    }
}
