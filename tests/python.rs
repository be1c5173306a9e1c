//! The Python package (python/): maturin builds its wheel in this build's
//! target directory (so it reuses the dependencies `cargo test` compiled:
//! python/ is a default workspace member, resolved with the same features),
//! pip installs it into the venv, and pytest runs python/tests against the
//! `mcgnode` binary under test: rollouts equal to `mcgnode rollout` bit for
//! bit, bags read as `bag info` and an independent decoder read them, the
//! CLI's error messages, training equal to `mcgnode train`, and the README's
//! example run as the README shows it.
//!
//! Needs the venv with maturin and pytest (`scripts/setup_venv.sh`); fails,
//! never skips, without them.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

mod common;

use common::{run_bounded, BIN, ROOT};

/// A venv program, or a failure naming the script that installs it.
fn venv_tool(name: &str) -> PathBuf {
    let p = Path::new(ROOT).join(".venv/bin").join(name);
    assert!(
        p.exists(),
        "{} is missing: run `scripts/setup_venv.sh` (in {ROOT}) to install maturin and \
         pytest into .venv, then re-run this test",
        p.display()
    );
    p
}

/// The target directory this build uses: the binary under test is
/// `<target>/release/mcgnode` (whether CARGO_TARGET_DIR, `--target-dir` or
/// the default chose it).
fn target_dir() -> PathBuf {
    Path::new(BIN)
        .parent()
        .and_then(Path::parent)
        .expect("the binary sits in <target>/<profile>/")
        .to_path_buf()
}

#[test]
fn the_python_package_builds_installs_and_agrees_with_the_cli() {
    let python = venv_tool("python3");
    let maturin = venv_tool("maturin");
    let _ = venv_tool("pytest");
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let wheels = d.join("wheels");

    let t0 = Instant::now();
    let build_log = d.join("build");
    std::fs::create_dir_all(&build_log).unwrap();
    let o = run_bounded(
        Command::new(&maturin)
            .args(["build", "--release", "-m", "python/Cargo.toml", "--out"])
            .arg(&wheels)
            .arg("-i")
            .arg(&python)
            .env("CARGO_TARGET_DIR", target_dir()),
        Duration::from_secs(900),
        &build_log,
    );
    assert!(
        o.status.success(),
        "maturin build failed:\n{}\n{}",
        o.stdout,
        o.stderr
    );
    let built = t0.elapsed();
    let wheel = std::fs::read_dir(&wheels)
        .expect("maturin wrote the wheel folder")
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "whl"))
        .expect("a wheel");
    let name = wheel.file_name().unwrap().to_string_lossy().to_string();
    assert!(
        name.starts_with("mcgnode-") && name.contains("-abi3-"),
        "not an abi3 wheel of mcgnode: {name}"
    );

    let install_log = d.join("install");
    std::fs::create_dir_all(&install_log).unwrap();
    let o = run_bounded(
        Command::new(&python)
            .args([
                "-m",
                "pip",
                "install",
                "--disable-pip-version-check",
                "--no-index",
                "--no-deps",
                "--force-reinstall",
            ])
            .arg(&wheel),
        Duration::from_secs(120),
        &install_log,
    );
    assert!(
        o.status.success(),
        "pip install {name} failed:\n{}\n{}",
        o.stdout,
        o.stderr
    );

    let test_log = d.join("pytest");
    std::fs::create_dir_all(&test_log).unwrap();
    let o = run_bounded(
        Command::new(&python)
            .args([
                "-m",
                "pytest",
                "-p",
                "no:cacheprovider",
                "-rfEs",
                "python/tests",
            ])
            .env("MCGNODE_BIN", BIN)
            .env("PYTHONDONTWRITEBYTECODE", "1"),
        Duration::from_secs(600),
        &test_log,
    );
    let report = format!("{}\n{}", o.stdout, o.stderr);
    assert!(o.status.success(), "pytest failed:\n{report}");
    let summary = report
        .lines()
        .rev()
        .find(|l| l.contains(" passed"))
        .unwrap_or_else(|| panic!("no pytest summary line:\n{report}"));
    assert!(
        !summary.contains("skipped") && !summary.contains("failed"),
        "pytest must run every test: {summary}\n{report}"
    );
    eprintln!(
        "wheel {name} built in {:.1} s; pytest: {}",
        built.as_secs_f64(),
        summary.trim_matches(|c| c == '=' || c == ' ')
    );
}
