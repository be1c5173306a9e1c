//! Other projects' datasets read into trajectories, to be written as bags.
//!
//! - [`tfrecord`]: TFRecord framing (lengths and masked CRC-32C, both checked).
//! - [`gns`]: the GNS datasets of Sanchez-Gonzalez et al. 2020
//!   (`tf.train.SequenceExample` records and their `metadata.json`).

pub mod gns;
pub mod tfrecord;

pub use gns::{
    encode_record, gns_trajectories, read_gns, GnsImport, GnsMetadata, GnsSource, KINEMATIC_TYPE,
};

use std::path::Path;

use crate::data::{write_trajectories_with_field, BagMetadata, DataError};
use crate::physics::Field;

/// Metadata key: the format a bag was imported from.
pub const KEY_IMPORTED_FROM: &str = "imported_from";
/// Metadata key: the file the trajectories were read from.
pub const KEY_IMPORT_SOURCE: &str = "import_source";
/// Metadata key: the dataset's own metadata (its text, as read).
pub const KEY_IMPORT_METADATA: &str = "import_metadata";
/// Metadata key: how the velocities were made.
pub const KEY_VELOCITIES: &str = "velocities";

/// Writes an imported GNS split as a bag at `out`, every message stating
/// `field` when given (GNS's metadata does not state gravity, so by default
/// the field is left unknown). Returns the number of states.
pub fn write_gns_bag(
    imp: &GnsImport,
    out: &Path,
    field: Option<&Field>,
) -> Result<usize, DataError> {
    let mut meta = BagMetadata {
        generator: Some(format!(
            "mcgnode {} bag import --from gns",
            env!("CARGO_PKG_VERSION")
        )),
        ..Default::default()
    };
    let put = |m: &mut BagMetadata, k: &str, v: String| m.other.insert(k.to_string(), v);
    put(&mut meta, KEY_IMPORTED_FROM, "gns".into());
    put(
        &mut meta,
        KEY_IMPORT_SOURCE,
        imp.records.display().to_string(),
    );
    put(&mut meta, KEY_IMPORT_METADATA, imp.metadata.1.clone());
    put(
        &mut meta,
        KEY_VELOCITIES,
        format!(
            "finite differences of the stored positions, (q_t - q_(t-1)) / dt with dt = {:?} \
             (the first state: (q_1 - q_0) / dt)",
            imp.meta.dt
        ),
    );
    write_trajectories_with_field(out, &imp.trajectories, &meta.to_map()?, field)?;
    Ok(imp.trajectories.iter().map(|t| t.samples.len()).sum())
}
