//! The node's ROS parameters from rclpy, inside the private network namespace
//! (scripts/netns.sh): every parameter is listed and readable (substeps,
//! model_dir and max_particles included), a run-time parameter set through
//! rclpy changes the next prediction, and read-only, out-of-range and
//! ill-typed changes are refused with the reason; the standard `/diagnostics`
//! (diagnostic_msgs/DiagnosticArray) reports OK, then WARN after a rejection.
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`).

use std::fs;
use std::time::Duration;

mod common;

use common::{beside_node, driver_outcome, in_netns, ros_env, run_bounded};

#[test]
fn rclpy_lists_gets_and_sets_parameters() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let params = dir.path().join("params.yaml");
    fs::write(
        &params,
        "mcgnode:\n  ros__parameters:\n    model: truth:spring\n    horizon: 25\n    substeps: 2\n",
    )
    .expect("writing params");
    let script = &beside_node(
        r"
        timeout 90 python3 tests/ros/params_drive.py --timeout 20
    ",
    );
    let log = dir.path().join("node.log");
    let o = run_bounded(
        in_netns(script, &params, &env_sh).env("LOG", &log),
        Duration::from_secs(120),
        dir.path(),
    );
    let (summary, _log, report) = driver_outcome(&o, &log, "PARAMS_SUMMARY ");
    println!("{summary}");
    let s: serde_json::Value = serde_json::from_str(&summary).expect("PARAMS_SUMMARY is JSON");
    assert_eq!(s["before"]["horizon"], 25, "{report}");
    assert_eq!(s["before"]["substeps"], 2, "{report}");
    assert_eq!(s["before"]["model"], "truth:spring", "{report}");
    let r = &s["results"];
    assert_eq!(r["horizon=7"]["successful"], true, "{report}");
    assert_eq!(s["horizon_after"], 7, "{report}");
    assert_eq!(
        s["predicted_states"], 7,
        "the new horizon was not used\n{report}"
    );
    let refused = |key: &str, want: &str| {
        assert_eq!(r[key]["successful"], false, "{key} accepted\n{report}");
        let why = r[key]["reason"].as_str().unwrap_or_default();
        assert!(
            why.contains(want),
            "{key}: {why:?} lacks {want:?}\n{report}"
        );
    };
    refused("qos_depth=3", "restart the node with --set qos_depth");
    refused("dt=-1", "must be finite and > 0");
    refused("max_particles=0", "outside 1..=");
    assert_eq!(s["qos_depth_after"], 10, "{report}");
    // The standard /diagnostics beside NodeDiagnostics.
    let ok = &s["ok_diag"];
    assert_eq!(ok["level"], 0, "{report}");
    assert_eq!(ok["name"], "mcgnode: predictions", "{report}");
    assert_eq!(ok["values"]["dropped"], "0", "{report}");
    assert_eq!(ok["values"]["rejected"], "0", "{report}");
    let warn = &s["warn_diag"];
    assert_eq!(warn["level"], 1, "{report}");
    assert_eq!(warn["values"]["rejected"], "1", "{report}");
    let msg = warn["message"].as_str().unwrap_or_default();
    assert!(
        msg.contains("1 states rejected") && msg.contains("masses"),
        "{msg}\n{report}"
    );
}

/// With `use_sim_time: true` diagnostics are stamped from `/clock` (as during
/// bag playback), not from the system clock.
#[test]
fn use_sim_time_stamps_diagnostics_from_clock() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let params = dir.path().join("params.yaml");
    fs::write(
        &params,
        "mcgnode:\n  ros__parameters:\n    model: truth:spring\n    use_sim_time: true\n    \
         diagnostics_period: 0.2\n",
    )
    .expect("writing params");
    let script = &beside_node(
        r"
        timeout 60 python3 tests/ros/clock_drive.py --sec 4242 --timeout 20
    ",
    );
    let log = dir.path().join("node.log");
    let o = run_bounded(
        in_netns(script, &params, &env_sh).env("LOG", &log),
        Duration::from_secs(90),
        dir.path(),
    );
    let (summary, _log, report) = driver_outcome(&o, &log, "CLOCK_SUMMARY ");
    let s: serde_json::Value = serde_json::from_str(&summary).expect("CLOCK_SUMMARY is JSON");
    for key in ["node_diagnostics_sec", "diagnostics_sec"] {
        let last = s[key].as_array().and_then(|v| v.last()).cloned();
        assert_eq!(last, Some(serde_json::json!(4242)), "{key}\n{report}");
    }
}
