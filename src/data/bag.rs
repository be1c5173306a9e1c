//! MCAP bags in the ROS 2 convention (profile `ros2`, `ros2msg` schemas, `cdr`
//! messages, zstd chunks): a streaming writer for any topics, and reading
//! `ParticleState` trajectories back with full validation.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Read, Seek, Write};
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata, Record};
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::msg::{
    particle_state_schema, Layout, ParticleState, Time, PARTICLE_STATE_MSG, PARTICLE_STATE_MSG_V1,
    PARTICLE_STATE_MSG_V2, PARTICLE_STATE_TYPE,
};
use super::source::{bag_parts, decompress_file, scan_sqlite, Codec, Storage};
use super::DataError;
use crate::physics::Field;
use crate::system::{Sample, Trajectory};

/// Topic the trajectories are written on.
pub const PARTICLE_STATE_TOPIC: &str = "/particle_state";
/// Name of the metadata record that holds the bag's key/value metadata.
pub const METADATA_NAME: &str = "mcgnode";

/// Floor of the reader's size limit for one record or decompressed chunk (the
/// limit is the larger of this and the file size): roomy for any chunk we or
/// rosbag2 write, small enough that a corrupt length cannot exhaust memory.
const MIN_RECORD_LIMIT: u64 = 256 << 20;

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
        let inner = mcap::WriteOptions::new()
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

    /// Writes the summary and footer, flushes, and returns the stream.
    pub fn finish(mut self) -> Result<W, DataError> {
        self.inner.finish().map_err(|e| self.err(e))?;
        let path = self.path.clone();
        let mut w = self.inner.into_inner();
        w.flush().map_err(|e| DataError::io(path, "flushing", e))?;
        Ok(w)
    }
}

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
    /// stamps ([`super::dataset::finite_difference_velocities`]).
    pub derived_velocities: Vec<u32>,
}

