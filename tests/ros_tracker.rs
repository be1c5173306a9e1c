//! Tracker input against rclpy, inside the private network namespace
//! (scripts/netns.sh): a best-effort publisher (as trackers and
//! SensorDataQoS publish) is heard with `input_qos: sensor_data`; a 100 Hz
//! PoseArray stream of 5 particles and a 1,000-point PointCloud2 stream at
//! 10 Hz, interleaved with malformed messages, are predicted from a bag's
//! template while the malformed ones are refused with their reasons; a
//! reliable PoseArray stream is predicted through `velocity_smoother:
//! model`, its cost per state read from /diagnostics. Each prints its
//! latency from publish to the prediction's arrival (not
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

/// `seconds` of a `n`-spring ring sampled every `every_ms`, as ParticleState
/// messages written to `path` as JSON (what tests/ros/tracker_drive.py
/// publishes), and its first state as a bag `template.mcap` beside it;
/// returns the messages.
fn states(path: &Path, n: usize, seconds: usize, every_ms: usize) -> Vec<ParticleState> {
    let mut cfg = SystemConfig::new(SystemKind::Spring, n);
    cfg.save_every = every_ms;
    cfg.states = seconds * 1000 / every_ms + 1;
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
    let mut first = tr.clone();
    first.samples.truncate(1);
    let template = path.with_file_name("template.mcap");
    mcgnode::data::write_trajectories_with_field(
        template,
        &[first],
        &Default::default(),
        Some(&cfg.field),
    )
    .expect("writing the template bag");
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
    let msgs = states(&d.join("states.json"), 5, 3, 10);
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

/// Parameters serving truth:spring from tracker input on `topic_param`.
fn tracker_params(d: &Path, topic_param: &str, horizon: u32) -> String {
    format!(
        "mcgnode:\n  ros__parameters:\n    model: truth:spring\n    dt: 0.01\n    \
         substeps: 10\n    horizon: {horizon}\n    diagnostics_period: 0.2\n    \
         markers: false\n    warn_period: 0.0\n    input_qos: sensor_data\n    \
         {topic_param}: /tracker/points\n    input_template: {}\n    frame_id: world\n",
        d.join("template.mcap").display()
    )
}

/// The checks both tracker streams share: every good state after warm-up
/// predicted (best effort may lose one in twenty), starting where the
/// tracker put the particles, in its frame; the malformed ones refused,
/// each reason in the node's log.
fn check_tracker_run(s: &serde_json::Value, report: &str, warmup: u64, reasons: &[&str], tol: f64) {
    let n = count(s, "published");
    let after = n - warmup;
    assert!(
        count(s, "predicted_after_warmup") * 100 >= after * 95,
        "{after} states after warm-up\n{report}"
    );
    let worst = s["worst_position_error"].as_f64().unwrap_or(f64::NAN);
    assert!(worst <= tol, "initial positions {worst} off\n{report}");
    assert_eq!(s["frames"], serde_json::json!(["world"]), "{report}");
    let diag = &s["diagnostics"];
    let (bad, rejected) = (
        count(s, "malformed"),
        diag["rejected"].as_u64().unwrap_or(0),
    );
    assert!(bad >= 20, "{report}");
    assert!(
        rejected <= bad && rejected * 10 >= bad * 9,
        "{rejected} of {bad}\n{report}"
    );
    for r in reasons {
        assert!(report.contains(r), "no refusal saying {r:?}\n{report}");
    }
}

/// Prints a tracker run's counts and latencies, with the machine's load.
fn print_run(label: &str, s: &serde_json::Value) {
    println!(
        "{label}: {} of {} predicted, {} malformed sent, {} rejected; \
         latency p50 {} ms, p99 {} ms, max {} ms ({})",
        s["predicted"],
        s["published"],
        s["malformed"],
        s["diagnostics"]["rejected"],
        s["p50_ms"],
        s["p99_ms"],
        s["max_ms"],
        load()
    );
}

#[test]
fn best_effort_pose_arrays_are_predicted_and_malformed_ones_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    states(&d.join("states.json"), 5, 3, 10);
    let params = tracker_params(d, "pose_array_topic", 20);
    let args = "--mode pose --topic /tracker/points --rate 100 --malformed --every 4";
    let (s, report) = drive(d, &params, args);
    print_run("best-effort PoseArray, 5 particles at 100 Hz", &s);
    let reasons = [
        "PoseArray has 4 points; the template (input_template) has 5 particles",
        "PoseArray has 6 points",
        "PoseArray has 0 points",
        "PoseArray point 0: x = NaN is not finite",
        "PoseArray point 0: y = inf is not finite",
        "PoseArray frame_id \"camera\" is not the frame_id parameter \"world\"",
        "PoseArray frame_id \"\" is not",
    ];
    check_tracker_run(&s, &report, 20, &reasons, 1e-12);
}

