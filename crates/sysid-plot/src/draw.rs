//! Drawing a [`Figure`] with plotters, on the SVG and the bitmap backend.

use crate::output::PlotError;
use crate::{Figure, Panel, Scale, Series, Stroke};
use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

/// Okabe-Ito colours (distinguishable with the common colour-vision deficiencies).
const PALETTE: [RGBColor; 8] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(204, 121, 167),
    RGBColor(0, 0, 0),
    RGBColor(240, 228, 66),
];

const FONT: &str = "sans-serif";

fn colour(index: usize) -> RGBColor {
    PALETTE[index % PALETTE.len()]
}

/// Registers the embedded DejaVu Sans as plotters' `sans-serif` (once per process).
fn register_fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded fonts are valid TrueType files; a failure would only mean
        // plotters' default lookup, which then reports its own error when drawing.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
    });
}

/// The figure as an SVG document.
pub fn svg(figure: &Figure) -> Result<String, PlotError> {
    register_fonts();
    check_data(figure)?;
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, figure.size()).into_drawing_area();
        draw_figure(&root, figure)
            .and_then(|()| root.present().map_err(|e| e.to_string()))
            .map_err(|message| PlotError::Draw {
                path: "<svg>".into(),
                message,
            })?;
    }
    Ok(text)
}

/// Draws the figure as a PNG file at `target`, atomically.
pub fn png(figure: &Figure, target: &Path, overwrite: bool) -> Result<(), PlotError> {
    register_fonts();
    check_data(figure)?;
    let pending = sysid_output::PendingPath::create(target, overwrite)?;
    let drawn = {
        let root = BitMapBackend::new(pending.path(), figure.size()).into_drawing_area();
        draw_figure(&root, figure).and_then(|()| root.present().map_err(|e| e.to_string()))
    };
    match drawn {
        Ok(()) => Ok(pending.commit()?),
        // dropping `pending` removes what was drawn
        Err(message) => Err(PlotError::Draw {
            path: target.to_path_buf(),
            message,
        }),
    }
}

/// Every panel has something to draw.
/// Every panel has something to draw, on axes that are not too wide (the tick search
/// of a range near `f64::MAX` does not end).
fn check_data(figure: &Figure) -> Result<(), PlotError> {
    // a figure grows with its panels: 100 000 columns asked for a 12 GB bitmap
    if figure.panels.len() > MAX_PANELS {
        return Err(PlotError::TooManyPanels {
            panels: figure.panels.len(),
            max: MAX_PANELS,
        });
    }
    for panel in &figure.panels {
        let Some((x, y)) = ranges(panel) else {
            return Err(PlotError::NoData {
                panel: panel.title.clone(),
            });
        };
        for (axis, (lo, hi)) in [(&panel.x_label, x), (&panel.y_label, y)] {
            let width = hi - lo;
            if !(width.is_finite() && width <= MAX_WIDTH) {
                return Err(PlotError::TooWide {
                    panel: panel.title.clone(),
                    axis: axis.clone(),
                    lo,
                    hi,
                });
            }
        }
    }
    Ok(())
}

fn draw_figure<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    figure: &Figure,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let rows = figure.panels.len().div_ceil(figure.columns).max(1);
    let areas = root.split_evenly((rows, figure.columns));
    for (panel, area) in figure.panels.iter().zip(areas.iter()) {
        draw_panel(area, panel)?;
    }
    Ok(())
}

/// Whether a point can be drawn on the panel's axes.
fn drawable(panel: &Panel, x: f64, y: f64) -> bool {
    let fits = |v: f64, scale| v.is_finite() && (scale == Scale::Linear || v > 0.0);
    fits(x, panel.x_scale) && fits(y, panel.y_scale)
}

