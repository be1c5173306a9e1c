//! Training bags into training data: the dataset of every bag's trajectories,
//! and what a model file records about them (digests, fingerprints, the
//! system's configuration, whether it is closed).

use std::path::{Path, PathBuf};

use super::bag::{read_bags, Bag, ReadOptions};
use super::dataset::{AccSource, Dataset};
use super::field::{bag_field, bag_system};
use crate::error::{bail, Result};
use crate::gnode::file::{EdgeParams, TrainedOn};
use crate::physics::SystemConfig;
use crate::system::{fingerprint, Trajectory};

/// Training data read from bags: the dataset and what a model file records about it.
pub struct TrainingData {
    /// States and target accelerations on one graph.
    pub dataset: Dataset,
    /// What the model file says about its training data.
    pub trained_on: TrainedOn,
    /// The simulator configuration from the first bag's metadata, if any.
    pub system_config: Option<SystemConfig>,
    /// Whether the data are a closed system (no anchors, no field), and why:
    /// `None` when the bags neither say nor show it.
    pub closed: Option<(bool, String)>,
}

/// Reads training bags (each an MCAP file, a rosbag2 directory or a .db3
/// file) into a dataset ([`load_training_data_from`] on the only
/// ParticleState topic).
pub fn load_training_data(bags: &[PathBuf], log: impl FnMut(&str)) -> Result<TrainingData> {
    load_training_data_from(bags, None, log)
}

/// Reads training bags into a dataset (recorded accelerations, else finite
/// differences; `log` says which) with fingerprints of every trajectory's
/// start, reading `topic` (needed when a bag holds several ParticleState
/// topics).
pub fn load_training_data_from(
    bags: &[PathBuf],
    topic: Option<&str>,
    mut log: impl FnMut(&str),
) -> Result<TrainingData> {
    if bags.is_empty() {
        bail!("no training bags given");
    }
    let read = read_training_bags(bags, topic)?;
    let ds = Dataset::from_trajectories(&read.trajectories)?;
    let source = match ds.source {
        AccSource::Recorded => "recorded",
        AccSource::FiniteDifference => "finite-difference",
    };
    log(&format!(
        "{} states of {} trajectories ({}-particle {}D graph); accelerations: {source}",
        ds.len(),
        read.trajectories.len(),
        ds.graph.n(),
        ds.graph.dim
    ));
    let trained_on = trained_on(bags, &read, &ds, source)?;
    Ok(TrainingData {
        dataset: ds,
        trained_on,
        system_config: read.system_config,
        closed: read.closed,
    })
}

/// What the training bags hold, read one after the other.
struct BagsRead {
    /// Every bag's trajectories, in bag order.
    trajectories: Vec<Trajectory>,
    /// Each bag's [`bag_digest`], in bag order.
    digests: Vec<String>,
    /// The first simulator configuration a bag's metadata gives.
    system_config: Option<SystemConfig>,
    /// Whether all bags are a closed system, when they agree on it.
    closed: Option<(bool, String)>,
}

/// Reads each training bag on `topic`, gathering its trajectories, digest,
/// system configuration and closedness.
fn read_training_bags(bags: &[PathBuf], topic: Option<&str>) -> Result<BagsRead> {
    let mut out = BagsRead {
        trajectories: vec![],
        digests: vec![],
        system_config: None,
        closed: None,
    };
    let read = ReadOptions {
        topic: topic.map(str::to_string),
    };
    for p in bags {
        let bag = read_bags(std::slice::from_ref(p), &read)?;
        if out.system_config.is_none() {
            out.system_config = bag_system(&bag)?;
        }
        let this = bag_closed(&bag)?;
        out.closed = match (out.closed, this) {
            (None, t) if out.trajectories.is_empty() => t,
            (Some((a, why)), Some((b, _))) if a == b => Some((a, why)),
            _ => None,
        };
        out.digests.push(bag_digest(p)?);
        out.trajectories.extend(bag.trajectories);
    }
    Ok(out)
}

/// Whether one bag is a closed system, and why (`None`: it does not say).
fn bag_closed(bag: &Bag) -> Result<Option<(bool, String)>> {
    // Closed: no anchors and no field, as the bag states or its data show.
    Ok(match bag_field(bag, None)? {
        _ if bag.trajectories.iter().any(|t| !t.graph.anchors.is_empty()) => {
            Some((false, "anchors".to_string()))
        }
        Some(o) => Some((o.field.is_free(), o.source)),
        None => None,
    })
}

/// What the model file records about its training data: the bags (paths
/// and digests), the dataset's size, the accelerations' `source` and the
/// fingerprint of every trajectory's start.
fn trained_on(bags: &[PathBuf], read: &BagsRead, ds: &Dataset, source: &str) -> Result<TrainedOn> {
    let trajectories = &read.trajectories;
    let first = trajectories.first().expect("dataset is not empty");
    Ok(TrainedOn {
        system: first.system.clone(),
        particles: ds.graph.n(),
        dim: ds.graph.dim,
        bag: bags
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(","),
        bag_sha256: read.digests.join(","),
        accelerations: source.to_string(),
        trajectories: trajectories.len(),
        states: ds.len(),
        start_fingerprints: trajectories
            .iter()
            .filter_map(|t| t.samples.first())
            .map(|s| fingerprint(&s.state))
            .collect(),
        system_config: read
            .system_config
            .as_ref()
            .map(serde_json::to_value)
            .transpose()?,
        edge_params: EdgeParams::of(&ds.graph),
    })
}

/// SHA-256 of a bag argument: of its file, or of each storage file of a
/// rosbag2 directory joined by `+`.
fn bag_digest(p: &Path) -> Result<String> {
    let parts = super::source::bag_parts(p)?;
    Ok(parts
        .iter()
        .map(|part| super::dataset::digest(&part.path))
        .collect::<Result<Vec<_>, _>>()?
        .join("+"))
}
