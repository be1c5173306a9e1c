//! Models: the solve op's backward, candle gradients and the inference kernel
//! checked against finite differences and against each other; Newton's third
//! law; model files; bad input.

use candle_core::{Device, Tensor, Var};
use mcgnode::dynamics::Dynamics;
use mcgnode::gnode::solve;
use mcgnode::gnode::Batch;
use mcgnode::gnode::EdgeInput;
use mcgnode::gnode::GraphPlan;
use mcgnode::gnode::{Hyper, ModelFile, Net, Variant};
use mcgnode::kernel::TrainedModel;
use mcgnode::models::ModelRef;
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::system::{Graph, State};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn system(kind: SystemKind, n: usize) -> (SystemConfig, Graph) {
    let c = SystemConfig::new(kind, n);
    let g = c.graph();
    (c, g)
}

/// [`system`], with two particle types in no symmetric order when `mixed`.
fn system_of_types(kind: SystemKind, n: usize, mixed: bool) -> (SystemConfig, Graph) {
    let (c, mut g) = system(kind, n);
    if mixed {
        g.types = (0..n).map(|i| u32::from(i % 3 == 1)).collect();
    }
    (c, g)
}

fn states(c: &SystemConfig, g: &Graph, k: usize, seed: u64) -> Vec<State> {
    (0..k).map(|i| c.start_for(g, seed, i)).collect()
}

fn model_file(net: &Net) -> ModelFile {
    let (_, m) = mcgnode::testing::random_model(
        net.hyper.variant,
        &SystemConfig::new(SystemKind::Spring, net.hyper.particles).graph(),
        0,
    )
    .unwrap();
    let mut f = m.file;
    f.hyper = net.hyper.clone();
    f.weights = net.store.weights().unwrap();
    f
}

#[test]
fn solve_backward_matches_finite_differences() {
    let dev = &Device::Cpu;
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let (b, k) = (3, 4);
    // Well-conditioned, non-symmetric K so that the transpose in the backward matters.
    let mut kv: Vec<f64> = (0..b * k * k)
        .map(|_| rng.random_range(-0.5..0.5))
        .collect();
    for s in 0..b {
        for i in 0..k {
            kv[s * k * k + i * k + i] += 3.0;
        }
    }
    let bv: Vec<f64> = (0..b * k).map(|_| rng.random_range(-1.0..1.0)).collect();
    let wv: Vec<f64> = (0..b * k).map(|_| rng.random_range(-1.0..1.0)).collect();
    let w = Tensor::from_vec(wv, (b, k, 1), dev).unwrap();
    let f = |kv: &[f64], bv: &[f64]| -> f64 {
        let kt = Tensor::from_vec(kv.to_vec(), (b, k, k), dev).unwrap();
        let bt = Tensor::from_vec(bv.to_vec(), (b, k, 1), dev).unwrap();
        (solve(&kt, &bt).unwrap() * &w)
            .unwrap()
            .sum_all()
            .unwrap()
            .to_scalar::<f64>()
            .unwrap()
    };
    let kvar = Var::from_tensor(&Tensor::from_vec(kv.clone(), (b, k, k), dev).unwrap()).unwrap();
    let bvar = Var::from_tensor(&Tensor::from_vec(bv.clone(), (b, k, 1), dev).unwrap()).unwrap();
    let x = solve(kvar.as_tensor(), bvar.as_tensor()).unwrap();
    // Forward: K x = b.
    let kx = kvar.as_tensor().matmul(&x).unwrap();
    let res = (kx - bvar.as_tensor())
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap()
        .to_scalar::<f64>()
        .unwrap();
    assert!(res < 1e-12, "residual {res}");
    let loss = (x * &w).unwrap().sum_all().unwrap();
    let grads = loss.backward().unwrap();
    let gk = grads
        .get(&kvar)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f64>()
        .unwrap();
    let gb = grads
        .get(&bvar)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f64>()
        .unwrap();
    let h = 1e-6;
    for i in 0..kv.len() {
        let (mut p, mut m) = (kv.clone(), kv.clone());
        p[i] += h;
        m[i] -= h;
        let fd = (f(&p, &bv) - f(&m, &bv)) / (2.0 * h);
        assert!(
            (fd - gk[i]).abs() < 1e-7 * (1.0 + fd.abs()),
            "dK[{i}]: fd {fd} vs {}",
            gk[i]
        );
    }
    for i in 0..bv.len() {
        let (mut p, mut m) = (bv.clone(), bv.clone());
        p[i] += h;
        m[i] -= h;
        let fd = (f(&kv, &p) - f(&kv, &m)) / (2.0 * h);
        assert!(
            (fd - gb[i]).abs() < 1e-7 * (1.0 + fd.abs()),
            "db[{i}]: fd {fd} vs {}",
            gb[i]
        );
    }
}

