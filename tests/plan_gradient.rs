//! Planning gradients (issue 22): ∂cost/∂controls by reverse mode through
//! the rollout against central finite differences, for every variant of the
//! GNODE family on a held chain of springs and on a held chain of bars
//! (constrained variants with SHAKE/RATTLE in their rollouts), with every
//! term of the cost; and refining a plan by gradient steps. The state-level
//! reverse pass is checked against candle in tests/engine.rs, the whole
//! sweep against candle's autodiff of the rollout written in candle ops. Run with
//! `cargo test --release --test plan_gradient`.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use candle_core::{Device, Tensor, Var};
mod common;

use common::cli::{ok, run_in};
use mcgnode::dynamics::Dynamics;
use mcgnode::dynamics::Timing;
use mcgnode::gnode::Variant;
use mcgnode::models::truth::truth;
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::plan::{refine, Controls, Cost, CostKind, Problem};
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph, State};
use mcgnode::testing::random_model;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A chain of `n` bars (length 0.5) hanging from a kinematic gripper,
/// particle 0, bent so that no bar is vertical.
fn bar_chain(n: usize) -> (Graph, State) {
    let edges = (1..=n)
        .map(|i| Edge {
            a: i,
            b: Endpoint::Particle(i - 1),
            kind: EdgeKind::Bar,
            rest_length: 0.5,
            stiffness: 0.0,
        })
        .collect();
    let g = Graph {
        dim: 2,
        types: (0..=n).map(|i| u32::from(i == 0)).collect(),
        masses: vec![1.0; n + 1],
        edges,
        anchors: vec![],
        interaction_radius: 0.0,
        kinematic: (0..=n).map(|i| i == 0).collect(),
        periodic_box: None,
    };
    let mut q = vec![0.0; 2 * (n + 1)];
    for i in 1..=n {
        let th = -1.2 + 0.3 * i as f64;
        q[2 * i] = q[2 * (i - 1)] + 0.5 * th.cos();
        q[2 * i + 1] = q[2 * (i - 1) + 1] - 0.5 * th.sin().abs() - 0.1;
    }
    // Onto the bar lengths exactly.
    for i in 1..=n {
        let (dx, dy) = (q[2 * i] - q[2 * i - 2], q[2 * i + 1] - q[2 * i - 1]);
        let s = 0.5 / (dx * dx + dy * dy).sqrt();
        q[2 * i] = q[2 * i - 2] + dx * s;
        q[2 * i + 1] = q[2 * i - 1] + dy * s;
    }
    let v = vec![0.0; q.len()];
    (g, State { q, v })
}

fn problem<'a>(model: &'a dyn Dynamics, g: &'a Graph, start: &'a State) -> Problem<'a> {
    let end = g.n() - 1;
    Problem {
        model,
        graph: g,
        start,
        timing: Timing::of_step(0.01, 4, 3),
        cost: Cost {
            kind: CostKind::Along,
            particles: vec![end, end - 1],
            targets: vec![
                start.q[2 * end] + 0.3,
                start.q[2 * end + 1] - 0.2,
                start.q[2 * end - 2],
                start.q[2 * end - 1] + 0.1,
            ],
            effort: 0.05,
            speed: 0.3,
            risk: 0.0,
        },
        max_speed: 2.0,
    }
}

/// ‖a − b‖∞ / ‖b‖∞.
fn rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

fn check(name: &str, p: &Problem, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let width = p.width();
    let u = Controls {
        steps: p.timing.horizon,
        width,
        u: (0..p.timing.horizon * width)
            .map(|_| rng.random_range(-0.6..0.6))
            .collect(),
    };
    let g = p.gradient(&u).unwrap();
    // The same rollout, and cost, as the search evaluates.
    assert_eq!(
        g.predicted,
        p.rollout(&u).unwrap(),
        "{name}: rollouts differ"
    );
    assert_eq!(g.cost, p.cost_of(&u).unwrap(), "{name}");
    let h = 1e-6;
    let fd: Vec<f64> = (0..u.u.len())
        .map(|f| {
            let mut up = u.clone();
            up.u[f] += h;
            let mut down = u.clone();
            down.u[f] -= h;
            (p.cost_of(&up).unwrap() - p.cost_of(&down).unwrap()) / (2.0 * h)
        })
        .collect();
    let r = rel(&g.grad, &fd);
    assert!(
        fd.iter().any(|x| x.abs() > 1e-3),
        "{name}: flat cost {fd:?}"
    );
    assert!(
        r <= 1e-6,
        "{name}: gradient {:?} vs finite differences {fd:?}: {r:.2e}",
        g.grad
    );
    eprintln!("{name}: gradient vs finite differences {r:.1e}");
}

