//! Repairing an MCAP file cut short (a recorder killed mid-run): everything up
//! to the last whole record is rewritten as a complete, indexed MCAP file
//! (summary, footer and end magic), which readers that need the index
//! (rosbags' AnyReader, `mcap info`) accept.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Read};
use std::path::Path;

use mcap::records::{MessageHeader, Record};
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::DataError;

/// What [`repair`] kept.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RepairReport {
    /// Messages kept (all of those in whole records).
    pub messages: usize,
    /// Channels kept.
    pub channels: usize,
    /// Metadata records kept.
    pub metadata: usize,
    /// Why reading stopped before the end magic ("" when the input was complete).
    pub stopped: String,
}

/// Rewrites the readable part of `input` as a complete MCAP file `output`
/// (written to a temporary file beside it, then renamed). Schemas, channels
/// (with their metadata), messages (with sequence, log and publish times) and
/// metadata records are kept in order; chunks are zstd-compressed. Refuses an
/// `output` that is the input, and an input with no readable record at all.
pub fn repair(input: &Path, output: &Path) -> Result<RepairReport, DataError> {
    check_paths(input, output)?;
    let mut file = File::open(input).map_err(|e| DataError::io(input, "opening", e))?;
    let len = file
        .metadata()
        .map_err(|e| DataError::io(input, "reading the size of", e))?
        .len();
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_end_magic(true)
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(usize::try_from(len.max(256 << 20)).unwrap_or(usize::MAX)),
    );
    let mut tmp = temp_file_beside(output)?;
    let mut rewrite = Rewrite::new(tmp.as_file_mut(), output)?;
    let mut records = 0usize;
    while let Some(event) = reader.next_event() {
        let (opcode, data) = match event {
            Err(e) => {
                rewrite.report.stopped = format!("after {records} records: {e}");
                break;
            }
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let buf = reader.insert(need);
                let got = loop {
                    match file.read(buf) {
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                        r => break r,
                    }
                }
                .map_err(|e| DataError::io(input, "reading", e))?;
                reader.notify_read(got);
                continue;
            }
            Ok(LinearReadEvent::Record { opcode, data }) => (opcode, data),
        };
        records += 1;
        let record = match mcap::parse_record(opcode, data) {
            Ok(r) => r,
            Err(e) => {
                rewrite.report.stopped = format!("record {records} does not parse: {e}");
                break;
            }
        };
        if !rewrite.record(record)? {
            break;
        }
    }
    if records == 0 {
        return Err(DataError::Mcap {
            path: input.to_path_buf(),
            msg: format!("no readable record ({})", rewrite.report.stopped),
        });
    }
    let report = rewrite.finish()?;
    tmp.as_file()
        .sync_all()
        .map_err(|e| DataError::io(output, "syncing", e))?;
    tmp.persist(output)
        .map_err(|e| DataError::io(output, "renaming the temporary file to", e.error))?;
    Ok(report)
}

/// Refuses an `input` that is a directory, and an `output` that is the input.
fn check_paths(input: &Path, output: &Path) -> Result<(), DataError> {
    if input.is_dir() {
        return Err(DataError::Bag {
            path: input.to_path_buf(),
            msg: "is a directory: bag repair rewrites one MCAP file (give the .mcap inside a rosbag2 directory)".into(),
        });
    }
    if output.exists() && std::fs::canonicalize(output).ok() == std::fs::canonicalize(input).ok() {
        return Err(DataError::Bag {
            path: output.to_path_buf(),
            msg: "the repaired bag must be written to another file than the input".into(),
        });
    }
    Ok(())
}

/// A temporary file in `output`'s directory, with an ordinary file's
/// permissions, to be renamed to `output` when complete.
fn temp_file_beside(output: &Path) -> Result<tempfile::NamedTempFile, DataError> {
    let dir = match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".mcgnode-repair-");
    // Temporary files are private (0600) by default; a bag is an ordinary file.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    builder
        .tempfile_in(dir)
        .map_err(|e| DataError::io(dir, "creating a temporary file in", e))
}