/// d loss / d θ from candle against central differences for a few parameters of
/// every variant, on the pendulum (so the constrained solve is inside).
#[test]
fn model_gradients_match_finite_differences() {
    let (c, g) = system(SystemKind::Pendulum, 3);
    let st = states(&c, &g, 4, 11);
    let acc: Vec<Vec<f64>> = st
        .iter()
        .map(|s| mcgnode::physics::acceleration(&g, &c.field, s))
        .collect();
    let plan = GraphPlan::new(&g);
    let sr: Vec<&State> = st.iter().collect();
    let ar: Vec<&[f64]> = acc.iter().map(std::vec::Vec::as_slice).collect();
    let batch = Batch::new(&plan, &sr, Some(&ar), 1).unwrap();
    for v in Variant::ALL {
        let net = Net::new(Hyper::new(v, 2, 1, 3), &mut ChaCha8Rng::seed_from_u64(5)).unwrap();
        let grads = net.loss(&batch).unwrap().backward().unwrap();
        for name in net.store.names().to_vec() {
            let var = net.store.get(&name).unwrap().clone();
            // A parameter the loss does not depend on (the last edge update when
            // only node outputs are decoded) has no gradient: zero.
            let g_an = grads
                .get(&var)
                .cloned()
                .unwrap_or_else(|| var.as_tensor().zeros_like().unwrap())
                .flatten_all()
                .unwrap()
                .to_vec1::<f64>()
                .unwrap();
            let base = var
                .as_tensor()
                .flatten_all()
                .unwrap()
                .to_vec1::<f64>()
                .unwrap();
            for i in [0, base.len() / 2, base.len() - 1] {
                let h = 1e-6;
                let eval = |delta: f64| {
                    let mut p = base.clone();
                    p[i] += delta;
                    var.set(&Tensor::from_vec(p, var.shape(), &Device::Cpu).unwrap())
                        .unwrap();
                    net.loss(&batch).unwrap().to_scalar::<f64>().unwrap()
                };
                let fd = (eval(h) - eval(-h)) / (2.0 * h);
                eval(0.0);
                let tol = 1e-6 * (1.0 + fd.abs());
                assert!(
                    (fd - g_an[i]).abs() < tol,
                    "{v} {name}[{i}]: finite difference {fd} vs candle {}",
                    g_an[i]
                );
            }
        }
    }
}

