//! ParticleState messages and MCAP bags: round trips, independent decoding with
//! Python readers, rejection of bad input, and finite-difference accelerations.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use mcgnode::data::msg::{
    decode_cdr, particle_state_schema, Point, Time, Vector3, CDR_LE_HEADER, PARTICLE_STATE_TYPE,
};
use mcgnode::data::{
    digest, read_trajectories, write_trajectories, AccSource, BagWriter, DataError, Dataset,
    ParticleState, PARTICLE_STATE_TOPIC,
};
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph, Sample, State, Trajectory};

// ---------------------------------------------------------------- fixtures

/// Three particles in 2D joined by two springs (a chain), no anchors.
fn chain_2d() -> Graph {
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
    }
}

/// A double pendulum in 3D: a bar from an anchor to particle 0, a bar 0–1, and
/// a spring from particle 1 to a second anchor.
fn pendulum_3d() -> Graph {
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
    }
}

/// A trajectory with smooth, non-trivial values (not physical: the bag does not care).
fn trajectory(
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
fn mixed_trajectories() -> Vec<Trajectory> {
    vec![
        trajectory(0, "spring", chain_2d(), 5, 0.0, true),
        trajectory(1, "spring", chain_2d(), 4, 0.0, false),
        trajectory(7, "pendulum", pendulum_3d(), 6, 0.0, true),
        trajectory(3, "", pendulum_3d(), 3, 12.5, false),
    ]
}

fn tmpdir() -> tempfile::TempDir {
    tempfile::tempdir().expect("temporary directory")
}

fn meta(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

/// Asserts `r` is an error whose message contains every one of `needles`.
#[track_caller]
fn assert_err<T: std::fmt::Debug>(r: Result<T, DataError>, needles: &[&str]) -> String {
    let e = r.expect_err("expected an error").to_string();
    for n in needles {
        assert!(e.contains(n), "error {e:?} does not mention {n:?}");
    }
    e
}

/// Writes `trajectories` and returns the path.
fn write_bag(dir: &Path, name: &str, trajectories: &[Trajectory]) -> PathBuf {
    let path = dir.join(name);
    write_trajectories(&path, trajectories, &meta(&[("k", "v")])).expect("write bag");
    path
}

/// What reading back must give: ids sorted, t measured from the first sample,
/// everything else unchanged. Times are compared to 1 ns (stamp resolution).
fn assert_same(read: &[Trajectory], written: &[Trajectory]) {
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

// ---------------------------------------------------------------- round trips

#[test]
fn round_trip_2d_3d_with_and_without_accelerations_and_anchors() {
    let dir = tmpdir();
    let trajs = mixed_trajectories();
    let path = write_bag(dir.path(), "mixed.mcap", &trajs);
    let bag = read_trajectories(&path).expect("read bag");
    assert_same(&bag.trajectories, &trajs);
    // The 3D pendulum keeps its anchors and bar/spring kinds.
    let p = bag.trajectories.iter().find(|t| t.id == 7).unwrap();
    assert_eq!(p.graph.anchors.len(), 2);
    assert_eq!(p.graph.n_bars(), 2);
    // Trajectory 3 started at t = 12.5; it is read back from 0.
    let late = bag.trajectories.iter().find(|t| t.id == 3).unwrap();
    assert_eq!(late.samples[0].t, 0.0);
}

#[test]
fn bag_writer_can_move_between_threads() {
    // The ROS node records from async tasks.
    fn assert_send<T: Send>() {}
    assert_send::<BagWriter>();
}

#[test]
fn metadata_round_trip() {
    let dir = tmpdir();
    let path = dir.path().join("m.mcap");
    let m = meta(&[
        ("generator", "mcgnode physics"),
        ("dt", "0.01"),
        ("empty", ""),
        ("unicode", "Δt = 1 µs, q̈"),
    ]);
    write_trajectories(&path, &mixed_trajectories()[..1], &m).unwrap();
    assert_eq!(read_trajectories(&path).unwrap().metadata, m);
    write_trajectories(&path, &mixed_trajectories()[..1], &BTreeMap::new()).unwrap();
    assert!(read_trajectories(&path).unwrap().metadata.is_empty());
}

#[test]
fn message_cdr_round_trip_and_encapsulation_header() {
    let t = &mixed_trajectories()[2];
    let msg = ParticleState::from_sample(t.id, 4, &t.system, &t.graph, &t.samples[4]);
    let bytes = msg.to_cdr().unwrap();
    assert_eq!(bytes[..4], CDR_LE_HEADER);
    assert_eq!(bytes[..4], [0x00, 0x01, 0x00, 0x00]);
    let back = ParticleState::from_cdr(&bytes).unwrap();
    assert_eq!(back, msg);
    let (g, s) = back.to_parts().unwrap();
    assert_eq!(g, t.graph);
    assert_eq!(s.state, t.samples[4].state);
    assert_eq!(s.acc, t.samples[4].acc);
    // 2D: z is 0 on the wire and anchors of edges are encoded as n + k.
    let c = &mixed_trajectories()[0];
    let m2 = ParticleState::from_sample(0, 0, "spring", &c.graph, &c.samples[0]);
    assert!(m2
        .positions
        .iter()
        .chain(&m2.velocities)
        .all(|v| v.z == 0.0));
    assert_eq!(msg.edge_b, vec![2, 1, 3]);
    assert_eq!(msg.edge_kind, vec![1, 1, 0]);
}

#[test]
fn schema_text_is_the_msg_file_plus_dependency_blocks() {
    let schema = particle_state_schema();
    let msg = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("msg/ParticleState.msg"),
    )
    .unwrap();
    assert!(schema.starts_with(&msg));
    let sep = "=".repeat(80);
    for dep in [
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Vector3",
        "geometry_msgs/Point",
    ] {
        assert!(
            schema.contains(&format!("{sep}\nMSG: {dep}\n")),
            "missing block {dep}"
        );
    }
    assert_eq!(schema.matches(&sep).count(), 4);
}

#[test]
fn time_conversion() {
    assert_eq!(
        Time::from_secs(1.5),
        Time {
            sec: 1,
            nanosec: 500_000_000
        }
    );
    assert_eq!(
        Time::from_secs(-0.25),
        Time {
            sec: -1,
            nanosec: 750_000_000
        }
    );
    assert_eq!(
        Time::from_secs(0.999_999_999_9),
        Time { sec: 1, nanosec: 0 }
    );
    assert_eq!(Time { sec: 3, nanosec: 7 }.as_nanos(), 3_000_000_007);
    assert_eq!(Time::from_secs(1e12).sec, i32::MAX);
}

#[test]
fn writing_is_deterministic_and_digest_is_sha256() {
    let dir = tmpdir();
    let trajs = mixed_trajectories();
    let a = write_bag(dir.path(), "a.mcap", &trajs);
    let b = write_bag(dir.path(), "b.mcap", &trajs);
    let da = digest(&a).unwrap();
    assert_eq!(da.len(), 64);
    assert_eq!(da, digest(&b).unwrap());
    let mut other = trajs.clone();
    other[0].samples[1].state.q[0] += 1e-9;
    let c = write_bag(dir.path(), "c.mcap", &other);
    assert_ne!(da, digest(&c).unwrap());
    // The standard SHA-256 test vector.
    let abc = dir.path().join("abc");
    std::fs::write(&abc, b"abc").unwrap();
    assert_eq!(
        digest(&abc).unwrap(),
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    );
    assert_err(digest(dir.path().join("missing")), &["missing", "opening"]);
}

#[test]
fn write_is_atomic_and_leaves_no_temporary_files() {
    let dir = tmpdir();
    let path = write_bag(dir.path(), "x.mcap", &mixed_trajectories());
    let before = std::fs::read(&path).unwrap();
    // A failing write (invalid trajectory) leaves the old file untouched.
    let mut bad = mixed_trajectories();
    bad[1].samples[2].state.v[0] = f64::NAN;
    assert_err(
        write_trajectories(&path, &bad, &BTreeMap::new()),
        &["trajectory 1", "sample 2", "NaN"],
    );
    assert_eq!(std::fs::read(&path).unwrap(), before);
    // Overwriting works and only the bag remains in the directory.
    write_trajectories(&path, &mixed_trajectories()[..2], &BTreeMap::new()).unwrap();
    assert_eq!(read_trajectories(&path).unwrap().trajectories.len(), 2);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("x.mcap")]);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o644, "bags are ordinary readable files");
    }
    assert_err(
        write_trajectories(
            dir.path().join("no/such/dir/x.mcap"),
            &mixed_trajectories(),
            &BTreeMap::new(),
        ),
        &["no/such/dir"],
    );
}