impl Bag {
    /// The `mcgnode` metadata record, typed; a value that does not parse is
    /// an error naming its key.
    pub fn meta(&self) -> Result<super::meta::BagMetadata, DataError> {
        super::meta::BagMetadata::from_map(&self.metadata)
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

/// Metadata records of a bag: (name, key/values), in file order.
pub type MetadataRecords = Vec<(String, BTreeMap<String, String>)>;

/// One message as found in a bag, for [`scan_bag`] and [`scan_input`].
#[derive(Debug)]
pub struct RawMessage<'a> {
    /// 0-based index among all messages of its file.
    pub index: usize,
    /// Channel topic.
    pub topic: &'a str,
    /// Schema name, e.g. `mcgnode_msgs/msg/ParticleState` ("" if none).
    pub schema_name: &'a str,
    /// Schema encoding, e.g. `ros2msg` ("" when the bag stores no definition).
    pub schema_encoding: &'a str,
    /// Schema text.
    pub schema_text: &'a [u8],
    /// Message encoding, e.g. `cdr`.
    pub message_encoding: &'a str,
    /// Log time, ns.
    pub log_time: u64,
    /// The message bytes (as stored: [`scan_input`] decompresses them first).
    pub data: &'a [u8],
    /// The storage file the message is in.
    pub file: &'a Path,
}

struct SchemaInfo {
    name: String,
    encoding: String,
    data: Vec<u8>,
}

struct ChannelInfo {
    topic: String,
    schema_id: u16,
    message_encoding: String,
}

/// Reads a whole MCAP file in order, checking every CRC, the end magic and that
/// nothing follows it. Calls `on_message` for each message (bytes as stored);
/// an error from it is reported with the file, the message index and the topic.
/// Returns the metadata records (name, key/values) in file order.
pub fn scan_bag(
    path: impl AsRef<Path>,
    mut on_message: impl FnMut(&RawMessage) -> Result<(), DataError>,
) -> Result<MetadataRecords, DataError> {
    let path = path.as_ref();
    scan_mcap(path, path, &mut on_message)
}

/// Reads every message of one bag argument in order: an MCAP file, a rosbag2
/// sqlite3 file, or a rosbag2 directory (its files in the order metadata.yaml
/// lists them), see [`super::source`]. Compressed messages and files are
/// decompressed first, so `data` is always the CDR bytes. Returns the MCAP
/// metadata records of all files.
pub fn scan_input(
    path: impl AsRef<Path>,
    mut on_message: impl FnMut(&RawMessage) -> Result<(), DataError>,
) -> Result<MetadataRecords, DataError> {
    let mut records = Vec::new();
    for part in bag_parts(path.as_ref())? {
        let tmp = match part.file_compression {
            Some(c) => Some(decompress_file(&part.path, c)?),
            None => None,
        };
        let read_path = tmp.as_ref().map_or(part.path.as_path(), |t| t.path());
        let declared = part.message_compression;
        let mut inner = |raw: &RawMessage| -> Result<(), DataError> {
            match payload(raw.data, declared)? {
                None => on_message(raw),
                Some(bytes) => on_message(&RawMessage {
                    data: &bytes,
                    ..*raw
                }),
            }
        };
        match part.storage {
            Storage::Mcap => records.extend(scan_mcap(read_path, &part.path, &mut inner)?),
            Storage::Sqlite3 => scan_sqlite(read_path, |index, m| {
                let raw = RawMessage {
                    index,
                    topic: &m.topic,
                    schema_name: &m.msg_type,
                    schema_encoding: &m.definition.0,
                    schema_text: m.definition.1.as_bytes(),
                    message_encoding: &m.serialization,
                    log_time: u64::try_from(m.timestamp).unwrap_or(0),
                    data: &m.data,
                    file: &part.path,
                };
                inner(&raw).map_err(|e| DataError::Message {
                    path: part.path.clone(),
                    index,
                    topic: m.topic.clone(),
                    reason: Box::new(e),
                })
            })?,
        }
    }
    Ok(records)
}

/// The decompressed bytes of a per-message-compressed message (`None`: not
/// compressed). `declared` is the codec metadata.yaml names: then every
/// message must be compressed with it.
fn payload(data: &[u8], declared: Option<Codec>) -> Result<Option<Vec<u8>>, DataError> {
    match (Codec::sniff(data), declared) {
        (None, None) => Ok(None),
        (Some(found), d) if d.is_none_or(|d| d == found) => found.decompress(data).map(Some),
        (found, d) => Err(DataError::Cdr(format!(
            "metadata.yaml declares {} message compression, but the message is {}",
            d.map_or("no", Codec::name),
            found.map_or("not compressed", Codec::name)
        ))),
    }
}

fn scan_mcap(
    read_path: &Path,
    path: &Path,
    on_message: &mut dyn FnMut(&RawMessage) -> Result<(), DataError>,
) -> Result<MetadataRecords, DataError> {
    let mut file = File::open(read_path).map_err(|e| DataError::io(path, "opening", e))?;
    let len = file
        .metadata()
        .map_err(|e| DataError::io(path, "reading the size of", e))?
        .len();
    let mcap_err = |what: String| DataError::Mcap {
        path: path.to_path_buf(),
        msg: what,
    };
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_prevalidate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_check_finishes_after_end_magic(true)
            // Bounds what a corrupt length field can make the reader allocate; chunks
            // decompress to more than the file size, hence the floor.
            .with_record_length_limit(
                usize::try_from(len.max(MIN_RECORD_LIMIT)).unwrap_or(usize::MAX),
            ),
    );
    let mut schemas: HashMap<u16, SchemaInfo> = HashMap::new();
    let mut channels: HashMap<u16, ChannelInfo> = HashMap::new();
    let mut metadata = Vec::new();
    let (mut n_records, mut n_messages) = (0usize, 0usize);
    while let Some(event) = reader.next_event() {
        let event = event.map_err(|e| {
            mcap_err(format!(
                "{} (after {n_records} records)",
                describe_mcap_error(&e)
            ))
        })?;
        let (opcode, data) = match event {
            LinearReadEvent::ReadRequest(need) => {
                let buf = reader.insert(need);
                let got =
                    read_some(&mut file, buf).map_err(|e| DataError::io(path, "reading", e))?;
                reader.notify_read(got);
                continue;
            }
            LinearReadEvent::Record { opcode, data } => (opcode, data),
        };
        n_records += 1;
        let record = mcap::parse_record(opcode, data).map_err(|e| {
            mcap_err(format!(
                "record {n_records} (opcode {opcode:#04x}): {}",
                describe_mcap_error(&e)
            ))
        })?;
        match record {
            Record::Schema { header, data } => {
                schemas.insert(
                    header.id,
                    SchemaInfo {
                        name: header.name,
                        encoding: header.encoding,
                        data: data.into_owned(),
                    },
                );
            }
            Record::Channel(c) => {
                if c.schema_id != 0 && !schemas.contains_key(&c.schema_id) {
                    return Err(mcap_err(format!(
                        "channel {} ({}) refers to unknown schema {}",
                        c.id, c.topic, c.schema_id
                    )));
                }
                channels.insert(
                    c.id,
                    ChannelInfo {
                        topic: c.topic,
                        schema_id: c.schema_id,
                        message_encoding: c.message_encoding,
                    },
                );
            }
            Record::Message { header, data } => {
                let index = n_messages;
                n_messages += 1;
                let ch = channels.get(&header.channel_id).ok_or_else(|| {
                    mcap_err(format!(
                        "message {index} refers to unknown channel {}",
                        header.channel_id
                    ))
                })?;
                let schema = schemas.get(&ch.schema_id);
                let raw = RawMessage {
                    index,
                    topic: &ch.topic,
                    schema_name: schema.map_or("", |s| s.name.as_str()),
                    schema_encoding: schema.map_or("", |s| s.encoding.as_str()),
                    schema_text: schema.map_or(&[][..], |s| s.data.as_slice()),
                    message_encoding: &ch.message_encoding,
                    log_time: header.log_time,
                    data: &data,
                    file: path,
                };
                on_message(&raw).map_err(|e| DataError::Message {
                    path: path.to_path_buf(),
                    index,
                    topic: ch.topic.clone(),
                    reason: Box::new(e),
                })?;
            }
            Record::Metadata(m) => metadata.push((m.name, m.metadata)),
            _ => {}
        }
    }
    Ok(metadata)
}

