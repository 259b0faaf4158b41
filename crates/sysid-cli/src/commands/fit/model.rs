//! `sysid fit --model m.toml`: the free parameters of a nonlinear model file,
//! estimated from their values in the file. Closed-form particle EM when the equations
//! are affine in them (seed 000; the robust driver by default), gradient EM otherwise
//! (seed 001; rejection FFBSi with `--particles` paths, analytic gradients). The
//! estimate is written as a model file that every nonlinear command reads.

use super::options::Options;
use super::toml_metadata::metadata_lines;
use crate::commands::particle::series_of;
use crate::error::CliError;
use crate::files::{fmt, write_output};
use sysid::em::gradient::{GradientEm, GradientModel, MStepOptions};
use sysid::em::{EmObserver, IterationInfo, Termination, run_em};
use sysid::modelfile::ModelFile;
use sysid::smc::FfbsiReject;

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
    if model.free_names().is_empty() {
        return Err(bad(
            "--model",
            format!(
                "{}: every parameter is fixed; nothing to estimate",
                path.display()
            ),
        ));
    }
    let file = o
        .data
        .read_for_names(&model.spec().inputs, &model.spec().outputs)?;
    match model.affine() {
        Some(affine) => super::affine::run_file(o, &affine, file),
        None => fit_gradient(o, &model, file),
    }
}

/// Records the natural parameters and the log-likelihood estimate of every iteration.
struct Trace<'a> {
    model: &'a sysid::modelfile::ExprGradient,
    rows: Vec<(f64, Vec<f64>)>,
}

impl EmObserver<Vec<f64>> for Trace<'_> {
    fn iteration(&mut self, info: &IterationInfo<'_, Vec<f64>>) {
        self.rows
            .push((info.loglik, self.model.constrained(info.estimate)));
    }
}

/// Gradient EM for a model that is not affine in its free parameters.
fn fit_gradient(
    o: &Options,
    model: &ModelFile,
    file: crate::files::DataFile,
) -> Result<(), CliError> {
    let method = match o.method.as_str() {
        // the robust driver is the default of closed-form particle EM
        "robust" | "em" => "gradient-em",
        other => {
            return Err(bad(
                "--method",
                format!(
                    "{other:?}: {} is not affine in its free parameters ({}), so it is fitted by \
                     gradient EM; use --method em",
                    model.origin(),
                    model.why_not_affine().unwrap_or_default()
                ),
            ));
        }
    };
    let options = o.particle_em(2)?;
    let context = o.data.data.display().to_string();
    let series = series_of(&file, &context)?;
    let gradient = model.gradient();
    let start = gradient.unconstrained(&model.free_values());
    let smoother = FfbsiReject {
        paths: o.particles,
        max_trials: None,
        parallel: false,
    };
    let em_error = |source| CliError::GradientEm {
        context: context.clone(),
        source,
    };
    let mut em = GradientEm::new(
        &gradient,
        series,
        o.particles,
        smoother,
        MStepOptions::default(),
        o.seed,
    )
    .map_err(em_error)?;
    let mut trace = Trace {
        model: &gradient,
        rows: Vec::new(),
    };
    let progress = crate::progress::Progress::new(o.max_iter as u64, "gradient EM", o.json);
    crate::progress::interruptible();
    let result = run_em(
        &mut em,
        start,
        &options,
        &mut (&mut trace, progress.clone()),
    );
    progress.finish();
    if let Termination::Error { iteration, error } = &result.termination {
        return Err(CliError::GradientEm {
            context: format!("{context}, EM iteration {iteration}"),
            source: error.clone(),
        });
    }
    let estimate = gradient.constrained(&result.estimate);
    let names = model.free_names();
    let warnings = settling_warnings(&names, &trace.rows);
    let summary = serde_json::json!({
        "method": method, "iterations": result.iterations, "particles": o.particles,
        "seed": o.seed, "loglik_estimate": result.loglik,
        "likelihood_decreases": result.decreases, "data": context,
        "interrupted": matches!(result.termination, Termination::Interrupted { .. }),
    });
    let fitted = model.with_values(&estimate);
    let mut outputs = vec![(o.out.clone(), fitted.to_toml(&metadata_lines(&summary)))];
    if let Some(path) = &o.trace {
        let mut text = format!("iteration,loglik,{}\n", names.join(","));
        for (k, (l, values)) in trace.rows.iter().enumerate() {
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
        .zip(&estimate)
        .map(|(n, v)| (n, serde_json::json!(v)))
        .collect::<serde_json::Map<_, _>>()
        .into();
    report["seconds"] = serde_json::json!(result.elapsed.as_secs_f64());
    report["warnings"] = serde_json::json!(warnings);
    crate::report(o.json, report, || {
        let values: Vec<String> = names
            .iter()
            .zip(&estimate)
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

/// A warning per parameter still drifting: over the last quarter of the iterations, its
/// mean moved by more than 2 % (or 5 standard deviations of its iterates) against the
/// quarter before. EM's iterates of a noisy E-step wander; a drift means more
/// iterations are needed.
fn settling_warnings(names: &[String], rows: &[(f64, Vec<f64>)]) -> Vec<String> {
    let q = rows.len() / 4;
    if q < 2 {
        return vec![format!(
            "only {} EM iterations: too few to tell whether the estimate has settled \
             (use --max-iter 100 or more)",
            rows.len()
        )];
    }
    let last = &rows[rows.len() - q..];
    let before = &rows[rows.len() - 2 * q..rows.len() - q];
    let mut warnings = Vec::new();
    for (k, name) in names.iter().enumerate() {
        let stats = |part: &[(f64, Vec<f64>)]| {
            let v: Vec<f64> = part.iter().map(|r| r.1[k]).collect();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
            (mean, var.sqrt())
        };
        let ((m1, _), (m2, sd2)) = (stats(before), stats(last));
        let change = (m2 - m1).abs();
        if change > 0.02 * m2.abs().max(1e-12) && change > 5.0 * sd2 / (q as f64).sqrt() {
            warnings.push(format!(
                "{name} is still moving ({} -> {} between the last two quarters of the \
                 iterations): run more iterations (--max-iter)",
                fmt(m1),
                fmt(m2)
            ));
        }
    }
    warnings
}
