//! The errors of drawing and writing a figure. Files are written all-or-nothing by
//! `sysid-output`.

use std::path::PathBuf;
use sysid_output::OutputError;
use thiserror::Error;

/// Why a figure or an output file could not be written.
#[derive(Debug, Error)]
pub enum PlotError {
    /// Writing a file failed, or the target may not be replaced (it exists and
    /// replacing it was not asked for, or it is not a regular file).
    #[error("{0}")]
    Output(#[from] OutputError),
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