#[test]
fn writer_rejects_bad_trajectories() {
    let dir = tmpdir();
    let p = dir.path().join("bad.mcap");
    let base = || mixed_trajectories()[..2].to_vec();
    let w = |t: &[Trajectory]| write_trajectories(&p, t, &BTreeMap::new());

    let mut t = base();
    t[1].id = 0;
    assert_err(w(&t), &["id 0", "twice"]);
    let mut t = base();
    t[0].samples.clear();
    assert_err(w(&t), &["trajectory 0", "no samples"]);
    let mut t = base();
    t[0].samples[3].t = t[0].samples[2].t;
    assert_err(w(&t), &["sample 3", "not after"]);
    let mut t = base();
    t[0].samples[0].t = -1.0;
    assert_err(w(&t), &["sample 0", "time"]);
    let mut t = base();
    t[0].samples[1].acc = Some(vec![1.0]);
    assert_err(w(&t), &["sample 1", "accelerations"]);
    let mut t = base();
    t[0].graph.masses[1] = 0.0;
    assert_err(w(&t), &["trajectory 0", "mass"]);
    let mut t = base();
    t[0].samples[4].state.q.pop();
    assert_err(w(&t), &["sample 4", "positions"]);
    assert!(!p.exists(), "nothing may be written on error");
}

