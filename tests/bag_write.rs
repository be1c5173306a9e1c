//! ParticleState messages and MCAP bags written and read back: round trips
//! in 2D and 3D, metadata, CDR and schema text, determinism, atomic writes,
//! and the writer's checks.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use mcgnode::data::msg::{particle_state_schema, Time, CDR_LE_HEADER};
use mcgnode::data::{digest, read_trajectories, write_trajectories, BagWriter, ParticleState};
use mcgnode::system::Trajectory;

use common::bags::*;

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
