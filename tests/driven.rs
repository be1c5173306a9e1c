//! Kinematic particles that move (issues 21 and 22): the held chain's
//! simulator against the work–energy balance, the ground truth and learned
//! models rolled out under a given motion (exactly the simulator's; to
//! interpolation accuracy from a recording), and `evaluate` following a
//! bag's recorded gripper. Run with `cargo test --release --test driven`.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

mod common;

use common::cli::{evaluate_json, log_ok, run_in};
use mcgnode::dynamics::{Dynamics, Still};
use mcgnode::models::truth::load_truth;
use mcgnode::physics::{hamiltonian, Drive, Integrator, SystemConfig, SystemKind};
use mcgnode::system::{Graph, State};

fn held(links: usize, states: usize, save_every: usize) -> (SystemConfig, Graph) {
    let mut cfg = SystemConfig::new(SystemKind::HeldChain, links);
    cfg.states = states;
    cfg.save_every = save_every;
    let g = cfg.graph();
    (cfg, g)
}

/// Energy of the chain alone: the whole Hamiltonian less the gripper's own
/// kinetic and gravitational terms (its motion is given).
fn chain_energy(cfg: &SystemConfig, g: &Graph, s: &State) -> f64 {
    let gi = g.n() - 1;
    let d = g.dim;
    let vg2: f64 = s.v[gi * d..(gi + 1) * d].iter().map(|x| x * x).sum();
    hamiltonian(g, &cfg.field, s)
        - 0.5 * g.masses[gi] * vg2
        - g.masses[gi] * cfg.field.gravity * s.q[gi * d + 1]
}

/// ∂U/∂q_g of the gripper's spring: the force the gripper exerts on it.
fn spring_pull(g: &Graph, s: &State) -> Vec<f64> {
    let d = g.dim;
    let (gi, e) = (g.n() - 1, &g.edges[0]);
    let diff: Vec<f64> = (0..d).map(|c| s.q[gi * d + c] - s.q[e.a * d + c]).collect();
    let r = diff.iter().map(|x| x * x).sum::<f64>().sqrt();
    diff.iter()
        .map(|x| e.stiffness * (r - e.rest_length) / r * x)
        .collect()
}

/// The chain's energy changes by the work the moving gripper does on it,
/// ∫ ∂U/∂q_g · q̇_g dt (trapezoid over every step), to the integrator's
/// O(dt²); with the gripper held, the same chain keeps its energy.
#[test]
fn the_gripper_does_the_work_the_chain_gains() {
    for dim in [2, 3] {
        let (mut cfg, _) = held(6, 2001, 1);
        cfg.dim = dim;
        let g = cfg.graph();
        assert_eq!((g.n(), g.n_kinematic(), g.edges.len()), (7, 1, 6));
        let start = cfg.start_for(&g, 1, 0);
        let drive = cfg.drive_for(1, 0).expect("the held chain has a drive");
        assert!(drive.moves() && drive.steps() == 2000);
        let mut it = Integrator::driven(&g, &cfg.field, 0.0, cfg.dt, start, drive.clone()).unwrap();
        let e0 = chain_energy(&cfg, &g, it.state());
        let (mut work, mut p_prev) = (0.0, 0.0);
        let power = |s: &State| {
            let gi = g.n() - 1;
            let f = spring_pull(&g, s);
            (0..dim).map(|c| f[c] * s.v[gi * dim + c]).sum::<f64>()
        };
        p_prev += power(it.state());
        let mut swing = 0.0_f64;
        for k in 1..=2000 {
            it.step();
            let s = it.state();
            let p = power(s);
            work += 0.5 * (p + p_prev) * cfg.dt;
            p_prev = p;
            // The gripper is exactly where the drive has it.
            let gi = g.n() - 1;
            assert_eq!(&s.q[gi * dim..(gi + 1) * dim], &drive.q[k][..]);
            swing = swing.max(work.abs());
        }
        let gained = chain_energy(&cfg, &g, it.state()) - e0;
        let err = (gained - work).abs() / swing.max(1.0);
        assert!(swing > 1.0, "{dim}D: the gripper did little work ({swing})");
        assert!(
            err < 2e-3,
            "{dim}D: gained {gained}, work {work} (error {err:.2e})"
        );
    }
}

