//! The LagrangeBench datasets (Toshev et al. 2023): `{train,valid,test}.h5`
//! beside a `metadata.json`, read with the pure-Rust `hdf5-reader` crate (no
//! libhdf5).
//!
//! Each HDF5 group is one trajectory: `position` (steps, particles, dim),
//! float32 or float64, and `particle_type` (particles,), integers. The
//! metadata gives `dim`, the solver's `dt` and `write_every` (so stored
//! frames are `dt · write_every` apart), `default_connectivity_radius` (the
//! interaction radius), `bounds` and `periodic_boundary_conditions` (one
//! flag per axis: a periodic axis makes the bag's box periodic there).
//!
//! Particle types follow LagrangeBench's `NodeType`: fluid (0) is free,
//! solid walls (1) and moving walls (2) are kinematic; rigid bodies (3) are
//! refused (their motion is neither free particles' nor given). Every mass
//! is 1. Velocities are not stored: they are the backward differences of the
//! positions over the frame interval (the first state takes the forward
//! one), each the minimum image on periodic axes so a particle wrapped
//! across a face keeps its speed.

use std::path::{Path, PathBuf};

use hdf5_reader::{Datatype, Hdf5File};

use super::frames::samples_from_frames;
use super::tfrecord::Damage;
use crate::data::DataError;
use crate::system::{Graph, PeriodicBox, Trajectory};

/// LagrangeBench's particle types (`lagrangebench.utils.NodeType`).
pub const FLUID: i64 = 0;
/// A wall that does not move.
pub const SOLID_WALL: i64 = 1;
/// A wall whose motion is given (a lid).
pub const MOVING_WALL: i64 = 2;
/// A rigid body (refused).
pub const RIGID_BODY: i64 = 3;

fn bad(path: &Path, msg: impl Into<String>) -> DataError {
    DataError::Import {
        path: path.to_path_buf(),
        msg: msg.into(),
    }
}

/// What a LagrangeBench `metadata.json` says that the import uses.
#[derive(Clone, Debug, PartialEq)]
pub struct LbMetadata {
    /// Spatial dimension, 2 or 3.
    pub dim: usize,
    /// Time between stored frames: `dt · write_every` (or `--dt`).
    pub frame_dt: f64,
    /// `default_connectivity_radius`.
    pub radius: f64,
    /// `bounds`, `[lo, hi]` per axis.
    pub bounds: Vec<[f64; 2]>,
    /// `periodic_boundary_conditions`, per axis.
    pub periodic: Vec<bool>,
}

impl LbMetadata {
    /// Reads the keys of a metadata.json text (`path` names it in errors);
    /// `frame_dt` replaces `dt · write_every`.
    pub fn from_json(text: &str, path: &Path, frame_dt: Option<f64>) -> Result<Self, DataError> {
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| bad(path, format!("not valid JSON: {e}")))?;
        let obj = v
            .as_object()
            .ok_or_else(|| bad(path, "not a JSON object"))?;
        let key = |k: &str| {
            obj.get(k)
                .ok_or_else(|| bad(path, format!("metadata key `{k}` is missing")))
        };
        let number = |k: &str| -> Result<f64, DataError> {
            let x = key(k)?;
            x.as_f64()
                .filter(|x| x.is_finite() && *x > 0.0)
                .ok_or_else(|| {
                    bad(
                        path,
                        format!("metadata key `{k}` is not a positive number: {x}"),
                    )
                })
        };
        let dim = number("dim")?;
        if dim != 2.0 && dim != 3.0 {
            return Err(bad(
                path,
                format!("metadata key `dim` is {dim}: expected 2 or 3"),
            ));
        }
        let dim = dim as usize;
        let frame_dt = match frame_dt {
            Some(dt) if dt.is_finite() && dt > 0.0 => dt,
            Some(dt) => return Err(bad(path, format!("--dt {dt} is not a positive number"))),
            None => number("dt")? * number("write_every")?,
        };
        let radius = number("default_connectivity_radius")?;
        let bounds = parse_bounds(key("bounds")?, dim).ok_or_else(|| {
            bad(
                path,
                format!("metadata key `bounds` is not {dim} pairs [lo, hi]"),
            )
        })?;
        let flags = key("periodic_boundary_conditions")?
            .as_array()
            .filter(|a| a.len() >= dim)
            .and_then(|a| a[..dim].iter().map(serde_json::Value::as_bool).collect());
        let periodic: Vec<bool> = flags.ok_or_else(|| {
            bad(
                path,
                format!("metadata key `periodic_boundary_conditions` is not {dim} booleans"),
            )
        })?;
        Ok(LbMetadata {
            dim,
            frame_dt,
            radius,
            bounds,
            periodic,
        })
    }

    /// The box of a periodic dataset (`None` when no axis wraps: the bounds
    /// are then walls, as wall particles show).
    pub fn periodic_box(&self) -> Option<PeriodicBox> {
        self.periodic.iter().any(|p| *p).then(|| PeriodicBox {
            lower: self.bounds.iter().map(|b| b[0]).collect(),
            upper: self.bounds.iter().map(|b| b[1]).collect(),
            periodic: self.periodic.clone(),
        })
    }
}

