//! GNS on the executor (`engine::Gns`): its loss and gradient against
//! candle's autodiff of the reference network (`baselines::graphnet`) to
//! 1e-10, and against central differences; the same bits with 1 and 2
//! threads; `train --model gns` on it by default. Springs (fixed edges),
//! soft spheres (a radius graph with kinematic walls, left out of the loss)
//! and a 3D lattice pair. Run with `cargo test --release --test gns_engine`.

mod common;

use common::baselines::{candle_accelerations, candle_loss_grad, rel};

use mcgnode::baselines::{BaselineHyper, BaselineNet, Kind};
use mcgnode::engine::{ExecutorModel, Gns};
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::system::{Graph, State};
use mcgnode::train::flat_params;
use rand::SeedableRng;

/// States, target accelerations and a GNS with random weights for `kind`.
fn case(
    kind: SystemKind,
    particles: usize,
    dim: usize,
) -> (Graph, Vec<State>, Vec<Vec<f64>>, BaselineNet) {
    let mut cfg = SystemConfig::new(kind, particles);
    cfg.dim = dim;
    cfg.states = 6;
    let tr = cfg.simulate(2, 5);
    let graph = tr[0].graph.clone();
    let (mut states, mut acc) = (vec![], vec![]);
    for t in &tr {
        for s in &t.samples {
            states.push(s.state.clone());
            acc.push(s.acc.clone().expect("simulated accelerations"));
        }
    }
    let types = graph.type_count();
    let mut hyper = BaselineHyper::new(Kind::Gns, graph.dim, types + 1);
    hyper.interaction_radius = graph.interaction_radius;
    let net = BaselineNet::new(hyper, &mut rand_chacha::ChaCha8Rng::seed_from_u64(7)).unwrap();
    (graph, states, acc, net)
}

fn native(net: &BaselineNet, graph: &Graph, threads: usize) -> Gns {
    Gns::new(
        net.hyper.gns_spec(),
        &net.param_sizes().unwrap(),
        graph,
        threads,
    )
    .unwrap()
}

/// Every case's loss and gradient against candle, to 1e-10.
#[test]
fn gradients_equal_candle() {
    for (kind, n, dim) in [
        (SystemKind::Spring, 5, 2),
        (SystemKind::SoftSpheres, 9, 2),
        (SystemKind::CollidingLattices, 16, 3),
        (SystemKind::HeldChain, 6, 2),
    ] {
        let (graph, states, acc, net) = case(kind, n, dim);
        let theta = flat_params(&net.store).unwrap();
        let idx: Vec<usize> = (0..states.len()).rev().step_by(2).collect();
        let (lc, gc) = candle_loss_grad(&net, &graph, (&states, &acc), &theta, &idx);
        let mut gns = native(&net, &graph, 1);
        let mut gn = vec![0.0; theta.len()];
        let samples = gns.samples(&states, &acc);
        let ln = gns.loss_grad(&theta, &samples, &idx, &mut gn);
        assert!(
            (ln - lc).abs() <= 1e-10 * lc.abs(),
            "{kind:?}: loss {ln} vs {lc}"
        );
        let r = rel(&gn, &gc);
        assert!(
            r <= 1e-10,
            "{kind:?}: gradient differs by {r:.2e} of its largest"
        );
        assert!(
            gc.iter().any(|g| g.abs() > 1e-6),
            "{kind:?}: a gradient to compare"
        );
        // The loss alone is the same number.
        assert_eq!(gns.loss(&theta, &samples, &idx), ln, "{kind:?}");
    }
}

/// Central differences on a spread of parameters (soft spheres: the radius
/// graph and the walls).
#[test]
fn gradients_equal_finite_differences() {
    let (graph, states, acc, net) = case(SystemKind::SoftSpheres, 9, 2);
    let theta = flat_params(&net.store).unwrap();
    let idx: Vec<usize> = (0..states.len()).collect();
    let mut gns = native(&net, &graph, 1);
    let mut g = vec![0.0; theta.len()];
    let samples = gns.samples(&states, &acc);
    gns.loss_grad(&theta, &samples, &idx, &mut g);
    let h = 1e-6;
    let mut worst: f64 = 0.0;
    for i in (0..theta.len()).step_by(theta.len() / 40 + 1) {
        let mut t = theta.clone();
        t[i] += h;
        let up = gns.loss(&t, &samples, &idx);
        t[i] -= 2.0 * h;
        let down = gns.loss(&t, &samples, &idx);
        let fd = (up - down) / (2.0 * h);
        let scale = g.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        worst = worst.max((fd - g[i]).abs() / scale);
    }
    assert!(worst < 1e-6, "finite differences differ by {worst:.2e}");
}

