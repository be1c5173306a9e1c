//! The one typed description of a model's architecture: which blocks (MLPs)
//! exist, their layer sizes and weight names, how node inputs are built and
//! how forces are decoded. The candle model ([`super::net`], the reference)
//! and the engine ([`crate::engine`], the one f64 executor: training, and
//! inference through [`crate::kernel`]) both read it, so adding a bias means
//! changing this description and one stage in each, and no weight name is
//! spelled twice.

use super::variant::{Biases, EdgeInput, Hyper, MessageFn, Norm};
use std::fmt;

use super::graph_plan::GraphPlan;
pub use super::graph_plan::EDGE_PHYSICS;

/// The parameter holding learnable log-masses, one per particle type.
pub const LOG_MASS: &str = "log_mass";

/// One MLP of the architecture.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Block {
    /// NODE: the one MLP over the flattened state (q, q̇).
    Flat,
    /// Node embedding of (one-hot, q, q̇), or of the one-hot alone when decoupled.
    NodeEmbed,
    /// Edge embedding of w_ij = q_i − q_j.
    EdgeEmbed,
    /// Message function W_V over (h_j ‖ h_ij) of a message-passing round.
    Message(usize),
    /// Edge update W_E over (h_i ‖ h_j) of a message-passing round.
    EdgeUpdate(usize),
    /// Global (body) embedding of (one-hot, q, q̇), when decoupled.
    GlobalEmbed,
    /// Node decoder: acceleration or force from h_i (‖ g_i when decoupled).
    NodeDecoder,
    /// Pairwise edge-force decoder (MCGNODE).
    EdgeDecoder,
    /// Body-force decoder of the global embedding (MCGNODE with external fields).
    BodyDecoder,
}

impl Block {
    /// The weight-name prefix of the block, as model files store it.
    pub fn prefix(self) -> String {
        match self {
            Block::Flat => "node".into(),
            Block::NodeEmbed => "node_em".into(),
            Block::EdgeEmbed => "edge_em".into(),
            Block::Message(l) => format!("mp{l}.v"),
            Block::EdgeUpdate(l) => format!("mp{l}.e"),
            Block::GlobalEmbed => "glob_em".into(),
            Block::NodeDecoder => "node_out".into(),
            Block::EdgeDecoder => "edge_out".into(),
            Block::BodyDecoder => "body_out".into(),
        }
    }

    /// Names of the weight matrix and bias of linear layer `i`.
    pub fn layer_names(self, i: usize) -> (String, String) {
        let p = self.prefix();
        (format!("{p}.l{i}.w"), format!("{p}.l{i}.b"))
    }
}

impl fmt::Display for Block {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.prefix())
    }
}

/// What the node embedding reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NodeInput {
    /// (one-hot type, q, q̇).
    Full,
    /// The one-hot type alone (decoupled variants: q and q̇ go to the body branch).
    TypeOnly,
}

/// How the network's output is formed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decoder {
    /// Per node, from h_i (and the global embedding g_i when `global`).
    Node {
        /// The decoder also reads the global embedding.
        global: bool,
    },
    /// Per edge pair, antisymmetrised (Newton's third law), plus a body-force
    /// decoder of the global embedding when `body`.
    Pairwise {
        /// A body-force branch exists.
        body: bool,
    },
}

/// The architecture of one model: every executor is driven by this.
#[derive(Clone, Debug, PartialEq)]
pub struct Arch {
    /// Spatial dimension.
    pub dim: usize,
    /// One-hot width.
    pub types: usize,
    /// Node and edge embedding width.
    pub embed: usize,
    /// Message-passing rounds (0 for NODE).
    pub rounds: usize,
    /// The MLPs with their layer sizes (input first), in definition order.
    pub mlps: Vec<(Block, Vec<usize>)>,
    /// Graph variants: what the node embedding reads.
    pub node_input: NodeInput,
    /// Graph variants: how outputs are decoded.
    pub decoder: Decoder,
    /// Outputs are forces, turned into accelerations by the constrained
    /// equation of motion with learnable masses (`LOG_MASS`).
    pub constrained: bool,
    /// NODE: the particle count it was built for.
    pub particles: usize,
    /// What the edge update reads from its end nodes.
    pub edge_input: EdgeInput,
    /// Input and output scales (identity when the model has none).
    pub norm: Norm,
    /// Edges read (rest length, stiffness) after q_i − q_j.
    pub edge_physics: bool,
    /// Contact edges are found at each state within this radius, and every
    /// edge reads whether it is one (0: fixed edges only, no such input).
    pub radius: f64,
    /// The biases it was derived from.
    pub biases: Biases,
}

