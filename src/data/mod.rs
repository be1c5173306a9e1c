//! Trajectories on disk: ROS 2 `mcgnode_msgs/msg/ParticleState` messages in MCAP
//! bags, and turning trajectories into training samples.
//!
//! - [`msg`]: the message structs (CDR, shared with the ROS node) and their schema.
//! - [`bag`]: writing MCAP bags; reading MCAP, rosbag2 directories and .db3.
//! - [`source`]: the storage files of a bag argument and their compression.
//! - [`meta`]: the `mcgnode` metadata record, typed.
//! - [`field`]: what a bag says about its system (configuration, field).
//! - [`import`]: other projects' datasets (GNS TFRecords) as trajectories.
//! - [`repair`]: rewriting an MCAP file cut short as a complete one.
//! - [`dataset`]: states and target accelerations for training; bag digests.
//! - [`load`]: training bags into a dataset and what a model file records about it.
//! - [`observe`]: trajectories as a tracker sees them (noise, uneven rate, gaps).
//! - [`stream`]: velocities of live position-only streams, causally (node, replay).

pub mod bag;
pub mod dataset;
mod error;
pub mod field;
pub mod import;
pub mod load;
pub mod meta;
pub mod msg;
pub mod observe;
pub mod repair;
pub mod source;
pub mod stream;

pub use bag::{
    read_bags, read_trajectories, scan_bag, scan_input, write_positions_only, write_trajectories,
    write_trajectories_with_field, Bag, BagWriter, ChannelId, MetadataRecords, RawMessage,
    ReadOptions, METADATA_NAME, PARTICLE_STATE_TOPIC,
};
pub use dataset::{digest, AccSource, Dataset};
pub use error::DataError;
pub use meta::BagMetadata;
pub use msg::ParticleState;
