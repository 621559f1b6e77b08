//! Where an [`McapInput`](super::McapInput) reads its bytes: a file opened again for each pass,
//! or any seekable reader shared by the passes, and the limits on what one record may claim.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use crate::error::{Error, McapProblem, Result};

/// Buffer size of the linear reader's file reads.
pub(super) const READ_BUFFER_BYTES: usize = 1 << 20;

/// Smallest limit on one record or decompressed chunk, whatever the file size. Recorders write
/// chunks of a few MiB (ours 4 MiB) and the largest single RGB-D message is a raw 4K frame of
/// ~25 MB; a compressed chunk may decompress to more than the whole file, so the limit is not
/// just the file length.
const MIN_RECORD_LENGTH_LIMIT_BYTES: u64 = 256 << 20;

/// The longest record (or decompressed chunk) the MCAP readers accept in a file of `file_len`
/// bytes. Without a limit the mcap readers allocate whatever length a corrupt record declares
/// (found by fuzzing: 8e18 bytes from a 2.5 kB file, fuzz/README.md).
pub(super) fn record_length_limit(file_len: u64) -> usize {
    usize::try_from(file_len.max(MIN_RECORD_LENGTH_LIMIT_BYTES)).unwrap_or(usize::MAX)
}

/// Where an [`McapInput`] reads its bytes, and the name its messages give it.
pub(super) struct Source {
    /// The file's path, or the name given to a reader.
    pub(super) path: PathBuf,
    /// `None`: the file at `path`, opened again for each pass (passes may overlap).
    pub(super) reader: Option<SharedReader>,
}

/// Any seekable byte source an [`McapInput`](super::McapInput) can read ([`std::fs::File`],
/// [`std::io::Cursor`] over bytes, ...).
pub trait ReadSeek: Read + Seek + Send {}

impl<T: Read + Seek + Send> ReadSeek for T {}

/// A reader shared by the passes over it; each pass keeps its own position.
pub(super) type SharedReader = Arc<Mutex<Box<dyn ReadSeek>>>;

/// One pass over a [`Source`].
pub(super) enum SourceReader {
    File(File),
    Shared { reader: SharedReader, position: u64 },
}

fn poisoned() -> std::io::Error {
    std::io::Error::other("another reader of the same MCAP input panicked")
}

impl Read for SourceReader {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self {
            SourceReader::File(f) => f.read(buf),
            SourceReader::Shared { reader, position } => {
                let mut r = reader.lock().map_err(|_| poisoned())?;
                r.seek(SeekFrom::Start(*position))?;
                let n = r.read(buf)?;
                *position += n as u64;
                Ok(n)
            }
        }
    }
}

impl Seek for SourceReader {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        match self {
            SourceReader::File(f) => f.seek(to),
            SourceReader::Shared { reader, position } => {
                let target = match to {
                    SeekFrom::Start(n) => Some(n),
                    SeekFrom::Current(d) => position.checked_add_signed(d),
                    SeekFrom::End(_) => Some(reader.lock().map_err(|_| poisoned())?.seek(to)?),
                };
                *position = target.ok_or_else(|| {
                    std::io::Error::new(std::io::ErrorKind::InvalidInput, "seek before the start")
                })?;
                Ok(*position)
            }
        }
    }
}

impl Source {
    /// Starts a pass at the beginning.
    pub(super) fn open(&self) -> Result<SourceReader> {
        match &self.reader {
            None => open_file(&self.path).map(SourceReader::File),
            Some(reader) => Ok(SourceReader::Shared {
                reader: Arc::clone(reader),
                position: 0,
            }),
        }
    }

    /// The length in bytes.
    pub(super) fn len(&self, pass: &mut SourceReader) -> Result<u64> {
        let len = match pass {
            SourceReader::File(f) => f.metadata().map(|m| m.len()),
            SourceReader::Shared { .. } => pass.seek(SeekFrom::End(0)),
        };
        len.map_err(|e| Error::io("cannot stat MCAP file", &self.path, e))
    }
}

pub(super) fn open_file(path: &Path) -> Result<File> {
    // Opening a directory succeeds on Unix; reading it then fails with a vaguer message.
    if path.is_dir() {
        return Err(Error::bad_mcap(path, McapProblem::Directory));
    }
    File::open(path).map_err(|e| Error::io("cannot open MCAP file", path, e))
}
