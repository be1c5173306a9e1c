//! Position-only, uneven and gapped input streams against rclpy, inside the
//! private network namespace (scripts/netns.sh): the node serves the shipped
//! 5-spring MCGNODE while three recordings of one ground-truth motion are
//! played into it at their recorded pace, one after the other (each starting
//! again at stamp 0, so each is a new run of trajectory 0):
//!
//! 1. full states at 100 Hz;
//! 2. the same states, positions only (velocities empty);
//! 3. positions only from a 1 kHz simulation, thinned to about 100 Hz with
//!    uneven steps (±30 %) and 5 % of the states dropped.
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`).

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::fs;
use std::time::Duration;

use mcgnode::data::observe::{observe, Observation};
use mcgnode::physics::{SystemConfig, SystemKind};
use mcgnode::system::Trajectory;

mod common;

use common::{beside_node, driver_outcome, in_netns, ros_env, run_bounded};

/// 3 s of a 5-spring ring sampled every `save_every` ms.
fn truth(save_every: usize) -> (SystemConfig, Trajectory) {
    let mut cfg = SystemConfig::new(SystemKind::Spring, 5);
    cfg.save_every = save_every;
    cfg.states = 3000 / save_every + 1;
    let graph = cfg.graph();
    let start = cfg.start_for(&graph, 21, 0);
    let tr = cfg.simulate_one(&graph, start, 0);
    (cfg, tr)
}

/// The summary's LiveAccuracy messages cut into runs: a run starts where the
/// shortest lead's comparison count falls.
fn runs(live: &[serde_json::Value]) -> Vec<Vec<&serde_json::Value>> {
    let mut out: Vec<Vec<&serde_json::Value>> = Vec::new();
    let mut last = u64::MAX;
    for m in live {
        let c = m["compared"][0].as_u64().unwrap_or(0);
        if out.is_empty() || c < last {
            out.push(Vec::new());
        }
        last = c;
        out.last_mut().expect("a run").push(m);
    }
    out
}

#[test]
fn position_only_uneven_and_gapped_streams_are_predicted() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let (cfg, full) = truth(10);
    let meta = Default::default();
    mcgnode::data::write_trajectories_with_field(
        d.join("full.mcap"),
        std::slice::from_ref(&full),
        &meta,
        Some(&cfg.field),
    )
    .expect("writing the full bag");
    mcgnode::data::write_positions_only(
        d.join("positions.mcap"),
        std::slice::from_ref(&full),
        &meta,
        Some(&cfg.field),
    )
    .expect("writing the position-only bag");
    let (_, fine) = truth(1);
    let o = Observation {
        thin: 10,
        uneven: 0.3,
        drop: 0.05,
        seed: 5,
        ..Observation::default()
    };
    let (uneven, _) = observe(&[fine], &o).expect("observing");
    let uneven_states = uneven[0].samples.len();
    mcgnode::data::write_positions_only(d.join("uneven.mcap"), &uneven, &meta, Some(&cfg.field))
        .expect("writing the uneven bag");
    let params = d.join("params.yaml");
    fs::write(
        &params,
        "mcgnode:\n  ros__parameters:\n    model: bags/models/spring5-mcgnode.json\n    \
         dt: 0.01\n    substeps: 10\n    horizon: 100\n    diagnostics_period: 0.2\n    \
         qos_depth: 1000\n    accuracy_lead_times: [0.1, 1.0]\n    accuracy_window: 100000\n    \
         accuracy_max_pending: 100000\n    input_max_gap: 0.5\n",
    )
    .expect("writing params");
    let driver = r#"
        python3 tests/ros/stream_drive.py --stop "$DIR/stop" --timeout 120 >"$DIR/drive.out" \
            2>"$DIR/drive.err" &
        drive=$!
        for _ in $(seq 400); do grep -q listening "$DIR/drive.err" && break; sleep 0.05; done
        grep -q listening "$DIR/drive.err" || { echo "driver never matched"; cat "$DIR/drive.err"; exit 2; }
        for b in full positions uneven; do
            python3 scripts/ros/play_bag.py "$DIR/$b.mcap" --timeout 30 --settle 0.5 \
                2>"$DIR/play-$b.err" || { cat "$DIR/play-$b.err"; exit 3; }
            sleep 1.2
        done
        touch "$DIR/stop"
        wait $drive; rc=$?
        cat "$DIR/drive.out"
        exit $rc
    "#;
    let log = d.join("node.log");
    let o = run_bounded(
        in_netns(&beside_node(driver), &params, &env_sh)
            .env("DIR", d)
            .env("LOG", &log),
        Duration::from_secs(150),
        d,
    );
    let (summary, node_log, report) = driver_outcome(&o, &log, "STREAM_SUMMARY ");
    let s: serde_json::Value = serde_json::from_str(&summary).expect("STREAM_SUMMARY is JSON");
    let num = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let n = full.samples.len() as u64;

    // Nothing rejected, nothing non-finite; every position-only state either
    // warmed its stream up or was predicted from estimated velocities.
    let diag = &s["diagnostics"];
    println!("diagnostics: {diag}");
    let count = |k: &str| diag[k].as_u64().unwrap_or(u64::MAX);
    assert_eq!(count("rejected"), 0, "{report}");
    assert_eq!(s["non_finite"], 0, "{report}");
    assert_eq!(count("received"), 2 * n + uneven_states as u64, "{report}");
    assert_eq!(
        count("warming_up"),
        4,
        "two states per position-only run\n{report}"
    );
    assert_eq!(
        count("derived"),
        n - 2 + uneven_states as u64 - 2,
        "{report}"
    );
    assert_eq!(
        count("predicted"),
        count("received") - count("warming_up"),
        "{report}"
    );
    // Runs 2 and 3 each start over (a stamp before the previous one).
    assert_eq!(count("history_resets"), 2, "{report}");
    assert!(node_log.contains("input stream 0 starts over"), "{report}");

    // The velocities the node estimated for the first predicted position-only
    // state (stamp 0.02 s) against the simulator's.
    let initial = s["initial"].as_array().expect("initial");
    let first_b = initial
        .windows(2)
        .find(|w| num(&w[1]["stamp"]) < num(&w[0]["stamp"]))
        .map(|w| &w[1])
        .unwrap_or_else(|| panic!("no second run\n{report}"));
    assert!((num(&first_b["stamp"]) - 0.02).abs() < 1e-9, "{first_b}");
    let v_true = &full.samples[2].state.v;
    let v_node: Vec<f64> = first_b["velocities"]
        .as_array()
        .expect("velocities")
        .iter()
        .flat_map(|v| [num(&v[0]), num(&v[1])])
        .collect();
    let scale = v_true.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let worst = v_node
        .iter()
        .zip(v_true)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    println!("estimated velocities at 0.02 s: worst error {worst:.2e} of {scale:.2e}");
    assert!(worst < 0.01 * scale, "{v_node:?} vs {v_true:?}");

    // Live accuracy: three runs, each from nothing; a lead reports only once
    // its run has reached it.
    let live = s["live"].as_array().expect("live");
    let runs = runs(live);
    assert_eq!(runs.len(), 3, "{report}");
    for (k, run) in runs.iter().enumerate() {
        let first = run[0];
        assert!(
            first["compared"][0].as_u64() <= Some(2) && first["compared"][1] == 0,
            "run {k} starts with another run's comparisons: {first}"
        );
        assert!(first["re"][1].is_null(), "run {k}: {first}");
        for m in run {
            assert!(num(&m["stamp"]) >= 0.1 - 1e-6, "run {k}: {m}");
            if m["compared"][1].as_u64() > Some(0) {
                assert!(
                    num(&m["stamp"]) >= 1.0 - 0.01,
                    "run {k} lead 1 s too early: {m}"
                );
            }
        }
    }
    let final_re = |run: &[&serde_json::Value], lead: usize| {
        let last = run.last().expect("messages");
        (
            num(&last["re_mean"][lead]),
            last["compared"][lead].as_u64().unwrap_or(0),
        )
    };
    let (re_full, c_full) = final_re(&runs[0], 1);
    let (re_pos, c_pos) = final_re(&runs[1], 1);
    let (re_uneven, c_uneven) = final_re(&runs[2], 1);
    println!(
        "mean RE at lead 1 s: full states {re_full:.3e} ({c_full} comparisons), positions only \
         {re_pos:.3e} ({c_pos}), uneven and gapped {re_uneven:.3e} ({c_uneven})"
    );
    assert!(c_full > 150 && c_pos > 150 && c_uneven > 20, "{report}");
    // The model is good (far below what standing still costs at 1 s, ~1e-1).
    assert!(re_full.is_finite() && re_full < 1e-2, "{report}");
    assert!(re_pos <= 2.0 * re_full, "{re_pos} vs {re_full}");
    assert!(
        re_uneven.is_finite() && re_uneven < 10.0 * re_full,
        "{report}"
    );
}