/// The truth rolled out under the simulator's own drive is the simulation;
/// under a drive interpolated from states saved every 100 steps it stays
/// within 1e-4 of it; `still` moves the gripper but nothing else.
#[test]
fn rollouts_follow_the_given_motion() {
    let (cfg, g) = held(8, 21, 100);
    let tr = cfg.try_simulate(1, 4).unwrap().remove(0);
    let drive = cfg.drive_for(4, 0).unwrap();
    let truth = load_truth("truth:held-chain").unwrap();
    let exact = truth
        .rollout_driven(
            &g,
            &tr.samples[0].state,
            mcgnode::dynamics::Timing::integration(cfg.dt, 2000, 100),
            &drive,
        )
        .unwrap();
    let recorded = Drive::from_samples(&g, &tr.samples, cfg.dt, 2000).unwrap();
    let interp = truth
        .rollout_driven(
            &g,
            &tr.samples[0].state,
            mcgnode::dynamics::Timing::integration(cfg.dt, 2000, 100),
            &recorded,
        )
        .unwrap();
    let worst = |a: &[State]| {
        a.iter()
            .zip(&tr.samples)
            .flat_map(|(x, s)| x.q.iter().zip(&s.state.q).map(|(p, q)| (p - q).abs()))
            .fold(0.0_f64, f64::max)
    };
    assert_eq!(exact.len(), 21);
    assert!(worst(&exact) == 0.0, "exact drive: {}", worst(&exact));
    let w = worst(&interp);
    assert!(w > 0.0 && w < 1e-4, "interpolated drive: {w}");
    // Held still instead, the chain goes elsewhere: the drive matters.
    let held_still = truth
        .rollout(
            &g,
            &tr.samples[0].state,
            mcgnode::dynamics::Timing::integration(cfg.dt, 2000, 100),
        )
        .unwrap();
    assert!(worst(&held_still) > 1e-2, "{}", worst(&held_still));
    let still = Still
        .rollout_driven(
            &g,
            &tr.samples[0].state,
            mcgnode::dynamics::Timing::integration(cfg.dt, 2000, 100),
            &drive,
        )
        .unwrap();
    let last = still.last().unwrap();
    let gi = g.n() - 1;
    assert_eq!(&last.q[gi * 2..], &drive.q[2000][..]);
    assert_eq!(&last.q[..gi * 2], &tr.samples[0].state.q[..gi * 2]);
    // A drive shorter than the rollout is refused, saying so.
    let e = truth
        .rollout_driven(
            &g,
            &tr.samples[0].state,
            mcgnode::dynamics::Timing::integration(cfg.dt, 2001, 100),
            &drive,
        )
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("covers 2000 steps, the rollout asks for 2001"),
        "{e}"
    );
}

/// `evaluate` follows a bag's recorded gripper: the truth scores near zero,
/// a learned MCGNODE (briefly trained) beats standing still, and standing
/// still moves the gripper too.
#[test]
fn evaluate_follows_the_recorded_gripper() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (out, seed, n) in [("train.mcap", "1", "20"), ("test.mcap", "2", "3")] {
        log_ok(&run_in(
            d,
            &[
                "simulate",
                "--system",
                "held-chain",
                "--particles",
                "5",
                "--trajectories",
                n,
                "--states",
                "31",
                "--seed",
                seed,
                "--out",
                out,
            ],
        ));
    }
    let eval = |model: &str| evaluate_json(d, &["--model", model, "--bag", "test.mcap"]);
    let t = eval("truth:held-chain");
    let re_truth = t["averages"]["re"].as_f64().unwrap();
    let re_still = t["still"]["re_mean"].as_f64().unwrap();
    assert!(
        re_truth < 1e-4 * re_still,
        "truth {re_truth:.3e}, still {re_still:.3e}"
    );
    // `rollout --initial` follows the recorded gripper too, for as long as
    // it was recorded.
    log_ok(&run_in(
        d,
        &[
            "rollout",
            "--model",
            "truth:held-chain",
            "--initial",
            "test.mcap",
            "--duration",
            "3",
            "--out",
            "r.mcap",
        ],
    ));
    let read = |p: &str| mcgnode::read_trajectories(d.join(p)).unwrap().trajectories;
    let (rec, roll) = (read("test.mcap"), read("r.mcap"));
    let (a, b) = (&rec[0].samples[30].state.q, &roll[0].samples[30].state.q);
    let worst = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0_f64, f64::max);
    assert!(worst < 1e-4, "rollout vs recording after 3 s: {worst}");
    let o = run_in(
        d,
        &[
            "rollout",
            "--model",
            "truth:held-chain",
            "--initial",
            "test.mcap",
            "--duration",
            "4",
            "--out",
            "r4.mcap",
        ],
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("give --duration 3 or less"),
        "{e}"
    );
    let log = log_ok(&run_in(
        d,
        &[
            "train",
            "--model",
            "mcgnode",
            "--data",
            "train.mcap",
            "--epochs",
            "400",
            "--out",
            "m.json",
        ],
    ));
    assert!(
        log.contains("1 kinematic particles, left out of the loss"),
        "{log}"
    );
    let m = eval("m.json");
    let re = m["averages"]["re"].as_f64().unwrap();
    assert!(
        re * 3.0 < re_still,
        "mcgnode {re:.3e}, still {re_still:.3e}"
    );
}
