//! Bags written by standard ROS 2 tooling (rosbags, in the project's venv):
//! rosbag2 directories with MCAP or sqlite3 storage, per-message, per-file and
//! chunk compression, split bags, bags without message definitions, the first
//! message layout; and the reverse (ours read by rosbags), including a bag
//! cut by a crash after `mcgnode bag repair`; bags with contacts (radius,
//! kinematic particles) and bags of the layout before them.

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

use mcgnode::data::msg::{
    encode_cdr, ros2msg_schema, ParticleStateV1, ParticleStateV2, DEP_HEADER, DEP_POINT, DEP_TIME,
    DEP_VECTOR3, FIELD_KNOWN, PARTICLE_STATE_MSG_V1, PARTICLE_STATE_MSG_V2, PARTICLE_STATE_TYPE,
};
use mcgnode::data::{
    read_bags, read_trajectories, write_trajectories, write_trajectories_with_field, BagWriter,
    ParticleState, ReadOptions,
};
use mcgnode::physics::{Field, SystemConfig, SystemKind};
use mcgnode::system::{Edge, EdgeKind, Endpoint, Graph, Sample, State, Trajectory};

use common::cli::{evaluate_json, mcgnode, ok, read, venv_python};
use common::ROOT;

/// Runs scripts/write_rosbag2.py IN OUT ARGS and checks it succeeded.
fn rosbags_write(input: &Path, out: &Path, args: &[&str]) {
    let o = Command::new(venv_python())
        .arg(Path::new(ROOT).join("scripts/write_rosbag2.py"))
        .arg(input)
        .arg(out)
        .args(args)
        .output()
        .expect("run write_rosbag2.py");
    assert!(
        o.status.success(),
        "write_rosbag2.py {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Runs scripts/decode_bag.py with rosbags' AnyReader.
fn rosbags_decode(bag: &Path) -> Output {
    Command::new(venv_python())
        .arg(Path::new(ROOT).join("scripts/decode_bag.py"))
        .arg(bag)
        .args(["--decoder", "rosbags", "--bits"])
        .output()
        .expect("run decode_bag.py")
}

/// A 2D chain of three particles (springs) and a 3D two-bar pendulum with an
/// anchor, several samples each with varied numbers.
fn trajectories() -> Vec<Trajectory> {
    let chain = Graph {
        dim: 2,
        types: vec![0, 1, 0],
        masses: vec![1.0, 2.5, 0.75],
        edges: vec![
            Edge {
                a: 0,
                b: Endpoint::Particle(1),
                kind: EdgeKind::Spring,
                rest_length: 1.0,
                stiffness: 3.0,
            },
            Edge {
                a: 1,
                b: Endpoint::Particle(2),
                kind: EdgeKind::Spring,
                rest_length: 1.25,
                stiffness: 0.5,
            },
        ],
        anchors: vec![],
        interaction_radius: 0.0,
        kinematic: vec![],
        periodic_box: None,
    };
    let pendulum = Graph {
        dim: 3,
        types: vec![0, 0],
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
                a: 1,
                b: Endpoint::Particle(0),
                kind: EdgeKind::Bar,
                rest_length: 1.0,
                stiffness: 0.0,
            },
        ],
        anchors: vec![vec![0.0, 0.0, 2.0]],
        interaction_radius: 0.0,
        kinematic: vec![],
        periodic_box: None,
    };
    let traj = |id: u32, g: &Graph, steps: usize| {
        let nd = g.ndof();
        Trajectory {
            id,
            system: if g.dim == 2 { "chain" } else { "tree" }.into(),
            graph: g.clone(),
            samples: (0..steps)
                .map(|k| Sample {
                    t: k as f64 * 0.125,
                    state: State {
                        q: (0..nd)
                            .map(|i| (i as f64 * 0.37 + k as f64 * 0.011).sin())
                            .collect(),
                        v: (0..nd).map(|i| (i * k) as f64 * 1e-3 - 0.1).collect(),
                    },
                    acc: (k % 2 == 0).then(|| (0..nd).map(|i| i as f64 / 7.0).collect()),
                })
                .collect(),
        }
    };
    vec![
        traj(3, &chain, 6),
        traj(7, &pendulum, 5),
        traj(9, &chain, 4),
    ]
}

