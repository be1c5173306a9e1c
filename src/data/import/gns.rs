//! The GNS datasets (Sanchez-Gonzalez et al. 2020, "Learning to simulate
//! complex physics with graph networks"): `{train,valid,test}.tfrecord`
//! files of `tf.train.SequenceExample`s beside a `metadata.json`.
//!
//! Each record is one trajectory: context `key` (int64) and `particle_type`
//! (bytes of little-endian int64, one per particle), and the feature list
//! `position` (per step, bytes of little-endian float32, N × dim). The
//! metadata gives `dim`, `dt` and `default_connectivity_radius` (also
//! `bounds`, `sequence_length` and the velocity/acceleration statistics,
//! kept as provenance).
//!
//! Particles of GNS's kinematic type ([`KINEMATIC_TYPE`], the boundary
//! particles) become kinematic; the others are free, with unit masses and
//! their GNS type ids. Positions are read as f32 and widened to f64 exactly.
//! Velocities are not stored: they are finite differences, as GNS computes
//! them, (q_t − q_{t−1}) / dt (the backward difference; the first state takes
//! the forward one, (q_1 − q_0) / dt). Accelerations are left unknown.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use prost::Message;

use super::frames::samples_from_frames;
use super::tfrecord::{self, Damage};
use crate::data::DataError;
use crate::system::{Graph, Trajectory};

/// GNS's particle type of kinematic (boundary) particles.
pub const KINEMATIC_TYPE: i64 = 3;
/// Largest particle type id accepted (GNS uses 0..=9; ids size a model's one-hot).
const MAX_TYPE: i64 = 255;

#[derive(Clone, PartialEq, Message)]
struct BytesList {
    #[prost(bytes = "vec", repeated, tag = "1")]
    value: Vec<Vec<u8>>,
}

#[derive(Clone, PartialEq, Message)]
struct FloatList {
    #[prost(float, repeated, tag = "1")]
    value: Vec<f32>,
}

#[derive(Clone, PartialEq, Message)]
struct Int64List {
    #[prost(int64, repeated, tag = "1")]
    value: Vec<i64>,
}

#[derive(Clone, PartialEq, prost::Oneof)]
enum Kind {
    #[prost(message, tag = "1")]
    Bytes(BytesList),
    #[prost(message, tag = "2")]
    Float(FloatList),
    #[prost(message, tag = "3")]
    Int64(Int64List),
}

#[derive(Clone, PartialEq, Message)]
struct Feature {
    #[prost(oneof = "Kind", tags = "1, 2, 3")]
    kind: Option<Kind>,
}

#[derive(Clone, PartialEq, Message)]
struct Features {
    #[prost(btree_map = "string, message", tag = "1")]
    feature: BTreeMap<String, Feature>,
}

#[derive(Clone, PartialEq, Message)]
struct FeatureList {
    #[prost(message, repeated, tag = "1")]
    feature: Vec<Feature>,
}

#[derive(Clone, PartialEq, Message)]
struct FeatureLists {
    #[prost(btree_map = "string, message", tag = "1")]
    feature_list: BTreeMap<String, FeatureList>,
}

#[derive(Clone, PartialEq, Message)]
struct SequenceExample {
    #[prost(message, optional, tag = "1")]
    context: Option<Features>,
    #[prost(message, optional, tag = "2")]
    feature_lists: Option<FeatureLists>,
}

/// What a GNS `metadata.json` says that the import uses.
#[derive(Clone, Debug, PartialEq)]
pub struct GnsMetadata {
    /// Spatial dimension, 2 or 3.
    pub dim: usize,
    /// Time between stored steps, seconds.
    pub dt: f64,
    /// `default_connectivity_radius`: the interaction radius.
    pub radius: f64,
    /// `bounds`, one `[lo, hi]` per axis, when given.
    pub bounds: Option<Vec<[f64; 2]>>,
}

