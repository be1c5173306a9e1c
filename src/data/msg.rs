//! The `mcgnode_msgs/msg/ParticleState` message: serde structs in wire order, CDR
//! encoding, the ros2msg schema text, and conversion to and from [`Graph`] + [`Sample`].
//!
//! The structs are plain serde structs so that both the MCAP bags and the ROS node
//! (ros2-client) can use them as they are.

use serde::{de::DeserializeOwned, Deserialize, Serialize};

use super::DataError;
use crate::physics::Field;
use crate::system::{Edge, EdgeKind, Endpoint, Graph, Sample, State};

/// ROS type name of [`ParticleState`].
pub const PARTICLE_STATE_TYPE: &str = "mcgnode_msgs/msg/ParticleState";

/// The one copy of the .msg definition.
pub const PARTICLE_STATE_MSG: &str = include_str!("../../msg/ParticleState.msg");

/// The first layout of the message (before `field_status`, `gravity`, `drag` and
/// `force`), kept so that bags written with it stay readable.
pub const PARTICLE_STATE_MSG_V1: &str = include_str!("particle_state_v1.msg");

/// The second layout (before `interaction_radius` and `kinematic`), kept so
/// that bags written with it stay readable.
pub const PARTICLE_STATE_MSG_V2: &str = include_str!("particle_state_v2.msg");

/// `field_status` value: gravity, drag and force are not known (`FIELD_UNKNOWN`).
pub const FIELD_UNKNOWN: u8 = 0;
/// `field_status` value: exactly gravity, drag and force act (`FIELD_KNOWN`).
pub const FIELD_KNOWN: u8 = 1;

/// `frame_id` written in headers: all vectors are in the world frame.
pub const FRAME_ID: &str = "world";

/// `edge_kind` value of a spring (`EDGE_SPRING` in the .msg).
pub const EDGE_SPRING: u8 = 0;
/// `edge_kind` value of a rigid bar (`EDGE_BAR` in the .msg).
pub const EDGE_BAR: u8 = 1;

/// `std_msgs/Header` definition, as a ros2msg dependency block (name, text).
pub const DEP_HEADER: (&str, &str) = (
    "std_msgs/Header",
    "# Standard metadata for higher-level stamped data types.\n\
     builtin_interfaces/Time stamp\n\
     string frame_id\n",
);
/// `builtin_interfaces/Time` definition, as a ros2msg dependency block.
pub const DEP_TIME: (&str, &str) = (
    "builtin_interfaces/Time",
    "# Time since the epoch (here: simulation time).\n\
     int32 sec\n\
     uint32 nanosec\n",
);
/// `geometry_msgs/Vector3` definition, as a ros2msg dependency block.
pub const DEP_VECTOR3: (&str, &str) =
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n");
/// `geometry_msgs/Point` definition, as a ros2msg dependency block.
pub const DEP_POINT: (&str, &str) = ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n");

/// Builds a ros2msg schema as rosbag2 writes it: the main definition, then each
/// dependency as a block headed by a line of 80 `=` and `MSG: pkg/Type`.
pub fn ros2msg_schema(main: &str, deps: &[(&str, &str)]) -> String {
    let mut s = main.to_string();
    for (name, text) in deps {
        if !s.ends_with('\n') {
            s.push('\n');
        }
        s.push_str(&"=".repeat(80));
        s.push_str("\nMSG: ");
        s.push_str(name);
        s.push('\n');
        s.push_str(text);
    }
    s
}

/// The full ros2msg schema text of [`ParticleState`] with its dependencies.
pub fn particle_state_schema() -> String {
    ros2msg_schema(
        PARTICLE_STATE_MSG,
        &[DEP_HEADER, DEP_TIME, DEP_VECTOR3, DEP_POINT],
    )
}

/// `builtin_interfaces/Time` in its wire layout.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds, `0..1_000_000_000`.
    pub nanosec: u32,
}

