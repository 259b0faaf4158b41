//! `sysid predict`: k-step-ahead predicted outputs, their standard deviations, the
//! prediction errors and the standardised errors.

use super::in_data;
use crate::error::CliError;
use crate::files::{create_output, fmt};
use std::io::Write;
use std::path::PathBuf;
use sysid::kalman::fit_percent;

/// Options of `sysid predict`.
#[derive(clap::Args, Debug)]
pub struct Options {
    #[command(flatten)]
    pub source: crate::ModelOnData,
    /// Prediction horizon k: y_t is predicted from the outputs up to t - k (and every
    /// input up to t). 1 gives the innovations.
    #[arg(long, default_value_t = 1)]
    pub horizon: usize,
    /// Nonlinear model files (`.toml`): particles of the bootstrap filter whose cloud is
    /// carried k - 1 steps ahead (the predictions' Monte Carlo error is about sd /
    /// sqrt(particles)).
    #[arg(long, default_value_t = 5000)]
    pub particles: usize,
    /// Nonlinear model files: the seed of the particle filter.
    #[arg(long, default_value_t = sysid::smc::DEFAULT_SEED)]
    pub seed: u64,
    /// Output CSV: t, then per output NAME: NAME_pred, NAME_sd, NAME_error, NAME_std
    /// (the error divided by the standard deviation).
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
    /// Print a machine-readable summary.
    #[arg(long)]
    pub json: bool,
}

pub fn run(o: &Options) -> Result<(), CliError> {
    if o.horizon == 0 {
        return Err(CliError::BadOption {
            option: "--horizon",
            message: "must be at least 1".into(),
        });
    }
    crate::files::check_outputs(std::iter::once(o.out.as_path()), o.force)?;
    if crate::commands::nonlinear::is_model_file(o.source.model_path()) {
        return run_model_file(o);
    }
    let (model, file) = o.source.load()?;
    let mut pred = model
        .predict(&file.record, o.horizon)
        .map_err(in_data(o.source.data_path()))?;
    // in the file's units (a model fitted with --detrend linear)
    pred.mean = file.restored(&pred.mean);
    let mut w = create_output(&o.out, o.force)?;
    let io = |source| CliError::Io {
        path: o.out.clone(),
        source,
    };
    writeln!(w, "{}", header(&file.output_names)).map_err(io)?;
    for t in 0..file.record.len() {
        let mut row = vec![file.label(t)];
        for i in 0..model.p() {
            for v in [
                pred.mean[(i, t)],
                pred.sd[(i, t)],
                pred.errors[(i, t)],
                pred.standardised[(i, t)],
            ] {
                row.push(fmt(v));
            }
        }
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.commit()?;
    let fit = fit_percent(&file.measured(), &pred.mean, 0);
    let spread = pred.standardised_rms();
    let warnings: Vec<String> = pred.warnings().iter().map(ToString::to_string).collect();
    for w in &warnings {
        crate::warn(w);
    }
    crate::report(
        o.json,
        serde_json::json!({
            "command": "predict", "horizon": o.horizon, "steps": file.record.len(),
            "loglik": pred.loglik, "outputs": file.output_names, "fit_percent": fit,
            "standardised_rms": spread, "out": o.out, "warnings": warnings,
        }),
        || {
            let per_output: Vec<String> = file
                .output_names
                .iter()
                .zip(&fit)
                .zip(&spread)
                .map(|((name, f), s)| format!("{name}: fit {f:.2} %, standardised rms {s:.3}"))
                .collect();
            format!(
                "{}-step predictions ({}); wrote {}",
                o.horizon,
                per_output.join("; "),
                o.out.display()
            )
        },
    );
    Ok(())
}

/// `sysid predict --model m.toml`: the library's particle predictions
/// ([`sysid::modelfile::ModelFile::predict_particles`]), written in the same layout.
fn run_model_file(o: &Options) -> Result<(), CliError> {
    let path = o.source.model_path();
    let (model, file) = o.source.load_model_file()?;
    let context = o.source.data_path().display().to_string();
    let series = crate::commands::particle::series_of(&file, &context)?;
    let pred = model
        .predict_particles(series, o.horizon, o.particles, o.seed)
        .map_err(|e| match e {
            sysid::modelfile::PredictionError::InvalidOption { name, reason } => {
                CliError::BadOption {
                    option: if name == "particles" {
                        "--particles"
                    } else {
                        "--horizon"
                    },
                    message: reason,
                }
            }
            other => CliError::BadOption {
                option: "--model",
                message: format!("{} on {context}: {other}", path.display()),
            },
        })?;
    let p = series.output_dim();
    let steps = series.steps();
    let mut w = create_output(&o.out, o.force)?;
    let io = |source| CliError::Io {
        path: o.out.clone(),
        source,
    };
    writeln!(w, "{}", header(&file.output_names)).map_err(io)?;
    let mut squared = vec![(0.0, 0usize); p];
    for t in 0..steps {
        let mut row = vec![file.label(t)];
        for (j, sum) in squared.iter_mut().enumerate() {
            let (m, s) = (pred.mean[t * p + j], pred.sd[t * p + j]);
            let error = series.output(t)[j] - m;
            row.extend([m, s, error, error / s].map(fmt));
            if !error.is_nan() {
                sum.0 += (error / s).powi(2);
                sum.1 += 1;
            }
        }
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.commit()?;
    let mean = nalgebra::DMatrix::from_fn(p, steps, |j, t| pred.mean[t * p + j]);
    let fit = fit_percent(&file.measured(), &mean, 0);
    let spread: Vec<f64> = squared
        .iter()
        .map(|(sum, n)| (sum / (*n).max(1) as f64).sqrt())
        .collect();
    crate::report(
        o.json,
        serde_json::json!({
            "command": "predict", "horizon": o.horizon, "steps": steps,
            "outputs": file.output_names, "fit_percent": fit, "standardised_rms": spread,
            "particles": o.particles, "seed": o.seed, "out": o.out, "warnings": [],
        }),
        || {
            let per_output: Vec<String> = file
                .output_names
                .iter()
                .zip(&fit)
                .zip(&spread)
                .map(|((name, f), s)| format!("{name}: fit {f:.2} %, standardised rms {s:.3}"))
                .collect();
            format!(
                "{}-step particle predictions ({} particles; {}); wrote {}",
                o.horizon,
                o.particles,
                per_output.join("; "),
                o.out.display()
            )
        },
    );
    Ok(())
}

/// The CSV header: t, then per output NAME_pred, NAME_sd, NAME_error, NAME_std.
fn header(outputs: &[String]) -> String {
    let mut header = vec!["t".to_string()];
    for name in outputs {
        for suffix in ["pred", "sd", "error", "std"] {
            header.push(format!("{name}_{suffix}"));
        }
    }
    header.join(",")
}
