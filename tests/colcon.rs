//! The repository as a ROS 2 workspace: `colcon build --base-paths ros` (colcon
//! from PyPI, in the venv) builds the interface package `ros/mcgnode_msgs`
//! and the node package `ros/mcgnode` (an ament_cmake wrapper around cargo)
//! into fresh build, install and log folders, once per run of this file.
//! Then, inside the private network namespace:
//! - `source install/setup.bash` alone lets rclpy import `mcgnode_msgs` and
//!   puts the installed `mcgnode` on PATH, which serves a prediction;
//! - the fleet scenario (tests/common/fleet.rs) runs with nodes started as
//!   `ros2 run mcgnode mcgnode --ros-args …` starts them (the installed
//!   `lib/mcgnode/mcgnode`, no subcommand) and from the installed
//!   `share/mcgnode/launch/mcgnode.launch.py`. `ros2 launch` itself is not on
//!   PyPI, so the launch file is evaluated by tests/ros/launch_cmd.py with
//!   stand-ins that build the command line as launch_ros does
//!   (tests/ros/launch_stub/README.md).
//!
//! The workspace is this checkout, so cargo's step reuses the binary `cargo
//! test` already built (a copy elsewhere would rebuild the crate, minutes the
//! suite cannot spend).
//!
//! Needs the venv (`scripts/setup_venv.sh`, which installs colcon).

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Duration;

mod common;

use common::fleet::DRIVE_AND_STOP;
use common::{in_netns, ros_env, run_bounded, ROOT};

/// The colcon workspace's folders, built once for this file's tests, in
/// cargo's folder for tests' files (one copy, replaced by each run: a temp
/// dir held by a static would never be removed).
fn install() -> &'static Path {
    static INSTALL: OnceLock<PathBuf> = OnceLock::new();
    INSTALL.get_or_init(build_workspace)
}

fn build_workspace() -> PathBuf {
    // The venv and the interface build the other ROS tests use.
    let _ = ros_env();
    let root = Path::new(ROOT);
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("colcon");
    if d.exists() {
        fs::remove_dir_all(&d).expect("removing the last run's colcon folders");
    }
    fs::create_dir_all(&d).expect("colcon folder");
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
    d
}

/// Runs `script` in the network namespace with the venv and the workspace's
/// setup.bash sourced (not build/msgs/env.sh), `$INSTALL` the colcon install,
/// `$DIR` a folder for logs.
fn in_workspace(script: &str, d: &Path, limit: Duration) -> common::Outcome {
    let prelude = r#"
        . "$VENV/bin/activate"
        export AMENT_PREFIX_PATH="$VENV"
        . "$INSTALL/setup.bash"
        set -u
    "#;
    run_bounded(
        in_netns(
            &format!("{prelude}{script}"),
            &d.join("none.yaml"),
            &d.join("none.sh"),
        )
        .env("VENV", Path::new(ROOT).join(".venv"))
        .env("INSTALL", install().join("install"))
        .env("DIR", d),
        limit,
        d,
    )
}

#[test]
fn colcon_builds_the_workspace_and_the_installed_node_serves() {
    let ws = install();
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    assert!(ws.join("install/mcgnode/bin/mcgnode").exists());
    assert!(ws.join("install/setup.bash").exists());
    let bag = d.join("s.mcap");
    let sim = Command::new(env!("CARGO_BIN_EXE_mcgnode"))
        .args(["simulate", "--trajectories", "1", "--states", "5", "--out"])
        .arg(&bag)
        .output()
        .expect("simulate");
    assert!(sim.status.success());
    let script = format!(
        r#"
        command -v mcgnode
        python3 -c 'import mcgnode_msgs.msg as m; print("imported", m.ParticleState.__name__)' || exit 2
        mcgnode serve --model truth:spring 2>"$DIR/node.log" &
        n=$!
        timeout 30 python3 scripts/ros/echo.py /mcgnode/predicted_trajectory --count 1 \
            >"$DIR/echo.out" 2>"$DIR/echo.err" &
        e=$!
        sleep 1
        timeout 30 python3 scripts/ros/play_bag.py "{}" --rate 10 --timeout 20 2>"$DIR/play.err" || exit 3
        wait $e; rc=$?
        kill -INT $n; wait $n; nrc=$?
        echo "echo $rc node $nrc"
        [ $rc -eq 0 ] && [ $nrc -eq 0 ]
    "#,
        bag.display()
    );
    let o = in_workspace(&script, d, Duration::from_secs(90));
    let read = |f: &str| fs::read_to_string(d.join(f)).unwrap_or_default();
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
            ws.join("install/mcgnode/bin/mcgnode").display()
        )),
        "the installed mcgnode is not the one on PATH\n{report}"
    );
    assert!(o.stdout.contains("imported ParticleState"), "{report}");
    assert!(read("echo.out").contains("positions"), "{report}");
}

