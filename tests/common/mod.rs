//! The harness shared by the ROS 2 integration tests: bounded children in
//! their own process groups, the rclpy environment, the network namespace.
#![allow(dead_code)] // each test binary uses its own subset

pub mod bags;
pub mod baselines;
pub mod cli;
pub mod fleet;

use std::fs;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The `mcgnode` binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_mcgnode");
/// The repository root.
pub const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// What a bounded child left behind.
pub struct Outcome {
    pub status: ExitStatus,
    pub stdout: String,
    pub stderr: String,
}

/// Runs `cmd` in its own process group with output to files; after `limit`
/// the whole group is killed and the test fails with what it printed.
pub fn run_bounded(cmd: &mut Command, limit: Duration, dir: &Path) -> Outcome {
    let out_path = dir.join("stdout.txt");
    let err_path = dir.join("stderr.txt");
    let mut child = cmd
        .current_dir(ROOT)
        .stdin(Stdio::null())
        .stdout(fs::File::create(&out_path).expect("creating stdout file"))
        .stderr(fs::File::create(&err_path).expect("creating stderr file"))
        .process_group(0)
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {cmd:?}: {e}"));
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("waiting for the child") {
            break Some(s);
        }
        if start.elapsed() > limit {
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let read = |p: &Path| fs::read_to_string(p).unwrap_or_default();
    if let Some(status) = status {
        Outcome {
            status,
            stdout: read(&out_path),
            stderr: read(&err_path),
        }
    } else {
        let _ = Command::new("kill")
            .args(["-KILL", "--", &format!("-{}", child.id())])
            .status();
        let _ = child.wait();
        panic!(
            "{cmd:?} overran {limit:?} and was killed\n--- stdout\n{}\n--- stderr\n{}",
            read(&out_path),
            read(&err_path)
        );
    }
}

/// The rclpy environment, built once per test binary: fails with the command
/// to run when the venv is missing.
pub fn ros_env() -> PathBuf {
    static BUILT: Mutex<bool> = Mutex::new(false);
    let mut built = BUILT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let root = Path::new(ROOT);
    let venv_ok = root.join(".venv/bin/python3").exists()
        && root.join(".venv/share/rosidl_default_generators").exists();
    assert!(
        venv_ok,
        "the rclpy venv is missing: run `scripts/setup_venv.sh` (in {ROOT}), then re-run this test"
    );
    if !*built {
        let dir = tempfile::tempdir().expect("tempdir");
        let o = run_bounded(
            Command::new("bash").arg("scripts/build_msgs.sh"),
            Duration::from_secs(300),
            dir.path(),
        );
        assert!(
            o.status.success(),
            "scripts/build_msgs.sh failed:\n{}\n{}",
            o.stdout,
            o.stderr
        );
        *built = true;
    }
    root.join("build/msgs/env.sh")
}

/// The script that starts the node on `$PARAMS` (log in `$LOG`, further
/// arguments in `$NODE_ARGS`), runs
/// `driver` (shell) beside it, stops the node with SIGINT (killing it after
/// 10 s) and succeeds when both exited 0.
pub fn beside_node(driver: &str) -> String {
    format!(
        r#"
        set -u
        . "$ENV"
        "$BIN" serve --params "$PARAMS" ${{NODE_ARGS:-}} 2>"$LOG" &
        node=$!
        {driver}
        rc=$?
        kill -INT $node
        for _ in $(seq 100); do kill -0 $node 2>/dev/null || break; sleep 0.1; done
        if kill -0 $node 2>/dev/null; then echo "node ignored SIGINT"; kill -KILL $node; exit 3; fi
        wait $node; node_rc=$?
        echo "node exit code $node_rc"
        [ $rc -eq 0 ] && [ $node_rc -eq 0 ]
    "#
    )
}

/// `scripts/netns.sh bash -c script` with BIN, ENV, PARAMS exported.
pub fn in_netns(script: &str, params: &Path, env_sh: &Path) -> Command {
    // Whatever the script leaves running when it ends (a node it started
    // before an early `exit`) is killed with it, never orphaned.
    let script = format!("trap 'kill -KILL $(jobs -p) 2>/dev/null || true' EXIT\n{script}");
    let mut c = Command::new("bash");
    c.arg("scripts/netns.sh")
        .args(["bash", "-c", &script])
        .env("BIN", BIN)
        .env("ENV", env_sh)
        .env("PARAMS", params)
        .env_remove("ROS_DOMAIN_ID");
    c
}

/// Checks that a run of the node beside rclpy scripts succeeded and returns
/// the node's log and a report of everything printed, for assertion messages.
pub fn expect_success(o: &Outcome, node_log: &Path) -> (String, String) {
    let log = fs::read_to_string(node_log).unwrap_or_default();
    let report = format!(
        "--- status {}\n--- stdout\n{}\n--- stderr\n{}\n--- node log\n{log}",
        o.status, o.stdout, o.stderr
    );
    assert!(
        o.status.success(),
        "the driver or the node failed\n{report}"
    );
    (log, report)
}

/// Checks that a driver run (an rclpy script beside the node) succeeded and
/// returns its summary (the line after `prefix`), the node's log, and a
/// report of everything both printed, for assertion messages.
pub fn driver_outcome(o: &Outcome, node_log: &Path, prefix: &str) -> (String, String, String) {
    let (log, report) = expect_success(o, node_log);
    let summary = o
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix(prefix))
        .unwrap_or_else(|| panic!("no {prefix}line\n{report}"))
        .to_string();
    (summary, log, report)
}
