//! Planning through a model (issue 22): the search against holding still and
//! against its own replay, the samplers, the CLI's JSON, and the closed loop
//! (`demo --mpc --quick`, also with a held-out stiffness and the risk term).
//! Run with `cargo test --release --test plan`.

mod common;

use common::cli::{log_ok, ok, run_in};
use mcgnode::dynamics::Dynamics;
use mcgnode::dynamics::Timing;
use mcgnode::models::truth::truth;
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::plan::{plan, Controls, Cost, CostKind, Problem, Sampler};
use std::process::Output;

fn problem<'a>(
    model: &'a dyn Dynamics,
    cfg: &SystemConfig,
    g: &'a mcgnode::Graph,
    start: &'a mcgnode::State,
) -> Problem<'a> {
    let end = cfg.particles - 1;
    Problem {
        model,
        graph: g,
        start,
        // Horizon 3 s: the chain's free end follows its gripper slowly (its
        // swing takes about 4.7 s).
        timing: Timing::of_step(0.005, 20, 30),
        cost: Cost {
            kind: CostKind::Final,
            particles: vec![end],
            targets: vec![start.q[2 * end] + 0.4, start.q[2 * end + 1] + 0.1],
            effort: 1e-3,
            speed: 0.0,
            risk: 0.0,
        },
        max_speed: 1.0,
    }
}

/// CEM with the true physics finds a sequence far cheaper than holding
/// still; its predicted trajectory is the rollout of its best sequence, bit
/// for bit; the same seed gives the same plan; the gripper moves as the
/// controls say and nothing else is driven.
#[test]
fn planning_beats_holding_still_and_replays_bit_for_bit() {
    let cfg = SystemConfig::new(SystemKind::HeldChain, 5);
    let g = cfg.graph();
    let start = cfg.start_for(&g, 3, 0);
    let model = truth(SystemKind::HeldChain);
    let p = problem(model.as_ref(), &cfg, &g, &start);
    let sampler = Sampler::Cem {
        candidates: 64,
        iterations: 3,
        elites: 8,
        sigma: 0.5,
    };
    let mut rounds = 0;
    let a = plan(&p, sampler, None, 5, |_| {
        rounds += 1;
        true
    })
    .unwrap();
    assert_eq!((rounds, a.evaluated, a.costs.len()), (3, 192, 64));
    let still = p.cost_of(&Controls::zeros(30, 2)).unwrap();
    assert!(a.cost < 0.1 * still, "plan {} vs still {still}", a.cost);
    assert!(a.iterations.windows(2).all(|w| w[1].best <= w[0].best));
    assert_eq!(a.predicted, p.rollout(&a.best).unwrap());
    assert_eq!(a.predicted.len(), 31);
    let b = plan(&p, sampler, None, 5, |_| true).unwrap();
    assert_eq!((a.best.clone(), a.cost), (b.best, b.cost));
    // The gripper's path is the controls' (velocity ramps to each knot).
    let drive = a.best.drive(&[5], 2, &start, p.timing);
    let last = a.predicted.last().unwrap();
    assert_eq!(&last.q[10..12], &drive.q[600][..]);
    assert_eq!(&last.v[10..12], a.best.row(29));
    // A cancelled search keeps its best so far.
    let one = plan(&p, sampler, None, 5, |_| false).unwrap();
    assert_eq!(one.iterations.len(), 1);
    // Random shooting and MPPI run and never end worse than their mean (the
    // warm start, holding still, is their first candidate).
    for s in [
        Sampler::Random {
            candidates: 32,
            sigma: 0.5,
        },
        Sampler::Mppi {
            candidates: 32,
            iterations: 2,
            sigma: 0.5,
            temperature: 0.1,
        },
    ] {
        let r = plan(&p, s, None, 1, |_| true).unwrap();
        assert!(r.cost <= still, "{s:?}: {} vs {still}", r.cost);
    }
}

/// Problems that cannot be planned are refused, saying what to change.
#[test]
fn ill_posed_problems_are_refused() {
    let cfg = SystemConfig::new(SystemKind::HeldChain, 4);
    let g = cfg.graph();
    let start = cfg.start_for(&g, 1, 0);
    let model = truth(SystemKind::HeldChain);
    let mut p = problem(model.as_ref(), &cfg, &g, &start);
    p.cost.targets.push(1.0);
    let s = Sampler::Random {
        candidates: 4,
        sigma: 0.1,
    };
    let e = plan(&p, s, None, 1, |_| true).unwrap_err().to_string();
    assert!(e.contains("one 2-vector per target particle"), "{e}");
    let spring = SystemConfig::new(SystemKind::Spring, 5);
    let gs = spring.graph();
    let ss = spring.start_for(&gs, 1, 0);
    let m = truth(SystemKind::Spring);
    let mut p = problem(m.as_ref(), &spring, &gs, &ss);
    p.cost.targets.truncate(2);
    let e = plan(&p, s, None, 1, |_| true).unwrap_err().to_string();
    assert!(e.contains("no kinematic particle"), "{e}");
}

