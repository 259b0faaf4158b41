//! Atomic output files: write to a temporary name beside the target, then move it into
//! place. A failure part-way leaves no partial file; an existing file is replaced only
//! when asked, and the no-replace move is itself atomic (a hard link, which fails if
//! the target exists).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use thiserror::Error;

/// Why a figure or an output file could not be written.
#[derive(Debug, Error)]
pub enum PlotError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
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
    /// The target exists and is not a regular file (a directory, a device, a fifo, or
    /// a symbolic link such as `/dev/stdout`): it is never replaced (the atomic rename
    /// would put a regular file in its place).
    #[error(
        "{path}: not a regular file (a directory, device, fifo or symbolic link); give a file name"
    )]
    NotAFile {
        /// The path.
        path: PathBuf,
    },
    /// A panel has no finite point to draw.
    #[error("panel {panel:?}: no finite point to draw")]
    NoData {
        /// The panel's title.
        panel: String,
    },
    /// A panel's values span more than an axis can show (beyond 1e307).
    #[error(
        "panel {panel:?}: the values of {axis} span {lo:e} to {hi:e} (with the margin), too wide to draw (at most 1e307)"
    )]
    TooWide {
        /// The panel's title.
        panel: String,
        /// The axis label.
        axis: String,
        /// The lower end of the range.
        lo: f64,
        /// The upper end.
        hi: f64,
    },
    /// More panels than one figure can hold (one per column of a wide file).
    #[error(
        "{panels} panels asked for one figure (one per column); at most {max}: plot a file with fewer columns"
    )]
    TooManyPanels {
        /// The panels asked for.
        panels: usize,
        /// The most a figure takes.
        max: usize,
    },
    /// The drawing library failed.
    #[error("{path}: drawing failed: {message}")]
    Draw {
        /// The file being drawn.
        path: PathBuf,
        /// The drawing library's message.
        message: String,
    },
}

impl PlotError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> PlotError {
        PlotError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// A fresh temporary path in `target`'s directory with `target`'s extension (some
/// writers choose the format by extension).
pub(crate) fn temporary_path(target: &Path) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = target
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    let unique = COUNTER.fetch_add(1, Ordering::Relaxed);
    target.with_file_name(format!(".{name}.tmp-{}-{unique}{ext}", std::process::id()))
}

/// Moves the finished `temporary` file to `target`; removes it on failure.
pub(crate) fn commit(temporary: &Path, target: &Path, overwrite: bool) -> Result<(), PlotError> {
    let moved = if overwrite {
        std::fs::rename(temporary, target)
    } else {
        match std::fs::hard_link(temporary, target) {
            Ok(()) => std::fs::remove_file(temporary),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                let _ = std::fs::remove_file(temporary);
                return Err(PlotError::WouldOverwrite {
                    path: target.to_path_buf(),
                });
            }
            // file systems without hard links: check, then rename
            Err(_) if target.exists() => {
                let _ = std::fs::remove_file(temporary);
                return Err(PlotError::WouldOverwrite {
                    path: target.to_path_buf(),
                });
            }
            Err(_) => std::fs::rename(temporary, target),
        }
    };
    moved.map_err(|source| {
        let _ = std::fs::remove_file(temporary);
        PlotError::io(target, source)
    })
}

/// An output file being written: the data go to a temporary file beside the target,
/// which [`PendingFile::commit`] moves into place. Dropped without a commit (an error
/// part-way), the temporary file is removed and the target is untouched.
#[derive(Debug)]
pub struct PendingFile {
    target: PathBuf,
    temporary: PathBuf,
    overwrite: bool,
    writer: Option<BufWriter<File>>,
}

