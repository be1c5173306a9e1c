//! Writing MCAP bags: a streaming writer for ROS 2 messages already encoded
//! as CDR, and whole trajectories written as ParticleState messages.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata};

use super::{METADATA_NAME, PARTICLE_STATE_TOPIC};
use crate::data::msg::{particle_state_schema, ParticleState, Time, PARTICLE_STATE_TYPE};
use crate::data::DataError;
use crate::physics::Field;
use crate::system::Trajectory;

/// A channel of a [`BagWriter`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ChannelId(pub u16);

/// Streaming MCAP writer for ROS 2 messages already encoded as CDR.
///
/// Call [`BagWriter::finish`]: dropping also completes the file, but silently
/// ignores any error.
pub struct BagWriter<W: Write + Seek = BufWriter<File>> {
    inner: mcap::Writer<W>,
    path: PathBuf,
    sequences: HashMap<u16, u32>,
}

impl BagWriter<BufWriter<File>> {
    /// Creates (truncates) `path` and starts a bag in it.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, DataError> {
        let path = path.as_ref();
        let file = File::create(path).map_err(|e| DataError::io(path, "creating", e))?;
        Self::with_path(BufWriter::new(file), path.to_path_buf())
    }
}

impl<W: Write + Seek> BagWriter<W> {
    /// Starts a bag on any seekable stream.
    pub fn new(w: W) -> Result<Self, DataError> {
        Self::with_path(w, PathBuf::from("<stream>"))
    }

    /// Starts a bag on any seekable stream; errors name `path` (the file it writes).
    pub fn with_path(w: W, path: PathBuf) -> Result<Self, DataError> {
        Self::with_chunk_size(w, path, Some(mcap::WriteOptions::DEFAULT_CHUNK_SIZE))
    }