#[test]
fn gradients_match_finite_differences_on_springs_and_bars() {
    let cfg = SystemConfig::new(SystemKind::HeldChain, 5);
    let springs = cfg.graph();
    let spring_start = cfg.start_for(&springs, 2, 0);
    let (bars, bar_start) = bar_chain(4);
    for (k, v) in Variant::ALL.into_iter().enumerate() {
        for (gname, g, start) in [
            ("held springs", &springs, &spring_start),
            ("held bars", &bars, &bar_start),
        ] {
            let (_, model) = random_model(v, g, 10 + k as u64).unwrap();
            let p = problem(&model, g, start);
            check(&format!("{v} on {gname}"), &p, 3 + k as u64);
        }
    }
}

/// A constrained model on bars projects its rollouts (SHAKE/RATTLE): the
/// gradient is of that rollout, not of an unprojected one.
#[test]
fn the_projected_rollout_is_the_one_differentiated() {
    let (g, start) = bar_chain(3);
    let (_, mut model) = random_model(Variant::Mcgnode, &g, 4).unwrap();
    let p = problem(&model, &g, &start);
    let u = Controls {
        steps: 3,
        width: 2,
        u: vec![0.4, -0.3, 0.1, 0.2, -0.5, 0.3],
    };
    let projected = p.gradient(&u).unwrap();
    model.kernel.set_project_bars(false);
    let p = problem(&model, &g, &start);
    let free = p.gradient(&u).unwrap();
    assert_ne!(projected.predicted, free.predicted);
    assert!(rel(&projected.grad, &free.grad) > 1e-6);
    check("MCGNODE on bars, unprojected", &p, 9);
}

/// Gradient steps from a candidate lower its cost at every step, to a
/// stationary point; a model without a reverse pass is refused with a message that
/// names what has one.
#[test]
fn refining_lowers_the_cost_and_models_without_gradients_are_refused() {
    let cfg = SystemConfig::new(SystemKind::HeldChain, 5);
    let g = cfg.graph();
    let start = cfg.start_for(&g, 2, 0);
    let (_, model) = random_model(Variant::Mcgnode, &g, 1).unwrap();
    let p = problem(&model, &g, &start);
    let init = Controls::zeros(3, p.width());
    let r = refine(&p, &init, 20).unwrap();
    assert_eq!(r.start_cost, p.cost_of(&init).unwrap());
    assert!(!r.steps.is_empty());
    assert!(r.steps.windows(2).all(|w| w[1].cost < w[0].cost));
    assert!(r.cost < r.start_cost, "{} vs {}", r.cost, r.start_cost);
    // It walks to a stationary point of the cost.
    let (first, last) = (r.steps[0].grad_norm, r.steps.last().unwrap().grad_norm);
    assert!(last < 1e-3 * first, "gradient norm {first} → {last}");
    assert_eq!(r.cost, p.cost_of(&r.best).unwrap());
    assert_eq!(r.predicted, p.rollout(&r.best).unwrap());
    assert!(r.best.u.iter().all(|x| x.abs() <= p.max_speed));
    let truth = truth(SystemKind::HeldChain);
    let p = problem(truth.as_ref(), &g, &start);
    let e = p.gradient(&init).unwrap_err().to_string();
    assert!(e.contains("no gradient") && e.contains("GNODE"), "{e}");
}

