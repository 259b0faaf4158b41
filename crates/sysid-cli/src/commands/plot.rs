//! `sysid plot`: figures from the files sysid writes.
//!
//! | file | recognised by | figure |
//! | --- | --- | --- |
//! | EM trace (`fit --trace`) | columns `iteration, loglik, ...` | log-likelihood, and one panel per parameter column |
//! | model (`fit`, `n4sid`, `simulate --model-out`) | `.json` | Bode magnitude of every input-output channel, one curve per model |
//! | states (`smooth`, `filter`, `psmooth`, `pf`) | columns `t, x1.., [x1_sd..]` (a model file's state names instead of `x1..`) | each state with a 95 % band (mean +- 1.96 sd), against `--truth` |
//! | chains (`pmmh --out`, `pgas --out`) | columns `chain, iteration, burn_in, ...` | each parameter and the log-likelihood against the iteration, one line per chain, the burn-in faint |
//! | data (`simulate`) | columns `t, u.., y..` | each column against t |
//!
//! Figures are `<out-dir>/<file stem>-<kind>.svg` and `.png`; the models together give
//! `<out-dir>/bode.svg` and `.png`.

use crate::error::CliError;
use crate::files::read_columns;
use std::path::{Path, PathBuf};
use sysid::kalman::LinearGaussianModel;
use sysid::kalman::ParameterCovariance;
use sysid_plot::{Band, Figure, Panel, Scale, Series, Stroke};

/// Options of `sysid plot`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Files written by sysid: EM traces, models (JSON), states, data (CSV).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// What the files are: auto (from their content), trace, bode, states, chains or
    /// data; for model files also step or impulse (their responses from rest, per
    /// channel).
    #[arg(long, default_value = "auto")]
    pub kind: String,
    /// States: a data file with the true states (columns named as the estimates':
    /// x1, x2, ... or a model file's state names; `simulate --states` writes them) to
    /// draw against the estimates.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Directory for the figures (created if missing).
    #[arg(long, default_value = ".")]
    pub out_dir: PathBuf,
    /// Replace existing figures.
    #[arg(long)]
    pub force: bool,
    /// Print the written files as one JSON line.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Trace,
    Bode,
    Step,
    Impulse,
    States,
    Chain,
    Data,
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Trace => "trace",
            Kind::Bode => "bode",
            Kind::Step => "step",
            Kind::Impulse => "impulse",
            Kind::States => "states",
            Kind::Chain => "chains",
            Kind::Data => "data",
        }
    }
}

fn bad(message: String) -> CliError {
    CliError::BadOption {
        option: "plot",
        message,
    }
}

/// The kind of a file: by `--kind`, else JSON = model, else by the CSV header.
fn kind_of(path: &Path, requested: &str) -> Result<Kind, CliError> {
    let kind = match requested {
        "trace" => Kind::Trace,
        "bode" => Kind::Bode,
        "step" => Kind::Step,
        "impulse" => Kind::Impulse,
        "states" => Kind::States,
        "chains" => Kind::Chain,
        "data" => Kind::Data,
        "auto" => {
            if path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("json"))
            {
                return Ok(Kind::Bode);
            }
            let (header, _) = crate::files::read_rows(path)?;
            let has = |name: &str| header.iter().any(|h| h == name);
            if has("chain") && has("iteration") && has("burn_in") {
                Kind::Chain
            } else if header.first().is_some_and(|h| h == "iteration") && has("loglik") {
                Kind::Trace
            } else if header.iter().any(|h| h.ends_with("_sd"))
                || (header.iter().any(|h| h == "x1") && !header.iter().any(|h| h.starts_with('y')))
            {
                Kind::States
            } else {
                Kind::Data
            }
        }
        other => {
            return Err(CliError::BadOption {
                option: "--kind",
                message: format!(
                    "unknown kind {other:?} (known: auto, trace, bode, step, impulse, states, chains, data)"
                ),
            });
        }
    };
    Ok(kind)
}

fn column<'a>(header: &[String], columns: &'a [Vec<f64>], name: &str) -> Option<&'a Vec<f64>> {
    header.iter().position(|h| h == name).map(|i| &columns[i])
}