/// `mcgnode plan --json` prints the costs, the best sequence and its
/// predicted trajectory, in the shapes its options ask for.
#[test]
fn the_plan_command_prints_json() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let j = json_ok(&run_in(
        d,
        &[
            "plan",
            "--model",
            "truth:held-chain",
            "--target",
            "0.8,-5.5",
            "--horizon",
            "6",
            "--dt",
            "0.01",
            "--substeps",
            "10",
            "--candidates",
            "24",
            "--iterations",
            "2",
            "--elites",
            "4",
            "--json",
        ],
    ));
    let best = j["best"].as_array().unwrap();
    assert_eq!(best.len(), 6);
    assert!(best.iter().all(|r| r.as_array().unwrap().len() == 2));
    assert_eq!(j["predicted"].as_array().unwrap().len(), 7);
    assert_eq!(j["costs"].as_array().unwrap().len(), 24);
    assert_eq!(j["iterations"].as_array().unwrap().len(), 2);
    assert_eq!(j["driven"], serde_json::json!([5]));
    assert_eq!(j["particle"], 4);
    let (cost, still) = (
        j["cost"].as_f64().unwrap(),
        j["hold_still_cost"].as_f64().unwrap(),
    );
    assert!(cost <= still, "{cost} > {still}");
    let o = run_in(
        d,
        &[
            "plan",
            "--model",
            "truth:spring",
            "--system",
            "spring",
            "--target",
            "1,1",
        ],
    );
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("no kinematic particle"), "{e}");
}

/// `demo --mpc --quick` writes mpc.json with each planner's success rate,
/// final distance and planning time, and mpc.png; the true physics as
/// planner ends nearer its targets than doing nothing.
#[test]
fn demo_mpc_writes_its_report() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = run_in(d, &["demo", "--mpc", "--quick", "--out", "out"]);
    log_ok(&o);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("out/mpc.json")).unwrap()).unwrap();
    for name in ["mcgnode", "mcgnode_refined", "gnode", "truth", "none"] {
        let p = &r["planners"][name];
        let rate = p["success_rate"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&rate), "{name}: {rate}");
        assert!(p["final_distance"].as_f64().unwrap() >= 0.0);
        assert!(p["seconds_per_step"].as_f64().unwrap() >= 0.0);
        assert_eq!(p["distances"].as_array().unwrap().len(), 4);
    }
    let dist = |n: &str| r["planners"][n]["final_distance"].as_f64().unwrap();
    assert!(dist("truth") < dist("none"), "{r}");
    assert_eq!(r["planners"]["none"]["seconds_per_step"], 0.0);
    // The learned planners say how much of their targets they explain.
    assert!(r["planners"]["mcgnode"]["explained"].as_f64().is_some());
    assert!(r["planners"]["truth"]["explained"].is_null());
    assert!(d.join("out/mpc.png").metadata().unwrap().len() > 1000);
}

/// `demo --mpc --quick --held-out-stiffness 250 --risk 2 --ensemble 2`: the
/// world's springs differ from the training data's, an ensemble plans with
/// and without the risk term beside the others; weights that cannot be
/// used and a risk weight on a single model are refused with the fix.
#[test]
fn demo_mpc_held_out_stiffness_with_risk() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let args = [
        "demo",
        "--mpc",
        "--quick",
        "--held-out-stiffness",
        "250",
        "--risk",
        "2",
        "--ensemble",
        "2",
        "--out",
        "out",
    ];
    log_ok(&run_in(d, &args));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("out/mpc.json")).unwrap()).unwrap();
    let names: Vec<&String> = r["planners"].as_object().unwrap().keys().collect();
    let want = [
        "gnode",
        "mcgnode",
        "mcgnode_ensemble",
        "mcgnode_risk",
        "none",
        "truth",
    ];
    assert_eq!(names, want, "{r}");
    let settings = r["settings"].as_str().unwrap();
    assert!(settings.contains("springs k = 250"), "{settings}");
    assert!(settings.contains("trained at k = 500"), "{settings}");
    assert!(settings.contains("ensemble of 2 members"), "{settings}");
    for name in want {
        assert_eq!(
            r["planners"][name]["distances"].as_array().unwrap().len(),
            4
        );
    }
    let refused = |args: &[&str], want: &str| {
        let o = run_in(d, args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(want), "{args:?}: {err}");
    };
    refused(
        &["demo", "--mpc", "--quick", "--risk", "1", "--ensemble", "1"],
        "an --ensemble of at least 2",
    );
    refused(&["demo", "--mpc", "--risk=-1"], "finite weights > 0");
    refused(
        &[
            "plan",
            "--model",
            "truth:held-chain",
            "--target",
            "1,-4",
            "--risk",
            "1",
        ],
        "train --ensemble K",
    );
}

/// The JSON `mcgnode` printed, after checking it succeeded.
fn json_ok(o: &Output) -> serde_json::Value {
    serde_json::from_str(&ok(o)).expect("mcgnode printed JSON")
}
