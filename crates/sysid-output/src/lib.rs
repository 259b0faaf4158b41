//! All-or-nothing output files: the data go to a temporary file beside the target
//! (`tempfile`), which is moved into place only once everything is written. A failure
//! part-way leaves no partial file; an existing file is replaced only when asked, and
//! the no-replace move is itself atomic (`persist_noclobber`: a hard link, which fails
//! if the target appeared meanwhile); a target that is not a regular file (a
//! directory, a device, a fifo, a symbolic link such as `/dev/stdout`) is refused.
//!
//! # Example
//! ```
//! use std::io::Write;
//! let dir = tempfile::tempdir()?;
//! let target = dir.path().join("out.csv");
//! sysid_output::write_atomically(&target, false, |w| w.write_all(b"t,y1\n1,0.5\n"))?;
//! // a second write without overwrite is refused and leaves the first
//! assert!(sysid_output::write_atomically(&target, false, |w| w.write_all(b"x")).is_err());
//! assert_eq!(std::fs::read_to_string(&target)?, "t,y1\n1,0.5\n");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use tempfile::{NamedTempFile, TempPath};

/// Why an output file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// Creating, writing or moving the file failed.
    #[error("{path}: {source}")]
    Io {
        /// The target file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The target exists and replacing it was not asked for.
    #[error("{path}: refusing to overwrite an existing file (use --force)")]
    WouldOverwrite {
        /// The existing file.
        path: PathBuf,
    },
    /// The target exists and is not a regular file: it is never replaced (the move
    /// would put a regular file in its place).
    #[error(
        "{path}: not a regular file (a directory, device, fifo or symbolic link); give a file name"
    )]
    NotAFile {
        /// The path.
        path: PathBuf,
    },
}

fn io(path: &Path, source: std::io::Error) -> OutputError {
    OutputError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Whether `target` may be replaced by a move: it does not exist, or it is a regular
/// file (not a symbolic link, whose replacement would replace the link, not its file).
pub fn is_replaceable(target: &Path) -> bool {
    match std::fs::symlink_metadata(target) {
        Ok(meta) => meta.file_type().is_file(),
        Err(_) => true,
    }
}

/// The checks made before anything is written.
fn check_target(target: &Path, overwrite: bool) -> Result<(), OutputError> {
    if !is_replaceable(target) {
        return Err(OutputError::NotAFile {
            path: target.to_path_buf(),
        });
    }
    if !overwrite && target.exists() {
        return Err(OutputError::WouldOverwrite {
            path: target.to_path_buf(),
        });
    }
    Ok(())
}

/// A temporary file in `target`'s directory, named after it and with its extension
/// (some writers choose the format by extension).
fn temporary_beside(target: &Path) -> Result<NamedTempFile, OutputError> {
    let dir = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let suffix = target
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    let prefix = format!(".{name}.tmp-");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(&suffix);
    // a new file gets the mode any program's new file gets (0666 less the umask), not
    // the temporary file's private 0600
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let file = builder.tempfile_in(dir).map_err(|e| io(target, e))?;
    // a replaced file keeps its mode
    if let Ok(old) = std::fs::metadata(target)
        && old.is_file()
    {
        file.as_file()
            .set_permissions(old.permissions())
            .map_err(|e| io(target, e))?;
    }
    Ok(file)
}

/// Moves the finished temporary file to `target` (removing it on failure).
fn persist(temporary: TempPath, target: &Path, overwrite: bool) -> Result<(), OutputError> {
    let moved = if overwrite {
        temporary.persist(target)
    } else {
        temporary.persist_noclobber(target)
    };
    moved.map_err(|e| {
        if !overwrite && target.exists() {
            OutputError::WouldOverwrite {
                path: target.to_path_buf(),
            }
        } else {
            io(target, e.error)
        }
        // `e.path` is dropped here, which removes the temporary file
    })
}

/// An output file being written; [`commit`](Self::commit) moves it into place.
/// Dropped without a commit (an error part-way), the temporary file is removed and the
/// target is untouched.
#[derive(Debug)]
pub struct PendingFile {
    target: PathBuf,
    overwrite: bool,
    writer: BufWriter<NamedTempFile>,
}

impl PendingFile {
    /// Starts writing `target`. Without `overwrite` an existing `target` is refused
    /// now, and again, atomically, at the commit.
    pub fn create(target: &Path, overwrite: bool) -> Result<PendingFile, OutputError> {
        check_target(target, overwrite)?;
        Ok(PendingFile {
            target: target.to_path_buf(),
            overwrite,
            writer: BufWriter::new(temporary_beside(target)?),
        })
    }

    /// The file this will become.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Flushes the data to disk and moves the file into place.
    pub fn commit(self) -> Result<(), OutputError> {
        let target = self.target;
        let file = self
            .writer
            .into_inner()
            .map_err(|e| io(&target, e.into_error()))?;
        file.as_file().sync_all().map_err(|e| io(&target, e))?;
        persist(file.into_temp_path(), &target, self.overwrite)
    }
}

impl Write for PendingFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.writer.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.writer.flush()
    }
}