/// x values: the `t` or `iteration` column, else 1, 2, ...
fn abscissa(header: &[String], columns: &[Vec<f64>], name: &str) -> Vec<f64> {
    column(header, columns, name).cloned().unwrap_or_else(|| {
        (1..=columns.first().map_or(0, Vec::len))
            .map(|k| k as f64)
            .collect()
    })
}

fn trace_figure(path: &Path) -> Result<Figure, CliError> {
    let (header, columns) = read_columns(path)?;
    let x = abscissa(&header, &columns, "iteration");
    let mut panels = Vec::new();
    for (name, values) in header
        .iter()
        .zip(&columns)
        .filter(|(h, _)| *h != "iteration")
    {
        let points = x.iter().copied().zip(values.iter().copied()).collect();
        let y_label = if name == "loglik" {
            "log-likelihood"
        } else {
            name.as_str()
        };
        panels.push(
            Panel::new(
                if name == "loglik" {
                    "log-likelihood".to_string()
                } else {
                    format!("parameter {name}")
                },
                "EM iteration",
                y_label,
            )
            .with_series(Series::line(name.clone(), points)),
        );
    }
    let columns = if panels.len() > 1 { 2 } else { 1 };
    Ok(Figure::grid(panels, columns))
}

/// MCMC chains: per parameter (and the log-likelihood), each chain's draws against the
/// iteration; the burn-in faint, the kept draws solid.
fn chain_figure(path: &Path) -> Result<Figure, CliError> {
    let (header, columns) = read_columns(path)?;
    let get = |name: &str| column(&header, &columns, name).cloned().unwrap_or_default();
    let (chain, iteration, burn_in) = (get("chain"), get("iteration"), get("burn_in"));
    let chains: Vec<usize> = {
        let mut ids: Vec<usize> = chain.iter().map(|&c| c.max(0.0) as usize).collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    };
    let bookkeeping = ["chain", "iteration", "burn_in", "log_prior", "accepted"];
    let kept_from = iteration
        .iter()
        .zip(&burn_in)
        .filter(|(_, b)| **b == 0.0)
        .map(|(&i, _)| i)
        .fold(f64::INFINITY, f64::min);
    let mut panels = Vec::new();
    for (name, values) in header
        .iter()
        .zip(&columns)
        .filter(|(h, _)| !bookkeeping.contains(&h.as_str()))
    {
        let title = if kept_from.is_finite() {
            format!("{name} (burn-in before iteration {kept_from}, faint)")
        } else {
            format!("{name} (burn-in only)")
        };
        let mut panel = Panel::new(title, "iteration", name.clone());
        for (k, &id) in chains.iter().enumerate() {
            let part = |burn: bool| -> Vec<(f64, f64)> {
                (0..values.len())
                    .filter(|&r| chain[r] as usize == id && (burn_in[r] != 0.0) == burn)
                    .map(|r| (iteration[r], values[r]))
                    .collect()
            };
            let burn = part(true);
            if !burn.is_empty() {
                panel = panel.with_series(Series::faint(burn).colour(k));
            }
            let kept = part(false);
            if !kept.is_empty() {
                panel = panel.with_series(Series::line(format!("chain {id}"), kept).colour(k));
            }
        }
        panels.push(panel);
    }
    if panels.is_empty() || chains.is_empty() {
        return Err(bad(format!(
            "{}: no draws (columns besides chain, iteration, burn_in)",
            path.display()
        )));
    }
    let columns = if panels.len() > 1 { 2 } else { 1 };
    Ok(Figure::grid(panels, columns))
}

/// The rows of the detail panel beside a long record's states.
const WINDOW: usize = 100;