/// The records read so far, written again to a new MCAP file.
struct Rewrite<'a> {
    /// The writer of the new file.
    w: mcap::Writer<BufWriter<&'a mut File>>,
    /// The file it will be, as errors name it.
    output: &'a Path,
    /// Schema ids of the input to those of the output.
    schema_ids: HashMap<u16, u16>,
    /// Channel ids of the input to those of the output.
    channel_ids: HashMap<u16, u16>,
    /// What was kept, and why reading stopped.
    report: RepairReport,
}

impl<'a> Rewrite<'a> {
    /// Starts the new file in `file` (to become `output`).
    fn new(file: &'a mut File, output: &'a Path) -> Result<Self, DataError> {
        let w = mcap::WriteOptions::new()
            .profile("ros2")
            .library(format!("mcgnode {} bag repair", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .compression_threads(0)
            .create(BufWriter::new(file))
            .map_err(|e| write_err(output, e))?;
        Ok(Self {
            w,
            output,
            schema_ids: HashMap::new(),
            channel_ids: HashMap::new(),
            report: RepairReport {
                messages: 0,
                channels: 0,
                metadata: 0,
                stopped: String::new(),
            },
        })
    }

    /// Writes one record again; false (with [`RepairReport::stopped`] saying
    /// why, unless the data ended) when the copy stops before it.
    fn record(&mut self, record: Record<'_>) -> Result<bool, DataError> {
        let output = self.output;
        let werr = |e: mcap::McapError| write_err(output, e);
        match record {
            Record::Schema { header, data } => {
                let id = self
                    .w
                    .add_schema(&header.name, &header.encoding, &data)
                    .map_err(werr)?;
                self.schema_ids.insert(header.id, id);
            }
            Record::Channel(c) => {
                let schema = if c.schema_id == 0 {
                    0
                } else if let Some(s) = self.schema_ids.get(&c.schema_id) {
                    *s
                } else {
                    self.report.stopped = format!(
                        "channel {} refers to unknown schema {}",
                        c.topic, c.schema_id
                    );
                    return Ok(false);
                };
                let metadata: BTreeMap<String, String> = c.metadata.clone();
                let id = self
                    .w
                    .add_channel(schema, &c.topic, &c.message_encoding, &metadata)
                    .map_err(werr)?;
                if self.channel_ids.insert(c.id, id).is_none() {
                    self.report.channels += 1;
                }
            }
            Record::Message { header, data } => {
                let Some(&channel_id) = self.channel_ids.get(&header.channel_id) else {
                    self.report.stopped = format!(
                        "message {} refers to unknown channel {}",
                        self.report.messages, header.channel_id
                    );
                    return Ok(false);
                };
                self.w
                    .write_to_known_channel(
                        &MessageHeader {
                            channel_id,
                            ..header
                        },
                        &data,
                    )
                    .map_err(werr)?;
                self.report.messages += 1;
            }
            Record::Metadata(m) => {
                self.w.write_metadata(&m).map_err(werr)?;
                self.report.metadata += 1;
            }
            Record::DataEnd(_) => return Ok(false),
            _ => {}
        }
        Ok(true)
    }

    /// Writes the summary and footer and flushes; returns what was kept.
    fn finish(mut self) -> Result<RepairReport, DataError> {
        let output = self.output;
        self.w.finish().map_err(|e| write_err(output, e))?;
        let mut out = self.w.into_inner();
        std::io::Write::flush(&mut out).map_err(|e| DataError::io(output, "flushing", e))?;
        Ok(self.report)
    }
}

/// The MCAP writer's error, naming the file written.
fn write_err(output: &Path, e: mcap::McapError) -> DataError {
    DataError::McapWrite {
        path: output.to_path_buf(),
        msg: e.to_string(),
    }
}