#[test]
fn every_rosbag2_layout_written_by_rosbags_reads_identically() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("ours.mcap");
    write_trajectories(&src, &trajectories(), &BTreeMap::new()).unwrap();
    let want = read(&src);
    assert_eq!(want.trajectories.len(), 3);
    let layouts: &[(&str, &[&str])] = &[
        ("mcap_dir", &["--storage", "mcap"]),
        ("mcap_dir_v8", &["--storage", "mcap", "--version", "8"]),
        ("db3_dir", &["--storage", "sqlite3"]),
        (
            "db3_no_definitions",
            &["--storage", "sqlite3", "--no-definitions"],
        ),
        ("mcap_msg_zstd", &["--compression", "message"]),
        (
            "mcap_msg_lz4",
            &["--compression", "message", "--format", "lz4"],
        ),
        (
            "db3_msg_zstd",
            &["--storage", "sqlite3", "--compression", "message"],
        ),
        ("mcap_file_zstd", &["--compression", "file"]),
        ("mcap_chunk_zstd", &["--compression", "chunk"]),
        ("split_mcap", &["--split"]),
        (
            "split_db3_msg",
            &[
                "--split",
                "--storage",
                "sqlite3",
                "--compression",
                "message",
            ],
        ),
    ];
    for (name, args) in layouts {
        let out = dir.path().join(name);
        rosbags_write(&src, &out, args);
        assert!(
            out.join("metadata.yaml").exists(),
            "{name}: a rosbag2 directory"
        );
        let got = read(&out);
        assert_eq!(got.trajectories, want.trajectories, "{name}");
        assert_eq!(got.topic, "/particle_state", "{name}");
        assert_eq!(got.field, None, "{name}");
        // metadata.yaml itself names the same bag.
        let via_yaml = read(&out.join("metadata.yaml"));
        assert_eq!(
            via_yaml.trajectories, want.trajectories,
            "{name} via metadata.yaml"
        );
    }
    // The split bags really have two storage files, read in order.
    for name in ["split_mcap", "split_db3_msg"] {
        let n = std::fs::read_dir(dir.path().join(name))
            .unwrap()
            .filter(|e| {
                let p = e.as_ref().unwrap().path();
                p.extension().is_some_and(|x| x == "mcap" || x == "db3")
            })
            .count();
        assert_eq!(n, 2, "{name}");
    }
    // The storage file inside a directory is also a bag by itself.
    let db3 = dir.path().join("db3_dir/db3_dir.db3");
    assert_eq!(read(&db3).trajectories, want.trajectories);
    // LZ4 chunks (written by the `mcap` library: rosbags only writes zstd).
    let lz4 = dir.path().join("lz4_chunks.mcap");
    rosbags_write(&src, &lz4, &["--compression", "chunk", "--format", "lz4"]);
    assert_eq!(read(&lz4).trajectories, want.trajectories);
}

#[test]
fn several_paths_are_read_in_order_and_must_agree() {
    let dir = tempfile::tempdir().unwrap();
    let all = trajectories();
    let (a, b) = (dir.path().join("a.mcap"), dir.path().join("b.mcap"));
    write_trajectories(&a, &all[..1], &BTreeMap::new()).unwrap();
    write_trajectories(&b, &all[1..], &BTreeMap::new()).unwrap();
    let b_dir = dir.path().join("b_dir");
    rosbags_write(&b, &b_dir, &["--storage", "sqlite3"]);
    let bag = read_bags(&[a.clone(), b_dir.clone()], &ReadOptions::default()).unwrap();
    let ids: Vec<u32> = bag.trajectories.iter().map(|t| t.id).collect();
    assert_eq!(ids, vec![3, 7, 9]);
    assert_eq!(bag.sources, vec![a.clone(), b_dir.clone()]);
    // Different fields in two bags: refused, naming both.
    let f = dir.path().join("f.mcap");
    let field = Field {
        gravity: 9.81,
        drag: 0.0,
        force: vec![],
    };
    write_trajectories_with_field(&f, &all[..1], &BTreeMap::new(), Some(&field)).unwrap();
    let e = read_bags(&[a.clone(), f.clone()], &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("a.mcap") && e.contains("f.mcap") && e.contains("gravity 9.81"),
        "{e}"
    );
    // A directory that is not a rosbag2 bag says so.
    let e = read_trajectories(dir.path()).unwrap_err().to_string();
    assert!(e.contains("without metadata.yaml"), "{e}");
}

