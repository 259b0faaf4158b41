//! `sysid resid`: are a model's one-step prediction errors white and independent of
//! the inputs? Autocorrelation, cross-correlation with the inputs, Ljung-Box test.

use super::in_data;
use crate::error::CliError;
use crate::files::{create_output, fmt};
use std::io::Write;
use std::path::PathBuf;
use sysid::kalman::KalmanError;
use sysid::kalman::residuals::ResidualTests;
use sysid_plot::{Band, Figure, Panel, Series, Stroke};

/// Options of `sysid resid`.
#[derive(clap::Args, Debug)]
pub struct Options {
    #[command(flatten)]
    pub source: crate::ModelOnData,
    /// Lags of the correlations and of the Ljung-Box test.
    #[arg(long, default_value_t = 20)]
    pub lags: usize,
    /// Nonlinear model files (`.toml`): particles of the bootstrap filter whose one-step
    /// predictions are tested.
    #[arg(long, default_value_t = 5000)]
    pub particles: usize,
    /// Nonlinear model files: the seed of the particle filter.
    #[arg(long, default_value_t = sysid::smc::DEFAULT_SEED)]
    pub seed: u64,
    /// Also write the correlations as CSV: lag, then per output NAME: NAME_acf, and per
    /// output and input: NAME_INPUT_ccf (lags -L..L; the autocorrelation is empty at
    /// negative lags).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also draw the correlations with their 95 % bounds, as resid.svg and resid.png
    /// in this directory (created if missing).
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
    /// Print a machine-readable summary.
    #[arg(long)]
    pub json: bool,
}

/// What correlated one-step errors of a model file ask for (a model file has no order
/// to raise).
const MODEL_FILE_ADVICE: &str = "revise the equations, or make the process noise free in the file \
     and fit it (`sysid fit --model`): a process noise held too small makes the one-step \
     predictions follow the noise-free simulation";

/// The correlations of one output's standardised errors.
pub fn run(o: &Options) -> Result<(), CliError> {
    let figures = o
        .out_dir
        .as_ref()
        .map(|d| ["resid.svg", "resid.png"].map(|f| d.join(f)));
    let targets: Vec<&std::path::Path> = o
        .out
        .iter()
        .map(|p| p.as_path())
        .chain(figures.iter().flatten().map(|p| p.as_path()))
        .collect();
    crate::files::refuse_existing(targets, o.force)?;
    let model_file = crate::commands::nonlinear::is_model_file(o.source.model_path());
    let (tests, file) = if model_file {
        model_file_tests(o)?
    } else {
        linear_tests(o)?
    };
    let names = Names {
        outputs: &file.output_names,
        inputs: &file.input_names,
    };
    if let Some(path) = &o.out {
        write_csv(path, o.force, &tests, &names)?;
    }
    let mut written = Vec::new();
    if let Some(dir) = &o.out_dir {
        std::fs::create_dir_all(dir).map_err(|source| CliError::Io {
            path: dir.clone(),
            source,
        })?;
        written = figure(&tests, &names)
            .write(dir, "resid", o.force)
            .map_err(CliError::Plot)?;
    }
    let warnings: Vec<String> = tests
        .warnings()
        .iter()
        .map(|w| {
            if model_file {
                w.message_advising(names.outputs, names.inputs, MODEL_FILE_ADVICE)
            } else {
                w.message(names.outputs, names.inputs)
            }
        })
        .collect();
    let summaries: Vec<serde_json::Value> = tests
        .outputs
        .iter()
        .map(|t| {
            let ccf_beyond: Vec<serde_json::Value> = names
                .inputs
                .iter()
                .zip(t.ccf_beyond_bound())
                .map(|(i, c)| serde_json::json!({"input": i, "lags": c}))
                .collect();
            serde_json::json!({
                "output": names.outputs[t.output], "samples": t.samples,
                "ljung_box": {"statistic": t.ljung_box.statistic, "p_value": t.ljung_box.p_value,
                              "lags": t.ljung_box.lags, "df": t.ljung_box.df},
                "acf": t.acf, "bound_95": t.bound_95(), "acf_beyond_bound": t.acf_beyond_bound(),
                "ccf_beyond_bound": ccf_beyond,
            })
        })
        .collect();
    for w in &warnings {
        crate::warn(w);
    }
    crate::report(
        o.json,
        serde_json::json!({
            "command": "resid", "lags": o.lags, "outputs": summaries, "out": o.out,
            "figures": written, "warnings": warnings,
        }),
        || {
            tests
                .outputs
                .iter()
                .map(|t| {
                    format!(
                        "{}: Ljung-Box Q({}) = {:.3}, p = {:.3e}{}",
                        names.outputs[t.output],
                        t.ljung_box.lags,
                        t.ljung_box.statistic,
                        t.ljung_box.p_value,
                        if t.ljung_box.p_value < 0.05 {
                            " (correlated)"
                        } else {
                            " (white)"
                        }
                    )
                })
                .collect::<Vec<_>>()
                .join("\n")
        },
    );
    Ok(())
}

