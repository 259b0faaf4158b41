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
use sysid::em::gradient::{GradientEm, GradientModel, MStepOptions};
use sysid::em::{EmObserver, EmOptions, IterationInfo, Termination, run_em};
use sysid::models::{WienerEstimate, WienerModel, normalised_magnitude_error, wiener_start};
use sysid::smc::FfbsiReject;

fn bad(option: &'static str, message: impl Into<String>) -> CliError {
    CliError::BadOption {
        option,
        message: message.into(),
    }
}

/// Collects `iteration, loglik, parameters...` rows for `--trace`.
struct Trace<'m> {
    model: &'m WienerModel,
    rows: Vec<Vec<f64>>,
}

impl EmObserver<Vec<f64>> for Trace<'_> {
    fn iteration(&mut self, info: &IterationInfo<'_, Vec<f64>>) {
        let mut row = vec![info.loglik];
        row.extend(self.model.constrained(info.estimate));
        self.rows.push(row);
    }
}

/// `sysid fit wiener`.
pub fn run(o: &Options) -> Result<(), CliError> {
    if o.particles < 2 {
        return Err(bad("--particles", "must be at least 2"));
    }
    if o.max_iter == 0 {
        return Err(bad("--iters", "must be at least 1"));
    }
    let file = o.data.read()?;
    crate::commands::check_column_counts(&file, 0, 2)?;
    let context = o.data.data.display().to_string();
    let series = series_of(&file, &context)?;
    let outputs: Vec<f64> = file.record.y.as_slice().to_vec();
    if outputs.iter().any(|v| v.is_nan()) {
        return Err(bad(
            "--data",
            format!("{context}: the N4SID start needs every y1 and y2 (missing values found)"),
        ));
    }
    let start = wiener_start(&outputs).map_err(|e| bad("--data", format!("{context}: {e}")))?;
    let model = WienerModel::default();
    let smoother = FfbsiReject {
        paths: o.particles,
        max_trials: None,
        parallel: false,
    };
    let mut em = GradientEm::new(
        &model,
        series,
        o.particles,
        smoother,
        MStepOptions::default(),
        o.seed,
    )
    .map_err(|source| CliError::GradientEm {
        context: "options".into(),
        source,
    })?
    .with_guided_filter();
    let options = EmOptions {
        max_iterations: o.max_iter,
        tol: 0.0,
        ..EmOptions::default()
    }
    .check()
    .map_err(|e| CliError::BadOption {
        option: "--max-iter",
        message: e.to_string(),
    })?;
    let mut trace = Trace {
        model: &model,
        rows: Vec::new(),
    };
    let theta = start.theta().map_err(|e| {
        bad(
            "--data",
            format!("{context}: the N4SID start is unusable: {e}"),
        )
    })?;
    let progress =
        crate::progress::Progress::new(options.max_iterations as u64, "fit wiener", o.json);
    crate::progress::interruptible();
    let result = run_em(
        &mut em,
        theta,
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
    let e = WienerEstimate::from_theta(&result.estimate);
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
            "normalised_magnitude_error_vs_reference_system": normalised_magnitude_error(&e)},
    });
    write_output(
        &o.out,
        o.force,
        &(serde_json::to_string_pretty(&json).expect("serialises") + "\n"),
    )?;
    if let Some(path) = &o.trace {
        let names = model.parameter_names();
        let mut text = format!("iteration,loglik,{}\n", names.join(","));
        for (k, row) in trace.rows.iter().enumerate() {
            let values: Vec<String> = row.iter().map(|v| v.to_string()).collect();
            text += &format!("{},{}\n", k + 1, values.join(","));
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