/// `plan --refine N --json` refines the search's best sequence by gradient
/// steps through a model file and prints the refined plan, the search's
/// cost and the final gradient; the true physics has no reverse pass and
/// is refused with the reason.
#[test]
fn the_plan_command_refines() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = |args: &[&str]| ok(&run_in(d, args));
    // A model that responds to its gripper (a random one hardly does).
    run(&[
        "simulate",
        "--system",
        "held-chain",
        "--particles",
        "5",
        "--trajectories",
        "10",
        "--states",
        "31",
        "--out",
        "hc.mcap",
    ]);
    run(&[
        "train", "--model", "mcgnode", "--data", "hc.mcap", "--epochs", "100", "--out", "m.json",
    ]);
    let args = |m: &'static str| {
        [
            "plan",
            "--model",
            m,
            "--target",
            "0.8,-5.5",
            "--horizon",
            "5",
            "--dt",
            "0.05",
            "--substeps",
            "10",
            "--candidates",
            "8",
            "--iterations",
            "1",
            "--elites",
            "2",
            "--refine",
            "10",
            "--json",
        ]
    };
    let j: serde_json::Value = serde_json::from_str(&run(&args("m.json"))).unwrap();
    let (cost, search) = (
        j["cost"].as_f64().unwrap(),
        j["search_cost"].as_f64().unwrap(),
    );
    assert!(cost <= search, "{cost} > {search}");
    let r = &j["refine"];
    assert_eq!(r["start_cost"].as_f64().unwrap(), search);
    assert_eq!(r["gradient"].as_array().unwrap().len(), 10);
    let steps = r["steps"].as_array().unwrap();
    assert!(!steps.is_empty(), "{j}");
    assert_eq!(steps.last().unwrap()["cost"].as_f64().unwrap(), cost);
    assert!(cost < search, "{cost} = {search}: nothing refined");
    assert_eq!(j["best"].as_array().unwrap().len(), 5);
    assert_eq!(j["predicted"].as_array().unwrap().len(), 6);
    let o = run_in(d, &args("truth:held-chain"));
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("no gradient"), "{e}");
}

/// ∂cost/∂u by candle's autodiff through the whole rollout, written out in
/// candle ops: the drive from the velocity knots, velocity Verlet, the
/// driven particles placed, q̈ from the candle model (with A(q), Ȧq̇ from
/// the tensors), the cost. No projection onto bars: candle has no SHAKE.
fn candle_gradient(net: &mcgnode::gnode::Net, p: &Problem, u: &Controls) -> (f64, Vec<f64>) {
    let dev = Device::Cpu;
    let g = p.graph;
    let (n, d) = (g.n(), g.dim);
    let nd = n * d;
    let plan = mcgnode::gnode::GraphPlan::new(g);
    let (dt, sub) = (p.timing.step(), p.timing.substeps());
    let driven = p.driven();
    let w = driven.len() * d;
    let uv = Var::from_slice(&u.u, u.u.len(), &dev).unwrap();
    let knot = |k: usize| uv.as_tensor().narrow(0, k * w, w).unwrap();
    let pick = |x: &[f64]| -> Vec<f64> {
        driven
            .iter()
            .flat_map(|&i| x[i * d..(i + 1) * d].to_vec())
            .collect()
    };
    let v0 = Tensor::from_vec(pick(&p.start.v), w, &dev).unwrap();
    // Driven coordinates: a 0/1 mask, and the map from drive rows onto them.
    let mut mask = vec![0.0; nd];
    let mut put = vec![0.0; nd * w];
    for (j, &i) in driven.iter().enumerate() {
        for c in 0..d {
            mask[i * d + c] = 1.0;
            put[(i * d + c) * w + j * d + c] = 1.0;
        }
    }
    let keep = Tensor::from_vec(mask.iter().map(|m| 1.0 - m).collect(), nd, &dev).unwrap();
    let put = Tensor::from_vec(put, (nd, w), &dev).unwrap();
    let place = |x: &Tensor, row: &Tensor| -> Tensor {
        let driven = put
            .matmul(&row.unsqueeze(1).unwrap())
            .unwrap()
            .squeeze(1)
            .unwrap();
        ((x * &keep).unwrap() + driven).unwrap()
    };
    let accel = |q: &Tensor, v: &Tensor| -> Tensor {
        let mut b = mcgnode::gnode::Batch::new(&plan, &[p.start], None, net.hyper.types).unwrap();
        b.q = q.reshape((n, d)).unwrap();
        b.v = v.reshape((n, d)).unwrap();
        if !plan.bars.is_empty() {
            b.constraint = Some(mcgnode::testing::candle_constraint(&plan, &b.q, &b.v).unwrap());
        }
        let a = net.forward(&b).unwrap().acc.reshape(nd).unwrap();
        (a * &keep).unwrap()
    };
    let scalar = |x: f64| Tensor::new(x, &dev).unwrap();
    let mut q = Tensor::from_vec(p.start.q.clone(), nd, &dev).unwrap();
    let mut v = Tensor::from_vec(p.start.v.clone(), nd, &dev).unwrap();
    let mut a = accel(&q, &v);
    let (mut dq_prev, mut vel_prev) = (
        Tensor::from_vec(pick(&p.start.q), w, &dev).unwrap(),
        v0.clone(),
    );
    let mut cost = scalar(0.0);
    let c = &p.cost;
    for j in 1..=u.steps * sub {
        let (k, s) = ((j - 1) / sub, ((j - 1) % sub + 1) as f64 / sub as f64);
        let from = if k == 0 { v0.clone() } else { knot(k - 1) };
        let vel = ((from * (1.0 - s)).unwrap() + (knot(k) * s).unwrap()).unwrap();
        let dqj = (&dq_prev + ((&vel_prev + &vel).unwrap() * (0.5 * dt)).unwrap()).unwrap();
        q = ((&q + (&v * dt).unwrap()).unwrap() + (&a * (0.5 * dt * dt)).unwrap()).unwrap();
        v = (&v + (&a * (0.5 * dt)).unwrap()).unwrap();
        q = place(&q, &dqj);
        v = place(&v, &vel);
        a = accel(&q, &v);
        v = (&v + (&a * (0.5 * dt)).unwrap()).unwrap();
        (dq_prev, vel_prev) = (dqj, vel);
        if j % sub == 0 {
            for (t, &pi) in c.particles.iter().enumerate() {
                let qi = q.narrow(0, pi * d, d).unwrap();
                let vi = v.narrow(0, pi * d, d).unwrap();
                let tgt =
                    Tensor::from_vec(c.targets[t * d..(t + 1) * d].to_vec(), d, &dev).unwrap();
                let term = ((qi - tgt).unwrap().sqr().unwrap().sum_all().unwrap()
                    + (vi.sqr().unwrap().sum_all().unwrap() * c.speed).unwrap())
                .unwrap();
                cost = (cost + (term / p.timing.horizon as f64).unwrap()).unwrap();
            }
        }
    }
    let effort =
        (uv.as_tensor().sqr().unwrap().sum_all().unwrap() * (c.effort * p.timing.dt)).unwrap();
    let cost = (cost + effort).unwrap();
    let grads = cost.backward().unwrap();
    let gu = grads.get(&uv).unwrap().to_vec1::<f64>().unwrap();
    (cost.to_scalar::<f64>().unwrap(), gu)
}