/// `read` that retries on interruption; 0 means end of file.
fn read_some(file: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    loop {
        match file.read(buf) {
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            r => return r,
        }
    }
}

/// MCAP errors in words a user can act on.
fn describe_mcap_error(e: &mcap::McapError) -> String {
    use mcap::McapError as E;
    match e {
        E::BadMagic => "bad magic number (not an MCAP file, or damaged)".into(),
        E::UnexpectedEof => "file ends in the middle of a record (truncated?)".into(),
        E::Parse(inner) => format!("record parse failed: {inner}"),
        other => other.to_string(),
    }
}

/// The field declarations of a .msg text in order, then its constants sorted,
/// normalised (comments, spacing and `pkg/msg/Type` vs `pkg/Type` do not
/// matter; tools such as rosbags write constants first).
fn declarations(msg: &str) -> Vec<String> {
    let lines: Vec<String> = msg
        .lines()
        .map(|l| l.split('#').next().unwrap_or(""))
        .map(|l| {
            l.split_whitespace()
                .map(|w| w.replace("/msg/", "/"))
                .collect::<Vec<_>>()
                .join(" ")
        })
        .map(|l| l.replace(" = ", "=").replace(" =", "=").replace("= ", "="))
        .filter(|l| !l.is_empty())
        .collect();
    let (mut constants, fields): (Vec<String>, Vec<String>) =
        lines.into_iter().partition(|l| l.contains('='));
    constants.sort();
    let mut out = fields;
    out.push("--".into());
    out.extend(constants);
    out
}