fn states_figure(path: &Path, truth: Option<&Path>) -> Result<Figure, CliError> {
    let (header, columns) = read_columns(path)?;
    let t = abscissa(&header, &columns, "t");
    let truth_path = truth;
    let truth = truth.map(read_columns).transpose()?;
    // the truth is drawn at its own times: it must cover the estimates' (a record of
    // another length used to be drawn over part of the window, in silence)
    if let (Some((th, tc)), Some(path)) = (&truth, truth_path) {
        let tt = abscissa(th, tc, "t");
        let span = |v: &[f64]| {
            v.iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                    (lo.min(x), hi.max(x))
                })
        };
        let ((lo, hi), (tlo, thi)) = (span(&t), span(&tt));
        if !t.is_empty() && (tt.is_empty() || tlo > lo || thi < hi) {
            return Err(CliError::BadOption {
                option: "--truth",
                message: format!(
                    "{}: its times run from {} to {}, the states' from {} to {}: give the \
                     record the states were estimated from",
                    path.display(),
                    crate::files::fmt(tlo),
                    crate::files::fmt(thi),
                    crate::files::fmt(lo),
                    crate::files::fmt(hi)
                ),
            });
        }
    }
    let mut panels = Vec::new();
    // a long record is shown whole and, beside it, its first WINDOW rows in detail
    let rows = t.len();
    let windowed = rows > 3 * WINDOW;
    // the states are the columns other than the time and the sds, named as the model
    // names them (x1, x2, ... or a model file's names)
    let names: Vec<String> = header
        .iter()
        .filter(|h| *h != "t" && !h.ends_with("_sd"))
        .cloned()
        .collect();
    for name in names {
        let Some(mean) = column(&header, &columns, &name) else {
            continue;
        };
        let sd = column(&header, &columns, &format!("{name}_sd"));
        let true_state = truth.as_ref().and_then(|(th, tc)| {
            let x = column(th, tc, &name)?;
            Some(abscissa(th, tc, "t").into_iter().zip(x.iter().copied()))
        });
        let panel = |title: String, shown: std::ops::Range<usize>| {
            let mut panel = Panel::new(title, "t", name.clone());
            let (first, last) = (t[shown.start], t[shown.end - 1]);
            if let Some(sd) = sd {
                let band = shown
                    .clone()
                    .map(|k| (t[k], mean[k] - 1.96 * sd[k], mean[k] + 1.96 * sd[k]))
                    .collect();
                panel = panel.with_band(Band {
                    name: "95 % band".into(),
                    points: band,
                    colour: 0,
                });
            }
            panel = panel.with_series(
                Series::line("estimate", shown.map(|k| (t[k], mean[k])).collect()).colour(0),
            );
            if let Some(points) = true_state.clone() {
                let points = points.filter(|&(x, _)| x >= first && x <= last).collect();
                panel = panel.with_series(
                    Series::line("true state", points)
                        .stroke(Stroke::Dashed)
                        .colour(1),
                );
            }
            panel
        };
        panels.push(panel(format!("state {name}"), 0..rows));
        if windowed {
            panels.push(panel(
                format!("state {name}, rows 1-{WINDOW} of {rows}"),
                0..WINDOW,
            ));
        }
    }
    if panels.is_empty() {
        return Err(bad(format!(
            "{}: no state columns (x1, x2, ... or a model's state names)",
            path.display()
        )));
    }
    let columns = if panels.len() > 1 { 2 } else { 1 };
    Ok(Figure::grid(panels, columns))
}

fn data_figure(path: &Path) -> Result<Figure, CliError> {
    let (header, columns) = read_columns(path)?;
    let t = abscissa(&header, &columns, "t");
    let panels: Vec<Panel> = header
        .iter()
        .zip(&columns)
        .filter(|(h, _)| *h != "t")
        .map(|(name, values)| {
            Panel::new(name.clone(), "t", name.clone()).with_series(Series::line(
                name.clone(),
                t.iter().copied().zip(values.iter().copied()).collect(),
            ))
        })
        .collect();
    if panels.is_empty() {
        return Err(bad(format!("{}: no columns besides t", path.display())));
    }
    let columns = if panels.len() > 1 { 2 } else { 1 };
    Ok(Figure::grid(panels, columns))
}