/// One and two threads give the same bits.
#[test]
fn threads_do_not_change_the_bits() {
    let (graph, states, acc, net) = case(SystemKind::SoftSpheres, 9, 2);
    let theta = flat_params(&net.store).unwrap();
    let idx: Vec<usize> = (0..states.len()).collect();
    let run = |threads| {
        let mut g = vec![0.0; theta.len()];
        let mut gns = native(&net, &graph, threads);
        let samples = gns.samples(&states, &acc);
        let l = gns.loss_grad(&theta, &samples, &idx, &mut g);
        (l, g)
    };
    assert_eq!(run(1), run(2));
}

/// `train --model gns` runs on the native engine by default and says so;
/// `--engine candle` trains the same model by autodiff to the same
/// validation loss (within 1e-6 relative after 5 epochs).
#[test]
fn train_gns_natively_from_the_cli() {
    use common::cli::{log_ok, run_in};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    log_ok(&run_in(
        d,
        &[
            "simulate",
            "--system",
            "soft-spheres",
            "--particles",
            "9",
            "--trajectories",
            "3",
            "--states",
            "11",
            "--out",
            "box.mcap",
        ],
    ));
    let train = |engine: &str, out: &str| {
        let log = log_ok(&run_in(
            d,
            &[
                "train", "--model", "gns", "--data", "box.mcap", "--epochs", "5", "--engine",
                engine, "--out", out,
            ],
        ));
        let file: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join(out)).unwrap()).unwrap();
        (log, file["training"]["validation_loss"].as_f64().unwrap())
    };
    let (log, native) = train("native", "native.json");
    assert!(log.contains("gradients by the native engine"), "{log}");
    let (log, candle) = train("candle", "candle.json");
    assert!(log.contains("gradients by candle's autodiff"), "{log}");
    assert!(
        (native - candle).abs() <= 1e-6 * candle.abs(),
        "validation loss {native} (native) against {candle} (candle)"
    );
}

/// A trained GNS rolls out on the executor: its accelerations equal candle's
/// forward pass of the same weights (to 1e-12 relative), kinematic particles
/// held, on the box (radius graph) and on the springs, graph after graph.
#[test]
fn rollouts_run_on_the_executor() {
    use mcgnode::baselines::train_baseline;
    use mcgnode::train::TrainConfig;
    use mcgnode::Dynamics;
    for (kind, n) in [(SystemKind::SoftSpheres, 9), (SystemKind::Spring, 5)] {
        let (graph, states, acc, net) = case(kind, n, 2);
        let cfg = TrainConfig {
            epochs: 2,
            ..TrainConfig::default()
        };
        let trained =
            train_baseline(net.hyper.clone(), &graph, &states, &acc, &cfg, |_| true).unwrap();
        let mut ours = vec![vec![0.0; graph.ndof()]; states.len()];
        trained
            .acceleration_batch(&graph, &states, &mut ours)
            .unwrap();
        let candle = candle_accelerations(&trained.net, &graph, &states);
        let ours_flat: Vec<f64> = ours.concat();
        for (i, (x, y)) in ours_flat.iter().zip(&candle).enumerate() {
            if graph.is_kinematic(i % graph.ndof() / graph.dim) {
                assert_eq!(*x, 0.0, "{kind:?}: a kinematic particle is held");
            } else {
                assert!(
                    (x - y).abs() <= 1e-12 * (1.0 + y.abs()),
                    "{kind:?}: {x} vs {y}"
                );
            }
        }
        // One state at a time gives the same as the batch.
        let mut one = vec![0.0; graph.ndof()];
        trained.acceleration(&graph, &states[3], &mut one).unwrap();
        assert_eq!(one, ours[3], "{kind:?}");
        // A rollout runs and stays finite.
        let r = trained
            .rollout(
                &graph,
                &states[0],
                mcgnode::dynamics::Timing::integration(1e-3, 50, 10),
            )
            .unwrap();
        assert_eq!(r.len(), 6);
    }
}
