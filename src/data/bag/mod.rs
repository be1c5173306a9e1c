//! MCAP bags in the ROS 2 convention (profile `ros2`, `ros2msg` schemas, `cdr`
//! messages, zstd chunks): a streaming writer for any topics, and reading
//! `ParticleState` trajectories back with full validation.
//!
//! - [`write`](mod@write): the streaming writer, and writing trajectories as a bag.
//! - [`commit`]: a file that is a readable MCAP after every finished chunk.
//! - [`scan`]: every message of a bag argument in order, as stored (MCAP,
//!   rosbag2 sqlite3 and directories, decompressed).
//! - `schema`: which ParticleState layout a bag's schema declares.
//! - [`read`]: ParticleState messages back into validated trajectories.

pub mod commit;
pub mod read;
pub mod scan;
mod schema;
pub mod write;

pub use read::{read_bags, read_trajectories, Bag, ReadOptions};
pub use scan::{scan_bag, scan_input, MetadataRecords, RawMessage};
pub use write::{
    write_positions_only, write_trajectories, write_trajectories_with_field, BagWriter, ChannelId,
};

/// Topic the trajectories are written on.
pub const PARTICLE_STATE_TOPIC: &str = "/particle_state";
/// Name of the metadata record that holds the bag's key/value metadata.
pub const METADATA_NAME: &str = "mcgnode";
