//! How far to trust a particle filter's result: the Monte Carlo standard deviation of
//! its log-likelihood estimate, from the run's own genealogy or from independent
//! repeats, and the smallest effective sample size, with warnings when either says the
//! estimate is unreliable.
//!
//! # Rules
//! - The log-likelihood sd is, with `repeats` > 0, the sample sd of the estimate over
//!   the run and `repeats` more filters with independent streams; without repeats, the
//!   run's single-run estimate ([`FilterOptions::variance_block`], `variance.rs`: one
//!   filter's cost, measured 8-14 % low, and blind to rare losses of the state, which
//!   only repeats can see). Above 1.5 nats the estimate is
//!   too noisy to compare models or to drive PMMH (Doucet, Pitt, Deligiannidis and
//!   Kohn 2015 recommend about 1 to 1.7); the warning says how many particles would
//!   bring it to 1 (the variance falls as 1/M).
//! - The filter lost the state when, for [`LOST_STEPS`] steps in a row, the weights
//!   sat on a handful of particles: an effective sample size below [`LOST_FRACTION`]
//!   of M (between 1.5 and 5). A single such step is an outlying observation; but
//!   there the likelihood's error comes from the few weights themselves, which the
//!   genealogy cannot measure, so a single-run sd is flagged as unreliable (on the
//!   measured cascaded tanks, one step at an ESS of 1.5 of 100 000: single-run sd 1.5,
//!   sd over 5 runs 26).
//!
//! # Example
//! ```
//! use rand_distr::{Distribution, StandardNormal};
//! use sysid_smc::{FilterDiagnostics, FilterOptions, LoglikSdMethod, ParticleFilter, Series};
//! use sysid_smc::{InitialSampler, ObservationDensity, StateSpace, TransitionSampler};
//! /// A random walk seen in unit noise.
//! struct Walk;
//! impl StateSpace for Walk { fn state_dim(&self) -> usize { 1 } }
//! impl InitialSampler for Walk {
//!     fn sample_initial<R: rand::Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
//!         x[0] = StandardNormal.sample(rng);
//!     }
//! }
//! impl TransitionSampler for Walk {
//!     fn sample_transition<R: rand::Rng + ?Sized>(
//!         &self, _t: usize, x: &[f64], _u: &[f64], next: &mut [f64], rng: &mut R,
//!     ) {
//!         let w: f64 = StandardNormal.sample(rng);
//!         next[0] = x[0] + 0.1 * w;
//!     }
//! }
//! impl ObservationDensity for Walk {
//!     fn log_observation(&self, _t: usize, x: &[f64], _u: &[f64], y: &[f64]) -> f64 {
//!         -0.5 * (y[0] - x[0]).powi(2) - 0.5 * (2.0 * std::f64::consts::PI).ln()
//!     }
//! }
//! let y: Vec<f64> = (0..100).map(|t| (t as f64 * 0.1).sin()).collect();
//! let series = Series::new(&y, 1)?;
//! let options = FilterOptions {
//!     particles: 200,
//!     variance_block: Some(sysid_smc::VARIANCE_SPAN),
//!     ..FilterOptions::default()
//! };
//! let mut pf = ParticleFilter::new(options)?;
//! let run = pf.run(&Walk, &series, 7)?;
//! // the sd from the run itself (no repeats)
//! let checked = FilterDiagnostics::diagnose(&Walk, &series, &pf, &run, 7, 0, || {});
//! assert_eq!(checked.loglik_sd_method, Some(LoglikSdMethod::SingleRun));
//! assert!(checked.loglik_sd.unwrap() < 1.5 && checked.warnings.is_empty());
//! // and from 5 independent repeats
//! let repeated = FilterDiagnostics::diagnose(&Walk, &series, &pf, &run, 7, 5, || {});
//! assert_eq!(repeated.loglik_sd_method, Some(LoglikSdMethod::Repeats));
//! assert!(repeated.loglik_sd.unwrap() < 1.5);
//! # Ok::<(), sysid_smc::SmcError>(())
//! ```

use crate::{FilterModel, FilterOptions, FilterSummary, ParticleFilter, Series, stream};

/// An ESS below this fraction of the particles (and below 5) means the filter lost the
/// state at that step.
pub const LOST_FRACTION: f64 = 0.01;

/// The log-likelihood sd above which the estimate is flagged (nats).
pub const SD_LIMIT: f64 = 1.5;

/// Runs further apart than this (nats) are not Monte Carlo scatter but lost states.
const CATASTROPHIC_SPREAD: f64 = 20.0;

/// Steps in a row with a collapsed ESS that make a lost state (one such step is an
/// outlying observation the filter recovers from).
pub const LOST_STEPS: usize = 3;

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

