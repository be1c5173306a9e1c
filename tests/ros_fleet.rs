//! A fleet on one DDS domain, against rclpy, inside the private network
//! namespace (scripts/netns.sh): three nodes started with `--ros-args`, two
//! in namespaces `/robot1` and `/robot2` serving different models and a third
//! renamed (`-r __node:=dyn3`) with its input remapped
//! (`-r particle_state:=/tracker/state`). tests/ros/fleet_drive.py publishes
//! to each, collects each one's predictions, calls each one's Rollout and
//! (robot1, robot2) Train, and checks that nothing crosses.
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`).

use std::fs;
use std::time::Duration;

mod common;

use common::{in_netns, ros_env, run_bounded};

#[test]
fn namespaced_nodes_on_one_domain_do_not_cross() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let params = d.join("unused.yaml");
    fs::write(&params, "mcgnode:\n  ros__parameters:\n    dt: 0.01\n").expect("params");
    let script = r#"
        set -u
        . "$ENV"
        "$BIN" simulate --trajectories 4 --states 50 --seed 3 --out "$DIR/train.mcap" 2>/dev/null \
            || exit 4
        "$BIN" serve --model truth:spring --set dt=0.01 \
            --ros-args -r __ns:=/robot1 -p horizon:=20 2>"$DIR/robot1.log" &
        n1=$!
        "$BIN" serve --model bags/models/spring5-mcgnode.json --set dt=0.01 \
            --ros-args -r __ns:=/robot2 -p horizon:=20 2>"$DIR/robot2.log" &
        n2=$!
        "$BIN" serve --model truth:spring --params-file-is-not-a-flag 2>"$DIR/bad.log"; bad=$?
        "$BIN" serve --model truth:spring --params "$PARAMS" --ros-args -r __node:=dyn3 \
            -r particle_state:=/tracker/state -p horizon:=20 --log-level warn 2>"$DIR/dyn3.log" &
        n3=$!
        python3 tests/ros/fleet_drive.py --state-bag "$DIR/train.mcap" \
            --train-bag "$DIR/train.mcap"; rc=$?
        kill -INT $n1 $n2 $n3
        wait $n1; r1=$?; wait $n2; r2=$?; wait $n3; r3=$?
        echo "exit codes: driver $rc, nodes $r1 $r2 $r3, bad flag $bad"
        [ $rc -eq 0 ] && [ $r1 -eq 0 ] && [ $r2 -eq 0 ] && [ $r3 -eq 0 ] && [ $bad -ne 0 ]
    "#;
    let o = run_bounded(
        in_netns(script, &params, &env_sh).env("DIR", d),
        Duration::from_secs(240),
        d,
    );
    let log = |name: &str| fs::read_to_string(d.join(format!("{name}.log"))).unwrap_or_default();
    let report = format!(
        "--- status {}\n--- stdout\n{}\n--- stderr\n{}\n--- robot1\n{}\n--- robot2\n{}\n--- dyn3\n{}",
        o.status,
        o.stdout,
        o.stderr,
        log("robot1"),
        log("robot2"),
        log("dyn3")
    );
    assert!(o.status.success(), "{report}");
    let summary = o
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix("FLEET_SUMMARY "))
        .unwrap_or_else(|| panic!("no FLEET_SUMMARY\n{report}"));
    println!("{summary}");
    let s: serde_json::Value = serde_json::from_str(summary).expect("JSON");
    assert_eq!(s["predictions"]["robot1"], 3, "{report}");
    assert_eq!(s["predictions"]["robot2"], 5, "{report}");
    assert_eq!(s["predictions"]["dyn3"], 2, "{report}");
    assert_eq!(s["swaps"]["dyn3"], 0, "{report}");
    // Each node says where it serves, with the names resolved.
    assert!(
        log("robot1").contains("/robot1/particle_state -> /robot1/mcgnode/predicted_trajectory"),
        "{report}"
    );
    assert!(
        log("robot2").contains("services /robot2/mcgnode/train"),
        "{report}"
    );
    // dyn3 logs at warn and above only: no INFO line.
    assert!(!log("dyn3").contains("[INFO]"), "{report}");
    assert!(
        log("bad").contains("--params-file-is-not-a-flag"),
        "{report}"
    );
}