// ---------------------------------------------------------------- bad messages

fn good_msg() -> ParticleState {
    let t = &mixed_trajectories()[2];
    ParticleState::from_sample(t.id, 0, &t.system, &t.graph, &t.samples[0])
}

fn good_msg_2d() -> ParticleState {
    let t = &mixed_trajectories()[0];
    ParticleState::from_sample(t.id, 0, &t.system, &t.graph, &t.samples[0])
}

#[test]
fn to_parts_rejects_every_inconsistency() {
    type Case = (
        &'static str,
        fn(&mut ParticleState),
        &'static [&'static str],
    );
    let cases: &[Case] = &[
        ("dimension 4", |m| m.dimension = 4, &["dimension", "4"]),
        ("dimension 0", |m| m.dimension = 0, &["dimension"]),
        (
            "no particles",
            |m| {
                m.types.clear();
                m.masses.clear();
                m.positions.clear();
                m.velocities.clear();
                m.accelerations.clear();
            },
            &["no particles"],
        ),
        (
            "masses",
            |m| {
                m.masses.pop();
            },
            &["masses", "1 entries for 2"],
        ),
        (
            "positions",
            |m| m.positions.push(Vector3::default()),
            &["positions", "3 entries for 2"],
        ),
        (
            "velocities",
            |m| {
                m.velocities.pop();
            },
            &["velocities"],
        ),
        (
            "accelerations",
            |m| {
                m.accelerations.pop();
            },
            &["accelerations", "or empty"],
        ),
        (
            "NaN position",
            |m| m.positions[1].y = f64::NAN,
            &["positions[1].y", "not finite"],
        ),
        (
            "inf velocity",
            |m| m.velocities[0].z = f64::INFINITY,
            &["velocities[0].z", "not finite"],
        ),
        (
            "NaN acceleration",
            |m| m.accelerations[1].x = f64::NAN,
            &["accelerations[1].x"],
        ),
        (
            "NaN anchor",
            |m| m.anchors[0].x = f64::NAN,
            &["anchors[0].x"],
        ),
        ("NaN mass", |m| m.masses[0] = f64::NAN, &["mass"]),
        ("negative mass", |m| m.masses[0] = -1.0, &["mass"]),
        (
            "NaN rest length",
            |m| m.edge_rest_length[1] = f64::NAN,
            &["edge 1"],
        ),
        (
            "inf stiffness",
            |m| m.edge_stiffness[2] = f64::INFINITY,
            &["edge 2"],
        ),
        (
            "edge_a out of range",
            |m| m.edge_a[1] = 2,
            &["edge 1", "out of range"],
        ),
        (
            "edge_b anchor out of range",
            |m| m.edge_b[0] = 4,
            &["edge 0", "anchor index 2"],
        ),
        ("self edge", |m| m.edge_b[1] = 0, &["edge 1", "itself"]),
        ("edge kind", |m| m.edge_kind[2] = 7, &["edge_kind[2] = 7"]),
        (
            "edge arrays",
            |m| {
                m.edge_stiffness.pop();
            },
            &["edge_stiffness has 2", "edge_a has 3"],
        ),
        ("edge_b length", |m| m.edge_b.push(0), &["edge_b has 4"]),
        (
            "nanosec",
            |m| m.header.stamp.nanosec = 1_000_000_000,
            &["nanosec"],
        ),
    ];
    for (name, f, needles) in cases {
        let mut m = good_msg();
        m.to_parts().expect("fixture is valid");
        f(&mut m);
        let e = assert_err(m.to_parts(), needles);
        assert!(e.starts_with("invalid ParticleState"), "{name}: {e}");
    }
    // 2D: a non-zero z anywhere is an error.
    let cases_2d: &[Case] = &[
        (
            "z position",
            |m| m.positions[2].z = 0.5,
            &["positions[2].z", "dimension is 2"],
        ),
        (
            "z velocity",
            |m| m.velocities[0].z = -1e-300,
            &["velocities[0].z"],
        ),
        (
            "z acceleration",
            |m| m.accelerations[1].z = 1.0,
            &["accelerations[1].z"],
        ),
        (
            "z anchor",
            |m| {
                m.anchors.push(Point {
                    x: 0.0,
                    y: 0.0,
                    z: 1.0,
                })
            },
            &["anchors[0].z"],
        ),
    ];
    for (name, f, needles) in cases_2d {
        let mut m = good_msg_2d();
        m.to_parts().expect("fixture is valid");
        f(&mut m);
        let e = assert_err(m.to_parts(), needles);
        assert!(e.starts_with("invalid ParticleState"), "{name}: {e}");
    }
}

