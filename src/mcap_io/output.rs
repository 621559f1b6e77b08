//! [`AtomicOutput`]: write to a temporary file beside the target, rename on success.
//!
//! A crash or error never leaves a half-written file under the final name, an existing file
//! is only replaced with `force`, and the output may not be one of the inputs. The file is
//! flushed to disk before the rename; [`OutputFile`] starts that flush in the background while
//! the file is still being written, so that little is left to wait for at the end.

use std::fs::{File, OpenOptions};
use std::io::{self, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::thread::JoinHandle;

use crate::error::{Error, Result};

/// A temporary output file that becomes `final_path` on [`AtomicOutput::commit`] and is
/// deleted when dropped uncommitted.
#[derive(Debug)]
pub struct AtomicOutput {
    final_path: PathBuf,
    temp_path: PathBuf,
    force: bool,
    committed: bool,
}

/// True when `a` and `b` name the same existing file or directory (after symlinks; on Unix
/// also hard links).
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(ca), Ok(cb)) => ca == cb,
        _ => false,
    }
}

/// True when `path` names a folder: an existing one, or any path ending in a separator
/// (`out/`), which can only ever be a folder.
pub fn names_folder(path: &Path) -> bool {
    let ends_in_separator = path
        .as_os_str()
        .as_encoded_bytes()
        .last()
        .is_some_and(|&byte| std::path::is_separator(char::from(byte)));
    ends_in_separator || path.is_dir()
}

fn output_error(path: &Path, message: impl Into<String>) -> Error {
    Error::InvalidParameter {
        name: "output",
        value: path.display().to_string(),
        expected: message.into(),
    }
}

impl AtomicOutput {
    /// Creates the temporary file `<final>.<pid>.tmp` in the target's directory.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] when `final_path` names a folder ([`names_folder`]), lies in
    /// a folder that does not exist, or is one of `inputs`; [`Error::OutputExists`] when it
    /// exists and `force` is false; [`Error::Io`] when the temporary file cannot be created
    /// (e.g. no permission to write in the folder).
    pub fn create(final_path: &Path, force: bool, inputs: &[&Path]) -> Result<(Self, OutputFile)> {
        // Checked here, not left to the rename at the end: `out/` (no such folder) would
        // otherwise create `out.<pid>.tmp`, do all the work, and fail only at the rename.
        if names_folder(final_path) {
            let found = if final_path.is_dir() {
                "a file path, found a directory"
            } else {
                "a file path, found a directory name (it ends in a separator)"
            };
            return Err(output_error(final_path, found));
        }
        // A missing folder is named as such, not as the temporary file that cannot be made.
        let folder = match final_path.parent() {
            Some(parent) if !parent.as_os_str().is_empty() => parent,
            _ => Path::new("."),
        };
        if !folder.is_dir() {
            let found = if folder.exists() {
                "is not a folder"
            } else {
                "does not exist"
            };
            return Err(output_error(
                final_path,
                format!("a file in an existing folder, but {} {found}", folder.display()),
            ));
        }
        for input in inputs {
            if same_file(final_path, input) {
                return Err(output_error(
                    final_path,
                    format!("a path different from the input {}", input.display()),
                ));
            }
        }
        // Renaming over a device (`-o /dev/null --force` as root) or a FIFO would replace it
        // with a regular file: only regular files are ever replaced.
        if let Ok(meta) = std::fs::metadata(final_path) {
            if !meta.is_file() {
                return Err(output_error(
                    final_path,
                    "a regular file path, found a device, FIFO or socket (occmask writes a temporary \
                     file and renames it, which would replace the device)",
                ));
            }
        }
        if final_path.exists() && !force {
            return Err(Error::OutputExists {
                path: final_path.to_owned(),
                appeared_while_writing: false,
            });
        }
        let file_name = final_path
            .file_name()
            .ok_or_else(|| output_error(final_path, "a path ending in a file name"))?;
        let mut temp_name = file_name.to_owned();
        temp_name.push(format!(".{}.tmp", std::process::id()));
        let temp_path = final_path.with_file_name(temp_name);
        let file = OpenOptions::new()
            .write(true)
            .read(true)
            .create_new(true)
            .open(&temp_path)
            .map_err(|e| Error::io("cannot create temporary output file", &temp_path, e))?;
        Ok((
            Self {
                final_path: final_path.to_owned(),
                temp_path,
                force,
                committed: false,
            },
            OutputFile::new(file),
        ))
    }

    /// The final path.
    pub fn path(&self) -> &Path {
        &self.final_path
    }

    /// The temporary path being written.
    pub fn temp_path(&self) -> &Path {
        &self.temp_path
    }

