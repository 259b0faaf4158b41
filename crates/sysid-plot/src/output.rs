//! The errors of drawing and writing a figure. Files are written all-or-nothing by
//! `sysid-output`.

use std::path::PathBuf;
use sysid_output::OutputError;
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

impl From<OutputError> for PlotError {
    fn from(e: OutputError) -> PlotError {
        match e {
            OutputError::Io { path, source } => PlotError::Io { path, source },
            OutputError::WouldOverwrite { path } => PlotError::WouldOverwrite { path },
            OutputError::NotAFile { path } => PlotError::NotAFile { path },
        }
    }
}
