//! Training sets from bags: finite-difference accelerations (second order),
//! recorded accelerations, rejected trajectory sets, typed metadata, and
//! position-only recordings.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use mcgnode::data::{read_trajectories, write_trajectories, AccSource, Dataset, ParticleState};
use mcgnode::system::{Sample, State, Trajectory};

use common::bags::*;

/// q_i(t) = A_i sin(ω t + φ_i), sampled every `dt`, accelerations not recorded.
fn sine_trajectory(dt: f64, steps: usize, omega: f64) -> Trajectory {
    let graph = chain_2d();
    let d = graph.ndof();
    let q = |i: usize, t: f64| (1.0 + 0.1 * i as f64) * (omega * t + 0.3 * i as f64).sin();
    let samples = (0..steps)
        .map(|k| {
            let t = k as f64 * dt;
            Sample {
                t,
                state: State {
                    q: (0..d).map(|i| q(i, t)).collect(),
                    v: (0..d)
                        .map(|i| q(i, t + 0.5 * std::f64::consts::PI / omega) * omega)
                        .collect(),
                },
                acc: None,
            }
        })
        .collect();
    Trajectory {
        id: 0,
        system: "spring".into(),
        graph,
        samples,
    }
}

/// Max |finite-difference − analytic| acceleration over the dataset.
fn fd_error(ds: &Dataset, dt: f64, omega: f64) -> f64 {
    let mut worst: f64 = 0.0;
    for (k, (s, a)) in ds.states.iter().zip(&ds.acc).enumerate() {
        // Interior state k of the dataset is sample k+1.
        let t = (k + 1) as f64 * dt;
        assert_eq!(a.len(), s.q.len());
        for (i, (qi, ai)) in s.q.iter().zip(a).enumerate() {
            let q = (1.0 + 0.1 * i as f64) * (omega * t + 0.3 * i as f64).sin();
            assert!((qi - q).abs() < 1e-12, "state {k} is not sample {}", k + 1);
            worst = worst.max((ai - (-omega * omega * q)).abs());
        }
    }
    worst
}

#[test]
fn finite_difference_accelerations_are_second_order() {
    let omega = 2.0;
    let dir = tmpdir();
    let mut errs = Vec::new();
    for dt in [0.04, 0.02, 0.01] {
        let steps = (4.0 / dt) as usize;
        // Through a bag, so stamps are quantised to 1 ns as in real data.
        let path = dir.path().join("sine.mcap");
        write_trajectories(
            &path,
            &[sine_trajectory(dt, steps, omega)],
            &BTreeMap::new(),
        )
        .unwrap();
        let bag = read_trajectories(&path).unwrap();
        let ds = Dataset::from_trajectories(&bag.trajectories).unwrap();
        assert_eq!(ds.source, AccSource::FiniteDifference);
        assert_eq!(ds.len(), steps - 2);
        assert_eq!(ds.acc.len(), ds.states.len());
        let err = fd_error(&ds, dt, omega);
        // Taylor bound: |error| ≤ Δ² max|q⁗| / 12, max|q⁗| = 1.5 ω⁴ here.
        let bound = dt * dt * 1.5 * omega.powi(4) / 12.0;
        assert!(
            err <= bound * 1.01,
            "dt {dt}: error {err} above bound {bound}"
        );
        errs.push(err);
    }
    for w in errs.windows(2) {
        let ratio = w[0] / w[1];
        assert!(
            (3.6..4.4).contains(&ratio),
            "halving Δ divided the error by {ratio}, not ≈4 (errors {errs:?})"
        );
    }
}

#[test]
fn recorded_accelerations_are_used_when_every_sample_has_them() {
    let with = vec![
        trajectory(0, "spring", chain_2d(), 5, 0.0, true),
        trajectory(1, "spring", chain_2d(), 4, 0.0, true),
    ];
    let ds = Dataset::from_trajectories(&with).unwrap();
    assert_eq!(ds.source, AccSource::Recorded);
    assert_eq!(ds.len(), 9);
    assert_eq!(ds.graph, chain_2d());
    assert_eq!(ds.acc[5], *with[1].samples[0].acc.as_ref().unwrap());
    assert_eq!(ds.states[5], with[1].samples[0].state);
    // One trajectory without: finite differences for all, interior states only.
    let mixed = vec![
        with[0].clone(),
        trajectory(1, "spring", chain_2d(), 4, 0.0, false),
    ];
    let ds = Dataset::from_trajectories(&mixed).unwrap();
    assert_eq!(ds.source, AccSource::FiniteDifference);
    assert_eq!(ds.len(), 3 + 2);
    assert_eq!(ds.states[0], with[0].samples[1].state);
}

#[test]
fn dataset_rejects_bad_trajectory_sets() {
    assert_err(Dataset::from_trajectories(&[]), &["no trajectories"]);
    let two_graphs = mixed_trajectories();
    assert_err(
        Dataset::from_trajectories(&two_graphs),
        &["trajectory 7", "different graph"],
    );
    let short = vec![trajectory(4, "spring", chain_2d(), 2, 0.0, false)];
    assert_err(
        Dataset::from_trajectories(&short),
        &["trajectory 4", "at least 3"],
    );
    // Uneven stamps: the three-point difference, exact for a parabola.
    let mut uneven = trajectory(5, "spring", chain_2d(), 6, 0.0, false);
    let times = [0.0, 0.1, 0.25, 0.3, 0.5, 0.52];
    for (s, t) in uneven.samples.iter_mut().zip(times) {
        s.t = t;
        for (i, q) in s.state.q.iter_mut().enumerate() {
            *q = (i as f64 + 1.0) * t * t - 0.5 * t;
        }
    }
    let ds = Dataset::from_trajectories(&[uneven]).unwrap();
    assert_eq!(ds.len(), 4);
    for a in &ds.acc {
        for (i, x) in a.iter().enumerate() {
            assert!((x - 2.0 * (i as f64 + 1.0)).abs() < 1e-9, "{a:?}");
        }
    }
    let mut nan = trajectory(6, "spring", chain_2d(), 6, 0.0, true);
    nan.samples[2].acc.as_mut().unwrap()[1] = f64::NAN;
    assert_err(
        Dataset::from_trajectories(&[nan]),
        &["trajectory 6 sample 2", "accelerations"],
    );
    let mut bad_state = trajectory(8, "spring", chain_2d(), 6, 0.0, true);
    bad_state.samples[1].state.q.push(0.0);
    assert_err(
        Dataset::from_trajectories(&[bad_state]),
        &["trajectory 8 sample 1"],
    );
}