/// Why a particle filter's result should not be trusted.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum FilterWarning {
    /// The weights sat on a handful of particles for several steps in a row.
    LostState {
        /// The first such step (0-based).
        first: usize,
        /// How many steps in a row.
        length: usize,
        /// The effective sample size below which a step counts.
        below: f64,
        /// The particles.
        particles: usize,
    },
    /// The log-likelihood estimate's Monte Carlo sd is above [`SD_LIMIT`].
    NoisyLoglik {
        /// The sd.
        sd: f64,
        /// How it was estimated.
        method: LoglikSdMethod,
        /// The runs (the filter and its repeats; 1 for the single-run estimate).
        runs: usize,
        /// The smallest and largest estimate.
        range: (f64, f64),
        /// The particles.
        particles: usize,
    },
    /// The sd is the single-run estimate, and at some step the weights sat on a
    /// handful of particles: there the estimate's error is beyond what the genealogy
    /// measures.
    SingleRunBlind {
        /// The single-run sd.
        sd: f64,
        /// The step (0-based) of the smallest ESS.
        step: usize,
        /// That ESS.
        ess: f64,
        /// The particles.
        particles: usize,
    },
    /// A repeat of the filter failed.
    RepeatFailed {
        /// Its stream.
        stream: u64,
        /// Why.
        reason: String,
    },
    /// The repeats could not be set up.
    RepeatsNotRun {
        /// Why.
        reason: String,
    },
}

impl FilterWarning {
    /// The warning with the steps named by `time_label` (a data file's times, say)
    /// instead of their numbers alone.
    pub fn describe(&self, time_label: &dyn Fn(usize) -> String) -> String {
        match self {
            FilterWarning::LostState {
                first,
                length,
                below,
                particles,
            } => format!(
                "the filter lost the state from step {} (time {}) for {length} steps: its \
                 weights sat on fewer than {below:.1} effective particles of {particles}; the \
                 log-likelihood and the states there are unreliable (more particles, or a \
                 model whose noise covers the data)",
                first + 1,
                time_label(*first),
            ),
            FilterWarning::NoisyLoglik {
                sd,
                method,
                runs,
                range: (low, high),
                particles,
            } => {
                let advice = if *method == LoglikSdMethod::SingleRun {
                    let needed = (*particles as f64 * sd * sd).ceil();
                    format!(
                        "about {needed:.0} particles would bring it to 1, unless some runs \
                         lose the state, which one run cannot show: check with independent \
                         repeats of the filter"
                    )
                } else if high - low > CATASTROPHIC_SPREAD {
                    // a few runs lost the state: the 1/M rule does not apply to such a
                    // spread
                    format!(
                        "the runs range from {low:.1} to {high:.1}, so some lost the state: \
                         use many more particles and check again"
                    )
                } else {
                    let needed = (*particles as f64 * sd * sd).ceil();
                    format!("about {needed:.0} particles would bring it to 1")
                };
                let over = match method {
                    LoglikSdMethod::SingleRun => "from this run's genealogy".to_string(),
                    LoglikSdMethod::Repeats => format!("over {runs} runs"),
                };
                format!(
                    "the log-likelihood estimate has a Monte Carlo sd of {sd:.2} nats {over} \
                     (above {SD_LIMIT}): {advice}"
                )
            }
            FilterWarning::SingleRunBlind {
                sd,
                step,
                ess,
                particles,
            } => format!(
                "the effective sample size fell to {ess:.1} of {particles} particles at step \
                 {} (time {}): at such a step the log-likelihood's error comes from a few \
                 weights, which the single-run sd ({sd:.2} nats) cannot see, so it may be far \
                 too small; check with independent repeats of the filter",
                step + 1,
                time_label(*step),
            ),
            FilterWarning::RepeatFailed { stream, reason } => format!(
                "a repeat of the filter (stream {stream}) failed: {reason}; the \
                 log-likelihood estimate is unreliable"
            ),
            FilterWarning::RepeatsNotRun { reason } => {
                format!("the repeats could not run: {reason}")
            }
        }
    }
}

impl std::fmt::Display for FilterWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe(&|t| (t + 1).to_string()))
    }
}

/// Where a log-likelihood sd comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoglikSdMethod {
    /// The run's own genealogy ([`FilterSummary::loglik_variance`]): one filter's cost,
    /// 10-17 % low in the measured cases, blind to rare losses of the state.
    SingleRun,
    /// The sample sd over the run and independent repeats of the filter.
    Repeats,
}

impl LoglikSdMethod {
    /// The method's name in reports (`single-run`, `repeats`).
    pub fn name(self) -> &'static str {
        match self {
            LoglikSdMethod::SingleRun => "single-run",
            LoglikSdMethod::Repeats => "repeats",
        }
    }
}

