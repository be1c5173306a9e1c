//! The `mcgnode_msgs/msg/ParticleState` message: serde structs in wire order, CDR
//! encoding, the ros2msg schema text, and conversion to and from [`Graph`] + [`Sample`].
//!
//! The structs are plain serde structs so that both the MCAP bags and the ROS node
//! (ros2-client) can use them as they are.
//!
//! - [`particle_state`]: the message in this build's layout, its constants and conversions.
//! - [`layouts`]: its earlier layouts, and decoding bytes of any of them.
//! - [`ros_types`]: the standard ROS types it is built from (Time, Header, Vector3, Point).
//! - [`cdr`]: plain CDR with its encapsulation header.
//!
//! [`Graph`]: crate::system::Graph
//! [`Sample`]: crate::system::Sample

pub mod cdr;
pub mod layouts;
pub mod particle_state;
pub mod ros_types;

pub use cdr::{decode_cdr, encode_cdr, CDR_LE_HEADER};
pub use layouts::{
    Layout, ParticleStateV1, ParticleStateV2, ParticleStateV3, PARTICLE_STATE_MSG_V1,
    PARTICLE_STATE_MSG_V2, PARTICLE_STATE_MSG_V3,
};
pub use particle_state::{
    particle_state_schema, to_vec3, ParticleState, EDGE_BAR, EDGE_SPRING, FIELD_KNOWN,
    FIELD_UNKNOWN, FRAME_ID, PARTICLE_STATE_MSG, PARTICLE_STATE_TYPE,
};
pub use ros_types::{
    ros2msg_schema, Header, Point, Time, Vector3, DEP_HEADER, DEP_POINT, DEP_TIME, DEP_VECTOR3,
};
