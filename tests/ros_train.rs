//! Retraining and model swaps against real rclpy: `mcgnode serve` starts on a
//! model file trained here, and tests/ros/train_drive.py (inside
//! scripts/netns.sh, fresh domain id) calls Train, LoadModel and the Train
//! action while publishing states; see that script for the checks.
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`); the interface package is
//! (re)built with `scripts/build_msgs.sh`. Every child is bounded and killed
//! with its process group when it overruns.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::fs;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

mod common;

use common::{beside_node, driver_outcome, in_netns, ros_env, run_bounded, BIN};

/// `mcgnode <args>`, which must succeed.
fn mcgnode(args: &[&str], dir: &Path) {
    let o = run_bounded(Command::new(BIN).args(args), Duration::from_secs(120), dir);
    assert!(
        o.status.success(),
        "mcgnode {args:?} failed:\n{}\n{}",
        o.stdout,
        o.stderr
    );
}

#[test]
fn node_retrains_and_swaps_models() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let (a, b, m0) = (d.join("a.mcap"), d.join("b.mcap"), d.join("m0.json"));
    let rec = d.join("rec");
    // A tiny 5-spring bag and a 3-epoch model to start from; a larger bag from
    // another seed to retrain on.
    mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--particles",
            "5",
            "--trajectories",
            "5",
            "--seed",
            "1",
            "--out",
            &s(&a),
        ],
        d,
    );
    mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--particles",
            "5",
            "--trajectories",
            "20",
            "--seed",
            "2",
            "--out",
            &s(&b),
        ],
        d,
    );
    mcgnode(
        &[
            "train",
            "--model",
            "mcgnode",
            "--data",
            &s(&a),
            "--epochs",
            "3",
            "--out",
            &s(&m0),
            "--quiet",
        ],
        d,
    );
    let params = d.join("params.yaml");
    fs::write(
        &params,
        format!(
            "mcgnode:\n  ros__parameters:\n    model: {:?}\n    horizon: 10\n    dt: 0.01\n    \
             record_dir: {:?}\n",
            s(&m0),
            s(&rec)
        ),
    )
    .expect("writing params");
    let script = &beside_node(
        r#"
        timeout 150 python3 tests/ros/train_drive.py --model "$M0" --state-bag "$A" \
            --train-bag "$B" --record-dir "$REC" --work "$WORK"
    "#,
    );
    let log = d.join("node.log");
    let o = run_bounded(
        in_netns(script, &params, &env_sh)
            .env("LOG", &log)
            .env("M0", &m0)
            .env("A", &a)
            .env("B", &b)
            .env("REC", &rec)
            .env("WORK", d),
        Duration::from_secs(200),
        d,
    );
    let (summary, node_log, report) = driver_outcome(&o, &log, "TRAIN_SUMMARY ");
    println!("train driver summary: {summary}");
    // The log says why each failure happened and announces each swap.
    for needle in [
        "model swapped",
        "already running",
        "/nonexistent/missing.mcap",
        "cannot load /nonexistent/model.json",
        "cancel requested",
        "training cancelled",
        "fine-tuning the served model",
        "cannot fine-tune",
    ] {
        assert!(
            node_log.contains(needle),
            "{needle:?} missing from the node log\n{report}"
        );
    }
    assert!(!node_log.contains("panicked"), "{report}");
    let swaps = node_log.matches("model swapped").count();
    // Train service, LoadModel twice, action, recorded training, fine-tuning.
    assert_eq!(swaps, 6, "expected 6 swaps\n{report}");
    let lock_us: Vec<f64> = node_log
        .match_indices("model swapped (")
        .filter_map(|(i, m)| {
            node_log[i + m.len()..]
                .split(' ')
                .next()
                .and_then(|n| n.parse().ok())
        })
        .collect();
    println!("write lock held per swap (µs): {lock_us:?}");
}