impl Arch {
    /// The architecture a set of hyperparameters defines.
    pub fn new(h: &Hyper) -> Self {
        Self::build(h, usize::MAX).expect("any architecture has fewer than usize::MAX layers")
    }

    /// [`Arch::new`] for hyperparameters read from a file: `None` for a
    /// dimension other than 2 or 3, and as soon as the architecture has more
    /// than `max_layers` linear layers, so that a corrupt count (10^15 rounds
    /// or hidden layers) is refused instead of described layer by layer.
    /// Sizes saturate rather than wrap, so a corrupt width shows as a
    /// [`Arch::param_count`] no file holds.
    pub fn within(h: &Hyper, max_layers: usize) -> Option<Self> {
        if !matches!(h.dim, 2 | 3) {
            return None;
        }
        Self::build(h, max_layers)
    }

    fn build(h: &Hyper, max_layers: usize) -> Option<Self> {
        let d = h.dim;
        let b = h.variant.biases();
        let body = b.decoupled && (!b.pairwise || h.body_force);
        let node_input = if b.decoupled {
            NodeInput::TypeOnly
        } else {
            NodeInput::Full
        };
        let decoder = if b.pairwise {
            Decoder::Pairwise { body }
        } else {
            Decoder::Node { global: body }
        };
        let rounds = if b.graph { h.rounds } else { 0 };
        let mut sizer = Sizer {
            h,
            max_layers,
            layers: 0,
        };
        let mlps = if b.graph {
            sizer.graph_mlps(node_input, decoder, body, rounds)?
        } else {
            vec![sizer.flat_mlp()?]
        };
        Some(Self {
            dim: d,
            types: h.types.max(1),
            embed: h.embed,
            rounds,
            mlps,
            node_input,
            decoder,
            constrained: b.constrained,
            particles: h.particles,
            edge_input: h.edge_input,
            norm: h.norm.clone().unwrap_or_else(|| Norm::identity(d)),
            edge_physics: h.edge_physics,
            radius: h.interaction_radius,
            biases: b,
        })
    }

    /// Scalar parameters in all ([`Arch::params`]); `None` if the count
    /// overflows.
    pub fn param_count(&self) -> Option<usize> {
        self.params().iter().try_fold(0usize, |n, (_, shape)| {
            n.checked_add(shape.iter().try_fold(1usize, |p, &x| p.checked_mul(x))?)
        })
    }

    /// Layer sizes of a block, if the architecture has it.
    pub fn sizes(&self, block: Block) -> Option<&[usize]> {
        self.mlps
            .iter()
            .find(|(b, _)| *b == block)
            .map(|(_, s)| s.as_slice())
    }

    /// Whether a model of this architecture can run on `graph`: valid, of its
    /// dimension, with known particle types, and (NODE) of its particle count.
    pub fn supports(&self, graph: &crate::system::Graph) -> Result<(), ArchError> {
        graph.validate()?;
        if graph.dim != self.dim {
            return Err(ArchError::Dimension {
                model: self.dim,
                system: graph.dim,
            });
        }
        if let Some(t) = graph.types.iter().find(|&&t| t as usize >= self.types) {
            return Err(ArchError::UnknownType {
                ty: *t,
                types: self.types,
            });
        }
        if graph.interaction_radius != self.radius {
            return Err(ArchError::Radius {
                model: self.radius,
                system: graph.interaction_radius,
            });
        }
        if !self.biases.graph && graph.periodic().is_some() {
            return Err(ArchError::Periodic);
        }
        if !self.biases.graph && graph.n() != self.particles {
            return Err(ArchError::Particles {
                built: self.particles,
                has: graph.n(),
            });
        }
        Ok(())
    }

