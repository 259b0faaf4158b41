//! `sysid fit lti`: reads the options and the data, calls the library's
//! [`LinearFit::run`], writes the model and the trace, and prints the summary.

use super::fix::{parse_diagonal, parse_fix};
use super::options::Options;
use crate::error::CliError;
use crate::files::{read_model_file, write_output};
use std::path::Path;
use sysid::em::linear::{
    Acceleration, CheckedLinearFitOptions, LinearFit, LinearFitError, LinearFitOptions,
    OrderChoice, OrderTable, Selection, Signals, Start, Switch, Uncertainty,
};

/// A library error as the command line's.
fn cli_error(e: LinearFitError) -> CliError {
    match e {
        // the library names its settings as the command line's flags (`max_iter` is
        // `--max-iter`), but for the start (`--init`) and the data's own checks
        LinearFitError::InvalidOption { option, message } => match option {
            "start" => CliError::BadOption {
                option: "--init",
                message,
            },
            "data" | "time" | "names" => CliError::BadOption {
                option: "--data",
                message,
            },
            setting => CliError::Setting(sysid::em::SettingError::Invalid {
                setting,
                reason: message,
            }),
        },
        LinearFitError::Kalman { context, source } => CliError::Kalman {
            context: match context {
                "fixed values" => "--fix".into(),
                "split" => "--split".into(),
                other => other.into(),
            },
            source,
        },
        LinearFitError::Subspace(e) => CliError::Subspace(e),
        LinearFitError::Trend(e) => crate::commands::detrend::error(e),
        LinearFitError::Em(e) => CliError::Em(e),
        LinearFitError::StartFailed { message } => CliError::FitFailedAtStart { message },
        LinearFitError::NoOrder { from, to } => CliError::BadOption {
            option: "--order",
            message: format!("no order in {from}..{to} could be fitted"),
        },
        LinearFitError::Interrupted { .. } => CliError::Interrupted {
            iteration: 0,
            written: Vec::new(),
        },
        other => CliError::BadOption {
            option: "fit",
            message: other.to_string(),
        },
    }
}

/// `--order`: a number, `FROM..TO`, or (with a start file) nothing or `auto`.
fn order_choice(o: &Options, n4sid: bool) -> Result<OrderChoice, CliError> {
    let select = parsed::<Selection>("--select", &o.select)?;
    let Some(text) = o.order.as_deref() else {
        return Ok(OrderChoice::OfStart);
    };
    if let Some((from, to)) = text.split_once("..") {
        let bad = || CliError::BadOption {
            option: "--order",
            message: format!("{from}..{to} is not a range of orders like 1..8"),
        };
        let from = from.trim().parse::<usize>().map_err(|_| bad())?;
        let to = to.trim().parse::<usize>().map_err(|_| bad())?;
        return Ok(OrderChoice::Range { from, to, select });
    }
    match crate::commands::n4sid::parse_order(text)? {
        sysid::subspace::Order::Fixed(n) => Ok(OrderChoice::Fixed(n)),
        // a start file has its order; N4SID needs one
        _ if n4sid => Err(CliError::BadOption {
            option: "--order",
            message: "--init n4sid needs a model order (--order n)".into(),
        }),
        _ => Ok(OrderChoice::OfStart),
    }
}

/// A flag's value in the library's spelling (`FromStr` of its option type).
fn parsed<T: std::str::FromStr<Err = String>>(
    flag: &'static str,
    text: &str,
) -> Result<T, CliError> {
    text.parse().map_err(|message| CliError::BadOption {
        option: flag,
        message,
    })
}

/// The library's options from the command line's (`file` for the start's columns).
fn library_options(
    o: &Options,
    file: &crate::files::DataFile,
) -> Result<CheckedLinearFitOptions, CliError> {
    let n4sid = o.init.eq_ignore_ascii_case("n4sid");
    let mut options = LinearFitOptions::default();
    options.order = order_choice(o, n4sid)?;
    options.fixes = o
        .fix
        .iter()
        .map(|f| parse_fix(f))
        .collect::<Result<_, _>>()?;
    options.diagonal = o
        .diag
        .iter()
        .map(|d| parse_diagonal(d))
        .collect::<Result<_, _>>()?;
    options.full_r = o.full_r;
    options.min_variance = o.min_variance;
    options.min_output_noise = o.min_output_noise;
    options.offset = o.offset;
    options.estimate_initial = o.estimate_initial;
    options.initial = crate::commands::parse_initial(&o.initial)?;
    options.acceleration = parsed::<Acceleration>("--accelerate", &o.accelerate)?;
    options.polish = parsed::<Switch>("--polish", &o.polish)?;
    options.std_errors = parsed::<Switch>("--std-errors", &o.std_errors)?;
    options.detrend = crate::commands::detrend::parse(&o.detrend)?;
    options.split = o.split;
    options.max_iterations = o.max_iter;
    options.tol = o.tol;
    options.tol_nats = o.tol_nats;
    let given = |id: &str| o.given.iter().any(|g| g == id);
    if !n4sid && let Some(setting) = ["weighting", "stable"].into_iter().find(|s| given(s)) {
        return Err(sysid::em::SettingError::not_applicable(
            setting,
            LinearFitOptions::MODEL_START,
        )
        .into());
    }
    if given("select") && !matches!(options.order, OrderChoice::Range { .. }) {
        return Err(
            sysid::em::SettingError::not_applicable("select", LinearFitOptions::ONE_ORDER).into(),
        );
    }
    options.start = if n4sid {
        Start::N4sid {
            stable: o.stable,
            weighting: parsed("--weighting", &o.weighting)?,
        }
    } else {
        let stored = read_model_file(Path::new(&o.init))?;
        crate::commands::check_columns(&stored.model, file)?;
        Start::Model {
            model: Box::new(stored.model),
            initial: stored.initial,
        }
    };
    options.check().map_err(cli_error)
}

