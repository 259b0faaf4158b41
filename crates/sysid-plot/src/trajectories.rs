//! Parameter trajectories of many runs of an iterative estimator, one panel per
//! parameter, with the true value dashed (seed 000's Figure 1).

use crate::{Figure, Panel, Series, Stroke};

/// One run: its start and its iterates (each a value per parameter).
#[derive(Debug, Clone, PartialEq)]
pub struct Run<'a> {
    /// The parameters at iteration 0.
    pub start: Vec<f64>,
    /// The parameters after each iteration.
    pub iterates: &'a [Vec<f64>],
}

/// A grid of panels, one per parameter (`names`), each with every run's trajectory as
/// a faint line and the truth as a dashed one. At most `max_points` points are drawn
/// per run (every k-th iterate, the last always), so a figure of hundreds of runs of
/// thousands of iterations stays small.
///
/// # Example
/// ```
/// use sysid_plot::trajectories::{Run, parameter_trajectories};
/// let iterates: Vec<Vec<f64>> = (1..=20).map(|k| vec![1.0 - 0.5f64.powi(k)]).collect();
/// let figure = parameter_trajectories(
///     "EM",
///     &["a"],
///     &[1.0],
///     &[Run { start: vec![0.0], iterates: &iterates }],
///     "EM iteration",
///     500,
/// );
/// assert!(figure.to_svg().unwrap().contains("true a = 1"));
/// ```
pub fn parameter_trajectories(
    title: &str,
    names: &[&str],
    truth: &[f64],
    runs: &[Run<'_>],
    x_label: &str,
    max_points: usize,
) -> Figure {
    let longest = runs.iter().map(|r| r.iterates.len()).max().unwrap_or(0);
    let panels = names
        .iter()
        .enumerate()
        .map(|(p, name)| {
            let mut panel = Panel::new(format!("{title}: {name}"), x_label, *name);
            for (k, run) in runs.iter().enumerate() {
                let every = run.iterates.len().div_ceil(max_points.max(1)).max(1);
                let last = run.iterates.len();
                let points = std::iter::once((0.0, run.start[p]))
                    .chain(
                        run.iterates
                            .iter()
                            .enumerate()
                            .filter(|(i, _)| (i + 1) % every == 0 || i + 1 == last)
                            .map(|(i, v)| ((i + 1) as f64, v[p])),
                    )
                    .collect();
                let line = Series::faint(points);
                panel = panel.with_series(if k == 0 {
                    Series {
                        name: Some(format!("runs (one line each, {})", runs.len())),
                        ..line
                    }
                } else {
                    line
                });
            }
            if let Some(&value) = truth.get(p) {
                panel = panel.with_series(
                    Series::line(
                        format!("true {name} = {value}"),
                        vec![(0.0, value), (longest as f64, value)],
                    )
                    .stroke(Stroke::Dashed)
                    .colour(6),
                );
            }
            panel
        })
        .collect();
    Figure::grid(panels, 2)
}
