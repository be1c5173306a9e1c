//! Baselines: candle grad-of-grad, LGN/HGN mechanics against analytic
//! Lagrangians/Hamiltonians, gradients against finite differences, GNS, files,
//! training.

use candle_core::{Device, Tensor, Var};
use mcgnode::baselines::{ensure_second_order, probe_second_derivative, DO_NOT_DETACH};
use mcgnode::baselines::{euler_lagrange, hamilton};
use mcgnode::gnode::Batch;
use mcgnode::gnode::GraphPlan;
use mcgnode::physics::{acceleration, SystemConfig, SystemKind};
use mcgnode::system::{Graph, State};
use std::process::Command;

const CHILD: &str = "MCGNODE_GRAD_PROBE_CHILD";

/// Child-process half of [`second_derivatives_need_do_not_detach`]: prints what
/// candle does in a fresh process. Run directly (no child variable), it checks
/// that the library's own switch works in-process.
#[test]
fn grad_probe_child() {
    match std::env::var(CHILD).as_deref() {
        Ok("probe") => match probe_second_derivative().unwrap() {
            Some(x) => println!("PROBE={x}"),
            None => println!("PROBE=none"),
        },
        Ok("late") => {
            // A backward pass before the variable is set fixes candle's
            // per-thread setting: the library must then refuse, not give zeros.
            let x = Var::new(&[1.0f64], &Device::Cpu).unwrap();
            x.as_tensor()
                .sqr()
                .unwrap()
                .sum_all()
                .unwrap()
                .backward()
                .unwrap();
            println!("LATE={}", ensure_second_order().is_err());
        }
        Ok(other) => panic!("unknown probe mode {other}"),
        Err(_) => {
            ensure_second_order().unwrap();
            let x = probe_second_derivative().unwrap().unwrap();
            assert!((x - 12.0).abs() < 1e-9, "{x}");
        }
    }
}