impl Time {
    /// Seconds to `Time`, rounded to the nearest nanosecond. Saturates outside the
    /// `i32` seconds range, and maps NaN to zero (writers validate times first).
    pub fn from_secs(t: f64) -> Time {
        Time::from_nanos(if t.is_nan() {
            0
        } else {
            (t * 1e9).round() as i64 // `as` saturates, which is what we want here
        })
    }

    /// Nanoseconds to `Time` (floor division, so `nanosec` is always in range).
    pub fn from_nanos(ns: i64) -> Time {
        let sec = ns.div_euclid(1_000_000_000);
        let nanosec = ns.rem_euclid(1_000_000_000) as u32;
        match i32::try_from(sec) {
            Ok(sec) => Time { sec, nanosec },
            Err(_) if sec < 0 => Time {
                sec: i32::MIN,
                nanosec: 0,
            },
            Err(_) => Time {
                sec: i32::MAX,
                nanosec: 999_999_999,
            },
        }
    }

    /// Total nanoseconds (exact).
    pub fn as_nanos(&self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }

    /// Seconds as a float.
    pub fn as_secs(&self) -> f64 {
        self.as_nanos() as f64 * 1e-9
    }
}

/// `std_msgs/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Time stamp.
    pub stamp: Time,
    /// Coordinate frame.
    pub frame_id: String,
}

/// `geometry_msgs/Vector3`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component (0 in 2D).
    pub z: f64,
}

/// `geometry_msgs/Point`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x coordinate.
    pub x: f64,
    /// y coordinate.
    pub y: f64,
    /// z coordinate (0 in 2D).
    pub z: f64,
}

/// `mcgnode_msgs/msg/ParticleState`; fields in .msg order (see msg/ParticleState.msg).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParticleState {
    /// Stamp = simulation time; frame of all vectors.
    pub header: Header,
    /// Trajectory id, unique within a bag.
    pub trajectory_id: u32,
    /// Index of the state within its trajectory.
    pub step: u32,
    /// "spring", "pendulum" or "" (unknown).
    pub system: String,
    /// 2 or 3.
    pub dimension: u8,
    /// Per particle type ids.
    pub types: Vec<u32>,
    /// Per particle masses.
    pub masses: Vec<f64>,
    /// Per particle positions.
    pub positions: Vec<Vector3>,
    /// Per particle velocities.
    pub velocities: Vec<Vector3>,
    /// Per particle accelerations, empty when unknown.
    pub accelerations: Vec<Vector3>,
    /// Per edge first end (a particle).
    pub edge_a: Vec<u32>,
    /// Per edge second end: a particle if `< n`, else anchor `b - n`.
    pub edge_b: Vec<u32>,
    /// Per edge [`EDGE_SPRING`] or [`EDGE_BAR`].
    pub edge_kind: Vec<u8>,
    /// Per edge rest length (spring) or length (bar).
    pub edge_rest_length: Vec<f64>,
    /// Per edge stiffness (springs).
    pub edge_stiffness: Vec<f64>,
    /// Fixed points.
    pub anchors: Vec<Point>,
    /// [`FIELD_UNKNOWN`] or [`FIELD_KNOWN`] (whether the next three fields are known).
    pub field_status: u8,
    /// Uniform gravitational acceleration (force m·g per particle).
    pub gravity: Vector3,
    /// Linear drag coefficient (force −c·v per particle).
    pub drag: f64,
    /// Constant force on every particle.
    pub force: Vector3,
    /// Pairs closer than this interact through contact edges rebuilt from
    /// positions (0: fixed edges only).
    pub interaction_radius: f64,
    /// Per particle: motion given, never predicted; empty when none is.
    pub kinematic: Vec<bool>,
}