/// Bode magnitudes of every channel, one curve per model.
pub(crate) fn bode_figure(
    models: &[(String, LinearGaussianModel)],
    covariances: &[Option<ParameterCovariance>],
    sample_time: Option<f64>,
) -> Result<Figure, CliError> {
    let (x_label, per) = match sample_time {
        Some(ts) => ("frequency (rad per time unit)", ts),
        None => ("frequency (rad/sample)", 1.0),
    };
    let (p, m) = (models[0].1.p(), models[0].1.m());
    for (name, model) in models {
        if model.p() != p || model.m() != m {
            return Err(bad(format!(
                "{name}: {} outputs and {} inputs, but {} has {p} and {m}",
                model.p(),
                model.m(),
                models[0].0
            )));
        }
    }
    if m == 0 {
        return Err(bad(
            "the models have no inputs: there is no frequency response to draw".into(),
        ));
    }
    let grid: Vec<f64> = (0..240)
        .map(|k| std::f64::consts::PI * 10f64.powf(-2.5 + 2.5 * k as f64 / 239.0))
        .collect();
    // per output: a row of magnitudes, then a row of phases, one column per input
    let mut panels = Vec::new();
    for i in 0..p {
        let channel = |j: usize| format!("G{}{} (u{} to y{})", i + 1, j + 1, j + 1, i + 1);
        let mut phases = Vec::new();
        for j in 0..m {
            let mut magnitude = Panel::new(
                format!("{}: magnitude", channel(j)),
                x_label,
                "magnitude (dB)",
            )
            .scales(Scale::Log, Scale::Linear);
            let mut phase =
                Panel::new(format!("{}: phase", channel(j)), x_label, "phase (degrees)")
                    .scales(Scale::Log, Scale::Linear);
            for (k, (name, model)) in models.iter().enumerate() {
                let response: Vec<Option<nalgebra::Complex<f64>>> = grid
                    .iter()
                    .map(|&w| model.frequency_response(w).map(|g| g[(i, j)]))
                    .collect();
                let db: Vec<(f64, f64)> = grid
                    .iter()
                    .zip(&response)
                    .map(|(&w, g)| (w / per, g.map_or(f64::NAN, |g| 20.0 * g.norm().log10())))
                    .collect();
                let degrees = unwrapped_degrees(&response);
                if let Some(sd) = covariances
                    .get(k)
                    .and_then(Option::as_ref)
                    .and_then(|cov| response_sd(model, cov, i, j, &grid))
                {
                    let band = |centre: &[f64], spread: &[f64]| -> Vec<(f64, f64, f64)> {
                        grid.iter()
                            .zip(centre.iter().zip(spread))
                            .map(|(w, (c, s))| (w / per, c - 1.96 * s, c + 1.96 * s))
                            .filter(|(_, lo, hi)| lo.is_finite() && hi.is_finite())
                            .collect()
                    };
                    let db_values: Vec<f64> = db.iter().map(|p| p.1).collect();
                    let label = format!("{name}: 95 % band");
                    magnitude = magnitude.with_band(Band {
                        name: label.clone(),
                        points: band(&db_values, &sd.0),
                        colour: k,
                    });
                    phase = phase.with_band(Band {
                        name: label,
                        points: band(&degrees, &sd.1),
                        colour: k,
                    });
                }
                magnitude = magnitude.with_series(Series::line(name.clone(), db).colour(k));
                phase = phase.with_series(
                    Series::line(
                        name.clone(),
                        grid.iter().map(|w| w / per).zip(degrees).collect(),
                    )
                    .colour(k),
                );
            }
            panels.push(magnitude);
            phases.push(phase);
        }
        panels.extend(phases);
    }
    Ok(Figure::grid(panels, m))
}

