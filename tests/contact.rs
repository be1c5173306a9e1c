//! Ground truth with contacts (issue 21): the soft-sphere force against the
//! gradient of its potential, and the systems that touch against the
//! conservation laws (momentum of the closed colliding lattices, energy of
//! all three, the falling chain's bars), kinematic particles held still, and
//! the input errors. Run with `cargo test --release --test contact`.

use mcgnode::physics::{
    constraint_residual, hamiltonian, Integrator, PhysicsError, SystemConfig, SystemKind,
};
use mcgnode::physics::{contact_energy, ContactLaw, Contacts};
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph, State, SystemError};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Total energy: kinetic, springs, gravity and contacts.
fn energy(cfg: &SystemConfig, g: &Graph, s: &State) -> f64 {
    hamiltonian(g, &cfg.field, s) + contact_energy(g, cfg.contact_stiffness, &s.q)
}

/// Σ m|v| over the free particles: the scale of momentum errors.
fn momentum_scale(g: &Graph, s: &State) -> f64 {
    let d = g.dim;
    (0..g.n())
        .map(|i| {
            g.masses[i]
                * s.v[i * d..(i + 1) * d]
                    .iter()
                    .map(|x| x * x)
                    .sum::<f64>()
                    .sqrt()
        })
        .sum()
}

/// What a run saw: worst relative energy error, worst momentum change
/// relative to Σm|v|, worst bar residual, most contact energy.
#[derive(Debug, Default)]
struct Run {
    energy: f64,
    momentum: f64,
    bars: f64,
    contact: f64,
}

/// Integrates trajectory 0 of `cfg` (seed 3) at step `dt` for `seconds`,
/// checking every `every` steps; also that kinematic particles never move.
fn run(cfg: &SystemConfig, dt: f64, seconds: f64, every: usize) -> Run {
    let g = cfg.graph();
    let start = cfg.start_for(&g, 3, 0);
    let (e0, p0) = (energy(cfg, &g, &start), start.momentum(&g));
    // Kinetic energy plus |m g y| of the free particles: the walls' constant
    // potential energy would only dilute the error.
    let d = g.dim;
    let lift: f64 = (0..g.n())
        .filter(|&i| !g.is_kinematic(i))
        .map(|i| (g.masses[i] * cfg.field.gravity * start.q[i * d + 1]).abs())
        .sum();
    let (escale, pscale) = (
        mcgnode::physics::kinetic_energy(&g, &start) + lift,
        momentum_scale(&g, &start),
    );
    let mut it =
        Integrator::with_contacts(&g, &cfg.field, cfg.contact_stiffness, dt, start.clone())
            .unwrap();
    let steps = (seconds / dt).round() as usize;
    let mut out = Run::default();
    for _ in 0..steps / every {
        it.advance(every);
        let s = it.state();
        out.energy = out.energy.max((energy(cfg, &g, s) - e0).abs() / escale);
        let p = s.momentum(&g);
        let dp = p
            .iter()
            .zip(&p0)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        out.momentum = out.momentum.max(dp / pscale);
        out.bars = out.bars.max(constraint_residual(&g, s));
        out.contact = out.contact.max(it.contact_energy());
    }
    for i in (0..g.n()).filter(|&i| g.is_kinematic(i)) {
        let (a, b) = (i * d, (i + 1) * d);
        assert_eq!(
            it.state().q[a..b],
            start.q[a..b],
            "kinematic particle {i} moved"
        );
        assert!(it.state().v[a..b].iter().all(|x| *x == 0.0));
    }
    assert_eq!(it.shake_failures(), 0);
    out
}

