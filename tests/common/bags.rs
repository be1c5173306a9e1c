//! Fixtures of the bag tests: small graphs and trajectories in 2D and 3D,
//! valid messages, and writers that skip validation.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use mcgnode::data::{
    write_trajectories, BagWriter, DataError, ParticleState, PARTICLE_STATE_TOPIC,
};
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph, Sample, State, Trajectory};

/// Three particles in 2D joined by two springs (a chain), no anchors.
pub fn chain_2d() -> Graph {
    Graph {
        dim: 2,
        types: vec![0, 1, 0],
        masses: vec![1.0, 2.5, 0.75],
        edges: vec![
            Edge {
                a: 0,
                b: Endpoint::Particle(1),
                kind: EdgeKind::Spring,
                rest_length: 1.0,
                stiffness: 3.5,
            },
            Edge {
                a: 1,
                b: Endpoint::Particle(2),
                kind: EdgeKind::Spring,
                rest_length: 1.25,
                stiffness: 2.0,
            },
        ],
        anchors: vec![],
        interaction_radius: 0.0,
        kinematic: vec![],
        periodic_box: None,
    }
}

/// A double pendulum in 3D: a bar from an anchor to particle 0, a bar 0–1, and
/// a spring from particle 1 to a second anchor.
pub fn pendulum_3d() -> Graph {
    Graph {
        dim: 3,
        types: vec![2, 3],
        masses: vec![1.0, 0.5],
        edges: vec![
            Edge {
                a: 0,
                b: Endpoint::Anchor(0),
                kind: EdgeKind::Bar,
                rest_length: 1.0,
                stiffness: 0.0,
            },
            Edge {
                a: 0,
                b: Endpoint::Particle(1),
                kind: EdgeKind::Bar,
                rest_length: 0.8,
                stiffness: 0.0,
            },
            Edge {
                a: 1,
                b: Endpoint::Anchor(1),
                kind: EdgeKind::Spring,
                rest_length: 0.3,
                stiffness: 7.0,
            },
        ],
        anchors: vec![vec![0.0, 0.0, 2.0], vec![0.5, -0.25, 0.125]],
        interaction_radius: 0.0,
        kinematic: vec![],
        periodic_box: None,
    }
}

/// A trajectory with smooth, non-trivial values (not physical: the bag does not care).
pub fn trajectory(
    id: u32,
    system: &str,
    graph: Graph,
    steps: usize,
    t0: f64,
    with_acc: bool,
) -> Trajectory {
    let d = graph.ndof();
    let samples = (0..steps)
        .map(|k| {
            let t = t0 + 0.01 * k as f64;
            let f =
                |i: usize, phase: f64| (1.3 * t + 0.7 * i as f64 + phase).sin() + 0.1 * i as f64;
            Sample {
                t,
                state: State {
                    q: (0..d).map(|i| f(i, 0.0)).collect(),
                    v: (0..d).map(|i| f(i, 1.0) / 3.0).collect(),
                },
                acc: with_acc.then(|| (0..d).map(|i| -f(i, 2.0) * 1e3).collect()),
            }
        })
        .collect();
    Trajectory {
        id,
        system: system.into(),
        graph,
        samples,
    }
}

/// Trajectories covering 2D/3D, with and without accelerations, with anchors.
pub fn mixed_trajectories() -> Vec<Trajectory> {
    vec![
        trajectory(0, "spring", chain_2d(), 5, 0.0, true),
        trajectory(1, "spring", chain_2d(), 4, 0.0, false),
        trajectory(7, "pendulum", pendulum_3d(), 6, 0.0, true),
        trajectory(3, "", pendulum_3d(), 3, 12.5, false),
    ]
}

pub fn tmpdir() -> tempfile::TempDir {
    tempfile::tempdir().expect("temporary directory")
}

pub fn meta(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

/// Asserts `r` is an error whose message contains every one of `needles`.
#[track_caller]
pub fn assert_err<T: std::fmt::Debug>(r: Result<T, DataError>, needles: &[&str]) -> String {
    let e = r.expect_err("expected an error").to_string();
    for n in needles {
        assert!(e.contains(n), "error {e:?} does not mention {n:?}");
    }
    e
}

/// Writes `trajectories` and returns the path.
pub fn write_bag(dir: &Path, name: &str, trajectories: &[Trajectory]) -> PathBuf {
    let path = dir.join(name);
    write_trajectories(&path, trajectories, &meta(&[("k", "v")])).expect("write bag");
    path
}

/// What reading back must give: ids sorted, t measured from the first sample,
/// everything else unchanged. Times are compared to 1 ns (stamp resolution).
pub fn assert_same(read: &[Trajectory], written: &[Trajectory]) {
    let mut want: Vec<&Trajectory> = written.iter().collect();
    want.sort_by_key(|t| t.id);
    assert_eq!(read.len(), want.len(), "number of trajectories");
    for (r, w) in read.iter().zip(want) {
        assert_eq!(r.id, w.id);
        assert_eq!(r.system, w.system, "trajectory {}", w.id);
        assert_eq!(r.graph, w.graph, "trajectory {}", w.id);
        assert_eq!(r.samples.len(), w.samples.len(), "trajectory {}", w.id);
        let t0 = w.samples[0].t;
        for (k, (rs, ws)) in r.samples.iter().zip(&w.samples).enumerate() {
            assert_eq!(rs.state, ws.state, "trajectory {} sample {k}", w.id);
            assert_eq!(rs.acc, ws.acc, "trajectory {} sample {k}", w.id);
            assert!(
                (rs.t - (ws.t - t0)).abs() < 2e-9,
                "trajectory {} sample {k}: t {} vs {}",
                w.id,
                rs.t,
                ws.t - t0
            );
        }
    }
}

pub fn good_msg() -> ParticleState {
    let t = &mixed_trajectories()[2];
    ParticleState::from_sample(t.id, 0, &t.system, &t.graph, &t.samples[0])
}

pub fn good_msg_2d() -> ParticleState {
    let t = &mixed_trajectories()[0];
    ParticleState::from_sample(t.id, 0, &t.system, &t.graph, &t.samples[0])
}

/// Writes ParticleState messages as given (no validation) with a BagWriter.
pub fn raw_bag(path: &Path, msgs: &[ParticleState]) {
    let mut w = BagWriter::create(path).unwrap();
    let ch = w.add_particle_state_channel(PARTICLE_STATE_TOPIC).unwrap();
    for m in msgs {
        w.write_particle_state(ch, m).unwrap();
    }
    w.finish().unwrap();
}

pub fn msgs_of(t: &Trajectory) -> Vec<ParticleState> {
    t.samples
        .iter()
        .enumerate()
        .map(|(k, s)| ParticleState::from_sample(t.id, k as u32, &t.system, &t.graph, s))
        .collect()
}