/// Which layout a bag's ParticleState schema declares (otherwise CDR would
/// decode into the wrong fields): this build's, the second (before contacts),
/// the first one, or unknown when the bag stores no definition (old sqlite3
/// bags).
fn check_schema(raw: &RawMessage) -> Result<Layout, DataError> {
    if raw.message_encoding != "cdr" {
        return Err(DataError::Invalid(format!(
            "message encoding {:?}, expected \"cdr\"",
            raw.message_encoding
        )));
    }
    if raw.schema_text.is_empty() && raw.schema_encoding.is_empty() {
        return Ok(Layout::Unknown);
    }
    if raw.schema_encoding != "ros2msg" {
        return Err(DataError::Invalid(format!(
            "schema encoding {:?}, expected \"ros2msg\"",
            raw.schema_encoding
        )));
    }
    let text = String::from_utf8_lossy(raw.schema_text);
    let main = text
        .split(&"=".repeat(80))
        .next()
        .unwrap_or_default()
        .to_string();
    let decl = declarations(&main);
    if decl == declarations(PARTICLE_STATE_MSG) {
        Ok(Layout::Current)
    } else if decl == declarations(PARTICLE_STATE_MSG_V2) {
        Ok(Layout::V2)
    } else if decl == declarations(PARTICLE_STATE_MSG_V1) {
        Ok(Layout::V1)
    } else {
        Err(DataError::Invalid(
            "its ParticleState schema differs from this build's msg/ParticleState.msg (and from its earlier layouts)".into(),
        ))
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
    let mut topics: BTreeMap<String, Vec<Entry>> = BTreeMap::new();
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
    let bag_err = |msg: String| DataError::Bag {
        path: path.to_path_buf(),
        msg,
    };
    let (topic, entries) = match (topics.len(), &opts.topic) {
        (0, Some(t)) => {
            return Err(bag_err(format!(
                "has no ParticleState messages on topic {t}"
            )))
        }
        (0, None) => (String::new(), vec![]),
        (1, _) => topics.pop_first().expect("one topic"),
        _ => {
            let list: Vec<String> = topics
                .iter()
                .map(|(t, e)| format!("{t} ({} messages)", e.len()))
                .collect();
            return Err(bag_err(format!(
                "has ParticleState messages on several topics: {}; choose one with --topic",
                list.join(", ")
            )));
        }
    };
    let mut field: Option<(Option<Field>, usize, PathBuf)> = None;
    let mut groups: BTreeMap<u32, Vec<Entry>> = BTreeMap::new();
    for e in entries {
        match &field {
            None => field = Some((e.field.clone(), e.index, e.file.clone())),
            Some((f, i, file)) if *f != e.field => {
                return Err(bag_err(format!(
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
    let mut trajectories = Vec::with_capacity(groups.len());
    let mut derived_velocities = vec![];
    for (id, mut entries) in groups {
        entries.sort_by_key(|e| e.step);
        let first = &entries[0];
        let (t0, graph, system) = (first.stamp_ns, first.graph.clone(), first.system.clone());
        let mut samples = Vec::with_capacity(entries.len());
        for (k, e) in entries.iter().enumerate() {
            if k > 0 {
                let prev = &entries[k - 1];
                if e.step == prev.step {
                    return Err(bag_err(format!(
                        "trajectory {id}: step {} appears twice (messages {} and {})",
                        e.step, prev.index, e.index
                    )));
                }
                if e.stamp_ns <= prev.stamp_ns {
                    return Err(bag_err(format!(
                        "trajectory {id}: step {} (message {}) is not stamped after step {} (message {})",
                        e.step, e.index, prev.step, prev.index
                    )));
                }
            }
            if e.graph != graph {
                return Err(bag_err(format!(
                    "trajectory {id}: the graph (types, masses, edges or anchors) at step {} (message {}) differs from step {} (message {})",
                    e.step, e.index, first.step, first.index
                )));
            }
            if e.system != system {
                return Err(bag_err(format!(
                    "trajectory {id}: system {:?} at step {} (message {}) differs from {:?}",
                    e.system, e.step, e.index, system
                )));
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
        if entries.iter().any(|e| e.no_v) {
            let v = super::dataset::finite_difference_velocities(&tr)
                .map_err(|e| bag_err(format!("position-only recording: {e}")))?;
            for ((s, e), v) in tr.samples.iter_mut().zip(&entries).zip(v) {
                if e.no_v {
                    s.state.v = v;
                }
            }
            derived_velocities.push(id);
        }
        trajectories.push(tr);
    }
    Ok((
        Bag {
            trajectories,
            metadata,
            field: field.and_then(|(f, _, _)| f),
            topic: topic.clone(),
            sources: vec![path.to_path_buf()],
            derived_velocities,
        },
        topic,
    ))
}