#[test]
fn point_clouds_of_1000_points_are_predicted_and_malformed_ones_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    states(&d.join("states.json"), 1000, 6, 100);
    let params = tracker_params(d, "point_cloud_topic", 10);
    let args = "--mode cloud --topic /tracker/points --rate 10 --malformed --every 2 --warmup 3";
    let (s, report) = drive(d, &params, args);
    print_run("best-effort PointCloud2, 1000 points at 10 Hz", &s);
    let reasons = [
        "PointCloud2 has 999 points; the template (input_template) has 1000 particles",
        "PointCloud2 frame_id \"camera\" is not the frame_id parameter \"world\"",
        "PointCloud2 has no field 'z'",
        "PointCloud2 field 'z' has datatype 2",
        "PointCloud2 field 'z' at offset 8 (4 bytes) does not fit in point_step 8",
        "PointCloud2 data has 15995 bytes; height 1 × row_step 16000 = 16000",
        "PointCloud2 point 0: z = NaN is not finite",
        "PointCloud2 has 0 points",
    ];
    // float32 fields: positions as rounded to single precision.
    check_tracker_run(&s, &report, 3, &reasons, 1e-4);
}

/// `velocity_smoother: model` in the node: a reliable 100 Hz PoseArray
/// stream of 5 particles (positions only) predicted through the shipped
/// MCGNODE model, each state's start fitted through its rollout over the
/// last 15 positions. Every state after the warm-up gets its prediction,
/// starting near where the tracker put the particles, and /diagnostics
/// carries the fit's cost per state (printed, not asserted).
#[test]
fn pose_arrays_are_predicted_through_the_model_smoother() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    states(&d.join("states.json"), 5, 3, 10);
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("bags/models/spring5-mcgnode.json");
    let params = format!(
        "mcgnode:\n  ros__parameters:\n    model: {}\n    dt: 0.01\n    substeps: 10\n    \
         horizon: 20\n    diagnostics_period: 0.2\n    markers: false\n    \
         velocity_smoother: model\n    smoother_window: 15\n    \
         pose_array_topic: /tracker/points\n    input_template: {}\n    frame_id: world\n",
        model.display(),
        d.join("template.mcap").display()
    );
    let args = "--mode pose --topic /tracker/points --rate 100 --reliable --warmup 15";
    let (s, report) = drive(d, &params, args);
    print_run(
        "reliable PoseArray, 5 particles at 100 Hz, model smoother",
        &s,
    );
    let std = &s["standard"];
    let ms = |k: &str| std[k].as_str().and_then(|v| v.parse::<f64>().ok());
    println!(
        "model smoother cost per state in the node: median {:?} ms, p99 {:?} ms over {} fits; \
         fitted start {} from the tracker's positions ({})",
        ms("smoother_cost_median_ms"),
        ms("smoother_cost_p99_ms"),
        std["smoother_fits"],
        s["worst_position_error"],
        load()
    );
    let n = count(&s, "published");
    // Window 15: the 15th state is the first predicted.
    assert_eq!(count(&s, "predicted_after_warmup"), n - 15, "{report}");
    assert_eq!(s["diagnostics"]["rejected"], 0, "{report}");
    for k in ["smoother_cost_median_ms", "smoother_cost_p99_ms"] {
        assert!(ms(k).is_some_and(f64::is_finite), "no finite {k}\n{report}");
    }
    let fits: u64 = std["smoother_fits"]
        .as_str()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    assert!(fits >= n - 15, "{fits} fits\n{report}");
    // Noise-free positions: the fit through the model stays close to them.
    let worst = s["worst_position_error"].as_f64().unwrap_or(f64::NAN);
    assert!(worst < 1e-2, "fitted start {worst} off\n{report}");
}
