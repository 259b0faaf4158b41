//! `sysid fit wiener`: blind Wiener identification (seed 001) by gradient EM from a
//! CSV file with the two outputs; the input is not needed (it is never measured).
//!
//! The start is the lecture's: the linear part from N4SID on y1, r1 = r2 = 0.1, each
//! breakpoint at a tenth of the reference system's. `--particles` sets the filter's
//! particles and the backward trajectories (FFBSi by rejection); `--iters` the EM
//! iterations (run exactly). The E-step's filter is the fully adapted one (exact for
//! the piecewise-linear outputs), and the estimate is reported in the canonical form
//! of `WienerModel` (companion `A`, minimum-phase side of `Q`).

use super::options::Options;
use crate::commands::particle::series_of;
use crate::error::CliError;
use crate::files::write_output;
use sysid::em::gradient::GradientModel;
use sysid::em::{FitRun, Termination};
use sysid::models::{WienerFitError, WienerFitOptions, WienerModel, fit_wiener};

fn bad(option: &'static str, message: impl Into<String>) -> CliError {
    CliError::BadOption {
        option,
        message: message.into(),
    }
}

/// A Wiener fit's error, named by the option or the data file (`context`).
fn wiener_error(context: &str) -> impl Fn(WienerFitError) -> CliError + '_ {
    move |e| match e {
        WienerFitError::InvalidOption { name, reason } => bad(
            if name == "particles" {
                "--particles"
            } else {
                "--iters"
            },
            reason,
        ),
        WienerFitError::Em(source) => CliError::GradientEm {
            context: "options".into(),
            source,
        },
        other => bad("--data", format!("{context}: {other}")),
    }
}

pub fn run(o: &Options) -> Result<(), CliError> {
    let options = WienerFitOptions::new(o.particles, o.max_iter)
        .check()
        .map_err(wiener_error(""))?;
    if crate::commands::nonlinear::is_model_file(&o.out) {
        return Err(bad(
            "--out",
            "the Wiener estimate is written as JSON (name it .json): the blind Wiener system \
             has no model file",
        ));
    }
    let file = o.data.read()?;
    crate::commands::check_column_counts(&file, 0, 2)?;
    let context = o.data.data.display().to_string();
    let series = series_of(&file, &context)?;
    let progress = crate::progress::Progress::new(o.max_iter as u64, "fit wiener", o.json);
    crate::progress::interruptible();
    let fit = fit_wiener(
        series,
        &options,
        &FitRun::new(o.seed).stopped_by(&crate::progress::interrupted),
        &mut progress.clone(),
    )
    .map_err(wiener_error(&context))?;
    progress.finish();
    let result = &fit.result;
    if let Termination::Error { iteration, error } = &result.termination {
        return Err(CliError::GradientEm {
            context: format!("{context}, EM iteration {iteration}"),
            source: error.clone(),
        });
    }
    let e = &fit.estimate;
    // a breakpoint can run off to infinity (no data beyond it): written as "inf", not
    // as serde's silent null
    let numbers = |values: &[f64]| -> Vec<serde_json::Value> {
        values
            .iter()
            .map(|&v| {
                if v.is_finite() {
                    serde_json::json!(v)
                } else {
                    serde_json::json!(v.to_string())
                }
            })
            .collect()
    };
    let json = serde_json::json!({
        "system": "wiener", "a": e.a.map(|row| numbers(&row)), "c": [1.0, 0.0],
        "q": e.q.map(|row| numbers(&row)), "breakpoints": numbers(&e.beta),
        "r": numbers(&e.r),
        "gradient_em": {"iterations": result.iterations, "particles": o.particles,
            "seed": o.seed, "loglik_estimate": result.loglik,
            "interrupted": matches!(result.termination, Termination::Interrupted { .. }),
            "normalised_magnitude_error_vs_reference_system": fit.magnitude_error()},
    });
    write_output(
        &o.out,
        o.force,
        &(serde_json::to_string_pretty(&json).expect("serialises") + "\n"),
    )?;
    if let Some(path) = &o.trace {
        let names = WienerModel::default().parameter_names();
        let mut text = format!("iteration,loglik,{}\n", names.join(","));
        for (k, (loglik, values)) in fit.iterates.iter().enumerate() {
            let mut row = vec![loglik.to_string()];
            row.extend(values.iter().map(|v| v.to_string()));
            text += &format!("{},{}\n", k + 1, row.join(","));
        }
        write_output(path, o.force, &text)?;
    }
    crate::report(
        o.json,
        serde_json::json!({
            "command": "fit", "system": "wiener", "iterations": result.iterations,
            "breakpoints": numbers(&e.beta), "r": numbers(&e.r), "loglik_estimate": result.loglik,
            "seconds": result.elapsed.as_secs_f64(), "out": o.out,
        }),
        || {
            format!(
                "gradient EM: {} iterations in {:.1} s; breakpoints {:?}, r {:?}; wrote {}",
                result.iterations,
                result.elapsed.as_secs_f64(),
                e.beta,
                e.r,
                o.out.display()
            )
        },
    );
    crate::commands::interrupted(
        &result.termination,
        std::iter::once(o.out.clone()).chain(o.trace.clone()),
    )
}
