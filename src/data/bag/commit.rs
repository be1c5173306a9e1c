//! A file an MCAP writer writes through that is a readable MCAP after every
//! commit, for recordings that must survive a SIGKILL.
//!
//! The writer's bytes are held in memory ([`CommitFile`]) until the owner
//! commits them at a record boundary ([`CommitHandle::commit`], after a
//! finished chunk): they then reach the file in one positioned write, followed
//! by a provisional footer (no summary: `summary_start` 0) and the end magic,
//! which the next commit overwrites. A killed writer leaves a summary-less MCAP
//! ending in a footer, which streaming readers (ours, `mcap`) and `rosbags`
//! (which needs the footer and end magic last) read whole; only what was not
//! yet committed is lost.

use std::fs::File;
use std::io::{self, Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt;
use std::sync::{Arc, Mutex, PoisonError};

/// The MCAP magic that opens and closes a file.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// A footer record with no summary (opcode 0x02, length 20, summary start 0,
/// summary offset start 0, CRC 0: none), then the end magic: 37 bytes.
fn provisional_footer() -> [u8; 37] {
    let mut f = [0u8; 37];
    f[0] = 0x02;
    f[1..9].copy_from_slice(&20u64.to_le_bytes());
    f[29..].copy_from_slice(MAGIC);
    f
}

struct Pending {
    file: File,
    /// Bytes already in the file (not counting the provisional footer).
    committed: u64,
    /// The bytes at `committed..`, not yet in the file.
    buf: Vec<u8>,
    /// The writer's position.
    pos: u64,
}

impl Pending {
    fn end(&self) -> u64 {
        self.committed + self.buf.len() as u64
    }
}

/// What the MCAP writer writes to ([`commit_file`]).
pub struct CommitFile(Arc<Mutex<Pending>>);

/// Commits what a [`CommitFile`] holds ([`commit_file`]).
pub struct CommitHandle(Arc<Mutex<Pending>>);

/// A writer over `file` (empty, written from its start) and the handle that
/// commits its bytes.
pub fn commit_file(file: File) -> (CommitFile, CommitHandle) {
    let shared = Arc::new(Mutex::new(Pending {
        file,
        committed: 0,
        buf: Vec::new(),
        pos: 0,
    }));
    (CommitFile(shared.clone()), CommitHandle(shared))
}

fn lock(m: &Mutex<Pending>) -> std::sync::MutexGuard<'_, Pending> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Write for CommitFile {
    fn write(&mut self, data: &[u8]) -> io::Result<usize> {
        let mut p = lock(&self.0);
        let Some(at) = p.pos.checked_sub(p.committed) else {
            return Err(io::Error::other(
                "the MCAP writer went back before the last commit",
            ));
        };
        let at = usize::try_from(at).map_err(io::Error::other)?;
        if p.buf.len() < at {
            p.buf.resize(at, 0);
        }
        let overlap = (p.buf.len() - at).min(data.len());
        p.buf[at..at + overlap].copy_from_slice(&data[..overlap]);
        p.buf.extend_from_slice(&data[overlap..]);
        p.pos += data.len() as u64;
        Ok(data.len())
    }

    /// Nothing reaches the file but by a commit (the MCAP writer flushes
    /// inside chunks too).
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Seek for CommitFile {
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        let mut p = lock(&self.0);
        let new = match to {
            SeekFrom::Start(n) => Some(n),
            SeekFrom::End(d) => p.end().checked_add_signed(d),
            SeekFrom::Current(d) => p.pos.checked_add_signed(d),
        };
        p.pos = new.ok_or_else(|| io::Error::other("seek before the start of the file"))?;
        Ok(p.pos)
    }
}

impl CommitHandle {
    /// Writes what is held to the file in one positioned write: with a
    /// provisional footer after it (`provisional`), or, for a finished bag
    /// whose own footer was just written, cut to its length.
    pub fn commit(&self, provisional: bool) -> io::Result<()> {
        let mut p = lock(&self.0);
        let mut bytes = std::mem::take(&mut p.buf);
        let len = bytes.len() as u64;
        if provisional {
            bytes.extend_from_slice(&provisional_footer());
        }
        let result = p.file.write_all_at(&bytes, p.committed);
        if result.is_ok() {
            p.committed += len;
            if !provisional {
                p.file.set_len(p.committed)?;
            }
            bytes.clear();
        } else {
            bytes.truncate(len as usize);
        }
        // The buffer's capacity is kept for the next chunk.
        p.buf = bytes;
        result
    }

    /// Bytes written so far, committed or not.
    pub fn len(&self) -> u64 {
        lock(&self.0).end()
    }

    /// Nothing written yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes held in memory, not yet committed.
    pub fn pending(&self) -> usize {
        lock(&self.0).buf.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commits_in_place_and_overwrites_the_provisional_footer() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f");
        let (mut w, h) = commit_file(File::create(&path).unwrap());
        w.write_all(b"abcdef").unwrap();
        // A placeholder patched later, as a chunk header is.
        w.seek(SeekFrom::Start(1)).unwrap();
        w.write_all(b"XY").unwrap();
        w.seek(SeekFrom::End(0)).unwrap();
        assert_eq!(
            std::fs::read(&path).unwrap(),
            b"",
            "nothing before a commit"
        );
        assert_eq!(h.pending(), 6);
        h.commit(true).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..6], b"aXYdef");
        assert_eq!(&bytes[6..], &provisional_footer());
        w.write_all(b"gh").unwrap();
        h.commit(true).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..8], b"aXYdefgh");
        assert_eq!(bytes.len(), 8 + 37);
        // Back before the last commit: an error, not a silent rewrite.
        w.seek(SeekFrom::Start(2)).unwrap();
        assert!(w.write_all(b"z").is_err());
        w.seek(SeekFrom::End(0)).unwrap();
        w.write_all(b"end").unwrap();
        h.commit(false).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"aXYdefghend");
        assert_eq!(h.len(), 11);
    }
}
