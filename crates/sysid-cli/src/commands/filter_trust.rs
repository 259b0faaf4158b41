//! How far to trust a particle filter's result: the library's
//! [`FilterDiagnostics`] (log-likelihood sd from the run's genealogy or from repeats,
//! the smallest ESS, a lost state), with the steps named by the data file's times.

use crate::files::fmt;
use serde_json::json;
use sysid::smc::{
    FilterDiagnostics, FilterModel, FilterSummary, LoglikSdMethod, ParticleFilter, Series,
};

/// The diagnostics of one filter run, with the warnings as printed.
pub(crate) struct FilterTrust {
    /// The library's diagnostics.
    pub diagnostics: FilterDiagnostics,
    /// The warnings, their steps named by the data file's times.
    pub warnings: Vec<String>,
}

impl FilterTrust {
    /// The log-likelihood sd as the summary line gives it: `, sd 1.4 (single run)`,
    /// or `, sd 1.6 over 10 runs (single-run 1.4)` with repeats; empty without either.
    pub fn describe_sd(&self, repeats: usize) -> String {
        let d = &self.diagnostics;
        match (d.loglik_sd, d.loglik_sd_method) {
            (Some(sd), Some(LoglikSdMethod::SingleRun)) => {
                format!(", sd {} (single run)", fmt(sd))
            }
            (Some(sd), Some(LoglikSdMethod::Repeats)) => {
                let single = d
                    .loglik_sd_single_run
                    .map(|s| format!(" (single-run {})", fmt(s)))
                    .unwrap_or_default();
                format!(", sd {} over {} runs{single}", fmt(sd), repeats + 1)
            }
            _ => String::new(),
        }
    }

    /// Smallest ESS of the run and the step (0-based) where it happened.
    pub fn min_ess(&self) -> Option<(f64, usize)> {
        self.diagnostics.min_ess
    }

    /// The diagnostics as JSON fields.
    pub fn json(&self) -> serde_json::Value {
        let d = &self.diagnostics;
        json!({
            "loglik_sd": d.loglik_sd, "loglik_sd_method": d.loglik_sd_method.map(|m| m.name()),
            "loglik_sd_single_run": d.loglik_sd_single_run, "repeats": d.repeat_logliks.len(),
            "repeat_logliks": d.repeat_logliks,
            "min_ess": d.min_ess.map(|(e, _)| e), "min_ess_step": d.min_ess.map(|(_, t)| t),
            "warnings": self.warnings,
        })
    }
}

/// Diagnoses the run of `pf` (summary `run`) with `repeats` more
/// filters on streams derived from `seed`. `time` names the steps in the
/// messages (the data file's time; row numbers without one); `progress` advances by
/// one per repeat.
pub(crate) fn diagnose<M: FilterModel + Sync>(
    model: &M,
    series: &Series<'_>,
    pf: &ParticleFilter,
    run: &FilterSummary,
    (seed, repeats): (u64, usize),
    time: &[f64],
    progress: &crate::progress::Progress,
) -> FilterTrust {
    let diagnostics =
        FilterDiagnostics::diagnose(model, series, pf, run, seed, repeats, || progress.inc(1));
    let time_label = |t: usize| time.get(t).map_or_else(|| (t + 1).to_string(), |v| fmt(*v));
    let warnings = diagnostics
        .warnings
        .iter()
        .map(|w| w.describe(&time_label))
        .collect();
    FilterTrust {
        diagnostics,
        warnings,
    }
}
