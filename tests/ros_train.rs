//! Retraining and model swaps against real rclpy: `mcgnode serve` starts on a
//! model file trained here, and tests/ros/train_drive.py (inside
//! scripts/netns.sh, fresh domain id) calls Train, LoadModel and the Train
//! action while publishing states; see that script for the checks.
//!
//! Needs the rclpy venv (`scripts/setup_venv.sh`); the interface package is
//! (re)built with `scripts/build_msgs.sh`. Every child is bounded and killed
//! with its process group when it overruns.

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

/// `mcgnode <args>`, which must succeed.
fn mcgnode(args: &[&str], dir: &Path) {
    let o = run_bounded(Command::new(BIN).args(args), Duration::from_secs(120), dir);
    assert!(
        o.status.success(),
        "mcgnode {args:?} failed:\n{}\n{}",
        o.stdout,
        o.stderr
    );
}

#[test]
fn node_retrains_and_swaps_models() {
    let env_sh = ros_env();
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let (a, b, m0) = (d.join("a.mcap"), d.join("b.mcap"), d.join("m0.json"));
    let rec = d.join("rec");
    // A tiny 5-spring bag and a 3-epoch model to start from; a larger bag from
    // another seed to retrain on.
    mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--particles",
            "5",
            "--trajectories",
            "5",
            "--seed",
            "1",
            "--out",
            &s(&a),
        ],
        d,
    );
    mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--particles",
            "5",
            "--trajectories",
            "20",
            "--seed",
            "2",
            "--out",
            &s(&b),
        ],
        d,
    );
    mcgnode(
        &[
            "train",
            "--model",
            "mcgnode",
            "--data",
            &s(&a),
            "--epochs",
            "3",
            "--out",
            &s(&m0),
            "--quiet",
        ],
        d,
    );
    let params = d.join("params.yaml");
    fs::write(
        &params,
        format!(
            "mcgnode:\n  ros__parameters:\n    model: {:?}\n    horizon: 10\n    dt: 0.01\n    \
             record_dir: {:?}\n",
            s(&m0),
            s(&rec)
        ),
    )
    .expect("writing params");
    let script = r#"
        set -u
        . "$ENV"
        "$BIN" serve --params "$PARAMS" 2>"$LOG" &
        node=$!
        timeout 150 python3 tests/ros/train_drive.py --model "$M0" --state-bag "$A" \
            --train-bag "$B" --record-dir "$REC" --work "$WORK"
        rc=$?
        kill -INT $node
        for _ in $(seq 100); do kill -0 $node 2>/dev/null || break; sleep 0.1; done
        if kill -0 $node 2>/dev/null; then echo "node ignored SIGINT"; kill -KILL $node; exit 3; fi
        wait $node; node_rc=$?
        echo "node exit code $node_rc"
        [ $rc -eq 0 ] && [ $node_rc -eq 0 ]
    "#;
    let log = d.join("node.log");
    let o = run_bounded(
        in_netns(script, &params, &env_sh)
            .env("LOG", &log)
            .env("M0", &m0)
            .env("A", &a)
            .env("B", &b)
            .env("REC", &rec)
            .env("WORK", d),
        Duration::from_secs(200),
        d,
    );
    let node_log = fs::read_to_string(&log).unwrap_or_default();
    let report = format!(
        "--- stdout\n{}\n--- stderr\n{}\n--- node log\n{node_log}",
        o.stdout, o.stderr
    );
    assert!(
        o.status.success(),
        "the driver or the node failed\n{report}"
    );
    let summary = o
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix("TRAIN_SUMMARY "))
        .unwrap_or_else(|| panic!("no TRAIN_SUMMARY line\n{report}"));
    println!("train driver summary: {summary}");
    // The log says why each failure happened and announces each swap.
    for needle in [
        "model swapped",
        "already running",
        "/nonexistent/missing.mcap",
        "cannot load /nonexistent/model.json",
        "cancel requested",
        "training cancelled",
    ] {
        assert!(
            node_log.contains(needle),
            "{needle:?} missing from the node log\n{report}"
        );
    }
    assert!(!node_log.contains("panicked"), "{report}");
    let swaps = node_log.matches("model swapped").count();
    // Train service, LoadModel twice, action, recorded training.
    assert_eq!(swaps, 5, "expected 5 swaps\n{report}");
    let lock_us: Vec<f64> = node_log
        .match_indices("model swapped (")
        .filter_map(|(i, m)| {
            node_log[i + m.len()..]
                .split(' ')
                .next()
                .and_then(|n| n.parse().ok())
        })
        .collect();
    println!("write lock held per swap (µs): {lock_us:?}");
}
