//! Ground-truth physics: conservation laws, constraint accuracy, the saved
//! accelerations, seeds and input errors. Run with
//! `cargo test --release --test physics`.

use mcgnode::physics::{
    acceleration, bar_jacobian, constraint_residual, hamiltonian, kinetic_energy, Field,
    Integrator, SystemConfig, SystemKind,
};
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph, State};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn norm(x: &[f64]) -> f64 {
    x.iter().map(|a| a * a).sum::<f64>().sqrt()
}

/// Σ m|v|: the momentum scale the conservation errors are relative to.
fn momentum_scale(g: &Graph, s: &State) -> f64 {
    let d = g.dim;
    (0..g.n())
        .map(|i| g.masses[i] * norm(&s.v[i * d..(i + 1) * d]))
        .sum()
}

/// Energy scale for relative drift: kinetic plus the absolute size of each
/// potential term, so a Hamiltonian that happens to be near 0 does not make
/// the relative error meaningless.
fn energy_scale(g: &Graph, f: &Field, s: &State) -> f64 {
    let d = g.dim;
    let grav: f64 = (0..g.n())
        .map(|i| (g.masses[i] * f.gravity * s.q[i * d + 1]).abs())
        .sum();
    hamiltonian(g, f, s).abs().max(kinetic_energy(g, s) + grav)
}

#[test]
fn five_pendulum_ten_seconds_paper_protocol() {
    let cfg = SystemConfig::new(SystemKind::Pendulum, 5);
    assert_eq!(cfg.dt, 1e-5);
    let g = cfg.graph();
    let start = cfg.start_for(&g, 11, 0);
    let h0 = hamiltonian(&g, &cfg.field, &start);
    let scale = energy_scale(&g, &cfg.field, &start);
    let mut it = Integrator::new(&g, &cfg.field, cfg.dt, start).unwrap();
    let (mut worst_res, mut worst_drift) = (0.0_f64, 0.0_f64);
    for _ in 0..1000 {
        it.advance(1000);
        worst_res = worst_res.max(constraint_residual(&g, it.state()));
        worst_drift = worst_drift.max((hamiltonian(&g, &cfg.field, it.state()) - h0).abs() / scale);
    }
    assert!((it.time() - 10.0).abs() < 1e-9);
    println!("5-pendulum 10 s: max bar residual {worst_res:.3e}, max relative energy drift {worst_drift:.3e} (H0 = {h0:.4}, scale {scale:.4})");
    assert_eq!(it.shake_failures(), 0);
    assert!(worst_res < 1e-9, "bar residual {worst_res}");
    assert!(worst_drift < 1e-6, "energy drift {worst_drift}");
    // The velocities must stay tangent to the bars as well.
    let (a, _) = bar_jacobian(&g, it.state());
    let av = &a * nalgebra::DVector::from_column_slice(&it.state().v);
    assert!(av.amax() < 1e-10, "A q̇ = {}", av.amax());
}

#[test]
fn spring_ring_conserves_momentum_and_energy() {
    let cfg = SystemConfig::new(SystemKind::Spring, 5);
    let g = cfg.graph();
    let start = cfg.start_for(&g, 3, 4);
    let p0 = start.momentum(&g);
    let pscale = momentum_scale(&g, &start);
    let h0 = hamiltonian(&g, &cfg.field, &start);
    let mut it = Integrator::new(&g, &cfg.field, cfg.dt, start).unwrap();
    let (mut dp, mut de) = (0.0_f64, 0.0_f64);
    // 20 s, the paper's spring test horizon.
    for _ in 0..200 {
        it.advance(100);
        let p = it.state().momentum(&g);
        dp = dp.max(norm(&[p[0] - p0[0], p[1] - p0[1]]) / pscale);
        de = de.max((hamiltonian(&g, &cfg.field, it.state()) - h0).abs() / h0.abs());
    }
    println!("5-spring 20 s at dt 1e-3: momentum error {dp:.3e} (relative to Σm|v|), relative energy error {de:.3e}");
    assert!(dp < 1e-13, "momentum error {dp}");
    // Velocity Verlet's energy error is O(dt²) and bounded; measured 3.5e-7
    // for this start, asserted with a wide margin.
    assert!(de < 1e-5, "energy error {de}");
    assert!(de > 0.0, "an energy error of exactly 0 means nothing moved");
}