fn parse_bounds(b: &serde_json::Value, dim: usize) -> Option<Vec<[f64; 2]>> {
    let axes = b.as_array().filter(|a| a.len() == dim)?;
    axes.iter()
        .map(|p| match p.as_array().map(Vec::as_slice) {
            Some([lo, hi]) => {
                let (lo, hi) = (lo.as_f64()?, hi.as_f64()?);
                (lo.is_finite() && hi.is_finite() && lo < hi).then_some([lo, hi])
            }
            _ => None,
        })
        .collect()
}

/// A dataset's numbers as f64 (float32 widened exactly).
fn floats(ds: &hdf5_reader::Dataset) -> Result<Vec<f64>, Damage> {
    let e = |e: hdf5_reader::error::Error| Damage(e.to_string());
    match ds.dtype() {
        Datatype::FloatingPoint { size: 4, .. } => Ok(ds
            .read_array::<f32>()
            .map_err(e)?
            .iter()
            .map(|x| f64::from(*x))
            .collect()),
        Datatype::FloatingPoint { size: 8, .. } => {
            Ok(ds.read_array::<f64>().map_err(e)?.iter().copied().collect())
        }
        t => Err(Damage(format!("holds {t:?}: expected float32 or float64"))),
    }
}

/// A dataset's integers as i64.
fn integers(ds: &hdf5_reader::Dataset) -> Result<Vec<i64>, Damage> {
    fn all<T: hdf5_reader::H5Type + Copy + Into<i64>>(
        ds: &hdf5_reader::Dataset,
    ) -> Result<Vec<i64>, Damage> {
        let a = ds.read_array::<T>().map_err(|e| Damage(e.to_string()))?;
        Ok(a.iter().map(|x| (*x).into()).collect())
    }
    match ds.dtype() {
        Datatype::FixedPoint {
            size: 8,
            signed: true,
            ..
        } => all::<i64>(ds),
        Datatype::FixedPoint {
            size: 4,
            signed: true,
            ..
        } => all::<i32>(ds),
        Datatype::FixedPoint {
            size: 4,
            signed: false,
            ..
        } => all::<u32>(ds),
        Datatype::FixedPoint {
            size: 2,
            signed: true,
            ..
        } => all::<i16>(ds),
        Datatype::FixedPoint {
            size: 1,
            signed: true,
            ..
        } => all::<i8>(ds),
        Datatype::FixedPoint {
            size: 1,
            signed: false,
            ..
        } => all::<u8>(ds),
        t => Err(Damage(format!("holds {t:?}: expected integers"))),
    }
}

