//! `mcgnode_msgs/msg/ParticleState` in this build's layout: its constants,
//! schema text, and conversion to and from [`Graph`] + [`Sample`].

use serde::{Deserialize, Serialize};

use super::cdr::encode_cdr;
use super::ros_types::{ros2msg_schema, Header, Point, Time, Vector3};
use super::ros_types::{DEP_HEADER, DEP_POINT, DEP_TIME, DEP_VECTOR3};
use crate::data::DataError;
use crate::physics::Field;
use crate::system::{Edge, EdgeKind, Endpoint, Graph, Sample, State};

/// ROS type name of [`ParticleState`].
pub const PARTICLE_STATE_TYPE: &str = "mcgnode_msgs/msg/ParticleState";

/// The one copy of the .msg definition.
pub const PARTICLE_STATE_MSG: &str = include_str!("../../../msg/ParticleState.msg");

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

/// The full ros2msg schema text of [`ParticleState`] with its dependencies.
pub fn particle_state_schema() -> String {
    ros2msg_schema(
        PARTICLE_STATE_MSG,
        &[DEP_HEADER, DEP_TIME, DEP_VECTOR3, DEP_POINT],
    )
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
    /// Lower bounds of the periodic box (z unused in 2D).
    pub box_lower: Vector3,
    /// Upper bounds of the periodic box.
    pub box_upper: Vector3,
    /// Per axis: whether the box wraps it; empty: no box.
    pub box_periodic: Vec<bool>,
}

impl ParticleState {
    /// The anchors' coordinates, `dim` each, checked.
    fn anchor_coords(&self, dim: usize) -> Result<Vec<Vec<f64>>, DataError> {
        self.anchors
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
            .collect()
    }

    /// The box these fields describe (`None` when `box_periodic` is empty);
    /// the graph's validation checks it has one flag per axis.
    fn periodic_box(&self, dim: usize) -> Option<crate::system::PeriodicBox> {
        if self.box_periodic.is_empty() {
            return None;
        }
        let axes = |v: &Vector3| [v.x, v.y, v.z][..dim.min(3)].to_vec();
        Some(crate::system::PeriodicBox {
            lower: axes(&self.box_lower),
            upper: axes(&self.box_upper),
            periodic: self.box_periodic.clone(),
        })
    }
}

/// Flat `dim`-vectors to 3-vectors (z = 0 in 2D). Tolerates a bad `dim`: the
/// result is then inconsistent, which [`ParticleState::to_parts`] reports.
/// Flat coordinates (`dim` per particle) as 3D vectors, z = 0 in 2D.
pub fn to_vec3(flat: &[f64], dim: usize) -> Vec<Vector3> {
    if dim == 0 {
        return Vec::new();
    }
    flat.chunks(dim).map(Vector3::from_coords).collect()
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
                .map(|a| Point::from_coords(&a[..a.len().min(dim)]))
                .collect(),
            interaction_radius: graph.interaction_radius,
            kinematic: graph.kinematic.clone(),
            box_lower: graph
                .periodic_box
                .as_ref()
                .map(|b| Vector3::from_coords(&b.lower))
                .unwrap_or_default(),
            box_upper: graph
                .periodic_box
                .as_ref()
                .map(|b| Vector3::from_coords(&b.upper))
                .unwrap_or_default(),
            box_periodic: graph
                .periodic_box
                .as_ref()
                .map(|b| b.periodic.clone())
                .unwrap_or_default(),
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
        let anchors = self.anchor_coords(dim)?;
        let edges = self.edges(n)?;
        let graph = Graph {
            dim,
            types: self.types.clone(),
            masses: self.masses.clone(),
            edges,
            anchors,
            interaction_radius: self.interaction_radius,
            kinematic: self.kinematic.clone(),
            periodic_box: self.periodic_box(dim),
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