#[test]
fn drag_dissipates_energy_monotonically() {
    for kind in [SystemKind::Spring, SystemKind::Pendulum] {
        let mut cfg = SystemConfig::new(kind, 4);
        cfg.field.drag = 0.1;
        let g = cfg.graph();
        let start = cfg.start_for(&g, 5, 0);
        let mut h = hamiltonian(&g, &cfg.field, &start);
        let h_start = h;
        let dt = 1e-3;
        let mut it = Integrator::new(&g, &cfg.field, dt, start).unwrap();
        for _ in 0..300 {
            it.advance(10);
            let h1 = hamiltonian(&g, &cfg.field, it.state());
            assert!(
                h1 < h,
                "{kind}: energy rose from {h} to {h1} at t = {}",
                it.time()
            );
            h = h1;
        }
        assert!(h < h_start - 1e-3, "{kind}: drag removed almost no energy");
    }
}

#[test]
fn constant_force_changes_momentum_by_n_f_t() {
    let mut cfg = SystemConfig::new(SystemKind::Spring, 5);
    cfg.field.force = vec![0.3, -0.2];
    cfg.field.gravity = 0.5;
    let g = cfg.graph();
    let start = cfg.start_for(&g, 9, 1);
    let p0 = start.momentum(&g);
    let mut it = Integrator::new(&g, &cfg.field, cfg.dt, start).unwrap();
    it.advance(3000);
    let t = it.time();
    let p = it.state().momentum(&g);
    let n = g.n() as f64;
    let want = [p0[0] + n * 0.3 * t, p0[1] + n * (-0.2 - 0.5 * cfg.mass) * t];
    for c in 0..2 {
        assert!(
            (p[c] - want[c]).abs() < 1e-10 * want[c].abs().max(1.0),
            "component {c}: {} vs {}",
            p[c],
            want[c]
        );
    }
    // The constant force is in the Hamiltonian as −F·q, so energy is conserved.
    let h0 = hamiltonian(&g, &cfg.field, &cfg.start_for(&g, 9, 1));
    let h1 = hamiltonian(&g, &cfg.field, it.state());
    assert!((h1 - h0).abs() < 1e-4 * h0.abs().max(1.0), "{h0} vs {h1}");
}

/// Max over interior samples of |central difference of q − saved acc|.
fn fd_error(cfg: &SystemConfig, seed: u64) -> f64 {
    let g = cfg.graph();
    let traj = cfg.simulate_one(&g, cfg.start_for(&g, seed, 0), 0);
    let h = cfg.save_every as f64 * cfg.dt;
    let s = &traj.samples;
    let mut worst = 0.0_f64;
    for k in 1..s.len() - 1 {
        let acc = s[k].acc.as_ref().unwrap();
        for (i, a) in acc.iter().enumerate() {
            let fd = (s[k + 1].state.q[i] - 2.0 * s[k].state.q[i] + s[k - 1].state.q[i]) / (h * h);
            worst = worst.max((fd - a).abs());
        }
    }
    worst
}