/// The standard deviations of a channel's magnitude (dB) and phase (degrees) along a
/// frequency grid, by the delta method from the fit's parameter covariance: the
/// derivatives in the free entries of `A, B, C, D` by central differences. `None` when
/// none of them is free (the response is then known exactly).
fn response_sd(
    model: &LinearGaussianModel,
    cov: &ParameterCovariance,
    i: usize,
    j: usize,
    grid: &[f64],
) -> Option<(Vec<f64>, Vec<f64>)> {
    let entries: Vec<(usize, char, usize, usize)> = cov
        .names
        .iter()
        .enumerate()
        .filter_map(|(k, name)| {
            let (matrix, rest) = name.split_once('[')?;
            let (r, c) = rest.trim_end_matches(']').split_once(',')?;
            let letter = matrix
                .chars()
                .next()
                .filter(|l| "ABCD".contains(*l) && matrix.len() == 1)?;
            Some((
                k,
                letter,
                r.parse::<usize>().ok()? - 1,
                c.parse::<usize>().ok()? - 1,
            ))
        })
        .collect();
    if entries.is_empty() {
        return None;
    }
    let moved = |&(_, letter, r, c): &(usize, char, usize, usize), delta: f64| {
        let pick = |m: &nalgebra::DMatrix<f64>| {
            let mut m = m.clone();
            if r < m.nrows() && c < m.ncols() {
                m[(r, c)] += delta;
            }
            m
        };
        let b = model.to_builder();
        match letter {
            'A' => b.a(pick(model.a())),
            'B' => b.b(pick(model.b())),
            'C' => b.c(pick(model.c())),
            _ => b.d(pick(model.d())),
        }
        .build()
        .ok()
    };
    // derivatives of (dB, degrees) at each frequency, one row per entry
    let mut jac = Vec::with_capacity(entries.len());
    for e in &entries {
        let value = match e.1 {
            'A' => model.a()[(e.2, e.3)],
            'B' => model.b()[(e.2, e.3)],
            'C' => model.c()[(e.2, e.3)],
            _ => model.d()[(e.2, e.3)],
        };
        let h = 1e-6 * value.abs().max(1e-3);
        let (plus, minus) = (moved(e, h)?, moved(e, -h)?);
        let row: Vec<(f64, f64)> = grid
            .iter()
            .map(
                |&w| match (plus.frequency_response(w), minus.frequency_response(w)) {
                    (Some(gp), Some(gm)) => {
                        let (gp, gm) = (gp[(i, j)], gm[(i, j)]);
                        let db = 20.0 * (gp.norm().log10() - gm.norm().log10()) / (2.0 * h);
                        let deg = (gp / gm).arg().to_degrees() / (2.0 * h);
                        (db, deg)
                    }
                    _ => (f64::NAN, f64::NAN),
                },
            )
            .collect();
        jac.push(row);
    }
    let var = |f: &dyn Fn(&(f64, f64)) -> f64, w: usize| -> f64 {
        let mut v = 0.0;
        for (a, ea) in entries.iter().enumerate() {
            for (b, eb) in entries.iter().enumerate() {
                v += f(&jac[a][w]) * cov.matrix[ea.0][eb.0] * f(&jac[b][w]);
            }
        }
        v.max(0.0).sqrt()
    };
    let db = (0..grid.len()).map(|w| var(&|d| d.0, w)).collect();
    let deg = (0..grid.len()).map(|w| var(&|d| d.1, w)).collect();
    Some((db, deg))
}

/// Step (`step`) or impulse responses from rest of every channel, one curve per model,
/// over the time the slowest stable pole takes to decay to 1e-3 (20 to 1000 samples;
/// 100 with an unstable model).
fn response_figure(
    models: &[(String, LinearGaussianModel)],
    step: bool,
    sample_time: Option<f64>,
) -> Result<Figure, CliError> {
    let (p, m) = (models[0].1.p(), models[0].1.m());
    if m == 0
        || models
            .iter()
            .any(|(_, model)| model.p() != p || model.m() != m)
    {
        return Err(bad(
            "step and impulse responses need models with the same inputs and outputs (and at \
             least one input)"
                .into(),
        ));
    }
    let steps = models
        .iter()
        .map(|(_, model)| {
            let radius = sysid::kalman::spectral_radius(model.a());
            if radius >= 1.0 {
                100
            } else if radius <= 0.0 {
                20
            } else {
                ((1e-3f64).ln() / radius.ln()).ceil() as usize
            }
        })
        .max()
        .unwrap_or(100)
        .clamp(20, 1000);
    let ts = sample_time.unwrap_or(1.0);
    let what = if step { "step" } else { "impulse" };
    let mut panels = Vec::new();
    for i in 0..p {
        for j in 0..m {
            let mut panel = Panel::new(
                format!("{what} response, u{} to y{}", j + 1, i + 1),
                if sample_time.is_some() {
                    "time"
                } else {
                    "samples"
                },
                format!("y{}", i + 1),
            );
            for (name, model) in models {
                let mut x = nalgebra::DVector::zeros(model.n());
                let mut points = Vec::with_capacity(steps);
                for k in 0..steps {
                    let u = if step || k == 0 { 1.0 } else { 0.0 };
                    let y = (model.c() * &x)[i] + model.d()[(i, j)] * u;
                    points.push((k as f64 * ts, y));
                    x = model.a() * x + model.b().column(j) * u;
                }
                panel = panel.with_series(Series::line(name.clone(), points));
            }
            panels.push(panel);
        }
    }
    Ok(Figure::grid(panels, m))
}

