//! `sysid fit --model m.toml`: the free parameters of a nonlinear model file,
//! estimated from their values in the file by the library's [`ModelFile::fit`]:
//! closed-form particle EM when the equations are affine in them (seed 000; the robust
//! driver by default); otherwise the likelihood maximised directly from several starts
//! by default (`--method robust`) or gradient EM (`--method em`; seed 001; rejection
//! FFBSi with `--particles` paths, analytic gradients). The estimate is written as a
//! model file that every nonlinear command reads.

use super::affine::{Job, fit_run, observer_of, progress_of, report};
use super::options::Options;
use super::toml_metadata::metadata_lines;
use crate::commands::particle::series_of;
use crate::error::CliError;
use crate::files::{fmt, short, write_output};
use sysid::em::Termination;
use sysid::em::gradient::{DirectFit, DirectOptions, GradientModel};
use sysid::modelfile::{FileFit, FileFitError, FileFitMethod, FileFitReport, ModelFile};

mod simulation;

fn bad(option: &'static str, message: impl Into<String>) -> CliError {
    CliError::BadOption {
        option,
        message: message.into(),
    }
}

/// `sysid fit --model m.toml`.
pub fn run(o: &Options) -> Result<(), CliError> {
    let path = o
        .model
        .as_deref()
        .ok_or_else(|| bad("--model", "give a model file"))?;
    let model = crate::commands::nonlinear::read(path)?;
    let method = model
        .fit_method(o.criterion, &o.settings()?)
        .map_err(|e| file_error(o, e))?;
    if model.free_names().is_empty() {
        return Err(file_error(
            o,
            FileFitError::NothingFree {
                origin: path.display().to_string(),
            },
        ));
    }
    let file = o
        .data
        .read_for_names(&model.spec().inputs, &model.spec().outputs)?;
    let context = o.data.data.display().to_string();
    let series = series_of(&file, &context)?;
    let progress = match &method {
        FileFitMethod::Simulation(_) => return simulation::run(o, &model, series, &method),
        FileFitMethod::ParticleEm(options) => progress_of(o, options.options()),
        FileFitMethod::Direct(_) => Some(crate::progress::Progress::spinner(
            "direct maximum likelihood",
            o.json,
        )),
        FileFitMethod::GradientEm(options) => Some(crate::progress::Progress::new(
            options.iterations as u64,
            "gradient EM",
            o.json,
        )),
    };
    let began = std::time::Instant::now();
    // Ctrl-C ends the run where it is; the result so far is written, marked interrupted
    crate::progress::interruptible();
    let mut observer = observer_of(&progress);
    let fit = model
        .fit(series, &method, &fit_run(o), observer.as_mut())
        .map_err(|e| file_error(o, e))?;
    if let Some(p) = &progress {
        p.finish();
    }
    let seconds = began.elapsed().as_secs_f64();
    match (&fit.report, model.affine(), method) {
        (FileFitReport::Affine(report_of), Some(affine), FileFitMethod::ParticleEm(options)) => {
            // the fit's own warnings are the robust driver's, reported with it
            let job = Job {
                o,
                file,
                options,
                extra_warnings: fit
                    .warnings
                    .iter()
                    .filter(|w| !matches!(w, sysid::modelfile::FileFitWarning::Robust(_)))
                    .map(ToString::to_string)
                    .collect(),
            };
            let start = affine
                .params(&model.free_values())
                .map_err(|m| bad("--model", m.reason))?;
            report(&job, &affine, &start, report_of, seconds, |p| {
                affine.theta(p)
            })
        }
        (
            FileFitReport::Direct {
                fit: direct,
                simulation_start,
            },
            ..,
        ) => report_direct(o, &model, &fit, direct, *simulation_start),
        _ => report_gradient(o, &model, &fit),
    }
}