#[test]
fn saved_accelerations_match_finite_differences() {
    for (kind, dt, every) in [
        (SystemKind::Spring, 1e-3, 20),
        (SystemKind::Pendulum, 1e-5, 400),
    ] {
        let mut cfg = SystemConfig::new(kind, 4);
        cfg.dt = dt;
        cfg.save_every = every;
        cfg.states = 30;
        let e1 = fd_error(&cfg, 21);
        cfg.save_every = every / 2;
        cfg.states = 59;
        let e2 = fd_error(&cfg, 21);
        let h = every as f64 * dt;
        println!(
            "{kind}: FD error {e1:.3e} at h = {h}, {e2:.3e} at h/2 (ratio {:.2})",
            e1 / e2
        );
        // O(h²): small in absolute terms and about 4× smaller at half the step.
        assert!(e1 < 0.5 * h * h * 1e3, "{kind}: FD error {e1}");
        assert!(e1 / e2 > 3.0 && e1 / e2 < 5.0, "{kind}: ratio {}", e1 / e2);
    }
}

fn random_state(g: &Graph, rng: &mut impl Rng) -> State {
    let d = g.ndof();
    State {
        q: (0..d).map(|_| rng.random_range(-2.0..2.0)).collect(),
        v: (0..d).map(|_| rng.random_range(-2.0..2.0)).collect(),
    }
}

fn bar(a: usize, b: Endpoint, l: f64) -> Edge {
    Edge {
        a,
        b,
        kind: EdgeKind::Bar,
        rest_length: l,
        stiffness: 0.0,
    }
}

/// A bar graph that is not a chain: a barred triangle hung from one anchor,
/// one corner also sprung to a second anchor, plus a free particle on a spring.
fn triangle_graph() -> Graph {
    Graph {
        dim: 2,
        types: vec![0; 4],
        masses: vec![1.0, 2.0, 0.5, 1.5],
        edges: vec![
            bar(0, Endpoint::Anchor(0), 1.0),
            bar(0, Endpoint::Particle(1), 1.2),
            bar(1, Endpoint::Particle(2), 0.8),
            bar(2, Endpoint::Particle(0), 1.1),
            Edge {
                a: 2,
                b: Endpoint::Anchor(1),
                kind: EdgeKind::Spring,
                rest_length: 0.5,
                stiffness: 3.0,
            },
            Edge {
                a: 3,
                b: Endpoint::Particle(1),
                kind: EdgeKind::Spring,
                rest_length: 1.0,
                stiffness: 2.0,
            },
        ],
        anchors: vec![vec![0.0, 0.0], vec![1.5, -0.5]],
        interaction_radius: 0.0,
        kinematic: vec![],
        periodic_box: None,
    }
}

#[test]
fn constrained_acceleration_satisfies_differentiated_constraints() {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let field = Field {
        gravity: 9.8,
        drag: 0.3,
        force: vec![0.1, 0.2],
    };
    let mut p3 = SystemConfig::new(SystemKind::Pendulum, 5);
    p3.dim = 3;
    let graphs = [
        SystemConfig::new(SystemKind::Pendulum, 5).graph(),
        p3.graph(),
        triangle_graph(),
    ];
    for g in &graphs {
        for _ in 0..20 {
            let s = random_state(g, &mut rng);
            let f = Field {
                force: field
                    .force
                    .iter()
                    .copied()
                    .chain([0.0])
                    .take(g.dim)
                    .collect(),
                ..field.clone()
            };
            let acc = acceleration(g, &f, &s);
            let (a, adot) = bar_jacobian(g, &s);
            let r = &a * nalgebra::DVector::from_column_slice(&acc) + &adot;
            let scale = adot.amax().max(1.0);
            assert!(
                r.amax() < 1e-10 * scale,
                "A q̈ + Ȧ q̇ = {} (dim {})",
                r.amax(),
                g.dim
            );
        }
    }
}