/// The message in its second layout ([`PARTICLE_STATE_MSG_V2`]): what bags
/// written before contacts hold. Decodes into a [`ParticleState`] with no
/// contacts (radius 0) and no kinematic particle.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParticleStateV2 {
    /// See [`ParticleState::header`].
    pub header: Header,
    /// See [`ParticleState::trajectory_id`].
    pub trajectory_id: u32,
    /// See [`ParticleState::step`].
    pub step: u32,
    /// See [`ParticleState::system`].
    pub system: String,
    /// See [`ParticleState::dimension`].
    pub dimension: u8,
    /// See [`ParticleState::types`].
    pub types: Vec<u32>,
    /// See [`ParticleState::masses`].
    pub masses: Vec<f64>,
    /// See [`ParticleState::positions`].
    pub positions: Vec<Vector3>,
    /// See [`ParticleState::velocities`].
    pub velocities: Vec<Vector3>,
    /// See [`ParticleState::accelerations`].
    pub accelerations: Vec<Vector3>,
    /// See [`ParticleState::edge_a`].
    pub edge_a: Vec<u32>,
    /// See [`ParticleState::edge_b`].
    pub edge_b: Vec<u32>,
    /// See [`ParticleState::edge_kind`].
    pub edge_kind: Vec<u8>,
    /// See [`ParticleState::edge_rest_length`].
    pub edge_rest_length: Vec<f64>,
    /// See [`ParticleState::edge_stiffness`].
    pub edge_stiffness: Vec<f64>,
    /// See [`ParticleState::anchors`].
    pub anchors: Vec<Point>,
    /// See [`ParticleState::field_status`].
    pub field_status: u8,
    /// See [`ParticleState::gravity`].
    pub gravity: Vector3,
    /// See [`ParticleState::drag`].
    pub drag: f64,
    /// See [`ParticleState::force`].
    pub force: Vector3,
}

impl From<ParticleStateV2> for ParticleState {
    fn from(m: ParticleStateV2) -> Self {
        ParticleState {
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
            interaction_radius: 0.0,
            kinematic: vec![],
        }
    }
}

/// The message in its first layout ([`PARTICLE_STATE_MSG_V1`]): what bags
/// written before the field entries hold. Decodes into a [`ParticleState`]
/// with `field_status` = [`FIELD_UNKNOWN`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParticleStateV1 {
    /// See [`ParticleState::header`].
    pub header: Header,
    /// See [`ParticleState::trajectory_id`].
    pub trajectory_id: u32,
    /// See [`ParticleState::step`].
    pub step: u32,
    /// See [`ParticleState::system`].
    pub system: String,
    /// See [`ParticleState::dimension`].
    pub dimension: u8,
    /// See [`ParticleState::types`].
    pub types: Vec<u32>,
    /// See [`ParticleState::masses`].
    pub masses: Vec<f64>,
    /// See [`ParticleState::positions`].
    pub positions: Vec<Vector3>,
    /// See [`ParticleState::velocities`].
    pub velocities: Vec<Vector3>,
    /// See [`ParticleState::accelerations`].
    pub accelerations: Vec<Vector3>,
    /// See [`ParticleState::edge_a`].
    pub edge_a: Vec<u32>,
    /// See [`ParticleState::edge_b`].
    pub edge_b: Vec<u32>,
    /// See [`ParticleState::edge_kind`].
    pub edge_kind: Vec<u8>,
    /// See [`ParticleState::edge_rest_length`].
    pub edge_rest_length: Vec<f64>,
    /// See [`ParticleState::edge_stiffness`].
    pub edge_stiffness: Vec<f64>,
    /// See [`ParticleState::anchors`].
    pub anchors: Vec<Point>,
}

impl From<ParticleStateV1> for ParticleState {
    fn from(m: ParticleStateV1) -> Self {
        ParticleState {
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
            field_status: FIELD_UNKNOWN,
            ..ParticleState::default()
        }
    }
}

/// Which layout a bag's `ParticleState` schema declares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// This build's msg/ParticleState.msg.
    Current,
    /// [`PARTICLE_STATE_MSG_V2`] (before contacts).
    V2,
    /// [`PARTICLE_STATE_MSG_V1`].
    V1,
    /// No schema text to tell (e.g. an old sqlite3 bag): try both.
    Unknown,
}

