//! The ROS 2 node against real rclpy: `mcgnode serve` and rclpy scripts run
//! together inside a private network namespace (scripts/netns.sh) with a fresh
//! domain id, so no DDS traffic leaves loopback.
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`); the interface package is
//! (re)built here with `scripts/build_msgs.sh`, which is quick when up to date.
//! Every child runs in its own process group, killed if it overruns its bound.

use std::fs;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_mcgnode");
const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// What a bounded child left behind.
struct Outcome {
    status: ExitStatus,
    stdout: String,
    stderr: String,
}

/// Runs `cmd` in its own process group with output to files; after `limit`
/// the whole group is killed and the test fails with what it printed.
fn run_bounded(cmd: &mut Command, limit: Duration, dir: &Path) -> Outcome {
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
    match status {
        Some(status) => Outcome {
            status,
            stdout: read(&out_path),
            stderr: read(&err_path),
        },
        None => {
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
}

/// The rclpy environment, built once per test binary: fails with the command
/// to run when the venv is missing.
fn ros_env() -> PathBuf {
    static BUILT: Mutex<bool> = Mutex::new(false);
    let mut built = BUILT.lock().unwrap_or_else(|e| e.into_inner());
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

/// A parameter file for the tests (short horizon, fast diagnostics).
fn write_params(dir: &Path) -> PathBuf {
    let p = dir.join("params.yaml");
    fs::write(
        &p,
        "mcgnode:\n  ros__parameters:\n    model: truth:spring\n    horizon: 25\n    dt: 0.001\n    \
         diagnostics_period: 0.25\n    warn_period: 1.0\n    max_rollout_steps: 1000\n",
    )
    .expect("writing params");
    p
}

/// `scripts/netns.sh bash -c script` with BIN, ENV, PARAMS exported.
fn in_netns(script: &str, params: &Path, env_sh: &Path) -> Command {
    let mut c = Command::new("bash");
    c.arg("scripts/netns.sh")
        .args(["bash", "-c", script])
        .env("BIN", BIN)
        .env("ENV", env_sh)
        .env("PARAMS", params)
        .env_remove("ROS_DOMAIN_ID");
    c
}

#[test]
fn node_serves_rclpy_clients() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let params = write_params(dir.path());
    // The node logs to a file so its stderr can be checked separately; it is
    // stopped with SIGINT and must exit 0.
    let script = r#"
        set -u
        . "$ENV"
        "$BIN" serve --params "$PARAMS" 2>"$LOG" &
        node=$!
        timeout 90 python3 tests/ros/drive.py --horizon 25 --dt 0.001 \
            --max-rollout-steps 1000 --warn-period 1.0
        rc=$?
        kill -INT $node
        for _ in $(seq 100); do kill -0 $node 2>/dev/null || break; sleep 0.1; done
        if kill -0 $node 2>/dev/null; then echo "node ignored SIGINT"; kill -KILL $node; exit 3; fi
        wait $node; node_rc=$?
        echo "node exit code $node_rc"
        [ $rc -eq 0 ] && [ $node_rc -eq 0 ]
    "#;
    let log = dir.path().join("node.log");
    let o = run_bounded(
        in_netns(script, &params, &env_sh).env("LOG", &log),
        Duration::from_secs(120),
        dir.path(),
    );
    let node_log = fs::read_to_string(&log).unwrap_or_default();
    let report = format!(
        "--- stdout\n{}\n--- stderr\n{}\n--- node log\n{node_log}",
        o.stdout, o.stderr
    );
    assert!(
        o.status.success(),
        "the rclpy driver or the node failed\n{report}"
    );
    let summary = o
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix("DRIVE_SUMMARY "))
        .unwrap_or_else(|| panic!("no DRIVE_SUMMARY line\n{report}"));
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
}

#[test]
fn node_exits_cleanly_on_sigterm() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let params = write_params(dir.path());
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
    let good = write_params(dir.path());
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