#[test]
fn non_chain_bar_graph_integrates_accurately() {
    // Start from a state that satisfies the bars: a triangle below the anchor.
    let g = triangle_graph();
    let (l01, l12, l20) = (1.2_f64, 0.8_f64, 1.1_f64);
    let p0 = [0.0, -1.0];
    let p1 = [p0[0] + l01, p0[1]];
    // Corner 2 from the law of cosines at corner 0.
    let cos0 = (l01 * l01 + l20 * l20 - l12 * l12) / (2.0 * l01 * l20);
    let p2 = [p0[0] + l20 * cos0, p0[1] - l20 * (1.0 - cos0 * cos0).sqrt()];
    let start = State {
        q: vec![p0[0], p0[1], p1[0], p1[1], p2[0], p2[1], 2.0, 0.0],
        v: vec![0.0; 8],
    };
    assert!(constraint_residual(&g, &start) < 1e-12);
    let field = Field {
        gravity: 10.0,
        drag: 0.0,
        force: vec![],
    };
    let h0 = hamiltonian(&g, &field, &start);
    let mut it = Integrator::new(&g, &field, 1e-4, start).unwrap();
    let mut worst = 0.0_f64;
    for _ in 0..100 {
        it.advance(100);
        worst = worst.max((hamiltonian(&g, &field, it.state()) - h0).abs());
        assert!(constraint_residual(&g, it.state()) < 1e-9);
    }
    assert_eq!(it.shake_failures(), 0);
    assert!(worst < 1e-5 * h0.abs().max(1.0), "energy error {worst}");
    assert!(
        kinetic_energy(&g, it.state()) > 1e-3,
        "the system should have started moving"
    );
}

#[test]
fn seeds_one_and_two_share_no_initial_state() {
    for kind in [SystemKind::Spring, SystemKind::Pendulum] {
        let cfg = SystemConfig::new(kind, 5);
        let g = cfg.graph();
        let a: Vec<State> = (0..100).map(|i| cfg.start_for(&g, 1, i)).collect();
        let b: Vec<State> = (0..100).map(|i| cfg.start_for(&g, 2, i)).collect();
        let mut closest = f64::INFINITY;
        for x in &a {
            for y in &b {
                let dq: Vec<f64> = x.q.iter().zip(&y.q).map(|(p, q)| p - q).collect();
                let dv: Vec<f64> = x.v.iter().zip(&y.v).map(|(p, q)| p - q).collect();
                closest = closest.min(norm(&dq) + norm(&dv));
            }
        }
        println!("{kind}: closest train/test start distance {closest:.3}");
        assert!(
            closest > 1e-3,
            "{kind}: train and test starts {closest} apart"
        );
        // Within one set, starts differ too.
        assert_ne!(a[0], a[1]);
    }
    let s1: std::collections::HashSet<u64> = (0..1000)
        .map(|i| SystemConfig::trajectory_seed(1, i))
        .collect();
    assert_eq!(s1.len(), 1000);
    assert!((0..1000).all(|i| !s1.contains(&SystemConfig::trajectory_seed(2, i))));
}

#[test]
fn system_kind_parses_and_explains_errors() {
    assert_eq!("spring".parse::<SystemKind>().unwrap(), SystemKind::Spring);
    assert_eq!(
        "Pendulum".parse::<SystemKind>().unwrap(),
        SystemKind::Pendulum
    );
    assert_eq!(SystemKind::Pendulum.to_string(), "pendulum");
    let err = "rope".parse::<SystemKind>().unwrap_err().to_string();
    assert!(
        err.contains("rope") && err.contains("spring") && err.contains("pendulum"),
        "{err}"
    );
}