/// Flat `dim`-vectors to 3-vectors (z = 0 in 2D). Tolerates a bad `dim`: the
/// result is then inconsistent, which [`ParticleState::to_parts`] reports.
/// Flat coordinates (`dim` per particle) as 3D vectors, z = 0 in 2D.
pub fn to_vec3(flat: &[f64], dim: usize) -> Vec<Vector3> {
    if dim == 0 {
        return Vec::new();
    }
    flat.chunks(dim)
        .map(|c| Vector3 {
            x: c.first().copied().unwrap_or(0.0),
            y: c.get(1).copied().unwrap_or(0.0),
            z: c.get(2).copied().unwrap_or(0.0),
        })
        .collect()
}

/// Index to the u32 of the wire; out-of-range values saturate so that validation
/// on the reading side reports them instead of wrapping silently.
fn idx_u32(i: usize) -> u32 {
    u32::try_from(i).unwrap_or(u32::MAX)
}

impl ParticleState {
    /// Builds the message for one sample of a trajectory (stamp = `sample.t`).
    pub fn from_sample(
        trajectory_id: u32,
        step: u32,
        system: &str,
        graph: &Graph,
        sample: &Sample,
    ) -> ParticleState {
        let n = graph.n();
        let dim = graph.dim;
        // Contact edges are rebuilt from positions and the radius by every
        // reader; only the fixed edges go on the wire.
        let edges: Vec<&Edge> = graph.fixed_edges().collect();
        let edge_b = edges
            .iter()
            .map(|e| match e.b {
                Endpoint::Particle(b) => idx_u32(b),
                Endpoint::Anchor(k) => idx_u32(n.saturating_add(k)),
            })
            .collect();
        ParticleState {
            header: Header {
                stamp: Time::from_secs(sample.t),
                frame_id: FRAME_ID.to_string(),
            },
            trajectory_id,
            step,
            system: system.to_string(),
            dimension: u8::try_from(dim).unwrap_or(u8::MAX),
            types: graph.types.clone(),
            masses: graph.masses.clone(),
            positions: to_vec3(&sample.state.q, dim),
            velocities: to_vec3(&sample.state.v, dim),
            accelerations: sample
                .acc
                .as_deref()
                .map(|a| to_vec3(a, dim))
                .unwrap_or_default(),
            edge_a: edges.iter().map(|e| idx_u32(e.a)).collect(),
            edge_b,
            edge_kind: edges
                .iter()
                .map(|e| match e.kind {
                    EdgeKind::Spring => EDGE_SPRING,
                    // Not reached: `fixed_edges` leaves contacts out.
                    EdgeKind::Bar | EdgeKind::Contact => EDGE_BAR,
                })
                .collect(),
            edge_rest_length: edges.iter().map(|e| e.rest_length).collect(),
            edge_stiffness: edges.iter().map(|e| e.stiffness).collect(),
            anchors: graph
                .anchors
                .iter()
                .map(|a| {
                    let v = to_vec3(a, dim).first().copied().unwrap_or_default();
                    Point {
                        x: v.x,
                        y: v.y,
                        z: v.z,
                    }
                })
                .collect(),
            interaction_radius: graph.interaction_radius,
            kinematic: graph.kinematic.clone(),
            ..ParticleState::default()
        }
    }

    /// The same message saying that exactly `field` acts on the particles
    /// (`field_status` = [`FIELD_KNOWN`]); `None` leaves it [`FIELD_UNKNOWN`].
    /// The simulator's gravity g points along −y: `gravity` = (0, −g, 0).
    pub fn with_field(mut self, field: Option<&Field>) -> ParticleState {
        match field {
            None => {
                self.field_status = FIELD_UNKNOWN;
                self.gravity = Vector3::default();
                self.drag = 0.0;
                self.force = Vector3::default();
            }
            Some(f) => {
                self.field_status = FIELD_KNOWN;
                self.gravity = Vector3 {
                    x: 0.0,
                    y: if f.gravity == 0.0 { 0.0 } else { -f.gravity },
                    z: 0.0,
                };
                self.drag = f.drag;
                let dim = usize::from(self.dimension).max(1);
                self.force = to_vec3(&f.force, dim).first().copied().unwrap_or_default();
            }
        }
        self
    }