impl PendingFile {
    /// Starts writing `target`. Without `overwrite` an existing `target` is refused
    /// now ([`PlotError::WouldOverwrite`]), and again, atomically, at the commit.
    pub fn create(target: &Path, overwrite: bool) -> Result<PendingFile, PlotError> {
        if !is_replaceable(target) {
            return Err(PlotError::NotAFile {
                path: target.to_path_buf(),
            });
        }
        if !overwrite && target.exists() {
            return Err(PlotError::WouldOverwrite {
                path: target.to_path_buf(),
            });
        }
        let temporary = temporary_path(target);
        let file = File::create(&temporary).map_err(|e| PlotError::io(target, e))?;
        Ok(PendingFile {
            target: target.to_path_buf(),
            temporary,
            overwrite,
            writer: Some(BufWriter::new(file)),
        })
    }

    /// The file this will become.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Flushes the data to disk and moves the file into place.
    pub fn commit(mut self) -> Result<(), PlotError> {
        let writer = self
            .writer
            .take()
            .expect("a pending file has its writer until commit");
        let flushed = writer
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|file| file.sync_all());
        match flushed {
            Ok(()) => commit(&self.temporary, &self.target, self.overwrite),
            Err(source) => {
                let _ = std::fs::remove_file(&self.temporary);
                Err(PlotError::io(&self.target, source))
            }
        }
    }
}

impl Write for PendingFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match &mut self.writer {
            Some(w) => w.write(buf),
            None => Err(std::io::Error::other("pending file already committed")),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.writer {
            Some(w) => w.flush(),
            None => Ok(()),
        }
    }
}

impl Drop for PendingFile {
    fn drop(&mut self) {
        if self.writer.take().is_some() {
            let _ = std::fs::remove_file(&self.temporary);
        }
    }
}

/// Whether `target` may be replaced by a rename: it does not exist, or it is a regular
/// file (not a symbolic link, whose rename would replace the link, not its file).
pub fn is_replaceable(target: &Path) -> bool {
    match std::fs::symlink_metadata(target) {
        Ok(meta) => meta.file_type().is_file(),
        Err(_) => true,
    }
}

/// Writes `target` through `write`, atomically (a [`PendingFile`] committed once
/// `write` has succeeded).
pub fn write_atomically(
    target: &Path,
    overwrite: bool,
    write: impl FnOnce(&mut PendingFile) -> std::io::Result<()>,
) -> Result<(), PlotError> {
    let mut file = PendingFile::create(target, overwrite)?;
    write(&mut file).map_err(|e| PlotError::io(target, e))?;
    file.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("sysid-plot-write-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn entries(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn refuses_to_replace_and_leaves_the_old_contents() {
        let dir = scratch("refuse");
        let target = dir.join("a.csv");
        std::fs::write(&target, "old").unwrap();
        let err = write_atomically(&target, false, |w| w.write_all(b"new")).unwrap_err();
        assert!(matches!(err, PlotError::WouldOverwrite { .. }), "{err}");
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "old");
        write_atomically(&target, true, |w| w.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "new");
        assert_eq!(entries(&dir), ["a.csv"]);
    }

    #[test]
    fn a_failed_write_leaves_no_file() {
        let dir = scratch("fail");
        let target = dir.join("b.csv");
        let err = write_atomically(&target, false, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("disk full"), "{err}");
        assert!(entries(&dir).is_empty(), "{:?}", entries(&dir));
    }

    #[test]
    fn a_dropped_pending_file_leaves_nothing() {
        let dir = scratch("drop");
        let mut file = PendingFile::create(&dir.join("d.csv"), false).unwrap();
        file.write_all(b"half").unwrap();
        drop(file);
        assert!(entries(&dir).is_empty(), "{:?}", entries(&dir));
    }

    #[test]
    fn the_no_replace_move_fails_if_the_target_appears_meanwhile() {
        let dir = scratch("race");
        let target = dir.join("c.csv");
        let temporary = temporary_path(&target);
        std::fs::write(&temporary, "mine").unwrap();
        std::fs::write(&target, "theirs").unwrap();
        assert!(matches!(
            commit(&temporary, &target, false),
            Err(PlotError::WouldOverwrite { .. })
        ));
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "theirs");
        assert_eq!(entries(&dir), ["c.csv"]);
    }
}