#[test]
fn the_field_travels_with_the_messages_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let trajs: Vec<Trajectory> = trajectories()
        .into_iter()
        .filter(|t| t.graph.dim == 2)
        .collect();
    let field = Field {
        gravity: 9.81,
        drag: 0.25,
        force: vec![0.5, -1.5],
    };
    let p = dir.path().join("field.mcap");
    write_trajectories_with_field(&p, &trajs, &BTreeMap::new(), Some(&field)).unwrap();
    assert_eq!(read(&p).field, Some(field.clone()));
    // rosbags decodes the field entries as written: gravity (0, -g, 0).
    let o = rosbags_decode(&p);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let m = &v["messages"][0];
    assert_eq!(m["field_status"], FIELD_KNOWN);
    let f = |x: &serde_json::Value| f64::from_bits(x.as_u64().unwrap());
    assert_eq!(f(&m["gravity"][1]), -9.81);
    assert_eq!(f(&m["gravity"][0]), 0.0);
    assert_eq!(f(&m["drag"]), 0.25);
    assert_eq!(f(&m["force"][1]), -1.5);
    // ... and written back by rosbags, mcgnode reads the same field.
    let out = dir.path().join("field_db3");
    rosbags_write(
        &p,
        &out,
        &["--storage", "sqlite3", "--compression", "message"],
    );
    let back = read(&out);
    assert_eq!(back.field, Some(field));
    assert_eq!(back.trajectories, read(&p).trajectories);
}

#[test]
fn bags_of_the_first_message_layout_stay_readable() {
    let dir = tempfile::tempdir().unwrap();
    let trajs = trajectories();
    let p = dir.path().join("v1.mcap");
    let mut w = BagWriter::create(&p).unwrap();
    let schema = ros2msg_schema(
        PARTICLE_STATE_MSG_V1,
        &[DEP_HEADER, DEP_TIME, DEP_VECTOR3, DEP_POINT],
    );
    let ch = w
        .add_channel("/particle_state", PARTICLE_STATE_TYPE, &schema)
        .unwrap();
    for tr in &trajs {
        for (k, s) in tr.samples.iter().enumerate() {
            let m = ParticleState::from_sample(tr.id, k as u32, &tr.system, &tr.graph, s);
            let v1 = ParticleStateV1 {
                header: m.header.clone(),
                trajectory_id: m.trajectory_id,
                step: m.step,
                system: m.system.clone(),
                dimension: m.dimension,
                types: m.types.clone(),
                masses: m.masses.clone(),
                positions: m.positions.clone(),
                velocities: m.velocities.clone(),
                accelerations: m.accelerations.clone(),
                edge_a: m.edge_a.clone(),
                edge_b: m.edge_b.clone(),
                edge_kind: m.edge_kind.clone(),
                edge_rest_length: m.edge_rest_length.clone(),
                edge_stiffness: m.edge_stiffness.clone(),
                anchors: m.anchors.clone(),
            };
            let bytes = encode_cdr(&v1).unwrap();
            // Shorter than the current layout: really the old wire format.
            assert!(bytes.len() < m.to_cdr().unwrap().len());
            w.write(ch, m.header.stamp.as_nanos() as u64, &bytes)
                .unwrap();
        }
    }
    w.finish().unwrap();
    let new = dir.path().join("new.mcap");
    write_trajectories(&new, &trajs, &BTreeMap::new()).unwrap();
    let want = read(&new);
    let got = read(&p);
    assert_eq!(got.trajectories, want.trajectories);
    assert_eq!(got.field, None);
    // Old-layout messages re-serialised by rosbags (its types from the bag's
    // own schema), in a directory with and without stored definitions.
    rosbags_round_trips(&p, dir.path(), "v1", &want.trajectories);
}