fn run_child(mode: &str, var: Option<&str>) -> String {
    let exe = std::env::current_exe().unwrap();
    let mut c = Command::new(exe);
    c.args([
        "--exact",
        "grad_probe_child",
        "--nocapture",
        "--test-threads=1",
    ])
    .env(CHILD, mode);
    match var {
        Some(v) => c.env(DO_NOT_DETACH, v),
        None => c.env_remove(DO_NOT_DETACH),
    };
    let out = c.output().expect("running the test binary as a child");
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "child failed: {text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

/// The second derivative the child reports (NaN for "none").
fn child_probe(var: Option<&str>) -> f64 {
    let text = run_child("probe", var);
    let v = text
        .split("PROBE=")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .unwrap_or_else(|| panic!("no probe line in child output: {text}"));
    v.parse().unwrap_or(f64::NAN)
}

#[test]
fn second_derivatives_need_do_not_detach() {
    // Without the variable candle detaches between ops: d/dx of (d/dx x³)
    // loses the chain-rule terms and comes out −6 instead of 6x = 12.
    for var in [None, Some("0")] {
        let x = child_probe(var);
        assert!(
            (x + 6.0).abs() < 1e-9,
            "without the variable ({var:?}): {x}"
        );
    }
    // With it, 6x at x = 2.
    let x = child_probe(Some("1"));
    assert!((x - 12.0).abs() < 1e-9, "with the variable: {x}");
    // Too late on a thread that already ran backward: a clear error.
    assert!(run_child("late", None).contains("LATE=true"));
    // In this process the library switches it on itself.
    ensure_second_order().unwrap();
    let x = probe_second_derivative().unwrap().unwrap();
    assert!((x - 12.0).abs() < 1e-9, "{x}");
}

fn states(
    kind: SystemKind,
    n: usize,
    count: usize,
    seed: u64,
) -> (SystemConfig, Graph, Vec<State>) {
    let c = SystemConfig::new(kind, n);
    let g = c.graph();
    let mut s: Vec<State> = (0..count).map(|i| c.start_for(&g, seed, i)).collect();
    // Start states have small velocities; give them some to exercise q̇ terms.
    for (i, st) in s.iter_mut().enumerate() {
        let (a, _) = mcgnode::physics::bar_jacobian(&g, st);
        for (k, v) in st.v.iter_mut().enumerate() {
            *v += 0.3 * ((i * 7 + k * 3) as f64).sin();
        }
        if a.nrows() > 0 {
            // Project velocities onto the constraint manifold (A v = 0).
            let av = &a * nalgebra::DVector::from_vec(st.v.clone());
            let lam = (&a * a.transpose()).lu().solve(&av).unwrap();
            let fix = a.transpose() * lam;
            for (v, f) in st.v.iter_mut().zip(fix.iter()) {
                *v -= f;
            }
        }
    }
    (c, g, s)
}

fn vars(b: &Batch) -> (Var, Var) {
    (
        Var::from_tensor(&b.q).unwrap(),
        Var::from_tensor(&b.v).unwrap(),
    )
}

/// Σ ½k(|q_a − q_b| − r)² over the forward particle edges (all springs here).
fn spring_energy(g: &Graph, b: &Batch, q: &Tensor) -> mcgnode::Result<Tensor> {
    let e = b.n_directed / 2;
    if e == 0 {
        return Ok(Tensor::zeros((), candle_core::DType::F64, &Device::Cpu)?);
    }
    let w = (q.index_select(&b.recv.narrow(0, 0, e)?, 0)?
        - q.index_select(&b.send.narrow(0, 0, e)?, 0)?)?;
    let r = w.sqr()?.sum(1)?.sqrt()?;
    let edge = g.edges[0];
    Ok((((r - edge.rest_length)?.sqr()? * (0.5 * edge.stiffness))?).sum_all()?)
}

fn masses(g: &Graph, b: &Batch) -> Tensor {
    let m: Vec<f64> = (0..b.b).flat_map(|_| g.masses.clone()).collect();
    Tensor::from_vec(m, (b.b * b.n, 1), &Device::Cpu).unwrap()
}

fn gravity_energy(c: &SystemConfig, m: &Tensor, q: &Tensor) -> mcgnode::Result<Tensor> {
    Ok((q.narrow(1, 1, 1)? * m)?
        .sum_all()?
        .affine(c.field.gravity, 0.0)?)
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// The Euler–Lagrange code, fed the true Lagrangian, reproduces physics.
#[test]
fn euler_lagrange_matches_physics() {
    ensure_second_order().unwrap();
    for (kind, n) in [(SystemKind::Spring, 5), (SystemKind::Pendulum, 3)] {
        let (c, g, s) = states(kind, n, 4, 11);
        let plan = GraphPlan::new(&g);
        let refs: Vec<&State> = s.iter().collect();
        let b = Batch::new(&plan, &refs, None, 1).unwrap();
        let (q, v) = vars(&b);
        let m = masses(&g, &b);
        let lag = |q: &Tensor, v: &Tensor| -> mcgnode::Result<Tensor> {
            let t = (v.sqr()?.broadcast_mul(&m)?.sum_all()? * 0.5)?;
            Ok(((t - spring_energy(&g, &b, q)?)? - gravity_energy(&c, &m, q)?)?)
        };
        let acc = euler_lagrange(lag, &q, &v, b.b, b.constraint.as_ref()).unwrap();
        let got = acc.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let want: Vec<f64> = s
            .iter()
            .flat_map(|st| acceleration(&g, &c.field, st))
            .collect();
        let err = max_diff(&got, &want);
        assert!(err < 1e-10, "{kind}: max |Δq̈| = {err:e}");
        assert!(want.iter().any(|x| x.abs() > 1e-2), "test states must move");
    }
}

/// A velocity-dependent Lagrangian (rotating frame) exercises K and the mixed
/// term: L = ½m|q̇ + ωJq|² − ½κ|q|² gives q̈ = −2ωJq̇ + ω²q − κq/m.
#[test]
fn euler_lagrange_handles_velocity_dependent_lagrangians() {
    ensure_second_order().unwrap();
    let (m, w, kap) = (1.7, 0.9, 2.3);
    let qs = [0.4, -1.1, 0.7, 0.2, -0.3, 0.5];
    let vs = [0.3, 0.8, -0.6, 0.1, 1.2, -0.4];
    let q =
        Var::from_tensor(&Tensor::from_vec(qs.to_vec(), (3, 2), &Device::Cpu).unwrap()).unwrap();
    let v =
        Var::from_tensor(&Tensor::from_vec(vs.to_vec(), (3, 2), &Device::Cpu).unwrap()).unwrap();
    let jq = |q: &Tensor| -> mcgnode::Result<Tensor> {
        Ok(Tensor::cat(
            &[q.narrow(1, 1, 1)?.neg()?, q.narrow(1, 0, 1)?],
            1,
        )?)
    };
    let lag = |q: &Tensor, v: &Tensor| -> mcgnode::Result<Tensor> {
        let u = (v + (jq(q)? * w)?)?;
        Ok(((u.sqr()?.sum_all()? * (0.5 * m))? - (q.sqr()?.sum_all()? * (0.5 * kap))?)?)
    };
    let acc = euler_lagrange(lag, &q, &v, 3, None).unwrap();
    let got = acc.flatten_all().unwrap().to_vec1::<f64>().unwrap();
    for i in 0..3 {
        let (x, y, vx, vy) = (qs[2 * i], qs[2 * i + 1], vs[2 * i], vs[2 * i + 1]);
        let want = [
            2.0 * w * vy + w * w * x - kap * x / m,
            -2.0 * w * vx + w * w * y - kap * y / m,
        ];
        assert!(
            max_diff(&got[2 * i..2 * i + 2], &want) < 1e-12,
            "{got:?} vs {want:?}"
        );
    }
}

/// Hamilton's equations, fed the true Hamiltonian, reproduce physics:
/// q̇ = p/m and ṗ = m q̈ (constraint forces included for pendulums).
#[test]
fn hamilton_matches_physics() {
    ensure_second_order().unwrap();
    for (kind, n) in [(SystemKind::Spring, 4), (SystemKind::Pendulum, 3)] {
        let (c, g, s) = states(kind, n, 3, 5);
        let plan = GraphPlan::new(&g);
        let refs: Vec<&State> = s.iter().collect();
        let b = Batch::new(&plan, &refs, None, 1).unwrap();
        let m = masses(&g, &b);
        let q = Var::from_tensor(&b.q).unwrap();
        let p = Var::from_tensor(&b.v.broadcast_mul(&m).unwrap()).unwrap();
        let ham = |q: &Tensor, p: &Tensor| -> mcgnode::Result<Tensor> {
            let t = (p.sqr()?.broadcast_div(&m)?.sum_all()? * 0.5)?;
            Ok(((t + spring_energy(&g, &b, q)?)? + gravity_energy(&c, &m, q)?)?)
        };
        let (qd, pd) = hamilton(ham, &q, &p, b.b, b.constraint.as_ref()).unwrap();
        let qd = qd.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let pd = pd.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let v: Vec<f64> = s.iter().flat_map(|st| st.v.clone()).collect();
        let f: Vec<f64> = s
            .iter()
            .flat_map(|st| {
                acceleration(&g, &c.field, st)
                    .into_iter()
                    .enumerate()
                    .map(|(k, a)| a * g.masses[k / g.dim])
                    .collect::<Vec<_>>()
            })
            .collect();
        assert!(max_diff(&qd, &v) < 1e-12);
        let err = max_diff(&pd, &f);
        assert!(err < 1e-10, "{kind}: max |Δṗ| = {err:e}");
    }
}

use mcgnode::baselines::{train_baseline, BaselineHyper, BaselineNet, Kind, TrainedBaseline};
use mcgnode::dynamics::Dynamics;
use mcgnode::physics::rk4_trajectories;
use mcgnode::train::TrainConfig;
use rand::SeedableRng;

fn dataset(
    kind: SystemKind,
    n: usize,
    traj: usize,
    seed: u64,
) -> (Graph, Vec<State>, Vec<Vec<f64>>) {
    let c = SystemConfig::new(kind, n);
    let t = c.simulate(traj, seed);
    let mut s = vec![];
    let mut a = vec![];
    for tr in &t {
        for x in &tr.samples {
            s.push(x.state.clone());
            a.push(x.acc.clone().unwrap());
        }
    }
    (t[0].graph.clone(), s, a)
}

fn loss_of(net: &BaselineNet, b: &Batch, g: &Graph) -> f64 {
    net.loss(b, &g.masses).unwrap().to_scalar::<f64>().unwrap()
}

/// LGN's accelerations with the Hessian taken as the learned mass (exact for
/// its Lagrangian) equal the generic Euler–Lagrange ones, with and without bars.
#[test]
fn lgn_shortcut_equals_generic_euler_lagrange() {
    for (sys, n) in [(SystemKind::Spring, 5), (SystemKind::Pendulum, 4)] {
        let (g, s, _) = dataset(sys, n, 1, 4);
        let plan = GraphPlan::new(&g);
        let refs: Vec<&State> = s.iter().step_by(9).collect();
        let b = Batch::new(&plan, &refs, None, 1).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let net = BaselineNet::new(BaselineHyper::new(Kind::Lgn, 2, 1), &mut rng).unwrap();
        let lm = net.store.get("log_mass").unwrap();
        lm.set(&Tensor::new(&[0.4f64], &Device::Cpu).unwrap())
            .unwrap();
        let flat = |t: Tensor| t.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let fast = flat(mcgnode::baselines::lgn::acceleration(&net, &b).unwrap());
        let generic = flat(mcgnode::baselines::lgn::acceleration_generic(&net, &b).unwrap());
        let scale = generic.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.0);
        let d = max_diff(&fast, &generic);
        assert!(d <= 1e-12 * scale, "{sys:?}: shortcut vs generic {d:.2e}");
    }
}

/// d loss/dθ by candle (through the derivative of the learned scalar) against
/// central finite differences, for a few entries of several parameters.
#[test]
fn training_gradients_match_finite_differences() {
    for (kind, sys, n) in [
        (Kind::Lgn, SystemKind::Spring, 4),
        (Kind::Lgn, SystemKind::Pendulum, 3),
        (Kind::Hgn, SystemKind::Spring, 4),
        (Kind::Hgn, SystemKind::Pendulum, 3),
        (Kind::Gns, SystemKind::Spring, 4),
    ] {
        let (g, s, a) = dataset(sys, n, 1, 3);
        let plan = GraphPlan::new(&g);
        let idx = [5usize, 40, 77];
        let refs: Vec<&State> = idx.iter().map(|&i| &s[i]).collect();
        let accs: Vec<&[f64]> = idx.iter().map(|&i| a[i].as_slice()).collect();
        let b = Batch::new(&plan, &refs, Some(&accs), 1).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let net = BaselineNet::new(BaselineHyper::new(kind, 2, 1), &mut rng).unwrap();
        // Move the masses off 1 so their gradient is generic.
        if kind != Kind::Gns {
            let lm = net.store.get("log_mass").unwrap();
            lm.set(&Tensor::new(&[0.3f64], &Device::Cpu).unwrap())
                .unwrap();
        }
        let grads = net.loss(&b, &g.masses).unwrap().backward().unwrap();
        let mut names: Vec<&str> =
            vec!["node_em.l0.w", "gn0.e.l1.b", "gn0.v.l0.w", "node_out.l1.w"];
        if kind != Kind::Gns {
            names.extend(["edge_out.l0.w", "log_mass"]);
        }
        let mut checked = 0;
        for name in names {
            let var = net.store.get(name).unwrap();
            let base = var
                .as_tensor()
                .flatten_all()
                .unwrap()
                .to_vec1::<f64>()
                .unwrap();
            let gv = grads
                .get(var.as_tensor())
                .unwrap_or_else(|| panic!("{kind}: no gradient for {name}"))
                .flatten_all()
                .unwrap()
                .to_vec1::<f64>()
                .unwrap();
            for &k in &[0usize, base.len() / 2, base.len() - 1] {
                let h = 1e-5;
                let eval = |x: f64| {
                    let mut p = base.clone();
                    p[k] = x;
                    var.set(&Tensor::from_vec(p, var.shape(), &Device::Cpu).unwrap())
                        .unwrap();
                    loss_of(&net, &b, &g)
                };
                let fd = (eval(base[k] + h) - eval(base[k] - h)) / (2.0 * h);
                eval(base[k]);
                let tol = 1e-6 * (1.0 + fd.abs());
                assert!(
                    (fd - gv[k]).abs() < tol,
                    "{kind} on {sys}: d loss/d {name}[{k}] autodiff {} vs finite difference {fd}",
                    gv[k]
                );
                checked += usize::from(fd.abs() > 1e-8);
            }
        }
        assert!(
            checked >= 5,
            "{kind}: too few non-zero gradients checked ({checked})"
        );
    }
}

/// The RK4 Hamiltonian data agree with the velocity-Verlet ground truth.
#[test]
fn rk4_data_match_verlet_data() {
    for (kind, n) in [(SystemKind::Spring, 3), (SystemKind::Pendulum, 2)] {
        let mut c = SystemConfig::new(kind, n);
        c.states = 20;
        if kind == SystemKind::Pendulum {
            // Coarser steps keep the test fast; both integrators remain accurate.
            c.dt = 1e-4;
            c.save_every = 100;
        }
        let rk = rk4_trajectories(&c, 2, 4).unwrap();
        let vv = c.simulate(2, 4);
        for (a, b) in rk.iter().zip(&vv) {
            assert_eq!(a.samples.len(), b.samples.len());
            for (x, y) in a.samples.iter().zip(&b.samples) {
                let d = max_diff(&x.state.q, &y.state.q).max(max_diff(&x.state.v, &y.state.v));
                assert!(
                    d < 1e-4,
                    "{kind}: RK4 and Verlet states differ by {d:e} at t = {}",
                    x.t
                );
            }
            let last = &a.samples.last().unwrap().state;
            assert!(
                max_diff(&last.q, &a.samples[0].state.q) > 1e-2,
                "system must move"
            );
        }
    }
}

fn quick_cfg(epochs: usize) -> TrainConfig {
    TrainConfig {
        epochs,
        patience: epochs,
        ..TrainConfig::default()
    }
}

/// Each baseline learns (the validation loss falls), saves, loads to the same
/// predictions and rolls out through `Dynamics`.
#[test]
fn baselines_train_save_load_and_roll_out() {
    let dir = tempfile::tempdir().unwrap();
    for kind in Kind::ALL {
        let (g, s, a) = dataset(SystemKind::Spring, 3, 4, 21);
        let mut first = None;
        let mut cfg = quick_cfg(15);
        cfg.lr = 3e-3;
        cfg.batch = 25;
        let t = train_baseline(BaselineHyper::new(kind, 2, 1), &g, &s, &a, &cfg, |r| {
            first.get_or_insert(r.validation_loss);
            true
        })
        .unwrap();
        let first = first.unwrap();
        let best = t.file.training.validation_loss;
        eprintln!("{kind}: validation loss {first:.3e} → {best:.3e}");
        assert!(
            best < 0.85 * first,
            "{kind}: validation loss {first} → {best}"
        );
        let path = dir.path().join(format!("{kind}.json"));
        t.file.save(&path).unwrap();
        let back = TrainedBaseline::load(&path).unwrap();
        assert_eq!(back.file, t.file);
        let mut x = vec![0.0; g.ndof()];
        let mut y = vec![0.0; g.ndof()];
        t.acceleration(&g, &s[3], &mut x).unwrap();
        back.acceleration(&g, &s[3], &mut y).unwrap();
        assert_eq!(x, y);
        let roll = back
            .rollout(
                &g,
                &s[0],
                mcgnode::dynamics::Timing::integration(0.01, 20, 1),
            )
            .unwrap();
        assert_eq!(roll.len(), 21);
        assert!(roll.iter().all(|st| st.validate(&g).is_ok()));
        // Batched lockstep rollouts (one candle call per step for all starts)
        // follow each start's own rollout.
        let starts = [s[0].clone(), s[21].clone(), s[42].clone()];
        let many = back
            .rollout_many(
                &g,
                &starts,
                mcgnode::dynamics::Timing::integration(0.01, 20, 5),
            )
            .unwrap();
        for (st, r) in starts.iter().zip(&many) {
            assert_eq!(r.diverged_at, None);
            let one = back
                .rollout(&g, st, mcgnode::dynamics::Timing::integration(0.01, 20, 5))
                .unwrap();
            assert_eq!(r.states.len(), one.len());
            for (a, b) in r.states.iter().zip(&one) {
                let d = max_diff(&a.q, &b.q).max(max_diff(&a.v, &b.v));
                assert!(
                    d < 1e-12,
                    "{kind}: lockstep differs from single rollout by {d}"
                );
            }
        }
        // Inductive: a 5-spring ring with the same model.
        let (g5, s5, _) = dataset(SystemKind::Spring, 5, 1, 2);
        back.acceleration(&g5, &s5[0], &mut vec![0.0; g5.ndof()])
            .unwrap();
        // Bad input is an error, not a panic.
        assert!(back.acceleration(&g, &s5[0], &mut x).is_err());
        let mut g3 = g.clone();
        g3.dim = 3;
        assert!(back.supports(&g3).is_err());
    }
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, "{\"format\": \"other\"}").unwrap();
    assert!(TrainedBaseline::load(&bad).is_err());
}