/// The record of a data file, with its times and column names.
pub(crate) fn signals(file: &crate::files::DataFile) -> Result<Signals, CliError> {
    Signals::new(file.record.clone())
        .with_time(file.time.clone())
        .and_then(|s| s.with_names(file.input_names.clone(), file.output_names.clone()))
        .map_err(cli_error)
}

/// `sysid fit lti`.
pub fn run(o: &Options) -> Result<(), CliError> {
    let file = o.data.read()?;
    file.require_outputs(&o.data.data)?;
    let options = library_options(o, &file)?;
    let data = signals(&file)?;
    let mut progress = crate::progress::Progress::new(o.max_iter as u64, "fit lti", o.json);
    // Ctrl-C stops EM after the iteration and writes the model so far
    crate::progress::interruptible();
    let started = std::time::Instant::now();
    let fit = LinearFit::run(&data, &options, &mut progress);
    progress.finish();
    let fit = fit.map_err(cli_error)?;
    if let (Some(table), false) = (&fit.order_table, o.json) {
        crate::say(&order_table_text(table));
    }
    // the fit's metadata with the data's entries (names, source, fingerprint)
    let data_entries = crate::files::metadata_of(&file, &o.data.data);
    let mut spec = fit.model_spec();
    spec.metadata = Some(sysid::kalman::Metadata {
        inputs: data_entries.inputs,
        outputs: data_entries.outputs,
        command: data_entries.command,
        data: data_entries.data,
        data_fingerprint: data_entries.data_fingerprint,
        sample_time: data_entries.sample_time,
        ..fit.metadata()
    });
    crate::files::write_model(&o.out, o.force, &spec)?;
    if let Some(path) = &o.trace {
        let mut text = String::from("iteration,loglik\n");
        for (k, l) in fit.trace.iter().enumerate() {
            text += &format!("{k},{l}\n");
        }
        write_output(path, o.force, &text)?;
    }
    if let Some(failure) = &fit.failure {
        let input = CliError::Em(failure.error.clone()).exit_code() == 2 || failure.data_cause;
        return Err(CliError::FitFailedMidRun {
            message: format!(
                "EM failed at iteration {}: {}; the last good model (iteration {}, \
                 log-likelihood {}) was written to {}{}; {}",
                failure.iteration,
                failure.error,
                fit.iterations,
                fit.loglik.unwrap_or(f64::NAN),
                o.out.display(),
                o.trace
                    .as_ref()
                    .map(|t| format!(" and the trace to {}", t.display()))
                    .unwrap_or_default(),
                failure.diagnosis
            ),
            input,
        });
    }
    crate::report(o.json, summary_json(o, &fit, started), || {
        summary_text(o, &fit, started)
    });
    for w in &fit.warnings {
        crate::warn(&w.to_string());
    }
    if let sysid::em::Termination::LikelihoodDecreased {
        iteration,
        previous,
        current,
    } = fit.em_termination
    {
        return Err(CliError::LikelihoodDecreased(format!(
            "EM decreased the log-likelihood at iteration {iteration} ({previous} -> {current}); \
             the better model was written; {}",
            fit.decrease_diagnosis.as_deref().unwrap_or_default()
        )));
    }
    crate::commands::interrupted(
        &fit.em_termination,
        std::iter::once(o.out.clone()).chain(o.trace.clone()),
    )
}

/// The order table, the chosen order marked.
fn order_table_text(table: &OrderTable) -> String {
    let mut text = format!(
        "{:>5} {:>14} {:>6} {:>12} {:>12} {:>12}",
        "order", "loglik", "k", "AIC", "BIC", "validation"
    );
    for r in &table.rows {
        text += &format!(
            "\n{:>5} {:>14.4} {:>6} {:>12.2} {:>12.2} {:>12}{}",
            r.order,
            r.loglik.unwrap_or(f64::NAN),
            r.parameters,
            r.aic(),
            r.bic(),
            r.validation.map_or("-".into(), |v| format!("{v:.2} %")),
            if r.order == table.chosen {
                "  <- chosen"
            } else {
                ""
            }
        );
    }
    text
}

