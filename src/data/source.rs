//! Where a bag's messages are stored: one MCAP file, one rosbag2 sqlite3 file
//! (.db3), or a rosbag2 directory (metadata.yaml naming its files in order,
//! their storage and their compression).
//!
//! rosbag2 compresses in one of three ways, all read here:
//! - MCAP chunk compression (zstd or lz4): handled by the MCAP reader.
//! - `compression_mode: MESSAGE`: each message's bytes are one zstd (or lz4)
//!   frame. The frame is recognised by its magic number, which a CDR
//!   encapsulation header (`00 0x`) can never start with, so bare files work
//!   too; when metadata.yaml declares a format, every message must use it.
//! - `compression_mode: FILE`: each storage file is one zstd (or lz4) stream
//!   (`DIR_0.mcap.zstd`); it is decompressed to a temporary file first.

use std::collections::HashMap;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use yaml_rust2::{Yaml, YamlLoader};

use super::DataError;

/// Name of the file that describes a rosbag2 directory.
pub const ROSBAG2_METADATA: &str = "metadata.yaml";

/// How a file stores its messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// MCAP.
    Mcap,
    /// rosbag2's sqlite3 storage (.db3).
    Sqlite3,
}

/// A compression format rosbag2 can use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    /// Zstandard frames.
    Zstd,
    /// LZ4 frames.
    Lz4,
}

impl Codec {
    /// The codec named in metadata.yaml (`zstd`, `lz4`); "" is none.
    fn parse(name: &str, file: &Path) -> Result<Option<Codec>, DataError> {
        match name.trim().to_ascii_lowercase().as_str() {
            "" => Ok(None),
            "zstd" => Ok(Some(Codec::Zstd)),
            "lz4" => Ok(Some(Codec::Lz4)),
            other => Err(DataError::Bag {
                path: file.to_path_buf(),
                msg: format!("compression_format {other:?} is not supported (zstd or lz4)"),
            }),
        }
    }

    /// The codec whose frame `data` starts with, if any.
    pub fn sniff(data: &[u8]) -> Option<Codec> {
        match data.get(..4) {
            Some([0x28, 0xb5, 0x2f, 0xfd]) => Some(Codec::Zstd),
            Some([0x04, 0x22, 0x4d, 0x18]) => Some(Codec::Lz4),
            _ => None,
        }
    }

    /// Decompresses one whole frame (or several concatenated ones).
    pub fn decompress(self, data: &[u8]) -> Result<Vec<u8>, DataError> {
        let mut out = Vec::new();
        match self {
            Codec::Zstd => {
                zstd::stream::read::Decoder::new(data).and_then(|mut d| d.read_to_end(&mut out))
            }
            Codec::Lz4 => lz4::Decoder::new(data).and_then(|mut d| d.read_to_end(&mut out)),
        }
        .map_err(|source| DataError::Decompress {
            codec: self.name(),
            source,
        })?;
        Ok(out)
    }

    /// Lower-case name, as in metadata.yaml.
    pub fn name(self) -> &'static str {
        match self {
            Codec::Zstd => "zstd",
            Codec::Lz4 => "lz4",
        }
    }
}

/// One storage file of a bag, in the order its messages are read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BagPart {
    /// The file.
    pub path: PathBuf,
    /// How it stores messages.
    pub storage: Storage,
    /// Whole-file compression (`compression_mode: FILE`).
    pub file_compression: Option<Codec>,
    /// Per-message compression declared by metadata.yaml (`compression_mode:
    /// MESSAGE`); messages are also sniffed when nothing is declared.
    pub message_compression: Option<Codec>,
}

/// The storage files of one bag argument: a file (MCAP or .db3, recognised by
/// its first bytes), a rosbag2 directory, or the metadata.yaml inside one.
pub fn bag_parts(path: &Path) -> Result<Vec<BagPart>, DataError> {
    if path.is_dir() {
        return rosbag2_parts(path);
    }
    if path.file_name().is_some_and(|n| n == ROSBAG2_METADATA) {
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        return rosbag2_parts(dir);
    }
    let (storage, file_compression) = sniff_file(path)?;
    Ok(vec![BagPart {
        path: path.to_path_buf(),
        storage,
        file_compression,
        message_compression: None,
    }])
}