/// The panel's axis ranges over its drawable points, padded by 4 % (a factor on log
/// axes); `None` if nothing is drawable.
fn ranges(panel: &Panel) -> Option<((f64, f64), (f64, f64))> {
    let mut points: Vec<(f64, f64)> = Vec::new();
    for s in &panel.series {
        points.extend(s.points.iter().copied());
    }
    for b in &panel.bands {
        points.extend(b.points.iter().flat_map(|&(x, lo, hi)| [(x, lo), (x, hi)]));
    }
    points.retain(|&(x, y)| drawable(panel, x, y));
    let first = points.first()?;
    let (mut x, mut y) = ((first.0, first.0), (first.1, first.1));
    for &(px, py) in &points {
        x = (x.0.min(px), x.1.max(px));
        y = (y.0.min(py), y.1.max(py));
    }
    Some((pad(x, panel.x_scale, false), pad(y, panel.y_scale, true)))
}

/// The widest axis range drawn.
const MAX_WIDTH: f64 = 1e307;

/// The most panels one figure takes (its size grows with them).
pub const MAX_PANELS: usize = 64;

fn pad((lo, hi): (f64, f64), scale: Scale, margin: bool) -> (f64, f64) {
    let share = if margin { 0.04 } else { 0.0 };
    match scale {
        Scale::Linear if hi > lo => {
            let width = hi - lo;
            (lo - share * width, hi + share * width)
        }
        // all values equal: a visible range around them
        Scale::Linear => {
            let half = 0.5 * lo.abs().max(1.0);
            (lo - half, hi + half)
        }
        Scale::Log => {
            let (l, h) = (lo.log10(), hi.log10());
            let (l, h) = if h > l {
                (l - share * (h - l), h + share * (h - l))
            } else {
                (l - 0.5, h + 0.5)
            };
            (10f64.powf(l), 10f64.powf(h))
        }
    }
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let frame = ranges(panel).ok_or("no data")?;
    let ((x0, x1), (y0, y1)) = frame;
    match (panel.x_scale, panel.y_scale) {
        (Scale::Linear, Scale::Linear) => draw_in(area, panel, frame, x0..x1, y0..y1),
        (Scale::Log, Scale::Linear) => draw_in(area, panel, frame, (x0..x1).log_scale(), y0..y1),
        (Scale::Linear, Scale::Log) => draw_in(area, panel, frame, x0..x1, (y0..y1).log_scale()),
        (Scale::Log, Scale::Log) => draw_in(
            area,
            panel,
            frame,
            (x0..x1).log_scale(),
            (y0..y1).log_scale(),
        ),
    }
}

/// The tick labels plotters draws on a linear axis (its default of 11).
const LABELS: usize = 11;

/// One format for every tick label of a linear axis: the decimals its tick step needs,
/// in scientific notation with one shared exponent when the ticks are large or small,
/// and `0` for a tick that is zero up to round-off (plotters' `-1.11e-16`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct AxisFormat {
    step: f64,
    exponent: Option<i32>,
    decimals: usize,
}

impl AxisFormat {
    /// The format of the ticks plotters puts on the axis `lo..hi`.
    fn linear(lo: f64, hi: f64) -> AxisFormat {
        use plotters::coord::ranged1d::{BoldPoints, Ranged};
        use plotters::coord::types::RangedCoordf64;
        let ticks = RangedCoordf64::from(lo..hi).key_points(BoldPoints(LABELS));
        let step = ticks
            .windows(2)
            .map(|w| w[1] - w[0])
            .fold(f64::INFINITY, f64::min);
        let step = if step.is_finite() && step > 0.0 {
            step
        } else {
            (hi - lo).abs().max(f64::MIN_POSITIVE)
        };
        let largest = ticks
            .iter()
            .chain([&lo, &hi])
            .fold(0.0_f64, |m, v| m.max(v.abs()));
        let decimals = |step: f64| (-(step.log10() + 1e-9).floor()).clamp(0.0, 15.0) as usize;
        if largest > 0.0 && !(1e-3..1e5).contains(&largest) {
            let exponent = largest.log10().floor() as i32;
            AxisFormat {
                step,
                exponent: Some(exponent),
                decimals: decimals(step / 10f64.powi(exponent)),
            }
        } else {
            AxisFormat {
                step,
                exponent: None,
                decimals: decimals(step),
            }
        }
    }