#[test]
fn contact_force_is_minus_the_gradient_of_the_potential() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for dim in [2, 3] {
        let n = 40;
        let g = Graph {
            dim,
            types: vec![0; n],
            masses: vec![1.0; n],
            // A bonded pair gets no contact force, however close.
            edges: vec![Edge {
                a: 0,
                b: Endpoint::Particle(1),
                kind: EdgeKind::Spring,
                rest_length: 1.0,
                stiffness: 0.0,
            }],
            anchors: vec![],
            interaction_radius: 0.8,
            kinematic: vec![],
            periodic_box: None,
        };
        let q: Vec<f64> = (0..n * dim).map(|_| rng.random_range(0.0..2.5)).collect();
        let k_c = 37.0;
        let mut c = Contacts::new(&g, k_c);
        let mut f = vec![0.0; n * dim];
        c.add_forces(&q, dim, &mut f);
        assert!(c.pairs().len() > 20, "only {} contacts", c.pairs().len());
        assert!(!c.pairs().contains(&(0, 1)));
        let h = 1e-6;
        let mut worst = 0.0_f64;
        for k in 0..n * dim {
            let (mut up, mut down) = (q.clone(), q.clone());
            up[k] += h;
            down[k] -= h;
            let grad = (c.energy(&up, dim) - c.energy(&down, dim)) / (2.0 * h);
            worst = worst.max((f[k] + grad).abs());
        }
        let fmax = f.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        println!("{dim}D: max |F + ∇V| = {worst:.2e}, max |F| = {fmax:.2}");
        assert!(fmax > 1.0);
        assert!(worst < 1e-6 * fmax, "{worst} vs {fmax}");
        // Momentum: the forces sum to zero.
        for comp in 0..dim {
            let s: f64 = (0..n).map(|i| f[i * dim + comp]).sum();
            assert!(s.abs() < 1e-12 * fmax * n as f64, "Σ F = {s}");
        }
    }
    // The law itself: continuous at the radius, repulsive inside.
    let law = ContactLaw {
        radius: 2.0,
        stiffness: 4.0,
    };
    assert_eq!((law.potential(2.0), law.repulsion(2.0)), (0.0, 0.0));
    assert_eq!((law.potential(1.5), law.repulsion(1.5)), (0.5, 2.0));
    assert_eq!(law.potential(3.0), 0.0);
}

#[test]
fn colliding_lattices_conserve_momentum_and_energy_to_order_dt2() {
    for (dim, n) in [(2, 32), (3, 54)] {
        let mut cfg = SystemConfig::new(SystemKind::CollidingLattices, n);
        cfg.dim = dim;
        cfg.validate().unwrap();
        assert!(cfg.field.is_free());
        let coarse = run(&cfg, 2e-3, 3.0, 10);
        let fine = run(&cfg, 1e-3, 3.0, 20);
        println!("{dim}D lattices: energy {:.2e} (dt 2e-3) {:.2e} (dt 1e-3), momentum {:.1e}, peak contact energy {:.3}",
            coarse.energy, fine.energy, fine.momentum, fine.contact);
        assert!(fine.contact > 1e-3, "the lattices never touched");
        assert!(coarse.momentum < 1e-12 && fine.momentum < 1e-12);
        assert!(fine.energy < 1e-3, "energy error {}", fine.energy);
        let ratio = coarse.energy / fine.energy;
        assert!(
            (3.0..5.5).contains(&ratio),
            "halving dt divided the energy error by {ratio}, not ~4"
        );
    }
}

#[test]
fn soft_spheres_in_a_static_box_conserve_energy() {
    for (dim, n) in [(2, 30), (3, 8)] {
        let mut cfg = SystemConfig::new(SystemKind::SoftSpheres, n);
        cfg.dim = dim;
        let g = cfg.graph();
        assert_eq!(g.n_kinematic(), g.n() - n);
        assert!(g.kinematic[n..].iter().all(|k| *k) && !g.kinematic[..n].iter().any(|k| *k));
        assert!(g.edges.is_empty() && g.interaction_radius == 1.0);
        let coarse = run(&cfg, 2e-3, 4.0, 25);
        let fine = run(&cfg, 1e-3, 4.0, 50);
        println!(
            "{dim}D soft spheres ({} particles, {n} free): energy {:.2e} (dt 2e-3) {:.2e} (dt 1e-3), peak contact energy {:.3}",
            g.n(), coarse.energy, fine.energy, fine.contact
        );
        assert!(fine.contact > 1e-3, "no collision");
        assert!(fine.energy < 1e-3, "energy error {}", fine.energy);
        assert!(
            coarse.energy > 2.0 * fine.energy,
            "the error does not shrink with dt"
        );
    }
}

