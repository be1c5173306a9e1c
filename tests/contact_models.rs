//! Learned models of systems that touch (issue 21), end to end through the
//! CLI: MCGNODE learns the closed colliding lattices from contact edges found
//! at every state, beats standing still and conserves momentum exactly;
//! rollouts of the soft-sphere box, by MCGNODE and by GNS on its radius
//! graph, hold its kinematic walls; a model serves only the interaction
//! radius it was trained with, and LGN and HGN refuse contacts instead of
//! learning them wrongly. The executors themselves
//! (engine against candle and finite differences on contact graphs) are in
//! tests/engine.rs. Run with `cargo test --release --test contact_models`.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

mod common;

use common::cli::{evaluate_json, log_ok, run_in};
use std::process::Output;

fn refused(o: &Output) -> String {
    assert!(!o.status.success(), "mcgnode should have refused");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Two 4×4 spring lattices thrown at each other: 10 training trajectories,
/// 600 epochs with edge physics (about 10 s here). Measured at 600 epochs:
/// mean RE about 5x below standing still; at 1,000 epochs 10x (the README).
/// The test asks for 2x, and for momentum conserved to round-off (ME scaled
/// below 1e-12 at every time): contact forces are pairwise and antisymmetric
/// like every other MCGNODE force.
#[test]
fn mcgnode_learns_colliding_lattices_and_conserves_momentum() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (out, seed, n) in [("train.mcap", "1", "10"), ("test.mcap", "2", "2")] {
        log_ok(&run_in(
            d,
            &[
                "simulate",
                "--system",
                "colliding-lattices",
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
    let log = log_ok(&run_in(
        d,
        &[
            "train",
            "--model",
            "mcgnode",
            "--data",
            "train.mcap",
            "--edge-physics",
            "--epochs",
            "600",
            "--out",
            "m.json",
        ],
    ));
    assert!(
        log.contains("contacts within radius 1 (found at every state)"),
        "{log}"
    );
    assert!(log.contains("closed system"), "{log}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("m.json")).unwrap()).unwrap();
    assert_eq!(m["hyper"]["interaction_radius"], 1.0);
    let e = evaluate_json(d, &["--model", "m.json", "--bag", "test.mcap"]);
    let (re, still) = (
        e["averages"]["re"].as_f64().unwrap(),
        e["still"]["re_mean"].as_f64().unwrap(),
    );
    assert!(
        re * 2.0 < still,
        "mean RE {re:.3e} against still {still:.3e}"
    );
    let me = e["summary"]["me_scaled"]["gmean"].as_array().unwrap();
    assert!(me.iter().all(|x| x.as_f64().unwrap() < 1e-12), "{me:?}");
    // The same model refuses the data with contacts taken away, and a model
    // trained without them refuses the data with them, each naming the fix.
    let log = log_ok(&run_in(
        d,
        &[
            "train",
            "--model",
            "gnode",
            "--data",
            "train.mcap",
            "--radius",
            "0",
            "--epochs",
            "2",
            "--out",
            "plain.json",
        ],
    ));
    assert!(!log.contains("contacts within"), "{log}");
    let o = run_in(
        d,
        &["evaluate", "--model", "plain.json", "--bag", "test.mcap"],
    );
    let e = refused(&o);
    assert!(e.contains("train --radius 1"), "{e}");
    let e = refused(&run_in(
        d,
        &[
            "train",
            "--model",
            "lgn",
            "--data",
            "train.mcap",
            "--epochs",
            "1",
            "--out",
            "l.json",
        ],
    ));
    assert!(e.contains("LGN and HGN do not model contacts"), "{e}");
}

/// A box of 9 soft spheres: a model trained briefly rolls it out with its
/// walls exactly where they started, its balls moving, every number finite.
#[test]
fn soft_sphere_rollouts_hold_the_walls() {
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
            "2",
            "--states",
            "11",
            "--out",
            "box.mcap",
        ],
    ));
    // MCGNODE, and GNS in its defining setting: a radius graph with the
    // walls as particles.
    for model in ["mcgnode", "gns"] {
        let log = log_ok(&run_in(
            d,
            &[
                "train", "--model", model, "--data", "box.mcap", "--epochs", "5", "--out", "m.json",
            ],
        ));
        assert!(
            log.contains("kinematic particles, left out of the loss"),
            "{model}: {log}"
        );
        log_ok(&run_in(
            d,
            &[
                "rollout",
                "--model",
                "m.json",
                "--initial",
                "box.mcap",
                "--duration",
                "0.5",
                "--out",
                "roll.mcap",
            ],
        ));
        walls_held(d, model);
    }
}

/// The rollout in `d`/roll.mcap kept its walls where box.mcap starts them,
/// and moved its balls.
fn walls_held(d: &std::path::Path, model: &str) {
    let read = |p: &str| {
        mcgnode::data::bag::read_bags(&[d.join(p)], &Default::default())
            .unwrap()
            .trajectories
    };
    let start = &read("box.mcap")[0];
    let roll = &read("roll.mcap")[0];
    let g = &roll.graph;
    assert_eq!(g.interaction_radius, 1.0);
    assert!(g.n_kinematic() > 0 && g.n_kinematic() + 9 == g.n());
    assert!(roll.samples.len() > 2);
    let q0 = &start.samples[0].state.q;
    let last = &roll.samples.last().unwrap().state;
    let dim = g.dim;
    assert!(
        last.q.iter().chain(&last.v).all(|x| x.is_finite()),
        "{model}"
    );
    let mut moved = 0.0_f64;
    for i in 0..g.n() {
        let (a, b) = (&q0[i * dim..(i + 1) * dim], &last.q[i * dim..(i + 1) * dim]);
        if g.is_kinematic(i) {
            assert_eq!(a, b, "{model}: wall particle {i} moved");
        } else {
            moved = moved.max(a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum());
        }
    }
    assert!(moved > 1e-3, "{model}: the balls did not move ({moved})");
}

/// GNS's loss, like the GNODE family's, leaves kinematic particles out: their
/// targets change nothing; its radius graph reaches the walls.
#[test]
fn gns_loss_leaves_kinematic_particles_out() {
    use mcgnode::baselines::{BaselineHyper, BaselineNet, Kind};
    use mcgnode::gnode::Batch;
    use mcgnode::gnode::GraphPlan;
    use mcgnode::physics::{SystemConfig, SystemKind};
    use rand::SeedableRng;
    let cfg = SystemConfig::new(SystemKind::SoftSpheres, 4);
    let tr = cfg.simulate(1, 3).remove(0);
    let g = &tr.graph;
    let states: Vec<&mcgnode::State> = tr.samples.iter().map(|s| &s.state).collect();
    let mut targets: Vec<Vec<f64>> = tr.samples.iter().map(|s| s.acc.clone().unwrap()).collect();
    let mut hyper = BaselineHyper::new(Kind::Gns, 2, 2);
    hyper.interaction_radius = 1.0;
    let net = BaselineNet::new(hyper, &mut rand_chacha::ChaCha8Rng::seed_from_u64(1)).unwrap();
    let plan = GraphPlan::new(g);
    let loss = |t: &[Vec<f64>]| {
        let tr: Vec<&[f64]> = t.iter().map(Vec::as_slice).collect();
        let b = Batch::new(&plan, &states, Some(&tr), 2).unwrap();
        assert!(b.n_directed > 0, "the radius graph has edges");
        net.loss(&b, &g.masses).unwrap().to_scalar::<f64>().unwrap()
    };
    let before = loss(&targets);
    for t in &mut targets {
        for (f, x) in t.iter_mut().enumerate() {
            if g.is_kinematic(f / 2) {
                *x += 50.0;
            }
        }
    }
    assert_eq!(loss(&targets), before);
}
