//! Live accuracy and the drift alarm against rclpy, inside the private
//! network namespace (scripts/netns.sh): the node serves the 5-spring ground
//! truth while a bag plays a 5-spring system whose springs stiffen by 20 %
//! mid-way. The states keep reporting the nominal stiffness, as a robot's
//! state message would when the world changes beneath the model; so the
//! predictions made before the change stop matching after it.
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`).

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::fs;
use std::time::Duration;

use mcgnode::physics::{SystemConfig, SystemKind};

mod common;

use common::{driver_outcome, in_netns, ros_env, run_bounded};

/// States every 0.1 s: 3 s at stiffness 1, then 4 s at 1.2.
const BEFORE: usize = 31;
const AFTER: usize = 40;
const CHANGE_AT: f64 = 3.0;

/// The played run in two parts: [`BEFORE`] states at stiffness 1, then
/// `after` states from the last of them with the stiffness times `factor`
/// (stamps continuing, the first state of the second part being the last of
/// the first). The second part's graph says the new stiffness only when
/// `reported`; else both carry the nominal graph.
fn drift_parts(
    factor: f64,
    after: usize,
    reported: bool,
) -> (SystemConfig, [mcgnode::system::Trajectory; 2]) {
    let mut cfg = SystemConfig::new(SystemKind::Spring, 5);
    cfg.states = BEFORE;
    let graph = cfg.graph();
    let start = cfg.start_for(&graph, 11, 0);
    let traj = cfg.simulate_one(&graph, start, 0);
    let mut stiff = cfg.clone();
    stiff.stiffness *= factor;
    stiff.states = after + 1;
    let last = traj.samples.last().expect("samples").clone();
    let mut second = stiff.simulate_one(&stiff.graph(), last.state, 0);
    second.samples.remove(0);
    for s in &mut second.samples {
        s.t += last.t;
    }
    if !reported {
        second.graph = traj.graph.clone();
    }
    (cfg, [traj, second])
}

/// The played trajectory: one run, the stiffness 20 % up at [`CHANGE_AT`]
/// and `after` states after it; every state carries the nominal graph.
fn drifting_trajectory(after: usize) -> (SystemConfig, mcgnode::system::Trajectory) {
    let (cfg, [mut traj, second]) = drift_parts(1.2, after, false);
    traj.samples.extend(second.samples);
    (cfg, traj)
}

/// Writes the drifting trajectory (known field) to `dir/drift.mcap`.
fn write_bag(dir: &std::path::Path, after: usize) -> std::path::PathBuf {
    let (cfg, traj) = drifting_trajectory(after);
    assert!((traj.samples[BEFORE - 1].t - CHANGE_AT).abs() < 1e-9);
    let bag = dir.join("drift.mcap");
    mcgnode::data::write_trajectories_with_field(
        &bag,
        &[traj],
        &Default::default(),
        Some(&cfg.field),
    )
    .expect("writing the bag");
    bag
}

/// Serves with `params` in the network namespace, plays `bags` one after
/// another at their recorded pace while tests/ros/accuracy_drive.py (with `driver_args`)
/// collects `count` live-accuracy messages, then waits (bounded, 30 s) for a
/// node log line matching `wait_for` when one is given; returns the driver's
/// summary, the node log and a report (bounded by `limit_s` in all).
#[allow(clippy::too_many_arguments)]
fn play(
    dir: &std::path::Path,
    bags: &[&std::path::Path],
    params: &std::path::Path,
    env_sh: &std::path::Path,
    count: usize,
    driver_args: &str,
    wait_for: &str,
    limit_s: u64,
) -> (String, String, String) {
    let script = r#"
        set -u
        . "$ENV"
        "$BIN" serve --params "$PARAMS" 2>"$DIR/node.log" &
        node=$!
        python3 tests/ros/accuracy_drive.py --count "$COUNT" $DRIVER_ARGS >"$DIR/drive.out" \
            2>"$DIR/drive.err" &
        drive=$!
        for _ in $(seq 400); do grep -q listening "$DIR/drive.err" && break; sleep 0.05; done
        grep -q listening "$DIR/drive.err" || { echo "driver never matched"; cat "$DIR/drive.err"; exit 2; }
        for bag in $BAGS; do
            python3 scripts/ros/play_bag.py "$bag" --rate 10 --timeout 30 2>"$DIR/play.err" \
                || { cat "$DIR/play.err"; exit 3; }
        done
        wait $drive; rc=$?
        cat "$DIR/drive.out"
        if [ -n "$WAIT_FOR" ]; then
            for _ in $(seq 300); do grep -qE "$WAIT_FOR" "$DIR/node.log" && break; sleep 0.1; done
        fi
        kill -INT $node; wait $node; node_rc=$?
        [ $rc -eq 0 ] && [ $node_rc -eq 0 ]
    "#;
    let o = run_bounded(
        in_netns(script, params, env_sh)
            .env("DIR", dir)
            .env(
                "BAGS",
                bags.iter()
                    .map(|b| b.display().to_string())
                    .collect::<Vec<_>>()
                    .join(" "),
            )
            .env("COUNT", count.to_string())
            .env("DRIVER_ARGS", driver_args)
            .env("WAIT_FOR", wait_for),
        Duration::from_secs(limit_s),
        dir,
    );
    driver_outcome(&o, &dir.join("node.log"), "ACCURACY_SUMMARY ")
}

#[test]
fn drift_alarm_follows_a_stiffness_change() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let bag = write_bag(dir.path(), AFTER);
    // Predictions every 0.1 s over 1 s, integrated with the simulator's step.
    let params = dir.path().join("params.yaml");
    fs::write(
        &params,
        "mcgnode:\n  ros__parameters:\n    model: truth:spring\n    dt: 0.1\n    substeps: 100\n    \
         horizon: 10\n    diagnostics_period: 0.2\n    accuracy_lead_times: [0.1, 0.5, 1.0]\n    \
         accuracy_window: 3\n    accuracy_warn_re: 1.0e-3\n    accuracy_error_re: 5.0e-3\n",
    )
    .expect("writing params");
    // Every state after the first is compared with a prediction; played at
    // the recorded pace (states 0.1 s apart), so stamps and wall time agree.
    let compared = BEFORE + AFTER - 1;
    let (summary, node_log, report) = play(
        dir.path(),
        &[&bag],
        &params,
        &env_sh,
        compared,
        "--timeout 60",
        "",
        150,
    );
    let s: serde_json::Value = serde_json::from_str(&summary).expect("ACCURACY_SUMMARY is JSON");
    let live = s["live"].as_array().expect("live");
    assert_eq!(live.len(), compared, "{report}");
    let num = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    // Before the change: every running RE tiny, no alarm.
    let before: Vec<&serde_json::Value> = live
        .iter()
        .filter(|m| num(m, "stamp") <= CHANGE_AT + 1e-6)
        .collect();
    assert_eq!(before.len(), BEFORE - 1, "{report}");
    for m in &before {
        assert_eq!(m["level"], 0, "alarm before the change: {m}\n{report}");
    }
    let worst_before = before
        .iter()
        .flat_map(|m| m["re_mean"].as_array().cloned().unwrap_or_default())
        .filter_map(|x| x.as_f64())
        .fold(0.0, f64::max);
    // The first alarm, by the compared state's stamp: within 2 s of the change.
    let first = live
        .iter()
        .find(|m| m["level"].as_u64().unwrap_or(0) >= 1)
        .unwrap_or_else(|| panic!("no drift alarm at all\n{report}"));
    let after_change = num(first, "stamp") - CHANGE_AT;
    println!(
        "worst running RE before the change {worst_before:.2e}; first alarm {after_change:.1} s \
         after it (level {}): {}",
        first["level"], first["message"]
    );
    assert!(
        after_change > 0.0 && after_change <= 2.0 + 1e-6,
        "alarm {after_change} s after the change\n{report}"
    );
    assert!(
        first["message"].as_str().unwrap_or("").contains("lead"),
        "{first}"
    );
    // EE is reported: the bag's field is known.
    assert!(first["ee_mean"][0].as_f64().is_some(), "{first}");
    // On /diagnostics too, within 2 s of wall time after the first changed
    // state was scored, and not before it.
    let t_change = live
        .iter()
        .find(|m| num(m, "stamp") > CHANGE_AT + 1e-6)
        .map(|m| num(m, "t"))
        .expect("a state after the change");
    let diags = s["diagnostics"].as_array().expect("diagnostics");
    let first_diag = diags
        .iter()
        .find(|d| d["level"].as_u64().unwrap_or(0) >= 1)
        .unwrap_or_else(|| panic!("no alarm on /diagnostics\n{report}"));
    let late = num(first_diag, "t") - t_change;
    println!(
        "/diagnostics alarm {late:.2} s (wall) after the first changed state was scored: {}",
        first_diag["message"]
    );
    assert!(late > -0.2 && late <= 2.0, "{late} s\n{report}");
    assert!(
        first_diag["message"]
            .as_str()
            .unwrap_or("")
            .contains("lead")
            && first_diag["values"]["re_mean@1s"].is_string(),
        "{first_diag}"
    );
    assert!(node_log.contains("drift: running RE at lead"), "{report}");
    // Later, as the error grows, the alarm turns to ERROR.
    let last = live.last().expect("messages");
    println!(
        "at the end ({:.1} s): running RE {} at leads {}, EE {}; level {}",
        num(last, "stamp"),
        last["re_mean"],
        last["lead_times"],
        last["ee_mean"],
        last["level"]
    );
    let first_error = live
        .iter()
        .find(|m| m["level"] == 2)
        .map(|m| num(m, "stamp") - CHANGE_AT);
    println!("first ERROR {first_error:?} s after the change");
    assert!(first_error.is_some(), "{report}");
}

/// With `accuracy_retrain`, the alarm starts a warm-start retraining of the
/// served model (the shipped 5-spring MCGNODE) on what the node records in
/// the next seconds; the new model is swapped in only if it beats the old one
/// on the last (held-out) recording.
#[test]
fn drift_alarm_starts_a_warm_start_retraining() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let after = 120;
    let bag = write_bag(dir.path(), after);
    // States from 0.5 s on are compared (the shortest lead).
    let params = dir.path().join("params.yaml");
    // Thresholds from this model's running RE at lead 1 s: 1.5-2.6e-3 before
    // the change, 1-2e-2 after it.
    fs::write(
        &params,
        format!(
            "mcgnode:\n  ros__parameters:\n    model: bags/models/spring5-mcgnode.json\n    \
             dt: 0.1\n    substeps: 100\n    horizon: 10\n    diagnostics_period: 0.2\n    \
             accuracy_lead_times: [0.5, 1.0]\n    accuracy_window: 3\n    \
             accuracy_warn_re: 5.0e-3\n    accuracy_error_re: 1.0e-2\n    \
             accuracy_retrain: true\n    accuracy_retrain_after: 6.0\n    \
             accuracy_retrain_epochs: 3000\n    record_dir: {:?}\n    \
             record_split_seconds: 1.0\n    model_dir: {:?}\n",
            dir.path().join("rec").display(),
            dir.path().join("models").display()
        ),
    )
    .expect("writing params");
    let compared = BEFORE + after - 5;
    // The retraining decides within the playback; wait (bounded) for its verdict.
    let (summary, node_log, report) = play(
        dir.path(),
        &[&bag],
        &params,
        &env_sh,
        compared,
        "--timeout 90 --linger 1",
        "drift retraining: (swapped|kept)",
        200,
    );
    let s: serde_json::Value = serde_json::from_str(&summary).expect("ACCURACY_SUMMARY is JSON");
    let live = s["live"].as_array().expect("live");
    let num = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    let first = live
        .iter()
        .find(|m| m["level"].as_u64().unwrap_or(0) >= 1)
        .unwrap_or_else(|| panic!("no drift alarm\n{report}"));
    let alarm_at = num(first, "stamp");
    println!(
        "alarm at {:.1} s (change at {CHANGE_AT} s): {}",
        alarm_at, first["message"]
    );
    assert!(
        alarm_at > CHANGE_AT && alarm_at <= CHANGE_AT + 2.0,
        "{report}"
    );
    assert!(node_log.contains("drift retraining after"), "{report}");
    let verdict = node_log
        .lines()
        .find(|l| l.contains("drift retraining: swapped") || l.contains("drift retraining: kept"))
        .unwrap_or_else(|| panic!("no retraining verdict\n{report}"));
    println!("{verdict}");
    assert!(
        verdict.contains("held-out RE") && !verdict.contains("failed"),
        "{report}"
    );
    let swapped = verdict.contains("swapped in");
    if swapped {
        assert!(node_log.contains("model swapped"), "{report}");
    }
    // The running RE at the longest lead over the last second, against the
    // second before the alarm: what the swap (or keeping the model) gave.
    let mean_re = |from: f64, to: f64| {
        let xs: Vec<f64> = live
            .iter()
            .filter(|m| (from..to).contains(&num(m, "stamp")))
            .filter_map(|m| m["re"].as_array()?.last()?.as_f64())
            .collect();
        xs.iter().sum::<f64>() / xs.len().max(1) as f64
    };
    let end = num(live.last().expect("messages"), "stamp");
    println!(
        "RE at lead 1 s: {:.2e} in the second before the change, {:.2e} in the last second \
         (swapped: {swapped})",
        mean_re(CHANGE_AT - 1.0, CHANGE_AT),
        mean_re(end - 1.0, end + 0.01)
    );
}

/// The spread alarm against the error alarm, with an ensemble (3 members,
/// `--edge-physics`, so it reads each spring's stiffness) trained on
/// stiffness 1: the springs stiffen by 30 % after 3 s, and the states say
/// so (their graph carries the new stiffness, as a robot's state would
/// when it knows what it picked up). The members disagree on the first
/// state outside their training, before the error of any prediction can be
/// observed; the error alarm follows. Nothing is raised before the change.
/// With `spread_retrain`, the spread alarm starts a retraining that keeps
/// the ensemble.
#[test]
fn spread_alarm_comes_before_the_error_alarm() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    use common::cli::{mcgnode as cli, ok};
    ok(&cli(
        &[
            "simulate",
            "--system",
            "spring",
            "--particles",
            "5",
            "--trajectories",
            "10",
            "--seed",
            "1",
            "--out",
            "train.mcap",
        ],
        d,
    ));
    ok(&cli(
        &[
            "train",
            "--model",
            "mcgnode",
            "--edge-physics",
            "--ensemble",
            "3",
            "--epochs",
            "300",
            "--data",
            "train.mcap",
            "--out",
            "ensemble.json",
            "--quiet",
        ],
        d,
    ));
    let (cfg, parts) = drift_parts(1.3, AFTER, true);
    let bags: Vec<std::path::PathBuf> = parts
        .iter()
        .zip(["before.mcap", "after.mcap"])
        .map(|(t, name)| {
            let bag = d.join(name);
            mcgnode::data::write_trajectories_with_field(
                &bag,
                std::slice::from_ref(t),
                &Default::default(),
                Some(&cfg.field),
            )
            .expect("writing a bag");
            bag
        })
        .collect();
    // Between this ensemble's spreads along the 1 s horizon in range (at
    // most 5.3e-3 in a run) and at 1.3x (4.4-6.9e-2).
    let spread_warn = 1.2e-2;
    let params = d.join("params.yaml");
    fs::write(
        &params,
        format!(
            "mcgnode:\n  ros__parameters:\n    model: {:?}\n    dt: 0.1\n    substeps: 100\n    \
             horizon: 10\n    diagnostics_period: 0.2\n    accuracy_lead_times: [0.1, 0.5, 1.0]\n    \
             accuracy_window: 3\n    accuracy_warn_re: 1.0e-2\n    accuracy_error_re: 5.0e-2\n    \
             spread_warn: {spread_warn}\n    spread_retrain: true\n    accuracy_retrain_after: 2.0\n    \
             accuracy_retrain_epochs: 20\n    record_dir: {:?}\n    record_split_seconds: 0.5\n    \
             model_dir: {:?}\n",
            d.join("ensemble.json").display(),
            d.join("rec").display(),
            d.join("models").display()
        ),
    )
    .expect("writing params");
    // The first state with the new graph starts live accuracy over (the
    // predictions before it were for another system): it is not compared.
    let compared = BEFORE + AFTER - 2;
    let bag_refs: Vec<&std::path::Path> = bags.iter().map(std::path::PathBuf::as_path).collect();
    let (summary, node_log, report) = play(
        d,
        &bag_refs,
        &params,
        &env_sh,
        compared,
        "--timeout 90 --predictions",
        "drift retraining: (swapped|kept)",
        200,
    );
    let s: serde_json::Value = serde_json::from_str(&summary).expect("ACCURACY_SUMMARY is JSON");
    let num = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    let predictions = s["predictions"].as_array().expect("predictions");
    let live = s["live"].as_array().expect("live");
    let in_range = |m: &&serde_json::Value| num(m, "stamp") <= CHANGE_AT + 1e-6;
    let spread_before = predictions
        .iter()
        .filter(in_range)
        .map(|m| num(m, "spread_max"))
        .fold(0.0, f64::max);
    let re_before = live
        .iter()
        .filter(in_range)
        .flat_map(|m| m["re_mean"].as_array().cloned().unwrap_or_default())
        .filter_map(|x| x.as_f64())
        .fold(0.0, f64::max);
    println!("in range: largest spread {spread_before:.2e}, largest running RE {re_before:.2e}");
    assert!(
        predictions.iter().filter(in_range).count() >= BEFORE - 1,
        "{report}"
    );
    assert!(
        spread_before < spread_warn,
        "a spread alarm in range\n{report}"
    );
    assert!(
        live.iter().filter(in_range).all(|m| m["level"] == 0),
        "an error alarm in range\n{report}"
    );
    let spread_at = predictions
        .iter()
        .find(|m| num(m, "spread_max") > spread_warn)
        .map(|m| num(m, "stamp"))
        .unwrap_or_else(|| panic!("the spread never passed {spread_warn}\n{report}"));
    let error_at = live
        .iter()
        .find(|m| m["level"].as_u64().unwrap_or(0) >= 1)
        .map(|m| num(m, "stamp"))
        .unwrap_or_else(|| panic!("no error alarm\n{report}"));
    println!(
        "change at {CHANGE_AT} s: spread alarm at {spread_at:.1} s, error alarm at {error_at:.1} s \
         ({:.1} s later)",
        error_at - spread_at
    );
    assert!(spread_at > CHANGE_AT, "{report}");
    assert!(
        error_at - spread_at >= 0.5 - 1e-6,
        "the spread alarm came {:.2} s before the error alarm\n{report}",
        error_at - spread_at
    );
    // On /diagnostics and in the log, and the retraining it started.
    let spread_diags = s["spread_diagnostics"].as_array().expect("spread statuses");
    assert!(
        spread_diags.iter().any(|m| m["level"] == 1),
        "no WARN of `mcgnode: spread`\n{report}"
    );
    assert!(
        node_log.lines().any(
            |l| l.contains("spread alarm on stream ") && l.contains(": the ensemble disagrees")
        ),
        "{report}"
    );
    assert!(
        node_log.contains("drift retraining after \"spread alarm"),
        "{report}"
    );
    let verdict = node_log
        .lines()
        .find(|l| l.contains("drift retraining: swapped") || l.contains("drift retraining: kept"))
        .unwrap_or_else(|| panic!("no retraining verdict\n{report}"));
    println!("{verdict}");
    if verdict.contains("swapped in") {
        let path = verdict
            .split("swapped in ")
            .nth(1)
            .and_then(|r| r.split(':').next())
            .expect("the swapped file");
        let file: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(path).expect("the retrained file"))
                .expect("JSON");
        assert_eq!(
            file["members"].as_array().map(Vec::len),
            Some(2),
            "the retrained model is still an ensemble of 3"
        );
    }
}
