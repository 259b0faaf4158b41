//! `sysid compare`: how well models reproduce a record, as MATLAB's `compare` does:
//! the fit per output of the simulated (`--horizon inf`) or k-step predicted outputs.

use super::{kalman_error, model_and_data, parse_initial};
use crate::DataArgs;
use crate::error::CliError;
use std::path::{Path, PathBuf};
use sysid::kalman::{Comparison, Horizon};
use sysid::modelfile::{InitialState, SimulationComparison};
use sysid_plot::{Figure, Panel, Series};

/// Options of `sysid compare`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Model files, one or more: linear (JSON) or nonlinear (`.toml`, simulated
    /// noise-free; --horizon inf only).
    #[arg(long, num_args = 1.., required = true)]
    pub model: Vec<PathBuf>,
    #[command(flatten)]
    pub data: DataArgs,
    /// `inf` (the default): the noise-free simulation of the record's inputs from the
    /// initial state that fits the record best (least squares); k: the k-step-ahead
    /// predictions (Kalman filter from the record's initial state, see --initial).
    #[arg(long, default_value = "inf")]
    pub horizon: String,
    /// Steps at the start of the record that are not scored (e.g. 50 for a predictor
    /// started from an unknown state, as shared/data/score_fit.py does).
    #[arg(long, default_value_t = 0)]
    pub burn_in: usize,
    /// For k-step predictions, the initial state of the record: `model`, `stationary`
    /// or `diffuse` (see `sysid loglik --help`).
    #[arg(long, default_value = "model")]
    pub initial: String,
    /// Nonlinear model files: the initial state minimises the simulation error over the
    /// first N samples (Levenberg-Marquardt from the file's initial means; default: the
    /// whole record, as for linear models). Benchmark protocols fix N, e.g. 5.
    #[arg(long)]
    pub initial_samples: Option<usize>,
    /// Also draw the measured and the models' outputs, one panel per output, as
    /// compare.svg and compare.png in this directory (created if missing).
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Replace existing figures.
    #[arg(long)]
    pub force: bool,
    /// Print a machine-readable summary.
    #[arg(long)]
    pub json: bool,
}

pub fn run(o: &Options) -> Result<(), CliError> {
    const OPTIONS: &[(&str, &str)] = &[("horizon", "--horizon"), ("burn_in", "--burn-in")];
    let horizon: Horizon =
        o.horizon
            .parse()
            .map_err(kalman_error(Path::new(""), &o.data.data, OPTIONS))?;
    parse_initial(&o.initial)?;
    if let Some(dir) = &o.out_dir {
        crate::files::refuse_existing(
            ["compare.svg", "compare.png"]
                .map(|f| dir.join(f))
                .iter()
                .map(|p| p.as_path()),
            o.force,
        )?;
    }
    let mut rows = Vec::new();
    let mut rms = Vec::new();
    let mut file_names = None;
    let mut curves = Vec::new();
    let mut data = None;
    for path in &o.model {
        if crate::commands::nonlinear::is_model_file(path) {
            let (comparison, file, simulated) = simulate_model_file(o, path, horizon)?;
            rows.push(serde_json::json!({
                "model": path, "fit_percent": comparison.fit_percent,
                "fit_percent_mean": comparison.mean_fit_percent(),
                "rms": simulated.rms, "initial_state": simulated.initial_state,
            }));
            rms.push((path.display().to_string(), simulated.rms));
            curves.push((path.display().to_string(), comparison));
            file_names.get_or_insert(file.output_names.clone());
            data.get_or_insert(file);
            continue;
        }
        let (model, file) = model_and_data(path, &o.data, &o.initial)?;
        // in the file's units (a model fitted with --detrend linear)
        let trend = file.trend.as_ref().map(|t| t.outputs_at(&file.time));
        let comparison = model
            .compare(&file.record, horizon, o.burn_in, trend.as_ref())
            .map_err(kalman_error(path, &o.data.data, OPTIONS))?;
        rows.push(serde_json::json!({
            "model": path, "fit_percent": comparison.fit_percent,
            "fit_percent_mean": comparison.mean_fit_percent(),
        }));
        curves.push((path.display().to_string(), comparison));
        file_names.get_or_insert(file.output_names.clone());
        data.get_or_insert_with(|| {
            let mut original = file;
            original.record.y = original.measured();
            original
        });
    }
    let file = data.expect("at least one model");
    let names = file_names.unwrap_or_default();
    let mut written = Vec::new();
    if let Some(dir) = &o.out_dir {
        std::fs::create_dir_all(dir).map_err(|source| CliError::Io {
            path: dir.clone(),
            source,
        })?;
        let figure = figure(&file, &names, &curves, o.burn_in, horizon);
        written = figure
            .write(dir, "compare", o.force)
            .map_err(CliError::Plot)?;
    }
    let what = match horizon {
        Horizon::Simulation => "simulation".to_string(),
        Horizon::Steps(k) => format!("{k}-step prediction"),
    };
    crate::report(
        o.json,
        serde_json::json!({
            "command": "compare", "horizon": o.horizon, "burn_in": o.burn_in,
            "outputs": names, "models": rows, "figures": written,
        }),
        || {
            let mut text = format!("fit % ({what}, scored from step {}):", o.burn_in + 1);
            for (path, comparison) in &curves {
                let per: Vec<String> = names
                    .iter()
                    .zip(&comparison.fit_percent)
                    .map(|(n, f)| format!("{n} {f:.2}"))
                    .collect();
                text += &format!("\n  {path}: {}", per.join(", "));
            }
            for (path, rms) in &rms {
                let per: Vec<String> = names
                    .iter()
                    .zip(rms)
                    .map(|(n, r)| format!("{n} {}", crate::files::fmt(*r)))
                    .collect();
                text += &format!("\n  {path}: simulation RMS {}", per.join(", "));
            }
            text
        },
    );
    Ok(())
}

