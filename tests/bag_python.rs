//! Independent decoders: Python `mcap` + `mcap-ros2-support` and `rosbags`
//! decode our bags to the same messages, bit for bit.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use mcgnode::data::msg::{Point, Time, Vector3};
use mcgnode::data::{write_trajectories, ParticleState, PARTICLE_STATE_TOPIC};
use mcgnode::system::Trajectory;

use common::bags::*;

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
                interaction_radius: f(&m["interaction_radius"]),
                kinematic: m["kinematic"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|k| k.as_bool().expect("bool"))
                    .collect(),
                // The Python side does not dump the periodic box; these bags have none.
                ..ParticleState::default()
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

#[test]
fn python_decoders_read_the_contact_entries() {
    let dir = tmpdir();
    let mut g = chain_2d();
    g.interaction_radius = 0.75;
    g.kinematic = (0..g.n()).map(|i| i % 2 == 0).collect();
    let trajs = vec![trajectory(4, "soft-spheres", g, 3, 0.0, true)];
    let path = dir.path().join("contacts.mcap");
    write_trajectories(&path, &trajs, &BTreeMap::new()).unwrap();
    let want = expected_messages(&trajs);
    assert_eq!(want[0].interaction_radius, 0.75);
    for decoder in ["mcap", "rosbags"] {
        let (mut msgs, _) = python_decode(&path, decoder);
        msgs.sort_by_key(|(_, m)| (m.trajectory_id, m.step));
        assert_eq!(msgs.len(), want.len());
        for ((_, got), want) in msgs.iter().zip(&want) {
            assert_eq!(got, want, "{decoder} decoded a different message");
            assert_eq!(got.kinematic, vec![true, false, true], "{decoder}");
        }
    }
}
