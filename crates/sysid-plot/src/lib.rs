//! Figures for sysid: line charts with bands, in panels, written as SVG and PNG.
//!
//! # Model
//! A [`Figure`] is a grid of [`Panel`]s; a panel has axis labels, linear or
//! logarithmic axes ([`Scale`]), line [`Series`] and shaded [`Band`]s (e.g. a 95 %
//! interval). The description is plain data, so a figure can be built by a library,
//! stored, or drawn again from a file by `sysid plot`.
//!
//! # Algorithm
//! Drawn with plotters. Text is set in DejaVu Sans, embedded in the binary (the
//! `dejavu` crate) and rasterised by `ab_glyph`, so no system font library is needed.
//! Axis ranges cover the finite points only; non-finite points are skipped, so a
//! missing value leaves a gap instead of spoiling the axes. Files are written to a
//! temporary name in the target directory and renamed into place: a failed draw leaves
//! no partial file, and an existing file is replaced only when asked.
//!
//! # Complexity
//! Linear in the number of points.
//!
//! # Example
//! ```
//! use sysid_plot::{Figure, Panel, Series};
//! let dir = std::env::temp_dir().join(format!("sysid-plot-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir).unwrap();
//! let points: Vec<(f64, f64)> = (0..50).map(|k| (k as f64, (k as f64 / 8.0).sin())).collect();
//! let figure = Figure::single(
//!     Panel::new("A sine", "t", "y").with_series(Series::line("sin(t/8)", points)),
//! );
//! let written = figure.write(&dir, "sine", true).unwrap();
//! assert!(written.iter().all(|p| p.exists()));
//! # std::fs::remove_dir_all(&dir).unwrap();
//! ```
//!
//! # References
//! The figures follow those of the seed documents: EM parameter trajectories (seed
//! 000, Figure 1) and Bode magnitudes of the initial, subspace and EM models (seed 004).

mod draw;
mod output;
pub mod trajectories;

pub use output::PlotError;

use std::path::{Path, PathBuf};

/// Axis scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Scale {
    /// Linear.
    #[default]
    Linear,
    /// Base-10 logarithmic; non-positive values are skipped.
    Log,
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Stroke {
    /// A solid line.
    #[default]
    Solid,
    /// A dashed line (references: the truth, a bound).
    Dashed,
    /// A thin, translucent line, for one member of a bundle (e.g. one EM run of many).
    Faint,
    /// Markers only.
    Points,
}

/// One curve.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry; `None` keeps the series out of the legend.
    pub name: Option<String>,
    /// The (x, y) points, in drawing order.
    pub points: Vec<(f64, f64)>,
    /// Palette index; `None` takes the next colour.
    pub colour: Option<usize>,
    /// Line style.
    pub stroke: Stroke,
}

impl Series {
    /// A solid line with a legend entry.
    pub fn line(name: impl Into<String>, points: Vec<(f64, f64)>) -> Series {
        Series {
            name: Some(name.into()),
            points,
            colour: None,
            stroke: Stroke::Solid,
        }
    }

    /// A faint line without a legend entry, in the first colour: one member of a bundle
    /// (e.g. one EM run of many).
    pub fn faint(points: Vec<(f64, f64)>) -> Series {
        Series {
            name: None,
            points,
            colour: Some(0),
            stroke: Stroke::Faint,
        }
    }

    /// This series with the given stroke.
    pub fn stroke(mut self, stroke: Stroke) -> Series {
        self.stroke = stroke;
        self
    }

    /// This series with the given palette colour.
    pub fn colour(mut self, colour: usize) -> Series {
        self.colour = Some(colour);
        self
    }

    /// This series without a legend entry.
    pub fn unnamed(mut self) -> Series {
        self.name = None;
        self
    }
}

/// A shaded region between two curves sharing their x values.
#[derive(Debug, Clone, PartialEq)]
pub struct Band {
    /// Legend entry.
    pub name: String,
    /// `(x, lower, upper)` triples.
    pub points: Vec<(f64, f64, f64)>,
    /// Palette index.
    pub colour: usize,
}

/// One chart: axes, curves and bands.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// Caption above the chart.
    pub title: String,
    /// Label of the horizontal axis.
    pub x_label: String,
    /// Label of the vertical axis.
    pub y_label: String,
    /// Horizontal scale.
    pub x_scale: Scale,
    /// Vertical scale.
    pub y_scale: Scale,
    /// Shaded bands, drawn first.
    pub bands: Vec<Band>,
    /// Curves, drawn in order over the bands.
    pub series: Vec<Series>,
}

impl Panel {
    /// An empty panel with linear axes.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Panel {
        Panel {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            x_scale: Scale::Linear,
            y_scale: Scale::Linear,
            bands: Vec::new(),
            series: Vec::new(),
        }
    }

    /// This panel with the given axis scales.
    pub fn scales(mut self, x: Scale, y: Scale) -> Panel {
        self.x_scale = x;
        self.y_scale = y;
        self
    }

    /// This panel with one more series.
    pub fn with_series(mut self, series: Series) -> Panel {
        self.series.push(series);
        self
    }

    /// This panel with one more band.
    pub fn with_band(mut self, band: Band) -> Panel {
        self.bands.push(band);
        self
    }
}

/// A grid of panels, written as `<stem>.svg` and `<stem>.png`.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// The panels, row by row.
    pub panels: Vec<Panel>,
    /// Panels per row.
    pub columns: usize,
    /// Size in pixels of one panel.
    pub panel_size: (u32, u32),
}

impl Figure {
    /// A figure of one panel, 800 x 500 pixels.
    pub fn single(panel: Panel) -> Figure {
        Figure::grid(vec![panel], 1)
    }

    /// A figure of several panels, `columns` per row, 560 x 380 pixels each.
    pub fn grid(panels: Vec<Panel>, columns: usize) -> Figure {
        let panel_size = if panels.len() == 1 {
            (800, 500)
        } else {
            (560, 380)
        };
        Figure {
            panels,
            columns: columns.max(1),
            panel_size,
        }
    }

    /// Size in pixels of the whole figure.
    pub fn size(&self) -> (u32, u32) {
        let rows = self.panels.len().div_ceil(self.columns).max(1) as u32;
        let columns = self.columns.min(self.panels.len()).max(1) as u32;
        (self.panel_size.0 * columns, self.panel_size.1 * rows)
    }

    /// The figure as an SVG document.
    pub fn to_svg(&self) -> Result<String, PlotError> {
        draw::svg(self)
    }

    /// Writes `<dir>/<stem>.svg` and `<dir>/<stem>.png` and returns their paths. An
    /// existing file is replaced only when `overwrite`; otherwise
    /// [`sysid_output::OutputError::WouldOverwrite`] is returned before anything is written.
    pub fn write(
        &self,
        dir: &Path,
        stem: &str,
        overwrite: bool,
    ) -> Result<Vec<PathBuf>, PlotError> {
        let svg_path = dir.join(format!("{stem}.svg"));
        let png_path = dir.join(format!("{stem}.png"));
        if !overwrite && let Some(path) = [&svg_path, &png_path].into_iter().find(|p| p.exists()) {
            return Err(sysid_output::OutputError::WouldOverwrite { path: path.clone() }.into());
        }
        let svg = self.to_svg()?;
        sysid_output::write_atomically(&svg_path, overwrite, |file| {
            std::io::Write::write_all(file, svg.as_bytes())
        })?;
        draw::png(self, &png_path, overwrite)?;
        Ok(vec![svg_path, png_path])
    }
}