/// Phases in degrees along a frequency grid, unwrapped (no jump of more than 180
/// degrees between neighbours); NaN where the response does not exist.
fn unwrapped_degrees(response: &[Option<nalgebra::Complex<f64>>]) -> Vec<f64> {
    let mut out = Vec::with_capacity(response.len());
    let mut previous: Option<f64> = None;
    for g in response {
        let Some(g) = g else {
            out.push(f64::NAN);
            continue;
        };
        let mut angle = g.arg().to_degrees();
        if let Some(prev) = previous {
            angle += 360.0 * ((prev - angle) / 360.0).round();
        }
        previous = Some(angle);
        out.push(angle);
    }
    out
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map_or("figure".into(), |s| s.to_string_lossy().into_owned())
}

pub fn run(o: &Options) -> Result<(), CliError> {
    let mut jobs: Vec<(String, Figure)> = Vec::new();
    let mut models = Vec::new();
    let mut sample_times = Vec::new();
    let mut model_kind = Kind::Bode;
    let mut covariances = Vec::new();
    for path in &o.files {
        match kind_of(path, &o.kind)? {
            kind @ (Kind::Bode | Kind::Step | Kind::Impulse) => {
                model_kind = kind;
                let file = crate::files::read_model_file(path)?;
                sample_times.push(file.metadata.as_ref().and_then(|m| m.sample_time));
                covariances.push(file.metadata.and_then(|m| m.covariance));
                models.push((stem(path), file.model));
            }
            kind => {
                let figure = match kind {
                    Kind::Trace => trace_figure(path)?,
                    Kind::States => states_figure(path, o.truth.as_deref())?,
                    Kind::Chain => chain_figure(path)?,
                    _ => data_figure(path)?,
                };
                jobs.push((format!("{}-{}", stem(path), kind.name()), figure));
            }
        }
    }
    if !models.is_empty() {
        // frequencies per unit of the data's time when every model has the same
        // sample time, else per sample
        let sample_time = sample_times
            .first()
            .copied()
            .flatten()
            .filter(|ts| sample_times.iter().all(|s| *s == Some(*ts)));
        let figure = match model_kind {
            Kind::Step | Kind::Impulse => {
                response_figure(&models, model_kind == Kind::Step, sample_time)?
            }
            _ => bode_figure(&models, &covariances, sample_time)?,
        };
        jobs.push((model_kind.name().into(), figure));
    }
    // two inputs with one name (a/trace.csv, b/trace.csv) get distinct figures
    let mut seen: Vec<String> = Vec::new();
    for (stem, _) in &mut jobs {
        let base = stem.clone();
        let mut k = 1;
        while seen.contains(stem) {
            k += 1;
            *stem = format!("{base}-{k}");
        }
        seen.push(stem.clone());
    }
    let targets: Vec<PathBuf> = jobs
        .iter()
        .flat_map(|(stem, _)| ["svg", "png"].map(|ext| o.out_dir.join(format!("{stem}.{ext}"))))
        .collect();
    crate::files::refuse_existing(targets.iter().map(PathBuf::as_path), o.force)?;
    let created = !o.out_dir.exists();
    std::fs::create_dir_all(&o.out_dir).map_err(|source| CliError::Io {
        path: o.out_dir.clone(),
        source,
    })?;
    let mut written = Vec::new();
    for (stem, figure) in &jobs {
        match figure.write(&o.out_dir, stem, o.force) {
            Ok(paths) => written.extend(paths),
            Err(e) => {
                // all or nothing: the figures of this command and a folder it made go
                for path in &written {
                    let _ = std::fs::remove_file(path);
                }
                if created {
                    let _ = std::fs::remove_dir(&o.out_dir);
                }
                return Err(e.into());
            }
        }
    }
    crate::report(
        o.json,
        serde_json::json!({"command": "plot", "figures": written}),
        || {
            written
                .iter()
                .map(|p| format!("wrote {}", p.display()))
                .collect::<Vec<_>>()
                .join("\n")
        },
    );
    Ok(())
}

#[cfg(test)]
mod phase_tests {
    use super::unwrapped_degrees;
    use nalgebra::Complex;

    /// A delay of three samples, `z^-3`: its phase is `-3 omega` in radians, a straight
    /// line through -180 and -360 degrees without jumps.
    #[test]
    fn a_delay_has_a_straight_unwrapped_phase() {
        let grid: Vec<f64> = (0..200)
            .map(|k| std::f64::consts::PI * k as f64 / 200.0)
            .collect();
        let response: Vec<Option<Complex<f64>>> = grid
            .iter()
            .map(|&w| Some(Complex::from_polar(1.0, -3.0 * w)))
            .collect();
        let phase = unwrapped_degrees(&response);
        for (w, p) in grid.iter().zip(&phase) {
            assert!((p - (-3.0 * w).to_degrees()).abs() < 1e-9, "omega {w}: {p}");
        }
        assert!(unwrapped_degrees(&[None, Some(Complex::new(1.0, 0.0))])[0].is_nan());
    }
}

