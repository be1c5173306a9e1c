//! Reading `ParticleState` trajectories back from bag arguments, grouped,
//! sorted and validated.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::scan::scan_input;
use super::schema::check_schema;
use super::METADATA_NAME;
use crate::data::msg::{Layout, ParticleState, PARTICLE_STATE_TYPE};
use crate::data::DataError;
use crate::physics::Field;
use crate::system::{Sample, Trajectory};

/// The content of a trajectory bag.
#[derive(Clone, Debug, PartialEq)]
pub struct Bag {
    /// Trajectories, sorted by id; samples sorted by step, `t` from the first stamp.
    pub trajectories: Vec<Trajectory>,
    /// The `mcgnode` metadata record (empty if absent): provenance only.
    pub metadata: BTreeMap<String, String>,
    /// The field every message states (`None`: the messages do not say, e.g.
    /// bags of the first message layout).
    pub field: Option<Field>,
    /// The ParticleState topic read ("" when there was none; several bag
    /// arguments with differently named topics: the names, comma-separated).
    pub topic: String,
    /// The bag arguments read, in order.
    pub sources: Vec<PathBuf>,
    /// Trajectories whose messages left `velocities` empty (position-only
    /// recordings): their velocities were derived from the positions and
    /// stamps ([`crate::data::dataset::finite_difference_velocities`]).
    pub derived_velocities: Vec<u32>,
}

impl Bag {
    /// The `mcgnode` metadata record, typed; a value that does not parse is
    /// an error naming its key.
    pub fn meta(&self) -> Result<crate::data::meta::BagMetadata, DataError> {
        crate::data::meta::BagMetadata::from_map(&self.metadata)
    }
}

/// One decoded message kept for grouping.
struct Entry {
    id: u32,
    index: usize,
    file: PathBuf,
    step: u32,
    stamp_ns: i64,
    system: String,
    graph: crate::system::Graph,
    sample: Sample,
    field: Option<Field>,
    /// The message left `velocities` empty.
    no_v: bool,
}

/// How to read trajectories from bags.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// The ParticleState topic to read; `None` reads the only one there is
    /// and refuses (listing them) when there are several.
    pub topic: Option<String>,
}

/// Reads every `ParticleState` message of one bag argument (an MCAP file, a
/// .db3 file or a rosbag2 directory; see [`read_bags`]) on its only
/// ParticleState topic.
pub fn read_trajectories(path: impl AsRef<Path>) -> Result<Bag, DataError> {
    read_bags(&[path.as_ref().to_path_buf()], &ReadOptions::default())
}

/// Reads the `ParticleState` messages of one or more bag arguments (each an
/// MCAP file, a rosbag2 sqlite3 file, or a rosbag2 directory) into
/// trajectories: grouped by `trajectory_id` within each argument (a rosbag2
/// directory split into several files is one argument), sorted by step, `t`
/// measured from the trajectory's first stamp. Trajectories of different
/// arguments are concatenated in argument order (their ids may repeat).
///
/// Refuses: several ParticleState topics without [`ReadOptions::topic`] (the
/// error lists them), a topic that is not there, messages that disagree on the
/// field they state, and arguments whose `mcgnode` metadata disagree on a key.
/// Everything is validated; errors name the file, the message and the problem.
pub fn read_bags(paths: &[PathBuf], opts: &ReadOptions) -> Result<Bag, DataError> {
    if paths.is_empty() {
        return Err(DataError::Trajectory("no bag given".into()));
    }
    let mut out = Bag {
        trajectories: vec![],
        metadata: BTreeMap::new(),
        field: None,
        topic: String::new(),
        sources: paths.to_vec(),
        derived_velocities: vec![],
    };
    let mut field_from: Option<(PathBuf, Option<Field>)> = None;
    let mut meta_from: BTreeMap<String, PathBuf> = BTreeMap::new();
    for path in paths {
        let (bag, topic) = read_one(path, opts)?;
        // Each argument has one ParticleState topic (or the one chosen); they
        // may be named differently.
        if out.topic.is_empty() {
            out.topic = topic;
        } else if !topic.is_empty() && !out.topic.split(',').any(|t| t == topic) {
            out.topic = format!("{},{topic}", out.topic);
        }
        match &field_from {
            None => field_from = Some((path.clone(), bag.field.clone())),
            Some((p, f))
                if f.as_ref().map(Field::normalized)
                    != bag.field.as_ref().map(Field::normalized) =>
            {
                return Err(DataError::Trajectory(format!(
                    "{} and {} state different fields ({}; {}): read them separately",
                    p.display(),
                    path.display(),
                    describe_field(f.as_ref()),
                    describe_field(bag.field.as_ref())
                )))
            }
            Some(_) => {}
        }
        for (k, v) in bag.metadata {
            match out.metadata.get(&k) {
                Some(old) if *old != v => {
                    return Err(DataError::Trajectory(format!(
                        "{} and {} disagree on their mcgnode metadata {k:?}: read them separately",
                        meta_from[&k].display(),
                        path.display()
                    )))
                }
                Some(_) => {}
                None => {
                    meta_from.insert(k.clone(), path.clone());
                    out.metadata.insert(k, v);
                }
            }
        }
        out.trajectories.extend(bag.trajectories);
        out.derived_velocities.extend(bag.derived_velocities);
    }
    out.field = field_from.and_then(|(_, f)| f);
    Ok(out)
}