    /// Flushes `file` to disk and renames the temporary file to the final path.
    ///
    /// # Errors
    /// [`Error::Io`] when syncing (the background flushes included) or renaming fails;
    /// [`Error::OutputExists`] when the target appeared meanwhile and `force` is false. The
    /// temporary file is removed.
    pub fn commit(mut self, file: OutputFile) -> Result<()> {
        let file = file
            .into_synced_file()
            .map_err(|e| Error::io("cannot flush output file", &self.final_path, e))?;
        drop(file);
        if !self.force && self.final_path.exists() {
            return Err(Error::OutputExists {
                path: self.final_path.clone(),
                appeared_while_writing: true,
            });
        }
        std::fs::rename(&self.temp_path, &self.final_path)
            .map_err(|e| Error::io("cannot rename temporary output into place", &self.final_path, e))?;
        self.committed = true;
        Ok(())
    }
}

/// Bytes written between two background flushes of an [`OutputFile`]: small against the
/// hundreds of megabytes of a recording, so the flush at the end waits for little, and large
/// enough that a flush (one `fsync`) per interval costs nothing measurable.
pub const WRITEBACK_INTERVAL_BYTES: u64 = 16 << 20;

/// The temporary file of an [`AtomicOutput`]. Every [`WRITEBACK_INTERVAL_BYTES`] written, a
/// background thread (started at the first interval, so small files never start one) flushes
/// what the file holds to disk while writing goes on: otherwise the whole file sits in the page
/// cache until [`AtomicOutput::commit`]'s flush, which then waits for all of it.
#[derive(Debug)]
pub struct OutputFile {
    file: File,
    bytes_since_writeback: u64,
    writeback: Option<Writeback>,
}

/// The background flush thread of an [`OutputFile`] and the queue of its requests.
#[derive(Debug)]
struct Writeback {
    request: SyncSender<()>,
    thread: JoinHandle<io::Result<()>>,
}

impl Writeback {
    /// Starts the thread, on a second handle of `file`.
    fn start(file: &File) -> io::Result<Self> {
        let file = file.try_clone()?;
        // One request may wait while one runs: the writer never blocks on the disk.
        let (request, requests) = mpsc::sync_channel::<()>(1);
        let thread = std::thread::Builder::new()
            .name("occmask-writeback".into())
            .spawn(move || {
                for () in requests {
                    file.sync_data()?;
                }
                Ok(())
            })?;
        Ok(Self { request, thread })
    }

    /// Waits for the thread (after the requests it holds) and returns its first error.
    fn join(self) -> io::Result<()> {
        drop(self.request);
        self.thread
            .join()
            .unwrap_or_else(|_| Err(io::Error::other("the output flush thread panicked")))
    }
}

impl OutputFile {
    fn new(file: File) -> Self {
        Self {
            file,
            bytes_since_writeback: 0,
            writeback: None,
        }
    }

    /// Asks the background thread to flush the file (starting it on the first call). A
    /// request while one is still waiting is dropped: that one will flush these bytes too.
    fn request_writeback(&mut self) -> io::Result<()> {
        let writeback = match self.writeback.take() {
            Some(writeback) => writeback,
            None => Writeback::start(&self.file)?,
        };
        match writeback.request.try_send(()) {
            Ok(()) | Err(TrySendError::Full(())) => {
                self.writeback = Some(writeback);
                Ok(())
            }
            // The thread stopped at a failed flush: report it now.
            Err(TrySendError::Disconnected(())) => writeback.join(),
        }
    }

    /// Waits for the background flushes, then flushes the rest of the file and its metadata.
    fn into_synced_file(mut self) -> io::Result<File> {
        if let Some(writeback) = self.writeback.take() {
            writeback.join()?;
        }
        self.file.sync_all()?;
        Ok(self.file)
    }
}

impl Write for OutputFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let written = self.file.write(buf)?;
        self.bytes_since_writeback += written as u64;
        if self.bytes_since_writeback >= WRITEBACK_INTERVAL_BYTES {
            self.bytes_since_writeback = 0;
            self.request_writeback()?;
        }
        Ok(written)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

impl Seek for OutputFile {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.file.seek(pos)
    }
}

