//! Bad input gives clear errors, never a panic or a wrong read: inconsistent
//! messages, truncated and flipped CDR and MCAP bytes, inconsistent bags, and
//! bags with other topics.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

mod common;

use mcgnode::data::msg::{decode_cdr, Point, Time, Vector3, PARTICLE_STATE_TYPE};
use mcgnode::data::{read_trajectories, BagWriter, ParticleState, PARTICLE_STATE_TOPIC};

use common::bags::*;

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