#[test]
fn three_dimensional_systems_work() {
    let mut cfg = SystemConfig::new(SystemKind::Spring, 4);
    cfg.dim = 3;
    let g = cfg.graph();
    let start = cfg.start_for(&g, 1, 0);
    assert_eq!(start.q.len(), 12);
    assert!(
        start.q.iter().skip(2).step_by(3).any(|z| z.abs() > 1e-3),
        "3D start is flat"
    );
    let pscale = momentum_scale(&g, &start);
    let p0 = start.momentum(&g);
    let h0 = hamiltonian(&g, &cfg.field, &start);
    let mut it = Integrator::new(&g, &cfg.field, cfg.dt, start).unwrap();
    it.advance(5000);
    let p = it.state().momentum(&g);
    let dp = norm(&(0..3).map(|c| p[c] - p0[c]).collect::<Vec<_>>()) / pscale;
    assert!(dp < 1e-13, "3D momentum error {dp}");
    assert!((hamiltonian(&g, &cfg.field, it.state()) - h0).abs() < 1e-4 * h0);

    let mut pc = SystemConfig::new(SystemKind::Pendulum, 3);
    pc.dim = 3;
    pc.states = 5;
    let traj = pc.simulate_one(&pc.graph(), pc.start_for(&pc.graph(), 1, 0), 0);
    let h0 = hamiltonian(&traj.graph, &pc.field, &traj.samples[0].state);
    for s in &traj.samples {
        assert!(constraint_residual(&traj.graph, &s.state) < 1e-9);
        assert!(
            (hamiltonian(&traj.graph, &pc.field, &s.state) - h0).abs() < 1e-6 * h0.abs().max(1.0)
        );
    }
}

#[test]
fn simulate_produces_the_documented_trajectories() {
    let mut cfg = SystemConfig::new(SystemKind::Pendulum, 3);
    cfg.states = 10;
    let trajs = cfg.simulate(3, 7);
    assert_eq!(trajs.len(), 3);
    for (i, t) in trajs.iter().enumerate() {
        assert_eq!(t.id, i as u32);
        assert_eq!(t.system, "pendulum");
        assert_eq!(t.samples.len(), 10);
        assert_eq!(t.samples[0].state, cfg.start_for(&t.graph, 7, i));
        for (k, s) in t.samples.iter().enumerate() {
            assert!((s.t - k as f64 * 1000.0 * 1e-5).abs() < 1e-12);
            assert_eq!(
                s.acc.as_ref().unwrap(),
                &acceleration(&t.graph, &cfg.field, &s.state)
            );
            assert!(constraint_residual(&t.graph, &s.state) < 1e-9);
        }
    }
    assert_eq!(trajs, cfg.simulate(3, 7), "simulation is not deterministic");
    assert_ne!(trajs[0].samples[0], cfg.simulate(1, 8)[0].samples[0]);

    let spring = SystemConfig::new(SystemKind::Spring, 5);
    let g = spring.graph();
    assert_eq!(g.edges.len(), 5);
    let s = spring.start_for(&g, 1, 0);
    assert!(
        norm(&s.momentum(&g)) < 1e-12,
        "spring start has net momentum"
    );
    // Sides of the perturbed polygon are near r0.
    for e in &g.edges {
        let Endpoint::Particle(b) = e.b else {
            panic!("ring edge to an anchor")
        };
        let r = norm(&[s.q[2 * e.a] - s.q[2 * b], s.q[2 * e.a + 1] - s.q[2 * b + 1]]);
        assert!((r - 1.0).abs() < 0.6, "side {r}");
    }
    assert_eq!(
        SystemConfig::new(SystemKind::Spring, 2).graph().edges.len(),
        1
    );
}

#[test]
fn bad_input_is_an_error() {
    let mut c = SystemConfig::new(SystemKind::Spring, 1);
    assert!(c.validate().unwrap_err().to_string().contains("at least 2"));
    assert!(c.try_simulate(1, 0).is_err());
    c.particles = 3;
    c.dt = 0.0;
    assert!(c.validate().unwrap_err().to_string().contains("dt"));
    c.dt = 1e-3;
    c.field.force = vec![1.0, 2.0, 3.0];
    assert!(c.validate().unwrap_err().to_string().contains("force"));
    c.field.force = vec![];
    c.field.drag = f64::NAN;
    assert!(c.validate().is_err());
    c.field.drag = 0.0;
    c.validate().unwrap();
    let g = c.graph();
    let start = c.start_for(&g, 0, 0);
    assert!(Integrator::new(&g, &c.field, -1.0, start.clone()).is_err());
    let short = State {
        q: vec![0.0; 2],
        v: vec![0.0; 2],
    };
    assert!(Integrator::new(&g, &c.field, 1e-3, short).is_err());
}