/// The field in words, for messages.
fn describe_field(f: Option<&Field>) -> String {
    match f {
        None => "field unknown".into(),
        Some(f) if f.is_free() => "no field".into(),
        Some(f) => format!(
            "gravity {}, drag {}, force {:?}",
            f.gravity, f.drag, f.force
        ),
    }
}

/// Reads one bag argument; returns it and the ParticleState topic read.
fn read_one(path: &Path, opts: &ReadOptions) -> Result<(Bag, String), DataError> {
    let (mut topics, metadata) = decode_messages(path, opts)?;
    let (topic, entries) = choose_topic(path, &mut topics, opts)?;
    let (field, groups) = group_by_trajectory(path, entries)?;
    let mut trajectories = Vec::with_capacity(groups.len());
    let mut derived_velocities = vec![];
    for (id, entries) in groups {
        let (tr, derived) = trajectory(path, id, entries)?;
        if derived {
            derived_velocities.push(id);
        }
        trajectories.push(tr);
    }
    Ok((
        Bag {
            trajectories,
            metadata,
            field,
            topic: topic.clone(),
            sources: vec![path.to_path_buf()],
            derived_velocities,
        },
        topic,
    ))
}

/// Decoded messages by topic.
type ByTopic = BTreeMap<String, Vec<Entry>>;
/// Decoded messages by trajectory id.
type ByTrajectory = BTreeMap<u32, Vec<Entry>>;

/// A bag whose content is inconsistent, with what is wrong.
fn bag_err(path: &Path, msg: String) -> DataError {
    DataError::Bag {
        path: path.to_path_buf(),
        msg,
    }
}

/// Decodes every ParticleState message of one bag argument (on the topic
/// `opts` names, if any), by topic, and the `mcgnode` metadata record.
fn decode_messages(
    path: &Path,
    opts: &ReadOptions,
) -> Result<(ByTopic, BTreeMap<String, String>), DataError> {
    let mut topics = ByTopic::new();
    let mut checked_schemas: Vec<(Vec<u8>, Layout)> = Vec::new();
    let records = scan_input(path, |raw| {
        if raw.schema_name != PARTICLE_STATE_TYPE {
            return Ok(());
        }
        if opts.topic.as_deref().is_some_and(|t| t != raw.topic) {
            return Ok(());
        }
        let layout =
            if let Some((_, l)) = checked_schemas.iter().find(|(s, _)| s == raw.schema_text) {
                *l
            } else {
                let l = check_schema(raw)?;
                checked_schemas.push((raw.schema_text.to_vec(), l));
                l
            };
        let msg = ParticleState::from_cdr_as(raw.data, layout)?;
        let field = msg.field()?;
        let (graph, sample, no_v) = msg.to_parts_positions_only()?;
        topics
            .entry(raw.topic.to_string())
            .or_default()
            .push(Entry {
                id: msg.trajectory_id,
                index: raw.index,
                file: raw.file.to_path_buf(),
                step: msg.step,
                stamp_ns: msg.header.stamp.as_nanos(),
                system: msg.system,
                graph,
                sample,
                field,
                no_v,
            });
        Ok(())
    })?;
    let mut metadata = BTreeMap::new();
    for (name, m) in records {
        if name == METADATA_NAME {
            metadata.extend(m);
        }
    }
    Ok((topics, metadata))
}

