//! Every message of one bag argument in order, as stored: MCAP files (every
//! CRC checked), rosbag2 sqlite3 files and directories, decompressed.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::Read;
use std::path::Path;

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::data::source::{bag_parts, decompress_file, scan_sqlite, Codec, Storage};
use crate::data::DataError;

/// Floor of the reader's size limit for one record or decompressed chunk (the
/// limit is the larger of this and the file size): roomy for any chunk we or
/// rosbag2 write, small enough that a corrupt length cannot exhaust memory.
const MIN_RECORD_LIMIT: u64 = 256 << 20;

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
/// lists them), see [`crate::data::source`]. Compressed messages and files are
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

/// Reads a whole MCAP file (`read_path`; errors name `path`, the file as the
/// user gave it) as [`scan_bag`] describes.
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
    let mut reader = mcap_reader(len);
    let mut scan = McapScan::new(path);
    let mut n_records = 0usize;
    while let Some(event) = reader.next_event() {
        let event = event.map_err(|e| {
            mcap_err(
                path,
                format!("{} (after {n_records} records)", describe_mcap_error(&e)),
            )
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
            mcap_err(
                path,
                format!(
                    "record {n_records} (opcode {opcode:#04x}): {}",
                    describe_mcap_error(&e)
                ),
            )
        })?;
        scan.take(record, on_message)?;
    }
    Ok(scan.metadata)
}

/// A reader of a whole MCAP file of `len` bytes that checks every CRC, the
/// end magic and that nothing follows it.
fn mcap_reader(len: u64) -> LinearReader {
    LinearReader::new_with_options(
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
    )
}

/// An MCAP file that does not read as one, with what is wrong.
fn mcap_err(path: &Path, what: String) -> DataError {
    DataError::Mcap {
        path: path.to_path_buf(),
        msg: what,
    }
}

/// What [`scan_mcap`] has seen of one file so far.
struct McapScan<'p> {
    /// The file, as errors name it.
    path: &'p Path,
    /// Schemas by id.
    schemas: HashMap<u16, SchemaInfo>,
    /// Channels by id.
    channels: HashMap<u16, ChannelInfo>,
    /// Metadata records, in file order.
    metadata: MetadataRecords,
    /// Messages seen.
    n_messages: usize,
}

impl<'p> McapScan<'p> {
    /// Nothing seen yet of the file at `path`.
    fn new(path: &'p Path) -> Self {
        Self {
            path,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            metadata: Vec::new(),
            n_messages: 0,
        }
    }

    /// Takes in the next record: schemas, channels and metadata are kept,
    /// messages handed to `on_message`.
    fn take(
        &mut self,
        record: Record<'_>,
        on_message: &mut dyn FnMut(&RawMessage) -> Result<(), DataError>,
    ) -> Result<(), DataError> {
        match record {
            Record::Schema { header, data } => {
                self.schemas.insert(
                    header.id,
                    SchemaInfo {
                        name: header.name,
                        encoding: header.encoding,
                        data: data.into_owned(),
                    },
                );
            }
            Record::Channel(c) => {
                if c.schema_id != 0 && !self.schemas.contains_key(&c.schema_id) {
                    return Err(mcap_err(
                        self.path,
                        format!(
                            "channel {} ({}) refers to unknown schema {}",
                            c.id, c.topic, c.schema_id
                        ),
                    ));
                }
                self.channels.insert(
                    c.id,
                    ChannelInfo {
                        topic: c.topic,
                        schema_id: c.schema_id,
                        message_encoding: c.message_encoding,
                    },
                );
            }
            Record::Message { header, data } => {
                self.message(header.channel_id, header.log_time, &data, on_message)?;
            }
            Record::Metadata(m) => self.metadata.push((m.name, m.metadata)),
            _ => {}
        }
        Ok(())
    }

    /// Hands the next message, on channel `channel_id`, to `on_message`; its
    /// error is reported with the file, the message's index and its topic.
    fn message(
        &mut self,
        channel_id: u16,
        log_time: u64,
        data: &[u8],
        on_message: &mut dyn FnMut(&RawMessage) -> Result<(), DataError>,
    ) -> Result<(), DataError> {
        let index = self.n_messages;
        self.n_messages += 1;
        let ch = self.channels.get(&channel_id).ok_or_else(|| {
            mcap_err(
                self.path,
                format!("message {index} refers to unknown channel {channel_id}"),
            )
        })?;
        let schema = self.schemas.get(&ch.schema_id);
        let raw = RawMessage {
            index,
            topic: &ch.topic,
            schema_name: schema.map_or("", |s| s.name.as_str()),
            schema_encoding: schema.map_or("", |s| s.encoding.as_str()),
            schema_text: schema.map_or(&[][..], |s| s.data.as_slice()),
            message_encoding: &ch.message_encoding,
            log_time,
            data,
            file: self.path,
        };
        on_message(&raw).map_err(|e| DataError::Message {
            path: self.path.to_path_buf(),
            index,
            topic: ch.topic.clone(),
            reason: Box::new(e),
        })
    }
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
