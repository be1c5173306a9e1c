//! Training settings: [`TrainConfig`] and the gradient engine it chooses.

use super::recipe::{self, paper, Auto, Recipe};
use crate::system::Graph;

/// Training settings.
#[derive(Clone, Debug)]
pub struct TrainConfig {
    /// Maximum epochs (paper: 10,000).
    pub epochs: usize,
    /// Adam learning rate (paper: 1e-3).
    pub lr: f64,
    /// Batch size (paper: 100).
    pub batch: usize,
    /// Fraction of states held out for validation (paper: 0.25).
    pub validation: f64,
    /// Stop when the validation loss has not improved for this many epochs.
    pub patience: usize,
    /// Seed for initialisation, split and shuffling (and, through distinct
    /// streams, subsampling and noise).
    pub seed: u64,
    /// Gaussian noise on the target accelerations, percent of their standard
    /// deviation (paper's noise experiments: 0, 1, 5, 10). Applied by
    /// [`apply_data_options`](super::apply_data_options).
    pub noise: f64,
    /// Train on a seeded random subset of this many states (paper's
    /// data-efficiency experiments: 100 to 10,000); `None`: all. Applied by
    /// [`apply_data_options`](super::apply_data_options).
    pub points: Option<usize>,
    /// Gradient engine of the GNODE family and GNS (LGN and HGN always use
    /// candle).
    pub engine: EngineKind,
    /// Threads of the native engine; results do not depend on it.
    pub threads: usize,
    /// Warm start: continue from this model's weights (and its Adam state when
    /// it has one). Its hyperparameters must be the ones trained.
    pub init: Option<Box<crate::gnode::ModelFile>>,
    /// Scale inputs and outputs by statistics of the training split (stored
    /// in the model file; see [`crate::gnode::Norm`]).
    pub normalize: bool,
    /// Step schedule: after epoch `e`, learning rate `lr` (pairs in any order;
    /// the latest passed applies).
    pub lr_drops: Vec<(usize, f64)>,
    /// Stop after the first epoch that ends this many seconds after training
    /// started (the best weights so far are kept): a wall-clock budget, as a
    /// robot retraining between tasks has, and what `reproduce` gives the
    /// baselines to compare them with MCGNODE at equal time.
    pub time_budget: Option<f64>,
    /// Save the run's state as it goes, and resume from the file when it
    /// exists (see [`checkpoint`](super::checkpoint)).
    pub checkpoint: Option<super::checkpoint::Checkpointing>,
    /// Members of an ensemble trained into one model file, seeds `seed`,
    /// `seed + 1`, … (1: one model; GNODE family only, see
    /// `crate::models::train_any_from_bags`).
    pub ensemble: usize,
    /// Settings the default recipe chooses from the data instead of taking
    /// them from this config ([`super::recipe`]; none by default).
    pub auto: Auto,
}

impl TrainConfig {
    /// The learning rate of epoch `epoch` (from 1).
    pub fn lr_at(&self, epoch: usize) -> f64 {
        self.lr_drops
            .iter()
            .filter(|(e, _)| epoch > *e)
            .max_by_key(|(e, _)| *e)
            .map_or(self.lr, |(_, lr)| *lr)
    }
}

impl TrainConfig {
    /// The settings of a user who names none under `recipe`:
    /// [`Recipe::Auto`] (the default of `mcgnode train`, the node and the
    /// Python package) leaves epochs, batch, learning rate and its step to
    /// the data ([`Auto::ALL`]); [`Recipe::Paper`] is
    /// [`TrainConfig::default`]. Set a setting the recipe would choose with
    /// [`set_epochs`](Self::set_epochs) and its siblings, which also take it
    /// away from the recipe.
    pub fn for_recipe(recipe: Recipe) -> Self {
        Self {
            auto: match recipe {
                Recipe::Auto => Auto::ALL,
                Recipe::Paper => Auto::default(),
            },
            ..Self::default()
        }
    }

    /// Trains at most `epochs` epochs, whatever the recipe.
    pub fn set_epochs(&mut self, epochs: usize) {
        self.epochs = epochs;
        self.auto.epochs = false;
    }

    /// Batches of `batch` states, whatever the recipe.
    pub fn set_batch(&mut self, batch: usize) {
        self.batch = batch;
        self.auto.batch = false;
    }

    /// Learning rate `lr`, whatever the recipe.
    pub fn set_lr(&mut self, lr: f64) {
        self.lr = lr;
        self.auto.lr = false;
    }

    /// The step schedule `drops` ([`TrainConfig::lr_drops`]) instead of the
    /// recipe's step.
    pub fn set_lr_drops(&mut self, drops: Vec<(usize, f64)>) {
        self.lr_drops = drops;
        self.auto.lr_drops = false;
    }
}

/// The paper's settings, nothing left to the recipe (see [`recipe`'s
/// notes](super::recipe#where-the-defaults-live) for why this is not the
/// auto recipe).
impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            epochs: paper::EPOCHS,
            lr: paper::LR,
            batch: paper::BATCH,
            validation: paper::VALIDATION,
            patience: recipe::PATIENCE,
            seed: recipe::SEED,
            noise: 0.0,
            points: None,
            engine: EngineKind::default(),
            threads: crate::engine::all_cores(),
            init: None,
            normalize: true,
            lr_drops: vec![],
            time_budget: None,
            checkpoint: None,
            ensemble: 1,
            auto: Auto::default(),
        }
    }
}

impl TrainConfig {
    /// This config with the settings in [`TrainConfig::auto`] chosen by the
    /// default recipe for `states` states of `graph` (before the split), and
    /// a line saying what was chosen (`None` when nothing was).
    pub fn resolved(&self, graph: &Graph, states: usize) -> (TrainConfig, Option<String>) {
        self.resolved_for(recipe::directed_edges(graph), states)
    }

    /// [`TrainConfig::resolved`] for states of `edges` directed edges each
    /// (with contacts: [`recipe::directed_edges_in`]).
    pub fn resolved_for(&self, edges: usize, states: usize) -> (TrainConfig, Option<String>) {
        let a = self.auto;
        let mut c = self.clone();
        c.auto = Auto::default();
        if !a.any() {
            return (c, None);
        }
        let warm = self.init.is_some();
        if a.batch {
            c.batch = recipe::batch_for_edges(edges);
        }
        if a.lr {
            c.lr = if warm { paper::LR } else { recipe::LR };
        }
        if a.epochs {
            let n_val = ((states as f64 * c.validation).round() as usize)
                .clamp(1, states.saturating_sub(1).max(1));
            c.epochs = recipe::epochs_for(states.saturating_sub(n_val), c.batch);
        }
        if a.lr_drops && !warm {
            c.lr_drops = vec![((c.epochs * 2).div_ceil(3), c.lr / recipe::LR_DROP_FACTOR)];
        }
        let drops = c
            .lr_drops
            .iter()
            .map(|(e, lr)| format!(", {lr:e} after epoch {e}"))
            .collect::<String>();
        let line = format!(
            "recipe: batch {} states ({} directed edges each), {} epochs, lr {:e}{drops}{}",
            c.batch,
            edges,
            c.epochs,
            c.lr,
            if warm { " (warm start)" } else { "" }
        );
        (c, Some(line))
    }
}

/// Which engine computes the gradients of the GNODE family and GNS.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum EngineKind {
    /// Hand-written reverse mode on the kernel's layout, over all cores (default).
    #[default]
    Native,
    /// Candle's autodiff: the reference.
    Candle,
}