/// A nonlinear model file's noise-free simulation of the record, as a comparison (and
/// the library's result, for its RMS and initial state).
fn simulate_model_file(
    o: &Options,
    path: &Path,
    horizon: Horizon,
) -> Result<(Comparison, crate::files::DataFile, SimulationComparison), CliError> {
    if horizon != Horizon::Simulation {
        return Err(CliError::BadOption {
            option: "--horizon",
            message: format!(
                "{}: a nonlinear model file is compared by its noise-free simulation \
                 (--horizon inf); k-step predictions of model files are not available yet",
                path.display()
            ),
        });
    }
    let model = crate::commands::nonlinear::read(path)?;
    let file = o
        .data
        .read_for_names(&model.spec().inputs, &model.spec().outputs)?;
    let series = crate::commands::particle::series_of(&file, &o.data.data.display().to_string())?;
    let samples = o.initial_samples.unwrap_or(series.steps());
    if samples == 0 {
        return Err(CliError::BadOption {
            option: "--initial-samples",
            message: "at least 1 sample is needed".into(),
        });
    }
    let result = model
        .compare_simulation(series, InitialState::Estimate { samples }, o.burn_in)
        .map_err(|e| CliError::BadOption {
            option: "--model",
            message: format!("{} on {}: {e}", path.display(), o.data.data.display()),
        })?;
    let p = series.output_dim();
    let comparison = Comparison {
        horizon,
        burn_in: o.burn_in,
        outputs: nalgebra::DMatrix::from_fn(p, series.steps(), |i, t| result.outputs[t * p + i]),
        fit_percent: result.fit_percent.clone(),
    };
    Ok((comparison, file, result))
}

/// One panel per output: the measured output and each model's.
fn figure(
    file: &crate::files::DataFile,
    names: &[String],
    curves: &[(String, Comparison)],
    burn_in: usize,
    horizon: Horizon,
) -> Figure {
    let panels = names
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let points = |row: &dyn Fn(usize) -> f64| -> Vec<(f64, f64)> {
                (burn_in..file.record.len())
                    .map(|t| (file.time[t], row(t)))
                    .filter(|(_, v)| v.is_finite())
                    .collect()
            };
            let what = horizon.to_string();
            let mut panel = Panel::new(
                format!("{name}: measured and the models' {what}"),
                "t",
                name.clone(),
            )
            .with_series(Series::line("measured", points(&|t| file.record.y[(i, t)])).colour(0));
            for (k, (path, comparison)) in curves.iter().enumerate() {
                let label = format!("{path}: fit {:.1} %", comparison.fit_percent[i]);
                let outputs = &comparison.outputs;
                panel = panel
                    .with_series(Series::line(label, points(&|t| outputs[(i, t)])).colour(k + 1));
            }
            panel
        })
        .collect();
    Figure::grid(panels, 1)
}