/// A batch with targets of `count` states of a system (3D when `dim` is 3).
fn target_batch(kind: SystemKind, n: usize, dim: usize, count: usize) -> (Graph, Batch) {
    let mut c = SystemConfig::new(kind, n);
    c.dim = dim;
    c.states = 20;
    let t = c.simulate(1, 6);
    let g = t[0].graph.clone();
    let plan = GraphPlan::new(&g);
    let picked: Vec<&mcgnode::system::Sample> =
        t[0].samples.iter().step_by(3).take(count).collect();
    let refs: Vec<&State> = picked.iter().map(|x| &x.state).collect();
    let accs: Vec<&[f64]> = picked.iter().map(|x| x.acc.as_deref().unwrap()).collect();
    let b = Batch::new(&plan, &refs, Some(&accs), 1).unwrap();
    (g, b)
}

fn flat(t: &Tensor) -> Vec<f64> {
    t.flatten_all().unwrap().to_vec1::<f64>().unwrap()
}

/// ‖a − b‖∞ / ‖b‖∞.
fn rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(scale > 0.0, "reference is all zeros");
    max_diff(a, b) / scale
}

/// HGN's derivatives with ∂H/∂p = M⁻¹p, H_pp = M⁻¹, H_pq = 0 and ∂V/∂q by
/// the hand-written backward pass equal the generic Hamilton code's, and so
/// do LGN's accelerations; with and without bars, in 2D and 3D.
#[test]
fn hand_written_potential_gradient_equals_autodiff() {
    for (sys, n, dim) in [
        (SystemKind::Spring, 5, 2),
        (SystemKind::Pendulum, 4, 2),
        (SystemKind::Spring, 4, 3),
        // Far from 5 particles, and a 3D lattice with many edges per node.
        (SystemKind::Spring, 40, 2),
        (SystemKind::Peridynamic, 27, 3),
    ] {
        let (g, b) = target_batch(sys, n, dim, 4);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        let net = BaselineNet::new(BaselineHyper::new(Kind::Hgn, dim, 1), &mut rng).unwrap();
        net.store
            .get("log_mass")
            .unwrap()
            .set(&Tensor::new(&[0.35f64], &Device::Cpu).unwrap())
            .unwrap();
        let m = masses(&g, &b);
        let p = b.v.broadcast_mul(&m).unwrap();
        let (qd, pd) = mcgnode::baselines::hgn::derivatives(&net, &b, &p).unwrap();
        let (qg, pg) = mcgnode::baselines::hgn::derivatives_generic(&net, &b, &p).unwrap();
        assert!(rel(&flat(&qd), &flat(&qg)) < 1e-12, "{sys} {dim}D: q̇");
        let e = rel(&flat(&pd), &flat(&pg));
        assert!(e < 1e-12, "{sys} {dim}D: ṗ differs by {e:e} (relative)");
        // Independently: ∂V/∂q against central differences of V.
        let gq = flat(&net.potential_grad(&b, &b.q).unwrap());
        let q0 = flat(&b.q);
        let v_at = |k: usize, h: f64| {
            let mut q = q0.clone();
            q[k] += h;
            let q = Tensor::from_vec(q, b.q.dims(), &Device::Cpu).unwrap();
            net.potential(&b, &q).unwrap().to_scalar::<f64>().unwrap()
        };
        for k in [0, q0.len() / 2, q0.len() - 1] {
            let fd = (v_at(k, 1e-6) - v_at(k, -1e-6)) / 2e-6;
            assert!(
                (fd - gq[k]).abs() < 1e-7 * (1.0 + fd.abs()),
                "{sys}: ∂V/∂q[{k}] {} vs {fd}",
                gq[k]
            );
        }
    }
}