#[test]
fn a_bag_cut_by_a_crash_is_repaired_into_one_rosbags_reads() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Large enough for several chunks.
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--trajectories",
            "60",
            "--states",
            "200",
            "--out",
            "full.mcap",
        ],
        d,
    ));
    let full = std::fs::read(d.join("full.mcap")).unwrap();
    let cut = d.join("cut.mcap");
    std::fs::write(&cut, &full[..full.len() * 7 / 10]).unwrap();
    // rosbags refuses the cut file, mcgnode's reader names the problem.
    let o = rosbags_decode(&cut);
    assert!(
        !o.status.success(),
        "rosbags should refuse a file without footer"
    );
    let e = read_trajectories(&cut).unwrap_err().to_string();
    assert!(e.contains("cut.mcap") && e.contains("truncated"), "{e}");
    let out = ok(&mcgnode(&["bag", "repair", "cut.mcap", "fixed.mcap"], d));
    assert!(out.contains("reading stopped"), "{out}");
    let fixed = d.join("fixed.mcap");
    let o = rosbags_decode(&fixed);
    assert!(
        o.status.success(),
        "rosbags reads the repaired bag: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let n_rosbags = v["messages"].as_array().unwrap().len();
    // Every message kept is one of the originals, unchanged, and most are kept.
    let orig = read(&d.join("full.mcap"));
    let repaired = read(&fixed);
    let kept: usize = repaired.trajectories.iter().map(|t| t.samples.len()).sum();
    let total: usize = orig.trajectories.iter().map(|t| t.samples.len()).sum();
    assert_eq!(kept, n_rosbags);
    assert!(kept > total / 3 && kept < total, "kept {kept} of {total}");
    for t in &repaired.trajectories {
        let o = orig.trajectories.iter().find(|o| o.id == t.id).unwrap();
        assert_eq!(
            t.samples[..],
            o.samples[..t.samples.len()],
            "trajectory {}",
            t.id
        );
    }
    assert_eq!(repaired.metadata, orig.metadata, "metadata record kept");
    assert!(out.contains(&format!("kept {kept} messages")), "{out}");
    // Repairing a complete bag keeps everything.
    let out = ok(&mcgnode(&["bag", "repair", "full.mcap", "same.mcap"], d));
    assert!(out.contains("the input was complete"), "{out}");
    assert_eq!(read(&d.join("same.mcap")).trajectories, orig.trajectories);
    // Writing over the input is refused, and so is a directory.
    let o = mcgnode(&["bag", "repair", "cut.mcap", "cut.mcap"], d);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("another file"));
    let o = mcgnode(&["bag", "repair", ".", "x.mcap"], d);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("is a directory"));
}

#[test]
fn bag_info_describes_files_topics_systems_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = d.join("two.mcap");
    let trajs = trajectories();
    let mut w = BagWriter::create(&p).unwrap();
    let a = w.add_particle_state_channel("/particle_state").unwrap();
    let b = w.add_particle_state_channel("/ground_truth").unwrap();
    let other = w
        .add_channel("/diagnostics", "std_msgs/msg/String", "string data\n")
        .unwrap();
    for tr in &trajs {
        for (k, s) in tr.samples.iter().enumerate() {
            let m = ParticleState::from_sample(tr.id, k as u32, &tr.system, &tr.graph, s);
            w.write_particle_state(a, &m).unwrap();
            if tr.id == 3 {
                w.write_particle_state(b, &m).unwrap();
            }
        }
    }
    w.write(other, 0, &[0, 1, 0, 0, 2, 0, 0, 0, b'x', 0])
        .unwrap();
    w.finish().unwrap();
    // Two ParticleState topics: info lists the topics, then asks for --topic.
    let o = mcgnode(&["bag", "info", "two.mcap"], d);
    assert!(!o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("/particle_state  mcgnode_msgs/msg/ParticleState  15 messages"),
        "{out}"
    );
    assert!(
        out.contains("/ground_truth  mcgnode_msgs/msg/ParticleState  6 messages"),
        "{out}"
    );
    assert!(
        out.contains("/diagnostics  std_msgs/msg/String  1 messages"),
        "{out}"
    );
    assert!(String::from_utf8_lossy(&o.stderr).contains("--topic"));
    let out = ok(&mcgnode(
        &["bag", "info", "two.mcap", "--topic", "/particle_state"],
        d,
    ));
    assert!(out.contains("messages: 22"), "{out}");
    assert!(
        out.contains("chain: 2 trajectories, 3 particles, 2D, 10 states, longest 0.625 s"),
        "{out}"
    );
    assert!(
        out.contains("tree: 1 trajectories, 2 particles, 3D, 5 states, longest 0.500 s"),
        "{out}"
    );
    assert!(out.contains("field: unknown"), "{out}");
    // A simulated pendulum directory written by rosbags.
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "pendulum",
            "--trajectories",
            "2",
            "--states",
            "11",
            "--out",
            "pend.mcap",
        ],
        d,
    ));
    rosbags_write(
        &d.join("pend.mcap"),
        &d.join("pend_dir"),
        &["--storage", "sqlite3", "--compression", "message"],
    );
    let out = ok(&mcgnode(&["bag", "info", "pend_dir"], d));
    assert!(out.contains("(sqlite3, message compression zstd)"), "{out}");
    assert!(
        out.contains("pendulum: 2 trajectories, 5 particles, 2D, 22 states"),
        "{out}"
    );
    assert!(out.contains("field: gravity 10 along -y, drag 0"), "{out}");
    assert!(out.contains("duration: 0.100 s"), "{out}");
}