/// The record's column names, for the tests' outputs and inputs.
struct Names<'a> {
    outputs: &'a [String],
    inputs: &'a [String],
}

fn write_csv(
    path: &std::path::Path,
    force: bool,
    tests: &ResidualTests,
    names: &Names,
) -> Result<(), CliError> {
    let lags = tests.lags;
    let mut w = create_output(path, force)?;
    let io = |source| CliError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut header = vec!["lag".to_string()];
    for t in &tests.outputs {
        let name = &names.outputs[t.output];
        header.push(format!("{name}_acf"));
        header.extend(
            names
                .inputs
                .iter()
                .map(|input| format!("{name}_{input}_ccf")),
        );
    }
    writeln!(w, "{}", header.join(",")).map_err(io)?;
    for i in 0..=2 * lags {
        let lag = i as isize - lags as isize;
        let mut row = vec![lag.to_string()];
        for t in &tests.outputs {
            row.push(if lag >= 0 {
                fmt(t.acf[lag as usize])
            } else {
                String::new()
            });
            row.extend(t.ccf.iter().map(|r| fmt(r[i])));
        }
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.commit()?;
    Ok(())
}

/// Per output: the autocorrelation (lags 1..L), and the cross-correlation with each
/// input (lags -L..L), with the 95 % bounds of white noise as a band.
fn figure(tests: &ResidualTests, names: &Names) -> Figure {
    let lags = tests.lags;
    let mut panels = Vec::new();
    for t in &tests.outputs {
        let name = &names.outputs[t.output];
        let bound = t.bound_95();
        let band = |from: isize| Band {
            name: "95 % bound of white noise".into(),
            points: (from..=lags as isize)
                .map(|k| (k as f64, -bound, bound))
                .collect(),
            colour: 7,
        };
        let acf = (1..=lags).map(|k| (k as f64, t.acf[k])).collect();
        panels.push(
            Panel::new(format!("autocorrelation of {name}'s errors"), "lag", "r")
                .with_band(band(1))
                .with_series(Series::line("autocorrelation", acf).stroke(Stroke::Points)),
        );
        for (input, r) in names.inputs.iter().zip(&t.ccf) {
            let points = r
                .iter()
                .enumerate()
                .map(|(i, v)| ((i as isize - lags as isize) as f64, *v))
                .collect();
            panels.push(
                Panel::new(format!("{name}'s errors and earlier {input}"), "lag", "r")
                    .with_band(band(-(lags as isize)))
                    .with_series(Series::line("cross-correlation", points).stroke(Stroke::Points)),
            );
        }
    }
    let columns = panels.len().min(2);
    Figure::grid(panels, columns)
}

/// The tests of a linear model's Kalman innovations.
fn linear_tests(o: &Options) -> Result<(ResidualTests, crate::files::DataFile), CliError> {
    let (model, file) = o.source.load()?;
    let tests = model
        .residual_tests(&file.record, o.lags)
        .map_err(|e| match e {
            KalmanError::TooManyLags {
                lags,
                usable,
                output,
            } => CliError::BadOption {
                option: "--lags",
                message: format!(
                    "{lags} must be at least 1 and below the {usable} usable residuals of {}",
                    file.output_names[output - 1]
                ),
            },
            e => in_data(o.source.data_path())(e),
        })?;
    Ok((tests, file))
}

/// The tests of a model file's one-step particle predictions
/// ([`sysid::modelfile::ModelFile::residual_tests`]).
fn model_file_tests(o: &Options) -> Result<(ResidualTests, crate::files::DataFile), CliError> {
    let path = o.source.model_path();
    let (model, file) = o.source.load_model_file()?;
    let context = o.source.data_path().display().to_string();
    let series = crate::commands::particle::series_of(&file, &context)?;
    let tests = model
        .residual_tests(series, o.lags, o.particles, o.seed)
        .map_err(|e| match e {
            sysid::modelfile::PredictionError::InvalidOption { name, reason } => {
                CliError::BadOption {
                    option: match name {
                        "lags" => "--lags",
                        "particles" => "--particles",
                        _ => "--model",
                    },
                    message: reason,
                }
            }
            other => CliError::BadOption {
                option: "--model",
                message: format!("{} on {context}: {other}", path.display()),
            },
        })?;
    Ok((tests, file))
}
