//! Candle's side of the baselines' engine tests (`gns_engine`,
//! `potential_engine`): the reference network's loss, gradient and
//! accelerations, and the relative difference they are compared by.

use mcgnode::baselines::BaselineNet;
use mcgnode::gnode::Batch;
use mcgnode::gnode::GraphPlan;
use mcgnode::system::{Graph, State};
use mcgnode::train::{CandleObjective, Objective};

/// Candle's loss and gradient of the reference network on states `idx`.
pub fn candle_loss_grad(
    net: &BaselineNet,
    graph: &Graph,
    (states, acc): (&[State], &[Vec<f64>]),
    theta: &[f64],
    idx: &[usize],
) -> (f64, Vec<f64>) {
    let plan = GraphPlan::new(graph);
    let loss = |idx: &[usize]| {
        let s: Vec<&State> = idx.iter().map(|&i| &states[i]).collect();
        let a: Vec<&[f64]> = idx.iter().map(|&i| acc[i].as_slice()).collect();
        let b = Batch::new(&plan, &s, Some(&a), net.hyper.types)?;
        net.loss(&b, &graph.masses)
    };
    let mut obj = CandleObjective::new(&net.store, loss);
    let mut grad = vec![0.0; theta.len()];
    let l = obj.loss_grad(theta, idx, &mut grad).unwrap();
    (l, grad)
}

/// Candle's accelerations of `states` (node-major, all states in a row).
pub fn candle_accelerations(net: &BaselineNet, graph: &Graph, states: &[State]) -> Vec<f64> {
    let plan = GraphPlan::new(graph);
    let refs: Vec<&State> = states.iter().collect();
    let b = Batch::new(&plan, &refs, None, net.hyper.types).unwrap();
    net.acceleration(&b)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap()
}

/// The largest difference between `a` and `b` over `b`'s largest entry.
pub fn rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
        / scale
}