#[test]
fn hamiltonian_of_hand_computed_cases() {
    // One spring stretched by 0.5, particles moving: H = ½k·0.25 + KE.
    let cfg = SystemConfig::new(SystemKind::Spring, 2);
    let mut g = cfg.graph();
    g.edges[0].stiffness = 4.0;
    let s = State {
        q: vec![0.0, 0.0, 1.5, 0.0],
        v: vec![1.0, 0.0, 0.0, 2.0],
    };
    let want = 0.5 * 4.0 * 0.25 + 0.5 * 1.0 + 0.5 * 4.0;
    assert!((hamiltonian(&g, &cfg.field, &s) - want).abs() < 1e-15);
    // Pendulum bob at y = −1, at rest, g = 10, m = 1, force (1, 0): H = −10 − 0.6.
    let p = SystemConfig::new(SystemKind::Pendulum, 1);
    let f = Field {
        force: vec![1.0, 0.0],
        ..p.field.clone()
    };
    let s = State {
        q: vec![0.6, -0.8],
        v: vec![0.0, 0.0],
    };
    assert!((hamiltonian(&p.graph(), &f, &s) - (-8.0 - 0.6)).abs() < 1e-14);
    // Its exact acceleration at rest is gravity's tangential part.
    let a = acceleration(&p.graph(), &p.field, &s);
    // Tangent to the circle at angle θ from −y with sin θ = 0.6: a = −g sin θ · (cos θ, sin θ).
    let want = [-10.0 * 0.6 * 0.8, -10.0 * 0.6 * 0.6];
    assert!(
        (a[0] - want[0]).abs() < 1e-13 && (a[1] - want[1]).abs() < 1e-13,
        "{a:?}"
    );
}

#[test]
fn truth_implements_dynamics() {
    use mcgnode::dynamics::Dynamics;
    use mcgnode::models::Truth;
    let cfg = SystemConfig::new(SystemKind::Spring, 5);
    let g = cfg.graph();
    let s = cfg.start_for(&g, 4, 2);
    let truth = Truth {
        field: cfg.field.clone(),
    };
    let f = truth.forces(&g, &s).unwrap();
    assert_eq!(f.edges.len(), 5);
    // Internal forces only: each particle's total is the sum of its edge
    // forces (f_ba = −f_ab), and the totals cancel.
    let mut sum = vec![0.0; g.ndof()];
    for e in &f.edges {
        for c in 0..2 {
            sum[e.a * 2 + c] += e.force[c];
            sum[e.b * 2 + c] -= e.force[c];
        }
    }
    for (a, b) in sum.iter().zip(&f.total) {
        assert!((a - b).abs() < 1e-12, "{a} vs {b}");
    }
    assert!(f.total.iter().step_by(2).sum::<f64>().abs() < 1e-12);
    let mut acc = vec![0.0; g.ndof()];
    truth.acceleration(&g, &s, &mut acc).unwrap();
    assert_eq!(acc, acceleration(&g, &cfg.field, &s));

    // A pendulum rollout is the RATTLE integrator, constraints kept.
    let p = SystemConfig::new(SystemKind::Pendulum, 3);
    let pg = p.graph();
    let start = p.start_for(&pg, 1, 0);
    let truth = Truth {
        field: p.field.clone(),
    };
    let states = truth
        .rollout(
            &pg,
            &start,
            mcgnode::dynamics::Timing::integration(1e-4, 500, 1),
        )
        .unwrap();
    assert_eq!(states.len(), 501);
    let mut it = Integrator::new(&pg, &p.field, 1e-4, start).unwrap();
    it.advance(500);
    assert_eq!(&states[500], it.state());
    assert!(constraint_residual(&pg, &states[500]) < 1e-9);
    // The bar forces between bobs pull along the bars.
    let f = truth.forces(&pg, &states[500]).unwrap();
    for e in &f.edges {
        let d: Vec<f64> = (0..2)
            .map(|c| states[500].q[e.a * 2 + c] - states[500].q[e.b * 2 + c])
            .collect();
        let cross = d[0] * e.force[1] - d[1] * e.force[0];
        assert!(
            cross.abs() < 1e-9 * norm(&e.force).max(1.0),
            "bar force not along the bar"
        );
    }
}

