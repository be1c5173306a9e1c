//! The training recipe: how the settings a user leaves out are chosen.
//!
//! The paper's settings (batch 100 states, Adam at 1e-3, 10,000 epochs, MLPs
//! of width 5) were tuned on 5-particle systems. On a 3D solid they learn
//! nothing in any budget a user waits for: a state of the 125-particle cube
//! has 1,560 directed bonds, so 100 states make one batch of 156,000 edge
//! samples and 750 training states give 8 Adam steps an epoch; after 300
//! epochs the validation MSE is 6.0e-3 against 7.7e-3 for predicting zero
//! acceleration. The default recipe sizes what matters by the data instead
//! (figures: the README's "Defaults that learn"):
//!
//! - **batch** in directed edges, [`BATCH_EDGES`] a batch (at most 100
//!   states, as the paper): 100 states of a 5-spring ring, 10 of the cube;
//! - **learning rate** 1e-2, stepped down to 1e-3 after two thirds of the
//!   epochs (a warm start, already trained, keeps 1e-3 throughout);
//! - **epochs** from a budget of [`STEPS`] Adam steps (at most 10,000
//!   epochs), so an epoch of few large batches does not leave the optimiser
//!   short of steps;
//! - **widths**: the MLPs that embed and decode edges get two hidden layers
//!   of [`EDGE_WIDTH`] (a bond's force is a sharp function of its length;
//!   width 5 plateaus on solids), the rest keep the authors' 5.
//!
//! `--recipe auto` is the default; `--recipe paper` restores the paper's settings exactly, and every setting
//! given on the command line overrides the recipe's choice.
//!
//! # Where the defaults live
//!
//! Every training default is stated once, here ([`paper`], [`PATIENCE`],
//! [`SEED`], [`LR`], [`LR_DROP_FACTOR`]) or beside the type it belongs to
//! ([`Hyper::PAPER_HIDDEN`](crate::gnode::Hyper::PAPER_HIDDEN) and the
//! other sizes a [`Hyper`](crate::gnode::Hyper) starts from). What a user
//! who names no setting gets is [`ModelOptions::default`](super::ModelOptions)
//! with [`TrainConfig::for_recipe`](super::TrainConfig::for_recipe)`(Recipe::default())`:
//! `mcgnode train`'s clap defaults read these constants, the node's Train
//! service and drift retraining and the Python package's `train` start from
//! the same two values, and a test in `src/cli/train.rs` fails if the
//! command line's defaults and these disagree.
//!
//! [`TrainConfig::default`](super::TrainConfig) is the paper's settings with
//! nothing left to the recipe, not the auto recipe: a config written as
//! `TrainConfig { epochs: 30, ..TrainConfig::default() }` must mean 30
//! epochs, and struct-update syntax cannot tell the recipe which fields were
//! written (`reproduce` and the tests rely on it). [`ModelOptions`](super::ModelOptions)
//! has no such trap: its recipe only adds widths to blocks that `block_hidden`
//! does not name, so its default is the auto recipe.

use crate::gnode::Variant;
use crate::system::Graph;

/// How unset settings are chosen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Recipe {
    /// Chosen from the data ([`Auto`]): learns solids, lattices and chains
    /// alike in minutes.
    #[default]
    Auto,
    /// The paper's appendix: batch 100, lr 1e-3, 10,000 epochs, width 5.
    Paper,
}

impl Recipe {
    /// Its name on the command line and in logs.
    pub fn name(self) -> &'static str {
        match self {
            Recipe::Auto => "auto",
            Recipe::Paper => "paper",
        }
    }
}

/// The paper's settings (its appendix): what [`Recipe::Paper`] trains with,
/// what [`TrainConfig::default`](crate::train::TrainConfig) holds and what
/// the default recipe caps its choices at.
pub mod paper {
    use crate::gnode::Hyper;

    /// Maximum epochs.
    pub const EPOCHS: usize = 10_000;
    /// Adam's learning rate (also the default recipe's for a warm start,
    /// which is already trained).
    pub const LR: f64 = 1e-3;
    /// States a batch.
    pub const BATCH: usize = 100;
    /// Fraction of the states held out for validation (the 75:25 split).
    pub const VALIDATION: f64 = 0.25;
    /// Hidden units of the graph MLPs.
    pub const HIDDEN: usize = Hyper::PAPER_HIDDEN;
    /// Node and edge embedding width.
    pub const EMBED: usize = Hyper::PAPER_EMBED;
    /// Message-passing rounds.
    pub const ROUNDS: usize = Hyper::PAPER_ROUNDS;
}