impl Drop for AtomicOutput {
    fn drop(&mut self) {
        if !self.committed {
            // Best effort: the error that made us drop is what the user needs to see.
            let _ = std::fs::remove_file(&self.temp_path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn commit_renames_and_drop_removes() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.mcap");
        let (o, mut f) = AtomicOutput::create(&out, false, &[]).unwrap();
        f.write_all(b"hello").unwrap();
        assert!(o.temp_path().exists() && !out.exists());
        o.commit(f).unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"hello");

        let (o, _f) = AtomicOutput::create(&dir.path().join("b.mcap"), false, &[]).unwrap();
        let temp = o.temp_path().to_owned();
        drop(o);
        assert!(!temp.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn large_outputs_are_flushed_in_the_background_and_keep_every_byte() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("big.mcap");
        let (o, mut f) = AtomicOutput::create(&out, false, &[]).unwrap();
        let interval = WRITEBACK_INTERVAL_BYTES as usize;
        let expected: Vec<u8> = (0..interval * 5 / 2).map(|i| (i % 251) as u8).collect();
        // Written in pieces, with a seek back to patch the start (as an MCAP writer may).
        f.write_all(&[0xff; 8]).unwrap();
        for piece in expected[8..].chunks(1 << 20) {
            f.write_all(piece).unwrap();
        }
        assert!(
            f.writeback.is_some(),
            "two intervals written: the flush thread runs"
        );
        f.seek(SeekFrom::Start(0)).unwrap();
        f.write_all(&expected[..8]).unwrap();
        f.seek(SeekFrom::End(0)).unwrap();
        o.commit(f).unwrap();
        assert!(std::fs::read(&out).unwrap() == expected);

        let (o, mut f) = AtomicOutput::create(&dir.path().join("small.mcap"), false, &[]).unwrap();
        f.write_all(&expected[..interval - 1]).unwrap();
        assert!(f.writeback.is_none(), "below one interval no thread is started");
        o.commit(f).unwrap();
    }

    #[test]
    fn refuses_overwrite_without_force_and_input_as_output() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.mcap");
        std::fs::write(&out, b"old").unwrap();
        let err = AtomicOutput::create(&out, false, &[]).unwrap_err();
        assert!(
            matches!(&err, Error::OutputExists { path, appeared_while_writing: false } if *path == out),
            "{err}"
        );
        let err = AtomicOutput::create(&out, true, &[out.as_path()])
            .unwrap_err()
            .to_string();
        assert!(err.contains("different from the input"), "{err}");
        let (o, f) = AtomicOutput::create(&out, true, &[]).unwrap();
        o.commit(f).unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"");
        let err = AtomicOutput::create(dir.path(), true, &[])
            .unwrap_err()
            .to_string();
        assert!(err.contains("directory"), "{err}");
    }

    #[test]
    fn an_output_that_appeared_while_writing_is_kept_unless_forced() {
        // Another process (another node of a cluster) finishes the same output first.
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.mcap");
        let (o, mut f) = AtomicOutput::create(&out, false, &[]).unwrap();
        f.write_all(b"mine").unwrap();
        let temp = o.temp_path().to_owned();
        std::fs::write(&out, b"theirs").unwrap();
        let err = o.commit(f).unwrap_err();
        assert!(
            matches!(
                &err,
                Error::OutputExists {
                    appeared_while_writing: true,
                    ..
                }
            ),
            "{err}"
        );
        assert_eq!(std::fs::read(&out).unwrap(), b"theirs");
        assert!(!temp.exists());

        let (o, mut f) = AtomicOutput::create(&out, true, &[]).unwrap();
        f.write_all(b"mine").unwrap();
        o.commit(f).unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"mine");
    }

    #[test]
    fn refuses_a_folder_name_and_a_missing_folder_before_writing_anything() {
        let dir = tempfile::tempdir().unwrap();
        // `new/` does not exist: a name ending in a separator is a folder all the same (the
        // temporary file would otherwise be `new.<pid>.tmp`, and only the rename would fail).
        let folder_name = PathBuf::from(format!("{}/new/", dir.path().display()));
        let err = AtomicOutput::create(&folder_name, true, &[])
            .unwrap_err()
            .to_string();
        assert!(err.contains("a file path, found a directory name"), "{err}");
        let err = AtomicOutput::create(&dir.path().join("new/a.mcap"), true, &[])
            .unwrap_err()
            .to_string();
        assert!(err.contains("new does not exist"), "{err}");
        let file = dir.path().join("f");
        std::fs::write(&file, b"").unwrap();
        let err = AtomicOutput::create(&file.join("a.mcap"), true, &[])
            .unwrap_err()
            .to_string();
        assert!(err.contains("f is not a folder"), "{err}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "only f");
        assert!(names_folder(Path::new("x/")) && !names_folder(&file));
        // A bare file name lies in the working folder, which exists.
        assert!(names_folder(Path::new(".")) && !names_folder(Path::new("a.mcap")));
    }

    #[cfg(unix)]
    #[test]
    fn refuses_to_replace_a_device() {
        let err = AtomicOutput::create(Path::new("/dev/null"), true, &[])
            .unwrap_err()
            .to_string();
        assert!(err.contains("a regular file path"), "{err}");
        assert!(std::fs::metadata("/dev/null").is_ok_and(|m| !m.is_file()));
    }
}