#[cfg(test)]
mod response_tests {
    use super::response_figure;
    use nalgebra::dmatrix;
    use sysid::kalman::LinearGaussianModel;

    /// x' = 0.5 x + u, y = x: the step response rises to the static gain 2 as
    /// 2 (1 - 0.5^k), the impulse response is 0.5^(k-1) after a zero.
    #[test]
    fn a_first_order_system_responds_as_its_formula() {
        let model = LinearGaussianModel::builder(
            dmatrix![0.5],
            dmatrix![1.0],
            dmatrix![1.0],
            dmatrix![1.0],
        )
        .b(dmatrix![1.0])
        .build()
        .unwrap();
        let models = vec![("m".to_string(), model)];
        let step = response_figure(&models, true, None).unwrap();
        let points = &step.panels[0].series[0].points;
        assert_eq!(
            points.len(),
            20,
            "decays to 1e-3 in 10 samples, at least 20 drawn"
        );
        for &(k, y) in points {
            assert!(
                (y - 2.0 * (1.0 - 0.5f64.powf(k))).abs() < 1e-12,
                "step at {k}: {y}"
            );
        }
        let impulse = response_figure(&models, false, Some(2.0)).unwrap();
        let points = &impulse.panels[0].series[0].points;
        assert_eq!(points[0], (0.0, 0.0));
        assert_eq!(points[3], (6.0, 0.25), "time in units of the sample time");
    }
}

#[cfg(test)]
mod band_tests {
    use super::response_sd;
    use nalgebra::{Complex, dmatrix};
    use sysid::kalman::{LinearGaussianModel, ParameterCovariance};

    /// G(z) = b / (z - a): the delta method's closed form, `d dB / d a = 20 / ln 10
    /// Re(1 / (z - a))`, `d dB / d b = 20 / (b ln 10)`, `d phase / d a = Im(1 / (z - a))`
    /// (radians), `d phase / d b = 0`, against the central differences.
    #[test]
    fn the_band_is_the_delta_method_of_a_first_order_system() {
        let (a, b) = (0.8, 0.5);
        let model =
            LinearGaussianModel::builder(dmatrix![a], dmatrix![1.0], dmatrix![0.1], dmatrix![0.2])
                .b(dmatrix![b])
                .build()
                .unwrap();
        let cov = ParameterCovariance {
            names: vec!["A[1,1]".into(), "B[1,1]".into(), "Q[1,1]".into()],
            matrix: vec![
                vec![4e-4, 1e-4, 0.5],
                vec![1e-4, 9e-4, 0.5],
                vec![0.5, 0.5, 9.0],
            ],
        };
        let grid = [0.01, 0.3, 1.0, 3.0];
        let (db, deg) = response_sd(&model, &cov, 0, 0, &grid).unwrap();
        let k = 20.0 / std::f64::consts::LN_10;
        for (w, &omega) in grid.iter().enumerate() {
            let inv = Complex::new(1.0, 0.0) / (Complex::from_polar(1.0, omega) - a);
            let (ja, jb) = (k * inv.re, k / b);
            let want_db = (ja * ja * 4e-4 + 2.0 * ja * jb * 1e-4 + jb * jb * 9e-4).sqrt();
            let want_deg = inv.im.to_degrees().abs() * 4e-4f64.sqrt();
            assert!(
                (db[w] - want_db).abs() < 1e-6 * want_db,
                "dB at {omega}: {} vs {want_db}",
                db[w]
            );
            assert!(
                (deg[w] - want_deg).abs() < 1e-6 * want_deg,
                "phase at {omega}: {} vs {want_deg}",
                deg[w]
            );
        }
        // no free entry of A, B, C, D: no band
        let noise_only = ParameterCovariance {
            names: vec!["Q[1,1]".into()],
            matrix: vec![vec![1.0]],
        };
        assert!(response_sd(&model, &noise_only, 0, 0, &grid).is_none());
    }
}
