//! Periodic boxes: the minimum image, the contact search in a periodic box
//! against brute force, the simulator's conservation laws, the executor
//! against candle on edges that cross the box's faces, a learned model's
//! momentum, and bags that carry their box. Run with
//! `cargo test --release --test periodic`.

mod common;

use mcgnode::dynamics::{Dynamics, Timing};
use mcgnode::gnode::{Batch, GraphPlan, Variant};
use mcgnode::physics::{
    brute_force_pairs, contact_energy, hamiltonian, NeighborSearch, SystemConfig, SystemKind,
};
use mcgnode::system::{Graph, PeriodicBox, State};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use common::cli::{mcgnode, ok, read};

/// `n` unit-mass particles in a box of side `side`, periodic on the axes `periodic`.
fn boxed(dim: usize, n: usize, radius: f64, side: f64, periodic: Vec<bool>) -> Graph {
    Graph {
        dim,
        types: vec![0; n],
        masses: vec![1.0; n],
        edges: vec![],
        anchors: vec![],
        interaction_radius: radius,
        kinematic: vec![],
        periodic_box: Some(PeriodicBox {
            lower: vec![-1.0; dim],
            upper: vec![side - 1.0; dim],
            periodic,
        }),
    }
}

/// Whether some pair is closer than `r` only across the box's faces.
fn crosses(q: &[f64], dim: usize, pairs: &[(usize, usize)], r: f64) -> bool {
    pairs.iter().any(|&(i, j)| {
        let d2: f64 = (0..dim)
            .map(|k| (q[i * dim + k] - q[j * dim + k]).powi(2))
            .sum();
        d2 >= r * r
    })
}

#[test]
fn a_pair_across_the_face_touches_by_its_short_vector() {
    let g = boxed(2, 2, 0.3, 5.0, vec![true, true]);
    g.validate().unwrap();
    let q = [-0.95, 0.5, 3.95, 0.5];
    let mut s = NeighborSearch::new(&g);
    assert_eq!(s.search(&q, 2, 0.3), &[(0, 1)]);
    let open = Graph {
        periodic_box: None,
        ..g.clone()
    };
    assert!(NeighborSearch::new(&open).search(&q, 2, 0.3).is_empty());
    let mut d = [q[0] - q[2], q[1] - q[3]];
    g.periodic_box.as_ref().unwrap().min_image(&mut d);
    assert!((d[0] - 0.1).abs() < 1e-12 && d[1] == 0.0, "{d:?}");
}

#[test]
fn the_cell_list_equals_brute_force_in_periodic_boxes() {
    let mut rng = ChaCha8Rng::seed_from_u64(48);
    let mut crossing = 0;
    for dim in [2, 3] {
        let flags: Vec<Vec<bool>> = if dim == 2 {
            vec![vec![true, true], vec![true, false]]
        } else {
            vec![vec![true, true, true], vec![false, true, true]]
        };
        for periodic in flags {
            for (side, radius) in [(5.0, 0.3), (5.0, 1.0), (5.0, 2.4), (2.5, 1.2), (9.0, 0.6)] {
                let n = if dim == 2 { 300 } else { 200 };
                let g = boxed(dim, n, radius, side, periodic.clone());
                g.validate().unwrap();
                // Inside the box, and some outside it (not wrapped yet).
                let q: Vec<f64> = (0..n * dim)
                    .map(|i| {
                        let span = if i % 7 == 0 { 3.0 * side } else { side };
                        -1.0 - if i % 7 == 0 { side } else { 0.0 } + rng.random::<f64>() * span
                    })
                    .collect();
                let want = brute_force_pairs(&g, &q, radius);
                let mut s = NeighborSearch::new(&g);
                let got = s.search(&q, dim, radius).to_vec();
                assert_eq!(got, want, "{dim}D box {side} radius {radius} {periodic:?}");
                assert!(!want.is_empty());
                crossing += usize::from(crosses(&q, dim, &want, radius));
                // The Verlet list along a small move, and across a wrap.
                let mut moving = NeighborSearch::new(&g);
                moving.search_moving(&q, dim, radius);
                let mut q2 = q.clone();
                q2.iter_mut().for_each(|x| *x += 0.01 * radius);
                g.periodic_box.as_ref().unwrap().wrap(&mut q2);
                let want2 = brute_force_pairs(&g, &q2, radius);
                assert_eq!(moving.search_moving(&q2, dim, radius), &want2[..]);
            }
        }
    }
    assert!(crossing >= 15, "pairs across the faces in {crossing} cases");
}

