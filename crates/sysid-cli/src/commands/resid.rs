//! `sysid resid`: are a model's one-step prediction errors white and independent of
//! the inputs? Autocorrelation, cross-correlation with the inputs, Ljung-Box test.

use super::in_data;
use crate::error::CliError;
use crate::files::{create_output, fmt};
use std::io::Write;
use std::path::PathBuf;
use sysid::kalman::residuals::{autocorrelation, cross_correlation, ljung_box};
use sysid_plot::{Band, Figure, Panel, Series, Stroke};

/// Options of `sysid resid`.
#[derive(clap::Args, Debug)]
pub struct Options {
    #[command(flatten)]
    pub source: crate::ModelOnData,
    /// Lags of the correlations and of the Ljung-Box test.
    #[arg(long, default_value_t = 20)]
    pub lags: usize,
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

/// The correlations of one output's standardised errors.
struct OutputTests {
    name: String,
    acf: Vec<f64>,
    /// per input: lags -L..=L
    ccf: Vec<(String, Vec<f64>)>,
    ljung_box: sysid::kalman::residuals::LjungBox,
    samples: usize,
}

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
    let (model, file) = o.source.load()?;
    let pred = model
        .predict(&file.record, 1)
        .map_err(in_data(o.source.data_path()))?;
    let mut tests = Vec::new();
    for (i, name) in file.output_names.iter().enumerate() {
        // the steps where the output is observed and its prediction determined
        let steps: Vec<usize> = (0..file.record.len())
            .filter(|&t| pred.standardised[(i, t)].is_finite() && pred.sd[(i, t)].is_finite())
            .collect();
        let e: Vec<f64> = steps.iter().map(|&t| pred.standardised[(i, t)]).collect();
        let lb = ljung_box(&e, o.lags, 0).ok_or_else(|| CliError::BadOption {
            option: "--lags",
            message: format!(
                "{} must be at least 1 and below the {} usable residuals of {name}",
                o.lags,
                e.len()
            ),
        })?;
        let ccf = file
            .input_names
            .iter()
            .enumerate()
            .map(|(j, input)| {
                let u: Vec<f64> = steps.iter().map(|&t| file.record.u[(j, t)]).collect();
                (input.clone(), cross_correlation(&e, &u, o.lags))
            })
            .collect();
        tests.push(OutputTests {
            name: name.clone(),
            acf: autocorrelation(&e, o.lags),
            ccf,
            ljung_box: lb,
            samples: e.len(),
        });
    }
    if let Some(path) = &o.out {
        write_csv(path, o.force, o.lags, &tests)?;
    }
    let mut written = Vec::new();
    if let Some(dir) = &o.out_dir {
        std::fs::create_dir_all(dir).map_err(|source| CliError::Io {
            path: dir.clone(),
            source,
        })?;
        written = figure(&tests, o.lags)
            .write(dir, "resid", o.force)
            .map_err(CliError::Plot)?;
    }
    let mut warnings = Vec::new();
    let mut summaries = Vec::new();
    for t in &tests {
        let bound = 1.96 / (t.samples as f64).sqrt();
        let beyond = t.acf[1..].iter().filter(|r| r.abs() > bound).count();
        let ccf_beyond: Vec<(String, usize)> = t
            .ccf
            .iter()
            .map(|(input, r)| (input.clone(), r.iter().filter(|v| v.abs() > bound).count()))
            .collect();
        if t.ljung_box.p_value < 0.05 {
            warnings.push(format!(
                "the one-step errors of {} are correlated (Ljung-Box p = {:.2e} over {} lags): \
                 the model misses dynamics of the data; try a higher order",
                t.name, t.ljung_box.p_value, t.ljung_box.lags
            ));
        }
        for (input, count) in &ccf_beyond {
            // 5 % of the lags fall outside by chance: flag a count above the binomial
            // mean plus two standard deviations (about its 97.5 % quantile)
            let trials = (2 * o.lags + 1) as f64;
            if *count as f64 > 0.05 * trials + 2.0 * (0.05 * 0.95 * trials).sqrt() + 1.0 {
                warnings.push(format!(
                    "the one-step errors of {} are correlated with {input} at {count} of {} lags \
                     beyond the 95 % bound: the model misses input dynamics",
                    t.name,
                    2 * o.lags + 1
                ));
            }
        }
        summaries.push(serde_json::json!({
            "output": t.name, "samples": t.samples,
            "ljung_box": {"statistic": t.ljung_box.statistic, "p_value": t.ljung_box.p_value,
                          "lags": t.ljung_box.lags, "df": t.ljung_box.df},
            "acf": t.acf, "bound_95": bound, "acf_beyond_bound": beyond,
            "ccf_beyond_bound": ccf_beyond.iter().map(|(i, c)| serde_json::json!({"input": i, "lags": c})).collect::<Vec<_>>(),
        }));
    }
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
                .iter()
                .map(|t| {
                    format!(
                        "{}: Ljung-Box Q({}) = {:.3}, p = {:.3e}{}",
                        t.name,
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

fn write_csv(
    path: &std::path::Path,
    force: bool,
    lags: usize,
    tests: &[OutputTests],
) -> Result<(), CliError> {
    let mut w = create_output(path, force)?;
    let io = |source| CliError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut header = vec!["lag".to_string()];
    for t in tests {
        header.push(format!("{}_acf", t.name));
        header.extend(
            t.ccf
                .iter()
                .map(|(input, _)| format!("{}_{input}_ccf", t.name)),
        );
    }
    writeln!(w, "{}", header.join(",")).map_err(io)?;
    for i in 0..=2 * lags {
        let lag = i as isize - lags as isize;
        let mut row = vec![lag.to_string()];
        for t in tests {
            row.push(if lag >= 0 {
                fmt(t.acf[lag as usize])
            } else {
                String::new()
            });
            row.extend(t.ccf.iter().map(|(_, r)| fmt(r[i])));
        }
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.commit()?;
    Ok(())
}

/// Per output: the autocorrelation (lags 1..L), and the cross-correlation with each
/// input (lags -L..L), with the 95 % bounds of white noise as a band.
fn figure(tests: &[OutputTests], lags: usize) -> Figure {
    let mut panels = Vec::new();
    for t in tests {
        let bound = 1.96 / (t.samples as f64).sqrt();
        let band = |from: isize| Band {
            name: "95 % bound of white noise".into(),
            points: (from..=lags as isize)
                .map(|k| (k as f64, -bound, bound))
                .collect(),
            colour: 7,
        };
        let acf = (1..=lags).map(|k| (k as f64, t.acf[k])).collect();
        panels.push(
            Panel::new(
                format!("autocorrelation of {}'s errors", t.name),
                "lag",
                "r",
            )
            .with_band(band(1))
            .with_series(Series::line("autocorrelation", acf).stroke(Stroke::Points)),
        );
        for (input, r) in &t.ccf {
            let points = r
                .iter()
                .enumerate()
                .map(|(i, v)| ((i as isize - lags as isize) as f64, *v))
                .collect();
            panels.push(
                Panel::new(
                    format!("{}'s errors and earlier {input}", t.name),
                    "lag",
                    "r",
                )
                .with_band(band(-(lags as isize)))
                .with_series(Series::line("cross-correlation", points).stroke(Stroke::Points)),
            );
        }
    }
    let columns = panels.len().min(2);
    Figure::grid(panels, columns)
}
