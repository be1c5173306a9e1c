//! The one error type of the data layer.

use std::path::PathBuf;

/// Everything that can go wrong reading, writing or converting trajectory data.
///
/// Messages are complete on their own (`{}` shows the whole story): they name the
/// file, the message index and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// Opening, reading, writing or renaming a file failed.
    #[error("{path}: {what}: {err}")]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// What we were doing.
        what: &'static str,
        /// The underlying error.
        err: std::io::Error,
    },
    /// The file is not a readable MCAP file (bad magic, truncated, CRC mismatch...).
    #[error("{path}: not a valid MCAP file: {msg}")]
    Mcap {
        /// The file concerned.
        path: PathBuf,
        /// What the MCAP reader reported, with where.
        msg: String,
    },
    /// The MCAP writer failed.
    #[error("{path}: writing MCAP failed: {msg}")]
    McapWrite {
        /// The file being written (or `<stream>`).
        path: PathBuf,
        /// What the writer reported.
        msg: String,
    },
    /// CDR bytes could not be encoded or decoded.
    #[error("CDR: {0}")]
    Cdr(String),
    /// A compressed message does not decompress.
    #[error("CDR: {codec} decompression failed: {source}")]
    Decompress {
        /// The codec's name (`zstd`, `lz4`).
        codec: &'static str,
        /// Why.
        source: std::io::Error,
    },
    /// A message decoded but its contents are inconsistent or out of range.
    #[error("invalid ParticleState: {0}")]
    Invalid(String),
    /// One message of a bag is bad; wraps the reason.
    #[error("{path}: message {index} (topic {topic}): {reason}")]
    Message {
        /// The file concerned.
        path: PathBuf,
        /// 0-based index of the message in the file (all topics counted).
        index: usize,
        /// The message's topic.
        topic: String,
        /// What is wrong with it.
        reason: Box<DataError>,
    },
    /// The bag is readable but its content is inconsistent (e.g. a trajectory's graph changes).
    #[error("{path}: {msg}")]
    Bag {
        /// The file concerned.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// Another project's dataset (GNS, LagrangeBench) cannot be imported.
    #[error("{path}: {msg}")]
    Import {
        /// The file concerned (records or metadata).
        path: PathBuf,
        /// What is wrong, naming the record and key.
        msg: String,
    },
    /// Trajectories cannot be turned into a training set, or cannot be written.
    #[error("{0}")]
    Trajectory(String),
}

crate::error::typed_errors!(DataError);

impl DataError {
    pub(crate) fn io(path: impl Into<PathBuf>, what: &'static str, err: std::io::Error) -> Self {
        DataError::Io {
            path: path.into(),
            what,
            err,
        }
    }
}