/// Mean distance of the particles from their centroid (3D).
fn mean_radius(s: &State) -> f64 {
    let n = s.q.len() / 3;
    let mut c = [0.0; 3];
    for p in s.q.chunks(3) {
        for (ck, x) in c.iter_mut().zip(p) {
            *ck += x / n as f64;
        }
    }
    (0..n)
        .map(|i| norm(&(0..3).map(|k| s.q[i * 3 + k] - c[k]).collect::<Vec<_>>()))
        .sum::<f64>()
        / n as f64
}

#[test]
fn peridynamic_cube_graph_is_the_documented_lattice() {
    use mcgnode::physics::PERIDYNAMIC_HORIZON;
    let cfg = SystemConfig::new(SystemKind::Peridynamic, 125);
    assert_eq!(cfg.dim, 3);
    cfg.validate().unwrap();
    let g = cfg.graph();
    assert_eq!(g.dim, 3);
    assert_eq!(g.n(), 125);
    assert!(g.anchors.is_empty());
    assert_eq!(g.types, vec![0; 125]);
    assert_eq!(g.masses, vec![1.0; 125]);
    // 3·k²(k−1) face bonds + 3·2·k(k−1)² face diagonals = 300 + 480.
    assert_eq!(g.edges.len(), 780);
    let (mut faces, mut diagonals) = (0, 0);
    for e in &g.edges {
        assert_eq!(e.kind, EdgeKind::Spring);
        let Endpoint::Particle(b) = e.b else {
            panic!("bond to an anchor")
        };
        assert!(e.a < b);
        if (e.rest_length - 1.0).abs() < 1e-12 {
            faces += 1;
            assert!((e.stiffness - 1.0).abs() < 1e-12);
        } else {
            diagonals += 1;
            assert!((e.rest_length - 2f64.sqrt()).abs() < 1e-12);
            assert!((e.stiffness - 1.0 / 2f64.sqrt()).abs() < 1e-12);
        }
        assert!(e.rest_length <= PERIDYNAMIC_HORIZON);
    }
    assert_eq!((faces, diagonals), (300, 480));
    // Particle i = x + k(y + kz), centred: 0 is the (−2, −2, −2) corner and
    // the bonds' rest lengths are the reference distances.
    let s = cfg.start_for(&g, 1, 0);
    let g2 = g.clone();
    let mut reference = State {
        q: vec![0.0; 375],
        v: vec![0.0; 375],
    };
    for i in 0..125 {
        let idx = [i % 5, (i / 5) % 5, i / 25];
        for (x, j) in reference.q[i * 3..i * 3 + 3].iter_mut().zip(idx) {
            *x = j as f64 - 2.0;
        }
    }
    assert!(hamiltonian(&g2, &cfg.field, &reference).abs() < 1e-24);
    assert!(
        norm(
            &s.q.iter()
                .zip(&reference.q)
                .map(|(a, b)| a - b)
                .collect::<Vec<_>>()
        ) < 1.5
    );
    // Both cube sizes count bonds right.
    assert_eq!(
        SystemConfig::new(SystemKind::Peridynamic, 8)
            .graph()
            .edges
            .len(),
        12 + 12
    );
}

