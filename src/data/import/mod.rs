//! Other projects' datasets read into trajectories, to be written as bags.
//!
//! - [`tfrecord`]: TFRecord framing (lengths and masked CRC-32C, both checked).
//! - [`gns`]: the GNS datasets of Sanchez-Gonzalez et al. 2020
//!   (`tf.train.SequenceExample` records and their `metadata.json`).
//! - [`lagrangebench`]: the LagrangeBench datasets (HDF5 groups and their
//!   `metadata.json`).

mod frames;
pub mod gns;
pub mod lagrangebench;
pub mod tfrecord;

pub use lagrangebench::{read_lagrangebench, LbImport, LbMetadata};

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
    let source = Imported {
        from: "gns",
        file: &imp.records,
        metadata: &imp.metadata.1,
        dt: imp.meta.dt,
    };
    write_imported(&source, &imp.trajectories, out, field)
}

/// Writes an imported LagrangeBench split as a bag at `out`, as
/// [`write_gns_bag`] does.
pub fn write_lagrangebench_bag(
    imp: &LbImport,
    out: &Path,
    field: Option<&Field>,
) -> Result<usize, DataError> {
    let source = Imported {
        from: "lagrangebench",
        file: &imp.file,
        metadata: &imp.metadata.1,
        dt: imp.meta.frame_dt,
    };
    write_imported(&source, &imp.trajectories, out, field)
}

/// Where imported trajectories came from, recorded in the bag's metadata.
struct Imported<'a> {
    from: &'a str,
    file: &'a Path,
    metadata: &'a str,
    dt: f64,
}

fn write_imported(
    src: &Imported,
    trajectories: &[crate::system::Trajectory],
    out: &Path,
    field: Option<&Field>,
) -> Result<usize, DataError> {
    let mut meta = BagMetadata {
        generator: Some(format!(
            "mcgnode {} bag import --from {}",
            env!("CARGO_PKG_VERSION"),
            src.from
        )),
        ..Default::default()
    };
    let put = |m: &mut BagMetadata, k: &str, v: String| m.other.insert(k.to_string(), v);
    put(&mut meta, KEY_IMPORTED_FROM, src.from.into());
    put(&mut meta, KEY_IMPORT_SOURCE, src.file.display().to_string());
    put(&mut meta, KEY_IMPORT_METADATA, src.metadata.to_string());
    put(
        &mut meta,
        KEY_VELOCITIES,
        format!(
            "finite differences of the stored positions, (q_t - q_(t-1)) / dt with dt = {:?} \
             (the first state: (q_1 - q_0) / dt)",
            src.dt
        ),
    );
    write_trajectories_with_field(out, trajectories, &meta.to_map()?, field)?;
    Ok(trajectories.iter().map(|t| t.samples.len()).sum())
}
