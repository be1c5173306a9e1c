//! Trajectories on disk: ROS 2 `mcgnode_msgs/msg/ParticleState` messages in MCAP
//! bags, and turning trajectories into training samples.
//!
//! - [`msg`]: the message structs (CDR, shared with the ROS node) and their schema.
//! - [`bag`]: writing and reading MCAP bags.
//! - [`dataset`]: states and target accelerations for training; bag digests.

pub mod bag;
pub mod dataset;
mod error;
pub mod msg;

pub use bag::{
    read_trajectories, scan_bag, write_trajectories, Bag, BagWriter, ChannelId, MetadataRecords,
    RawMessage, METADATA_NAME, PARTICLE_STATE_TOPIC,
};
pub use dataset::{digest, AccSource, Dataset};
pub use error::DataError;
pub use msg::ParticleState;