    /// [`BagWriter::with_path`] with chunks finished at `chunk_size`
    /// uncompressed bytes (MCAP's default: 1 MiB), or (`None`) only by
    /// [`BagWriter::finish_chunk`].
    pub fn with_chunk_size(
        w: W,
        path: PathBuf,
        chunk_size: Option<u64>,
    ) -> Result<Self, DataError> {
        let inner = mcap::WriteOptions::new()
            .chunk_size(chunk_size)
            .profile("ros2")
            .library(format!("mcgnode {}", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            // Single-threaded zstd: deterministic output, no worker threads in the node.
            .compression_threads(0)
            .create(w)
            .map_err(|e| DataError::McapWrite {
                path: path.clone(),
                msg: e.to_string(),
            })?;
        Ok(BagWriter {
            inner,
            path,
            sequences: HashMap::new(),
        })
    }

    fn err(&self, e: mcap::McapError) -> DataError {
        DataError::McapWrite {
            path: self.path.clone(),
            msg: e.to_string(),
        }
    }

    /// Adds a topic with a `ros2msg` schema (e.g. `mcgnode_msgs/msg/ParticleState`
    /// and its full text with dependency blocks) and `cdr` messages. Adding the same
    /// topic and schema twice returns the same channel.
    pub fn add_channel(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema_text: &str,
    ) -> Result<ChannelId, DataError> {
        let schema = self
            .inner
            .add_schema(schema_name, "ros2msg", schema_text.as_bytes())
            .map_err(|e| self.err(e))?;
        let id = self
            .inner
            .add_channel(schema, topic, "cdr", &BTreeMap::new())
            .map_err(|e| self.err(e))?;
        Ok(ChannelId(id))
    }

    /// Adds a `ParticleState` topic.
    pub fn add_particle_state_channel(&mut self, topic: &str) -> Result<ChannelId, DataError> {
        self.add_channel(topic, PARTICLE_STATE_TYPE, &particle_state_schema())
    }

    /// Writes one message: `cdr` must include the encapsulation header.
    pub fn write(
        &mut self,
        channel: ChannelId,
        log_time_ns: u64,
        cdr: &[u8],
    ) -> Result<(), DataError> {
        let seq = self.sequences.entry(channel.0).or_insert(0);
        *seq = seq.wrapping_add(1);
        let header = MessageHeader {
            channel_id: channel.0,
            sequence: *seq,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.inner
            .write_to_known_channel(&header, cdr)
            .map_err(|e| self.err(e))
    }

    /// Encodes and writes a `ParticleState`, logged at its header stamp
    /// (negative stamps are logged at 0).
    pub fn write_particle_state(
        &mut self,
        channel: ChannelId,
        msg: &ParticleState,
    ) -> Result<(), DataError> {
        let t = u64::try_from(msg.header.stamp.as_nanos()).unwrap_or(0);
        self.write(channel, t, &msg.to_cdr()?)
    }

    /// Writes a metadata record (key/value strings under a name).
    pub fn add_metadata(
        &mut self,
        name: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<(), DataError> {
        self.inner
            .write_metadata(&Metadata {
                name: name.to_string(),
                metadata: metadata.clone(),
            })
            .map_err(|e| self.err(e))
    }

    /// Finishes the open chunk, if any (its message indexes written after
    /// it), and flushes the stream: what was written is then whole records.
    pub fn finish_chunk(&mut self) -> Result<(), DataError> {
        self.inner.flush().map_err(|e| self.err(e))
    }

    /// Writes the summary and footer, flushes, and returns the stream.
    pub fn finish(mut self) -> Result<W, DataError> {
        self.inner.finish().map_err(|e| self.err(e))?;
        let path = self.path.clone();
        let mut w = self.inner.into_inner();
        w.flush().map_err(|e| DataError::io(path, "flushing", e))?;
        Ok(w)
    }
}

/// Checks what must hold for a trajectory to be written and read back unchanged.
fn check_trajectory(tr: &Trajectory) -> Result<(), DataError> {
    let bad = |m: String| Err(DataError::Trajectory(format!("trajectory {}: {m}", tr.id)));
    if let Err(e) = tr.graph.validate() {
        return bad(e.to_string());
    }
    if tr.samples.is_empty() {
        return bad("has no samples".into());
    }
    if u32::try_from(tr.samples.len()).is_err() {
        return bad("has more than 2^32 samples".into());
    }
    let mut last_ns = None;
    for (k, s) in tr.samples.iter().enumerate() {
        if let Err(e) = s.state.validate(&tr.graph) {
            return bad(format!("sample {k}: {e}"));
        }
        if !(s.t.is_finite() && s.t >= 0.0 && s.t < f64::from(i32::MAX)) {
            return bad(format!(
                "sample {k}: time {} is not in [0, 2^31) seconds",
                s.t
            ));
        }
        let ns = Time::from_secs(s.t).as_nanos();
        if last_ns.is_some_and(|l| ns <= l) {
            return bad(format!(
                "sample {k}: time {} is not after the previous sample's (at 1 ns resolution)",
                s.t
            ));
        }
        last_ns = Some(ns);
        if let Some(a) = &s.acc {
            if a.len() != tr.graph.ndof() || a.iter().any(|x| !x.is_finite()) {
                return bad(format!(
                    "sample {k}: accelerations are not {} finite numbers",
                    tr.graph.ndof()
                ));
            }
        }
    }
    Ok(())
}

/// Writes trajectories as `ParticleState` messages on [`PARTICLE_STATE_TOPIC`]
/// (step = sample index, stamp = sample time) plus the metadata record
/// [`METADATA_NAME`]. Written to a temporary file beside `path`, then renamed, so
/// `path` is either the old file or the complete new one. The messages leave
/// the field unknown: use [`write_trajectories_with_field`] when it is known.
pub fn write_trajectories(
    path: impl AsRef<Path>,
    trajectories: &[Trajectory],
    metadata: &BTreeMap<String, String>,
) -> Result<(), DataError> {
    write_trajectories_with_field(path, trajectories, metadata, None)
}

/// [`write_trajectories`], with every message stating `field` (the uniform
/// field, drag and force acting; `None`: unknown).
pub fn write_trajectories_with_field(
    path: impl AsRef<Path>,
    trajectories: &[Trajectory],
    metadata: &BTreeMap<String, String>,
    field: Option<&Field>,
) -> Result<(), DataError> {
    write_bag(path.as_ref(), trajectories, metadata, field, false)
}

/// [`write_trajectories_with_field`] as a tracker reports the states:
/// positions only (`velocities` and `accelerations` left empty), which the
/// reader and the node then estimate.
pub fn write_positions_only(
    path: impl AsRef<Path>,
    trajectories: &[Trajectory],
    metadata: &BTreeMap<String, String>,
    field: Option<&Field>,
) -> Result<(), DataError> {
    write_bag(path.as_ref(), trajectories, metadata, field, true)
}

fn write_bag(
    path: &Path,
    trajectories: &[Trajectory],
    metadata: &BTreeMap<String, String>,
    field: Option<&Field>,
    positions_only: bool,
) -> Result<(), DataError> {
    if let (Some(f), Some(tr)) = (field, trajectories.first()) {
        f.validate(tr.graph.dim)
            .map_err(|e| DataError::Trajectory(format!("field: {e}")))?;
    }
    let mut ids = std::collections::BTreeSet::new();
    for tr in trajectories {
        check_trajectory(tr)?;
        if !ids.insert(tr.id) {
            return Err(DataError::Trajectory(format!(
                "trajectory id {} appears twice",
                tr.id
            )));
        }
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".mcgnode-bag-").suffix(".tmp");
    // Temporary files are private (0600) by default; a bag is an ordinary file.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let mut tmp = builder
        .tempfile_in(dir)
        .map_err(|e| DataError::io(dir, "creating a temporary file in", e))?;
    let mut w = BagWriter::with_path(BufWriter::new(tmp.as_file_mut()), path.to_path_buf())?;
    w.add_metadata(METADATA_NAME, metadata)?;
    let ch = w.add_particle_state_channel(PARTICLE_STATE_TOPIC)?;
    for tr in trajectories {
        for (k, s) in tr.samples.iter().enumerate() {
            let mut msg = ParticleState::from_sample(tr.id, k as u32, &tr.system, &tr.graph, s)
                .with_field(field);
            if positions_only {
                msg.velocities.clear();
                msg.accelerations.clear();
            }
            w.write_particle_state(ch, &msg)?;
        }
    }
    w.finish()?;
    tmp.as_file()
        .sync_all()
        .map_err(|e| DataError::io(path, "syncing", e))?;
    tmp.persist(path)
        .map_err(|e| DataError::io(path, "renaming the temporary file to", e.error))?;
    Ok(())
}
