//! How far to trust a particle filter's result: the library's
//! [`FilterDiagnostics`] (log-likelihood sd from repeats, the smallest ESS, a lost
//! state), with the steps named by the data file's times.

use crate::files::fmt;
use serde_json::json;
use sysid::smc::{FilterDiagnostics, FilterModel, ParticleFilter, Series};

/// The diagnostics of one filter run, with the warnings as printed.
pub(crate) struct FilterTrust {
    /// The library's diagnostics.
    pub diagnostics: FilterDiagnostics,
    /// The warnings, their steps named by the data file's times.
    pub warnings: Vec<String>,
}

impl FilterTrust {
    /// Sample sd of the log-likelihood estimates (None without repeats).
    pub fn loglik_sd(&self) -> Option<f64> {
        self.diagnostics.loglik_sd
    }

    /// Smallest ESS of the run and the step (0-based) where it happened.
    pub fn min_ess(&self) -> Option<(f64, usize)> {
        self.diagnostics.min_ess
    }

    /// The diagnostics as JSON fields.
    pub fn json(&self) -> serde_json::Value {
        let d = &self.diagnostics;
        json!({
            "loglik_sd": d.loglik_sd, "repeats": d.repeat_logliks.len(),
            "repeat_logliks": d.repeat_logliks,
            "min_ess": d.min_ess.map(|(e, _)| e), "min_ess_step": d.min_ess.map(|(_, t)| t),
            "warnings": self.warnings,
        })
    }
}

/// Diagnoses the run of `pf` (log-likelihood `loglik`) with `repeats` more
/// filters on streams derived from `seed`. `time` names the steps in the
/// messages (the data file's time; row numbers without one); `progress` advances by
/// one per repeat.
pub(crate) fn diagnose<M: FilterModel + Sync>(
    model: &M,
    series: &Series<'_>,
    pf: &ParticleFilter,
    loglik: f64,
    (seed, repeats): (u64, usize),
    time: &[f64],
    progress: &crate::progress::Progress,
) -> FilterTrust {
    let diagnostics =
        FilterDiagnostics::diagnose(model, series, pf, loglik, seed, repeats, || progress.inc(1));
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
