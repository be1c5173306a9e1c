//! The ROS 2 node against real rclpy: `mcgnode serve` and rclpy scripts run
//! together inside a private network namespace (scripts/netns.sh) with a fresh
//! domain id, so no DDS traffic leaves loopback.
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`); the interface package is
//! (re)built here with `scripts/build_msgs.sh`, which is quick when up to date.
//! Every child runs in its own process group, killed if it overruns its bound.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

mod common;

use common::{
    beside_node, driver_outcome, expect_success, in_netns, ros_env, run_bounded, BIN, ROOT,
};

/// A parameter file for the tests (short horizon, fast diagnostics);
/// `record_dir` records with bags split every second.
fn write_params(dir: &Path, record_dir: Option<&Path>) -> PathBuf {
    let p = dir.join("params.yaml");
    let mut text = String::from(
        "mcgnode:\n  ros__parameters:\n    model: truth:spring\n    horizon: 25\n    dt: 0.001\n    \
         diagnostics_period: 0.25\n    warn_period: 1.0\n    max_rollout_steps: 1000\n",
    );
    if let Some(r) = record_dir {
        text += &format!(
            "    record_dir: {:?}\n    record_split_seconds: 1.0\n",
            r.display()
        );
    }
    fs::write(&p, text).expect("writing params");
    p
}

/// A number from the driver's JSON summary (`"key": 12`).
fn summary_number(summary: &str, key: &str) -> u64 {
    let pat = format!("\"{key}\": ");
    let at = summary
        .find(&pat)
        .unwrap_or_else(|| panic!("{key} missing from {summary}"));
    summary[at + pat.len()..]
        .chars()
        .take_while(char::is_ascii_digit)
        .collect::<String>()
        .parse()
        .unwrap_or_else(|_| panic!("{key} is not a number in {summary}"))
}

#[test]
fn node_serves_rclpy_clients() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let params = write_params(dir.path(), Some(&rec));
    // The node logs to a file so its stderr can be checked separately; it is
    // stopped with SIGINT and must exit 0.
    let script = &beside_node(
        r"
        timeout 90 python3 tests/ros/drive.py --horizon 25 --dt 0.001 \
            --max-rollout-steps 1000 --warn-period 1.0
    ",
    );
    let log = dir.path().join("node.log");
    let o = run_bounded(
        in_netns(script, &params, &env_sh).env("LOG", &log),
        Duration::from_secs(120),
        dir.path(),
    );
    let (summary, node_log, report) = driver_outcome(&o, &log, "DRIVE_SUMMARY ");
    println!("rclpy driver summary: {summary}");
    assert!(node_log.contains("serving truth:spring"), "{report}");
    assert!(node_log.contains("shutting down"), "{report}");
    assert!(!node_log.contains("panicked"), "{report}");
    let warnings = node_log.matches("rejected input").count();
    assert!(
        (1..5).contains(&warnings),
        "expected 1 to 4 rate-limited warnings for 5 rejections, got {warnings}\n{report}"
    );
    assert!(node_log.contains("similar warnings suppressed"), "{report}");

    // The recording, split by duration, read back by mcap-ros2-support and rosbags.
    let predictions = summary_number(&summary, "predictions");
    // Undecodable samples cannot be recorded as ParticleState.
    let received = predictions + summary_number(&summary, "rejected")
        - summary_number(&summary, "undecodable");
    let check = run_bounded(
        Command::new(".venv/bin/python3")
            .arg("tests/ros/check_recording.py")
            .arg(&rec)
            .args(["--horizon", "25"])
            .args(["--predictions", &predictions.to_string()])
            .args(["--received", &received.to_string()]),
        Duration::from_secs(60),
        dir.path(),
    );
    assert!(
        check.status.success(),
        "recording check failed:\n{}\n{}\n{report}",
        check.stdout,
        check.stderr
    );
    println!("{}", check.stdout.trim());
    let bags = fs::read_dir(&rec)
        .map(std::iter::Iterator::count)
        .unwrap_or(0);
    assert!(
        bags >= 2,
        "expected the 1 s split to give several bags, got {bags}"
    );
}

/// States the served model cannot vouch for are never accepted silently:
/// edges it was not trained on are rejected, inputs far outside its training
/// scales are counted as out of range and warned about (refused once
/// `out_of_range_refuse` is set), in NodeDiagnostics and on /rosout
/// (tests/ros/range_drive.py).
#[test]
fn node_flags_states_outside_what_its_model_saw() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let model = dir.path().join("m.json");
    let o = run_bounded(
        Command::new(BIN)
            .args([
                "train", "--model", "mcgnode", "--epochs", "2", "--quiet", "--data",
            ])
            .arg(Path::new(ROOT).join("bags/spring5-sample.mcap"))
            .arg("--out")
            .arg(&model),
        Duration::from_secs(60),
        dir.path(),
    );
    assert!(o.status.success(), "training failed: {}", o.stderr);
    let params = dir.path().join("params.yaml");
    fs::write(
        &params,
        format!(
            "mcgnode:\n  ros__parameters:\n    model: {:?}\n    horizon: 5\n    dt: 0.01\n    \
             diagnostics_period: 0.2\n    warn_period: 0.5\n    markers: false\n",
            model.display()
        ),
    )
    .expect("writing params");
    let script = &beside_node("timeout 60 python3 tests/ros/range_drive.py");
    let log = dir.path().join("node.log");
    let o = run_bounded(
        in_netns(script, &params, &env_sh).env("LOG", &log),
        Duration::from_secs(90),
        dir.path(),
    );
    let (summary, node_log, report) = driver_outcome(&o, &log, "RANGE_SUMMARY ");
    println!("rclpy range driver summary: {summary}");
    // Three unseen edges, one 1e300 state (absurd, refused by default), one
    // refused with out_of_range_refuse.
    assert_eq!(summary_number(&summary, "rejected"), 5, "{report}");
    assert!(node_log.contains("absurd state"), "{report}");
    assert_eq!(summary_number(&summary, "out_of_range"), 2, "{report}");
    assert!(node_log.contains("out-of-range input"), "{report}");
    assert!(!node_log.contains("panicked"), "{report}");
}

#[test]
fn node_exits_cleanly_on_sigterm() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let params = write_params(dir.path(), None);
    // Wait (bounded) for the node to be up, then SIGTERM it.
    let script = r#"
        set -u
        . "$ENV"
        "$BIN" serve --params "$PARAMS" 2>"$LOG" &
        node=$!
        for _ in $(seq 200); do grep -q serving "$LOG" && break; sleep 0.05; done
        grep -q serving "$LOG" || { echo "node did not start"; kill -KILL $node; exit 2; }
        kill -TERM $node
        for _ in $(seq 100); do kill -0 $node 2>/dev/null || break; sleep 0.1; done
        if kill -0 $node 2>/dev/null; then echo "node ignored SIGTERM"; kill -KILL $node; exit 3; fi
        wait $node
    "#;
    let log = dir.path().join("node.log");
    let o = run_bounded(
        in_netns(script, &params, &env_sh).env("LOG", &log),
        Duration::from_secs(60),
        dir.path(),
    );
    let node_log = fs::read_to_string(&log).unwrap_or_default();
    assert!(
        o.status.success() && node_log.contains("shutting down"),
        "status {}\n{}\n{}\n--- node log\n{node_log}",
        o.status,
        o.stdout,
        o.stderr
    );
}

#[test]
fn bad_parameters_are_rejected_at_start() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bad = dir.path().join("bad.yaml");
    fs::write(&bad, "mcgnode:\n  ros__parameters:\n    horizn: 10\n").expect("writing");
    let good = write_params(dir.path(), None);
    let bad_arg = bad.to_string_lossy().into_owned();
    let good_arg = good.to_string_lossy().into_owned();
    let cases: [(Vec<&str>, &str); 5] = [
        (vec!["--params", &bad_arg], "unknown parameter \"horizn\""),
        (
            vec!["--params", &good_arg, "--set", "horizon=abc"],
            "must be an integer",
        ),
        (vec!["--set", "dt=0"], "must be finite and > 0"),
        (vec!["--model", "truth:rope"], "unknown system kind"),
        (
            vec!["--params", "/nonexistent/p.yaml"],
            "cannot read parameter file",
        ),
    ];
    for (args, want) in cases {
        // Through netns.sh all the same: a parameter check that wrongly passed
        // would start DDS, which must stay on loopback.
        let mut c = Command::new("bash");
        c.arg("scripts/netns.sh").arg(BIN).arg("serve").args(&args);
        let o = run_bounded(&mut c, Duration::from_secs(20), dir.path());
        assert!(!o.status.success(), "{args:?} was accepted");
        assert!(
            o.stderr.contains(want),
            "{args:?}: want {want:?} in:\n{}",
            o.stderr
        );
    }
}

#[test]
fn shipped_launch_params_are_valid() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut files: Vec<PathBuf> = fs::read_dir(Path::new(ROOT).join("launch_params"))
        .expect("launch_params/ exists")
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "yaml"))
        .collect();
    files.sort();
    let names: Vec<String> = files
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    for want in ["spring5.yaml", "pendulum5.yaml"] {
        assert!(
            names.iter().any(|n| n == want),
            "launch_params/{want} missing: {names:?}"
        );
    }
    for f in &files {
        // --print-params exits before any DDS entity exists.
        let o = run_bounded(
            Command::new(BIN)
                .arg("serve")
                .arg("--params")
                .arg(f)
                .arg("--print-params"),
            Duration::from_secs(20),
            dir.path(),
        );
        assert!(o.status.success(), "{}: {}", f.display(), o.stderr);
        assert!(o.stdout.contains("ros__parameters:"), "{}", o.stdout);
        let name = f
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let system = name.trim_end_matches(char::is_numeric);
        assert!(
            o.stdout.contains(&format!("truth:{system}")) || !o.stdout.contains("truth:"),
            "{}: model does not match the file's system:\n{}",
            f.display(),
            o.stdout
        );
    }
}

/// The rclpy stand-ins for the ros2 CLI: play a bag onto the node's input,
/// echo its predictions and diagnostics, call Rollout with a YAML request.
#[test]
fn stand_ins_play_echo_and_call() {
    use mcgnode::physics::{SystemConfig, SystemKind};
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let params = write_params(dir.path(), None);
    let mut cfg = SystemConfig::new(SystemKind::Spring, 5);
    cfg.states = 12;
    let trajectories = cfg.simulate(1, 7);
    let bag = dir.path().join("spring.mcap");
    mcgnode::data::write_trajectories(&bag, &trajectories, &Default::default())
        .expect("writing the bag");
    let request = dir.path().join("rollout.yaml");
    // Two particles 1.5 apart on a spring of rest length 1: they attract.
    fs::write(
        &request,
        "steps: 3\ndt: 0.1\ninitial:\n  dimension: 2\n  types: [0, 0]\n  masses: [1.0, 1.0]\n  \
         positions: [{x: 0.0}, {x: 1.5}]\n  velocities: [{}, {}]\n  edge_a: [0]\n  edge_b: [1]\n  \
         edge_kind: [0]\n  edge_rest_length: [1.0]\n  edge_stiffness: [1.0]\n",
    )
    .expect("writing the request");
    let script = r#"
        set -u
        . "$ENV"
        "$BIN" serve --params "$PARAMS" 2>"$DIR/node.log" &
        node=$!
        python3 scripts/ros/echo.py /mcgnode/predicted_trajectory --json --field header.stamp \
            --count 12 --timeout 60 >"$DIR/echo.out" 2>"$DIR/echo.err" &
        echo_pid=$!
        for _ in $(seq 400); do grep -q listening "$DIR/echo.err" && break; sleep 0.05; done
        grep -q listening "$DIR/echo.err" || { echo "echo never matched"; cat "$DIR/echo.err"; exit 2; }
        python3 scripts/ros/play_bag.py "$BAG" --rate 50 --timeout 30 || exit 3
        wait $echo_pid || { echo "echo failed"; cat "$DIR/echo.err"; exit 4; }
        python3 scripts/ros/echo.py /mcgnode/diagnostics --json --count 1 --timeout 30 \
            >"$DIR/diag.out" || exit 5
        python3 scripts/ros/call.py /mcgnode/rollout mcgnode_msgs/srv/Rollout --file "$REQ" \
            --json --timeout 30 >"$DIR/call.out" || exit 6
        kill -INT $node; wait $node
    "#;
    let o = run_bounded(
        in_netns(script, &params, &env_sh)
            .env("DIR", dir.path())
            .env("BAG", &bag)
            .env("REQ", &request),
        Duration::from_secs(120),
        dir.path(),
    );
    let read = |name: &str| fs::read_to_string(dir.path().join(name)).unwrap_or_default();
    expect_success(&o, &dir.path().join("node.log"));
    // One prediction per played state, stamped with the state's sample time.
    let stamps: Vec<serde_json::Value> = read("echo.out")
        .lines()
        .map(|l| serde_json::from_str(l).expect("echo --json line"))
        .collect();
    let want: Vec<serde_json::Value> = trajectories[0]
        .samples
        .iter()
        .map(|s| {
            let t = mcgnode::data::msg::Time::from_secs(s.t);
            serde_json::json!({"sec": t.sec, "nanosec": t.nanosec})
        })
        .collect();
    assert_eq!(stamps, want);
    let diag: serde_json::Value = serde_json::from_str(read("diag.out").trim()).expect("diag");
    assert_eq!(diag["received"], 12, "{diag}");
    assert_eq!(diag["predicted"], 12, "{diag}");
    let call: serde_json::Value = serde_json::from_str(read("call.out").trim()).expect("call");
    assert_eq!(call["success"], true, "{call}");
    assert_eq!(call["trajectory"]["steps"], 3, "{call}");
    let positions = call["trajectory"]["positions"]
        .as_array()
        .expect("positions");
    assert_eq!(positions.len(), 3 * 2 * 2, "{call}");
    // State 2 (the last), particle 1, x: positions[(2 * n + 1) * d].
    let x1 = positions[(2 * 2 + 1) * 2].as_f64().expect("x");
    assert!(
        x1 < 1.5,
        "the stretched spring should pull particle 1 back: x = {x1}"
    );
}

/// A shipped bag of the first message layout is played through rclpy (field
/// unknown), and the node, serving the spring model, refuses the pendulum
/// states it was not trained for: counted as rejected, with the reason.
#[test]
fn node_refuses_states_its_model_was_not_trained_for() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let params = dir.path().join("params.yaml");
    fs::write(
        &params,
        "mcgnode:\n  ros__parameters:\n    model: bags/models/spring5-mcgnode.json\n    horizon: 5\n    \
         dt: 0.01\n    diagnostics_period: 0.25\n    warn_period: 1.0\n",
    )
    .expect("writing params");
    let script = r#"
        set -u
        . "$ENV"
        "$BIN" serve --params "$PARAMS" 2>"$DIR/node.log" &
        node=$!
        python3 scripts/ros/play_bag.py bags/pendulum5-sample.mcap --rate 50 --limit 6 \
            --timeout 30 2>"$DIR/play.err" || { cat "$DIR/play.err"; exit 3; }
        sleep 0.5
        python3 scripts/ros/echo.py /mcgnode/diagnostics --json --count 1 --timeout 30 \
            >"$DIR/diag.out" || exit 5
        kill -INT $node; wait $node
    "#;
    let o = run_bounded(
        in_netns(script, &params, &env_sh).env("DIR", dir.path()),
        Duration::from_secs(120),
        dir.path(),
    );
    let read = |name: &str| fs::read_to_string(dir.path().join(name)).unwrap_or_default();
    expect_success(&o, &dir.path().join("node.log"));
    assert!(
        read("play.err").contains("published 6 messages"),
        "{}",
        read("play.err")
    );
    let diag: serde_json::Value = serde_json::from_str(read("diag.out").trim()).expect("diag");
    assert_eq!(diag["received"], 6, "{diag}");
    assert_eq!(diag["rejected"], 6, "{diag}");
    assert_eq!(diag["predicted"], 0, "{diag}");
    let last = diag["last_error"].as_str().unwrap_or_default();
    assert!(
        last.contains("trained on a system with springs") && last.contains("rigid bars"),
        "{last}"
    );
    let log = read("node.log");
    assert!(log.contains("rejected input"), "{log}");
}

/// scripts/ros_markers.sh, as the README runs it: the node's recording holds
/// one MarkerArray per played state, and `bag draw` turns the last into a PNG.
#[test]
fn markers_script_records_and_draws_what_rviz_would_show() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("markers.png");
    let rec = dir.path().join("rec");
    let o = run_bounded(
        Command::new("scripts/ros_markers.sh")
            .arg(&png)
            .args(["--states", "6", "--keep"])
            .arg(&rec)
            .env("BIN", BIN)
            .current_dir(ROOT),
        Duration::from_secs(180),
        dir.path(),
    );
    assert!(o.status.success(), "{}\n{}", o.stdout, o.stderr);
    assert!(
        o.stdout.contains("drew MarkerArray 5 (of 6;"),
        "{}",
        o.stdout
    );
    let bytes = fs::read(&png).unwrap();
    assert!(
        bytes.len() > 5000 && bytes.starts_with(b"\x89PNG"),
        "not a PNG"
    );
}

/// With `lifecycle: true` the node is a managed node that rclpy drives
/// through configure, activate and deactivate (tests/ros/lifecycle_drive.py).
#[test]
fn managed_lifecycle_gates_the_predictions() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let params = write_params(dir.path(), None);
    let script = &beside_node("timeout 90 python3 tests/ros/lifecycle_drive.py");
    let log = dir.path().join("node.log");
    let o = run_bounded(
        in_netns(script, &params, &env_sh)
            .env("LOG", &log)
            .env("NODE_ARGS", "--set lifecycle=true"),
        Duration::from_secs(150),
        dir.path(),
    );
    let (summary, node_log, report) = driver_outcome(&o, &log, "LIFECYCLE_SUMMARY ");
    println!("lifecycle driver summary: {summary}");
    assert!(
        node_log.contains("lifecycle: unconfigured -> inactive (configure)"),
        "{report}"
    );
    assert!(
        node_log.contains("lifecycle transition 0 \"activate\" is not available from unconfigured"),
        "{report}"
    );
    assert!(
        node_log.contains("rejected input: the node is unconfigured"),
        "{report}"
    );
}

/// scripts/build_msgs.sh run by several tests and scripts at once (each test
/// binary's rclpy environment beside scripts/ros_markers.sh): every run
/// succeeds (one at a time, under build/msgs.lock), and a reader sourcing
/// build/msgs/env.sh meanwhile always finds it whole. Before the lock, CI
/// saw both failures when the package needed a rebuild: two builds in one
/// tree ("build failed"), and a driver without rclpy (env.sh read while it
/// was rewritten in place). This test does not force a rebuild: the other
/// tests of this binary use the installed package meanwhile.
#[test]
fn concurrent_message_builds_all_succeed() {
    let env_sh = ros_env();
    let runs: Vec<_> = (0..3)
        .map(|_| {
            Command::new("timeout")
                .args(["300", "bash", "scripts/build_msgs.sh"])
                .current_dir(ROOT)
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .expect("run scripts/build_msgs.sh")
        })
        .collect();
    // Sourced while the builds run: complete every time.
    let probe = format!(
        "for _ in $(seq 200); do . '{}'; [ \"${{ROS_DISTRO:-}}\" = kilted ] || exit 1; unset ROS_DISTRO; done",
        env_sh.display()
    );
    let o = Command::new("bash")
        .args(["-c", &probe])
        .output()
        .expect("run bash");
    for child in runs {
        let out = child
            .wait_with_output()
            .expect("wait for scripts/build_msgs.sh");
        assert!(
            out.status.success(),
            "scripts/build_msgs.sh failed beside two others:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    assert!(
        o.status.success(),
        "build/msgs/env.sh was read half written"
    );
}

/// Trains a 3-member ensemble on the shipped spring bag into `dir` and
/// writes parameters serving it (horizon 8, dt 0.01); the parameter file.
fn ensemble_params(dir: &Path) -> PathBuf {
    let model = dir.join("ensemble.json");
    let train = Command::new(BIN)
        .args([
            "train",
            "--data",
            "bags/spring5-sample.mcap",
            "--model",
            "mcgnode",
        ])
        .args(["--epochs", "3", "--ensemble", "3", "--quiet", "--out"])
        .arg(&model)
        .current_dir(ROOT)
        .output()
        .expect("running train");
    assert!(train.status.success(), "{train:?}");
    let params = dir.join("params.yaml");
    fs::write(
        &params,
        format!(
            "mcgnode:\n  ros__parameters:\n    model: {:?}\n    horizon: 8\n    dt: 0.01\n    \
             diagnostics_period: 0.25\n    spread_warn: 1.0e-12\n",
            model.display()
        ),
    )
    .expect("writing params");
    params
}

/// A JSON array of numbers.
fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect()
}

/// The number under `key` in the first status of an echoed DiagnosticArray.
fn diagnostic_value(diag: &serde_json::Value, key: &str) -> f64 {
    diag["status"][0]["values"]
        .as_array()
        .expect("values")
        .iter()
        .find(|kv| kv["key"] == key)
        .unwrap_or_else(|| panic!("no {key} in {diag}"))["value"]
        .as_str()
        .expect("a string")
        .parse()
        .expect("a number")
}

/// An ensemble (`train --ensemble 3`) served: each PredictedTrajectory carries
/// its spread (`steps × n` numbers, finite, growing from ~0), the Rollout
/// reply for the same input carries the same spread, and `/diagnostics`
/// reports the latest prediction's largest spread as `spread_max`.
#[test]
fn node_publishes_an_ensembles_spread() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let params = ensemble_params(dir.path());
    let script = r#"
        set -u
        . "$ENV"
        "$BIN" serve --params "$PARAMS" 2>"$DIR/node.log" &
        node=$!
        python3 scripts/ros/echo.py /mcgnode/predicted_trajectory --json --count 3 --timeout 60 \
            >"$DIR/echo.out" 2>"$DIR/echo.err" &
        echo_pid=$!
        for _ in $(seq 400); do grep -q listening "$DIR/echo.err" && break; sleep 0.05; done
        grep -q listening "$DIR/echo.err" || { echo "echo never matched"; cat "$DIR/echo.err"; exit 2; }
        python3 scripts/ros/play_bag.py bags/spring5-sample.mcap --rate 20 --limit 3 --timeout 30 \
            || exit 3
        wait $echo_pid || { echo "echo failed"; cat "$DIR/echo.err"; exit 4; }
        sleep 0.5
        python3 scripts/ros/echo.py /diagnostics --json --count 1 --timeout 30 \
            >"$DIR/diag.out" || exit 5
        python3 -c 'import json,sys; t=json.loads(open(sys.argv[1]).readlines()[-1]); print(json.dumps({"initial": t["initial"], "steps": t["steps"], "dt": t["dt"]}))' \
            "$DIR/echo.out" >"$DIR/req.json" || exit 6
        python3 scripts/ros/call.py /mcgnode/rollout mcgnode_msgs/srv/Rollout --file "$DIR/req.json" \
            --json --timeout 30 >"$DIR/call.out" || exit 7
        kill -INT $node; wait $node
    "#;
    let o = run_bounded(
        in_netns(script, &params, &env_sh).env("DIR", dir.path()),
        Duration::from_secs(150),
        dir.path(),
    );
    let read = |name: &str| fs::read_to_string(dir.path().join(name)).unwrap_or_default();
    expect_success(&o, &dir.path().join("node.log"));
    let json = |text: &str| -> serde_json::Value { serde_json::from_str(text).expect("JSON") };
    let out = read("echo.out");
    let last = json(out.lines().last().expect("three predictions"));
    let (steps, n) = (
        8,
        last["initial"]["masses"].as_array().expect("masses").len(),
    );
    assert_eq!(last["steps"], steps, "{last}");
    let spread = numbers(&last["spread"]);
    assert_eq!(spread.len(), steps * n, "steps × particles numbers");
    assert!(
        spread.iter().all(|s| s.is_finite() && *s >= 0.0),
        "{spread:?}"
    );
    let (first, end) = (&spread[..n], &spread[(steps - 1) * n..]);
    assert!(
        end.iter().sum::<f64>() > first.iter().sum::<f64>(),
        "the members drift apart along the horizon: {first:?} .. {end:?}"
    );
    let call = json(read("call.out").trim());
    assert_eq!(call["success"], true, "{call}");
    assert_eq!(
        numbers(&call["trajectory"]["spread"]),
        spread,
        "the topic's spread"
    );
    let diag = json(read("diag.out").trim());
    let reported = diagnostic_value(&diag, "spread_max");
    let max = spread.iter().copied().fold(0.0, f64::max);
    let alarm = diag["status"]
        .as_array()
        .expect("statuses")
        .iter()
        .find(|s| s["name"] == "mcgnode: spread")
        .unwrap_or_else(|| panic!("no spread status in {diag}"));
    assert_eq!(
        alarm["level"], 1,
        "spread_warn 1e-12 is passed: WARN, {alarm}"
    );
    assert!(
        (reported - max).abs() <= 1e-6 * max,
        "spread_max {reported} against the latest prediction's {max}"
    );
}
