//! The repository as a ROS 2 workspace: `colcon build --base-paths ros` (colcon
//! from PyPI, in the venv) builds the interface package `ros/mcgnode_msgs`
//! and the node package `ros/mcgnode` (an ament_cmake wrapper around cargo)
//! into fresh build, install and log folders; then, inside the private
//! network namespace, `source install/setup.bash` alone lets rclpy import
//! `mcgnode_msgs` and puts the installed `mcgnode` on PATH, which serves a
//! prediction to an rclpy subscriber.
//!
//! The workspace is this checkout, so cargo's step reuses the binary `cargo
//! test` already built (a copy elsewhere would rebuild the crate, minutes the
//! suite cannot spend); colcon's folders are new each run.
//!
//! Needs the venv (`scripts/setup_venv.sh`, which installs colcon).

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::path::Path;
use std::process::Command;
use std::time::Duration;

mod common;

use common::{in_netns, ros_env, run_bounded};

#[test]
fn colcon_builds_the_workspace_and_the_installed_node_serves() {
    // The venv and the interface build the other ROS tests use.
    let _ = ros_env();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let venv = root.join(".venv");
    assert!(
        venv.join("bin/colcon").exists(),
        "colcon is not in {}: run scripts/setup_venv.sh",
        venv.display()
    );
    let build = Command::new(venv.join("bin/colcon"))
        .current_dir(root)
        .env(
            "PATH",
            format!(
                "{}:{}",
                venv.join("bin").display(),
                std::env::var("PATH").unwrap_or_default()
            ),
        )
        .env("AMENT_PREFIX_PATH", &venv)
        .env("CMAKE_PREFIX_PATH", &venv)
        .args(["--log-base"])
        .arg(d.join("log"))
        .args(["build", "--base-paths", "ros", "--build-base"])
        .arg(d.join("build"))
        .arg("--install-base")
        .arg(d.join("install"))
        .args(["--cmake-args", "-DBUILD_TESTING=OFF"])
        .arg(format!(
            "-DPython3_EXECUTABLE={}",
            venv.join("bin/python3").display()
        ))
        .output()
        .expect("running colcon");
    let out = String::from_utf8_lossy(&build.stdout);
    assert!(
        build.status.success() && out.contains("2 packages finished"),
        "colcon build failed:\n{out}\n{}",
        String::from_utf8_lossy(&build.stderr)
    );
    assert!(d.join("install/mcgnode/bin/mcgnode").exists());
    assert!(d.join("install/setup.bash").exists());
    let bag = d.join("s.mcap");
    let sim = Command::new(env!("CARGO_BIN_EXE_mcgnode"))
        .args(["simulate", "--trajectories", "1", "--states", "5", "--out"])
        .arg(&bag)
        .output()
        .expect("simulate");
    assert!(sim.status.success());
    // Only the venv (the underlay a ROS install's setup.bash would be) and
    // the workspace's setup.bash: not build/msgs/env.sh.
    let script = r#"
        . "$VENV/bin/activate"
        export AMENT_PREFIX_PATH="$VENV"
        . "$DIR/install/setup.bash"
        set -u
        command -v mcgnode
        python3 -c 'import mcgnode_msgs.msg as m; print("imported", m.ParticleState.__name__)' || exit 2
        mcgnode serve --model truth:spring 2>"$DIR/node.log" &
        n=$!
        timeout 30 python3 scripts/ros/echo.py /mcgnode/predicted_trajectory --count 1 \
            >"$DIR/echo.out" 2>"$DIR/echo.err" &
        e=$!
        sleep 1
        timeout 30 python3 scripts/ros/play_bag.py "$BAG" --rate 10 --timeout 20 2>"$DIR/play.err" || exit 3
        wait $e; rc=$?
        kill -INT $n; wait $n; nrc=$?
        echo "echo $rc node $nrc"
        [ $rc -eq 0 ] && [ $nrc -eq 0 ]
    "#;
    let o = run_bounded(
        in_netns(script, &d.join("none.yaml"), &d.join("none.sh"))
            .env("VENV", &venv)
            .env("DIR", d)
            .env("BAG", &bag),
        Duration::from_secs(90),
        d,
    );
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let report = format!(
        "{}\n{}\n--- node\n{}\n--- echo\n{}{}\n--- play\n{}",
        o.stdout,
        o.stderr,
        read("node.log"),
        read("echo.out"),
        read("echo.err"),
        read("play.err")
    );
    assert!(o.status.success(), "{report}");
    assert!(
        o.stdout.contains(&format!(
            "{}",
            d.join("install/mcgnode/bin/mcgnode").display()
        )),
        "the installed mcgnode is not the one on PATH\n{report}"
    );
    assert!(o.stdout.contains("imported ParticleState"), "{report}");
    assert!(read("echo.out").contains("positions"), "{report}");
}
