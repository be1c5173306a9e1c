//! The earlier layouts of `ParticleState`, kept so that bags written with
//! them stay readable, and decoding CDR bytes of any layout.

use serde::{Deserialize, Serialize};

use super::cdr::decode_cdr;
use super::particle_state::{ParticleState, FIELD_UNKNOWN};
use super::ros_types::{Header, Point, Vector3};
use crate::data::DataError;

/// The first layout of the message (before `field_status`, `gravity`, `drag` and
/// `force`), kept so that bags written with it stay readable.
pub const PARTICLE_STATE_MSG_V1: &str = include_str!("particle_state_v1.msg");

/// The third layout (before the periodic box), kept so that bags written
/// with it stay readable.
pub const PARTICLE_STATE_MSG_V3: &str = include_str!("particle_state_v3.msg");

/// The second layout (before `interaction_radius` and `kinematic`), kept so
/// that bags written with it stay readable.
pub const PARTICLE_STATE_MSG_V2: &str = include_str!("particle_state_v2.msg");

/// The message in its third layout ([`PARTICLE_STATE_MSG_V3`]): what bags
/// written before periodic boxes hold. Decodes into a [`ParticleState`]
/// without a box.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParticleStateV3 {
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
    /// See [`ParticleState::interaction_radius`].
    pub interaction_radius: f64,
    /// See [`ParticleState::kinematic`].
    pub kinematic: Vec<bool>,
}

impl From<ParticleStateV3> for ParticleState {
    fn from(m: ParticleStateV3) -> Self {
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
            interaction_radius: m.interaction_radius,
            kinematic: m.kinematic,
            ..ParticleState::default()
        }
    }
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
            ..ParticleState::default()
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
    /// [`PARTICLE_STATE_MSG_V3`] (before periodic boxes).
    V3,
    /// [`PARTICLE_STATE_MSG_V2`] (before contacts).
    V2,
    /// [`PARTICLE_STATE_MSG_V1`].
    V1,
    /// No schema text to tell (e.g. an old sqlite3 bag): try both.
    Unknown,
}

impl ParticleState {
    /// Decodes CDR bytes (with encapsulation header) in this build's layout;
    /// garbage and truncated bytes give an error.
    pub fn from_cdr(bytes: &[u8]) -> Result<ParticleState, DataError> {
        Self::from_cdr_as(bytes, Layout::Current)
    }

    /// Decodes CDR bytes in the given layout. [`Layout::Unknown`] (a bag that
    /// stores no definition) tries this build's layout, then the third
    /// ([`ParticleStateV3`], no box), the second
    /// ([`ParticleStateV2`], no contacts), then the first
    /// ([`ParticleStateV1`], field unknown): a whole message of one cannot
    /// pass for another (a shorter one is short of bytes, a longer one has
    /// more than 3 bytes over: each layout appends at least 12), but a message
    /// cut exactly at an older layout's end would read as that layout, so
    /// this is used only when the bag cannot say.
    pub fn from_cdr_as(bytes: &[u8], layout: Layout) -> Result<ParticleState, DataError> {
        match layout {
            Layout::Current => decode_cdr(bytes),
            Layout::V3 => decode_cdr::<ParticleStateV3>(bytes).map(ParticleState::from),
            Layout::V2 => decode_cdr::<ParticleStateV2>(bytes).map(ParticleState::from),
            Layout::V1 => decode_cdr::<ParticleStateV1>(bytes).map(ParticleState::from),
            Layout::Unknown => decode_cdr::<ParticleState>(bytes).or_else(|e| {
                decode_cdr::<ParticleStateV3>(bytes)
                    .map(ParticleState::from)
                    .or_else(|_| decode_cdr::<ParticleStateV2>(bytes).map(ParticleState::from))
                    .or_else(|_| decode_cdr::<ParticleStateV1>(bytes).map(ParticleState::from))
                    .map_err(|_| e)
            }),
        }
    }
}
