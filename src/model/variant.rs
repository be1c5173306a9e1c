//! The model family and its hyperparameters. Each graph variant adds one
//! inductive bias to the previous one (paper, appendix "Graph Architectures"):
//! GNODE → CGNODE (+ constrained equation of motion, learnable masses) →
//! CDGNODE (+ decoupled body forces) → MCGNODE (+ pairwise forces, Newton's third law).

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

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

impl fmt::Display for Variant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Variant {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .iter()
            .copied()
            .find(|v| v.name() == s.to_ascii_lowercase())
            .ok_or_else(|| {
                format!(
                    "unknown model {s:?}; expected one of node, gnode, cgnode, cdgnode, mcgnode"
                )
            })
    }
}

/// Message and edge-update functions of a message-passing round.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum MessageFn {
    /// One linear map (the paper's equations).
    Linear,
    /// An MLP with the graph MLPs' hidden layers (the authors' code).
    Mlp,
}

/// What the edge update W_E reads from the two end nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum EdgeInput {
    /// h_i ‖ h_j (the paper's equation).
    Concat,
    /// h_i ⊙ h_j (the authors' code).
    Product,
}

/// Architecture presets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ArchPreset {
    /// What the authors' code ran, behind the paper's numbers: two hidden
    /// layers per MLP, MLP message functions, h_i ⊙ h_j in the edge update.
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

fn one() -> usize {
    1
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
}

impl Hyper {
    /// Applies an architecture preset.
    pub fn with_preset(mut self, preset: ArchPreset) -> Self {
        (self.hidden_layers, self.message, self.edge_input) = preset.settings();
        self
    }

    /// Defaults for a variant: the paper's sizes with the authors' architecture
    /// ([`ArchPreset::Authors`]).
    pub fn new(variant: Variant, dim: usize, types: usize, particles: usize) -> Self {
        let (hidden_layers, message, edge_input) = ArchPreset::Authors.settings();
        Self {
            variant,
            dim,
            types: types.max(1),
            hidden: 5,
            embed: 5,
            rounds: 1,
            body_force: true,
            node_hidden: 16,
            node_layers: 2,
            particles,
            hidden_layers,
            message,
            edge_input,
            block_hidden: Default::default(),
        }
    }
}