/// One group as a trajectory.
fn trajectory(
    group: &hdf5_reader::group::Group,
    id: u32,
    meta: &LbMetadata,
    system: &str,
) -> Result<Trajectory, Damage> {
    let dataset = |k: &str| group.dataset(k).map_err(|e| format!("dataset `{k}`: {e}"));
    let types = integers(&dataset("particle_type")?).map_err(|e| format!("`particle_type` {e}"))?;
    let pos = dataset("position")?;
    let (n, d) = (types.len(), meta.dim);
    match pos.shape() {
        [t, pn, pd] if *pn as usize == n && *pd as usize == d && *t >= 2 => {}
        s => {
            return Err(Damage(format!(
                "`position` has shape {s:?}: expected (steps ≥ 2, {n} particles, {d})"
            )))
        }
    }
    if let Some(t) = types
        .iter()
        .find(|t| ![FLUID, SOLID_WALL, MOVING_WALL].contains(*t))
    {
        return Err(Damage(format!(
            "particle type {t} is not fluid (0), a solid wall (1) or a moving wall (2){}",
            if *t == RIGID_BODY {
                ": rigid bodies are not supported"
            } else {
                ""
            }
        )));
    }
    let q = floats(&pos).map_err(|e| format!("`position` {e}"))?;
    if let Some(i) = q.iter().position(|x| !x.is_finite()) {
        return Err(Damage(format!("`position` value {i} is not finite")));
    }
    let kinematic: Vec<bool> = types.iter().map(|t| *t != FLUID).collect();
    let graph = Graph {
        dim: d,
        types: types.iter().map(|t| *t as u32).collect(),
        masses: vec![1.0; n],
        edges: vec![],
        anchors: vec![],
        interaction_radius: meta.radius,
        kinematic: if kinematic.contains(&true) {
            kinematic
        } else {
            vec![]
        },
        periodic_box: meta.periodic_box(),
    };
    graph.validate().map_err(|e| e.to_string())?;
    let frames: Vec<&[f64]> = q.chunks_exact(n * d).collect();
    let samples = samples_from_frames(&frames, d, meta.frame_dt, graph.periodic_box.as_ref());
    Ok(Trajectory {
        id,
        system: system.to_string(),
        graph,
        samples,
    })
}

/// A LagrangeBench dataset read: its trajectories, the metadata, the files.
#[derive(Clone, Debug)]
pub struct LbImport {
    /// One trajectory per group, in the groups' name order.
    pub trajectories: Vec<Trajectory>,
    /// What the metadata says.
    pub meta: LbMetadata,
    /// The HDF5 file read.
    pub file: PathBuf,
    /// The metadata file read, and its text.
    pub metadata: (PathBuf, String),
}

/// Reads split `split` (`train`, `valid`, `test`) of the LagrangeBench
/// dataset in `dir` (`{split}.h5` and `metadata.json`); `frame_dt`
/// replaces the metadata's frame interval.
pub fn read_lagrangebench(
    dir: &Path,
    split: &str,
    frame_dt: Option<f64>,
) -> Result<LbImport, DataError> {
    let file = dir.join(format!("{split}.h5"));
    if !file.is_file() {
        return Err(bad(&file, "not found: DIR must hold {train,valid,test}.h5"));
    }
    let meta_path = dir.join("metadata.json");
    let text = std::fs::read_to_string(&meta_path)
        .map_err(|e| DataError::io(&meta_path, "reading the metadata", e))?;
    let meta = LbMetadata::from_json(&text, &meta_path, frame_dt)?;
    let h5 =
        Hdf5File::open(&file).map_err(|e| bad(&file, format!("not a readable HDF5 file: {e}")))?;
    let mut groups = h5
        .root_group()
        .and_then(|r| r.groups())
        .map_err(|e| bad(&file, format!("listing the trajectories: {e}")))?;
    groups.sort_by(|a, b| a.name().cmp(b.name()));
    if groups.is_empty() {
        return Err(bad(&file, "holds no trajectory group"));
    }
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned());
    let system = format!("lagrangebench/{}", name.unwrap_or_default());
    let trajectories = groups
        .iter()
        .enumerate()
        .map(|(k, g)| {
            let id = g.name().parse().unwrap_or(k as u32);
            trajectory(g, id, &meta, &system)
                .map_err(|e| bad(&file, format!("group {:?}: {}", g.name(), e.0)))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(LbImport {
        trajectories,
        meta,
        file,
        metadata: (meta_path, text),
    })
}
