//! The hand-written training engine against candle's autodiff and against
//! finite differences, for every variant × {2D, 3D} × {body force on, off} ×
//! {ring, chain with anchor, branched tree of bars, 3D lattice} × {the
//! authors' architecture, the paper text's} at sizes the models were not built for; bit-identical weights whatever the thread
//! count; and both engines ending a seeded training at the same loss.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use mcgnode::engine::Engine;
use mcgnode::gnode::Batch;
use mcgnode::gnode::GraphPlan;
use mcgnode::gnode::{ArchPreset, Hyper, Net, Norm, Variant};
use mcgnode::kernel::TrainedModel;
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph, State};
use mcgnode::train::{train, EngineKind, TrainConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn edge(a: usize, b: Endpoint, kind: EdgeKind, rest: f64) -> Edge {
    Edge {
        a,
        b,
        kind,
        rest_length: rest,
        stiffness: 1.0,
    }
}

fn graph(dim: usize, n: usize, edges: Vec<Edge>, anchors: Vec<Vec<f64>>) -> Graph {
    Graph {
        dim,
        types: (0..n).map(|i| (i % 2) as u32).collect(),
        masses: (0..n).map(|i| 1.0 + 0.1 * i as f64).collect(),
        edges,
        anchors,
        interaction_radius: 0.0,
        kinematic: vec![],
        periodic_box: None,
    }
}

/// A ring of springs.
fn ring(dim: usize, n: usize) -> Graph {
    let e = (0..n)
        .map(|i| edge(i, Endpoint::Particle((i + 1) % n), EdgeKind::Spring, 1.0))
        .collect();
    graph(dim, n, e, vec![])
}

/// A chain of bars hanging from an anchor, with one spring across.
fn chain(dim: usize, n: usize) -> Graph {
    let mut e = vec![edge(0, Endpoint::Anchor(0), EdgeKind::Bar, 1.0)];
    e.extend((1..n).map(|i| edge(i, Endpoint::Particle(i - 1), EdgeKind::Bar, 1.0)));
    e.push(edge(0, Endpoint::Particle(n - 1), EdgeKind::Spring, 2.0));
    graph(dim, n, e, vec![vec![0.0; dim]])
}

/// A branched tree of bars: node i hangs from node (i − 1)/2, the root from an anchor.
fn tree(dim: usize, n: usize) -> Graph {
    let mut e = vec![edge(0, Endpoint::Anchor(0), EdgeKind::Bar, 1.0)];
    e.extend((1..n).map(|i| edge(i, Endpoint::Particle((i - 1) / 2), EdgeKind::Bar, 1.0)));
    graph(dim, n, e, vec![vec![0.0; dim]])
}

/// A 2×2×2 lattice with springs along its edges and one body diagonal.
fn lattice() -> Graph {
    let id = |x: usize, y: usize, z: usize| x + 2 * y + 4 * z;
    let mut e = vec![];
    for x in 0..2 {
        for y in 0..2 {
            for z in 0..2 {
                let a = id(x, y, z);
                if x == 0 {
                    e.push(edge(
                        a,
                        Endpoint::Particle(id(1, y, z)),
                        EdgeKind::Spring,
                        1.0,
                    ));
                }
                if y == 0 {
                    e.push(edge(
                        a,
                        Endpoint::Particle(id(x, 1, z)),
                        EdgeKind::Spring,
                        1.0,
                    ));
                }
                if z == 0 {
                    e.push(edge(
                        a,
                        Endpoint::Particle(id(x, y, 1)),
                        EdgeKind::Spring,
                        1.0,
                    ));
                }
            }
        }
    }
    e.push(edge(
        0,
        Endpoint::Particle(7),
        EdgeKind::Spring,
        3f64.sqrt(),
    ));
    graph(3, 8, e, vec![])
}

/// Systems that touch: `n` free particles, springs joining every other
/// pair (0–1, 2–3, …; a bonded pair keeps its bond) or, with `bars`, the
/// chain of bars from an anchor, then `kin` kinematic particles joined to
/// nothing; contacts within radius 1.5, so that the states of [`data`]
/// (about 0.7·√d apart along a diagonal) have a varying number of them.
fn touching(dim: usize, n: usize, kin: usize, bars: bool) -> Graph {
    let mut g = if bars {
        chain(dim, n)
    } else {
        let e = (0..n / 2)
            .map(|i| edge(2 * i, Endpoint::Particle(2 * i + 1), EdgeKind::Spring, 1.0))
            .collect();
        graph(dim, n, e, vec![])
    };
    for _ in 0..kin {
        g.types.push(1);
        g.masses.push(1.0);
    }
    g.kinematic = (0..n + kin).map(|i| i >= n).collect();
    g.interaction_radius = 1.5;
    g
}

/// Random states near the graph's rest shape, and random targets.
fn data(g: &Graph, k: usize, seed: u64) -> (Vec<State>, Vec<Vec<f64>>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let nd = g.ndof();
    let states = (0..k)
        .map(|_| State {
            q: (0..nd)
                .map(|i| (i / g.dim) as f64 * 0.7 + rng.random_range(-0.5..0.5))
                .collect(),
            v: (0..nd).map(|_| rng.random_range(-1.0..1.0)).collect(),
        })
        .collect();
    let targets = (0..k)
        .map(|_| (0..nd).map(|_| rng.random_range(-2.0..2.0)).collect())
        .collect();
    (states, targets)
}

/// ‖a − b‖∞ / ‖b‖∞.
fn rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

struct Case {
    name: String,
    graph: Graph,
    hyper: Hyper,
}

fn cases() -> Vec<Case> {
    let mut out = vec![];
    let graphs: Vec<(&str, Graph)> = vec![
        ("ring2d-7", ring(2, 7)),
        ("ring3d-6", ring(3, 6)),
        ("chain2d-4", chain(2, 4)),
        ("chain3d-3", chain(3, 3)),
        ("tree2d-6", tree(2, 6)),
        ("tree3d-7", tree(3, 7)),
        ("lattice3d-8", lattice()),
        ("touching2d-7+2", touching(2, 7, 2, false)),
        ("touching3d-6+3", touching(3, 6, 3, false)),
        ("touching-bars2d-4+2", touching(2, 4, 2, true)),
    ];
    for (gi, (gname, g)) in graphs.into_iter().enumerate() {
        for v in Variant::ALL {
            for body in [true, false] {
                for preset in [ArchPreset::Authors, ArchPreset::Paper] {
                    // Graph models are built for 5 particles and run on other
                    // sizes; NODE is not inductive.
                    let particles = if v == Variant::Node { g.n() } else { 5 };
                    let mut h = Hyper::new(v, g.dim, 2, particles).with_preset(preset);
                    h.body_force = body;
                    h.rounds = 1 + gi % 2;
                    h.interaction_radius = g.interaction_radius;
                    // The authors' preset runs with non-trivial input and output scales.
                    if preset == ArchPreset::Authors {
                        h.norm = Some(Norm {
                            q_mean: (0..g.dim).map(|c| 0.3 - 0.2 * c as f64).collect(),
                            q_scale: 1.7,
                            v_scale: 0.6,
                            w_scale: 1.3,
                            out_scale: 0.4,
                            k_scale: 2.5,
                        });
                        // Edges read their rest length and stiffness too.
                        h.edge_physics = !body;
                    }
                    out.push(Case {
                        name: format!("{v} {gname} body={body} rounds={} {preset:?}", h.rounds),
                        graph: g.clone(),
                        hyper: h,
                    });
                }
            }
        }
    }
    out
}

/// The candle model `net` of `case` as a trained model (kernel and file).
fn trained(case: &Case, net: &Net) -> TrainedModel {
    let file = mcgnode::testing::random_model(case.hyper.variant, &case.graph, 0)
        .map(|(_, m)| m.file)
        .unwrap();
    let file = mcgnode::gnode::ModelFile {
        hyper: case.hyper.clone(),
        weights: net.store.weights().unwrap(),
        ..file
    };
    TrainedModel::from_file(file).unwrap()
}

#[test]
fn engine_gradients_equal_candle_and_finite_differences() {
    for (ci, case) in cases().into_iter().enumerate() {
        let g = &case.graph;
        // One case in three uses enough states for several chunks on two threads.
        let k = if ci % 3 == 0 { 150 } else { 6 };
        let (states, targets) = data(g, k, 100 + ci as u64);
        let net = Net::new(
            case.hyper.clone(),
            &mut ChaCha8Rng::seed_from_u64(ci as u64),
        )
        .unwrap();
        // Candle.
        let plan = GraphPlan::new(g);
        let sr: Vec<&State> = states.iter().collect();
        let tr: Vec<&[f64]> = targets.iter().map(std::vec::Vec::as_slice).collect();
        let batch = Batch::new(&plan, &sr, Some(&tr), case.hyper.types).unwrap();
        let loss_c = net.loss(&batch).unwrap();
        let grads_c = loss_c.backward().unwrap();
        let loss_c = loss_c.to_scalar::<f64>().unwrap();
        // Engine.
        let mut eng = Engine::new(&case.hyper, g, 1 + ci % 2).unwrap();
        let theta = eng.layout().flatten(&net.store.weights().unwrap()).unwrap();
        let idx: Vec<usize> = (0..k).collect();
        let mut grad = vec![0.0; theta.len()];
        let samples = eng.samples(&states, &targets);
        let loss_e = eng.loss_grad(&theta, &samples, &idx, &mut grad);
        let name = &case.name;
        assert!(loss_e.is_finite() && loss_e > 0.0, "{name}: loss {loss_e}");
        assert!(
            (loss_e - loss_c).abs() <= 1e-12 * loss_c,
            "{name}: engine loss {loss_e} vs candle {loss_c}"
        );
        assert_eq!(eng.loss(&theta, &samples, &idx), loss_e, "{name}");
        // Gradients, parameter by parameter, against candle.
        let ge = eng.layout().weights(&grad);
        let mut all_e = vec![];
        let mut all_c = vec![];
        for pname in net.store.names() {
            let var = net.store.get(pname).unwrap();
            let gc = grads_c
                .get(var)
                .map(|t| t.flatten_all().unwrap().to_vec1::<f64>().unwrap())
                .unwrap_or_else(|| vec![0.0; var.elem_count()]);
            all_e.extend_from_slice(&ge[pname].data);
            all_c.extend(gc);
        }
        let r = rel(&all_e, &all_c);
        assert!(
            r <= 1e-10,
            "{name}: engine vs candle gradients differ by {r:.2e}"
        );
        assert!(all_c.iter().any(|x| *x != 0.0), "{name}: zero gradient");
        // Finite differences of the engine's own loss, a few entries of every
        // parameter.
        let mut th = theta.clone();
        let scale = all_e.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for pname in net.store.names() {
            let off = eng.layout().offset(pname).unwrap();
            let len = ge[pname].data.len();
            for j in [0, len / 2, len - 1] {
                let hstep = 1e-6;
                th[off + j] = theta[off + j] + hstep;
                let up = eng.loss(&th, &samples, &idx);
                th[off + j] = theta[off + j] - hstep;
                let down = eng.loss(&th, &samples, &idx);
                th[off + j] = theta[off + j];
                let fd = (up - down) / (2.0 * hstep);
                let an = grad[off + j];
                // Truncation (h²) and round-off (ε·loss/h) of the central difference.
                assert!(
                    (fd - an).abs() <= 1e-6 * scale + 1e-8 * an.abs() + 1e-8 * loss_e,
                    "{name} {pname}[{j}]: finite difference {fd} vs engine {an}"
                );
            }
        }
        // The engine's accelerations are the kernel's.
        let model = trained(&case, &net);
        let mut ws = model.kernel.workspace(g).unwrap();
        let acc_e = eng.accelerations(&theta, &states[..3]);
        let mut a = vec![0.0; g.ndof()];
        for (s, st) in states[..3].iter().enumerate() {
            model.kernel.acceleration(&mut ws, &st.q, &st.v, &mut a);
            // The kernel holds kinematic particles (their acceleration is 0).
            let mut acc_e = acc_e[s].clone();
            for (f, x) in acc_e.iter_mut().enumerate() {
                if g.is_kinematic(f / g.dim) {
                    assert_eq!(a[f], 0.0, "{name}: a kinematic particle accelerates");
                    *x = 0.0;
                }
            }
            let r = rel(&acc_e, &a);
            assert!(r <= 1e-12, "{name}: engine vs kernel accelerations {r:.2e}");
        }
    }
}

fn spring_data() -> (Graph, Vec<State>, Vec<Vec<f64>>) {
    let c = SystemConfig::new(SystemKind::Spring, 5);
    let trajs = c.simulate(4, 1);
    let g = trajs[0].graph.clone();
    let (mut s, mut a) = (vec![], vec![]);
    for t in &trajs {
        for x in &t.samples {
            s.push(x.state.clone());
            a.push(
                x.acc
                    .clone()
                    .expect("simulated samples carry accelerations"),
            );
        }
    }
    (g, s, a)
}

#[test]
fn weights_are_bit_identical_for_one_and_two_threads() {
    let (g, s, a) = spring_data();
    for v in [Variant::Gnode, Variant::Mcgnode] {
        let run = |threads: usize| {
            let cfg = TrainConfig {
                epochs: 3,
                seed: 9,
                threads,
                ..TrainConfig::default()
            };
            let t = train(Hyper::new(v, 2, 1, 5), &g, &s, &a, &cfg, |_| true).unwrap();
            (t.net.store.weights().unwrap(), t.report.validation_loss)
        };
        let (w1, l1) = run(1);
        let (w2, l2) = run(2);
        assert_eq!(l1.to_bits(), l2.to_bits(), "{v}: validation loss");
        for (name, a1) in &w1 {
            let a2 = &w2[name];
            assert!(
                a1.data
                    .iter()
                    .zip(&a2.data)
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
                "{v}: parameter {name} differs between 1 and 2 threads"
            );
        }
    }
}

#[test]
fn both_engines_end_a_seeded_training_at_the_same_loss() {
    let (g, s, a) = spring_data();
    let c = SystemConfig::new(SystemKind::Pendulum, 3);
    let pt = c.simulate(3, 2);
    let pg = pt[0].graph.clone();
    let ps: Vec<State> = pt
        .iter()
        .flat_map(|t| t.samples.iter().map(|x| x.state.clone()))
        .collect();
    let pa: Vec<Vec<f64>> = pt
        .iter()
        .flat_map(|t| t.samples.iter().map(|x| x.acc.clone().unwrap()))
        .collect();
    for (v, g, s, a) in [
        (Variant::Mcgnode, &g, &s, &a),
        (Variant::Gnode, &g, &s, &a),
        (Variant::Cdgnode, &pg, &ps, &pa),
        (Variant::Node, &pg, &ps, &pa),
    ] {
        let run = |engine: EngineKind| {
            let cfg = TrainConfig {
                epochs: 30,
                seed: 4,
                engine,
                ..TrainConfig::default()
            };
            let h = Hyper::new(v, g.dim, 1, g.n());
            train(h, g, s, a, &cfg, |_| true).unwrap().report
        };
        let (n, c) = (run(EngineKind::Native), run(EngineKind::Candle));
        let r = (n.validation_loss - c.validation_loss).abs() / c.validation_loss;
        assert!(
            r <= 1e-6,
            "{v}: native {} vs candle {} (relative {r:.2e})",
            n.validation_loss,
            c.validation_loss
        );
        assert_eq!(n.best_epoch, c.best_epoch, "{v}");
    }
}

/// The contact cases above test what they claim: their states have contacts,
/// in numbers that vary from state to state, the ones a brute-force search
/// finds; both executors see every one; and kinematic particles' targets
/// change neither loss.
#[test]
fn contact_cases_have_varying_contacts_and_kinematic_targets_do_not_count() {
    for g in [
        touching(2, 7, 2, false),
        touching(3, 6, 3, false),
        touching(2, 4, 2, true),
    ] {
        let (states, mut targets) = data(&g, 40, 7);
        let plan = GraphPlan::new(&g);
        let mut search = plan.contact_search();
        let mut counts = vec![];
        for st in &states {
            let mut pairs = vec![];
            plan.contacts(&mut search, &st.q, &mut pairs);
            let brute = mcgnode::physics::brute_force_pairs(&g, &st.q, 1.5);
            assert_eq!(pairs, brute);
            counts.push(pairs.len());
        }
        let (lo, hi) = (counts.iter().min().unwrap(), counts.iter().max().unwrap());
        assert!(*lo < *hi && *hi > 0, "contacts per state {counts:?}");
        let sr: Vec<&State> = states.iter().collect();
        let batch = Batch::new(&plan, &sr, None, 2).unwrap();
        let total: usize = counts.iter().sum();
        assert_eq!(
            batch.n_directed,
            2 * (states.len() * plan.n_edges() + total)
        );
        let flags = batch.contact.sum_all().unwrap().to_scalar::<f64>().unwrap();
        assert_eq!(flags, (2 * total) as f64);
        // Kinematic targets: loss unchanged, in candle and in the engine.
        let mut h = Hyper::new(Variant::Mcgnode, g.dim, 2, 5);
        h.interaction_radius = 1.5;
        let net = Net::new(h.clone(), &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        let mut eng = Engine::new(&h, &g, 1).unwrap();
        let theta = eng.layout().flatten(&net.store.weights().unwrap()).unwrap();
        let idx: Vec<usize> = (0..states.len()).collect();
        let losses = |t: &[Vec<f64>], eng: &mut Engine| {
            let tr: Vec<&[f64]> = t.iter().map(Vec::as_slice).collect();
            let c = net.loss(&Batch::new(&plan, &sr, Some(&tr), 2).unwrap());
            let c = c.unwrap().to_scalar::<f64>().unwrap();
            let samples = eng.samples(&states, t);
            (c, eng.loss(&theta, &samples, &idx))
        };
        let before = losses(&targets, &mut eng);
        for t in &mut targets {
            for (f, x) in t.iter_mut().enumerate() {
                if g.is_kinematic(f / g.dim) {
                    *x += 100.0;
                }
            }
        }
        assert_eq!(losses(&targets, &mut eng), before);
    }
}

/// A model trained without contacts refuses a system with them, and one
/// trained with a radius refuses another radius, each naming `--radius`.
#[test]
fn a_model_serves_only_its_radius() {
    let g = touching(2, 5, 1, false);
    let mut h = Hyper::new(Variant::Mcgnode, 2, 2, 5);
    let e = Engine::new(&h, &g, 1)
        .err()
        .expect("no contacts in the model");
    assert!(e.to_string().contains("train --radius 1.5"), "{e}");
    h.interaction_radius = 2.0;
    let e = Engine::new(&h, &g, 1).err().expect("another radius");
    assert!(
        e.to_string().contains("trained with interaction radius 2"),
        "{e}"
    );
    h.interaction_radius = 1.5;
    assert!(Engine::new(&h, &g, 1).is_ok());
}

/// Planning gradients chain the engine's reverse pass down to a state:
/// ∂(ḡ·q̈)/∂q and ∂(ḡ·q̈)/∂q̇ equal candle's autodiff (through the edge
/// inputs, node inputs and the constraint's A(q), Ȧq̇) to 1e-10 and central
/// finite differences of the kernel's accelerations, for every case.
#[test]
fn state_gradients_equal_candle_and_finite_differences() {
    use mcgnode::dynamics::StateGradient;
    for (ci, case) in cases().into_iter().enumerate() {
        let (g, name) = (&case.graph, &case.name);
        let net = Net::new(
            case.hyper.clone(),
            &mut ChaCha8Rng::seed_from_u64(ci as u64),
        )
        .unwrap();
        let model = trained(&case, &net);
        let mut sg = model.kernel.gradient(g).unwrap();
        let (states, _) = data(g, 1, 500 + ci as u64);
        let st = &states[0];
        let nd = g.ndof();
        let mut rng = ChaCha8Rng::seed_from_u64(900 + ci as u64);
        let gacc: Vec<f64> = (0..nd)
            .map(|f| {
                if g.is_kinematic(f / g.dim) {
                    0.0
                } else {
                    rng.random_range(-1.0..1.0)
                }
            })
            .collect();
        let (mut acc, mut gq, mut gv) = (vec![0.0; nd], vec![0.0; nd], vec![0.0; nd]);
        sg.vjp(&st.q, &st.v, &gacc, &mut acc, &mut gq, &mut gv);
        let mut a0 = vec![0.0; nd];
        sg.acceleration(&st.q, &st.v, &mut a0);
        assert!(
            rel(&acc, &a0) <= 1e-12,
            "{name}: the reverse pass's q̈ differs"
        );
        // Candle, with q and q̇ as variables.
        let plan = GraphPlan::new(g);
        let mut batch = Batch::new(&plan, &[st], None, case.hyper.types).unwrap();
        let dev = candle_core::Device::Cpu;
        let qv = candle_core::Var::from_slice(&st.q, (g.n(), g.dim), &dev).unwrap();
        let vv = candle_core::Var::from_slice(&st.v, (g.n(), g.dim), &dev).unwrap();
        batch.q = qv.as_tensor().clone();
        batch.v = vv.as_tensor().clone();
        if !plan.bars.is_empty() {
            batch.constraint = Some(
                mcgnode::testing::candle_constraint(&plan, qv.as_tensor(), vv.as_tensor()).unwrap(),
            );
        }
        let out = net.forward(&batch).unwrap().acc;
        let w = candle_core::Tensor::from_slice(&gacc, (g.n(), g.dim), &dev).unwrap();
        let grads = (out * w).unwrap().sum_all().unwrap().backward().unwrap();
        let flat = |v: &candle_core::Var| {
            grads
                .get(v)
                .map(|t| t.flatten_all().unwrap().to_vec1::<f64>().unwrap())
                .unwrap_or_else(|| vec![0.0; nd])
        };
        let (cq, cv) = (flat(&qv), flat(&vv));
        assert!(cq.iter().any(|x| *x != 0.0), "{name}: zero ∂/∂q");
        let (rq, rv) = (rel(&gq, &cq), rel(&gv, &cv));
        assert!(
            rq <= 1e-10 && rv <= 1e-10,
            "{name}: engine vs candle ∂/∂q {rq:.2e}, ∂/∂q̇ {rv:.2e}"
        );
        // Central differences of L = ḡ·q̈ on the kernel.
        let mut l_at = |q: &[f64], v: &[f64]| {
            let mut a = vec![0.0; nd];
            sg.acceleration(q, v, &mut a);
            a.iter().zip(&gacc).map(|(x, y)| x * y).sum::<f64>()
        };
        let scale = gq.iter().chain(&gv).fold(0.0f64, |m, x| m.max(x.abs()));
        let h = 1e-6;
        for f in 0..nd {
            for (which, an) in [(0, gq[f]), (1, gv[f])] {
                let (mut qp, mut vp) = (st.q.clone(), st.v.clone());
                let (mut qm, mut vm) = (st.q.clone(), st.v.clone());
                if which == 0 {
                    qp[f] += h;
                    qm[f] -= h;
                } else {
                    vp[f] += h;
                    vm[f] -= h;
                }
                let fd = (l_at(&qp, &vp) - l_at(&qm, &vm)) / (2.0 * h);
                assert!(
                    (fd - an).abs() <= 1e-6 * scale + 1e-6 * an.abs(),
                    "{name}: ∂L/∂{}[{f}] finite difference {fd} vs engine {an}",
                    ["q", "q̇"][which]
                );
            }
        }
    }
}

/// Inference (the rollouts' and the node's pass: on graphs of 128 directed
/// edges or more, MCGNODE's edge stages fused block by block, on one core or
/// on two) gives the bits of the training engine's stage-by-stage pass (the
/// reverse pass's forward sweep), for the default 5-wide blocks and
/// `train`'s 16-wide edge blocks, without and with the body branch (its
/// blocks after the edges'), with springs and contacts, on a small
/// graph and on one of about 9,000 directed edges, state after state as
/// contacts come and go; and candle's accelerations to 1e-10.
#[test]
fn inference_gives_the_training_pass_bits() {
    use mcgnode::dynamics::StateGradient;
    // A jittered 40 × 30 grid with springs along its rows, contacts within
    // 1.5 (about eight neighbours each), kinematic bottom row.
    let (cols, rows) = (40, 30);
    let n = cols * rows;
    let springs = (0..n)
        .filter(|i| i % cols + 1 < cols && i % 3 == 0)
        .map(|i| edge(i, Endpoint::Particle(i + 1), EdgeKind::Spring, 1.0))
        .collect();
    let mut big = graph(2, n, springs, vec![]);
    big.interaction_radius = 1.5;
    big.kinematic = (0..n).map(|i| i < cols).collect();
    let grid = |rng: &mut ChaCha8Rng| State {
        q: (0..n)
            .flat_map(|i| [(i % cols) as f64, (i / cols) as f64])
            .map(|x| x + rng.random_range(-0.2..0.2))
            .collect(),
        v: (0..2 * n).map(|_| rng.random_range(-1.0..1.0)).collect(),
    };
    let small = touching(2, 7, 2, false);
    let wide = mcgnode::train::recipe::edge_blocks(Variant::Mcgnode);
    for (gname, g) in [("small", &small), ("grid", &big)] {
        for (blocks, body) in [(vec![], false), (wide.clone(), false), (wide.clone(), true)] {
            let (net, model) = mcgnode::testing::random_model_with(Variant::Mcgnode, g, 3, |h| {
                h.block_hidden
                    .extend(blocks.iter().map(|(b, w)| ((*b).to_string(), w.clone())));
                h.body_force = body;
            })
            .unwrap();
            let mut sg = model.kernel.gradient(g).unwrap();
            let mut one = model.kernel.workspace(g).unwrap();
            let mut two = model.kernel.workspace(g).unwrap();
            two.split_rows();
            let mut rng = ChaCha8Rng::seed_from_u64(11);
            let nd = g.ndof();
            for k in 0..6 {
                // The same workspaces state after state: one core, two cores.
                let ws = if k % 2 == 0 { &mut one } else { &mut two };
                let st = if gname == "grid" {
                    grid(&mut rng)
                } else {
                    data(g, 1, 40 + k).0.remove(0)
                };
                let (mut want, mut gq, mut gv) = (vec![0.0; nd], vec![0.0; nd], vec![0.0; nd]);
                sg.vjp(&st.q, &st.v, &vec![0.0; nd], &mut want, &mut gq, &mut gv);
                let mut got = vec![f64::NAN; nd];
                model.kernel.acceleration(ws, &st.q, &st.v, &mut got);
                assert!(want.iter().any(|x| *x != 0.0), "{gname}: q̈ is zero");
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert!(
                    bits(&got) == bits(&want),
                    "{gname}, {} edge blocks, body {body}, state {k}: inference differs from the training pass by {:.2e}",
                    if blocks.is_empty() { "default" } else { "train's" },
                    rel(&got, &want)
                );
                if k == 0 {
                    // And candle, the independent reference, on the free
                    // particles (kinematic ones are held by the kernel).
                    let plan = GraphPlan::new(g);
                    let types = model.kernel.hyper().types;
                    let batch = Batch::new(&plan, &[&st], None, types).unwrap();
                    let out = net.forward(&batch).unwrap().acc;
                    let c = out.flatten_all().unwrap().to_vec1::<f64>().unwrap();
                    let free = |v: &[f64]| -> Vec<f64> {
                        (0..nd)
                            .filter(|f| !g.is_kinematic(f / g.dim))
                            .map(|f| v[f])
                            .collect()
                    };
                    let r = rel(&free(&got), &free(&c));
                    assert!(r <= 1e-10, "{gname}, body {body}: kernel vs candle {r:.2e}");
                }
            }
        }
    }
}
