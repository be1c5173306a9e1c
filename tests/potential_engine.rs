//! LGN and HGN on the executor (`engine::Potential`): the loss and its
//! gradient (a second derivative of the learned potential: the tangent of
//! the force pass and its reverse pass) against candle's autodiff of the
//! reference networks (`baselines::{lgn, hgn}`) to 1e-10 and against
//! central differences; the forces against candle's; the same bits with 1
//! and 2 threads; `train --model lgn|hgn` on it by default. A ring of
//! springs and a pendulum of bars (2D), and the peridynamic cube (3D). Run with
//! `cargo test --release --test potential_engine`.

mod common;

use common::baselines::{candle_accelerations, candle_loss_grad, rel};

use mcgnode::baselines::{BaselineHyper, BaselineNet, Kind};
use mcgnode::engine::{ExecutorModel, Potential};
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::system::{Graph, State};
use mcgnode::train::flat_params;
use rand::{Rng, SeedableRng};

/// States, target accelerations and a model of `kind` with random weights
/// (log-masses too, so that the masses' gradients are not at a symmetric
/// point) for `system`.
fn case(
    kind: Kind,
    system: SystemKind,
    particles: usize,
) -> (Graph, Vec<State>, Vec<Vec<f64>>, BaselineNet) {
    let mut cfg = SystemConfig::new(system, particles);
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
    let hyper = BaselineHyper::new(kind, graph.dim, types + 1);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let net = BaselineNet::new(hyper, &mut rng).unwrap();
    let lm: Vec<f64> = (0..=types).map(|_| rng.random_range(-0.5..0.5)).collect();
    net.store
        .get("log_mass")
        .unwrap()
        .set(&candle_core::Tensor::from_vec(lm, types + 1, &candle_core::Device::Cpu).unwrap())
        .unwrap();
    (graph, states, acc, net)
}

fn native(net: &BaselineNet, graph: &Graph, threads: usize) -> Potential {
    let spec = net.hyper.potential_spec().expect("LGN or HGN");
    Potential::new(spec, &net.param_sizes().unwrap(), graph, threads).unwrap()
}

/// A ring of springs, a chain of bars (the multipliers) and a 3D cube.
const CASES: [(SystemKind, usize); 3] = [
    (SystemKind::Spring, 5),
    (SystemKind::Pendulum, 5),
    (SystemKind::Peridynamic, 27),
];

/// Every case's loss and gradient against candle, to 1e-10.
#[test]
fn gradients_equal_candle() {
    for kind in [Kind::Lgn, Kind::Hgn] {
        for (system, n) in CASES {
            let (graph, states, acc, net) = case(kind, system, n);
            let theta = flat_params(&net.store).unwrap();
            let idx: Vec<usize> = (0..states.len()).rev().step_by(2).collect();
            let (lc, gc) = candle_loss_grad(&net, &graph, (&states, &acc), &theta, &idx);
            let mut pot = native(&net, &graph, 1);
            let mut gn = vec![0.0; theta.len()];
            let samples = pot.samples(&states, &acc);
            let ln = pot.loss_grad(&theta, &samples, &idx, &mut gn);
            let what = format!("{kind} on {system:?}");
            assert!(
                (ln - lc).abs() <= 1e-10 * lc.abs(),
                "{what}: loss {ln} vs {lc}"
            );
            let r = rel(&gn, &gc);
            assert!(
                r <= 1e-10,
                "{what}: gradient differs by {r:.2e} of its largest"
            );
            assert!(
                gc.iter().any(|g| g.abs() > 1e-6),
                "{what}: a gradient to compare"
            );
            assert_eq!(pot.loss(&theta, &samples, &idx), ln, "{what}");
        }
    }
}

/// A graph without edges (particles that interact through node energies
/// only): loss, gradient and accelerations still equal candle's.
#[test]
fn a_graph_without_edges_equals_candle() {
    for kind in [Kind::Lgn, Kind::Hgn] {
        let (mut graph, states, acc, net) = case(kind, SystemKind::Spring, 5);
        graph.edges.clear();
        let theta = flat_params(&net.store).unwrap();
        let idx: Vec<usize> = (0..states.len()).collect();
        let (lc, gc) = candle_loss_grad(&net, &graph, (&states, &acc), &theta, &idx);
        let mut pot = native(&net, &graph, 1);
        let mut gn = vec![0.0; theta.len()];
        let samples = pot.samples(&states, &acc);
        let ln = pot.loss_grad(&theta, &samples, &idx, &mut gn);
        assert!(
            (ln - lc).abs() <= 1e-10 * lc.abs(),
            "{kind}: loss {ln} vs {lc}"
        );
        let r = rel(&gn, &gc);
        assert!(
            r <= 1e-10,
            "{kind}: gradient differs by {r:.2e} of its largest"
        );
    }
}