fn stderr_of(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn mcgnode_from_a_metadata_free_closed_bag_conserves_momentum() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (seed, name) in [("1", "train"), ("2", "test")] {
        ok(&mcgnode(
            &[
                "simulate",
                "--system",
                "spring",
                "--trajectories",
                "6",
                "--states",
                "30",
                "--seed",
                seed,
                "--out",
                &format!("{name}.mcap"),
            ],
            d,
        ));
        // What another tool records: no mcgnode metadata, field unknown.
        rosbags_write(
            &d.join(format!("{name}.mcap")),
            &d.join(name),
            &["--strip-field"],
        );
        let b = read(&d.join(name));
        assert!(b.metadata.is_empty() && b.field.is_none());
    }
    let train = |body: &str, out: &str| {
        let o = mcgnode(
            &[
                "train",
                "--model",
                "mcgnode",
                "--data",
                "train",
                "--epochs",
                "3",
                "--body-force",
                body,
                "--out",
                out,
            ],
            d,
        );
        ok(&o);
        stderr_of(&o)
    };
    let log = train("auto", "closed.json");
    assert!(
        log.contains("body-force branch: off") && log.contains("inferred: a closed system"),
        "{log}"
    );
    let e = evaluate_json(d, &["--model", "closed.json", "--bag", "test"]);
    assert_eq!(e["dt_source"], "the header stamps");
    assert!((e["dt"].as_f64().unwrap() - 0.1).abs() < 1e-12);
    assert!(
        e["field_source"].as_str().unwrap().contains("inferred"),
        "{}",
        e["field_source"]
    );
    let me = e["summary"]["me_scaled"]["gmean"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .fold(0.0, f64::max);
    assert!(me < 1e-12, "ME scaled {me:e}: momentum must be conserved");
    // The same model with the body-force branch on does not conserve it: the
    // check above can fail.
    train("on", "open.json");
    let e = evaluate_json(d, &["--model", "open.json", "--bag", "test"]);
    let me_open = e["averages"]["me_scaled"].as_f64().unwrap();
    assert!(me_open > 1e-9, "ME scaled with body force {me_open:e}");
    // Data that are not closed and say nothing: MCGNODE is refused with the flag.
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "spring",
            "--trajectories",
            "3",
            "--states",
            "20",
            "--gravity",
            "2",
            "--out",
            "fall.mcap",
        ],
        d,
    ));
    rosbags_write(&d.join("fall.mcap"), &d.join("fall"), &["--strip-field"]);
    let o = mcgnode(
        &[
            "train", "--model", "mcgnode", "--data", "fall", "--epochs", "1", "--out", "x.json",
        ],
        d,
    );
    assert!(!o.status.success());
    assert!(stderr_of(&o).contains("--body-force"), "{}", stderr_of(&o));
}