/// The hand-written kernel equals candle's forward to 1e-12, for every variant,
/// on springs and pendulums, including a graph size the model was not built on;
/// with one round and two (the kernel runs round 0's edge update once per type
/// pair), both edge inputs, and two particle types in no symmetric order.
#[test]
fn kernel_matches_candle() {
    for (kind, n, mixed) in [
        (SystemKind::Spring, 5, false),
        (SystemKind::Spring, 12, false),
        (SystemKind::Spring, 7, true),
        (SystemKind::Pendulum, 5, false),
        (SystemKind::Pendulum, 4, true),
    ] {
        let (c, g) = system_of_types(kind, n, mixed);
        let st = states(&c, &g, 6, 21);
        let plan = GraphPlan::new(&g);
        let sr: Vec<&State> = st.iter().collect();
        let batch = Batch::new(&plan, &sr, None, 2).unwrap();
        let settings = [
            (1, EdgeInput::Product),
            (2, EdgeInput::Product),
            (1, EdgeInput::Concat),
        ];
        for (v, (rounds, edge_input)) in Variant::ALL
            .into_iter()
            .flat_map(|v| settings.map(|s| (v, s)))
        {
            let mut hy = Hyper::new(v, 2, 2, n);
            (hy.rounds, hy.edge_input) = (rounds, edge_input);
            let net = Net::new(hy, &mut ChaCha8Rng::seed_from_u64(7)).unwrap();
            let out = net.forward(&batch).unwrap();
            let acc_c = out.acc.flatten_all().unwrap().to_vec1::<f64>().unwrap();
            let m = TrainedModel::from_file(model_file(&net)).unwrap();
            let mut ws = m.kernel.workspace(&g).unwrap();
            let nd = g.ndof();
            let mut a = vec![0.0; nd];
            for (s, state) in st.iter().enumerate() {
                m.kernel.acceleration(&mut ws, &state.q, &state.v, &mut a);
                for i in 0..nd {
                    let (x, y) = (a[i], acc_c[s * nd + i]);
                    assert!(x.is_finite());
                    assert!(
                        (x - y).abs() <= 1e-12 * (1.0 + y.abs()),
                        "{v} {kind:?} n={n} rounds {rounds} {edge_input:?}: kernel {x} vs candle {y}"
                    );
                }
            }
            if let Some(f) = out.force {
                let fc = f.flatten_all().unwrap().to_vec1::<f64>().unwrap();
                m.kernel.acceleration(&mut ws, &st[5].q, &st[5].v, &mut a);
                m.kernel.read_forces(&mut ws);
                for i in 0..nd {
                    assert!(
                        (ws.force[i] - fc[5 * nd + i]).abs()
                            <= 1e-12 * (1.0 + fc[5 * nd + i].abs())
                    );
                }
            }
        }
    }
}

/// A workspace keeps values that depend on the parameters alone (the type
/// embeddings, round 0's edge update by type pair) from one step to the
/// next while the same model's parameters come back; given another model's
/// (of the same shape, as a node swapping models does), it computes them
/// again: the same bits as a fresh workspace, model after model, state
/// after state.
#[test]
fn a_workspace_follows_the_parameters_it_is_given() {
    for (kind, n, mixed) in [
        (SystemKind::Spring, 5, false),
        (SystemKind::Spring, 7, true),
        (SystemKind::Pendulum, 4, true),
    ] {
        let (c, g) = system_of_types(kind, n, mixed);
        let st = states(&c, &g, 4, 5);
        for v in [Variant::Mcgnode, Variant::Cdgnode, Variant::Gnode] {
            let models: Vec<TrainedModel> = [7, 8]
                .map(|seed| {
                    let net =
                        Net::new(Hyper::new(v, 2, 2, n), &mut ChaCha8Rng::seed_from_u64(seed));
                    TrainedModel::from_file(model_file(&net.unwrap())).unwrap()
                })
                .into();
            let mut shared = models[0].kernel.workspace(&g).unwrap();
            let bits = |a: &[f64]| a.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            for (k, s) in st.iter().enumerate() {
                for m in [&models[k % 2], &models[1 - k % 2], &models[k % 2]] {
                    let (mut got, mut want) = (vec![0.0; g.ndof()], vec![0.0; g.ndof()]);
                    m.kernel.acceleration(&mut shared, &s.q, &s.v, &mut got);
                    let mut fresh = m.kernel.workspace(&g).unwrap();
                    m.kernel.acceleration(&mut fresh, &s.q, &s.v, &mut want);
                    assert_eq!(bits(&got), bits(&want), "{v} {kind:?} n={n} state {k}");
                }
            }
            // The two models differ, so a stale value would have shown.
            let mut a = [vec![0.0; g.ndof()], vec![0.0; g.ndof()]];
            for (m, a) in models.iter().zip(&mut a) {
                m.kernel.acceleration(&mut shared, &st[0].q, &st[0].v, a);
            }
            assert_ne!(bits(&a[0]), bits(&a[1]));
        }
    }
}

