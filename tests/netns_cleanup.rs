//! Nothing a ROS test starts outlives it: `scripts/netns.sh` runs its command
//! as the init of a PID namespace, so whatever the command started in the
//! background (a node, an rclpy driver, even a double-forked daemon) ends with
//! the command, whether it exits, fails, or is killed from outside.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// Processes whose command line holds `marker`, other than a pgrep itself.
fn survivors(marker: &str) -> Vec<String> {
    let o = Command::new("pgrep")
        .args(["-fa", marker])
        .output()
        .expect("pgrep (procps) is needed by this test: apt-get install procps");
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter(|l| !l.contains("pgrep"))
        .map(str::to_string)
        .collect()
}

/// Waits up to 5 s for no process to carry `marker`.
fn none_left(marker: &str) -> Vec<String> {
    let start = Instant::now();
    loop {
        let left = survivors(marker);
        if left.is_empty() || start.elapsed() > Duration::from_secs(5) {
            return left;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A script that leaves two sleepers behind (one double-forked) and says so.
fn leaver(marker_secs: u32, then: &str) -> Command {
    let script = format!(
        "sleep {marker_secs} & (sleep {} &) ; echo started; {then}",
        marker_secs + 1
    );
    let mut c = Command::new("bash");
    c.current_dir(ROOT)
        .args(["scripts/netns.sh", "bash", "-c", &script])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    c
}

#[test]
fn background_processes_end_with_the_command() {
    for (secs, then) in [(917_311, "exit 0"), (917_321, "exit 7")] {
        // Its output goes to a file: a sleeper left holding a pipe would
        // block a reader for ever.
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.txt");
        let mut child = leaver(secs, then)
            .stdout(std::fs::File::create(&out).unwrap())
            .spawn()
            .expect("running scripts/netns.sh");
        let start = Instant::now();
        while child.try_wait().unwrap().is_none() {
            assert!(start.elapsed() < Duration::from_secs(20), "netns.sh hung");
            std::thread::sleep(Duration::from_millis(50));
        }
        let printed = std::fs::read_to_string(&out).unwrap();
        assert!(
            printed.contains("started"),
            "the script did not run: {printed}"
        );
        let marker = format!("^sleep {}", secs / 10);
        let left = none_left(&marker);
        assert!(left.is_empty(), "`{then}` left running: {left:?}");
    }
}

#[test]
fn killing_the_command_from_outside_ends_what_it_started() {
    let secs = 917_331;
    let mut child = leaver(secs, "sleep 600").spawn().expect("spawn netns.sh");
    let marker = format!("^sleep {}", secs / 10);
    // Once both sleepers run, kill only the outer process, as a harness that
    // times a test out (or a crashed test process) would.
    let mut line = String::new();
    let out = child.stdout.take().expect("piped stdout");
    std::io::BufRead::read_line(&mut std::io::BufReader::new(out), &mut line)
        .expect("reading the script's output");
    assert_eq!(line.trim(), "started", "the script did not run");
    std::thread::sleep(Duration::from_millis(200));
    assert!(
        survivors(&format!("^sleep {}", secs / 10)).len() >= 2,
        "the sleepers are not running: the check below would prove nothing"
    );
    child.kill().expect("SIGKILL to netns.sh");
    let _ = child.wait();
    let left = none_left(&marker);
    assert!(left.is_empty(), "left running after SIGKILL: {left:?}");
}