#[test]
fn a_metadata_free_pendulum_bag_gives_the_true_energy_error_or_names_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&mcgnode(
        &[
            "simulate",
            "--system",
            "pendulum",
            "--particles",
            "3",
            "--trajectories",
            "3",
            "--states",
            "11",
            "--out",
            "pend.mcap",
        ],
        d,
    ));
    ok(&mcgnode(
        &[
            "train",
            "--model",
            "gnode",
            "--data",
            "pend.mcap",
            "--epochs",
            "2",
            "--out",
            "m.json",
        ],
        d,
    ));
    // The truth: our own bag, whose metadata and messages both state gravity 10.
    let truth = evaluate_json(
        d,
        &["--model", "m.json", "--bag", "pend.mcap", "--allow-overlap"],
    );
    let ee = |e: &serde_json::Value| e["averages"]["ee"].as_f64().unwrap();
    // Written again by rosbags: no metadata, the field in the messages.
    rosbags_write(&d.join("pend.mcap"), &d.join("pend_dir"), &[]);
    let with_field = evaluate_json(
        d,
        &[
            "--model",
            "m.json",
            "--bag",
            "pend_dir",
            "--allow-overlap",
            "--dt",
            "1e-5",
        ],
    );
    assert_eq!(with_field["field_source"], "the messages' field entries");
    assert_eq!(ee(&with_field), ee(&truth));
    // Field unknown: refused, naming the flags.
    rosbags_write(&d.join("pend.mcap"), &d.join("bare"), &["--strip-field"]);
    let o = mcgnode(
        &[
            "evaluate",
            "--model",
            "m.json",
            "--bag",
            "bare",
            "--allow-overlap",
        ],
        d,
    );
    assert!(!o.status.success());
    let err = stderr_of(&o);
    assert!(
        err.contains("--gravity") && err.contains("--closed"),
        "{err}"
    );
    let o = mcgnode(
        &[
            "replay",
            "--model",
            "m.json",
            "--bag",
            "bare",
            "--horizon",
            "0.02",
        ],
        d,
    );
    assert!(!o.status.success());
    assert!(stderr_of(&o).contains("--gravity"), "{}", stderr_of(&o));
    // With the flag, the true EE.
    let flagged = evaluate_json(
        d,
        &[
            "--model",
            "m.json",
            "--bag",
            "bare",
            "--allow-overlap",
            "--dt",
            "1e-5",
            "--gravity",
            "10",
        ],
    );
    assert_eq!(flagged["field_source"], "flags");
    assert_eq!(ee(&flagged), ee(&truth));
    // A wrong statement (no gravity) contradicts what the model was trained on.
    let o = mcgnode(
        &[
            "evaluate",
            "--model",
            "m.json",
            "--bag",
            "bare",
            "--allow-overlap",
            "--closed",
        ],
        d,
    );
    assert!(!o.status.success());
    let err = stderr_of(&o);
    assert!(err.contains("trained with gravity 10"), "{err}");
}

#[test]
fn zero_force_written_either_way_is_one_field() {
    use mcgnode::physics::SystemConfig;
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = SystemConfig::new(mcgnode::physics::SystemKind::Spring, 3);
    cfg.field.force = vec![0.0, 0.0];
    let meta = mcgnode::data::BagMetadata {
        system_config: Some(cfg.clone()),
        ..Default::default()
    }
    .to_map()
    .unwrap();
    let p = dir.path().join("zero_force.mcap");
    let trajs: Vec<Trajectory> = trajectories()
        .into_iter()
        .filter(|t| t.graph.dim == 2)
        .collect();
    write_trajectories_with_field(&p, &trajs, &meta, Some(&cfg.field)).unwrap();
    let bag = read(&p);
    let origin = mcgnode::data::field::bag_field(&bag, None)
        .unwrap()
        .expect("stated");
    assert!(origin.field.is_free());
    assert_eq!(origin.source, "the messages' field entries");
    // A real force in the metadata that the messages do not carry is refused.
    let mut other = cfg.clone();
    other.field.force = vec![0.5, 0.0];
    let meta = mcgnode::data::BagMetadata {
        system_config: Some(other),
        ..Default::default()
    }
    .to_map()
    .unwrap();
    write_trajectories_with_field(&p, &trajs, &meta, Some(&cfg.field)).unwrap();
    let e = mcgnode::data::field::bag_field(&read(&p), None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("system_config"), "{e}");
}