/// A contact workspace reuses its edge layout while the contacts stay those
/// of the step before, and lays them out again when they change: along a
/// soft-sphere trajectory whose contacts come and go (each state twice in a
/// row, then the next), every acceleration has a fresh workspace's bits.
#[test]
fn a_contact_workspace_follows_its_contacts() {
    let cfg = SystemConfig::new(SystemKind::SoftSpheres, 9);
    let tr = cfg.simulate(1, 3).remove(0);
    let g = &tr.graph;
    for v in [Variant::Mcgnode, Variant::Gnode] {
        let (_, m) = mcgnode::testing::random_model(v, g, 4).unwrap();
        let mut shared = m.kernel.workspace(g).unwrap();
        let bits = |a: &[f64]| a.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mut sets = vec![];
        for (k, s) in tr.samples.iter().map(|x| &x.state).enumerate() {
            for _ in 0..2 {
                let (mut got, mut want) = (vec![0.0; g.ndof()], vec![0.0; g.ndof()]);
                m.kernel.acceleration(&mut shared, &s.q, &s.v, &mut got);
                let mut fresh = m.kernel.workspace(g).unwrap();
                m.kernel.acceleration(&mut fresh, &s.q, &s.v, &mut want);
                assert_eq!(bits(&got), bits(&want), "{v} state {k}");
            }
            sets.push(shared.edge_pairs().collect::<Vec<_>>());
        }
        sets.dedup();
        assert!(sets.len() > 2, "the contacts changed along the trajectory");
    }
}

/// Constrained variants satisfy A q̈ + Ȧ q̇ = 0 whatever their weights.
#[test]
fn constrained_accelerations_respect_bars() {
    let (c, g) = system(SystemKind::Pendulum, 5);
    for v in [Variant::Cgnode, Variant::Cdgnode, Variant::Mcgnode] {
        let (_, m) = mcgnode::testing::random_model(v, &g, 3).unwrap();
        for s in states(&c, &g, 5, 8) {
            let mut a = vec![0.0; g.ndof()];
            m.acceleration(&g, &s, &mut a).unwrap();
            let plan = GraphPlan::new(&g);
            let k = plan.bars.len();
            let (mut am, mut adq) = (vec![0.0; k * g.ndof()], vec![0.0; k]);
            plan.constraint_rows(&s.q, &s.v, &mut am, &mut adq);
            for r in 0..k {
                let lhs: f64 = (0..g.ndof())
                    .map(|j| am[r * g.ndof() + j] * a[j])
                    .sum::<f64>()
                    + adq[r];
                assert!(lhs.abs() < 1e-10, "{v}: constraint {r} violated by {lhs}");
            }
        }
    }
}