    fn label(&self, v: f64) -> String {
        let d = self.decimals;
        if v.abs() < 1e-9 * self.step {
            // zero up to round-off, with the axis's decimals (no `-0`)
            return match self.exponent {
                Some(_) => "0".into(),
                None => format!("{:.d$}", 0.0),
            };
        }
        match self.exponent {
            Some(e) => format!("{:.d$}e{e}", v / 10f64.powi(e)),
            None => format!("{v:.d$}"),
        }
    }
}

/// The label of a tick at `v` on an axis of `scale` (`format` for a linear one).
fn axis_label(scale: Scale, format: &AxisFormat, v: f64) -> String {
    match scale {
        Scale::Linear => format.label(v),
        Scale::Log => tick(&v),
    }
}

/// A tick label: short, scientific for very large or small magnitudes.
fn tick(v: &f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        // three significant digits, trailing zeros of the mantissa dropped
        let text = format!("{v:.2e}");
        let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
        let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
        format!("{mantissa}e{exponent}")
    } else {
        let text = format!("{v:.4}");
        let text = text.trim_end_matches('0').trim_end_matches('.');
        if text == "-0" {
            "0".into()
        } else {
            text.into()
        }
    }
}

/// A panel's axis ranges, `((x0, x1), (y0, y1))`.
type Frame = ((f64, f64), (f64, f64));

/// A point's position in the frame, in `[0, 1]^2` (log axes by the logarithm).
fn unit(frame: Frame, panel: &Panel, (x, y): (f64, f64)) -> (f64, f64) {
    let along = |v: f64, (lo, hi): (f64, f64), scale: Scale| match scale {
        Scale::Linear => (v - lo) / (hi - lo),
        Scale::Log => (v.log10() - lo.log10()) / (hi.log10() - lo.log10()),
    };
    (
        along(x, frame.0, panel.x_scale),
        along(y, frame.1, panel.y_scale),
    )
}

/// The corner of the frame where the legend covers the fewest points (the upper right
/// on a tie).
fn emptiest_corner(panel: &Panel, frame: Frame) -> SeriesLabelPosition {
    let entries = panel.bands.len() + panel.series.iter().filter(|s| s.name.is_some()).count();
    let (w, h) = (0.38, (0.05 + 0.065 * entries as f64).min(0.6));
    let corners = [
        (
            SeriesLabelPosition::UpperRight,
            (1.0 - w, 1.0),
            (1.0 - h, 1.0),
        ),
        (SeriesLabelPosition::UpperLeft, (0.0, w), (1.0 - h, 1.0)),
        (SeriesLabelPosition::LowerRight, (1.0 - w, 1.0), (0.0, h)),
        (SeriesLabelPosition::LowerLeft, (0.0, w), (0.0, h)),
    ];
    let mut covered = [0usize; 4];
    let points = panel
        .series
        .iter()
        .flat_map(|s| s.points.iter().copied())
        .chain(
            panel
                .bands
                .iter()
                .flat_map(|b| b.points.iter().flat_map(|&(x, lo, hi)| [(x, lo), (x, hi)])),
        )
        .filter(|&(x, y)| drawable(panel, x, y));
    for p in points {
        let (u, v) = unit(frame, panel, p);
        for (k, (_, (u0, u1), (v0, v1))) in corners.iter().enumerate() {
            if (*u0..=*u1).contains(&u) && (*v0..=*v1).contains(&v) {
                covered[k] += 1;
            }
        }
    }
    let best = (0..4).min_by_key(|&k| covered[k]).unwrap_or(0);
    corners[best].0.clone()
}

/// Whether a line of these points would turn more often than every four pixels of a
/// plot `width` pixels wide (a noisy record of thousands of steps, drawn as a solid
/// block); a smooth curve of many points is not dense.
fn dense(points: &[(f64, f64)], width: usize) -> bool {
    if points.len() <= width {
        return false;
    }
    let turns = points
        .windows(3)
        .filter(|w| (w[1].1 - w[0].1) * (w[2].1 - w[1].1) < 0.0)
        .count();
    turns > width / 4
}