    /// The field the message states: `None` for [`FIELD_UNKNOWN`]. Refuses what
    /// mcgnode cannot represent (gravity off the −y axis, negative drag, a
    /// z component in 2D) and unknown status values.
    pub fn field(&self) -> Result<Option<Field>, DataError> {
        let bad = |m: String| Err(DataError::Invalid(m));
        match self.field_status {
            FIELD_UNKNOWN => return Ok(None),
            FIELD_KNOWN => {}
            other => {
                return bad(format!(
                    "field_status = {other} is neither FIELD_UNKNOWN (0) nor FIELD_KNOWN (1)"
                ))
            }
        }
        let dim = match self.dimension {
            2 | 3 => usize::from(self.dimension),
            d => return bad(format!("dimension must be 2 or 3, got {d}")),
        };
        check_vec3("gravity", 0, &self.gravity, dim)?;
        check_vec3("force", 0, &self.force, dim)?;
        let g = self.gravity;
        if g.x != 0.0 || g.z != 0.0 {
            return bad(format!(
                "gravity ({}, {}, {}) does not point along -y: mcgnode models gravity as (0, -g, 0)",
                g.x, g.y, g.z
            ));
        }
        if !(self.drag.is_finite() && self.drag >= 0.0) {
            return bad(format!("drag = {} is not a finite number >= 0", self.drag));
        }
        let f = [self.force.x, self.force.y, self.force.z];
        let field = Field {
            gravity: if g.y == 0.0 { 0.0 } else { -g.y },
            drag: self.drag,
            force: if f.iter().all(|x| *x == 0.0) {
                vec![]
            } else {
                f[..dim].to_vec()
            },
        };
        field
            .validate(dim)
            .map_err(|e| DataError::Invalid(e.to_string()))?;
        Ok(Some(field))
    }

    /// Checks everything and returns the graph and the sample (`t` = stamp in
    /// seconds, absolute). The error says which field and element is wrong.
    pub fn to_parts(&self) -> Result<(Graph, Sample), DataError> {
        self.to_parts_with(false).map(|(g, s, _)| (g, s))
    }

    /// [`ParticleState::to_parts`] for bag reading, where `velocities` may be
    /// empty (a position-only recording): the sample's velocities are then
    /// zeros to be replaced, and the flag is true.
    pub fn to_parts_positions_only(&self) -> Result<(Graph, Sample, bool), DataError> {
        self.to_parts_with(true)
    }

