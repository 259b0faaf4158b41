//! How far to trust a particle filter's result: the Monte Carlo standard deviation of
//! its log-likelihood estimate, from independent repeats, and the smallest effective
//! sample size, with warnings when either says the estimate is unreliable.
//!
//! # Rules
//! - The log-likelihood sd is the sample sd of the estimate over the run and
//!   `repeats` more filters with independent streams. Above 1.5 nats the estimate is
//!   too noisy to compare models or to drive PMMH (Doucet, Pitt, Deligiannidis and
//!   Kohn 2015 recommend about 1 to 1.7); the warning says how many particles would
//!   bring it to 1 (the variance falls as 1/M).
//! - The filter lost the state when, for [`LOST_STEPS`] steps in a row, the weights
//!   sat on a handful of particles: an effective sample size below [`LOST_FRACTION`]
//!   of M (between 1.5 and 5). A single such step is an outlying observation.

use super::particle::ParticleArgs;
use crate::files::fmt;
use serde_json::json;
use sysid::smc::{FilterModel, FilterOptions, ParticleFilter, Series, stream};

/// An ESS below this fraction of the particles (and below 5) means the filter lost the
/// state at that step.
const LOST_FRACTION: f64 = 0.01;

/// The log-likelihood sd above which the estimate is flagged (nats).
const SD_LIMIT: f64 = 1.5;

/// Runs further apart than this (nats) are not Monte Carlo scatter but lost states.
const CATASTROPHIC_SPREAD: f64 = 20.0;

/// Steps in a row with a collapsed ESS that make a lost state (one such step is an
/// outlying observation the filter recovers from).
const LOST_STEPS: usize = 3;

/// The ESS below which a step counts as collapsed.
fn lost_below(particles: usize) -> f64 {
    (LOST_FRACTION * particles as f64).clamp(1.5, 5.0)
}

/// The first run of at least [`LOST_STEPS`] consecutive collapsed steps: its first
/// step and its length.
fn lost_stretch(ess: &[f64], particles: usize) -> Option<(usize, usize)> {
    let below = lost_below(particles);
    let mut t = 0;
    while t < ess.len() {
        if ess[t] < below {
            let length = ess[t..].iter().take_while(|&&e| e < below).count();
            if length >= LOST_STEPS {
                return Some((t, length));
            }
            t += length;
        } else {
            t += 1;
        }
    }
    None
}

/// The diagnostics of one filter run.
pub(crate) struct FilterTrust {
    /// Sample sd of the log-likelihood estimates (None without repeats).
    pub loglik_sd: Option<f64>,
    /// The log-likelihood estimates of the repeats (the run's not included).
    pub repeats: Vec<f64>,
    /// Smallest ESS of the run and the step (0-based) where it happened.
    pub min_ess: Option<(f64, usize)>,
    /// Reasons not to trust the estimate.
    pub warnings: Vec<String>,
}

impl FilterTrust {
    /// The diagnostics as JSON fields.
    pub fn json(&self) -> serde_json::Value {
        json!({
            "loglik_sd": self.loglik_sd, "repeats": self.repeats.len(),
            "repeat_logliks": self.repeats,
            "min_ess": self.min_ess.map(|(e, _)| e), "min_ess_step": self.min_ess.map(|(_, t)| t),
            "warnings": self.warnings,
        })
    }
}

/// Diagnoses the run of `pf` (log-likelihood `loglik`): its ESS, and `args.repeats`
/// more filters with the same options on streams derived from `args.seed`. `time`
/// names the steps in the messages (the data file's time; row numbers without one);
/// `progress` advances by one per repeat.
pub(crate) fn diagnose<M: FilterModel + Sync>(
    model: &M,
    series: &Series<'_>,
    pf: &ParticleFilter,
    loglik: f64,
    args: &ParticleArgs,
    time: &[f64],
    progress: &crate::progress::Progress,
) -> FilterTrust {
    let (options, ess, seed, repeats) = (pf.options(), pf.ess(), args.seed, args.repeats);
    let time_label = |t: usize| time.get(t).map_or_else(|| (t + 1).to_string(), |v| fmt(*v));
    let particles = options.particles;
    let mut warnings = Vec::new();
    let min_ess = ess
        .iter()
        .copied()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(t, e)| (e, t));
    if let Some((first, length)) = lost_stretch(ess, particles) {
        warnings.push(format!(
            "the filter lost the state from step {} (time {}) for {length} steps: its \
             weights sat on fewer than {:.1} effective particles of {particles}; the \
             log-likelihood and the states there are unreliable (more particles, or a \
             model whose noise covers the data)",
            first + 1,
            time_label(first),
            lost_below(particles)
        ));
    }
    let mut estimates = Vec::with_capacity(repeats);
    if repeats > 0 {
        let quiet = FilterOptions {
            record_summaries: false,
            ..options.clone()
        };
        match ParticleFilter::new(quiet) {
            Ok(mut filter) => {
                for k in 1..=repeats as u64 {
                    let repeat_seed: u64 = rand::RngExt::random(&mut stream(seed, k));
                    let run = filter.run(model, series, repeat_seed);
                    progress.inc(1);
                    match run {
                        Ok(s) => estimates.push(s.loglik),
                        Err(e) => {
                            warnings.push(format!(
                                "a repeat of the filter (stream {k}) failed: {e}; the \
                                 log-likelihood estimate is unreliable"
                            ));
                            break;
                        }
                    }
                }
            }
            Err(e) => warnings.push(format!("the repeats could not run: {e}")),
        }
    }
    let loglik_sd = (!estimates.is_empty() && estimates.len() == repeats).then(|| {
        let all: Vec<f64> = std::iter::once(loglik)
            .chain(estimates.iter().copied())
            .collect();
        let mean = all.iter().sum::<f64>() / all.len() as f64;
        (all.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (all.len() - 1) as f64).sqrt()
    });
    if let Some(sd) = loglik_sd
        && sd > SD_LIMIT
    {
        let (low, high) = std::iter::once(loglik)
            .chain(estimates.iter().copied())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(v), h.max(v))
            });
        let advice = if high - low > CATASTROPHIC_SPREAD {
            // a few runs lost the state: the 1/M rule does not apply to such a spread
            format!(
                "the runs range from {low:.1} to {high:.1}, so some lost the state: use many \
                 more particles and check again"
            )
        } else {
            let needed = (particles as f64 * sd * sd).ceil();
            format!("about {needed:.0} particles would bring it to 1")
        };
        warnings.push(format!(
            "the log-likelihood estimate has a Monte Carlo sd of {sd:.2} nats over {} runs \
             (above {SD_LIMIT}): {advice}",
            repeats + 1
        ));
    }
    FilterTrust {
        loglik_sd,
        repeats: estimates,
        min_ess,
        warnings,
    }
}