#[test]
fn the_launch_file_and_its_config_are_installed_and_its_defaults_serve_the_shipped_model() {
    let share = install().join("install/mcgnode/share/mcgnode");
    let launch = share.join("launch/mcgnode.launch.py");
    for f in [
        &launch,
        &share.join("config/spring5.yaml"),
        &share.join("config/pendulum5.yaml"),
        &share.join("models/spring5-mcgnode.json"),
    ] {
        assert!(f.exists(), "not installed: {}", f.display());
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let launch = launch.display();
    // The launch arguments, then the command line of the defaults and of a
    // namespaced start; each command's effective parameters as the node
    // would load them (`serve --print-params` with the same ROS arguments).
    let script = format!(
        r#"
        python3 tests/ros/launch_cmd.py "{launch}" --describe >"$DIR/args.json" || exit 2
        python3 tests/ros/launch_cmd.py "{launch}" >"$DIR/default.json" || exit 3
        python3 tests/ros/launch_cmd.py "{launch}" namespace:=robot7 model:=truth:pendulum \
            >"$DIR/ns.json" || exit 4
        python3 tests/ros/launch_cmd.py "{launch}" no_such:=1 2>"$DIR/unknown.err" && exit 5
        for c in default ns; do
            python3 -c 'import json, sys; print("\n".join(json.load(open(sys.argv[1]))[0]))' \
                "$DIR/$c.json" >"$DIR/$c.argv" || exit 6
            exe=$(head -1 "$DIR/$c.argv")
            mapfile -t rest < <(tail -n +2 "$DIR/$c.argv")
            "$exe" serve --print-params "${{rest[@]}}" >"$DIR/$c.params" 2>"$DIR/$c.err" || exit 7
        done
    "#
    );
    let o = in_workspace(&script, d, Duration::from_secs(60));
    let read = |f: &str| fs::read_to_string(d.join(f)).unwrap_or_default();
    let report = format!(
        "{}\n{}\n--- default\n{}{}{}\n--- ns\n{}{}{}\n--- unknown\n{}",
        o.stdout,
        o.stderr,
        read("default.json"),
        read("default.params"),
        read("default.err"),
        read("ns.json"),
        read("ns.params"),
        read("ns.err"),
        read("unknown.err")
    );
    assert!(o.status.success(), "{report}");
    let args: serde_json::Value = serde_json::from_str(&read("args.json")).expect("JSON");
    for a in ["model", "namespace", "params_file", "name"] {
        assert!(
            args.get(a).is_some(),
            "launch argument {a} missing\n{report}"
        );
    }
    assert!(read("unknown.err").contains("no_such"), "{report}");
    // The installed executable as ros2 run finds it, the installed config,
    // and the shipped model (the config names it relative to the repository).
    let default: Vec<Vec<String>> = serde_json::from_str(&read("default.json")).expect("JSON");
    let argv = &default[0];
    assert!(
        argv[0].ends_with("install/mcgnode/lib/mcgnode/mcgnode"),
        "{report}"
    );
    assert_eq!(argv[1], "--ros-args", "{report}");
    assert!(
        argv.iter()
            .any(|a| a.ends_with("share/mcgnode/config/spring5.yaml")),
        "{report}"
    );
    let params = read("default.params");
    let model = share.join("models/spring5-mcgnode.json");
    assert!(
        params.contains(&format!("model: \"{}\"", model.display())),
        "{report}"
    );
    assert!(
        params.contains("horizon: 100"),
        "the config's horizon\n{report}"
    );
    let ns: Vec<Vec<String>> = serde_json::from_str(&read("ns.json")).expect("JSON");
    assert!(ns[0].contains(&"__ns:=/robot7".to_string()), "{report}");
    assert!(
        read("ns.params").contains("model: \"truth:pendulum\""),
        "{report}"
    );
}

#[test]
fn the_fleet_runs_when_started_the_ros2_run_way_and_from_the_launch_file() {
    let ws = install();
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    fs::write(
        d.join("robot2.yaml"),
        "mcgnode:\n  ros__parameters:\n    dt: 0.01\n    horizon: 20\n",
    )
    .expect("params");
    fs::write(
        d.join("dyn3.yaml"),
        "mcgnode:\n  ros__parameters:\n    dt: 0.01\n",
    )
    .expect("params");
    let exe = ws.join("install/mcgnode/lib/mcgnode/mcgnode");
    let launch = ws.join("install/mcgnode/share/mcgnode/launch/mcgnode.launch.py");
    let model = Path::new(ROOT).join("bags/models/spring5-mcgnode.json");
    // robot1: `ros2 run mcgnode mcgnode --ros-args …` (no subcommand; the
    // default model, truth:spring). robot2: the launch file. dyn3: ros2 run
    // with a parameter file, a rename and a remap.
    let script = format!(
        r#"
        "{bin}" simulate --trajectories 4 --states 50 --seed 3 --out "$DIR/train.mcap" 2>/dev/null \
            || exit 4
        "{exe}" --ros-args -r __ns:=/robot1 -p dt:=0.01 -p horizon:=20 2>"$DIR/robot1.log" &
        n1=$!
        python3 tests/ros/launch_cmd.py "{launch}" namespace:=/robot2 model:="{model}" \
            params_file:="$DIR/robot2.yaml" --exec 2>"$DIR/robot2.log" &
        n2=$!
        "{exe}" --ros-args -r __node:=dyn3 -r particle_state:=/tracker/state \
            --params-file "$DIR/dyn3.yaml" -p horizon:=20 --log-level warn 2>"$DIR/dyn3.log" &
        n3=$!
        {DRIVE_AND_STOP}
    "#,
        bin = common::BIN,
        exe = exe.display(),
        launch = launch.display(),
        model = model.display(),
    );
    let o = in_workspace(&script, d, Duration::from_secs(240));
    let report = common::fleet::check(&o, d);
    // robot2 really came from the launch file.
    let log = fs::read_to_string(d.join("robot2.log")).unwrap_or_default();
    assert!(
        log.contains("launch: ") && log.contains("__ns:=/robot2"),
        "{report}"
    );
}