/// A 3D lattice from a simulator that is not ours (scripts/sim_lattice3d.py:
/// numpy, its own lattice, stiffness, masses and step; written by rosbags's
/// rosbag2 writer with no `mcgnode` metadata) reads as what its messages say,
/// trains with the default recipe with no flag (closed system from the
/// field entries, step from the stamps, edges recorded) and evaluates beside
/// the standing-still reference, conserving momentum exactly.
#[test]
fn a_python_simulator_lattice_trains_and_evaluates_with_no_project_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, seed, traj) in [("lattice", "0", "3"), ("lattice-test", "9", "2")] {
        let o = Command::new(venv_python())
            .arg(Path::new(ROOT).join("scripts/sim_lattice3d.py"))
            .arg(d.join(name))
            .args([
                "--side",
                "2",
                "--trajectories",
                traj,
                "--states",
                "31",
                "--seed",
                seed,
            ])
            .output()
            .expect("run sim_lattice3d.py");
        assert!(
            o.status.success(),
            "sim_lattice3d.py failed: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let bag = read(&d.join("lattice"));
    assert!(bag.metadata.is_empty(), "{:?}", bag.metadata);
    let tr = &bag.trajectories[0];
    assert_eq!((tr.graph.n(), tr.graph.dim, tr.samples.len()), (8, 3, 31));
    // 2x2x2: 12 axis bonds and 12 face diagonals, one stiffness.
    assert_eq!(tr.graph.edges.len(), 24);
    assert!(tr.graph.edges.iter().all(|e| e.stiffness == 2.0));
    let o = mcgnode(
        &[
            "train", "--model", "mcgnode", "--data", "lattice", "--epochs", "3", "--out", "m.json",
        ],
        d,
    );
    ok(&o);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("closed system"), "{log}");
    assert!(
        log.contains("recipe: batch 100 states (48 directed edges each)"),
        "{log}"
    );
    assert!(log.contains("explains"), "{log}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("m.json")).unwrap()).unwrap();
    assert_eq!(m["trained_on"]["edge_params"].as_array().unwrap().len(), 2);
    assert!(m["training"]["explained"].as_f64().is_some());
    let e = evaluate_json(d, &["--model", "m.json", "--bag", "lattice-test"]);
    assert_eq!(e["dt_source"], "the header stamps");
    assert!(e["still"]["re_mean"].as_f64().unwrap() > 0.0);
    assert!(e["summary"]["me_scaled"]["gmean"]
        .as_array()
        .unwrap()
        .iter()
        .all(|x| x.as_f64().unwrap() < 1e-12));
}

/// Writes every sample of `trajs` as `encode(message)` under `schema_main`.
fn write_layout(
    p: &Path,
    trajs: &[Trajectory],
    field: Option<&Field>,
    schema_main: &str,
    encode: impl Fn(ParticleState) -> Vec<u8>,
) {
    let mut w = BagWriter::create(p).unwrap();
    let schema = ros2msg_schema(schema_main, &[DEP_HEADER, DEP_TIME, DEP_VECTOR3, DEP_POINT]);
    let ch = w
        .add_channel("/particle_state", PARTICLE_STATE_TYPE, &schema)
        .unwrap();
    for tr in trajs {
        for (k, s) in tr.samples.iter().enumerate() {
            let m = ParticleState::from_sample(tr.id, k as u32, &tr.system, &tr.graph, s)
                .with_field(field);
            let t = m.header.stamp.as_nanos() as u64;
            w.write(ch, t, &encode(m)).unwrap();
        }
    }
    w.finish().unwrap();
}

#[test]
fn bags_of_the_layout_before_contacts_stay_readable() {
    let dir = tempfile::tempdir().unwrap();
    let trajs = trajectories();
    let field = Field {
        gravity: 10.0,
        ..Field::default()
    };
    let p = dir.path().join("v2.mcap");
    write_layout(&p, &trajs, Some(&field), PARTICLE_STATE_MSG_V2, |m| {
        let full = m.to_cdr().unwrap();
        let v2 = ParticleStateV2 {
            header: m.header,
            trajectory_id: m.trajectory_id,
            step: m.step,
            system: m.system,
            dimension: m.dimension,
            types: m.types,
            masses: m.masses,
            positions: m.positions,
            velocities: m.velocities,
            accelerations: m.accelerations,
            edge_a: m.edge_a,
            edge_b: m.edge_b,
            edge_kind: m.edge_kind,
            edge_rest_length: m.edge_rest_length,
            edge_stiffness: m.edge_stiffness,
            anchors: m.anchors,
            field_status: m.field_status,
            gravity: m.gravity,
            drag: m.drag,
            force: m.force,
        };
        let bytes = encode_cdr(&v2).unwrap();
        // Shorter than the current layout: really the older wire format.
        assert!(bytes.len() + 12 <= full.len());
        bytes
    });
    let new = dir.path().join("new.mcap");
    write_trajectories_with_field(&new, &trajs, &BTreeMap::new(), Some(&field)).unwrap();
    let want = read(&new);
    let got = read(&p);
    assert_eq!(got.trajectories, want.trajectories);
    assert_eq!(got.field, Some(field));
    assert!(got
        .trajectories
        .iter()
        .all(|t| !t.graph.has_contacts() && t.graph.kinematic.is_empty()));
    // Re-serialised by rosbags from the bag's own schema, with and without
    // stored definitions (the reader then tries each layout).
    rosbags_round_trips(&p, dir.path(), "v2", &want.trajectories);
}

#[test]
fn contact_bags_keep_radius_and_kinematic_through_rosbags() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = SystemConfig::new(SystemKind::SoftSpheres, 6);
    cfg.states = 3;
    cfg.save_every = 10;
    let trajs = cfg.try_simulate(2, 1).unwrap();
    let p = dir.path().join("spheres.mcap");
    write_trajectories_with_field(&p, &trajs, &BTreeMap::new(), Some(&cfg.field)).unwrap();
    let ours = read(&p);
    for (a, b) in ours.trajectories.iter().zip(&trajs) {
        assert_eq!(a.graph, b.graph);
        assert!(a
            .samples
            .iter()
            .zip(&b.samples)
            .all(|(x, y)| x.state == y.state));
    }
    let g = &ours.trajectories[0].graph;
    assert_eq!(g.interaction_radius, 1.0);
    assert_eq!(g.n_kinematic(), g.n() - 6);
    for (name, args) in [
        ("mcap_dir", &["--storage", "mcap"][..]),
        (
            "db3_nodefs",
            &["--storage", "sqlite3", "--no-definitions"][..],
        ),
    ] {
        let out = dir.path().join(name);
        rosbags_write(&p, &out, args);
        assert_eq!(read(&out).trajectories, ours.trajectories, "{name}");
    }
    let info = ok(&mcgnode(&["bag", "info", "spheres.mcap"], dir.path()));
    let walls = g.n_kinematic();
    assert!(
        info.contains(&format!(
            "contacts: interaction radius 1 (closer pairs touch), {walls} kinematic particles"
        )),
        "{info}"
    );
    let plain = dir.path().join("plain.mcap");
    write_trajectories(&plain, &trajectories(), &BTreeMap::new()).unwrap();
    let info = ok(&mcgnode(&["bag", "info", "plain.mcap"], dir.path()));
    assert!(
        info.contains(
            "contacts: none (interaction radius 0: fixed edges only), no kinematic particles"
        ),
        "{info}"
    );
}

