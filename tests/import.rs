//! `mcgnode bag import --from gns|lagrangebench`: GNS-format datasets written
//! by the Python `tfrecord` package (scripts/bag_to_gns.py) and
//! LagrangeBench-format ones written by h5py (scripts/bag_to_lagrangebench.py)
//! from trajectories of our own simulator read back bit for bit, with their
//! counts, types, dt, radius and (LagrangeBench) periodic box; damaged files
//! are refused with errors naming the file and the key; training on the
//! imported bag takes the bag's radius.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::cli::{mcgnode, ok, read, venv_python};
use common::ROOT;

/// Simulates soft spheres (free balls in a box of kinematic walls) and
/// writes them as a GNS dataset in `d/gns` with the `tfrecord` package.
fn gns_dataset(d: &Path, extra: &[&str]) -> (PathBuf, PathBuf) {
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "soft-spheres",
            "--particles",
            "6",
            "--trajectories",
            "2",
            "--states",
            "12",
            "--seed",
            "3",
            "--out",
            "sim.mcap",
        ],
        d,
    ));
    let mut cmd = Command::new(venv_python());
    cmd.arg(Path::new(ROOT).join("scripts/bag_to_gns.py"))
        .args(["sim.mcap", "gns"])
        .args(extra)
        .current_dir(d);
    let out = cmd.output().expect("run bag_to_gns.py");
    assert!(
        out.status.success(),
        "bag_to_gns.py failed (is `tfrecord` installed? run scripts/setup_venv.sh): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    (d.join("sim.mcap"), d.join("gns"))
}

/// Runs `mcgnode ARGS` in `d`, expecting a refusal; its stderr.
fn refused(d: &Path, args: &[&str]) -> String {
    let o = mcgnode(args, d);
    assert!(!o.status.success(), "{args:?} succeeded");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn gns_round_trip_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (sim, _) = gns_dataset(d, &[]);
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("gns/metadata.json")).unwrap())
            .unwrap();
    let dt = meta["dt"].as_f64().unwrap();
    let radius = meta["default_connectivity_radius"].as_f64().unwrap();
    let out = ok(&mcgnode(
        &[
            "bag",
            "import",
            "--from",
            "gns",
            "gns",
            "--gravity",
            "1",
            "--out",
            "imp.mcap",
        ],
        d,
    ));
    assert!(out.contains("2 trajectories"), "{out}");
    let src = read(&sim);
    let imp = read(&d.join("imp.mcap"));
    assert_eq!(src.trajectories.len(), imp.trajectories.len());
    for (s, i) in src.trajectories.iter().zip(&imp.trajectories) {
        assert_eq!(s.id, i.id, "keys are the trajectory ids");
        assert_eq!(s.graph.n(), i.graph.n());
        assert_eq!(s.samples.len(), i.samples.len());
        assert_eq!(i.graph.dim, s.graph.dim);
        assert_eq!(i.graph.interaction_radius.to_bits(), radius.to_bits());
        assert_eq!(i.graph.interaction_radius, s.graph.interaction_radius);
        // Kinematic walls carry GNS's boundary type 3, free balls water's 5.
        assert_eq!(i.graph.kinematic, s.graph.kinematic);
        assert!(i.graph.n_kinematic() > 0);
        for (k, t) in i.graph.types.iter().enumerate() {
            assert_eq!(*t, if s.graph.is_kinematic(k) { 3 } else { 5 });
        }
        assert!(i.graph.masses.iter().all(|m| *m == 1.0));
        for (k, (a, b)) in s.samples.iter().zip(&i.samples).enumerate() {
            let want: Vec<u64> = a
                .state
                .q
                .iter()
                .map(|x| f64::from(*x as f32).to_bits())
                .collect();
            let got: Vec<u64> = b.state.q.iter().map(|x| x.to_bits()).collect();
            assert_eq!(got, want, "trajectory {} state {k}: positions", s.id);
            assert!((b.t - k as f64 * dt).abs() < 1e-9, "state {k} at {}", b.t);
        }
        // Velocities: backward differences of the stored positions.
        let (q0, q1) = (&i.samples[1].state.q, &i.samples[2].state.q);
        for (j, v) in i.samples[2].state.v.iter().enumerate() {
            assert!((v - (q1[j] - q0[j]) / dt).abs() <= 1e-9 * (1.0 + v.abs()));
        }
    }
    let info = ok(&mcgnode(&["bag", "info", "imp.mcap"], d));
    let n = src.trajectories[0].graph.n();
    assert!(info.contains(&format!("{n} particles")), "{info}");
    assert!(
        info.contains(&format!("interaction radius {radius}")),
        "{info}"
    );
    // Training with the defaults takes the radius from the bag (2 epochs: the
    // radius, not the fit, is checked here).
    ok(&mcgnode(
        &[
            "train", "--model", "mcgnode", "--data", "imp.mcap", "--epochs", "2", "--out", "m.json",
        ],
        d,
    ));
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("m.json")).unwrap()).unwrap();
    let text = model.to_string();
    assert!(
        text.contains(&format!("\"interaction_radius\":{radius:?}")),
        "the model file does not record radius {radius}"
    );
}