#[test]
fn peridynamic_solid_conserves_momentum_and_energy_and_expands() {
    let cfg = SystemConfig::new(SystemKind::Peridynamic, 125);
    assert_eq!((cfg.dt, cfg.save_every, cfg.states), (1e-3, 100, 100));
    assert!(cfg.field.is_free());
    let trajs = cfg.try_simulate(2, 5).unwrap();
    assert_eq!(trajs.len(), 2);
    let (mut dp, mut de, mut expanded) = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut p_rel = f64::INFINITY;
    for t in &trajs {
        assert_eq!(t.system, "peridynamic");
        assert_eq!(t.samples.len(), 100);
        let g = &t.graph;
        let s0 = &t.samples[0].state;
        let p0 = s0.momentum(g);
        let pscale = momentum_scale(g, s0);
        p_rel = p_rel.min(norm(&p0) / pscale);
        let h0 = hamiltonian(g, &cfg.field, s0);
        let r0 = mean_radius(s0);
        let mut rmax = 0.0_f64;
        for s in &t.samples {
            let p = s.state.momentum(g);
            dp = dp.max(norm(&(0..3).map(|c| p[c] - p0[c]).collect::<Vec<_>>()) / pscale);
            de = de.max((hamiltonian(g, &cfg.field, &s.state) - h0).abs() / h0.abs());
            rmax = rmax.max(mean_radius(&s.state));
        }
        expanded = expanded.max(rmax / r0);
    }
    println!(
        "peridynamic 125, 10 s at dt 1e-3: momentum error {dp:.3e} (relative to Σm|v|), \
         relative energy error {de:.3e}, max mean-radius growth {expanded:.4}, |p0|/Σm|v| ≥ {p_rel:.3e}"
    );
    assert!(dp < 1e-12, "momentum error {dp}");
    // Measured 3e-7: Verlet's bounded O(dt²) energy error at dt 1e-3; 1e-5
    // leaves a 30× margin and still catches a force inconsistent with H.
    assert!(de < 1e-5, "energy error {de}");
    assert!(expanded > 1.0, "the compressed solid never expanded");
    assert!(p_rel > 0.0, "momentum should be small but not zero");
}

#[test]
fn peridynamic_bad_input_and_seeds() {
    for n in [100, 1, 0, 9] {
        let err = SystemConfig::new(SystemKind::Peridynamic, n)
            .validate()
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("cube number") && err.contains(&n.to_string()),
            "{n}: {err}"
        );
        assert!(SystemConfig::new(SystemKind::Peridynamic, n)
            .try_simulate(1, 0)
            .is_err());
    }
    let mut c = SystemConfig::new(SystemKind::Peridynamic, 27);
    c.validate().unwrap();
    c.dim = 2;
    let err = c.validate().unwrap_err().to_string();
    assert!(err.contains("3-dimensional") && err.contains('2'), "{err}");
    assert_eq!(
        "peridynamic".parse::<SystemKind>().unwrap(),
        SystemKind::Peridynamic
    );
    assert_eq!(SystemKind::Peridynamic.to_string(), "peridynamic");

    // Different seeds, different starts; the same seed, the same start.
    let c = SystemConfig::new(SystemKind::Peridynamic, 27);
    let g = c.graph();
    let (a, b) = (c.start_for(&g, 1, 0), c.start_for(&g, 2, 0));
    assert_ne!(a, b);
    assert_eq!(a, c.start_for(&g, 1, 0));
    assert_ne!(a, c.start_for(&g, 1, 1));
    // Compressed by 2–8 % (with ±0.01 jitter), so every bond is short.
    for s in [&a, &b] {
        let longest = g
            .edges
            .iter()
            .map(|e| {
                let Endpoint::Particle(j) = e.b else { panic!() };
                let r = norm(
                    &(0..3)
                        .map(|k| s.q[e.a * 3 + k] - s.q[j * 3 + k])
                        .collect::<Vec<_>>(),
                );
                r / e.rest_length
            })
            .fold(0.0_f64, f64::max);
        assert!(longest < 1.0, "a bond is stretched at the start: {longest}");
    }
}