#[test]
fn a_bag_with_one_kinematic_flag_too_few_is_refused_naming_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.mcap");
    let trajs = trajectories();
    let n = trajs[0].graph.n();
    write_layout(
        &p,
        &trajs[..1],
        None,
        mcgnode::data::msg::PARTICLE_STATE_MSG,
        |mut m| {
            m.kinematic = vec![true; n - 1];
            m.interaction_radius = 0.5;
            m.to_cdr().unwrap()
        },
    );
    let e = read_trajectories(&p).unwrap_err().to_string();
    assert!(
        e.contains(&format!("{} kinematic flags for {n} particles", n - 1))
            && e.contains("one per particle"),
        "{e}"
    );
    // A negative radius likewise.
    write_layout(
        &p,
        &trajs[..1],
        None,
        mcgnode::data::msg::PARTICLE_STATE_MSG,
        |mut m| {
            m.interaction_radius = -1.0;
            m.to_cdr().unwrap()
        },
    );
    let e = read_trajectories(&p).unwrap_err().to_string();
    assert!(e.contains("interaction radius -1"), "{e}");
}

/// `bag` re-serialised by rosbags from its own schema into a directory, with
/// and without stored definitions (the reader then tries each layout), reads
/// back as `want`.
fn rosbags_round_trips(bag: &Path, dir: &Path, tag: &str, want: &[mcgnode::system::Trajectory]) {
    for (name, args) in [
        ("dir", &["--compression", "message"][..]),
        (
            "db3_nodefs",
            &["--storage", "sqlite3", "--no-definitions"][..],
        ),
    ] {
        let out = dir.join(format!("{tag}_{name}"));
        rosbags_write(bag, &out, args);
        assert_eq!(read(&out).trajectories, want, "{tag}_{name}");
    }
}