#[test]
fn cdr_decode_rejects_truncated_and_garbage_bytes() {
    let bytes = good_msg().to_cdr().unwrap();
    for len in 0..bytes.len() {
        assert!(
            ParticleState::from_cdr(&bytes[..len]).is_err(),
            "truncated to {len} of {} bytes decoded",
            bytes.len()
        );
    }
    assert_err(ParticleState::from_cdr(&[0, 1]), &["too short"]);
    let mut wrong = bytes.clone();
    wrong[1] = 0x07;
    assert_err(ParticleState::from_cdr(&wrong), &["encapsulation"]);
    let mut long = bytes.clone();
    long.extend_from_slice(&[0; 8]);
    assert_err(ParticleState::from_cdr(&long), &["left over"]);
    // Up to 3 bytes of alignment padding are accepted.
    let mut padded = bytes.clone();
    padded.extend_from_slice(&[0; 3]);
    assert_eq!(ParticleState::from_cdr(&padded).unwrap(), good_msg());
    // Random garbage never panics (it is an error, or decodes into something
    // to_parts then judges).
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    for _ in 0..2000 {
        let n = (x % 300) as usize;
        let mut g = vec![0u8, 1, 0, 0];
        for _ in 0..n {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            g.push(x as u8);
        }
        if let Ok(m) = decode_cdr::<ParticleState>(&g) {
            let _ = m.to_parts();
        }
    }
    // A big-endian message decodes too (other DDS vendors may send one).
    let msg = decode_cdr::<Time>(&[0, 0, 0, 0, 0, 0, 0, 5, 0, 0, 0, 9]).unwrap();
    assert_eq!(msg, Time { sec: 5, nanosec: 9 });
}

// ---------------------------------------------------------------- bad files

#[test]
fn missing_empty_and_non_mcap_files_give_clear_errors() {
    let dir = tmpdir();
    assert_err(
        read_trajectories(dir.path().join("nope.mcap")),
        &["nope.mcap", "opening"],
    );
    let empty = dir.path().join("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    assert_err(
        read_trajectories(&empty),
        &["empty.mcap", "not a valid MCAP"],
    );
    let text = dir.path().join("text.mcap");
    std::fs::write(&text, "this is not a bag\n".repeat(10)).unwrap();
    assert_err(read_trajectories(&text), &["text.mcap", "magic"]);
    assert_err(read_trajectories(dir.path()), &[]);
}