/// Training gradients (d loss/dθ for every parameter) through the
/// hand-written ∂V/∂q equal candle's grad-of-grad through the generic
/// mechanics, for LGN and HGN, with and without bars, 2D and 3D.
#[test]
fn training_gradients_equal_grad_of_grad() {
    for kind in [Kind::Lgn, Kind::Hgn] {
        for (sys, n, dim) in [
            (SystemKind::Spring, 5, 2),
            (SystemKind::Pendulum, 3, 2),
            (SystemKind::Spring, 4, 3),
            (SystemKind::Peridynamic, 8, 3),
        ] {
            let (g, b) = target_batch(sys, n, dim, 3);
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
            let net = BaselineNet::new(BaselineHyper::new(kind, dim, 1), &mut rng).unwrap();
            net.store
                .get("log_mass")
                .unwrap()
                .set(&Tensor::new(&[-0.2f64], &Device::Cpu).unwrap())
                .unwrap();
            let fast = net.loss(&b, &g.masses).unwrap();
            let generic = if kind == Kind::Hgn {
                mcgnode::baselines::hgn::loss_generic(&net, &b, &g.masses).unwrap()
            } else {
                let a = mcgnode::baselines::lgn::acceleration_generic(&net, &b).unwrap();
                (a - b.target.as_ref().unwrap())
                    .unwrap()
                    .sqr()
                    .unwrap()
                    .mean_all()
                    .unwrap()
            };
            let (lf, lg) = (
                fast.to_scalar::<f64>().unwrap(),
                generic.to_scalar::<f64>().unwrap(),
            );
            assert!(
                (lf - lg).abs() <= 1e-12 * lg.abs(),
                "{kind} {sys}: loss {lf} vs {lg}"
            );
            let (gf, gg) = (fast.backward().unwrap(), generic.backward().unwrap());
            let mut all_f = vec![];
            let mut all_g = vec![];
            for name in net.store.names() {
                let v = net.store.get(name).unwrap();
                // Output biases do not reach ∂V/∂q: no gradient is a zero gradient.
                let zero = || vec![0.0; v.elem_count()];
                all_f.extend(gf.get(v.as_tensor()).map_or_else(zero, flat));
                all_g.extend(gg.get(v.as_tensor()).map_or_else(zero, flat));
            }
            let e = rel(&all_f, &all_g);
            assert!(
                e < 1e-10,
                "{kind} on {sys} {dim}D: gradients differ by {e:e} (relative ∞-norm)"
            );
        }
    }
}

