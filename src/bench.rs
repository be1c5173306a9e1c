//! Speed measurements (`mcgnode bench` and the criterion benches): median wall
//! times of training steps and rollouts, next to the authors' JAX figures
//! measured on this same 2-core machine.

use crate::model::batch::Batch;
use crate::model::plan::GraphPlan;
use crate::model::{Hyper, Net, TrainedModel, Variant};
use crate::physics::{SystemConfig, SystemKind};
use crate::system::{Graph, State};
use anyhow::Result;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::time::Instant;

/// One measured figure.
#[derive(Clone, Debug, Serialize)]
pub struct Figure {
    /// What was measured.
    pub name: String,
    /// Median over repeats.
    pub value: f64,
    /// Unit of `value`.
    pub unit: String,
    /// The JAX reference on this machine, if there is one (same unit).
    pub jax: Option<String>,
    /// Repeats.
    pub repeats: usize,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// An untrained model of a variant for a system (speed does not depend on
/// training). As `train` would configure it: MCGNODE has a body-force branch
/// only when the graph has anchors (springs are closed systems).
pub fn random_model(variant: Variant, graph: &Graph, seed: u64) -> Result<(Net, TrainedModel)> {
    let mut hyper = Hyper::new(variant, graph.dim, 1, graph.n());
    hyper.body_force = !graph.anchors.is_empty();
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
        },
        weights: net.store.weights()?,
    };
    let m = TrainedModel::from_file(file)?;
    Ok((net, m))
}

/// Median time of one training step (forward, backward, Adam-free) at batch `b`.
pub fn train_step_seconds(
    system: SystemKind,
    variant: Variant,
    b: usize,
    repeats: usize,
) -> Result<f64> {
    let cfg = SystemConfig::new(system, 5);
    let g = cfg.graph();
    let (net, _) = random_model(variant, &g, 0)?;
    let plan = GraphPlan::new(&g);
    let states: Vec<State> = (0..b).map(|i| cfg.start_for(&g, 99, i)).collect();
    let acc: Vec<Vec<f64>> = states
        .iter()
        .map(|s| crate::physics::acceleration(&g, &cfg.field, s))
        .collect();
    let sr: Vec<&State> = states.iter().collect();
    let ar: Vec<&[f64]> = acc.iter().map(|a| a.as_slice()).collect();
    let mut times = vec![];
    for _ in 0..repeats {
        let t = Instant::now();
        let batch = Batch::new(&plan, &sr, Some(&ar), 1)?;
        let loss = net.loss(&batch)?;
        let grads = loss.backward()?;
        // Read every gradient back, as the optimiser does.
        for v in net.store.vars() {
            if let Some(gr) = grads.get(&v) {
                let _ = gr.flatten_all()?.to_vec1::<f64>()?;
            }
        }
        times.push(t.elapsed().as_secs_f64());
    }
    Ok(median(times))
}

/// Median time of a kernel rollout of `steps` steps.
pub fn rollout_seconds(
    system: SystemKind,
    n: usize,
    variant: Variant,
    steps: usize,
    repeats: usize,
) -> Result<f64> {
    let cfg = SystemConfig::new(system, n);
    let g = cfg.graph();
    let (_, m) = random_model(variant, &g, 0)?;
    let s0 = cfg.start_for(&g, 5, 0);
    let mut ws = m.kernel.workspace(&g).map_err(anyhow::Error::msg)?;
    let mut times = vec![];
    for _ in 0..repeats {
        let t = Instant::now();
        let r = m.rollout_with(&mut ws, &s0, cfg.dt, steps, steps, |_, _, _| {});
        times.push(t.elapsed().as_secs_f64());
        r.map_err(anyhow::Error::msg)?;
    }
    Ok(median(times))
}

/// Runs the whole benchmark set.
pub fn run_all(quick: bool) -> Result<Vec<Figure>> {
    let r = if quick { 5 } else { 21 };
    let mut out = vec![];
    let step_s = train_step_seconds(SystemKind::Spring, Variant::Mcgnode, 100, r * 5)?;
    out.push(Figure {
        name: "5-spring MCGNODE training step, batch 100".into(),
        value: step_s * 1e3,
        unit: "ms".into(),
        jax: Some("0.65-1.44".into()),
        repeats: r * 5,
    });
    let step_p = train_step_seconds(SystemKind::Pendulum, Variant::Mcgnode, 100, r * 5)?;
    out.push(Figure {
        name: "5-pendulum MCGNODE training step, batch 100".into(),
        value: step_p * 1e3,
        unit: "ms".into(),
        jax: Some("3.2".into()),
        repeats: r * 5,
    });
    let rs = rollout_seconds(SystemKind::Spring, 5, Variant::Mcgnode, 20_000, r)?;
    out.push(Figure {
        name: "5-spring MCGNODE rollout, 20 s (20,000 steps)".into(),
        value: rs,
        unit: "s".into(),
        jax: Some("0.25".into()),
        repeats: r,
    });
    let rp = rollout_seconds(SystemKind::Pendulum, 5, Variant::Mcgnode, 100_000, r.min(7))?;
    out.push(Figure {
        name: "5-pendulum MCGNODE rollout, 1 s (100,000 steps)".into(),
        value: rp,
        unit: "s".into(),
        jax: Some("2.75".into()),
        repeats: r.min(7),
    });
    for n in [5usize, 50, 500] {
        let steps = 2_000_000 / n.max(1) / if quick { 10 } else { 1 };
        let s = rollout_seconds(SystemKind::Spring, n, Variant::Mcgnode, steps, r.min(5))?;
        out.push(Figure {
            name: format!("{n}-spring MCGNODE rollout speed"),
            value: steps as f64 / s,
            unit: "steps/s".into(),
            jax: None,
            repeats: r.min(5),
        });
    }
    Ok(out)
}
