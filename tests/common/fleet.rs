//! The fleet scenario's checks (tests/ros/fleet_drive.py beside three nodes:
//! `/robot1` on truth:spring, `/robot2` on the shipped 5-spring MCGNODE, and
//! `dyn3` renamed with its input remapped to `/tracker/state`), shared by the
//! fleet started with `mcgnode serve` (tests/ros_fleet.rs) and the one started
//! as `ros2 run` and `ros2 launch` start it (tests/colcon.rs).

use std::fs;
use std::path::Path;

use super::Outcome;

/// The shell that runs the driver, stops nodes `$n1 $n2 $n3` and succeeds when
/// all four exited 0. Expects `$DIR/train.mcap`.
pub const DRIVE_AND_STOP: &str = r#"
        python3 tests/ros/fleet_drive.py --state-bag "$DIR/train.mcap" \
            --train-bag "$DIR/train.mcap"; rc=$?
        kill -INT $n1 $n2 $n3
        wait $n1; r1=$?; wait $n2; r2=$?; wait $n3; r3=$?
        echo "exit codes: driver $rc, nodes $r1 $r2 $r3"
        [ $rc -eq 0 ] && [ $r1 -eq 0 ] && [ $r2 -eq 0 ] && [ $r3 -eq 0 ]
"#;

/// Asserts that each node served its own predictions and nothing crossed;
/// the nodes' logs are `DIR/{robot1,robot2,dyn3}.log`. Returns the report.
pub fn check(o: &Outcome, d: &Path) -> String {
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
    report
}