#[test]
fn soft_spheres_stay_in_their_box() {
    let cfg = SystemConfig::new(SystemKind::SoftSpheres, 30);
    let traj = cfg.simulate_one(&cfg.graph(), cfg.start_for(&cfg.graph(), 1, 0), 0);
    let g = &traj.graph;
    let walls: Vec<usize> = (0..g.n()).filter(|&i| g.is_kinematic(i)).collect();
    let q0 = &traj.samples[0].state.q;
    let hi = |c: usize| {
        walls
            .iter()
            .map(|&i| q0[i * 2 + c])
            .fold(f64::MIN, f64::max)
    };
    for s in &traj.samples {
        for i in 0..30 {
            for c in 0..2 {
                let x = s.state.q[i * 2 + c];
                assert!(x > 0.0 && x < hi(c), "ball {i} left the box: {x}");
            }
        }
        // Recorded accelerations: zero for the walls, gravity-led for balls.
        let a = s.acc.as_ref().unwrap();
        assert!(walls
            .iter()
            .all(|&i| a[i * 2] == 0.0 && a[i * 2 + 1] == 0.0));
    }
}

#[test]
fn falling_chain_keeps_its_bars_and_its_energy() {
    for dim in [2, 3] {
        let mut cfg = SystemConfig::new(SystemKind::FallingChain, 10);
        cfg.dim = dim;
        let g = cfg.graph();
        assert_eq!(g.n_bars(), 9);
        let coarse = run(&cfg, 2e-4, 1.0, 50);
        let fine = run(&cfg, 1e-4, 1.0, 100);
        println!(
            "{dim}D falling chain: bars {:.1e}, energy {:.2e} (dt 2e-4) {:.2e} (dt 1e-4), peak contact energy {:.3}",
            fine.bars, coarse.energy, fine.energy, fine.contact
        );
        assert!(fine.contact > 1e-2, "the chain never reached the floor");
        assert!(
            fine.bars < 1e-9 && coarse.bars < 1e-9,
            "bar residual {}",
            fine.bars
        );
        assert!(fine.energy < 1e-3, "energy error {}", fine.energy);
        assert!(
            coarse.energy > 2.0 * fine.energy,
            "the error does not shrink with dt"
        );
    }
}

#[test]
fn the_integrator_refuses_what_it_cannot_hold_still() {
    let cfg = SystemConfig::new(SystemKind::FallingChain, 4);
    let mut g = cfg.graph();
    let mut s = cfg.start_for(&g, 1, 0);
    let d = g.dim;
    let wall = g.n() - 1;
    s.v[wall * d] = 1.0;
    let e = Integrator::new(&g, &cfg.field, 1e-4, s.clone()).unwrap_err();
    assert_eq!(e, PhysicsError::KinematicMoving(wall));
    assert!(e.to_string().contains("start them at rest"), "{e}");
    s.v[wall * d] = 0.0;
    g.edges.push(Edge {
        a: 0,
        b: Endpoint::Particle(wall),
        kind: EdgeKind::Bar,
        rest_length: 1.0,
        stiffness: 0.0,
    });
    let e = Integrator::new(&g, &cfg.field, 1e-4, s.clone()).unwrap_err();
    assert!(matches!(e, PhysicsError::KinematicBar(0)), "{e}");
    let g = cfg.graph();
    let e = Integrator::with_contacts(&g, &cfg.field, -1.0, 1e-4, s).unwrap_err();
    assert!(matches!(e, PhysicsError::ContactStiffness(_)));
}

#[test]
fn contact_configurations_are_checked() {
    let cfg = SystemConfig::new(SystemKind::CollidingLattices, 30);
    let e = cfg.validate().unwrap_err().to_string();
    assert!(e.contains("2·k^dim") && e.contains("32"), "{e}");
    let mut cfg = SystemConfig::new(SystemKind::SoftSpheres, 10);
    cfg.interaction_radius = 0.0;
    let e = cfg.validate().unwrap_err().to_string();
    assert!(
        e.contains("interaction_radius") && e.contains("soft-spheres"),
        "{e}"
    );
    let mut cfg = SystemConfig::new(SystemKind::Spring, 5);
    cfg.contact_stiffness = f64::NAN;
    assert!(cfg.validate().is_err());
    let cfg = SystemConfig::new(SystemKind::FallingChain, 5);
    let e = mcgnode::physics::rk4_trajectories(&cfg, 1, 1).unwrap_err();
    assert!(e.to_string().contains("--integrator verlet"), "{e}");
    for kind in SystemKind::ALL {
        assert_eq!(kind.name().parse::<SystemKind>().unwrap(), kind);
        let json = serde_json::to_string(&kind).unwrap();
        assert_eq!(json, format!("\"{}\"", kind.name()));
    }
}