#[test]
fn typed_metadata_round_trips_and_names_bad_keys() {
    use mcgnode::data::meta::BagMetadata;
    use mcgnode::physics::{SystemConfig, SystemKind};
    let m = BagMetadata {
        system_config: Some(SystemConfig::new(SystemKind::Pendulum, 3)),
        seed: Some(42),
        integrator: Some("verlet".into()),
        generator: Some("test".into()),
        model: Some("truth:pendulum".into()),
        recorder: Some("mcgnode serve".into()),
        node_dt: Some(0.1 + 0.2),
        node_horizon: Some(300),
        other: meta(&[("robot", "arm 7")]),
    };
    let map = m.to_map().unwrap();
    assert_eq!(map["seed"], "42");
    assert_eq!(map["dt"], "0.30000000000000004");
    assert_eq!(map["robot"], "arm 7");
    assert_eq!(BagMetadata::from_map(&map).unwrap(), m);
    // Written into a bag and read back through Bag::meta.
    let dir = tmpdir();
    let p = write_bag_with(dir.path(), &map);
    assert_eq!(read_trajectories(&p).unwrap().meta().unwrap(), m);
    let e = BagMetadata::from_map(&meta(&[("horizon", "ten")]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("horizon") && e.contains("ten"), "{e}");
    assert_eq!(
        BagMetadata::from_map(&BTreeMap::new()).unwrap(),
        BagMetadata::default()
    );
}

fn write_bag_with(dir: &Path, m: &BTreeMap<String, String>) -> PathBuf {
    let p = dir.join("meta.mcap");
    write_trajectories(&p, &mixed_trajectories()[..1], m).unwrap();
    p
}

/// q_i(t) = A_i sin(ω t + φ_i) at irregular times (steps h·(1 ± 0.3)),
/// as ParticleState messages without velocities or accelerations.
fn position_only_bag(dir: &Path, name: &str, h: f64, omega: f64) -> (PathBuf, Vec<f64>) {
    let graph = chain_2d();
    let d = graph.ndof();
    let mut times = vec![0.0];
    for k in 1..60 {
        let last = times[k - 1];
        times.push(last + h * (1.0 + 0.3 * (k as f64 * 1.7).sin()));
    }
    let q = |i: usize, t: f64| (1.0 + 0.1 * i as f64) * (omega * t + 0.3 * i as f64).sin();
    let msgs: Vec<ParticleState> = times
        .iter()
        .enumerate()
        .map(|(k, &t)| {
            let s = Sample {
                t,
                state: State {
                    q: (0..d).map(|i| q(i, t)).collect(),
                    v: vec![0.0; d],
                },
                acc: None,
            };
            let mut m = ParticleState::from_sample(2, k as u32, "mocap", &graph, &s);
            m.velocities.clear();
            m
        })
        .collect();
    let p = dir.join(name);
    raw_bag(&p, &msgs);
    (p, times)
}

#[test]
fn position_only_recordings_get_second_order_velocities() {
    let dir = tmpdir();
    let omega = 2.0 * std::f64::consts::PI;
    let mut errors = vec![];
    for (name, h) in [("coarse.mcap", 0.02), ("fine.mcap", 0.01)] {
        let (p, times) = position_only_bag(dir.path(), name, h, omega);
        let bag = read_trajectories(&p).unwrap();
        assert_eq!(bag.derived_velocities, vec![2]);
        let tr = &bag.trajectories[0];
        let mut worst: f64 = 0.0;
        for (s, t) in tr.samples.iter().zip(&times) {
            for (i, v) in s.state.v.iter().enumerate() {
                let want = (1.0 + 0.1 * i as f64) * omega * (omega * t + 0.3 * i as f64).cos();
                worst = worst.max((v - want).abs());
            }
        }
        errors.push(worst);
        // Accelerations from the uneven stamps too (a training set).
        let ds = Dataset::from_trajectories(&bag.trajectories).unwrap();
        assert_eq!(ds.source, AccSource::FiniteDifference);
        assert_eq!(ds.len(), times.len() - 2);
    }
    // Second order: halving the step divides the error by about 4.
    assert!(errors[0] < 0.05 * omega, "{errors:?}");
    let ratio = errors[0] / errors[1];
    assert!(
        (3.0..5.5).contains(&ratio),
        "error ratio {ratio} ({errors:?})"
    );
    // One lone position-only state cannot be differentiated.
    let single = position_only_bag(dir.path(), "x.mcap", 0.01, omega).0;
    let one = read_trajectories(&single).unwrap().trajectories[0].samples[..1].to_vec();
    let lone = dir.path().join("lone.mcap");
    let mut m = ParticleState::from_sample(1, 0, "mocap", &chain_2d(), &one[0]);
    m.velocities.clear();
    raw_bag(&lone, &[m]);
    assert_err(read_trajectories(&lone), &["position-only", "at least two"]);
}