fn bad(path: &Path, msg: impl Into<String>) -> DataError {
    DataError::Import {
        path: path.to_path_buf(),
        msg: msg.into(),
    }
}

impl GnsMetadata {
    /// Reads the keys of a metadata.json text (`path` names it in errors);
    /// `dt` replaces (or stands in for a missing) key `dt`.
    pub fn from_json(text: &str, path: &Path, dt: Option<f64>) -> Result<Self, DataError> {
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| bad(path, format!("not valid JSON: {e}")))?;
        let obj = v
            .as_object()
            .ok_or_else(|| bad(path, "not a JSON object"))?;
        let number = |key: &str, fix: &str| -> Result<f64, DataError> {
            let x = obj
                .get(key)
                .ok_or_else(|| bad(path, format!("metadata key `{key}` is missing{fix}")))?;
            x.as_f64()
                .ok_or_else(|| bad(path, format!("metadata key `{key}` is not a number: {x}")))
        };
        let d = number("dim", "")?;
        if d != 2.0 && d != 3.0 {
            return Err(bad(
                path,
                format!("metadata key `dim` is {d}: expected 2 or 3"),
            ));
        }
        let dt = match dt {
            Some(dt) => dt,
            None => number("dt", ": give the time between stored steps with --dt")?,
        };
        if !(dt.is_finite() && dt > 0.0) {
            return Err(bad(
                path,
                format!("time step dt = {dt} is not a positive number"),
            ));
        }
        let radius = number("default_connectivity_radius", "")?;
        if !(radius.is_finite() && radius > 0.0) {
            return Err(bad(
                path,
                format!("metadata key `default_connectivity_radius` = {radius} is not positive"),
            ));
        }
        let bounds = match obj.get("bounds") {
            None => None,
            Some(b) => Some(parse_bounds(b, d as usize).map_err(|m| bad(path, m.0))?),
        };
        Ok(GnsMetadata {
            dim: d as usize,
            dt,
            radius,
            bounds,
        })
    }
}

fn parse_bounds(b: &serde_json::Value, dim: usize) -> Result<Vec<[f64; 2]>, Damage> {
    let msg = || {
        Damage(format!(
            "metadata key `bounds` is not {dim} pairs [lo, hi]: {b}"
        ))
    };
    let axes = b.as_array().filter(|a| a.len() == dim).ok_or_else(msg)?;
    axes.iter()
        .map(|p| match p.as_array().map(Vec::as_slice) {
            Some([lo, hi]) => match (lo.as_f64(), hi.as_f64()) {
                (Some(lo), Some(hi)) if lo.is_finite() && hi.is_finite() && lo < hi => Ok([lo, hi]),
                _ => Err(msg()),
            },
            _ => Err(msg()),
        })
        .collect()
}

/// Little-endian numbers of a feature stored as bytes (or, for int64, as an
/// int64 list).
fn feature_bytes<'a>(f: &'a Feature, what: &str) -> Result<&'a [u8], Damage> {
    match &f.kind {
        Some(Kind::Bytes(b)) if b.value.len() == 1 => Ok(&b.value[0]),
        Some(Kind::Bytes(b)) => Err(Damage(format!(
            "`{what}` holds {} byte strings: expected 1",
            b.value.len()
        ))),
        _ => Err(Damage(format!("`{what}` is not a bytes feature"))),
    }
}