/// MCGNODE's pairwise forces are antisymmetric and sum to zero (no body branch).
#[test]
fn mcgnode_forces_obey_newtons_third_law() {
    let (c, g) = system(SystemKind::Spring, 7);
    let mut hy = Hyper::new(Variant::Mcgnode, 2, 1, 7);
    hy.body_force = false;
    let net = Net::new(hy, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
    let m = TrainedModel::from_file(model_file(&net)).unwrap();
    let s = c.start_for(&g, 4, 0);
    let f = m.forces(&g, &s).unwrap();
    assert_eq!(f.edges.len(), 7);
    for c in 0..2 {
        let total: f64 = (0..7).map(|i| f.total[i * 2 + c]).sum();
        let scale: f64 = (0..7).map(|i| f.total[i * 2 + c].abs()).sum();
        assert!(scale > 1e-6, "forces should not vanish");
        assert!(
            total.abs() < 1e-14 * scale.max(1.0),
            "net internal force {total}"
        );
    }
}

#[test]
fn model_file_round_trip_and_bad_files() {
    let (c, g) = system(SystemKind::Pendulum, 3);
    let (_, m) = mcgnode::testing::random_model(Variant::Mcgnode, &g, 9).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("m.json");
    m.file.save(&p).unwrap();
    let back = TrainedModel::load(&p).unwrap();
    assert_eq!(back.file, m.file);
    let s = c.start_for(&g, 1, 0);
    let (mut a1, mut a2) = (vec![0.0; 6], vec![0.0; 6]);
    m.acceleration(&g, &s, &mut a1).unwrap();
    back.acceleration(&g, &s, &mut a2).unwrap();
    assert_eq!(
        a1, a2,
        "weights must survive the JSON round trip bit for bit"
    );

    std::fs::write(dir.path().join("junk.json"), "{ not json").unwrap();
    // The typed cause is found again through the context: a caller can
    // branch on a missing file without matching the message.
    let Err(e) = mcgnode::models::load_any_model(&ModelRef::File(dir.path().join("junk.json")))
    else {
        panic!("junk.json loaded");
    };
    assert!(
        matches!(
            e.find::<mcgnode::gnode::ModelFileError>(),
            Some(mcgnode::gnode::ModelFileError::Parse { .. })
        ),
        "{e:?}"
    );
    assert!(e.find::<mcgnode::data::DataError>().is_none());
    let err = |p: &std::path::Path| format!("{:#}", TrainedModel::load(p).unwrap_err());
    assert!(err(&dir.path().join("missing.json")).contains("cannot read model file"));
    std::fs::write(dir.path().join("junk.json"), "{ not json").unwrap();
    assert!(err(&dir.path().join("junk.json")).contains("not a valid mcgnode model file"));
    let text = std::fs::read_to_string(&p).unwrap();
    std::fs::write(dir.path().join("cut.json"), &text[..text.len() / 2]).unwrap();
    assert!(err(&dir.path().join("cut.json")).contains("not a valid"));
    // Weights of the wrong shape.
    let mut bad = m.file.clone();
    bad.weights.get_mut("edge_out.l0.w").unwrap().shape = vec![1, 1];
    bad.save(&dir.path().join("shape.json")).unwrap();
    assert!(
        TrainedModel::load(&dir.path().join("shape.json")).is_err() || {
            // If the kernel accepted it, the forward would be wrong: it must not.
            false
        }
    );
    // A graph the model cannot handle: unknown particle type, wrong dimension.
    let mut g2 = g.clone();
    g2.types[1] = 3;
    assert!(m.supports(&g2).unwrap_err().to_string().contains("type 3"));
    let s_nan = State {
        q: vec![f64::NAN; 6],
        v: vec![0.0; 6],
    };
    assert!(m
        .rollout(
            &g,
            &s_nan,
            mcgnode::dynamics::Timing::integration(1e-3, 10, 1)
        )
        .is_err());
}

/// A branched tree of unit bars in 2D hanging from the origin (node i from
/// node (i − 1)/2), and a state on it with random angles and angular rates.
fn tree_on_bars(n: usize, seed: u64) -> (Graph, State) {
    use mcgnode::system::{Edge, EdgeKind, Endpoint};
    let bar = |a: usize, b: Endpoint| Edge {
        a,
        b,
        kind: EdgeKind::Bar,
        rest_length: 1.0,
        stiffness: 0.0,
    };
    let mut edges = vec![bar(0, Endpoint::Anchor(0))];
    edges.extend((1..n).map(|i| bar(i, Endpoint::Particle((i - 1) / 2))));
    let g = Graph {
        dim: 2,
        types: vec![0; n],
        masses: vec![1.0; n],
        edges,
        anchors: vec![vec![0.0, 0.0]],
        interaction_radius: 0.0,
        kinematic: vec![],
        periodic_box: None,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut q, mut v) = (vec![0.0; 2 * n], vec![0.0; 2 * n]);
    for i in 0..n {
        let th: f64 = rng.random_range(-1.2..1.2);
        let om: f64 = rng.random_range(-1.0..1.0);
        let (pq, pv) = if i == 0 {
            ([0.0, 0.0], [0.0, 0.0])
        } else {
            let p = (i - 1) / 2;
            ([q[2 * p], q[2 * p + 1]], [v[2 * p], v[2 * p + 1]])
        };
        q[2 * i] = pq[0] + th.sin();
        q[2 * i + 1] = pq[1] - th.cos();
        v[2 * i] = pv[0] + om * th.cos();
        v[2 * i + 1] = pv[1] + om * th.sin();
    }
    (g, State { q, v })
}

/// Learned constrained rollouts (CGNODE, MCGNODE) keep every bar length exact
/// with the projection (on by default), on a chain and on a branched tree;
/// without it the lengths drift.
#[test]
fn learned_rollouts_keep_bars_exact() {
    let (c, chain) = system(SystemKind::Pendulum, 5);
    let cases = [
        (chain.clone(), c.start_for(&chain, 3, 0)),
        tree_on_bars(6, 4),
    ];
    for (g, start) in cases {
        for v in [Variant::Cgnode, Variant::Mcgnode] {
            let mut hy = Hyper::new(v, 2, 1, g.n());
            hy.body_force = true;
            let net = Net::new(hy, &mut ChaCha8Rng::seed_from_u64(8)).unwrap();
            let worst = |project: bool| {
                let mut m = TrainedModel::from_file(model_file(&net)).unwrap();
                m.kernel.set_project_bars(project);
                let out = m
                    .rollout(
                        &g,
                        &start,
                        mcgnode::dynamics::Timing::integration(1e-3, 2000, 100),
                    )
                    .unwrap();
                out.iter()
                    .map(|s| mcgnode::physics::constraint_residual(&g, s))
                    .fold(0.0f64, f64::max)
            };
            let (on, off) = (worst(true), worst(false));
            assert!(
                on < 1e-12,
                "{v} n={}: bar error {on:.2e} with projection",
                g.n()
            );
            assert!(
                off > 100.0 * on.max(1e-14),
                "{v}: drift without projection only {off:.2e}"
            );
        }
    }
}

/// What the node asks for each state, a rollout and the forces at its start
/// from one call, equals the two asked apart (to the bit), on a model that
/// keeps its workspace between calls while the graph changes under it.
#[test]
fn predict_into_equals_rollout_and_forces_apart() {
    let (c5, g5) = system(SystemKind::Pendulum, 5);
    let (c7, g7) = system(SystemKind::Pendulum, 7);
    for v in [Variant::Gnode, Variant::Cgnode, Variant::Mcgnode] {
        let (_, m) = mcgnode::testing::random_model(v, &g5, 4).unwrap();
        // One set of buffers, refilled by every call.
        let mut p = mcgnode::Predicted::default();
        for (c, g) in [(&c5, &g5), (&c7, &g7), (&c5, &g5)] {
            let s = c.start_for(g, 9, 0);
            m.predict_into(
                g,
                &s,
                mcgnode::dynamics::Timing::integration(1e-3, 30, 3),
                &mut p,
            )
            .unwrap();
            let (states, forces) = (p.states.to_states(), p.forces.to_forces(g.dim));
            // A fresh model: nothing kept from the calls before.
            let fresh = TrainedModel::from_file(m.file.clone()).unwrap();
            assert_eq!(
                states,
                fresh
                    .rollout(g, &s, mcgnode::dynamics::Timing::integration(1e-3, 30, 3))
                    .unwrap(),
                "{v}"
            );
            assert_eq!(forces, fresh.forces(g, &s).unwrap(), "{v}");
            assert_eq!(states.len(), 11);
            assert!(forces.total.iter().any(|f| *f != 0.0), "{v}");
            assert_eq!(forces.edges.is_empty(), v != Variant::Mcgnode, "{v}");
        }
    }
}