/// Central differences on a spread of parameters, every log-mass among them.
#[test]
fn gradients_equal_finite_differences() {
    for (kind, system) in [
        (Kind::Lgn, SystemKind::Spring),
        (Kind::Hgn, SystemKind::Spring),
        (Kind::Lgn, SystemKind::Pendulum),
        (Kind::Hgn, SystemKind::Pendulum),
    ] {
        let (graph, states, acc, net) = case(kind, system, 5);
        let theta = flat_params(&net.store).unwrap();
        let idx: Vec<usize> = (0..states.len()).collect();
        let mut pot = native(&net, &graph, 1);
        let mut g = vec![0.0; theta.len()];
        let samples = pot.samples(&states, &acc);
        pot.loss_grad(&theta, &samples, &idx, &mut g);
        let h = 1e-6;
        let scale = g.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let mut worst: f64 = 0.0;
        let sizes = net.param_sizes().unwrap();
        let at = sizes.iter().position(|(n, _)| n == "log_mass").unwrap();
        let start: usize = sizes[..at].iter().map(|(_, len)| len).sum();
        let masses = start..start + sizes[at].1;
        let spread = (0..theta.len()).step_by(theta.len() / 40 + 1);
        for i in spread.chain(masses) {
            let mut t = theta.clone();
            t[i] += h;
            let up = pot.loss(&t, &samples, &idx);
            t[i] -= 2.0 * h;
            let down = pot.loss(&t, &samples, &idx);
            let fd = (up - down) / (2.0 * h);
            worst = worst.max((fd - g[i]).abs() / scale);
        }
        assert!(
            worst < 1e-6,
            "{kind} on {system:?}: finite differences differ by {worst:.2e}"
        );
    }
}

/// One and two threads give the same bits.
#[test]
fn threads_do_not_change_the_bits() {
    let (graph, states, acc, net) = case(Kind::Hgn, SystemKind::Peridynamic, 27);
    let theta = flat_params(&net.store).unwrap();
    let idx: Vec<usize> = (0..states.len()).collect();
    let run = |threads| {
        let mut g = vec![0.0; theta.len()];
        let mut pot = native(&net, &graph, threads);
        let samples = pot.samples(&states, &acc);
        let l = pot.loss_grad(&theta, &samples, &idx, &mut g);
        (l, g)
    };
    assert_eq!(run(1), run(2));
}

/// The accelerations f / m equal candle's (to 1e-12 relative).
#[test]
fn accelerations_equal_candle() {
    for kind in [Kind::Lgn, Kind::Hgn] {
        for (system, n) in CASES {
            let (graph, states, _, net) = case(kind, system, n);
            let theta = flat_params(&net.store).unwrap();
            let ours = native(&net, &graph, 1)
                .accelerations(&theta, &states)
                .concat();
            let theirs = candle_accelerations(&net, &graph, &states);
            let r = rel(&ours, &theirs);
            assert!(
                r <= 1e-12,
                "{kind} on {system:?}: accelerations differ by {r:.2e}"
            );
        }
    }
}

/// `train --model lgn|hgn` runs on the native engine by default and says
/// so; `--engine candle` trains the same model by autodiff to the same
/// validation loss (within 1e-6 relative after 4 epochs), on springs and on
/// a pendulum (bars).
#[test]
fn train_lgn_and_hgn_natively_from_the_cli() {
    use common::cli::{log_ok, run_in};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (system, out) in [("spring", "springs.mcap"), ("pendulum", "pendulum.mcap")] {
        log_ok(&run_in(
            d,
            &[
                "simulate",
                "--system",
                system,
                "--particles",
                "5",
                "--trajectories",
                "3",
                "--states",
                "11",
                "--out",
                out,
            ],
        ));
    }
    let train = |model: &str, data: &str, engine: &str| {
        let out = format!("{model}-{engine}.json");
        let log = log_ok(&run_in(
            d,
            &[
                "train", "--model", model, "--data", data, "--epochs", "4", "--engine", engine,
                "--out", &out,
            ],
        ));
        let file: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join(&out)).unwrap()).unwrap();
        (log, file["training"]["validation_loss"].as_f64().unwrap())
    };
    for model in ["lgn", "hgn"] {
        for data in ["springs.mcap", "pendulum.mcap"] {
            let (log, native) = train(model, data, "native");
            assert!(log.contains("gradients by the native engine"), "{log}");
            let (log, candle) = train(model, data, "candle");
            assert!(log.contains("gradients by candle's autodiff"), "{log}");
            assert!(
                (native - candle).abs() <= 1e-6 * candle.abs(),
                "{model} on {data}: validation loss {native} (native) against {candle} (candle)"
            );
        }
    }
}

/// Trained LGN and HGN roll out on the executor: their accelerations equal
/// candle's forward and force passes of the same weights (to 1e-12
/// relative), state by state as in a batch, with and without bars.
#[test]
fn rollouts_run_on_the_executor() {
    use mcgnode::baselines::train_baseline;
    use mcgnode::train::TrainConfig;
    use mcgnode::Dynamics;
    for (kind, system) in [
        (Kind::Lgn, SystemKind::Spring),
        (Kind::Hgn, SystemKind::Pendulum),
    ] {
        let (graph, states, acc, net) = case(kind, system, 5);
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
        let theirs = candle_accelerations(&trained.net, &graph, &states);
        let r = rel(&ours.concat(), &theirs);
        assert!(
            r <= 1e-12,
            "{kind} on {system:?}: accelerations differ by {r:.2e}"
        );
        let mut one = vec![0.0; graph.ndof()];
        trained.acceleration(&graph, &states[3], &mut one).unwrap();
        assert_eq!(one, ours[3], "{kind}");
        let r = trained
            .rollout(
                &graph,
                &states[0],
                mcgnode::dynamics::Timing::integration(1e-3, 50, 10),
            )
            .unwrap();
        assert_eq!(r.len(), 6);
        assert!(
            r.iter().all(|s| s.q.iter().all(|x| x.is_finite())),
            "{kind}"
        );
    }
}
