//! `sysid fit --model m.toml`: the free parameters of a nonlinear model file,
//! estimated from their values in the file by the library's [`ModelFile::fit`]:
//! closed-form particle EM when the equations are affine in them (seed 000; the robust
//! driver by default), gradient EM otherwise (seed 001; rejection FFBSi with
//! `--particles` paths, analytic gradients). The estimate is written as a model file
//! that every nonlinear command reads.

use super::affine::{Job, fit_options, fit_run, observer_of, progress_of, report};
use super::options::Options;
use super::toml_metadata::metadata_lines;
use crate::commands::particle::series_of;
use crate::error::CliError;
use crate::files::{fmt, write_output};
use sysid::em::Termination;
use sysid::em::affine::AffineEmSpec;
use sysid::modelfile::{FileFit, FileFitError, FileFitReport, ModelFile};

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
    let options = fit_options(o, AffineEmSpec::default())?;
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
    let job = Job {
        o,
        file,
        options,
        extra_warnings: Vec::new(),
    };
    let series = series_of(&job.file, &context)?;
    match o.criterion.as_str() {
        "likelihood" => {}
        "simulation" => return simulation::run(o, &model, series),
        other => {
            return Err(bad(
                "--criterion",
                format!("{other:?} is not a criterion: use likelihood or simulation"),
            ));
        }
    }
    let affine = model.affine();
    let progress = match &affine {
        Some(_) => progress_of(&job),
        None => Some(crate::progress::Progress::new(
            o.max_iter as u64,
            "gradient EM",
            o.json,
        )),
    };
    let began = std::time::Instant::now();
    // Ctrl-C ends the run where it is; the result so far is written, marked interrupted
    crate::progress::interruptible();
    let mut observer = observer_of(&progress);
    let fit = model
        .fit(series, &job.options, &fit_run(o), observer.as_mut())
        .map_err(|e| file_error(o, e))?;
    if let Some(p) = &progress {
        p.finish();
    }
    let seconds = began.elapsed().as_secs_f64();
    match (&fit.report, affine) {
        (FileFitReport::Affine(report_of), Some(affine)) => {
            // the fit's own warnings are the robust driver's, reported with it
            let job = Job {
                extra_warnings: fit
                    .warnings
                    .iter()
                    .filter(|w| !matches!(w, sysid::modelfile::FileFitWarning::Robust(_)))
                    .map(ToString::to_string)
                    .collect(),
                ..job
            };
            let start = affine
                .params(&model.free_values())
                .map_err(|m| bad("--model", m.reason))?;
            report(&job, &affine, &start, report_of, seconds, |p| {
                affine.theta(p)
            })
        }
        _ => report_gradient(o, &model, &fit),
    }
}

/// A model file's fit error, named by the option or the data it comes from.
pub(super) fn file_error(o: &Options, e: FileFitError) -> CliError {
    let context = o.data.data.display().to_string();
    match e {
        FileFitError::NothingFree { .. } => bad("--model", e.to_string()),
        FileFitError::NotAffine { .. } => bad("--method", e.to_string()),
        FileFitError::InvalidOption { reason, .. } => bad("--particles", reason),
        FileFitError::Start(m) => bad("--model", m.reason),
        FileFitError::Affine(source) => CliError::AffineEm { context, source },
        FileFitError::Gradient(source) => CliError::GradientEm { context, source },
        other => bad("--model", other.to_string()),
    }
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
    for (path, text) in &outputs {
        write_output(path, o.force, text)?;
    }
    for w in &warnings {
        crate::warn(w);
    }
    let mut report = summary;
    report["command"] = serde_json::json!("fit");
    report["out"] = serde_json::json!(o.out);
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