#[test]
fn gns_damage_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_, gns) = gns_dataset(d, &[]);
    let records = gns.join("train.tfrecord");
    let good = std::fs::read(&records).unwrap();
    let import = ["bag", "import", "--from", "gns", "gns", "--out", "bad.mcap"];
    // Truncated: the last record is cut short.
    std::fs::write(&records, &good[..good.len() - 10]).unwrap();
    let e = refused(d, &import);
    assert!(
        e.contains("train.tfrecord") && e.contains("record 1") && e.contains("truncated"),
        "{e}"
    );
    // A flipped byte in the data: its CRC does not match.
    let mut bad = good.clone();
    bad[40] ^= 0x10;
    std::fs::write(&records, &bad).unwrap();
    let e = refused(d, &import);
    assert!(e.contains("train.tfrecord") && e.contains("CRC"), "{e}");
    std::fs::write(&records, &good).unwrap();
    // Wrong shape: the metadata says 3D, the positions are 2D.
    let meta_path = gns.join("metadata.json");
    let meta = std::fs::read_to_string(&meta_path).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&meta).unwrap();
    v["dim"] = 3.into();
    v.as_object_mut().unwrap().remove("bounds");
    std::fs::write(&meta_path, v.to_string()).unwrap();
    let e = refused(d, &import);
    assert!(
        e.contains("train.tfrecord") && e.contains("`position`") && e.contains("key 0"),
        "{e}"
    );
    // Missing keys: the radius; dt, whose message names the flag.
    for (key, needle) in [("default_connectivity_radius", ""), ("dt", "--dt")] {
        let mut v: serde_json::Value = serde_json::from_str(&meta).unwrap();
        v.as_object_mut().unwrap().remove(key);
        std::fs::write(&meta_path, v.to_string()).unwrap();
        let e = refused(d, &import);
        assert!(
            e.contains("metadata.json") && e.contains(&format!("`{key}`")),
            "{e}"
        );
        assert!(e.contains(needle), "{e}");
    }
    // --dt stands in for the missing key.
    let o = ok(&mcgnode(
        &[
            "bag", "import", "--from", "gns", "gns", "--dt", "0.1", "--out", "dt.mcap",
        ],
        d,
    ));
    assert!(o.contains("dt 0.1"), "{o}");
    // LagrangeBench's HDF5 is refused with its reason.
    let e = refused(
        d,
        &[
            "bag",
            "import",
            "--from",
            "lagrangebench",
            "gns",
            "--out",
            "lb.mcap",
        ],
    );
    assert!(e.contains("train.h5") && e.contains("not found"), "{e}");
}

