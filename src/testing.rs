//! Support for tests and benches, not part of the library's interface
//! (hidden from the docs): models with random weights.

use crate::error::Result;
use crate::kernel::TrainedModel;
use crate::model::{Hyper, Net, Variant};
use crate::system::Graph;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// An untrained model of a variant for a system (speed does not depend on
/// training). As `train` would configure it: MCGNODE has a body-force branch
/// only when the graph has anchors (springs are closed systems).
pub fn random_model(variant: Variant, graph: &Graph, seed: u64) -> Result<(Net, TrainedModel)> {
    let types = graph
        .types
        .iter()
        .map(|&t| t as usize + 1)
        .max()
        .unwrap_or(1);
    let mut hyper = Hyper::new(variant, graph.dim, types, graph.n());
    hyper.body_force = !graph.anchors.is_empty();
    hyper.interaction_radius = graph.interaction_radius;
    let net = Net::new(hyper.clone(), &mut ChaCha8Rng::seed_from_u64(seed))?;
    let file = crate::model::ModelFile {
        format: crate::model::file::FORMAT.into(),
        crate_version: env!("CARGO_PKG_VERSION").into(),
        hyper,
        trained_on: crate::model::file::TrainedOn {
            system: String::new(),
            particles: graph.n(),
            dim: graph.dim,
            bag: String::new(),
            bag_sha256: String::new(),
            accelerations: String::new(),
            trajectories: 0,
            states: 0,
            start_fingerprints: vec![],
            system_config: None,
            edge_params: vec![],
        },
        training: crate::model::file::TrainingReport {
            seed,
            epochs_requested: 0,
            epochs_run: 0,
            best_epoch: 0,
            train_loss: 0.0,
            validation_loss: 0.0,
            stopped_early: false,
            seconds: 0.0,
            batch: 0,
            lr: 0.0,
            patience: 0,
            noise: 0.0,
            points: None,
            lr_drops: vec![],
            time_budget: None,
            out_of_time: false,
            resumed_at: None,
            trivial_loss: None,
            explained: None,
        },
        weights: net.store.weights()?,
        optimizer: None,
    };
    let m = TrainedModel::from_file(file)?;
    Ok((net, m))
}