/// The graph network's input backward pass, with GNS's residual updates and
/// distance feature, against candle's autodiff of Σ c_h∘h + Σ c_e∘e.
#[test]
fn graph_network_input_gradients_equal_autodiff() {
    use mcgnode::baselines::{GraphNet, GraphNetSpec};
    use mcgnode::gnode::ParamStore;
    for (residual, edge_distance, rounds) in [(true, true, 2), (false, false, 1), (false, true, 2)]
    {
        let (_, b) = target_batch(SystemKind::Spring, 5, 2, 3);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        let mut store = ParamStore::new();
        let spec = GraphNetSpec {
            node_in: 3,
            dim: 2,
            hidden: 7,
            latent: 6,
            rounds,
            residual,
            edge_distance,
        };
        let net = GraphNet::new(&mut store, spec, &mut rng).unwrap();
        let q = Var::from_tensor(&b.q).unwrap();
        let x = Tensor::cat(&[&b.onehot, q.as_tensor()], 1).unwrap();
        let t = net.run_traced(&store, &b, q.as_tensor(), &x).unwrap();
        let e = t.e.clone().unwrap();
        let ch = Tensor::randn(0.0f64, 1.0, t.h.dims(), &Device::Cpu).unwrap();
        let ce = Tensor::randn(0.0f64, 1.0, e.dims(), &Device::Cpu).unwrap();
        let s = ((&t.h * &ch).unwrap().sum_all().unwrap() + (&e * &ce).unwrap().sum_all().unwrap())
            .unwrap();
        let want = flat(s.backward().unwrap().get(q.as_tensor()).unwrap());
        let (gx, gq) = net.input_grads(&store, &b, &t, &ch, Some(&ce)).unwrap();
        let got = (gx.narrow(1, 1, 2).unwrap() + gq.unwrap()).unwrap();
        let err = rel(&flat(&got), &want);
        assert!(
            err < 1e-12,
            "residual {residual}, distance {edge_distance}: {err:e}"
        );
    }
}