/// Runs the first sh block of the guide's section `title` (which must hold
/// a line starting `must`) as written, in a fresh directory with the
/// repository root's `.venv` and `scripts` and `mcgnode` on PATH; the
/// directory.
fn run_guide_block(title: &str, must: &str) -> tempfile::TempDir {
    let guide = std::fs::read_to_string(Path::new(ROOT).join("docs/guide.md")).unwrap();
    let section = guide
        .split(title)
        .nth(1)
        .unwrap_or_else(|| panic!("the guide has a section `{title}`"));
    let block = section
        .split("```sh\n")
        .nth(1)
        .and_then(|b| b.split("```").next())
        .expect("the section shows a sh block");
    let lines: Vec<&str> = block.lines().filter(|l| !l.trim().is_empty()).collect();
    assert!(lines.iter().any(|l| l.starts_with(must)), "{block}");
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for name in [".venv", "scripts"] {
        std::os::unix::fs::symlink(Path::new(ROOT).join(name), d.join(name)).unwrap();
    }
    let bin_dir = Path::new(common::BIN).parent().unwrap();
    let path = format!(
        "{}:{}",
        bin_dir.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    for line in lines {
        let o = Command::new("bash")
            .args(["-c", line])
            .env("PATH", &path)
            .current_dir(d)
            .output()
            .expect("run bash");
        assert!(
            o.status.success(),
            "guide line `{line}` failed:\n{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
    }
    dir
}

/// The guide's LagrangeBench import lines, run as written.
#[test]
fn the_guides_lagrangebench_lines_run_as_written() {
    let dir = run_guide_block(
        "### Importing LagrangeBench datasets",
        "mcgnode bag import --from lagrangebench",
    );
    let bag = read(&dir.path().join("lb-imported.mcap"));
    assert_eq!(bag.trajectories.len(), 2);
    assert!(bag.trajectories[0].graph.periodic_box.is_some());
}

/// The guide's GNS import lines, run as written (from a copy of the
/// repository root's `.venv` and `scripts`, with `mcgnode` on PATH).
#[test]
fn the_guides_import_lines_run_as_written() {
    let dir = run_guide_block(
        "### Importing GNS datasets",
        "mcgnode bag import --from gns",
    );
    let d = dir.path();
    let bag = read(&d.join("imported.mcap"));
    assert_eq!(bag.trajectories.len(), 4);
    assert!(d.join("imported-model.json").exists());
}

/// Simulates `system` (16 particles, 2 trajectories, 8 states) and writes
/// it as a LagrangeBench dataset in `d/lb` with h5py; the bag.
fn lb_dataset(d: &Path, system: &str, extra: &[&str]) -> PathBuf {
    let args = ["simulate", "--system", system, "--particles", "16"];
    let more = [
        "--trajectories",
        "2",
        "--states",
        "8",
        "--seed",
        "4",
        "--out",
        "sim.mcap",
    ];
    ok(&mcgnode(&[&args[..], &more[..]].concat(), d));
    let out = Command::new(venv_python())
        .arg(Path::new(ROOT).join("scripts/bag_to_lagrangebench.py"))
        .args(["sim.mcap", "lb"])
        .args(extra)
        .current_dir(d)
        .output()
        .expect("run bag_to_lagrangebench.py");
    assert!(
        out.status.success(),
        "bag_to_lagrangebench.py failed (is `h5py` installed? run scripts/setup_venv.sh): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    d.join("sim.mcap")
}

/// Imports `d/lb`'s train split to `d/imp.mcap`; the command's output.
fn lb_import(d: &Path) -> String {
    let args = [
        "bag",
        "import",
        "--from",
        "lagrangebench",
        "lb",
        "--split",
        "train",
    ];
    ok(&mcgnode(
        &[&args[..], &["--closed", "--out", "imp.mcap"]].concat(),
        d,
    ))
}

#[test]
fn lagrangebench_periodic_round_trip() {
    // float32 positions in a box periodic on every axis: positions bit for
    // bit (as f32), the box and its flags, dt and radius from the metadata,
    // velocities the minimum-image differences.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sim = lb_dataset(d, "periodic-spheres", &["--float32"]);
    let out = lb_import(d);
    assert!(
        out.contains("2 trajectories") && out.contains(", periodic;"),
        "{out}"
    );
    let (src, imp) = (read(&sim), read(&d.join("imp.mcap")));
    assert_eq!(src.trajectories.len(), imp.trajectories.len());
    for (s, i) in src.trajectories.iter().zip(&imp.trajectories) {
        assert_eq!(i.graph.periodic_box, s.graph.periodic_box);
        assert!(i.graph.periodic_box.is_some());
        assert_eq!(i.graph.interaction_radius, s.graph.interaction_radius);
        assert_eq!((i.graph.n(), i.graph.dim), (s.graph.n(), s.graph.dim));
        assert_eq!(i.graph.n_kinematic(), 0);
        let dt = s.samples[1].t - s.samples[0].t;
        for (k, (a, b)) in s.samples.iter().zip(&i.samples).enumerate() {
            let want: Vec<u64> = a
                .state
                .q
                .iter()
                .map(|x| f64::from(*x as f32).to_bits())
                .collect();
            let got: Vec<u64> = b.state.q.iter().map(|x| x.to_bits()).collect();
            assert_eq!(got, want, "trajectory {} state {k}", s.id);
            assert!((b.t - k as f64 * dt).abs() < 1e-9, "state {k} at {}", b.t);
        }
        let pb = i.graph.periodic_box.as_ref().unwrap();
        for k in 1..i.samples.len() {
            let (q0, q1) = (&i.samples[k - 1].state.q, &i.samples[k].state.q);
            for (j, v) in i.samples[k].state.v.iter().enumerate() {
                let c = j % i.graph.dim;
                let l = pb.upper[c] - pb.lower[c];
                let mut dq = q1[j] - q0[j];
                dq -= l * (dq / l).round();
                assert!(
                    (v - dq / dt).abs() <= 1e-9 * (1.0 + v.abs()),
                    "velocity {j} of {k}"
                );
            }
        }
    }
    let info = ok(&mcgnode(&["bag", "info", "imp.mcap"], d));
    assert!(
        info.contains("16 particles") && info.contains("periodic box"),
        "{info}"
    );
}

#[test]
fn lagrangebench_walls_are_kinematic_and_damage_is_named() {
    // float64, soft spheres in a box of walls: positions bit for bit, walls
    // (type 1) kinematic, no periodic box.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sim = lb_dataset(d, "soft-spheres", &[]);
    let out = lb_import(d);
    assert!(out.contains("not periodic"), "{out}");
    let (src, imp) = (read(&sim), read(&d.join("imp.mcap")));
    for (s, i) in src.trajectories.iter().zip(&imp.trajectories) {
        assert_eq!(i.graph.kinematic, s.graph.kinematic);
        assert!(i.graph.n_kinematic() > 0);
        assert!(i.graph.periodic_box.is_none());
        for (a, b) in s.samples.iter().zip(&i.samples) {
            assert_eq!(a.state.q, b.state.q, "float64 positions exactly");
        }
    }
    assert!(ok(&mcgnode(&["bag", "info", "imp.mcap"], d)).contains("not periodic"));
    // A missing metadata key is named.
    lb_dataset(
        d,
        "soft-spheres",
        &["--drop", "default_connectivity_radius"],
    );
    let args = [
        "bag",
        "import",
        "--from",
        "lagrangebench",
        "lb",
        "--out",
        "x.mcap",
    ];
    let e = refused(d, &args);
    assert!(
        e.contains("metadata.json") && e.contains("default_connectivity_radius"),
        "{e}"
    );
    // A truncated HDF5 file names the file.
    lb_dataset(d, "soft-spheres", &[]);
    let h5 = d.join("lb/train.h5");
    let bytes = std::fs::read(&h5).unwrap();
    std::fs::write(&h5, &bytes[..bytes.len() / 3]).unwrap();
    let e = refused(d, &args);
    assert!(e.contains("train.h5"), "{e}");
    // Another split that is not there.
    let e = refused(d, &[&args[..], &["--split", "test"]].concat());
    assert!(e.contains("test.h5") && e.contains("not found"), "{e}");
}

#[test]
fn damaged_lagrangebench_files_are_errors_not_panics() {
    // 400 copies of a real file with 1-8 bytes changed or cut short: each
    // reads or is refused with the file named, and nothing panics.
    use rand::{Rng, SeedableRng};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    lb_dataset(d, "soft-spheres", &["--float32"]);
    let h5 = d.join("lb/train.h5");
    let good = std::fs::read(&h5).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(48);
    let (mut read_ok, mut refused) = (0, 0);
    for case in 0..400 {
        let mut bytes = good.clone();
        for _ in 0..rng.random_range(1..=8) {
            let i = rng.random_range(0..bytes.len());
            bytes[i] = rng.random();
        }
        if case % 10 == 0 {
            bytes.truncate(rng.random_range(0..bytes.len()));
        }
        std::fs::write(&h5, &bytes).unwrap();
        match mcgnode::data::import::read_lagrangebench(&d.join("lb"), "train", None) {
            Ok(imp) => {
                read_ok += 1;
                for t in &imp.trajectories {
                    t.graph.validate().expect("an accepted graph is valid");
                }
            }
            Err(e) => {
                refused += 1;
                assert!(e.to_string().contains("train.h5"), "case {case}: {e}");
            }
        }
    }
    println!("{read_ok} read, {refused} refused");
    assert!(refused > 0, "some damage must be noticed");
}