    fn to_parts_with(&self, allow_no_v: bool) -> Result<(Graph, Sample, bool), DataError> {
        let bad = |m: String| Err(DataError::Invalid(m));
        let dim = match self.dimension {
            2 | 3 => usize::from(self.dimension),
            d => return bad(format!("dimension must be 2 or 3, got {d}")),
        };
        if self.header.stamp.nanosec >= 1_000_000_000 {
            return bad(format!(
                "header.stamp.nanosec = {} is not below 1e9",
                self.header.stamp.nanosec
            ));
        }
        let n = self.types.len();
        if n == 0 {
            return bad("no particles (types is empty)".into());
        }
        let no_v = allow_no_v && self.velocities.is_empty();
        for (name, len) in [
            ("masses", self.masses.len()),
            ("positions", self.positions.len()),
            ("velocities", if no_v { n } else { self.velocities.len() }),
        ] {
            if len != n {
                return bad(format!("{name} has {len} entries for {n} particles"));
            }
        }
        let na = self.accelerations.len();
        if na != 0 && na != n {
            return bad(format!(
                "accelerations has {na} entries for {n} particles (must be {n} or empty)"
            ));
        }
        let q = flatten("positions", &self.positions, dim)?;
        let v = if no_v {
            vec![0.0; n * dim]
        } else {
            flatten("velocities", &self.velocities, dim)?
        };
        let acc = if na == 0 {
            None
        } else {
            Some(flatten("accelerations", &self.accelerations, dim)?)
        };
        let anchors = self
            .anchors
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let v = Vector3 {
                    x: p.x,
                    y: p.y,
                    z: p.z,
                };
                check_vec3("anchors", i, &v, dim).map(|()| [v.x, v.y, v.z][..dim].to_vec())
            })
            .collect::<Result<Vec<_>, _>>()?;
        let edges = self.edges(n)?;
        let graph = Graph {
            dim,
            types: self.types.clone(),
            masses: self.masses.clone(),
            edges,
            anchors,
            interaction_radius: self.interaction_radius,
            kinematic: self.kinematic.clone(),
        };
        graph
            .validate()
            .map_err(|e| DataError::Invalid(e.to_string()))?;
        let state = State { q, v };
        state
            .validate(&graph)
            .map_err(|e| DataError::Invalid(e.to_string()))?;
        let sample = Sample {
            t: self.header.stamp.as_secs(),
            state,
            acc,
        };
        Ok((graph, sample, no_v))
    }

    /// Decodes the edge arrays (indices are range-checked by `Graph::validate`).
    fn edges(&self, n: usize) -> Result<Vec<Edge>, DataError> {
        let m = self.edge_a.len();
        for (name, len) in [
            ("edge_b", self.edge_b.len()),
            ("edge_kind", self.edge_kind.len()),
            ("edge_rest_length", self.edge_rest_length.len()),
            ("edge_stiffness", self.edge_stiffness.len()),
        ] {
            if len != m {
                return Err(DataError::Invalid(format!(
                    "{name} has {len} entries but edge_a has {m}"
                )));
            }
        }
        (0..m)
            .map(|k| {
                let kind = match self.edge_kind[k] {
                    EDGE_SPRING => EdgeKind::Spring,
                    EDGE_BAR => EdgeKind::Bar,
                    other => {
                        return Err(DataError::Invalid(format!(
                            "edge_kind[{k}] = {other} is neither EDGE_SPRING (0) nor EDGE_BAR (1)"
                        )))
                    }
                };
                let b = self.edge_b[k] as usize;
                Ok(Edge {
                    a: self.edge_a[k] as usize,
                    b: if b < n {
                        Endpoint::Particle(b)
                    } else {
                        Endpoint::Anchor(b - n)
                    },
                    kind,
                    rest_length: self.edge_rest_length[k],
                    stiffness: self.edge_stiffness[k],
                })
            })
            .collect()
    }

    /// CDR bytes with the encapsulation header, as stored in bags and sent by DDS.
    pub fn to_cdr(&self) -> Result<Vec<u8>, DataError> {
        encode_cdr(self)
    }

    /// Decodes CDR bytes (with encapsulation header) in this build's layout;
    /// garbage and truncated bytes give an error.
    pub fn from_cdr(bytes: &[u8]) -> Result<ParticleState, DataError> {
        Self::from_cdr_as(bytes, Layout::Current)
    }

    /// Decodes CDR bytes in the given layout. [`Layout::Unknown`] (a bag that
    /// stores no definition) tries this build's layout, then the second
    /// ([`ParticleStateV2`], no contacts), then the first
    /// ([`ParticleStateV1`], field unknown): a whole message of one cannot
    /// pass for another (a shorter one is short of bytes, a longer one has
    /// more than 3 bytes over: each layout appends at least 12), but a message
    /// cut exactly at an older layout's end would read as that layout, so
    /// this is used only when the bag cannot say.
    pub fn from_cdr_as(bytes: &[u8], layout: Layout) -> Result<ParticleState, DataError> {
        match layout {
            Layout::Current => decode_cdr(bytes),
            Layout::V2 => decode_cdr::<ParticleStateV2>(bytes).map(ParticleState::from),
            Layout::V1 => decode_cdr::<ParticleStateV1>(bytes).map(ParticleState::from),
            Layout::Unknown => decode_cdr::<ParticleState>(bytes).or_else(|e| {
                decode_cdr::<ParticleStateV2>(bytes)
                    .map(ParticleState::from)
                    .or_else(|_| decode_cdr::<ParticleStateV1>(bytes).map(ParticleState::from))
                    .map_err(|_| e)
            }),
        }
    }
}