fn particle_types(ctx: &Features) -> Result<Vec<i64>, Damage> {
    let f = ctx
        .feature
        .get("particle_type")
        .ok_or("context feature `particle_type` is missing")?;
    if let Some(Kind::Int64(l)) = &f.kind {
        return Ok(l.value.clone());
    }
    let b = feature_bytes(f, "particle_type")?;
    if b.len() % 8 != 0 {
        return Err(Damage(format!(
            "`particle_type` holds {} bytes: not a whole number of int64",
            b.len()
        )));
    }
    Ok(b.chunks_exact(8)
        .map(|c| i64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
        .collect())
}

/// The positions of one record, `steps × n × dim` f32 widened to f64.
fn positions(lists: &FeatureLists, n: usize, dim: usize) -> Result<Vec<Vec<f64>>, Damage> {
    let steps = &lists
        .feature_list
        .get("position")
        .ok_or("feature list `position` is missing")?
        .feature;
    if steps.len() < 2 {
        return Err(Damage(format!(
            "feature list `position` has {} steps: at least 2 are needed (velocities are \
             differences)",
            steps.len()
        )));
    }
    let want = n * dim * 4;
    steps
        .iter()
        .enumerate()
        .map(|(t, f)| {
            let b = feature_bytes(f, "position")?;
            if b.len() != want {
                return Err(Damage(format!(
                    "`position` step {t} holds {} bytes: expected {n} particles × {dim} × 4 = \
                     {want} (shape (steps, particles, dim) float32)",
                    b.len()
                )));
            }
            let q: Vec<f64> = b
                .chunks_exact(4)
                .map(|c| f64::from(f32::from_le_bytes(c.try_into().unwrap_or([0; 4]))))
                .collect();
            if let Some(i) = q.iter().position(|x| !x.is_finite()) {
                return Err(Damage(format!(
                    "`position` step {t}: value {i} is not finite"
                )));
            }
            Ok(q)
        })
        .collect()
}

/// One decoded record as a trajectory (`id` unless the context has a `key`).
fn trajectory(
    record: &[u8],
    id: u32,
    meta: &GnsMetadata,
    system: &str,
) -> Result<Trajectory, Damage> {
    let ex = SequenceExample::decode(record).map_err(|e| format!("not a SequenceExample: {e}"))?;
    let ctx = ex.context.ok_or("no context features")?;
    let id = match ctx.feature.get("key").map(|f| &f.kind) {
        None => id,
        Some(Some(Kind::Int64(l))) if l.value.len() == 1 => u32::try_from(l.value[0])
            .map_err(|_| format!("context `key` {} is not a u32", l.value[0]))?,
        Some(_) => return Err("context `key` is not one int64".into()),
    };
    let types = particle_types(&ctx).map_err(|e| format!("key {id}: {e}"))?;
    if types.is_empty() {
        return Err(Damage(format!(
            "key {id}: `particle_type` lists no particle"
        )));
    }
    if let Some(t) = types.iter().find(|t| !(0..=MAX_TYPE).contains(*t)) {
        return Err(Damage(format!(
            "key {id}: particle type {t} is not in 0..={MAX_TYPE}"
        )));
    }
    let lists = ex
        .feature_lists
        .ok_or_else(|| format!("key {id}: no feature lists"))?;
    let (n, dim) = (types.len(), meta.dim);
    let qs = positions(&lists, n, dim).map_err(|e| format!("key {id}: {e}"))?;
    let kinematic: Vec<bool> = types.iter().map(|t| *t == KINEMATIC_TYPE).collect();
    let graph = Graph {
        dim,
        types: types.iter().map(|t| *t as u32).collect(),
        masses: vec![1.0; n],
        edges: vec![],
        anchors: vec![],
        interaction_radius: meta.radius,
        kinematic: if kinematic.iter().any(|k| *k) {
            kinematic
        } else {
            vec![]
        },
        // The GNS datasets' `bounds` are walls the particles stay within,
        // never a periodic box.
        periodic_box: None,
    };
    let samples = samples_from_frames(&qs, dim, meta.dt, None);
    Ok(Trajectory {
        id,
        system: system.to_string(),
        graph,
        samples,
    })
}

/// Every record of a GNS TFRecord file's bytes as a trajectory; errors name
/// `file`, the record and its key.
pub fn gns_trajectories(
    bytes: &[u8],
    file: &Path,
    meta: &GnsMetadata,
    system: &str,
) -> Result<Vec<Trajectory>, DataError> {
    let records = tfrecord::records(bytes).map_err(|e| bad(file, e.0))?;
    if records.is_empty() {
        return Err(bad(file, "holds no record"));
    }
    let mut ids = std::collections::BTreeSet::new();
    let mut out = Vec::with_capacity(records.len());
    for (k, r) in records.iter().enumerate() {
        let tr = trajectory(r, k as u32, meta, system)
            .map_err(|e| bad(file, format!("record {k}: {e}")))?;
        if !ids.insert(tr.id) {
            return Err(bad(
                file,
                format!("record {k}: key {} appears twice", tr.id),
            ));
        }
        out.push(tr);
    }
    Ok(out)
}

/// Where a GNS dataset is read from.
#[derive(Clone, Debug)]
pub struct GnsSource {
    /// A directory holding `metadata.json` and `{split}.tfrecord`, or a
    /// `.tfrecord` file (with `metadata`).
    pub src: PathBuf,
    /// The split read from a directory (`train`, `valid`, `test`).
    pub split: String,
    /// The metadata.json (default: `metadata.json` beside the records).
    pub metadata: Option<PathBuf>,
    /// Time between stored steps, replacing the metadata's `dt`.
    pub dt: Option<f64>,
}

/// A GNS dataset read: its trajectories, the metadata, and the files.
#[derive(Clone, Debug)]
pub struct GnsImport {
    /// One trajectory per record.
    pub trajectories: Vec<Trajectory>,
    /// What the metadata says.
    pub meta: GnsMetadata,
    /// The records file read.
    pub records: PathBuf,
    /// The metadata file read, and its text.
    pub metadata: (PathBuf, String),
}

/// Reads a GNS dataset split.
pub fn read_gns(s: &GnsSource) -> Result<GnsImport, DataError> {
    let (records, dir) = if s.src.is_dir() {
        (s.src.join(format!("{}.tfrecord", s.split)), s.src.clone())
    } else {
        let dir = s.src.parent().map(Path::to_path_buf).unwrap_or_default();
        (s.src.clone(), dir)
    };
    let meta_path = s
        .metadata
        .clone()
        .unwrap_or_else(|| dir.join("metadata.json"));
    let text = std::fs::read_to_string(&meta_path).map_err(|e| {
        DataError::io(
            &meta_path,
            "reading the metadata (give another with --metadata)",
            e,
        )
    })?;
    let meta = GnsMetadata::from_json(&text, &meta_path, s.dt)?;
    let bytes = std::fs::read(&records).map_err(|e| DataError::io(&records, "reading", e))?;
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let system = if name.is_empty() {
        "gns".to_string()
    } else {
        format!("gns/{name}")
    };
    let trajectories = gns_trajectories(&bytes, &records, &meta, &system)?;
    Ok(GnsImport {
        trajectories,
        meta,
        records,
        metadata: (meta_path, text),
    })
}

/// One trajectory framed as a GNS TFRecord record (`steps`: per step, the
/// n × dim positions), as GNS's files hold them: for tests and fuzzing.
pub fn encode_record(key: i64, types: &[i64], steps: &[Vec<f32>]) -> Vec<u8> {
    let bytes = |b: Vec<u8>| Feature {
        kind: Some(Kind::Bytes(BytesList { value: vec![b] })),
    };
    let mut context = BTreeMap::new();
    context.insert(
        "key".to_string(),
        Feature {
            kind: Some(Kind::Int64(Int64List { value: vec![key] })),
        },
    );
    let tb = types.iter().flat_map(|t| t.to_le_bytes()).collect();
    context.insert("particle_type".to_string(), bytes(tb));
    let feature = steps
        .iter()
        .map(|q| bytes(q.iter().flat_map(|x| x.to_le_bytes()).collect()))
        .collect();
    let mut lists = BTreeMap::new();
    lists.insert("position".to_string(), FeatureList { feature });
    let ex = SequenceExample {
        context: Some(Features { feature: context }),
        feature_lists: Some(FeatureLists {
            feature_list: lists,
        }),
    };
    tfrecord::frame(&ex.encode_to_vec())
}