    /// Edge input features: q_i − q_j, then the constant inputs
    /// (`EdgeConst`).
    pub fn edge_features(&self) -> usize {
        self.dim + EdgeConst::width_of(self.edge_consts())
    }

    /// Whether the model finds contact edges and reads the contact flag.
    pub fn contacts(&self) -> bool {
        self.radius > 0.0
    }

    /// The constant inputs this model's edges read after w_ij, in order.
    pub fn edge_consts(&self) -> impl Iterator<Item = EdgeConst> {
        EdgeConst::read_by(self.edge_physics, self.radius)
    }

    /// Raw edge-physics inputs (rest length, stiffness) divided by their
    /// scales: a fixed edge's or a contact's.
    pub fn scaled_physics(&self, raw: [f64; EDGE_PHYSICS]) -> [f64; EDGE_PHYSICS] {
        let scale = self.edge_physics_scale();
        std::array::from_fn(|f| raw[f] / scale[f])
    }

    /// What each edge-physics input is divided by: the rest length is a
    /// length like w_ij, the stiffness has its own scale.
    pub fn edge_physics_scale(&self) -> [f64; EDGE_PHYSICS] {
        [self.norm.w_scale, self.norm.k_scale]
    }

    /// Whether the global (body) embedding exists.
    pub fn has_global(&self) -> bool {
        matches!(
            self.decoder,
            Decoder::Node { global: true } | Decoder::Pairwise { body: true }
        )
    }

    /// Every parameter's name and shape, in definition order (the order the
    /// candle store declares them and seeded initialisation draws them).
    pub fn params(&self) -> Vec<(String, Vec<usize>)> {
        let mut out = vec![];
        for (block, sizes) in &self.mlps {
            for (i, w) in sizes.windows(2).enumerate() {
                let (wn, bn) = block.layer_names(i);
                out.push((wn, vec![w[0], w[1]]));
                out.push((bn, vec![w[1]]));
            }
        }
        if self.constrained {
            out.push((LOG_MASS.to_string(), vec![self.types]));
        }
        out
    }

    /// The node features the inputs buffer holds: one-hot, then q and q̇.
    pub fn node_features(&self) -> usize {
        self.types + 2 * self.dim
    }

    /// Whether round `l` must update node states: in the last round a
    /// pairwise decoder reads only edges.
    pub fn updates_nodes(&self, l: usize) -> bool {
        !(l + 1 == self.rounds && matches!(self.decoder, Decoder::Pairwise { .. }))
    }

    /// Whether round `l` must update edge states: in the last round a node
    /// decoder reads only nodes.
    pub fn updates_edges(&self, l: usize) -> bool {
        l + 1 < self.rounds || matches!(self.decoder, Decoder::Pairwise { .. })
    }
}

/// A graph a GNODE-family model cannot run on.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ArchError {
    /// The graph is invalid.
    #[error(transparent)]
    System(#[from] crate::system::SystemError),
    /// A model of absolute positions (NODE) on a periodic box.
    #[error(
        "this model reads absolute positions, which a periodic box wraps: \
         train a graph model (gnode, mcgnode, ...) for a periodic system"
    )]
    Periodic,
    /// The model and the system have different dimensions.
    #[error("model is {model}D, system is {system}D")]
    Dimension {
        /// The model's.
        model: usize,
        /// The system's.
        system: usize,
    },
    /// A particle type the model has no embedding for.
    #[error("particle type {ty} is unknown to the model (it knows {types} types)")]
    UnknownType {
        /// The type.
        ty: u32,
        /// Types the model knows.
        types: usize,
    },
    /// The graph's interaction radius is not the model's.
    #[error(
        "{}",
        radius_mismatch(*model, *system)
    )]
    Radius {
        /// The model's radius (0: trained without contacts).
        model: f64,
        /// The graph's.
        system: f64,
    },
    /// NODE (not inductive) meets another particle count.
    #[error("NODE model is built for {built} particles, system has {has} (NODE is not inductive)")]
    Particles {
        /// The count it was built for.
        built: usize,
        /// The graph's.
        has: usize,
    },
}