/// A temporary path beside a target, for writers that create their file themselves
/// (an image encoder given a path): write to [`path`](Self::path), then
/// [`commit`](Self::commit). Dropped without a commit, whatever was written there is
/// removed.
#[derive(Debug)]
pub struct PendingPath {
    target: PathBuf,
    overwrite: bool,
    temporary: TempPath,
}

impl PendingPath {
    /// Reserves a temporary path for `target` (with its extension), after the checks
    /// of [`PendingFile::create`].
    pub fn create(target: &Path, overwrite: bool) -> Result<PendingPath, OutputError> {
        check_target(target, overwrite)?;
        Ok(PendingPath {
            target: target.to_path_buf(),
            overwrite,
            temporary: temporary_beside(target)?.into_temp_path(),
        })
    }

    /// Where to write.
    pub fn path(&self) -> &Path {
        &self.temporary
    }

    /// Moves what was written into place.
    pub fn commit(self) -> Result<(), OutputError> {
        persist(self.temporary, &self.target, self.overwrite)
    }
}

/// Writes `target` through `write`, all or nothing (a [`PendingFile`] committed once
/// `write` has succeeded).
pub fn write_atomically(
    target: &Path,
    overwrite: bool,
    write: impl FnOnce(&mut PendingFile) -> std::io::Result<()>,
) -> Result<(), OutputError> {
    let mut file = PendingFile::create(target, overwrite)?;
    write(&mut file).map_err(|e| io(target, e))?;
    file.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entries(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[cfg(unix)]
    #[test]
    fn a_new_file_gets_the_umask_s_mode_and_a_replaced_one_keeps_its_own() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        // what the umask gives any new file here
        let plain = dir.path().join("plain.txt");
        std::fs::write(&plain, "x").unwrap();
        let ours = dir.path().join("ours.txt");
        write_atomically(&ours, false, |w| w.write_all(b"x")).unwrap();
        assert_eq!(mode(&ours), mode(&plain));
        assert_ne!(mode(&ours), 0o600, "not the temporary file's private mode");
        std::fs::set_permissions(&ours, std::fs::Permissions::from_mode(0o640)).unwrap();
        write_atomically(&ours, true, |w| w.write_all(b"y")).unwrap();
        assert_eq!(mode(&ours), 0o640);
        assert_eq!(std::fs::read_to_string(&ours).unwrap(), "y");
    }

    #[test]
    fn refuses_to_replace_and_leaves_the_old_contents() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("a.csv");
        std::fs::write(&target, "old").unwrap();
        let err = write_atomically(&target, false, |w| w.write_all(b"new")).unwrap_err();
        assert!(matches!(err, OutputError::WouldOverwrite { .. }), "{err}");
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "old");
        write_atomically(&target, true, |w| w.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "new");
        assert_eq!(entries(dir.path()), ["a.csv"]);
    }

    #[test]
    fn a_failed_write_leaves_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("b.csv");
        let err = write_atomically(&target, false, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("disk full"), "{err}");
        assert!(entries(dir.path()).is_empty(), "{:?}", entries(dir.path()));
    }

    #[test]
    fn a_dropped_pending_file_or_path_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let mut file = PendingFile::create(&dir.path().join("d.csv"), false).unwrap();
        file.write_all(b"half").unwrap();
        drop(file);
        let path = PendingPath::create(&dir.path().join("e.png"), false).unwrap();
        assert!(path.path().to_string_lossy().ends_with(".png"));
        std::fs::write(path.path(), b"image").unwrap();
        drop(path);
        assert!(entries(dir.path()).is_empty(), "{:?}", entries(dir.path()));
    }

    #[test]
    fn the_no_replace_move_fails_if_the_target_appears_meanwhile() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("c.csv");
        let mut file = PendingFile::create(&target, false).unwrap();
        file.write_all(b"mine").unwrap();
        std::fs::write(&target, "theirs").unwrap();
        assert!(matches!(
            file.commit(),
            Err(OutputError::WouldOverwrite { .. })
        ));
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "theirs");
        assert_eq!(entries(dir.path()), ["c.csv"]);
    }

    #[test]
    fn a_directory_or_a_link_is_never_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        assert!(matches!(
            PendingFile::create(&sub, true),
            Err(OutputError::NotAFile { .. })
        ));
        #[cfg(unix)]
        {
            let link = dir.path().join("link");
            std::os::unix::fs::symlink(dir.path().join("elsewhere"), &link).unwrap();
            assert!(matches!(
                PendingFile::create(&link, true),
                Err(OutputError::NotAFile { .. })
            ));
        }
    }
}