/// Writes the estimate of the direct fit (and, with `--trace`, its starts' table), and
/// reports.
fn report_direct(
    o: &Options,
    model: &ModelFile,
    fit: &FileFit,
    direct: &DirectFit,
    simulation_start: Option<usize>,
) -> Result<(), CliError> {
    let context = o.data.data.display().to_string();
    let gradient = model.gradient();
    let names = model.free_names();
    let named = |z: &[f64]| -> serde_json::Value {
        names
            .iter()
            .cloned()
            .zip(gradient.constrained(z))
            .map(|(n, v)| (n, serde_json::json!(v)))
            .collect::<serde_json::Map<_, _>>()
            .into()
    };
    let finite = |l: f64| l.is_finite().then_some(l);
    let starts: Vec<serde_json::Value> = direct
        .starts
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let origin = match k {
                0 => "file",
                _ if Some(k) == simulation_start => "simulation-error fit",
                _ => "perturbed",
            };
            serde_json::json!({
                "origin": origin, "start": named(&s.start), "start_loglik": finite(s.start_loglik),
                "end": named(&s.end), "loglik": finite(s.loglik),
                "evaluations": s.evaluations, "converged": s.converged,
            })
        })
        .collect();
    let warnings: Vec<String> = fit.warnings.iter().map(ToString::to_string).collect();
    let summary = serde_json::json!({
        "method": fit.method(), "seed": o.seed, "loglik_estimate": direct.loglik,
        "loglik_sd": direct.loglik_sd, "particles": direct.particles, "data": context,
        "interrupted": fit.interrupted(),
    });
    let mut outputs = vec![(o.out.clone(), fit.fitted.to_toml(&metadata_lines(&summary)))];
    if let Some(path) = &o.trace {
        let mut text = format!(
            "start,start_loglik,loglik,evaluations,converged,{}\n",
            names.join(",")
        );
        for (k, s) in direct.starts.iter().enumerate() {
            let values: Vec<String> = gradient.constrained(&s.end).into_iter().map(fmt).collect();
            text += &format!(
                "{k},{},{},{},{},{}\n",
                fmt(s.start_loglik),
                fmt(s.loglik),
                s.evaluations,
                s.converged,
                values.join(",")
            );
        }
        outputs.push((path.clone(), text));
    }
    let mut report = written(o, &outputs, &warnings, summary)?;
    report["estimate"] = named(&direct.estimate);
    report["starts"] = serde_json::json!(starts);
    report["chosen"] = serde_json::json!(direct.chosen);
    report["explore_particles"] = serde_json::json!(DirectOptions::default().explore_particles);
    report["finish_evaluations"] = serde_json::json!(direct.finish_evaluations);
    report["converged"] = serde_json::json!(direct.converged);
    report["standard_errors"] = match &direct.standard_errors {
        Some(se) => names
            .iter()
            .cloned()
            .zip(se)
            .map(|(n, v)| (n, serde_json::json!(v)))
            .collect::<serde_json::Map<_, _>>()
            .into(),
        None => serde_json::Value::Null,
    };
    report["seconds"] = serde_json::json!({
        "exploration": direct.timing.0.as_secs_f64(),
        "finish": direct.timing.1.as_secs_f64(),
    });
    report["warnings"] = serde_json::json!(warnings);
    crate::report(o.json, report, || {
        let values: Vec<String> = names
            .iter()
            .zip(&fit.estimate)
            .enumerate()
            .map(|(k, (n, v))| match &direct.standard_errors {
                Some(se) => format!("{n} = {} (se {})", short(*v), short(se[k])),
                None => format!("{n} = {}", short(*v)),
            })
            .collect();
        format!(
            "likelihood maximised directly ({} is not affine in its free parameters): {} \
             starts explored by a {}-particle filter in {:.1} s, start {}'s best finished \
             by a {}-particle filter ({} filters, {:.1} s); loglik {} (sd {}); {}; wrote {}",
            model.origin(),
            direct.starts.len(),
            DirectOptions::default().explore_particles,
            direct.timing.0.as_secs_f64(),
            direct.chosen,
            direct.particles,
            direct.finish_evaluations,
            direct.timing.1.as_secs_f64(),
            fmt(direct.loglik),
            fmt(direct.loglik_sd),
            values.join(", "),
            o.out.display()
        )
    });
    if fit.interrupted() {
        // the filters run stand for the iterations
        return Err(CliError::Interrupted {
            iteration: direct.starts.iter().map(|s| s.evaluations).sum::<usize>()
                + direct.finish_evaluations,
            written: outputs.into_iter().map(|(path, _)| path).collect(),
        });
    }
    Ok(())
}

