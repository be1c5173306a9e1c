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

use common::fleet::DRIVE_AND_STOP;
use common::{in_netns, ros_env, run_bounded};

#[test]
fn namespaced_nodes_on_one_domain_do_not_cross() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let params = d.join("unused.yaml");
    fs::write(&params, "mcgnode:\n  ros__parameters:\n    dt: 0.01\n").expect("params");
    let script = format!(
        r#"
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
        "$BIN" serve --model truth:spring --params "$PARAMS" --ros-args -r __node:=dyn3 \
            -r particle_state:=/tracker/state -p horizon:=20 --log-level warn 2>"$DIR/dyn3.log" &
        n3=$!
        "$BIN" serve --model truth:spring --params-file-is-not-a-flag 2>"$DIR/bad.log" \
            && exit 5
        {DRIVE_AND_STOP}
    "#
    );
    let o = run_bounded(
        in_netns(&script, &params, &env_sh).env("DIR", d),
        Duration::from_secs(240),
        d,
    );
    let report = common::fleet::check(&o, d);
    let bad = fs::read_to_string(d.join("bad.log")).unwrap_or_default();
    assert!(bad.contains("--params-file-is-not-a-flag"), "{report}");
}