#[test]
fn truncated_bags_give_errors_at_every_offset() {
    let dir = tmpdir();
    let path = write_bag(dir.path(), "full.mcap", &mixed_trajectories());
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    for len in 0..bytes.len() {
        std::fs::write(&cut, &bytes[..len]).unwrap();
        let e = assert_err(read_trajectories(&cut), &["cut.mcap"]);
        assert!(!e.is_empty());
    }
    let mut longer = bytes.clone();
    longer.push(0);
    std::fs::write(&cut, &longer).unwrap();
    assert_err(read_trajectories(&cut), &["cut.mcap", "after end magic"]);
}

#[test]
fn every_flipped_byte_gives_an_error() {
    let dir = tmpdir();
    let path = write_bag(dir.path(), "full.mcap", &mixed_trajectories()[..2]);
    let bytes = std::fs::read(&path).unwrap();
    let bad = dir.path().join("flipped.mcap");
    let mut undetected = Vec::new();
    for i in 0..bytes.len() {
        for mask in [0x01u8, 0x80] {
            let mut b = bytes.clone();
            b[i] ^= mask;
            std::fs::write(&bad, &b).unwrap();
            match read_trajectories(&bad) {
                Err(e) => assert!(e.to_string().contains("flipped.mcap"), "{e}"),
                Ok(_) => undetected.push((i, mask)),
            }
        }
    }
    assert!(
        undetected.is_empty(),
        "flips not detected at (offset, mask) {undetected:?}"
    );
}

/// Writes ParticleState messages as given (no validation) with a BagWriter.
fn raw_bag(path: &Path, msgs: &[ParticleState]) {
    let mut w = BagWriter::create(path).unwrap();
    let ch = w.add_particle_state_channel(PARTICLE_STATE_TOPIC).unwrap();
    for m in msgs {
        w.write_particle_state(ch, m).unwrap();
    }
    w.finish().unwrap();
}

fn msgs_of(t: &Trajectory) -> Vec<ParticleState> {
    t.samples
        .iter()
        .enumerate()
        .map(|(k, s)| ParticleState::from_sample(t.id, k as u32, &t.system, &t.graph, s))
        .collect()
}

#[test]
fn inconsistent_bags_name_the_message() {
    let dir = tmpdir();
    let p = dir.path().join("inc.mcap");
    let t = mixed_trajectories()[2].clone();

    let mut m = msgs_of(&t);
    m[3].masses[1] = 0.6;
    raw_bag(&p, &m);
    assert_err(
        read_trajectories(&p),
        &["inc.mcap", "trajectory 7", "graph", "message 3"],
    );

    let mut m = msgs_of(&t);
    m[2].edge_rest_length[0] = 1.5;
    raw_bag(&p, &m);
    assert_err(
        read_trajectories(&p),
        &["trajectory 7", "step 2", "message 2"],
    );

    let mut m = msgs_of(&t);
    m[4].step = 1;
    raw_bag(&p, &m);
    assert_err(
        read_trajectories(&p),
        &["step 1 appears twice", "messages 1 and 4"],
    );

    let mut m = msgs_of(&t);
    m[4].header.stamp = m[1].header.stamp;
    raw_bag(&p, &m);
    assert_err(read_trajectories(&p), &["not stamped after"]);

    let mut m = msgs_of(&t);
    m[5].system = "spring".into();
    raw_bag(&p, &m);
    assert_err(read_trajectories(&p), &["system", "message 5"]);

    let mut m = msgs_of(&t);
    m[2].positions[0].x = f64::NAN;
    raw_bag(&p, &m);
    assert_err(
        read_trajectories(&p),
        &["inc.mcap", "message 2", "/particle_state", "positions[0].x"],
    );

    // Undecodable CDR on a ParticleState channel.
    let mut w = BagWriter::create(&p).unwrap();
    let ch = w.add_particle_state_channel(PARTICLE_STATE_TOPIC).unwrap();
    w.write_particle_state(ch, &msgs_of(&t)[0]).unwrap();
    w.write(ch, 5, &[0, 1, 0, 0, 3, 0]).unwrap();
    w.finish().unwrap();
    assert_err(read_trajectories(&p), &["message 1", "CDR"]);

    // A ParticleState schema that is not ours.
    let mut w = BagWriter::create(&p).unwrap();
    let ch = w
        .add_channel(
            "/old",
            PARTICLE_STATE_TYPE,
            "uint32 trajectory_id\nfloat64[] positions\n",
        )
        .unwrap();
    w.write(ch, 0, &msgs_of(&t)[0].to_cdr().unwrap()).unwrap();
    w.finish().unwrap();
    assert_err(read_trajectories(&p), &["message 0", "/old", "differs"]);
}