/// Epochs without a better validation loss before training stops, under
/// either recipe. The paper states no early stopping; a tenth of its epochs
/// stops a paper-length run only on a long plateau, and the default recipe's
/// shorter runs (300 epochs on the cube) practically never.
pub const PATIENCE: usize = 1_000;
/// Seed of initialisation, split and shuffling.
pub const SEED: u64 = 0;
/// The default recipe's learning rate for a fresh model (a warm start keeps
/// [`paper::LR`]): ten times the paper's, which the step down returns to.
pub const LR: f64 = 1e-2;
/// The default recipe divides the learning rate by this after two thirds of
/// the epochs.
pub const LR_DROP_FACTOR: f64 = 10.0;

/// Directed edges in a batch under the default recipe.
pub const BATCH_EDGES: usize = 16_000;
/// Adam steps the default recipe's epoch count aims at.
pub const STEPS: usize = 22_500;
/// Hidden width of the edge MLPs under the default recipe.
pub const EDGE_WIDTH: usize = 16;
/// The most states a batch holds (the paper's batch).
const MAX_BATCH: usize = paper::BATCH;
/// The most epochs the step budget may ask for (the paper's count).
const MAX_EPOCHS: usize = paper::EPOCHS;

/// Which settings the default recipe chooses from the data; the others are
/// taken from [`super::TrainConfig`] as given. `Auto::default()` chooses
/// none: a config means exactly what it says (the paper's settings by
/// default), as `reproduce` and the tests want.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Auto {
    /// Epochs from the step budget.
    pub epochs: bool,
    /// Batch from the edge budget.
    pub batch: bool,
    /// Learning rate [`LR`] ([`paper::LR`] for a warm start).
    pub lr: bool,
    /// The step down after two thirds of the epochs.
    pub lr_drops: bool,
}

impl Auto {
    /// The default recipe for every setting.
    pub const ALL: Auto = Auto {
        epochs: true,
        batch: true,
        lr: true,
        lr_drops: true,
    };

    /// The default recipe for all but the epochs, which the caller gives
    /// (the node's Train requests and drift retraining).
    pub const GIVEN_EPOCHS: Auto = Auto {
        epochs: false,
        ..Auto::ALL
    };

    /// Whether it chooses anything.
    pub fn any(self) -> bool {
        self.epochs || self.batch || self.lr || self.lr_drops
    }
}

/// Directed edges of one state of `graph` (bonds both ways; an edge to an
/// anchor counts once, as the models see it).
pub fn directed_edges(graph: &Graph) -> usize {
    graph
        .edges
        .iter()
        .map(|e| match e.b {
            crate::system::Endpoint::Particle(_) => 2,
            crate::system::Endpoint::Anchor(_) => 1,
        })
        .sum::<usize>()
        .max(1)
}

/// Directed edges of an average state of `states` of `graph`: its fixed
/// edges and, with contacts, the mean number of contact edges (both ways)
/// over at most 64 states spread through the data.
pub fn directed_edges_in(graph: &Graph, states: &[crate::system::State]) -> usize {
    let fixed = directed_edges(graph);
    if !graph.has_contacts() || states.is_empty() {
        return fixed;
    }
    let mut search = crate::physics::neighbors::NeighborSearch::new(graph);
    let step = states.len().div_ceil(64);
    let (mut pairs, mut seen) = (0, 0);
    for s in states.iter().step_by(step) {
        pairs += search
            .search(&s.q, graph.dim, graph.interaction_radius)
            .len();
        seen += 1;
    }
    let fixed = if graph.edges.is_empty() { 0 } else { fixed };
    (fixed + (2 * pairs).div_ceil(seen)).max(1)
}

/// The default recipe's batch, in states, for states of `graph`.
pub fn batch_for(graph: &Graph) -> usize {
    batch_for_edges(directed_edges(graph))
}

/// The default recipe's batch, in states, for states of `edges` directed edges.
pub fn batch_for_edges(edges: usize) -> usize {
    (BATCH_EDGES / edges.max(1)).clamp(1, MAX_BATCH)
}