crate::error::typed_errors!(ArchError);

/// What a radius mismatch says, with its fix.
fn radius_mismatch(model: f64, system: f64) -> String {
    if model == 0.0 {
        format!(
            "the system has contacts (interaction radius {system}) but the model was trained \
             without them: train one on these data (train --radius {system})"
        )
    } else if system == 0.0 {
        format!(
            "the model finds contacts within radius {model}, the system has none: give the \
             system interaction_radius {model}, or use a model trained without --radius"
        )
    } else {
        format!(
            "the model was trained with interaction radius {model}, the system has {system}: \
             train one for this radius (train --radius {system})"
        )
    }
}

/// Layer sizes of the blocks of one [`Hyper`], counting layers so that a
/// corrupt file's sizes stop at `max_layers` instead of allocating.
struct Sizer<'a> {
    h: &'a Hyper,
    max_layers: usize,
    layers: usize,
}

impl Sizer<'_> {
    fn count(&mut self, n: usize) -> Option<()> {
        self.layers = self.layers.checked_add(n)?;
        (self.layers <= self.max_layers).then_some(())
    }

    /// Layer sizes of a block: its override, or `hidden` × `hidden_layers`
    /// (`hidden` false: one linear layer).
    fn mlp(
        &mut self,
        block: Block,
        inp: usize,
        out: usize,
        hidden: bool,
    ) -> Option<(Block, Vec<usize>)> {
        let h = self.h;
        let over = h.block_hidden.get(&block.prefix());
        self.count(match over {
            Some(hs) => hs.len().checked_add(1)?,
            None if hidden => h.hidden_layers.checked_add(1)?,
            None => 1,
        })?;
        let mut sizes = vec![inp];
        match over {
            Some(hs) => sizes.extend(hs),
            None if hidden => sizes.extend(std::iter::repeat_n(h.hidden, h.hidden_layers)),
            None => {}
        }
        sizes.push(out);
        Some((block, sizes))
    }

    /// The graph models' blocks: embeddings, rounds, body, decoder.
    fn graph_mlps(
        &mut self,
        node_input: NodeInput,
        decoder: Decoder,
        body: bool,
        rounds: usize,
    ) -> Option<Vec<(Block, Vec<usize>)>> {
        let h = self.h;
        let (d, t, em) = (h.dim, h.types.max(1), h.embed);
        let d2 = d.saturating_mul(2);
        let msg_hidden = h.message == MessageFn::Mlp;
        let edge_extra =
            EdgeConst::width_of(EdgeConst::read_by(h.edge_physics, h.interaction_radius));
        let edge_in = match h.edge_input {
            EdgeInput::Concat => em.saturating_mul(2),
            EdgeInput::Product => em,
        };
        let node_in = match node_input {
            NodeInput::TypeOnly => t,
            NodeInput::Full => t.saturating_add(d2),
        };
        let mut mlps = vec![
            self.mlp(Block::NodeEmbed, node_in, em, true)?,
            self.mlp(Block::EdgeEmbed, d.saturating_add(edge_extra), em, true)?,
        ];
        for l in 0..rounds {
            mlps.push(self.mlp(Block::Message(l), em.saturating_mul(2), em, msg_hidden)?);
            mlps.push(self.mlp(Block::EdgeUpdate(l), edge_in, em, msg_hidden)?);
        }
        if body {
            mlps.push(self.mlp(Block::GlobalEmbed, t.saturating_add(d2), em, true)?);
        }
        match decoder {
            Decoder::Pairwise { body } => {
                mlps.push(self.mlp(Block::EdgeDecoder, em, d, true)?);
                if body {
                    mlps.push(self.mlp(Block::BodyDecoder, em, d, true)?);
                }
            }
            Decoder::Node { global } => {
                let inp = if global { em.saturating_mul(2) } else { em };
                mlps.push(self.mlp(Block::NodeDecoder, inp, d, true)?);
            }
        }
        Some(mlps)
    }

    /// NODE's one MLP over the whole state.
    fn flat_mlp(&mut self) -> Option<(Block, Vec<usize>)> {
        let h = self.h;
        self.count(h.node_layers.checked_add(1)?)?;
        let io = h.particles.saturating_mul(h.dim);
        let mut sizes = vec![io.saturating_mul(2)];
        sizes.extend(std::iter::repeat_n(h.node_hidden, h.node_layers));
        sizes.push(io);
        Some((Block::Flat, sizes))
    }
}