#[test]
fn a_box_not_wider_than_two_radii_is_refused_with_its_fix() {
    let g = boxed(2, 3, 1.0, 2.0, vec![true, true]);
    let e = g.validate().unwrap_err().to_string();
    assert!(e.contains("enlarge the box or lower the radius"), "{e}");
    let mut bad = boxed(3, 3, 0.1, 2.0, vec![true, true]);
    bad.periodic_box.as_mut().unwrap().periodic.push(true);
    assert!(bad.validate().is_ok());
    bad.periodic_box.as_mut().unwrap().periodic.pop();
    let e = bad.validate().unwrap_err().to_string();
    assert!(e.contains("one per axis"), "{e}");
}

/// The periodic spheres' configuration in `dim` dimensions.
fn spheres(dim: usize, n: usize) -> SystemConfig {
    let mut cfg = SystemConfig::new(SystemKind::PeriodicSpheres, n);
    cfg.dim = dim;
    cfg
}

#[test]
fn periodic_spheres_conserve_momentum_and_energy_and_stay_in_their_box() {
    for (dim, n) in [(2, 16), (3, 27)] {
        let cfg = spheres(dim, n);
        let tr = cfg.simulate(1, 3).remove(0);
        let g = &tr.graph;
        let b = g.periodic().expect("a periodic box").clone();
        let energy = |s: &State| {
            hamiltonian(g, &cfg.field, s) + contact_energy(g, cfg.contact_stiffness, &s.q)
        };
        let s0 = &tr.samples[0].state;
        let (e0, scale) = (energy(s0), mcgnode::physics::kinetic_energy(g, s0));
        let pscale: f64 = (0..n)
            .map(|i| {
                (0..dim)
                    .map(|c| s0.v[i * dim + c].powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .sum();
        let (mut de, mut dp, mut peak, mut wrapped) = (0.0_f64, 0.0_f64, 0.0_f64, false);
        for w in tr.samples.windows(2) {
            let s = &w[1].state;
            de = de.max((energy(s) - e0).abs() / scale);
            let p = s.momentum(g);
            dp = dp.max(p.iter().map(|x| x.abs()).fold(0.0, f64::max) / pscale);
            peak = peak.max(contact_energy(g, cfg.contact_stiffness, &s.q));
            for (k, x) in s.q.iter().enumerate() {
                let c = k % dim;
                assert!(*x >= b.lower[c] && *x < b.upper[c], "{x} outside the box");
                wrapped |= (x - w[0].state.q[k]).abs() > 0.5 * b.length(c);
            }
        }
        println!("{dim}D periodic spheres: energy {de:.2e}, momentum {dp:.1e}, peak contact energy {peak:.3}");
        assert!(wrapped, "no particle crossed a face");
        assert!(peak > 1e-3, "no collision");
        assert!(dp <= 1e-12, "momentum changed by {dp}");
        assert!(de < 1e-3, "energy error {de}");
    }
}

#[test]
fn the_executor_equals_candle_on_edges_across_the_faces() {
    let cfg = spheres(2, 16);
    let tr = cfg.simulate(1, 5).remove(0);
    let g = &tr.graph;
    let states: Vec<State> = tr
        .samples
        .iter()
        .step_by(5)
        .map(|s| s.state.clone())
        .collect();
    let plan = GraphPlan::new(g);
    let across = states
        .iter()
        .filter(|s| {
            crosses(
                &s.q,
                2,
                &brute_force_pairs(g, &s.q, g.interaction_radius),
                g.interaction_radius,
            )
        })
        .count();
    assert!(
        across >= 3,
        "only {across} states have contacts across the faces"
    );
    let sr: Vec<&State> = states.iter().collect();
    let batch = Batch::new(&plan, &sr, None, 1).unwrap();
    let open = Graph {
        periodic_box: None,
        ..g.clone()
    };
    for v in [Variant::Mcgnode, Variant::Gnode, Variant::Cdgnode] {
        let (net, m) = mcgnode::testing::random_model(v, g, 11).unwrap();
        let acc_c = net
            .forward(&batch)
            .unwrap()
            .acc
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        let mut ws = m.kernel.workspace(g).unwrap();
        let mut ws_open = m.kernel.workspace(&open).unwrap();
        let (nd, mut a, mut b) = (g.ndof(), vec![0.0; g.ndof()], vec![0.0; g.ndof()]);
        let mut differs = false;
        for (s, st) in states.iter().enumerate() {
            m.kernel.acceleration(&mut ws, &st.q, &st.v, &mut a);
            for i in 0..nd {
                let (x, y) = (a[i], acc_c[s * nd + i]);
                assert!(
                    (x - y).abs() <= 1e-10 * (1.0 + y.abs()),
                    "{v} state {s}: executor {x} vs candle {y}"
                );
            }
            m.kernel.acceleration(&mut ws_open, &st.q, &st.v, &mut b);
            differs |= a.iter().zip(&b).any(|(x, y)| (x - y).abs() > 1e-6);
        }
        assert!(differs, "{v}: the box changed nothing");
    }
}

#[test]
fn a_random_mcgnode_keeps_momentum_over_a_periodic_rollout() {
    let cfg = spheres(2, 16);
    let tr = cfg.simulate(1, 9).remove(0);
    let g = &tr.graph;
    let (_, m) = mcgnode::testing::random_model(Variant::Mcgnode, g, 5).unwrap();
    let start = &tr.samples[0].state;
    let states = m.rollout(g, start, Timing::new(1e-3, 1, 2000)).unwrap();
    let p0 = start.momentum(g);
    let b = g.periodic().unwrap();
    let scale: f64 = start.v.iter().map(|x| x.abs()).sum::<f64>().max(1.0);
    let mut me = 0.0_f64;
    for s in &states {
        let p = s.momentum(g);
        me = me.max(
            p.iter()
                .zip(&p0)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
                / scale,
        );
        for (k, x) in s.q.iter().enumerate() {
            assert!(
                *x >= b.lower[k % 2] && *x < b.upper[k % 2],
                "{x} outside the box"
            );
        }
    }
    println!(
        "MCGNODE periodic rollout: {} states, ME {me:.1e}",
        states.len()
    );
    assert!(states.len() > 100);
    assert!(me <= 1e-12, "momentum error {me}");
}

#[test]
fn models_without_periodic_support_refuse_the_box() {
    let cfg = spheres(2, 9);
    let g = cfg.graph();
    let (_, m) = mcgnode::testing::random_model(Variant::Node, &g, 1).unwrap();
    let e = m.kernel.workspace(&g).unwrap_err().to_string();
    assert!(e.contains("periodic box"), "{e}");
}

#[test]
fn a_periodic_bag_says_so_and_an_old_bag_reads_without_a_box() {
    let d = tempfile::tempdir().unwrap();
    let bag = d.path().join("periodic.mcap");
    let bag_s = bag.to_str().unwrap();
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "periodic-spheres",
            "--particles",
            "9",
            "--trajectories",
            "2",
            "--out",
            bag_s,
        ],
        d.path(),
    ));
    let info = ok(&mcgnode(&["bag", "info", bag_s], d.path()));
    assert!(
        info.contains("periodic box [0, ") && info.contains("(periodic x, y)"),
        "{info}"
    );
    let read_back = read(&bag);
    let cfg = spheres(2, 9);
    for t in &read_back.trajectories {
        assert_eq!(t.graph.periodic_box, cfg.graph().periodic_box);
    }
    for model in ["gns", "lgn", "node"] {
        let o = mcgnode(
            &[
                "train", "--model", model, "--data", bag_s, "--epochs", "1", "--out", "m.json",
            ],
            d.path(),
        );
        let err = String::from_utf8_lossy(&o.stderr);
        let said =
            err.contains("no periodic boundaries") || err.contains("which a periodic box wraps");
        assert!(!o.status.success() && said, "{model}: {err}");
    }
    let old = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("bags/spring5-sample.mcap");
    let info = ok(&mcgnode(&["bag", "info", old.to_str().unwrap()], d.path()));
    assert!(info.contains("not periodic"), "{info}");
    assert!(read(&old)
        .trajectories
        .iter()
        .all(|t| t.graph.periodic_box.is_none()));
}