/// The default recipe's epochs for `train_states` training states in batches
/// of `batch`.
pub fn epochs_for(train_states: usize, batch: usize) -> usize {
    let steps_per_epoch = train_states.div_ceil(batch.max(1)).max(1);
    STEPS.div_ceil(steps_per_epoch).clamp(1, MAX_EPOCHS)
}

/// The default recipe's hidden sizes for the blocks that embed and decode
/// edges in `variant` (none for NODE, which has no graph): entries to add to
/// [`super::ModelOptions::block_hidden`] where the user named no sizes.
pub fn edge_blocks(variant: Variant) -> Vec<(&'static str, Vec<usize>)> {
    let w = vec![EDGE_WIDTH, EDGE_WIDTH];
    let b = variant.biases();
    if !b.graph {
        return vec![];
    }
    // MCGNODE decodes a force per edge; the others decode per node.
    let out = if variant == Variant::Mcgnode {
        "edge_out"
    } else {
        "node_out"
    };
    vec![("edge_em", w.clone()), (out, w)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{SystemConfig, SystemKind};
    use crate::train::TrainConfig;

    fn graph(kind: SystemKind, n: usize) -> Graph {
        SystemConfig::new(kind, n).graph()
    }

    #[test]
    fn batch_is_sized_by_edges() {
        // 5 springs: 10 directed edges, capped at the paper's 100 states.
        assert_eq!(directed_edges(&graph(SystemKind::Spring, 5)), 10);
        assert_eq!(batch_for(&graph(SystemKind::Spring, 5)), 100);
        // The 125-particle cube: 780 bonds, 1,560 directed: 10 states.
        let cube = graph(SystemKind::Peridynamic, 125);
        assert_eq!(directed_edges(&cube), 1560);
        assert_eq!(batch_for(&cube), 10);
        // A pendulum's pivot bar counts once (the network sees it once).
        let p = graph(SystemKind::Pendulum, 5);
        assert_eq!(directed_edges(&p), 9);
        // A 1,000-particle solid still gets one state a batch.
        assert_eq!(batch_for(&graph(SystemKind::Peridynamic, 1000)), 1);
    }

    #[test]
    fn epochs_come_from_the_step_budget() {
        // The cube: 750 training states in batches of 10 = 75 steps an epoch.
        assert_eq!(epochs_for(750, 10), 300);
        assert_eq!(epochs_for(7500, 100), 300);
        // Never more than the paper's 10,000, never none.
        assert_eq!(epochs_for(1, 100), MAX_EPOCHS);
        assert_eq!(epochs_for(10_000_000, 1), 1);
    }

    #[test]
    fn resolving_fills_only_what_is_left_to_the_recipe() {
        let g = graph(SystemKind::Peridynamic, 125);
        let paper = TrainConfig::default();
        let (c, line) = paper.resolved(&g, 1000);
        assert!(line.is_none());
        assert_eq!((c.batch, c.lr, c.epochs), (100, 1e-3, 10_000));
        assert!(c.lr_drops.is_empty());

        let auto = TrainConfig {
            auto: Auto::ALL,
            ..TrainConfig::default()
        };
        // 1000 states: 750 train after the 25 % split.
        let (c, line) = auto.resolved(&g, 1000);
        assert_eq!((c.batch, c.lr, c.epochs), (10, 1e-2, 300));
        assert_eq!(c.lr_drops, vec![(200, 1e-3)]);
        assert!(line.unwrap().contains("batch 10 states"));
        assert_eq!(c.auto, Auto::default());

        // Given settings stay; the step follows the given epochs and rate.
        let some = TrainConfig {
            epochs: 30,
            lr: 5e-3,
            auto: Auto {
                epochs: false,
                lr: false,
                ..Auto::ALL
            },
            ..TrainConfig::default()
        };
        let (c, _) = some.resolved(&g, 1000);
        assert_eq!((c.batch, c.lr, c.epochs), (10, 5e-3, 30));
        assert_eq!(c.lr_drops, vec![(20, 5e-4)]);
    }

    #[test]
    fn edge_blocks_follow_the_decoder() {
        let names = |v| {
            edge_blocks(v)
                .into_iter()
                .map(|(b, s)| (b, s.len()))
                .collect::<Vec<_>>()
        };
        assert_eq!(
            names(Variant::Mcgnode),
            vec![("edge_em", 2), ("edge_out", 2)]
        );
        assert_eq!(names(Variant::Gnode), vec![("edge_em", 2), ("node_out", 2)]);
        assert!(edge_blocks(Variant::Node).is_empty());
    }
}