/// The constant inputs an edge reads after w_ij = (q_i − q_j)/w_scale,
/// declared once: which a model reads ([`EdgeConst::read_by`]), how many
/// numbers each is and what they are for an edge ([`EdgeConst::values`]).
/// The MLP's width, the executor's edge inputs and the sizes of a model file
/// follow from here; adding an edge input is a variant here (candle, the
/// reference, builds its own).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EdgeConst {
    /// Rest length and stiffness, scaled (`--edge-physics`); a contact's are
    /// the interaction radius and 0.
    Physics,
    /// 1 for a contact edge, 0 for a bond (models trained with a radius).
    ContactFlag,
}

impl EdgeConst {
    /// Every kind.
    pub const ALL: [EdgeConst; 2] = [EdgeConst::Physics, EdgeConst::ContactFlag];
    /// The widest kind's width (what a caller's scratch must hold).
    pub const MAX_WIDTH: usize = 8;

    /// The inputs a model with these settings reads, in order.
    pub fn read_by(edge_physics: bool, radius: f64) -> impl Iterator<Item = EdgeConst> {
        [
            edge_physics.then_some(EdgeConst::Physics),
            (radius > 0.0).then_some(EdgeConst::ContactFlag),
        ]
        .into_iter()
        .flatten()
    }

    /// Numbers of this input per edge.
    pub fn width(self) -> usize {
        match self {
            EdgeConst::Physics => EDGE_PHYSICS,
            EdgeConst::ContactFlag => 1,
        }
    }

    /// Numbers of all of `inputs` per edge.
    pub fn width_of(inputs: impl Iterator<Item = EdgeConst>) -> usize {
        inputs.map(EdgeConst::width).sum()
    }

    /// This input's numbers for fixed edge `fixed` of `plan` (`None`: a
    /// contact), as `arch` scales them, into `out` (`width()` long).
    pub fn values(self, arch: &Arch, plan: &GraphPlan, fixed: Option<usize>, out: &mut [f64]) {
        match self {
            EdgeConst::Physics => {
                let raw = match fixed {
                    Some(j) => plan.edge_physics(j),
                    None => plan.contact_physics(),
                };
                out.copy_from_slice(&arch.scaled_physics(raw));
            }
            EdgeConst::ContactFlag => out[0] = if fixed.is_some() { 0.0 } else { 1.0 },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Callers hold an input's numbers in a scratch of `MAX_WIDTH`, and the
    /// edge embedding's width is the inputs' (a new kind must fit both).
    #[test]
    fn edge_inputs_fit_and_size_the_embedding() {
        for c in EdgeConst::ALL {
            assert!(c.width() <= EdgeConst::MAX_WIDTH, "{c:?}");
        }
        let mut h = Hyper::new(super::super::Variant::Mcgnode, 3, 2, 5);
        h.edge_physics = true;
        h.interaction_radius = 1.5;
        let a = Arch::new(&h);
        assert_eq!(a.edge_features(), 3 + EDGE_PHYSICS + 1);
        assert_eq!(a.sizes(Block::EdgeEmbed).unwrap()[0], a.edge_features());
    }
}