#[test]
fn other_topics_are_skipped_and_several_particle_state_topics_need_a_choice() {
    let dir = tmpdir();
    let p = dir.path().join("multi.mcap");
    let a = mixed_trajectories()[0].clone();
    let b = mixed_trajectories()[2].clone();
    let mut w = BagWriter::create(&p).unwrap();
    let ca = w.add_particle_state_channel("/particle_state").unwrap();
    let other = w
        .add_channel("/diagnostics", "std_msgs/msg/String", "string data\n")
        .unwrap();
    let cb = w.add_particle_state_channel("/ground_truth").unwrap();
    assert_eq!(w.add_particle_state_channel("/particle_state").unwrap(), ca);
    for (ma, mb) in msgs_of(&a).iter().zip(msgs_of(&b).iter()) {
        w.write_particle_state(cb, mb).unwrap();
        w.write(other, 0, &[0, 1, 0, 0, 2, 0, 0, 0, b'x', 0])
            .unwrap();
        w.write_particle_state(ca, ma).unwrap();
    }
    w.write_particle_state(cb, &msgs_of(&b)[5]).unwrap();
    w.finish().unwrap();
    // Two ParticleState topics: refused without a choice, naming both.
    let n_a = a.samples.len();
    assert_err(
        read_trajectories(&p),
        &[
            "several topics",
            &format!("/particle_state ({n_a} messages)"),
            &format!("/ground_truth ({} messages)", n_a + 1),
            "--topic",
        ],
    );
    let read = |topic: &str| {
        mcgnode::data::read_bags(
            std::slice::from_ref(&p),
            &mcgnode::data::ReadOptions {
                topic: Some(topic.into()),
            },
        )
    };
    let bag = read("/particle_state").unwrap();
    assert_eq!(bag.topic, "/particle_state");
    assert_same(&bag.trajectories, &[a]);
    let bag = read("/ground_truth").unwrap();
    let mut b_short = b.clone();
    b_short.samples.truncate(n_a);
    b_short.samples.push(b.samples[5].clone());
    assert_same(&bag.trajectories, &[b_short]);
    assert_err(read("/nope"), &["no ParticleState messages on topic /nope"]);
}

// ---------------------------------------------------------------- independent decoders

fn venv_python() -> PathBuf {
    let py = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python3");
    assert!(
        py.exists(),
        "{} is missing: run scripts/setup_venv.sh",
        py.display()
    );
    py
}

