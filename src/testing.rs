//! Support for tests and benches, not part of the library's interface
//! (hidden from the docs): models with random weights.

use crate::error::Result;
use crate::gnode::{Hyper, Net, Variant};
use crate::kernel::TrainedModel;
use crate::system::Graph;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// An untrained model of a variant for a system (speed does not depend on
/// training). As `train` would configure it: MCGNODE has a body-force branch
/// only when the graph has anchors (springs are closed systems).
pub fn random_model(variant: Variant, graph: &Graph, seed: u64) -> Result<(Net, TrainedModel)> {
    random_model_with(variant, graph, seed, |_| {})
}

/// [`random_model`] with its hyperparameters edited by `edit` first (for
/// example the default recipe's wider edge blocks).
pub fn random_model_with(
    variant: Variant,
    graph: &Graph,
    seed: u64,
    edit: impl FnOnce(&mut Hyper),
) -> Result<(Net, TrainedModel)> {
    let types = graph.type_count();
    let mut hyper = Hyper::new(variant, graph.dim, types, graph.n());
    hyper.body_force = !graph.anchors.is_empty();
    hyper.interaction_radius = graph.interaction_radius;
    edit(&mut hyper);
    let net = Net::new(hyper.clone(), &mut ChaCha8Rng::seed_from_u64(seed))?;
    let file = crate::gnode::ModelFile {
        format: crate::gnode::file::FORMAT.into(),
        crate_version: env!("CARGO_PKG_VERSION").into(),
        hyper,
        trained_on: crate::gnode::file::TrainedOn {
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
        training: crate::gnode::file::TrainingReport {
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
        members: vec![],
    };
    let m = TrainedModel::from_file(file)?;
    Ok((net, m))
}

/// The bar constraint of a one-state candle batch built from the tensors
/// `q`, `v` (`n × d`) by candle ops — A `(1, k, n·d)`, Aᵀ, Ȧq̇ `(1, k, 1)` —
/// where [`crate::gnode::batch::Batch::new`] computes it from numbers, so
/// that candle's autodiff reaches positions and velocities through A(q) and
/// Ȧq̇ (the reference for the executor's reverse pass down to a state).
pub fn candle_constraint(
    plan: &crate::gnode::graph_plan::GraphPlan,
    q: &candle_core::Tensor,
    v: &candle_core::Tensor,
) -> Result<(
    candle_core::Tensor,
    candle_core::Tensor,
    candle_core::Tensor,
)> {
    use crate::gnode::graph_plan::BarEnd;
    use candle_core::{Device, Tensor};
    let (n, d, k) = (plan.n, plan.dim, plan.bars.len());
    let (mut inc, mut fixed) = (vec![0.0; k * n], vec![0.0; k * d]);
    for (r, bar) in plan.bars.iter().enumerate() {
        inc[r * n + bar.a] = 1.0;
        match &bar.b {
            BarEnd::Particle(b) => inc[r * n + b] = -1.0,
            BarEnd::Fixed(p) => fixed[r * d..(r + 1) * d].copy_from_slice(p),
        }
    }
    let inc = Tensor::from_vec(inc, (k, n), &Device::Cpu)?;
    let fixed = Tensor::from_vec(fixed, (k, d), &Device::Cpu)?;
    let dq = (inc.matmul(q)? - fixed)?;
    let dv = inc.matmul(v)?;
    let a = inc
        .unsqueeze(2)?
        .broadcast_mul(&dq.unsqueeze(1)?)?
        .reshape((1, k, n * d))?;
    let at = a.transpose(1, 2)?.contiguous()?;
    let adq = dv.sqr()?.sum_keepdim(1)?.reshape((1, k, 1))?;
    Ok((a, at, adq))
}