/// A bag in the layout before the box (contacts and kinematic walls, no box
/// fields) reads as it was written, without a box.
#[test]
fn bags_of_the_layout_before_the_box_read_as_not_periodic() {
    use mcgnode::data::msg::{
        encode_cdr, ros2msg_schema, ParticleStateV3, DEP_HEADER, DEP_POINT, DEP_TIME, DEP_VECTOR3,
        PARTICLE_STATE_MSG_V3, PARTICLE_STATE_TYPE,
    };
    use mcgnode::data::{write_trajectories, BagWriter, ParticleState};
    let d = tempfile::tempdir().unwrap();
    let trajs = SystemConfig::new(SystemKind::SoftSpheres, 6).simulate(1, 2);
    let p = d.path().join("v3.mcap");
    let mut w = BagWriter::create(&p).unwrap();
    let schema = ros2msg_schema(
        PARTICLE_STATE_MSG_V3,
        &[DEP_HEADER, DEP_TIME, DEP_VECTOR3, DEP_POINT],
    );
    let ch = w
        .add_channel("/particle_state", PARTICLE_STATE_TYPE, &schema)
        .unwrap();
    for tr in &trajs {
        for (k, s) in tr.samples.iter().enumerate() {
            let m = ParticleState::from_sample(tr.id, k as u32, &tr.system, &tr.graph, s);
            let full = m.to_cdr().unwrap();
            let v3 = ParticleStateV3 {
                header: m.header.clone(),
                trajectory_id: m.trajectory_id,
                step: m.step,
                system: m.system.clone(),
                dimension: m.dimension,
                types: m.types.clone(),
                masses: m.masses.clone(),
                positions: m.positions.clone(),
                velocities: m.velocities.clone(),
                accelerations: m.accelerations.clone(),
                edge_a: m.edge_a.clone(),
                edge_b: m.edge_b.clone(),
                edge_kind: m.edge_kind.clone(),
                edge_rest_length: m.edge_rest_length.clone(),
                edge_stiffness: m.edge_stiffness.clone(),
                anchors: m.anchors.clone(),
                field_status: m.field_status,
                gravity: m.gravity,
                drag: m.drag,
                force: m.force,
                interaction_radius: m.interaction_radius,
                kinematic: m.kinematic.clone(),
            };
            let bytes = encode_cdr(&v3).unwrap();
            // Shorter than the current layout: really the older wire format.
            assert!(bytes.len() + 12 <= full.len());
            w.write(ch, m.header.stamp.as_nanos() as u64, &bytes)
                .unwrap();
        }
    }
    w.finish().unwrap();
    let new = d.path().join("new.mcap");
    write_trajectories(&new, &trajs, &Default::default()).unwrap();
    let (got, want) = (read(&p), read(&new));
    assert_eq!(got.trajectories, want.trajectories);
    assert!(got
        .trajectories
        .iter()
        .all(|t| t.graph.periodic_box.is_none()
            && t.graph.has_contacts()
            && t.graph.n_kinematic() > 0));
}