/// Runs scripts/decode_bag.py with exact float bits and returns the decoded
/// messages as ParticleStates (with their topics) and the metadata.
fn python_decode(bag: &Path, decoder: &str) -> (Vec<(String, ParticleState)>, serde_json::Value) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/decode_bag.py");
    let out = Command::new(venv_python())
        .arg(&script)
        .arg(bag)
        .args(["--decoder", decoder, "--bits"])
        .output()
        .expect("run decode_bag.py");
    assert!(
        out.status.success(),
        "decode_bag.py --decoder {decoder} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("JSON from decode_bag.py");
    let u = |x: &serde_json::Value| x.as_u64().expect("integer");
    let f = |x: &serde_json::Value| f64::from_bits(u(x));
    let fs = |x: &serde_json::Value| x.as_array().unwrap().iter().map(f).collect::<Vec<_>>();
    let us = |x: &serde_json::Value| {
        x.as_array()
            .unwrap()
            .iter()
            .map(|y| u(y) as u32)
            .collect::<Vec<_>>()
    };
    let v3 = |x: &serde_json::Value| {
        x.as_array()
            .unwrap()
            .iter()
            .map(|p| {
                let p = fs(p);
                Vector3 {
                    x: p[0],
                    y: p[1],
                    z: p[2],
                }
            })
            .collect::<Vec<_>>()
    };
    let msgs = v["messages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            let anchors = v3(&m["anchors"])
                .into_iter()
                .map(|p| Point {
                    x: p.x,
                    y: p.y,
                    z: p.z,
                })
                .collect();
            let sec = m["sec"].as_i64().unwrap() as i32;
            let nanosec = u(&m["nanosec"]) as u32;
            assert_eq!(
                u(&m["log_time"]) as i64,
                Time { sec, nanosec }.as_nanos(),
                "log time = stamp"
            );
            let msg = ParticleState {
                header: mcgnode::data::msg::Header {
                    stamp: Time { sec, nanosec },
                    frame_id: m["frame_id"].as_str().unwrap().into(),
                },
                trajectory_id: u(&m["trajectory_id"]) as u32,
                step: u(&m["step"]) as u32,
                system: m["system"].as_str().unwrap().into(),
                dimension: u(&m["dimension"]) as u8,
                types: us(&m["types"]),
                masses: fs(&m["masses"]),
                positions: v3(&m["positions"]),
                velocities: v3(&m["velocities"]),
                accelerations: v3(&m["accelerations"]),
                edge_a: us(&m["edge_a"]),
                edge_b: us(&m["edge_b"]),
                edge_kind: us(&m["edge_kind"]).into_iter().map(|k| k as u8).collect(),
                edge_rest_length: fs(&m["edge_rest_length"]),
                edge_stiffness: fs(&m["edge_stiffness"]),
                anchors,
                field_status: u(&m["field_status"]) as u8,
                gravity: {
                    let g = fs(&m["gravity"]);
                    Vector3 {
                        x: g[0],
                        y: g[1],
                        z: g[2],
                    }
                },
                drag: f(&m["drag"]),
                force: {
                    let g = fs(&m["force"]);
                    Vector3 {
                        x: g[0],
                        y: g[1],
                        z: g[2],
                    }
                },
            };
            (m["topic"].as_str().unwrap().to_string(), msg)
        })
        .collect();
    (msgs, v["metadata"].clone())
}

/// Our messages, sorted by (trajectory, step): the order among equal log times
/// is up to each decoder, so both sides are sorted the same way.
fn expected_messages(trajs: &[Trajectory]) -> Vec<ParticleState> {
    let mut all: Vec<ParticleState> = trajs.iter().flat_map(msgs_of).collect();
    all.sort_by_key(|m| (m.trajectory_id, m.step));
    all
}

#[test]
fn python_mcap_ros2_decodes_our_bags_identically() {
    let dir = tmpdir();
    let trajs = mixed_trajectories();
    let path = dir.path().join("indep.mcap");
    let m = meta(&[("seed", "42"), ("system", "spring+pendulum")]);
    write_trajectories(&path, &trajs, &m).unwrap();
    let (mut msgs, metadata) = python_decode(&path, "mcap");
    msgs.sort_by_key(|(_, m)| (m.trajectory_id, m.step));
    let want = expected_messages(&trajs);
    assert_eq!(msgs.len(), want.len());
    for ((topic, got), want) in msgs.iter().zip(&want) {
        assert_eq!(topic, PARTICLE_STATE_TOPIC);
        assert_eq!(got, want, "mcap_ros2 decoded a different message");
    }
    assert_eq!(metadata["mcgnode"]["seed"], "42");
    assert_eq!(metadata["mcgnode"]["system"], "spring+pendulum");
    // Spot checks on plain values, in case both sides shared a mistake.
    let first_pendulum = msgs.iter().find(|(_, m)| m.trajectory_id == 7).unwrap();
    assert_eq!(
        first_pendulum.1.anchors[0],
        Point {
            x: 0.0,
            y: 0.0,
            z: 2.0
        }
    );
    assert_eq!(first_pendulum.1.edge_b, vec![2, 1, 3]);
    assert_eq!(first_pendulum.1.masses, vec![1.0, 0.5]);
}

#[test]
fn rosbags_decodes_our_bags_identically() {
    let dir = tmpdir();
    let trajs = mixed_trajectories();
    let path = dir.path().join("indep.mcap");
    write_trajectories(&path, &trajs, &BTreeMap::new()).unwrap();
    let (mut msgs, _) = python_decode(&path, "rosbags");
    msgs.sort_by_key(|(_, m)| (m.trajectory_id, m.step));
    let want = expected_messages(&trajs);
    assert_eq!(msgs.len(), want.len());
    for ((_, got), want) in msgs.iter().zip(&want) {
        assert_eq!(got, want, "rosbags decoded a different message");
    }
}

// ---------------------------------------------------------------- datasets

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