/// The reverse sweep equals candle's autodiff of the same rollout to 1e-8
/// relative, for every variant on the held chain of springs, and on the
/// chain of bars for the models whose rollouts it projects on nothing
/// (NODE, GNODE: no learned masses; MCGNODE with projection off).
#[test]
fn gradients_equal_candle_autodiff_through_the_rollout() {
    let cfg = SystemConfig::new(SystemKind::HeldChain, 5);
    let springs = cfg.graph();
    let spring_start = cfg.start_for(&springs, 2, 0);
    let (bars, bar_start) = bar_chain(4);
    let mut cases = vec![];
    for v in Variant::ALL {
        cases.push((v, &springs, &spring_start, true));
    }
    for v in [Variant::Node, Variant::Gnode, Variant::Mcgnode] {
        cases.push((v, &bars, &bar_start, v != Variant::Mcgnode));
    }
    for (k, (v, g, start, project)) in cases.into_iter().enumerate() {
        let (net, mut model) = random_model(v, g, 20 + k as u64).unwrap();
        model.kernel.set_project_bars(project);
        let p = problem(&model, g, start);
        let mut rng = ChaCha8Rng::seed_from_u64(k as u64);
        let u = Controls {
            steps: p.timing.horizon,
            width: p.width(),
            u: (0..p.timing.horizon * p.width())
                .map(|_| rng.random_range(-0.6..0.6))
                .collect(),
        };
        let ours = p.gradient(&u).unwrap();
        let (cost, theirs) = candle_gradient(&net, &p, &u);
        let name = format!("{v} on {} particles", g.n());
        assert!(
            (cost - ours.cost).abs() <= 1e-12 * cost.abs(),
            "{name}: cost {} vs candle {cost}",
            ours.cost
        );
        let r = rel(&ours.grad, &theirs);
        assert!(
            r <= 1e-8,
            "{name}: {:?} vs candle {theirs:?}: {r:.2e}",
            ours.grad
        );
        eprintln!("{name}: gradient vs candle {r:.1e}");
    }
}
