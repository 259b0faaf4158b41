use super::in_data;
use crate::StatesArgs;
use crate::error::CliError;
use crate::files::{create_output, fmt};
use std::io::Write;
use sysid::kalman::KalmanWorkspace;

/// Which state estimates `sysid filter` and `sysid smooth` write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pass {
    /// `E[x_t | y_1..t]` (square-root Kalman filter).
    Filter,
    /// `E[x_t | y_1..T]` (RTS smoother).
    Smooth,
}

/// One step's state means and standard deviations.
type MeanAndSd = (Vec<f64>, Vec<f64>);

pub fn run(a: &StatesArgs, pass: Pass) -> Result<(), CliError> {
    crate::files::refuse_existing(std::iter::once(a.out.as_path()), a.force)?;
    let (model, file) = a.source.load()?;
    let mut warnings = Vec::new();
    let mut ws = KalmanWorkspace::new();
    let n = model.n();
    // (means, standard deviations) per step, and the log-likelihood
    let (rows, loglik): (Vec<MeanAndSd>, f64) = match pass {
        Pass::Filter => {
            let f = ws
                .filter(&model, &file.record)
                .map_err(in_data(a.source.data_path()))?;
            // with a diffuse initial state, the first steps may not determine every
            // state yet: its variance is infinite, written as inf
            let rows = (0..file.record.len())
                .map(|k| {
                    let p = f.filtered_covariance(k);
                    let undetermined = f.filtered_undetermined(k);
                    (
                        f.filtered_mean(k).iter().copied().collect(),
                        (0..n)
                            .map(|i| match undetermined[i] {
                                true => f64::INFINITY,
                                false => p[(i, i)].max(0.0).sqrt(),
                            })
                            .collect(),
                    )
                })
                .collect();
            let steps = f.diffuse_steps();
            if steps > 0 {
                warnings.push(format!(
                    "the diffuse initial state is not yet determined by the data in the first \
                     {steps} step(s): some of their filtered states have an infinite standard \
                     deviation (written as inf)"
                ));
            }
            (rows, f.loglik())
        }
        Pass::Smooth => {
            let sm = ws
                .smooth(&model, &file.record)
                .map_err(in_data(a.source.data_path()))?;
            let rows = (0..sm.len())
                .map(|k| {
                    let p = sm.covariance(k);
                    (
                        sm.mean(k).iter().copied().collect(),
                        (0..n).map(|i| p[(i, i)].max(0.0).sqrt()).collect(),
                    )
                })
                .collect();
            (rows, sm.loglik())
        }
    };
    let mut w = create_output(&a.out, a.force)?;
    let io = |source| CliError::Io {
        path: a.out.clone(),
        source,
    };
    let mut header = vec!["t".to_string()];
    header.extend((1..=n).map(|i| format!("x{i}")));
    header.extend((1..=n).map(|i| format!("x{i}_sd")));
    writeln!(w, "{}", header.join(",")).map_err(io)?;
    for (k, (mean, sd)) in rows.iter().enumerate() {
        let mut row = vec![file.label(k)];
        row.extend(mean.iter().chain(sd).map(|&v| fmt(v)));
        writeln!(w, "{}", row.join(",")).map_err(io)?;
    }
    w.commit()?;
    let (command, what) = match pass {
        Pass::Filter => ("filter", "filtered"),
        Pass::Smooth => ("smooth", "smoothed"),
    };
    for w in &warnings {
        crate::warn(w);
    }
    crate::report(
        a.json,
        serde_json::json!({
            "command": command, "loglik": loglik, "steps": rows.len(), "states": n, "out": a.out,
            "diffuse_directions": model.diffuse().ncols(), "warnings": warnings,
        }),
        || {
            format!(
                "loglik {loglik}; wrote {what} states to {}",
                a.out.display()
            )
        },
    );
    Ok(())
}