/// Recognises a storage file by its first bytes (a compressed file by its
/// codec's magic and the storage named by the extension under it).
fn sniff_file(path: &Path) -> Result<(Storage, Option<Codec>), DataError> {
    let mut head = [0u8; 16];
    let mut file = File::open(path).map_err(|e| DataError::io(path, "opening", e))?;
    let mut got = 0;
    while got < head.len() {
        match file.read(&mut head[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(DataError::io(path, "reading", e)),
        }
    }
    let head = &head[..got];
    if head.starts_with(b"SQLite format 3\0") {
        return Ok((Storage::Sqlite3, None));
    }
    if let Some(codec) = Codec::sniff(head) {
        let name = path.to_string_lossy();
        let storage = if name.contains(".db3") {
            Storage::Sqlite3
        } else {
            Storage::Mcap
        };
        return Ok((storage, Some(codec)));
    }
    // Anything else is read as MCAP, whose reader names what is wrong.
    Ok((Storage::Mcap, None))
}

/// Reads metadata.yaml of a rosbag2 directory (YAML 1.2) into its parts.
fn rosbag2_parts(dir: &Path) -> Result<Vec<BagPart>, DataError> {
    let meta = dir.join(ROSBAG2_METADATA);
    if !meta.exists() {
        return Err(DataError::Bag {
            path: dir.to_path_buf(),
            msg: format!(
                "is a directory without {ROSBAG2_METADATA}: not a rosbag2 bag (give the .mcap or .db3 file itself)"
            ),
        });
    }
    let text = std::fs::read_to_string(&meta).map_err(|e| DataError::io(&meta, "reading", e))?;
    let bad = |msg: String| metadata_err(&meta, msg);
    let docs = YamlLoader::load_from_str(&text).map_err(|e| bad(format!("not YAML: {e}")))?;
    let info = docs
        .first()
        .map(|d| &d["rosbag2_bagfile_information"])
        .filter(|i| !i.is_badvalue())
        .ok_or_else(|| bad("has no rosbag2_bagfile_information".into()))?;
    let str_of = |key: &str| -> Result<String, DataError> {
        match &info[key] {
            Yaml::BadValue | Yaml::Null => Ok(String::new()),
            Yaml::String(s) => Ok(s.clone()),
            other => Err(bad(format!("{key} is not a string: {other:?}"))),
        }
    };
    let storage = storage_of(&str_of("storage_identifier")?, &meta)?;
    let codec = Codec::parse(&str_of("compression_format")?, &meta)?;
    let mode = str_of("compression_mode")?.to_ascii_uppercase();
    let (file_compression, message_compression) = compression_of(&mode, codec, &meta)?;
    let files = relative_file_paths(info, &meta)?;
    Ok(files
        .into_iter()
        .map(|f| BagPart {
            path: storage_file(dir, &f),
            storage,
            file_compression,
            message_compression,
        })
        .collect())
}

/// A metadata.yaml (`meta`) that does not describe a bag we read, with why.
fn metadata_err(meta: &Path, msg: String) -> DataError {
    DataError::Bag {
        path: meta.to_path_buf(),
        msg,
    }
}

/// The storage a metadata.yaml's `storage_identifier` names.
fn storage_of(identifier: &str, meta: &Path) -> Result<Storage, DataError> {
    match identifier {
        "mcap" => Ok(Storage::Mcap),
        "sqlite3" => Ok(Storage::Sqlite3),
        "" => Err(metadata_err(meta, "storage_identifier is missing".into())),
        other => Err(metadata_err(
            meta,
            format!("storage_identifier {other:?} is not supported (mcap or sqlite3)"),
        )),
    }
}

/// How a rosbag2 directory's files are compressed, from its
/// `compression_mode` (upper case) and `compression_format`: (whole files,
/// each message).
fn compression_of(
    mode: &str,
    codec: Option<Codec>,
    meta: &Path,
) -> Result<(Option<Codec>, Option<Codec>), DataError> {
    match (mode, codec) {
        ("" | "NONE", _) => Ok((None, None)),
        ("FILE", Some(c)) => Ok((Some(c), None)),
        ("MESSAGE", Some(c)) => Ok((None, Some(c))),
        ("FILE" | "MESSAGE", None) => Err(metadata_err(
            meta,
            format!("compression_mode {mode} without a compression_format"),
        )),
        (other, _) => Err(metadata_err(
            meta,
            format!("compression_mode {other:?} is not supported (FILE, MESSAGE or none)"),
        )),
    }
}

/// The storage files metadata.yaml lists (`relative_file_paths`, not empty).
fn relative_file_paths(info: &Yaml, meta: &Path) -> Result<Vec<String>, DataError> {
    let bad = |msg: String| metadata_err(meta, msg);
    let files = match &info["relative_file_paths"] {
        Yaml::Array(a) => a
            .iter()
            .map(|f| {
                f.as_str()
                    .map(str::to_string)
                    .ok_or_else(|| bad(format!("relative_file_paths entry {f:?} is not a string")))
            })
            .collect::<Result<Vec<_>, _>>()?,
        _ => return Err(bad("relative_file_paths is not a list".into())),
    };
    if files.is_empty() {
        return Err(bad("relative_file_paths is empty".into()));
    }
    Ok(files)
}

/// Where the storage file `f` listed in `dir`'s metadata.yaml is.
fn storage_file(dir: &Path, f: &str) -> PathBuf {
    // rosbag2 before Humble wrote paths with the directory's name in front.
    let direct = dir.join(f);
    if direct.exists() {
        direct
    } else {
        Path::new(f)
            .file_name()
            .map(|n| dir.join(n))
            .filter(|p| p.exists())
            .unwrap_or(direct)
    }
}

/// Decompresses a whole-file-compressed part into a temporary file.
pub fn decompress_file(path: &Path, codec: Codec) -> Result<tempfile::NamedTempFile, DataError> {
    let input = File::open(path).map_err(|e| DataError::io(path, "opening", e))?;
    let mut tmp = tempfile::NamedTempFile::new()
        .map_err(|e| DataError::io(path, "creating a temporary file to decompress", e))?;
    let res = match codec {
        Codec::Zstd => zstd::stream::read::Decoder::new(input)
            .and_then(|mut d| std::io::copy(&mut d, tmp.as_file_mut())),
        Codec::Lz4 => {
            lz4::Decoder::new(input).and_then(|mut d| std::io::copy(&mut d, tmp.as_file_mut()))
        }
    };
    res.map_err(|e| DataError::io(path, "decompressing", e))?;
    Ok(tmp)
}

/// One message of a sqlite3 bag, with its topic's type and definition.
pub struct SqliteMessage {
    /// Topic name.
    pub topic: String,
    /// Message type, e.g. `mcgnode_msgs/msg/ParticleState`.
    pub msg_type: String,
    /// Serialization format (`cdr`).
    pub serialization: String,
    /// Definition encoding (`ros2msg`) and text, when the bag stores them
    /// (rosbag2 from Iron on); empty otherwise.
    pub definition: (String, String),
    /// Receive time, ns.
    pub timestamp: i64,
    /// The stored bytes.
    pub data: Vec<u8>,
}

/// Reads every message of a rosbag2 sqlite3 file in time order (ties by row id).
pub fn scan_sqlite(
    path: &Path,
    mut on_message: impl FnMut(usize, &SqliteMessage) -> Result<(), DataError>,
) -> Result<(), DataError> {
    use rusqlite::{Connection, OpenFlags};
    let err = |e: rusqlite::Error| sqlite_err(path, e);
    let db = Connection::open_with_flags(path, OpenFlags::SQLITE_OPEN_READ_ONLY).map_err(err)?;
    let defs = sqlite_definitions(&db, path)?;
    let topics = sqlite_topics(&db, path)?;
    let mut st = db
        .prepare("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id")
        .map_err(err)?;
    let mut rows = st.query([]).map_err(err)?;
    let mut index = 0usize;
    while let Some(r) = rows.next().map_err(err)? {
        let topic_id: i64 = r.get(0).map_err(err)?;
        let (topic, msg_type, serialization) =
            topics
                .get(&topic_id)
                .cloned()
                .ok_or_else(|| DataError::Bag {
                    path: path.to_path_buf(),
                    msg: format!("message {index} refers to unknown topic id {topic_id}"),
                })?;
        let definition = defs.get(&msg_type).cloned().unwrap_or_default();
        let m = SqliteMessage {
            topic,
            msg_type,
            serialization,
            definition,
            timestamp: r.get(1).map_err(err)?,
            data: r.get(2).map_err(err)?,
        };
        on_message(index, &m)?;
        index += 1;
    }
    Ok(())
}

/// A sqlite3 error, naming the file.
fn sqlite_err(path: &Path, e: rusqlite::Error) -> DataError {
    DataError::Bag {
        path: path.to_path_buf(),
        msg: format!("sqlite3: {e}"),
    }
}

/// The message definitions a rosbag2 sqlite3 file stores (from Iron on), by
/// message type: (encoding, text). Empty when it has none.
fn sqlite_definitions(
    db: &rusqlite::Connection,
    path: &Path,
) -> Result<HashMap<String, (String, String)>, DataError> {
    let err = |e: rusqlite::Error| sqlite_err(path, e);
    let has_defs: bool = db
        .query_row(
            "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = 'message_definitions'",
            [],
            |r| r.get::<_, i64>(0),
        )
        .map_err(err)?
        > 0;
    let mut defs = HashMap::new();
    if has_defs {
        let mut st = db
            .prepare(
                "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions",
            )
            .map_err(err)?;
        let rows = st
            .query_map([], |r| {
                Ok((
                    r.get::<_, String>(0)?,
                    (r.get::<_, String>(1)?, r.get::<_, String>(2)?),
                ))
            })
            .map_err(err)?;
        for row in rows {
            let (t, d) = row.map_err(err)?;
            defs.insert(t, d);
        }
    }
    Ok(defs)
}

/// A sqlite3 topic: name, message type and serialization format.
type SqliteTopic = (String, String, String);

/// The topics of a rosbag2 sqlite3 file, by id.
fn sqlite_topics(
    db: &rusqlite::Connection,
    path: &Path,
) -> Result<HashMap<i64, SqliteTopic>, DataError> {
    let err = |e: rusqlite::Error| sqlite_err(path, e);
    let mut topics = HashMap::new();
    let mut st = db
        .prepare("SELECT id, name, type, serialization_format FROM topics")
        .map_err(err)?;
    let rows = st
        .query_map([], |r| {
            Ok((
                r.get::<_, i64>(0)?,
                (
                    r.get::<_, String>(1)?,
                    r.get::<_, String>(2)?,
                    r.get::<_, String>(3)?,
                ),
            ))
        })
        .map_err(err)?;
    for row in rows {
        let (id, t) = row.map_err(err)?;
        topics.insert(id, t);
    }
    Ok(topics)
}