/// Rejects non-finite components and, in 2D, a non-zero z.
fn check_vec3(field: &str, i: usize, v: &Vector3, dim: usize) -> Result<(), DataError> {
    for (c, x) in [("x", v.x), ("y", v.y), ("z", v.z)] {
        if !x.is_finite() {
            return Err(DataError::Invalid(format!(
                "{field}[{i}].{c} = {x} is not finite"
            )));
        }
    }
    if dim == 2 && v.z != 0.0 {
        return Err(DataError::Invalid(format!(
            "{field}[{i}].z = {} but dimension is 2 (z must be 0)",
            v.z
        )));
    }
    Ok(())
}

/// 3-vectors to flat `dim`-vectors, checking each.
fn flatten(field: &str, vs: &[Vector3], dim: usize) -> Result<Vec<f64>, DataError> {
    let mut out = Vec::with_capacity(vs.len() * dim);
    for (i, v) in vs.iter().enumerate() {
        check_vec3(field, i, v, dim)?;
        out.extend_from_slice(&[v.x, v.y, v.z][..dim]);
    }
    Ok(out)
}

/// The encapsulation header of little-endian plain CDR.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

// `cdr-encoding` needs a `byteorder` type, which is not one of our direct
// dependencies; rustdds (inside ros2-client) re-exports the same functions
// with a representation id instead.
use ros2_client::dds::rustdds::serialization::{
    deserialize_from_cdr_with_rep_id, to_writer_with_rep_id, RepresentationIdentifier,
};

/// Serialises any message to little-endian CDR with the 4-byte encapsulation header.
pub fn encode_cdr<T: Serialize>(msg: &T) -> Result<Vec<u8>, DataError> {
    let mut buf = CDR_LE_HEADER.to_vec();
    to_writer_with_rep_id(&mut buf, msg, RepresentationIdentifier::CDR_LE)
        .map_err(|e| DataError::Cdr(format!("encoding failed: {e}")))?;
    Ok(buf)
}

/// Deserialises CDR bytes with their encapsulation header (little- or big-endian
/// plain CDR). Truncated or garbage input gives an error; at most 3 trailing
/// padding bytes are accepted.
pub fn decode_cdr<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, DataError> {
    if bytes.len() < 4 {
        return Err(DataError::Cdr(format!(
            "{} bytes is too short for the 4-byte encapsulation header",
            bytes.len()
        )));
    }
    let rep = match [bytes[0], bytes[1]] {
        [0x00, 0x01] => RepresentationIdentifier::CDR_LE,
        [0x00, 0x00] => RepresentationIdentifier::CDR_BE,
        other => {
            return Err(DataError::Cdr(format!(
                "encapsulation {:02x} {:02x} is not plain CDR (expected 00 01 or 00 00)",
                other[0], other[1]
            )))
        }
    };
    let body = &bytes[4..];
    let (msg, used) = deserialize_from_cdr_with_rep_id::<T>(body, rep)
        .map_err(|e| DataError::Cdr(format!("decoding {} body bytes failed: {e}", body.len())))?;
    if body.len() - used > 3 {
        return Err(DataError::Cdr(format!(
            "{} bytes left over after the message (schema mismatch?)",
            body.len() - used
        )));
    }
    Ok(msg)
}
