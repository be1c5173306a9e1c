//! The CLI and the venv's Python as the bag tests run them: `mcgnode` in a
//! directory, its success checked, `evaluate --json` parsed, bags read.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use mcgnode::data::{read_trajectories, Bag};

use super::{BIN, ROOT};

/// The venv's Python, or a failure naming the script that creates it.
pub fn venv_python() -> PathBuf {
    let py = Path::new(ROOT).join(".venv/bin/python3");
    assert!(
        py.exists(),
        "{} is missing: run scripts/setup_venv.sh (in {ROOT}), then re-run this test",
        py.display()
    );
    py
}

/// `mcgnode ARGS`, run in `dir`.
pub fn mcgnode(args: &[&str], dir: &Path) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run mcgnode")
}

/// Fails with what `mcgnode` printed unless it succeeded; its stdout.
pub fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "mcgnode failed:\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// `mcgnode evaluate --json ARGS`, run in `d`, parsed.
pub fn evaluate_json(d: &Path, args: &[&str]) -> serde_json::Value {
    let mut all = vec!["evaluate", "--json"];
    all.extend_from_slice(args);
    serde_json::from_str(&ok(&mcgnode(&all, d))).expect("evaluate --json")
}

/// A bag's trajectories, or a failure naming the path.
pub fn read(path: &Path) -> Bag {
    read_trajectories(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()))
}

/// `mcgnode ARGS` in `dir`, the directory first (as the contact, driven and
/// planning tests write their calls).
pub fn run_in(dir: &Path, args: &[&str]) -> Output {
    mcgnode(args, dir)
}

/// Fails with what `mcgnode` printed unless it succeeded; its stderr (the
/// log: training's choices and figures).
pub fn log_ok(o: &Output) -> String {
    ok(o);
    String::from_utf8_lossy(&o.stderr).into_owned()
}