/// The outline of a long series' min/max envelope over `buckets` equal slices of the
/// frame's width: the maxima left to right, then the minima back.
fn envelope(points: &[(f64, f64)], buckets: usize, frame: Frame, scale: Scale) -> Vec<(f64, f64)> {
    let buckets = buckets.max(1);
    let (lo, hi) = match scale {
        Scale::Linear => frame.0,
        Scale::Log => (frame.0.0.log10(), frame.0.1.log10()),
    };
    let position = |x: f64| match scale {
        Scale::Linear => x,
        Scale::Log => x.log10(),
    };
    let mut slices: Vec<Option<(f64, f64, f64)>> = vec![None; buckets];
    for &(x, y) in points {
        let k = (((position(x) - lo) / (hi - lo)) * buckets as f64).floor();
        let k = (k.max(0.0) as usize).min(buckets - 1);
        let slot = slices[k].get_or_insert((x, y, y));
        slot.1 = slot.1.min(y);
        slot.2 = slot.2.max(y);
    }
    let filled: Vec<(f64, f64, f64)> = slices.into_iter().flatten().collect();
    filled
        .iter()
        .map(|&(x, _, top)| (x, top))
        .chain(filled.iter().rev().map(|&(x, bottom, _)| (x, bottom)))
        .collect()
}

/// Consecutive drawable points, split at the non-drawable ones (gaps).
fn segments(panel: &Panel, series: &Series) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for &(x, y) in &series.points {
        if drawable(panel, x, y) {
            out.last_mut().expect("non-empty").push((x, y));
        } else if !out.last().expect("non-empty").is_empty() {
            out.push(Vec::new());
        }
    }
    out.retain(|s| !s.is_empty());
    out
}

