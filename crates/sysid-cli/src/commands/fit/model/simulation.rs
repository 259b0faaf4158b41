//! `sysid fit --model m.toml --criterion simulation`: the library's
//! [`ModelFile::fit_simulation_error`], its estimate written as a model file (with the
//! estimated initial state as the initial means) and reported.

use super::{bad, file_error};
use crate::commands::fit::options::Options;
use crate::commands::fit::toml_metadata::metadata_lines;
use crate::error::CliError;
use crate::files::{fmt, write_output};
use sysid::em::FitRun;
use sysid::modelfile::{FileFitMethod, FileFitReport, ModelFile};
use sysid::smc::Series;

/// Fits, writes and reports.
pub fn run(
    o: &Options,
    model: &ModelFile,
    series: Series<'_>,
    method: &FileFitMethod,
) -> Result<(), CliError> {
    if o.trace.is_some() {
        return Err(bad(
            "--trace",
            "--criterion simulation has no iteration trace; leave --trace out",
        ));
    }
    crate::files::refuse_existing(std::iter::once(o.out.as_path()), o.force)?;
    crate::progress::interruptible();
    let began = std::time::Instant::now();
    let run = FitRun::new(o.seed).stopped_by(&crate::progress::interrupted);
    let fitted = model
        .fit(series, method, &run, &mut ())
        .map_err(|e| file_error(o, e))?;
    let (FileFitReport::Simulation(fit), FileFitMethod::Simulation(options)) =
        (&fitted.report, method)
    else {
        unreachable!("the simulation-error method gives its report")
    };
    let asked = options.starts;
    let seconds = began.elapsed().as_secs_f64();
    let names = model.free_names();
    let outputs = &model.spec().outputs;
    let warnings: Vec<String> = fit.warnings.iter().map(ToString::to_string).collect();
    let summary = serde_json::json!({
        "method": "simulation-error", "criterion": "simulation", "starts": asked,
        "seed": o.seed, "data": o.data.data.display().to_string(),
        "rms": fit.rms.first(), "fit_percent": fit.fit_percent.first(),
        "interrupted": fit.interrupted,
    });
    write_output(
        &o.out,
        o.force,
        &fit.fitted.to_toml(&metadata_lines(&summary)),
    )?;
    for w in &warnings {
        crate::warn(w);
    }
    let mut report = summary;
    report["command"] = serde_json::json!("fit");
    report["out"] = serde_json::json!(o.out);
    report["outputs"] = serde_json::json!(outputs);
    report["rms"] = serde_json::json!(fit.rms);
    report["fit_percent"] = serde_json::json!(fit.fit_percent);
    report["estimate"] = object(&names, fit.estimate.iter().map(|&v| Some(v)));
    report["standard_errors"] = object(&names, fit.standard_errors.iter().copied());
    report["initial_state"] = object(
        &model.spec().states,
        fit.initial_state.iter().map(|&v| Some(v)),
    );
    report["runs"] = fit
        .starts
        .iter()
        .map(|s| {
            serde_json::json!({
                "rms": s.rms, "evaluations": s.evaluations,
                "termination": s.termination, "converged": s.converged,
            })
        })
        .collect::<Vec<_>>()
        .into();
    report["best_run"] = serde_json::json!(fit.best);
    report["seconds"] = serde_json::json!(seconds);
    report["warnings"] = serde_json::json!(warnings);
    crate::report(o.json, report, || {
        let mut text = format!(
            "simulation-error fit of {}: {} runs in {seconds:.2} s, best run {} (RMS {})\n",
            model.origin(),
            fit.starts.len(),
            fit.best + 1,
            fmt(fit.starts[fit.best].rms),
        );
        for ((name, rms), fit_pc) in outputs.iter().zip(&fit.rms).zip(&fit.fit_percent) {
            text += &format!(
                "  {name}: simulation RMS {}, fit {fit_pc:.2} %\n",
                fmt(*rms)
            );
        }
        for ((name, v), se) in names.iter().zip(&fit.estimate).zip(&fit.standard_errors) {
            let se = se.map_or(String::new(), |s| format!(" (se {})", fmt(s)));
            text += &format!("  {name} = {}{se}\n", fmt(*v));
        }
        let x0: Vec<String> = model
            .spec()
            .states
            .iter()
            .zip(&fit.initial_state)
            .map(|(n, v)| format!("{n} = {}", fmt(*v)))
            .collect();
        text += &format!("  initial state: {}\n", x0.join(", "));
        text += &format!("wrote {}", o.out.display());
        text
    });
    if fit.interrupted {
        return Err(CliError::Interrupted {
            iteration: fit.starts.len(),
            written: vec![o.out.clone()],
        });
    }
    Ok(())
}

/// `{name: value}` with `null` for a missing value.
fn object(names: &[String], values: impl Iterator<Item = Option<f64>>) -> serde_json::Value {
    names
        .iter()
        .cloned()
        .zip(values)
        .map(|(n, v)| (n, serde_json::json!(v)))
        .collect::<serde_json::Map<_, _>>()
        .into()
}