/// The topic to read and its messages: the one asked for, or the only one
/// there is; refuses (listing them) when there are several.
fn choose_topic(
    path: &Path,
    topics: &mut ByTopic,
    opts: &ReadOptions,
) -> Result<(String, Vec<Entry>), DataError> {
    Ok(match (topics.len(), &opts.topic) {
        (0, Some(t)) => {
            return Err(bag_err(
                path,
                format!("has no ParticleState messages on topic {t}"),
            ))
        }
        (0, None) => (String::new(), vec![]),
        (1, _) => topics.pop_first().expect("one topic"),
        _ => {
            let list: Vec<String> = topics
                .iter()
                .map(|(t, e)| format!("{t} ({} messages)", e.len()))
                .collect();
            return Err(bag_err(
                path,
                format!(
                    "has ParticleState messages on several topics: {}; choose one with --topic",
                    list.join(", ")
                ),
            ));
        }
    })
}

/// The messages grouped by trajectory id, and the field they all state
/// (refused when two messages state different fields).
fn group_by_trajectory(
    path: &Path,
    entries: Vec<Entry>,
) -> Result<(Option<Field>, ByTrajectory), DataError> {
    let mut field: Option<(Option<Field>, usize, PathBuf)> = None;
    let mut groups = ByTrajectory::new();
    for e in entries {
        match &field {
            None => field = Some((e.field.clone(), e.index, e.file.clone())),
            Some((f, i, file)) if *f != e.field => {
                return Err(bag_err(path, format!(
                    "message {} of {} states {}, message {} of {} states {}: one bag must describe one field",
                    i,
                    file.display(),
                    describe_field(f.as_ref()),
                    e.index,
                    e.file.display(),
                    describe_field(e.field.as_ref())
                )))
            }
            Some(_) => {}
        }
        groups.entry(e.id).or_default().push(e);
    }
    Ok((field.and_then(|(f, _, _)| f), groups))
}

/// Trajectory `id` from its messages: sorted by step, `t` from the first
/// stamp, checked for repeated steps, stamps out of order and a graph or
/// system that changes. Velocities the messages left empty are derived from
/// the positions (then the flag is true).
fn trajectory(
    path: &Path,
    id: u32,
    mut entries: Vec<Entry>,
) -> Result<(Trajectory, bool), DataError> {
    entries.sort_by_key(|e| e.step);
    let first = &entries[0];
    let (t0, graph, system) = (first.stamp_ns, first.graph.clone(), first.system.clone());
    let mut samples = Vec::with_capacity(entries.len());
    for (k, e) in entries.iter().enumerate() {
        if k > 0 {
            check_order(path, id, &entries[k - 1], e)?;
        }
        if e.graph != graph {
            return Err(bag_err(path, format!(
                "trajectory {id}: the graph (types, masses, edges or anchors) at step {} (message {}) differs from step {} (message {})",
                e.step, e.index, first.step, first.index
            )));
        }
        if e.system != system {
            return Err(bag_err(
                path,
                format!(
                    "trajectory {id}: system {:?} at step {} (message {}) differs from {:?}",
                    e.system, e.step, e.index, system
                ),
            ));
        }
        let mut s = e.sample.clone();
        s.t = (e.stamp_ns - t0) as f64 * 1e-9;
        samples.push(s);
    }
    let mut tr = Trajectory {
        id,
        system,
        graph,
        samples,
    };
    let derived = entries.iter().any(|e| e.no_v);
    if derived {
        let v = crate::data::dataset::finite_difference_velocities(&tr)
            .map_err(|e| bag_err(path, format!("position-only recording: {e}")))?;
        for ((s, e), v) in tr.samples.iter_mut().zip(&entries).zip(v) {
            if e.no_v {
                s.state.v = v;
            }
        }
    }
    Ok((tr, derived))
}

/// Refuses a message `e` of trajectory `id` whose step repeats, or whose
/// stamp is not after, that of the message before it (`prev`, by step).
fn check_order(path: &Path, id: u32, prev: &Entry, e: &Entry) -> Result<(), DataError> {
    if e.step == prev.step {
        return Err(bag_err(
            path,
            format!(
                "trajectory {id}: step {} appears twice (messages {} and {})",
                e.step, prev.index, e.index
            ),
        ));
    }
    if e.stamp_ns <= prev.stamp_ns {
        return Err(bag_err(
            path,
            format!(
                "trajectory {id}: step {} (message {}) is not stamped after step {} (message {})",
                e.step, e.index, prev.step, prev.index
            ),
        ));
    }
    Ok(())
}
