//! `sysid forecast`: outputs beyond the end of a record, with prediction intervals.

use super::in_data;
use crate::error::CliError;
use crate::files::{ColumnChoice, create_output, fmt, read_data};
use sysid::kalman::ForecastIntervals;

/// The library's name of the option `--level`.
const LEVEL: &[(&str, &str)] = &[("level", "--level")];
use std::io::Write;
use std::path::PathBuf;

/// Options of `sysid forecast`.
#[derive(clap::Args, Debug)]
pub struct Options {
    #[command(flatten)]
    pub source: crate::ModelOnData,
    /// Number of steps beyond the data.
    #[arg(long)]
    pub steps: usize,
    /// CSV of the inputs over the forecast (the same input columns as the data, at
    /// least --steps rows); required for a model with inputs.
    #[arg(long)]
    pub future_inputs: Option<PathBuf>,
    /// Coverage of the prediction intervals.
    #[arg(long, default_value_t = 0.95)]
    pub level: f64,
    /// Output CSV: step (1..steps after the data), then per output NAME: NAME,
    /// NAME_sd, NAME_lower, NAME_upper.
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
    if o.steps == 0 {
        return Err(CliError::BadOption {
            option: "--steps",
            message: "must be at least 1".into(),
        });
    }
    let level_error = super::kalman_error(&o.source.model, o.source.data_path(), LEVEL);
    ForecastIntervals::half_width(o.level).map_err(&level_error)?;
    crate::files::check_outputs(std::iter::once(o.out.as_path()), o.force)?;
    let (model, file) = o.source.load()?;
    // the forecast's means, sds, covariances and intervals, and the future times
    let p = model.p() as f64;
    crate::resources::check_memory(
        "--steps",
        &format!("{} steps ahead", o.steps),
        8.0 * o.steps as f64 * (p * p + 6.0 * p + 1.0 + model.m() as f64),
    )?;
    let future = match (&o.future_inputs, model.m()) {
        (_, 0) => nalgebra::DMatrix::zeros(0, o.steps),
        (None, m) => {
            return Err(CliError::BadOption {
                option: "--future-inputs",
                message: format!(
                    "the model has {m} input(s) ({}): give their values over the {} steps",
                    file.input_names.join(", "),
                    o.steps
                ),
            });
        }
        (Some(path), _) => {
            let inputs = read_data(
                path,
                &ColumnChoice {
                    inputs: Some(file.input_names.clone()),
                    outputs: Some(Vec::new()),
                    outputs_if_present: false,
                },
            )?;
            if inputs.record.len() < o.steps {
                return Err(CliError::BadOption {
                    option: "--future-inputs",
                    message: format!(
                        "{} has {} rows, fewer than --steps {}",
                        path.display(),
                        inputs.record.len(),
                        o.steps
                    ),
                });
            }
            inputs.record.u.columns(0, o.steps).clone_owned()
        }
    };
    // a model fitted with --detrend linear: the trends continue past the record
    let future_times = file.times_after(o.steps);
    let future = match &file.trend {
        Some(trend) if model.m() > 0 => future - trend.inputs_at(&future_times),
        _ => future,
    };
    let mut forecast = model
        .forecast(&file.record, &future, o.steps)
        .map_err(in_data(o.source.data_path()))?;
    if let Some(trend) = &file.trend {
        forecast.mean += trend.outputs_at(&future_times);
    }
    let intervals = forecast.intervals(o.level).map_err(&level_error)?;
    let mut w = create_output(&o.out, o.force)?;
    let io = |source| CliError::Io {
        path: o.out.clone(),
        source,
    };
    let mut header = vec!["step".to_string()];
    for name in &file.output_names {
        header.extend([
            name.clone(),
            format!("{name}_sd"),
            format!("{name}_lower"),
            format!("{name}_upper"),
        ]);
    }
    writeln!(w, "{}", header.join(",")).map_err(io)?;
    for j in 0..o.steps {
        let mut row = vec![(j + 1).to_string()];
        for i in 0..model.p() {
            row.extend(
                [
                    forecast.mean[(i, j)],
                    forecast.sd[(i, j)],
                    intervals.lower[(i, j)],
                    intervals.upper[(i, j)],
                ]
                .map(fmt),
            );
        }
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.commit()?;
    let last: Vec<String> = file
        .output_names
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let (mean, sd) = (
                forecast.mean[(i, o.steps - 1)],
                forecast.sd[(i, o.steps - 1)],
            );
            format!("{name} {mean:.6} ± {:.6}", intervals.z * sd)
        })
        .collect();
    crate::report(
        o.json,
        serde_json::json!({
            "command": "forecast", "steps": o.steps, "level": o.level, "z": intervals.z,
            "outputs": file.output_names, "out": o.out,
            "last": forecast.mean.column(o.steps - 1).iter().collect::<Vec<_>>(),
        }),
        || {
            format!(
                "{} steps ahead ({} % intervals): {}; wrote {}",
                o.steps,
                100.0 * o.level,
                last.join(", "),
                o.out.display()
            )
        },
    );
    Ok(())
}