fn draw_in<DB, X, Y>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
    frame: Frame,
    x: X,
    y: Y,
) -> Result<(), String>
where
    DB: DrawingBackend,
    DB::ErrorType: 'static,
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, (FONT, 18).into_font().style(FontStyle::Bold))
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(64)
        .build_cartesian_2d(x, y)
        .map_err(e)?;
    let ((x0, x1), (y0, y1)) = frame;
    let (x_format, y_format) = (AxisFormat::linear(x0, x1), AxisFormat::linear(y0, y1));
    let x_tick = |v: &f64| axis_label(panel.x_scale, &x_format, *v);
    let y_tick = |v: &f64| axis_label(panel.y_scale, &y_format, *v);
    chart
        .configure_mesh()
        .x_desc(&panel.x_label)
        .y_desc(&panel.y_label)
        .x_label_formatter(&x_tick)
        .y_label_formatter(&y_tick)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(e)?;
    let mut legend = false;
    for band in &panel.bands {
        let fill = colour(band.colour).mix(0.22);
        let points: Vec<&(f64, f64, f64)> = band
            .points
            .iter()
            .filter(|&&(x, lo, hi)| drawable(panel, x, lo) && drawable(panel, x, hi))
            .collect();
        // inside the frame: a polygon is not clipped to it
        let clamp = |v: f64| v.clamp(y0, y1);
        let outline: Vec<(f64, f64)> = points
            .iter()
            .map(|&&(x, _, hi)| (x, clamp(hi)))
            .chain(points.iter().rev().map(|&&(x, lo, _)| (x, clamp(lo))))
            .collect();
        chart
            .draw_series(std::iter::once(Polygon::new(outline, fill.filled())))
            .map_err(e)?
            .label(band.name.clone())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 22, y + 5)], fill.filled()));
        legend = true;
    }
    let mut next_colour = 0;
    for series in &panel.series {
        let index = series.colour.unwrap_or_else(|| {
            next_colour += 1;
            next_colour - 1
        });
        let base = colour(index);
        let style = match series.stroke {
            Stroke::Faint => base.mix(0.35).stroke_width(1),
            Stroke::Points => base.filled(),
            _ => base.stroke_width(2),
        };
        let mut first = true;
        let width = chart.plotting_area().dim_in_pixel().0 as usize;
        for part in segments(panel, series) {
            if dense(&part, width) && !matches!(series.stroke, Stroke::Points | Stroke::Faint) {
                // more turns than pixels resolve: the min/max envelope over two-pixel slices,
                // filled and outlined translucent, so that what lies under it (a true
                // state) shows and a flat stretch stays a line
                let fill = base.mix(0.45);
                let outline = envelope(&part, width / 2, frame, panel.x_scale);
                let mut closed = outline.clone();
                closed.extend(outline.first().copied());
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        closed,
                        fill.stroke_width(1),
                    )))
                    .map_err(e)?;
                let drawn = chart
                    .draw_series(std::iter::once(Polygon::new(outline, fill.filled())))
                    .map_err(e)?;
                if first && let Some(name) = &series.name {
                    drawn
                        .label(format!("{name} (min-max envelope)"))
                        .legend(move |(x, y)| {
                            Rectangle::new([(x, y - 5), (x + 22, y + 5)], fill.filled())
                        });
                    legend = true;
                }
                first = false;
                continue;
            }
            let drawn = match series.stroke {
                Stroke::Points => {
                    chart.draw_series(part.into_iter().map(|p| Circle::new(p, 2, style)))
                }
                Stroke::Dashed => chart.draw_series(DashedLineSeries::new(part, 8, 5, style)),
                _ => chart.draw_series(LineSeries::new(part, style)),
            }
            .map_err(e)?;
            if first && let Some(name) = &series.name {
                drawn.label(name.clone()).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 22, y)], base.stroke_width(2))
                });
                legend = true;
            }
            first = false;
        }
    }
    if legend {
        chart
            .configure_series_labels()
            .label_font((FONT, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .position(emptiest_corner(panel, frame))
            .draw()
            .map_err(e)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Band;
    use plotters::coord::types::RangedCoordf64;

    #[test]
    fn ticks_are_short() {
        assert_eq!(tick(&0.5), "0.5");
        assert_eq!(tick(&25.0), "25");
        assert_eq!(tick(&-0.0), "0");
        assert_eq!(tick(&1e-5), "1e-5");
        assert_eq!(tick(&2e6), "2e6");
        assert_eq!(tick(&-1.2e5), "-1.2e5");
        assert_eq!(tick(&1.234e-7), "1.23e-7");
    }

    /// One format per axis: the decimals of the step (zero too), one exponent.
    #[test]
    fn linear_axes_have_one_tick_format() {
        let f = AxisFormat::linear(-1.0, 1.0);
        assert_eq!(f.label(-1.11e-16), "0.0");
        assert_eq!(f.label(0.2 + 0.1 - 0.1), "0.2");
        assert_eq!(f.label(-1.0), "-1.0");
        let f = AxisFormat::linear(-3.0e5, -1.0e4);
        assert_eq!(f.exponent, Some(5));
        assert_eq!(f.label(-1.0e5), "-1.0e5");
        assert_eq!(f.label(-2.0e4), "-0.2e5");
        let f = AxisFormat::linear(0.0, 200.0);
        assert_eq!((f.label(0.0), f.label(40.0)), ("0".into(), "40".into()));
        let f = AxisFormat::linear(1e-6, 5e-6);
        assert_eq!(f.label(2e-6), "2.0e-6");
        // every tick plotters would draw is labelled distinctly
        for (lo, hi) in [(-0.37, 12.9), (1234.5, 1234.9), (-7e-4, 3e-4), (0.0, 1e7)] {
            use plotters::coord::ranged1d::{BoldPoints, Ranged};
            let ticks = RangedCoordf64::from(lo..hi).key_points(BoldPoints(LABELS));
            let f = AxisFormat::linear(lo, hi);
            let labels: Vec<String> = ticks.iter().map(|&t| f.label(t)).collect();
            let mut unique = labels.clone();
            unique.dedup();
            assert_eq!(unique, labels, "{lo}..{hi}");
            assert!(labels.iter().all(|l| !l.contains("e-16")), "{labels:?}");
        }
    }

    #[test]
    fn the_legend_goes_to_the_emptiest_corner() {
        // points fill the upper half: the legend goes to a lower corner
        let points = (0..100)
            .map(|k| (k as f64, 1.0 + (k % 7) as f64 * 0.1))
            .collect();
        let panel = Panel::new("p", "x", "y")
            .with_series(Series::line("s", points))
            .with_series(Series::line("floor", vec![(0.0, 0.0), (10.0, 0.0)]));
        let frame = ranges(&panel).unwrap();
        assert_eq!(
            emptiest_corner(&panel, frame),
            SeriesLabelPosition::LowerRight
        );
    }

    #[test]
    fn only_a_series_that_turns_often_is_dense() {
        let smooth: Vec<(f64, f64)> = (0..5000).map(|k| (k as f64, (k as f64).ln_1p())).collect();
        assert!(!dense(&smooth, 500));
        let noisy: Vec<(f64, f64)> = (0..5000)
            .map(|k| (k as f64, ((k * 7919) % 13) as f64))
            .collect();
        assert!(dense(&noisy, 500));
        assert!(!dense(&noisy[..400], 500));
    }

    #[test]
    fn a_long_series_is_drawn_as_its_envelope() {
        let points: Vec<(f64, f64)> = (0..1000)
            .map(|k| (k as f64, if k % 2 == 0 { 1.0 } else { -1.0 }))
            .collect();
        let frame = ((0.0, 999.0), (-1.0, 1.0));
        let outline = envelope(&points, 100, frame, Scale::Linear);
        assert_eq!(outline.len(), 200);
        assert!(outline[..100].iter().all(|p| p.1 == 1.0));
        assert!(outline[100..].iter().all(|p| p.1 == -1.0));
    }

    #[test]
    fn ranges_skip_non_finite_and_non_positive_log_points() {
        let panel = Panel::new("p", "x", "y")
            .scales(Scale::Log, Scale::Linear)
            .with_series(Series::line(
                "s",
                vec![(0.0, 5.0), (1.0, f64::NAN), (10.0, 2.0), (100.0, 4.0)],
            ));
        let ((x0, x1), (y0, y1)) = ranges(&panel).unwrap();
        assert!(
            (x0 - 10.0).abs() < 1e-9 && (x1 - 100.0).abs() < 1e-9,
            "{x0} {x1}"
        );
        assert!(y0 < 2.0 && y1 > 4.0 && y1 < 5.0, "{y0} {y1}");
        let empty = Panel::new("e", "x", "y").with_series(Series::line("s", vec![(f64::NAN, 1.0)]));
        assert!(ranges(&empty).is_none());
    }

    #[test]
    fn gaps_split_a_series() {
        let panel = Panel::new("p", "x", "y");
        let s = Series::line(
            "s",
            vec![(0.0, 1.0), (1.0, f64::NAN), (2.0, 1.0), (3.0, 2.0)],
        );
        assert_eq!(
            segments(&panel, &s),
            vec![vec![(0.0, 1.0)], vec![(2.0, 1.0), (3.0, 2.0)]]
        );
    }

    #[test]
    fn the_svg_has_the_labels_and_legend() {
        let panel = Panel::new("Bode magnitude", "frequency (rad/sample)", "|G| (dB)")
            .scales(Scale::Log, Scale::Linear)
            .with_band(Band {
                name: "95 % band".into(),
                points: vec![(0.1, -1.0, 1.0), (1.0, -2.0, 2.0)],
                colour: 0,
            })
            .with_series(Series::line("truth", vec![(0.1, 0.0), (1.0, 0.5)]).stroke(Stroke::Dashed))
            .with_series(Series::line("EM", vec![(0.1, 0.1), (1.0, 0.4)]));
        let svg = Figure::single(panel).to_svg().unwrap();
        for text in [
            "Bode magnitude",
            "frequency (rad/sample)",
            "|G| (dB)",
            "truth",
            "EM",
            "95 % band",
        ] {
            assert!(svg.contains(text), "missing {text:?}");
        }
        let empty = Figure::single(Panel::new("nothing", "x", "y"));
        assert!(matches!(empty.to_svg(), Err(PlotError::NoData { .. })));
    }
}