#[test]
fn errors_in_a_periodic_box_are_minimum_images() {
    // Side 4 (x in [-1, 3)): the truth at x = 2.9, the prediction wrapped
    // to -0.9, 0.2 away across the face, not 3.8.
    let g = boxed(2, 1, 0.5, 4.0, vec![true, true]);
    let st = |x: f64| State {
        q: vec![x, 0.5],
        v: vec![0.0, 0.0],
    };
    let (truth, pred) = (vec![st(2.9), st(2.9)], vec![st(2.9), st(-0.9)]);
    let field = mcgnode::physics::Field::default();
    let c = mcgnode::metrics::error_curves(&g, &field, &truth, &pred, &[0.0, 1.0]).unwrap();
    assert!((c.re_abs[1] - 0.2).abs() < 1e-12, "{}", c.re_abs[1]);
    let open = Graph {
        periodic_box: None,
        ..g.clone()
    };
    let c = mcgnode::metrics::error_curves(&open, &field, &truth, &pred, &[0.0, 1.0]).unwrap();
    assert!(
        (c.re_abs[1] - 3.8).abs() < 1e-12,
        "an open box: {}",
        c.re_abs[1]
    );
    // LagrangeBench's MSE likewise, over 5 frames: (0.2² + 0) / 2 each.
    use mcgnode::lagrange_metrics::{trajectory_metrics_sampled, Frames};
    let truth6 = vec![st(2.9); 6];
    let mut pred6 = vec![st(-0.9); 6];
    pred6[0] = st(2.9);
    fn frames(s: &[State]) -> Frames<'_> {
        Frames {
            q: s.iter().map(|s| s.q.as_slice()).collect(),
        }
    }
    let mse5 = |pb: Option<&PeriodicBox>| {
        trajectory_metrics_sampled(&frames(&truth6), &frames(&pred6), 2, 1.0, 1.0, None, pb)
            .unwrap()
            .mse5
            .expect("5 frames")
    };
    assert!((mse5(g.periodic_box.as_ref()) - 0.02).abs() < 1e-12);
    assert!((mse5(None) - 3.8 * 3.8 / 2.0).abs() < 1e-12, "an open box");
}
