//! Tracker input against rclpy, inside the private network namespace
//! (scripts/netns.sh): a best-effort publisher (as trackers and
//! SensorDataQoS publish) is heard with `input_qos: sensor_data`, and its
//! latency from publish to the prediction's arrival is printed (not
//! asserted: timings depend on the machine).
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`).

use std::fs;
use std::path::Path;
use std::time::Duration;

use mcgnode::data::msg::ParticleState;
use mcgnode::physics::{SystemConfig, SystemKind};

mod common;

use common::{beside_node, driver_outcome, in_netns, ros_env, run_bounded};

/// `seconds` of a `n`-spring ring sampled every 10 ms, as ParticleState
/// messages written to `path` as JSON (what tests/ros/tracker_drive.py
/// publishes); returns the messages.
fn states(path: &Path, n: usize, seconds: usize) -> Vec<ParticleState> {
    let mut cfg = SystemConfig::new(SystemKind::Spring, n);
    cfg.save_every = 10;
    cfg.states = seconds * 100 + 1;
    let graph = cfg.graph();
    let start = cfg.start_for(&graph, 21, 0);
    let tr = cfg.simulate_one(&graph, start, 0);
    let msgs: Vec<ParticleState> = tr
        .samples
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let step = u32::try_from(k).expect("a step");
            ParticleState::from_sample(0, step, "spring", &graph, s).with_field(Some(&cfg.field))
        })
        .collect();
    fs::write(path, serde_json::to_string(&msgs).expect("JSON")).expect("writing states");
    msgs
}

/// Runs the node on `params` beside tracker_drive.py with `args`; returns
/// the driver's summary and a report for assertion messages.
fn drive(d: &Path, params: &str, args: &str) -> (serde_json::Value, String) {
    let env_sh = ros_env();
    let params_path = d.join("params.yaml");
    fs::write(&params_path, params).expect("writing params");
    let driver = format!(
        r#"timeout 100 python3 tests/ros/tracker_drive.py --states "$DIR/states.json" {args}"#
    );
    let log = d.join("node.log");
    let o = run_bounded(
        in_netns(&beside_node(&driver), &params_path, &env_sh)
            .env("DIR", d)
            .env("LOG", &log),
        Duration::from_secs(150),
        d,
    );
    let (summary, _log, report) = driver_outcome(&o, &log, "TRACKER_SUMMARY ");
    let s = serde_json::from_str(&summary).expect("TRACKER_SUMMARY is JSON");
    (s, report)
}

fn count(s: &serde_json::Value, k: &str) -> u64 {
    s[k].as_u64().unwrap_or(0)
}

fn load() -> String {
    std::process::Command::new("uptime")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default()
}

#[test]
fn best_effort_states_are_served_with_sensor_data_qos() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let msgs = states(&d.join("states.json"), 5, 3);
    let (s, report) = drive(
        d,
        "mcgnode:\n  ros__parameters:\n    model: truth:spring\n    dt: 0.01\n    \
         substeps: 10\n    horizon: 20\n    diagnostics_period: 0.2\n    markers: false\n    \
         input_qos: sensor_data\n",
        "--mode state --rate 100",
    );
    println!(
        "best-effort ParticleState, 5 particles at 100 Hz: {} of {} predicted, latency p50 {} \
         ms, p99 {} ms, max {} ms ({})",
        s["predicted"],
        s["published"],
        s["p50_ms"],
        s["p99_ms"],
        s["max_ms"],
        load()
    );
    let n = msgs.len() as u64;
    assert_eq!(count(&s, "published"), n, "{report}");
    // Best effort may lose a sample; a reliable input would hear none.
    assert!(count(&s, "predicted") * 100 >= n * 95, "{report}");
    let diag = &s["diagnostics"];
    assert_eq!(diag["rejected"], 0, "{report}");
    assert!(diag["received"].as_u64() >= Some(n * 95 / 100), "{report}");
}
