//! Architecture choices for the GNODE family: [`ModelOptions`] and the
//! body-force branch.

use super::recipe::{self, paper, Recipe};
use crate::error::{bail, Result};
use crate::gnode::{ArchPreset, EdgeInput, Hyper, MessageFn, Variant};

/// Whether MCGNODE learns a body-force branch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BodyForce {
    /// On unless the bag says the system is closed (no field, no anchors)
    /// (the default).
    #[default]
    Auto,
    /// Always learn body forces.
    On,
    /// Never: internal forces only, momentum conserved exactly.
    Off,
}

/// Architecture choices on top of a variant's paper defaults.
///
/// The default is what `mcgnode train`, the node's Train service and the
/// Python package's `train` use when given no option: the paper's sizes
/// ([`paper`]) with the authors' architecture and the auto recipe's wider
/// edge MLPs; [`ModelOptions::for_recipe`]`(Recipe::Paper)` is the paper's
/// settings exactly (`--recipe paper`).
#[derive(Clone, Debug, PartialEq)]
pub struct ModelOptions {
    /// Hidden units of the graph MLPs.
    pub hidden: usize,
    /// Embedding width.
    pub embed: usize,
    /// Message-passing rounds.
    pub rounds: usize,
    /// Body-force branch (MCGNODE).
    pub body_force: BodyForce,
    /// One-hot width; default: largest type in the data + 1.
    pub types: Option<usize>,
    /// The ParticleState topic to train on, when a bag holds several.
    pub topic: Option<String>,
    /// Architecture preset (the authors' code by default).
    pub arch: ArchPreset,
    /// Hidden layers per graph MLP, overriding the preset.
    pub hidden_layers: Option<usize>,
    /// Message functions, overriding the preset.
    pub message: Option<MessageFn>,
    /// Edge-update input, overriding the preset.
    pub edge_input: Option<EdgeInput>,
    /// Per-block hidden sizes (block weight prefix → sizes).
    pub block_hidden: std::collections::BTreeMap<String, Vec<usize>>,
    /// Edges read their rest length and stiffness.
    pub edge_physics: bool,
    /// The interaction radius to train with, overriding the bags' (none:
    /// theirs).
    pub radius: Option<f64>,
    /// With [`Recipe::Auto`] (the default), the blocks that embed and decode
    /// edges get the recipe's widths ([`recipe::edge_blocks`]) unless
    /// `block_hidden` names them; [`Recipe::Paper`] adds nothing.
    pub recipe: Recipe,
}

impl Default for ModelOptions {
    fn default() -> Self {
        Self {
            hidden: paper::HIDDEN,
            embed: paper::EMBED,
            rounds: paper::ROUNDS,
            body_force: BodyForce::default(),
            types: None,
            topic: None,
            arch: ArchPreset::default(),
            hidden_layers: None,
            message: None,
            edge_input: None,
            block_hidden: Default::default(),
            edge_physics: false,
            radius: None,
            recipe: Recipe::default(),
        }
    }
}

impl ModelOptions {
    /// The default options under `recipe` ([`Recipe::Paper`]: the paper's
    /// widths everywhere, as `reproduce` trains).
    pub fn for_recipe(recipe: Recipe) -> Self {
        Self {
            recipe,
            ..Self::default()
        }
    }

    /// The hyperparameters these options give a variant on a `dim`-D graph of
    /// `particles` particles with `types` types (body force left on).
    pub fn hyper(
        &self,
        variant: Variant,
        dim: usize,
        types: usize,
        particles: usize,
    ) -> Result<Hyper> {
        let mut h = Hyper::new(variant, dim, types, particles).with_preset(self.arch);
        h.hidden = self.hidden;
        h.embed = self.embed;
        h.rounds = self.rounds;
        h.hidden_layers = self.hidden_layers.unwrap_or(h.hidden_layers);
        h.message = self.message.unwrap_or(h.message);
        h.edge_input = self.edge_input.unwrap_or(h.edge_input);
        h.block_hidden = self.block_hidden.clone();
        if self.recipe == Recipe::Auto {
            for (block, sizes) in recipe::edge_blocks(variant) {
                h.block_hidden.entry(block.to_string()).or_insert(sizes);
            }
        }
        h.edge_physics = self.edge_physics;
        let known: Vec<String> = crate::gnode::Arch::new(&h)
            .mlps
            .iter()
            .map(|(b, _)| b.prefix())
            .collect();
        if let Some(bad) = h.block_hidden.keys().find(|k| !known.contains(k)) {
            bail!(
                "--block-hidden names block {bad:?}, which a {variant} model does not have (it has: {})",
                known.join(", ")
            );
        }
        if h.hidden == 0 || h.embed == 0 {
            bail!("--hidden and --embed must be positive");
        }
        Ok(h)
    }
}