/// The diagnostics of one filter run.
#[derive(Debug, Clone, PartialEq)]
pub struct FilterDiagnostics {
    /// The Monte Carlo sd of the log-likelihood estimate: over the run and its
    /// repeats when there are repeats, else the run's single-run estimate (`None` when
    /// neither exists, or when a repeat failed).
    pub loglik_sd: Option<f64>,
    /// How [`FilterDiagnostics::loglik_sd`] was estimated.
    pub loglik_sd_method: Option<LoglikSdMethod>,
    /// The run's single-run sd, whether or not repeats ran (`None` when the filter
    /// ran without [`FilterOptions::variance_block`]).
    pub loglik_sd_single_run: Option<f64>,
    /// The log-likelihood estimates of the repeats (the run's not included).
    pub repeat_logliks: Vec<f64>,
    /// Smallest ESS of the run and the step (0-based) where it happened.
    pub min_ess: Option<(f64, usize)>,
    /// Reasons not to trust the estimate.
    pub warnings: Vec<FilterWarning>,
}

impl FilterDiagnostics {
    /// Diagnoses the last run of `filter` (its summary `run`): its ESS, its
    /// single-run variance when the filter estimated one, and `repeats` more filters
    /// with the same options on the streams `1..=repeats` derived from `seed` (the
    /// run's own seed; the results do not depend on the threads). `on_repeat` is called
    /// after each repeat (a progress bar).
    pub fn diagnose<M: FilterModel + Sync>(
        model: &M,
        series: &Series<'_>,
        filter: &ParticleFilter,
        run: &FilterSummary,
        seed: u64,
        repeats: usize,
        mut on_repeat: impl FnMut(),
    ) -> FilterDiagnostics {
        let (options, ess) = (filter.options(), filter.ess());
        let (loglik, particles) = (run.loglik, options.particles);
        let single_run = run.loglik_variance.map(f64::sqrt);
        let mut warnings = Vec::new();
        let min_ess = ess
            .iter()
            .copied()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(t, e)| (e, t));
        if let Some((first, length)) = lost_stretch(ess, particles) {
            warnings.push(FilterWarning::LostState {
                first,
                length,
                below: lost_below(particles),
                particles,
            });
        }
        let mut estimates = Vec::with_capacity(repeats);
        if repeats > 0 {
            let quiet = FilterOptions {
                record_summaries: false,
                variance_block: None,
                ..options.clone()
            };
            match ParticleFilter::new(quiet) {
                Ok(mut repeat) => {
                    for k in 1..=repeats as u64 {
                        let repeat_seed: u64 = rand::RngExt::random(&mut stream(seed, k));
                        let run = repeat.run(model, series, repeat_seed);
                        on_repeat();
                        match run {
                            Ok(s) => estimates.push(s.loglik),
                            Err(e) => {
                                warnings.push(FilterWarning::RepeatFailed {
                                    stream: k,
                                    reason: e.to_string(),
                                });
                                break;
                            }
                        }
                    }
                }
                Err(e) => warnings.push(FilterWarning::RepeatsNotRun {
                    reason: e.to_string(),
                }),
            }
        }
        let all: Vec<f64> = std::iter::once(loglik)
            .chain(estimates.iter().copied())
            .collect();
        let (loglik_sd, loglik_sd_method) = if repeats == 0 {
            (single_run, single_run.map(|_| LoglikSdMethod::SingleRun))
        } else if estimates.len() == repeats {
            let mean = all.iter().sum::<f64>() / all.len() as f64;
            let sd = (all.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>()
                / (all.len() - 1) as f64)
                .sqrt();
            (Some(sd), Some(LoglikSdMethod::Repeats))
        } else {
            (None, None)
        };
        if let (Some(sd), Some(LoglikSdMethod::SingleRun), Some((ess, step))) =
            (loglik_sd, loglik_sd_method, min_ess)
            && ess < lost_below(particles)
            && !warnings
                .iter()
                .any(|w| matches!(w, FilterWarning::LostState { .. }))
        {
            warnings.push(FilterWarning::SingleRunBlind {
                sd,
                step,
                ess,
                particles,
            });
        }
        if let (Some(sd), Some(method)) = (loglik_sd, loglik_sd_method)
            && sd > SD_LIMIT
        {
            let range = all
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                    (l.min(v), h.max(v))
                });
            warnings.push(FilterWarning::NoisyLoglik {
                sd,
                method,
                runs: repeats + 1,
                range,
                particles,
            });
        }
        FilterDiagnostics {
            loglik_sd,
            loglik_sd_method,
            loglik_sd_single_run: single_run,
            repeat_logliks: estimates,
            min_ess,
            warnings,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::lost_stretch;

    #[test]
    fn a_lost_state_is_three_collapsed_steps_in_a_row() {
        let ok = [50.0; 10];
        assert_eq!(lost_stretch(&ok, 100), None);
        let mut one = ok;
        one[4] = 1.0;
        assert_eq!(
            lost_stretch(&one, 100),
            None,
            "one outlier is not a lost state"
        );
        let mut three = ok;
        three[2..5].copy_from_slice(&[1.0, 1.2, 1.1]);
        assert_eq!(lost_stretch(&three, 100), Some((2, 3)));
    }
}