#[test]
fn graphs_without_contacts_read_and_write_as_before() {
    let cfg = SystemConfig::new(SystemKind::Spring, 5);
    let g = cfg.graph();
    let json = serde_json::to_string(&g).unwrap();
    assert!(
        !json.contains("interaction_radius") && !json.contains("kinematic"),
        "{json}"
    );
    let cjson = serde_json::to_string(&cfg).unwrap();
    assert!(
        !cjson.contains("contact") && !cjson.contains("radius"),
        "{cjson}"
    );
    let back: Graph = serde_json::from_str(&json).unwrap();
    assert_eq!(back, g);
    let back: SystemConfig = serde_json::from_str(&cjson).unwrap();
    assert_eq!(back, cfg);
    // A contact graph keeps both through a round trip.
    let c = SystemConfig::new(SystemKind::SoftSpheres, 4).graph();
    let back: Graph = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
    assert_eq!(back, c);
}

#[test]
fn graph_validation_names_the_fix() {
    let mut g = SystemConfig::new(SystemKind::Spring, 3).graph();
    g.interaction_radius = -1.0;
    assert_eq!(g.validate(), Err(SystemError::Radius(-1.0)));
    g.interaction_radius = f64::NAN;
    let e = g.validate().unwrap_err().to_string();
    assert!(e.contains("finite number ≥ 0"), "{e}");
    g.interaction_radius = 1.0;
    g.kinematic = vec![true, false];
    let e = g.validate().unwrap_err().to_string();
    assert!(
        e.contains("2 kinematic flags for 3 particles") && e.contains("one per particle"),
        "{e}"
    );
    g.kinematic = vec![false; 3];
    g.validate().unwrap();
    g.edges.push(Edge {
        a: 0,
        b: Endpoint::Anchor(0),
        kind: EdgeKind::Contact,
        rest_length: 1.0,
        stiffness: 0.0,
    });
    g.anchors.push(vec![0.0, 0.0]);
    assert!(g
        .validate()
        .unwrap_err()
        .to_string()
        .contains("contact edge joins two particles"));
}

#[test]
fn simulate_records_contact_systems_exactly() {
    let mut cfg = SystemConfig::new(SystemKind::CollidingLattices, 18);
    cfg.states = 5;
    let trajs = cfg.try_simulate(2, 4).unwrap();
    assert_eq!(trajs.len(), 2);
    for t in &trajs {
        assert_eq!(t.system, "colliding-lattices");
        assert_eq!(t.graph.interaction_radius, 1.0);
        assert!(t.graph.kinematic.is_empty());
        // The recorded acceleration is the integrator's at that state.
        let s = &t.samples[3];
        let mut it = Integrator::with_contacts(
            &t.graph,
            &cfg.field,
            cfg.contact_stiffness,
            cfg.dt,
            s.state.clone(),
        )
        .unwrap();
        assert_eq!(s.acc.as_ref().unwrap(), &it.exact_acceleration());
    }
    assert_ne!(trajs[0].samples[0].state, trajs[1].samples[0].state);
}

#[test]
fn the_truth_model_refuses_contacts_it_cannot_compute() {
    let m = mcgnode::models::truth::load_truth("truth:soft-spheres").unwrap();
    let g = SystemConfig::new(SystemKind::SoftSpheres, 4).graph();
    let e = m.supports(&g).unwrap_err().to_string();
    assert!(
        e.contains("no contact law") && e.contains("mcgnode simulate"),
        "{e}"
    );
    // Graphs without contacts are served as before.
    let spring = SystemConfig::new(SystemKind::Spring, 4).graph();
    mcgnode::models::truth::load_truth("truth:spring")
        .unwrap()
        .supports(&spring)
        .unwrap();
}