/// `--json`'s summary.
fn summary_json(o: &Options, fit: &LinearFit, started: std::time::Instant) -> serde_json::Value {
    let finite = |v: f64| v.is_finite().then_some(v);
    let order_table = fit.order_table.as_ref().map(|t| {
        serde_json::json!({
            "select": t.select.name(), "chosen": t.chosen,
            "orders": t.rows.iter().map(|r| serde_json::json!({
                "order": r.order, "loglik": r.loglik, "parameters": r.parameters,
                "aic": finite(r.aic()), "bic": finite(r.bic()),
                "validation_simulation_fit_percent": r.validation,
            })).collect::<Vec<_>>(),
        })
    });
    let parameters = fit.uncertainty.as_ref().map(|u| {
        u.parameters
            .iter()
            .map(|p| {
                serde_json::json!({
                    "name": p.name, "value": p.value, "std_error": p.std_error,
                    "ci95": [p.value - 1.96 * p.std_error, p.value + 1.96 * p.std_error],
                })
            })
            .collect::<Vec<_>>()
    });
    serde_json::json!({
        "command": "fit", "loglik": fit.loglik, "em_loglik": fit.em_loglik,
        "initial": fit.initial, "iterations": fit.iterations,
        "starts": fit.starts.iter().map(|s| serde_json::json!({
            "weighting": s.weighting.map(|w| w.name()), "em_loglik": s.em_loglik,
            "loglik": s.loglik, "em_iterations": s.em_iterations,
        })).collect::<Vec<_>>(),
        "order_table": order_table,
        "parameters": parameters,
        "e_steps": fit.e_steps, "accelerate": fit.acceleration.name(),
        "polish": fit.polish.as_ref().map(|p| serde_json::json!({
            "coordinates": p.parameters, "identified": p.identified,
            "iterations": p.iterations, "evaluations": p.evaluations, "status": p.status,
            "converged": p.converged, "gain": p.loglik - p.loglik_before,
            "distance_nats": p.distance,
        })),
        "termination": fit.status.name(),
        "em_termination": sysid::em::linear::FitStatus::of_em(&fit.em_termination).name(),
        "seconds": started.elapsed().as_secs_f64(), "out": o.out,
        "warnings": fit.warnings.iter().map(ToString::to_string).collect::<Vec<_>>(),
        "validation": fit.validation.map(|v| serde_json::json!({
            "rows": v.rows,
            "simulation_fit_percent": v.simulation_fit_percent,
            "prediction_fit_percent": v.prediction_fit_percent,
        })),
    })
}

/// The human summary.
fn summary_text(o: &Options, fit: &LinearFit, started: std::time::Instant) -> String {
    let percent = |v: Option<f64>| v.map_or("-".into(), |f| format!("{f:.2}"));
    let validation = fit
        .validation
        .map(|v| {
            format!(
                "\nvalidation ({} rows held out): simulation fit {} %, one-step prediction fit {} %",
                v.rows,
                percent(v.simulation_fit_percent),
                percent(v.prediction_fit_percent)
            )
        })
        .unwrap_or_default();
    let polish = fit
        .polish
        .as_ref()
        .map(|p| {
            format!(
                "; polish: {} (+{:.3e} nats)",
                p.status,
                p.loglik - p.loglik_before
            )
        })
        .unwrap_or_default();
    let table = fit
        .uncertainty
        .as_ref()
        .map(parameter_table)
        .unwrap_or_default();
    format!(
        "loglik {} after {} EM iterations ({} E-steps, {}){polish}; {} in {:.2} s; wrote \
         {}{validation}{table}",
        fit.loglik.unwrap_or(f64::NEG_INFINITY),
        fit.iterations,
        fit.e_steps,
        sysid::em::linear::FitStatus::of_em(&fit.em_termination).name(),
        fit.status.name(),
        started.elapsed().as_secs_f64(),
        o.out.display()
    )
}

/// The estimates as a table (statsmodels' summary): value, standard error, z, 95 %
/// interval; a leading newline.
fn parameter_table(u: &Uncertainty) -> String {
    let mut text = format!(
        "\n{:>10} {:>14} {:>12} {:>8} {:>14} {:>14}",
        "parameter", "estimate", "std err", "z", "[0.025", "0.975]"
    );
    for p in &u.parameters {
        text += &format!(
            "\n{:>10} {:>14.6e} {:>12.4e} {:>8.2} {:>14.6e} {:>14.6e}",
            p.name,
            p.value,
            p.std_error,
            p.value / p.std_error,
            p.value - 1.96 * p.std_error,
            p.value + 1.96 * p.std_error
        );
    }
    text
}