/// A model file's fit error, named by the option or the data it comes from.
pub(super) fn file_error(o: &Options, e: FileFitError) -> CliError {
    let context = o.data.data.display().to_string();
    match e {
        FileFitError::NothingFree { .. } => bad("--model", e.to_string()),
        FileFitError::NotAffine { .. } => bad("--method", e.to_string()),
        FileFitError::Setting(e) => CliError::Setting(e),
        FileFitError::Start(m) => bad("--model", m.reason),
        FileFitError::Affine(source) => CliError::AffineEm { context, source },
        FileFitError::Gradient(source) => CliError::GradientEm { context, source },
        other => bad("--model", other.to_string()),
    }
}

/// Writes `outputs`, prints `warnings`, and starts the report from `summary`.
fn written(
    o: &Options,
    outputs: &[(std::path::PathBuf, String)],
    warnings: &[String],
    summary: serde_json::Value,
) -> Result<serde_json::Value, CliError> {
    for (path, text) in outputs {
        write_output(path, o.force, text)?;
    }
    for w in warnings {
        crate::warn(w);
    }
    let mut report = summary;
    report["command"] = serde_json::json!("fit");
    report["out"] = serde_json::json!(o.out);
    Ok(report)
}

/// Writes the estimate of gradient EM and its trace, and reports.
fn report_gradient(o: &Options, model: &ModelFile, fit: &FileFit) -> Result<(), CliError> {
    let context = o.data.data.display().to_string();
    let FileFitReport::Gradient { result, iterates } = &fit.report else {
        unreachable!("a fit of a model that is not affine is gradient EM")
    };
    if let Termination::Error { iteration, error } = &result.termination {
        return Err(CliError::GradientEm {
            context: format!("{context}, EM iteration {iteration}"),
            source: error.clone(),
        });
    }
    let names = model.free_names();
    let warnings: Vec<String> = fit.warnings.iter().map(ToString::to_string).collect();
    let summary = serde_json::json!({
        "method": fit.method(), "iterations": result.iterations, "particles": o.particles,
        "seed": o.seed, "loglik_estimate": result.loglik,
        "likelihood_decreases": result.decreases, "data": context,
        "interrupted": fit.interrupted(),
    });
    let mut outputs = vec![(o.out.clone(), fit.fitted.to_toml(&metadata_lines(&summary)))];
    if let Some(path) = &o.trace {
        let mut text = format!("iteration,loglik,{}\n", names.join(","));
        for (k, (l, values)) in iterates.iter().enumerate() {
            let values: Vec<String> = values.iter().map(|&v| fmt(v)).collect();
            text += &format!("{},{},{}\n", k + 1, fmt(*l), values.join(","));
        }
        outputs.push((path.clone(), text));
    }
    let mut report = written(o, &outputs, &warnings, summary)?;
    report["estimate"] = names
        .iter()
        .cloned()
        .zip(&fit.estimate)
        .map(|(n, v)| (n, serde_json::json!(v)))
        .collect::<serde_json::Map<_, _>>()
        .into();
    report["seconds"] = serde_json::json!(result.elapsed.as_secs_f64());
    report["warnings"] = serde_json::json!(warnings);
    crate::report(o.json, report, || {
        let values: Vec<String> = names
            .iter()
            .zip(&fit.estimate)
            .map(|(n, v)| format!("{n} = {}", fmt(*v)))
            .collect();
        format!(
            "gradient EM ({} is not affine in its free parameters): {} iterations in {:.2} s \
             ({} particles), loglik estimate {}; {}; wrote {}",
            model.origin(),
            result.iterations,
            result.elapsed.as_secs_f64(),
            o.particles,
            result.loglik.map_or("-".into(), fmt),
            values.join(", "),
            o.out.display()
        )
    });
    crate::commands::interrupted(
        &result.termination,
        outputs.into_iter().map(|(path, _)| path),
    )
}
