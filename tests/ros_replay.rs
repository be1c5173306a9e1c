//! The node's Replay service against real rclpy: `mcgnode serve` with the
//! shipped 5-spring model and `scripts/ros/call.py` run together inside a
//! private network namespace (scripts/netns.sh) with a fresh domain id.
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`); the interface package is
//! (re)built here with `scripts/build_msgs.sh`. Every child runs in its own
//! process group, killed if it overruns its bound.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::fs;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use mcgnode::kernel::TrainedModel;
use mcgnode::replay::{replay_bag, ReplayOptions};

mod common;

use common::{ros_env, run_bounded, BIN, ROOT};

/// Serves the shipped 5-spring model (launch_params/spring5.yaml: horizon 100
/// of dt 0.1) and replays the shipped sample bag through it.
#[test]
fn replay_service_scores_a_bag_with_the_served_model() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let script = r#"
        set -u
        . "$ENV"
        "$BIN" serve --params launch_params/spring5.yaml 2>"$DIR/node.log" &
        node=$!
        for _ in $(seq 200); do grep -q serving "$DIR/node.log" && break; sleep 0.05; done
        grep -q serving "$DIR/node.log" || { echo "node did not start"; kill -KILL $node; exit 2; }
        python3 scripts/ros/call.py /mcgnode/replay mcgnode_msgs/srv/Replay \
            '{bag: bags/spring5-sample.mcap}' --json --timeout 60 >"$DIR/ok.out" || rc=3
        python3 scripts/ros/call.py /mcgnode/replay mcgnode_msgs/srv/Replay \
            '{bag: /nonexistent/x.mcap}' --json --timeout 30 >"$DIR/bad.out" || rc=4
        kill -INT $node
        for _ in $(seq 100); do kill -0 $node 2>/dev/null || break; sleep 0.1; done
        if kill -0 $node 2>/dev/null; then echo "node ignored SIGINT"; kill -KILL $node; exit 5; fi
        wait $node
        exit ${rc:-0}
    "#;
    let mut cmd = Command::new("bash");
    cmd.arg("scripts/netns.sh")
        .args(["bash", "-c", script])
        .env("BIN", BIN)
        .env("ENV", &env_sh)
        .env("DIR", dir.path())
        .env_remove("ROS_DOMAIN_ID");
    let o = run_bounded(&mut cmd, Duration::from_secs(150), dir.path());
    let read = |name: &str| fs::read_to_string(dir.path().join(name)).unwrap_or_default();
    let report = format!(
        "status {}\n--- stdout\n{}\n--- stderr\n{}\n--- node log\n{}",
        o.status,
        o.stdout,
        o.stderr,
        read("node.log")
    );
    assert!(o.status.success(), "{report}");
    assert!(!read("node.log").contains("panicked"), "{report}");

    let ok: serde_json::Value = serde_json::from_str(read("ok.out").trim()).expect("response");
    assert_eq!(ok["success"], true, "{ok}");
    let r: serde_json::Value =
        serde_json::from_str(ok["report_json"].as_str().expect("report_json")).expect("JSON");
    // The node's settings: its current model, dt and horizon × dt.
    assert!(
        r["model"]
            .as_str()
            .is_some_and(|m| m.starts_with("mcgnode trained on 5-particle spring")),
        "{r}"
    );
    assert_eq!(r["dt"], 0.1, "{r}");
    assert!((r["horizon"].as_f64().unwrap() - 10.0).abs() < 1e-9, "{r}");
    assert_eq!(r["trajectories"], 5);
    // The same replay in-process gives the same numbers.
    let model = TrainedModel::load(&Path::new(ROOT).join("bags/models/spring5-mcgnode.json"))
        .expect("model");
    let opts = ReplayOptions {
        dt: Some(0.1),
        horizon: Some(100.0 * 0.1),
        ..ReplayOptions::default()
    };
    let want = replay_bag(
        &model,
        &Path::new(ROOT).join("bags/spring5-sample.mcap"),
        &opts,
    )
    .expect("local replay");
    assert_eq!(r["starts"], want.starts);
    assert_eq!(r["comparisons"], want.comparisons);
    let re = r["averages"]["re"].as_f64().expect("averages.re");
    assert!(re > 0.0 && re < 1.0, "{r}");
    assert!(
        (re - want.averages.re).abs() <= 1e-12 * re,
        "{re} vs {}",
        want.averages.re
    );

    let bad: serde_json::Value = serde_json::from_str(read("bad.out").trim()).expect("response");
    assert_eq!(bad["success"], false, "{bad}");
    assert!(
        bad["message"]
            .as_str()
            .is_some_and(|m| m.contains("/nonexistent/x.mcap")),
        "{bad}"
    );
    assert_eq!(bad["report_json"], "");
}
