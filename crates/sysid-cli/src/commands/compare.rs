//! `sysid compare`: how well models reproduce a record, as MATLAB's `compare` does:
//! the fit per output of the simulated (`--horizon inf`) or k-step predicted outputs.

use super::{in_data, model_and_data, parse_initial};
use crate::DataArgs;
use crate::error::CliError;
use std::path::PathBuf;
use sysid::kalman::fit_percent;
use sysid_plot::{Figure, Panel, Series};

/// Options of `sysid compare`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Model files (JSON), one or more.
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

/// The horizon: `None` for the simulation, `Some(k)` for k-step predictions.
fn parse_horizon(text: &str) -> Result<Option<usize>, CliError> {
    let bad = |message: String| CliError::BadOption {
        option: "--horizon",
        message,
    };
    match text.trim() {
        "inf" | "Inf" | "infinity" => Ok(None),
        other => match other.parse::<usize>() {
            Ok(0) => Err(bad("must be at least 1, or inf".into())),
            Ok(k) => Ok(Some(k)),
            Err(_) => Err(bad(format!(
                "{other:?} is neither a positive integer nor inf"
            ))),
        },
    }
}

pub fn run(o: &Options) -> Result<(), CliError> {
    let horizon = parse_horizon(&o.horizon)?;
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
    let mut file_names = None;
    let mut curves = Vec::new();
    let mut data = None;
    for path in &o.model {
        let (model, file) = model_and_data(path, &o.data, &o.initial)?;
        if file.record.len() <= o.burn_in {
            return Err(CliError::BadOption {
                option: "--burn-in",
                message: format!(
                    "{} leaves no step of the record's {} to score",
                    o.burn_in,
                    file.record.len()
                ),
            });
        }
        let outputs = match horizon {
            None => {
                model
                    .response(&file.record, None)
                    .map_err(|source| CliError::Model {
                        path: path.clone(),
                        source,
                    })?
                    .outputs
            }
            Some(k) => {
                model
                    .predict(&file.record, k)
                    .map_err(in_data(&o.data.data))?
                    .mean
            }
        };
        // in the file's units (a model fitted with --detrend linear)
        let outputs = file.restored(&outputs);
        let fit = fit_percent(&file.measured(), &outputs, o.burn_in);
        let mean = fit.iter().sum::<f64>() / fit.len() as f64;
        rows.push(serde_json::json!({
            "model": path, "fit_percent": fit, "fit_percent_mean": mean,
        }));
        curves.push((path.display().to_string(), outputs, fit));
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
        let figure = figure(&file, &names, &curves, o.burn_in, &o.horizon);
        written = figure
            .write(dir, "compare", o.force)
            .map_err(CliError::Plot)?;
    }
    let what = match horizon {
        None => "simulation".to_string(),
        Some(k) => format!("{k}-step prediction"),
    };
    crate::report(
        o.json,
        serde_json::json!({
            "command": "compare", "horizon": o.horizon, "burn_in": o.burn_in,
            "outputs": names, "models": rows, "figures": written,
        }),
        || {
            let mut text = format!("fit % ({what}, scored from step {}):", o.burn_in + 1);
            for (path, _, fit) in &curves {
                let per: Vec<String> = names
                    .iter()
                    .zip(fit)
                    .map(|(n, f)| format!("{n} {f:.2}"))
                    .collect();
                text += &format!("\n  {path}: {}", per.join(", "));
            }
            text
        },
    );
    Ok(())
}

/// One panel per output: the measured output and each model's.
fn figure(
    file: &crate::files::DataFile,
    names: &[String],
    curves: &[(String, nalgebra::DMatrix<f64>, Vec<f64>)],
    burn_in: usize,
    horizon: &str,
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
            let what = match parse_horizon(horizon) {
                Ok(Some(1)) => "one-step predictions".to_string(),
                Ok(Some(k)) => format!("{k}-step predictions"),
                _ => "simulation".to_string(),
            };
            let mut panel = Panel::new(
                format!("{name}: measured and the models' {what}"),
                "t",
                name.clone(),
            )
            .with_series(Series::line("measured", points(&|t| file.record.y[(i, t)])).colour(0));
            for (k, (path, outputs, fit)) in curves.iter().enumerate() {
                let label = format!("{path}: fit {:.1} %", fit[i]);
                panel = panel
                    .with_series(Series::line(label, points(&|t| outputs[(i, t)])).colour(k + 1));
            }
            panel
        })
        .collect();
    Figure::grid(panels, 1)
}
