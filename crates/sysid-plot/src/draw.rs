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
    let ((x0, x1), (y0, y1)) = ranges(panel).ok_or("no data")?;
    match (panel.x_scale, panel.y_scale) {
        (Scale::Linear, Scale::Linear) => draw_in(area, panel, x0..x1, y0..y1),
        (Scale::Log, Scale::Linear) => draw_in(area, panel, (x0..x1).log_scale(), y0..y1),
        (Scale::Linear, Scale::Log) => draw_in(area, panel, x0..x1, (y0..y1).log_scale()),
        (Scale::Log, Scale::Log) => {
            draw_in(area, panel, (x0..x1).log_scale(), (y0..y1).log_scale())
        }
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

fn draw_in<DB, X, Y>(area: &DrawingArea<DB, Shift>, panel: &Panel, x: X, y: Y) -> Result<(), String>
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
    chart
        .configure_mesh()
        .x_desc(&panel.x_label)
        .y_desc(&panel.y_label)
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
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
        let outline: Vec<(f64, f64)> = points
            .iter()
            .map(|&&(x, _, hi)| (x, hi))
            .chain(points.iter().rev().map(|&&(x, lo, _)| (x, lo)))
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
        for part in segments(panel, series) {
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
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(e)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Band;

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
