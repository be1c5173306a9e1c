//! The node's Plan service against real rclpy (issue 22): `mcgnode serve`
//! with the true physics of a held chain as its model, and
//! `scripts/ros/call.py` calling Plan from a simulated held-chain state, then
//! Rollout with the plan's kinematic motion, inside a private network
//! namespace (scripts/netns.sh). The replay must reproduce the plan's
//! predicted trajectory bit for bit, and the plan must beat holding still.
//! The Plan action (`tests/ros/plan_drive.py`) must give the service's plan
//! with a feedback per round, and stop a long goal on cancel.
//! An ensemble's plan must carry the spread the Rollout service reports for
//! its motion.
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`); the interface package is
//! (re)built with `scripts/build_msgs.sh`.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::fs;
use std::process::Command;
use std::time::Duration;

use mcgnode::data::msg::Point;
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::ros::wire::PlanRequest;
use mcgnode::system::Sample;

mod common;

use common::{ros_env, run_bounded, BIN};

/// A held chain of 5 links below its gripper (start seed 11), and a Plan
/// request from it: the free end to (dx, dy) from where it starts, at the
/// end of the horizon (CEM, 64 candidates × 3 rounds over 30 steps, seed 3).
fn held_chain_request(dx: f64, dy: f64) -> (mcgnode::system::Graph, PlanRequest) {
    let cfg = SystemConfig::new(SystemKind::HeldChain, 5);
    let g = cfg.graph();
    let state = cfg.start_for(&g, 11, 0);
    let sample = Sample {
        t: 0.0,
        state: state.clone(),
        acc: None,
    };
    let req = PlanRequest {
        initial: mcgnode::ParticleState::from_sample(0, 0, "held-chain", &g, &sample),
        particles: vec![4],
        targets: vec![Point {
            x: state.q[8] + dx,
            y: state.q[9] + dy,
            z: 0.0,
        }],
        cost: "final".into(),
        effort: 1e-3,
        horizon: 30,
        sampler: "cem".into(),
        candidates: 64,
        iterations: 3,
        elites: 8,
        max_speed: 1.0,
        seed: 3,
        ..PlanRequest::default()
    };
    (g, req)
}

/// Shell, beside the node (`common::beside_node`, its log in `$LOG`): waits
/// until it serves, calls Plan with `$DIR/plan.json` (reply in `plan.out`),
/// then Rollout with the plan's kinematic motion (`rollout.out`); `$rc` is
/// set on a failure.
const PLAN_THEN_ROLLOUT: &str = r#"
        for _ in $(seq 200); do grep -q serving "$LOG" && break; sleep 0.05; done
        grep -q serving "$LOG" || { echo "node did not start"; exit 2; }
        python3 scripts/ros/call.py /mcgnode/plan mcgnode_msgs/srv/Plan --file "$DIR/plan.json" \
            --json --timeout 60 >"$DIR/plan.out" || rc=3
        python3 - "$DIR" <<'PY' || rc=4
import json, sys
d = sys.argv[1]
plan = json.load(open(f"{d}/plan.out"))
req = json.load(open(f"{d}/plan.json"))
json.dump({
    "initial": req["initial"],
    "steps": req["horizon"],
    "dt": 0.0,
    "kinematic_positions": plan["kinematic_positions"],
    "kinematic_velocities": plan["kinematic_velocities"],
}, open(f"{d}/rollout.json", "w"))
PY
        python3 scripts/ros/call.py /mcgnode/rollout mcgnode_msgs/srv/Rollout --file "$DIR/rollout.json" \
            --json --timeout 60 >"$DIR/rollout.out" || rc=5
"#;

/// Runs `driver` beside the node on `$DIR/params.yaml` in a private network
/// namespace (bounded at 150 s), and returns it with a report of what it
/// and the node printed and `plan.out`'s start.
fn beside_node_in(d: &std::path::Path, driver: &str) -> (common::Outcome, String) {
    let params = d.join("params.yaml");
    let mut cmd = common::in_netns(&common::beside_node(driver), &params, &ros_env());
    cmd.env("DIR", d).env("LOG", d.join("node.log"));
    let o = run_bounded(&mut cmd, Duration::from_secs(150), d);
    let read = |name: &str| fs::read_to_string(d.join(name)).unwrap_or_default();
    let report = format!(
        "status {}\n--- stdout\n{}\n--- stderr\n{}\n--- node log\n{}\n--- plan\n{}",
        o.status,
        o.stdout,
        o.stderr,
        read("node.log"),
        read("plan.out").chars().take(2000).collect::<String>()
    );
    (o, report)
}

#[test]
fn plan_then_rollout_replays_the_prediction_bit_for_bit() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    // The target 0.4 to the side of the chain's free end and 0.1 up, at the
    // end of 3 s.
    let (_, req) = held_chain_request(0.4, 0.1);
    fs::write(d.join("plan.json"), serde_json::to_string(&req).unwrap()).unwrap();
    // Refining needs a reverse pass, which the true physics has not.
    let refine = PlanRequest {
        refine: 5,
        ..req.clone()
    };
    fs::write(
        d.join("refine.json"),
        serde_json::to_string(&refine).unwrap(),
    )
    .unwrap();
    // dt 0.1 with 20 substeps: the plan's control step and integration step.
    fs::write(
        d.join("params.yaml"),
        "mcgnode:\n  ros__parameters:\n    model: truth:held-chain\n    dt: 0.1\n    substeps: 20\n    horizon: 10\n",
    )
    .unwrap();
    let driver = format!(
        r#"{PLAN_THEN_ROLLOUT}
        python3 tests/ros/plan_drive.py --goal "$DIR/plan.json" >"$DIR/action.out" 2>&1 || rc=7
        python3 scripts/ros/call.py /mcgnode/plan mcgnode_msgs/srv/Plan --file "$DIR/refine.json" \
            --json --timeout 60 >"$DIR/refine.out" || rc=8
        [ "${{rc:-0}}" -eq 0 ]
    "#
    );
    let (o, report) = beside_node_in(d, &driver);
    let read = |name: &str| fs::read_to_string(d.join(name)).unwrap_or_default();
    let report = report + &format!("\n--- action\n{}", read("action.out"));
    assert!(o.status.success(), "{report}");
    assert!(!read("node.log").contains("panicked"), "{report}");
    let plan: serde_json::Value = serde_json::from_str(read("plan.out").trim()).expect("plan");
    let roll: serde_json::Value =
        serde_json::from_str(read("rollout.out").trim()).expect("rollout");
    assert_eq!(plan["success"], true, "{plan}");
    assert_eq!(roll["success"], true, "{roll}");
    let (cost, still) = (
        plan["cost"].as_f64().unwrap(),
        plan["hold_still_cost"].as_f64().unwrap(),
    );
    assert!(
        cost < 0.1 * still,
        "plan {cost} against holding still {still}"
    );
    assert_eq!(plan["driven"], serde_json::json!([5]));
    assert_eq!(plan["best"].as_array().unwrap().len(), 30);
    assert_eq!(plan["costs"].as_array().unwrap().len(), 64);
    // 30 control steps of 20 integration steps, and the start.
    assert_eq!(plan["kinematic_positions"].as_array().unwrap().len(), 601);
    let (p, r) = (&plan["trajectory"], &roll["trajectory"]);
    assert_eq!(p["steps"], 30);
    assert_eq!(r["steps"], 30);
    // Bit for bit: the same numbers, printed and parsed exactly.
    assert_eq!(p["positions"], r["positions"], "positions differ");
    assert_eq!(p["velocities"], r["velocities"], "velocities differ");
    // Particle 5 of the last of 30 states of 6 particles, 2 numbers each.
    let at = (29 * 6 + 5) * 2;
    let last = &r["positions"].as_array().unwrap()[at..at + 2];
    let grip = &plan["kinematic_positions"].as_array().unwrap()[600];
    assert_eq!(
        last,
        [grip["x"].clone(), grip["y"].clone()],
        "the gripper ends where the plan moved it"
    );
    assert_eq!(grip["z"], 0.0);
    // The Plan action: the same request gives the service's plan, bit for
    // bit, with a feedback per round; a cancel ends a long goal early.
    let action = read("action.out");
    let summary = action
        .lines()
        .find_map(|l| l.strip_prefix("PLAN_ACTION_SUMMARY "))
        .unwrap_or_else(|| panic!("no action summary: {action}"));
    let a: serde_json::Value = serde_json::from_str(summary).unwrap();
    assert_eq!(a["feedback"], 3, "{a}");
    assert_eq!(a["result"]["cost"], plan["cost"], "action vs service");
    assert_eq!(a["result"]["best"], plan["best"], "action vs service");
    assert!(a["cancelled_after"].as_u64().unwrap() < 100, "{a}");
    let refined: serde_json::Value =
        serde_json::from_str(read("refine.out").trim()).expect("refine");
    assert_eq!(refined["success"], false, "{refined}");
    assert!(
        refined["message"].as_str().unwrap().contains("no gradient"),
        "{refined}"
    );
}

/// An ensemble's plan (`train --ensemble 3` on held-chain data) carries its
/// members' spread along the best rollout: `steps × n` numbers, finite,
/// growing from the start, and equal bit for bit to the spread the Rollout
/// service reports for the plan's kinematic motion (the same mean rollout
/// computed by another request path).
#[test]
fn an_ensembles_plan_carries_the_spread_the_rollout_reports() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let bag = d.join("held.mcap");
    let model = d.join("ensemble.json");
    let run = |args: &[&str]| {
        let o = Command::new(BIN)
            .args(args)
            .current_dir(common::ROOT)
            .output()
            .expect("running mcgnode");
        assert!(o.status.success(), "{args:?}: {o:?}");
    };
    let (bag_s, model_s) = (bag.to_str().unwrap(), model.to_str().unwrap());
    run(&[
        "simulate",
        "--system",
        "held-chain",
        "--particles",
        "5",
        "--trajectories",
        "4",
        "--states",
        "31",
        "--out",
        bag_s,
    ]);
    run(&[
        "train",
        "--data",
        bag_s,
        "--model",
        "mcgnode",
        "--epochs",
        "3",
        "--ensemble",
        "3",
        "--quiet",
        "--out",
        model_s,
    ]);
    let (g, base) = held_chain_request(0.2, 0.0);
    let req = PlanRequest {
        horizon: 10,
        candidates: 32,
        iterations: 2,
        elites: 4,
        seed: 5,
        ..base
    };
    fs::write(d.join("plan.json"), serde_json::to_string(&req).unwrap()).unwrap();
    fs::write(
        d.join("params.yaml"),
        format!(
            "mcgnode:\n  ros__parameters:\n    model: {:?}\n    dt: 0.1\n    substeps: 20\n    horizon: 10\n",
            model.display()
        ),
    )
    .unwrap();
    let driver = format!("{PLAN_THEN_ROLLOUT}\n        [ \"${{rc:-0}}\" -eq 0 ]\n");
    let (o, report) = beside_node_in(d, &driver);
    let read = |name: &str| fs::read_to_string(d.join(name)).unwrap_or_default();
    assert!(o.status.success(), "{report}");
    let plan: serde_json::Value = serde_json::from_str(read("plan.out").trim()).expect("plan");
    let roll: serde_json::Value =
        serde_json::from_str(read("rollout.out").trim()).expect("rollout");
    assert_eq!(plan["success"], true, "{plan}");
    assert_eq!(roll["success"], true, "{roll}");
    let spread: Vec<f64> = plan["trajectory"]["spread"]
        .as_array()
        .expect("a spread")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect();
    let n = g.n();
    assert_eq!(spread.len(), 10 * n, "steps × particles: {spread:?}");
    assert!(
        spread.iter().all(|s| s.is_finite() && *s >= 0.0),
        "{spread:?}"
    );
    let sum = |k: usize| spread[k * n..(k + 1) * n].iter().sum::<f64>();
    assert!(sum(9) > sum(0) && sum(9) > 0.0, "no growth: {spread:?}");
    assert_eq!(
        plan["trajectory"]["spread"], roll["trajectory"]["spread"],
        "the plan's spread against the rollout's\n{report}"
    );
    assert_eq!(
        plan["trajectory"]["positions"],
        roll["trajectory"]["positions"]
    );
}