/// The baselines (candle) share the training loop and its checkpoints: GNS
/// stopped after epoch 2 and resumed ends with the weights of a straight run.
#[test]
fn baseline_training_resumes_from_its_checkpoint() {
    use mcgnode::train::Checkpointing;
    let (g, s, a) = dataset(SystemKind::Spring, 5, 2, 3);
    let dir = tempfile::tempdir().unwrap();
    let cfg = TrainConfig {
        threads: 1,
        ..quick_cfg(5)
    };
    let hy = BaselineHyper::new(Kind::Gns, 2, 1);
    let straight = train_baseline(hy.clone(), &g, &s, &a, &cfg, |_| true).unwrap();
    let ck = TrainConfig {
        checkpoint: Some(Checkpointing {
            path: dir.path().join("gns.json"),
            every: 0.0,
        }),
        ..cfg
    };
    assert!(train_baseline(hy.clone(), &g, &s, &a, &ck, |r| r.epoch < 2).is_err());
    let resumed = train_baseline(hy, &g, &s, &a, &ck, |r| r.epoch > 2).unwrap();
    assert_eq!(resumed.file.weights, straight.file.weights);
    assert_eq!(resumed.file.training.resumed_at, Some(2));
    assert_eq!(
        resumed.file.training.validation_loss,
        straight.file.training.validation_loss
    );
}
