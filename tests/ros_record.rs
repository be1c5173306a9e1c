//! A recording node killed with SIGKILL: `mcgnode serve` records while rclpy
//! publishes 300 states at 100 Hz (inside scripts/netns.sh), is killed right
//! after the last one, and its unrepaired bag is read by `rosbags`, the `mcap`
//! streaming reader and our own reader. At most `record_flush_seconds` x rate
//! states (plus slack for what was still in flight) may be lost.

use std::fs;
use std::path::Path;
use std::time::Duration;

mod common;

use common::{in_netns, ros_env, run_bounded};
use mcgnode::data::{scan_bag, ParticleState};

const STATES: usize = 300;
const RATE: f64 = 100.0;
const FLUSH_SECONDS: f64 = 0.25;

#[test]
fn a_killed_recorder_leaves_a_bag_every_reader_reads() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("rec");
    let params = dir.path().join("params.yaml");
    fs::write(
        &params,
        format!(
            "mcgnode:\n  ros__parameters:\n    model: truth:spring\n    horizon: 25\n    \
             dt: 0.001\n    record_dir: {:?}\n    record_flush_seconds: {FLUSH_SECONDS}\n",
            rec.display()
        ),
    )
    .expect("writing params");
    let log = dir.path().join("node.log");
    let script = format!(
        r#"
        set -u
        . "$ENV"
        "$BIN" serve --params "$PARAMS" 2>"$LOG" &
        node=$!
        timeout 60 python3 tests/ros/kill_record.py publish --states {STATES} --rate {RATE} || exit 1
        kill -KILL $node
        wait $node
        echo "node killed: $?"
        "#
    );
    let o = run_bounded(
        in_netns(&script, &params, &env_sh).env("LOG", &log),
        Duration::from_secs(120),
        dir.path(),
    );
    let node_log = fs::read_to_string(&log).unwrap_or_default();
    let report = format!(
        "--- stdout\n{}\n--- stderr\n{}\n--- node log\n{node_log}",
        o.stdout, o.stderr
    );
    assert!(
        o.stdout.contains(&format!("PUBLISHED {STATES}")) && o.stdout.contains("node killed: 137"),
        "the run did not publish and kill\n{report}"
    );
    assert!(!node_log.contains("shutting down"), "not killed\n{report}");

    let (via_rosbags, via_mcap) = python_steps(&rec, dir.path(), &report);
    let ours = our_steps(&rec, &report);
    let slack = 10;
    let allowed = (FLUSH_SECONDS * RATE) as usize + slack;
    println!(
        "recorded states read back after SIGKILL: ours {}, rosbags {}, mcap {} of {STATES}",
        ours.len(),
        via_rosbags.len(),
        via_mcap.len()
    );
    assert_eq!(via_rosbags, ours, "rosbags and our reader disagree");
    assert_eq!(via_mcap, ours, "mcap and our reader disagree");
    assert!(
        ours.iter().enumerate().all(|(i, s)| *s as usize == i),
        "not the first states in order: {ours:?}"
    );
    assert!(
        STATES - ours.len() <= allowed,
        "lost {} of {STATES} states, more than {allowed}\n{report}",
        STATES - ours.len()
    );
}

/// The ParticleState steps `rosbags` and the `mcap` streaming reader find in
/// the bags of `rec`, as the kill left them.
fn python_steps(rec: &Path, tmp: &Path, report: &str) -> (Vec<u32>, Vec<u32>) {
    let py = run_bounded(
        std::process::Command::new(".venv/bin/python3")
            .args(["tests/ros/kill_record.py", "read"])
            .arg(rec),
        Duration::from_secs(60),
        tmp,
    );
    let line = py
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix("READ "))
        .unwrap_or_else(|| panic!("no READ line\n{}\n{}\n{report}", py.stdout, py.stderr));
    let steps = |key: &str| -> Vec<u32> {
        let at = line.find(&format!("\"{key}\": [")).expect(key) + key.len() + 5;
        let list = &line[at..at + line[at..].find(']').expect("]")];
        list.split(", ")
            .filter(|s| !s.is_empty())
            .map(|s| s.parse().expect("a step"))
            .collect()
    };
    (steps("rosbags"), steps("mcap"))
}

/// The ParticleState steps our reader finds (every CRC, the footer and the
/// end magic checked).
fn our_steps(rec: &Path, report: &str) -> Vec<u32> {
    let mut ours = Vec::new();
    let mut bags: Vec<_> = fs::read_dir(rec)
        .expect("record_dir")
        .map(|e| e.expect("entry").path())
        .collect();
    bags.sort();
    for bag in &bags {
        scan_bag(bag, |m| {
            if m.schema_name.ends_with("ParticleState") {
                ours.push(ParticleState::from_cdr(m.data)?.step);
            }
            Ok(())
        })
        .unwrap_or_else(|e| panic!("our reader: {e}\n{report}"));
    }
    ours
}
