//! The multi-start fit of a model that is not affine in its parameters: its particle
//! log-likelihood maximised directly from several starts, the best one finished with
//! an accurate filter.
//!
//! # Why
//! Gradient EM ([`super::GradientEm`]) has one start, costs a particle smoother and a
//! BFGS M-step per iteration, and crawls where the states are nearly determined by the
//! parameters (a small process noise: EM's rate is the fraction of missing
//! information). On the two-tank model of `../shared/data/nonlinear/twotank` written
//! non-affinely, it ran 500 iterations (about 1000 s) from a start 20 % off and was
//! still moving; from the file's rough start it ended 2 to 3 times off after 308. A
//! bootstrap filter's log-likelihood on common random numbers is a cheap, smooth
//! enough function of a few parameters, and a search on it does not crawl.
//!
//! # Algorithm
//! 1. **Starts** are the caller's (the user's and perturbations of it), as unconstrained
//!    vectors.
//! 2. **Exploration**: from every start, Nelder–Mead on the log-likelihood of an
//!    `explore_particles` bootstrap filter ([`crate::likelihood_search`]), one seed for
//!    every start and point so that their values compare, at most
//!    `explore_evaluations` filters each, restarted from its best point with the first
//!    simplex's size while a round gains [`RESTART_GAIN`] nats (a simplex collapses on
//!    a ridge far from the maximum); the starts run in parallel.
//! 3. **Selection**: the start whose search ended highest (the earlier one on a tie).
//! 4. **Finish**: Nelder–Mead from there on a `particles` filter (a new common seed),
//!    with a third of the simplex steps and the same patience, restarted while a round gains
//!    [`FINISH_RESTART_GAIN`] nats, then (at most [`CURVATURE_ROUNDS`] times) the
//!    log-likelihood's curvature by central differences, its Newton point, and a
//!    simplex along the curvature's eigenvectors scaled to its 1-nat contour (on a
//!    narrow ridge an axis-aligned simplex stalls short of the top: 0.8 nats on a
//!    linear model written non-affinely, `sysid-modelfile/tests/direct.rs`), all within
//!    `evaluations` filters; the same curvature gives standard errors. The estimate's
//!    log-likelihood is the mean of [`REPEATS`](crate::likelihood_search::REPEATS) independent filters, with their sd.
//!    `particles = 0` skips it (the exploration's best is the estimate, scored by its
//!    filter).
//!
//! Warnings ([`DirectWarning`]): a search that spent its budget before converging,
//! another start that ended within [`RIVAL_NATS`] nats elsewhere with a valley of
//! [`VALLEY_NATS`] between (a second maximum),
//! a scoring filter too noisy to rank nearby points, an interrupted run.
//!
//! # Complexity
//! `starts x explore_evaluations` filters of `O(T explore_particles)` (in parallel over
//! the starts), then `evaluations + 2 REPEATS` of `O(T particles)`. Nelder–Mead needs
//! more evaluations per parameter as the dimension grows: this is for models with a
//! handful of free parameters, where a filter is cheap; gradient EM scales better in
//! the dimension.
//!
//! # Determinism
//! Start `k`'s search depends only on its start and the seed; the result is the same
//! on any number of threads.

use super::{GradientEmError, GradientModel};
use crate::likelihood_search::{Curvature, Search, filtered_loglik, scored};
use rand::RngExt;
use rayon::prelude::*;
use std::cell::RefCell;
use std::time::{Duration, Instant};
use sysid_smc::{FilterOptions, ParticleFilter, Series, stream};

/// Another start whose search ended within this many nats of the best one, at a point
/// more than 10 % away in some parameter, is a second maximum worth a warning.
pub const RIVAL_NATS: f64 = 3.0;

/// A start's search is restarted from its best point while a round gains this many
/// nats.
pub const RESTART_GAIN: f64 = 1.0;

/// The finish's simplex is restarted while a round gains this many nats (along a
/// flat ridge a simplex stalls before the top: on the two-tank file one round ended
/// 2.3 nats below the others' maximum).
pub const FINISH_RESTART_GAIN: f64 = 0.5;

/// Rounds of the finish's curvature-shaped restarts
/// ([`crate::likelihood_search`]'s `curvature_rounds`).
pub const CURVATURE_ROUNDS: usize = 3;

/// Evaluations per vertex of a simplex without a gain before it counts as stalled (the
/// polish's 5 are too few on a narrow ridge: on the two-tank file the finish then
/// stopped after 25 filters every time, its simplex still too wide to turn).
pub const EXPLORE_PATIENCE: usize = 10;

/// The dip (nats) half-way between two starts' ends, below the lower end, that makes
/// them two maxima.
pub const VALLEY_NATS: f64 = 2.0;

/// The scoring filter's sd (nats) above which it is called too noisy to rank points.
pub const NOISY_SD: f64 = 1.0;

/// Settings of [`fit_direct`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectOptions {
    /// Particles of the exploration's filter. Default 1000.
    pub explore_particles: usize,
    /// Filters each start's search may spend. Default 200.
    pub explore_evaluations: usize,
    /// Particles of the finishing filter; 0 skips the finish. Default 10 000.
    pub particles: usize,
    /// Filters the finish may spend. Default 300.
    pub evaluations: usize,
    /// Run the starts in parallel. Default true.
    pub parallel: bool,
}

impl Default for DirectOptions {
    fn default() -> Self {
        DirectOptions {
            explore_particles: 1000,
            explore_evaluations: 200,
            particles: 10_000,
            evaluations: 300,
            parallel: true,
        }
    }
}

/// What one start's exploration did (vectors on the unconstrained scale).
#[derive(Debug, Clone, PartialEq)]
pub struct DirectStart {
    /// Where it started.
    pub start: Vec<f64>,
    /// The log-likelihood there (exploration filter, common seed; `-inf` if invalid).
    pub start_loglik: f64,
    /// Where its search ended (the best point it evaluated).
    pub end: Vec<f64>,
    /// The log-likelihood there.
    pub loglik: f64,
    /// Filters it ran.
    pub evaluations: usize,
    /// Whether its search converged within the budget.
    pub converged: bool,
}

/// Why a direct fit should be read with care.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum DirectWarning {
    /// The search that gave the estimate spent its budget before converging.
    NotConverged {
        /// The stage: `exploration` or `finish`.
        stage: &'static str,
        /// Its budget (filters).
        evaluations: usize,
        /// What the stage gained over its start (nats).
        gain: f64,
    },
    /// Another start ended nearly as high somewhere else.
    RivalMaximum {
        /// That start (0 is the user's).
        start: usize,
        /// How far below the chosen start's exploration value (nats).
        gap: f64,
        /// The parameter that differs most, and its two values (chosen, rival).
        parameter: String,
        /// Values (chosen, rival).
        values: (f64, f64),
    },
    /// The scoring filter's Monte Carlo sd is above [`NOISY_SD`].
    NoisyFilter {
        /// Its particles.
        particles: usize,
        /// Its sd (nats).
        sd: f64,
    },
    /// The run was stopped early; the best point so far is the estimate.
    Interrupted,
}

impl std::fmt::Display for DirectWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DirectWarning::NotConverged {
                stage,
                evaluations,
                gain,
            } => write!(
                f,
                "the {stage} search spent its {evaluations} filters before converging (it \
                 had gained {gain:.1} nats): the estimate may be below the maximum; fit \
                 again from it (its values in the written file)"
            ),
            DirectWarning::RivalMaximum {
                start,
                gap,
                parameter,
                values: (chosen, rival),
            } => write!(
                f,
                "start {start} ended only {gap:.1} nats lower at another point ({parameter} \
                 {rival:.4} against {chosen:.4}): the likelihood has a second maximum, \
                 check both (the starts' table in --json)"
            ),
            DirectWarning::NoisyFilter { particles, sd } => write!(
                f,
                "the {particles}-particle filter that scores the estimate has a Monte Carlo \
                 sd of {sd:.2} nats (above {NOISY_SD}): it cannot rank nearby points, so the \
                 search may have stopped early or moved by noise; use more particles"
            ),
            DirectWarning::Interrupted => f.write_str(
                "interrupted: the best point so far is the estimate, not a converged fit",
            ),
        }
    }
}

/// The result of [`fit_direct`].
#[derive(Debug, Clone, PartialEq)]
pub struct DirectFit {
    /// The estimate, unconstrained.
    pub estimate: Vec<f64>,
    /// The estimate's log-likelihood (mean of [`REPEATS`](crate::likelihood_search::REPEATS) independent filters of the
    /// finish, or of the exploration when there is no finish).
    pub loglik: f64,
    /// The Monte Carlo sd of one such filter, from the repeats.
    pub loglik_sd: f64,
    /// Particles of the filter that scored the estimate.
    pub particles: usize,
    /// Every start's exploration, in the order given.
    pub starts: Vec<DirectStart>,
    /// The start the estimate comes from.
    pub chosen: usize,
    /// Filters the finish ran (0 without one).
    pub finish_evaluations: usize,
    /// Whether the search that gave the estimate converged.
    pub converged: bool,
    /// Standard errors of the parameters (constrained scale, in the model's order)
    /// from the curvature of the finishing filter's log-likelihood near the estimate
    /// (observed information by central differences on common random numbers, mapped
    /// by the delta method), when the finish took one and it was a maximum's.
    pub standard_errors: Option<Vec<f64>>,
    /// Whether the run was stopped early.
    pub interrupted: bool,
    /// What should temper a reading of the estimate.
    pub warnings: Vec<DirectWarning>,
    /// Wall time of the exploration and of the finish.
    pub timing: (Duration, Duration),
}

/// A filter's log-likelihood at unconstrained points of `model`.
struct Likelihood<'a, G: GradientModel> {
    model: &'a G,
    data: Series<'a>,
    filter: RefCell<ParticleFilter>,
}

impl<'a, G: GradientModel> Likelihood<'a, G> {
    fn new(
        model: &'a G,
        data: Series<'a>,
        particles: usize,
        parallel: bool,
    ) -> Result<Self, GradientEmError> {
        let filter = ParticleFilter::new(FilterOptions {
            particles,
            record_summaries: false,
            parallel,
            ..FilterOptions::default()
        })?;
        Ok(Likelihood {
            model,
            data,
            filter: RefCell::new(filter),
        })
    }

    /// The log-likelihood at `theta` (`-inf` where it is not a model or the filter
    /// fails).
    fn at(&self, theta: &[f64], seed: u64) -> f64 {
        filtered_loglik(&self.filter, self.model.smc_model(theta), &self.data, seed)
    }
}

/// Fits `model` to `data` from `starts` (unconstrained vectors; the first is the
/// user's) by the algorithm of the module docs. `steps` are the exploration simplex's
/// steps per coordinate (unconstrained scale). `stop` ends the run with the best point
/// so far.
///
/// # Errors
/// [`GradientEmError::InvalidOption`]: no starts, a start or `steps` of the wrong
/// length, fewer than 2 particles, no evaluations. [`GradientEmError::InvalidParams`]:
/// no start has a finite log-likelihood.
pub fn fit_direct<G: GradientModel>(
    model: &G,
    data: Series<'_>,
    starts: &[Vec<f64>],
    steps: &[f64],
    options: &DirectOptions,
    seed: u64,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<DirectFit, GradientEmError> {
    check(model, starts, steps, options)?;
    let began = Instant::now();
    // the exploration's common numbers, the finish's, and the scoring repeats'
    let explore_seed: u64 = stream(seed, 0).random();
    let finish_seed: u64 = stream(seed, 1).random();
    let score_seed: u64 = stream(seed, 2).random();
    let explore = |start: &Vec<f64>| -> Result<DirectStart, GradientEmError> {
        if stop() {
            // a start not reached before the stop: not explored
            return Ok(DirectStart {
                start: start.clone(),
                start_loglik: f64::NEG_INFINITY,
                end: start.clone(),
                loglik: f64::NEG_INFINITY,
                evaluations: 0,
                converged: false,
            });
        }
        let likelihood = Likelihood::new(model, data, options.explore_particles, false)?;
        let common = |theta: &[f64]| likelihood.at(theta, explore_seed);
        let search = Search::new(&common, stop).with_patience(EXPLORE_PATIENCE);
        let start_loglik = search.evaluate(start);
        let converged = if start_loglik.is_finite() {
            search
                .nelder_mead_restarted(
                    steps,
                    options.explore_evaluations.saturating_sub(1),
                    RESTART_GAIN,
                )
                .map_err(GradientEmError::InvalidOption)?
        } else {
            false
        };
        let (end, loglik) = search.best();
        Ok(DirectStart {
            start: start.clone(),
            start_loglik,
            end,
            loglik,
            evaluations: search.evaluations(),
            converged,
        })
    };
    let explored: Vec<DirectStart> = if options.parallel {
        starts.par_iter().map(explore).collect::<Result<_, _>>()?
    } else {
        starts.iter().map(explore).collect::<Result<_, _>>()?
    };
    let explore_time = began.elapsed();
    let chosen = explored
        .iter()
        .enumerate()
        .filter(|(_, s)| s.loglik.is_finite())
        .fold(None, |best: Option<(usize, f64)>, (k, s)| match best {
            Some((_, l)) if l >= s.loglik => best,
            _ => Some((k, s.loglik)),
        })
        .map(|(k, _)| k)
        .ok_or_else(|| {
            GradientEmError::InvalidParams(format!(
                "no start has a finite log-likelihood under a {}-particle filter: every one \
                 is an invalid model or loses the data; start nearer the data",
                options.explore_particles
            ))
        })?;
    // a stop in the exploration ends the run at its best point: no rival check and no
    // finish (each costs many filters), only the exploration filter's score
    let stopped = stop();
    let mut warnings = if stopped {
        Vec::new()
    } else {
        let likelihood = Likelihood::new(model, data, options.explore_particles, true)?;
        rivals(model, &explored, chosen, |theta| {
            likelihood.at(theta, explore_seed)
        })
    };
    let finished = began.elapsed();
    let best = &explored[chosen];
    let mut curvature = None;
    let (estimate, loglik, loglik_sd, particles, finish_evaluations, converged) =
        if options.particles == 0 || options.evaluations == 0 || stopped {
            let likelihood = Likelihood::new(model, data, options.explore_particles, true)?;
            let (l, sd) = scored(&|t, s| likelihood.at(t, s), &best.end, score_seed);
            if !best.converged && !stop() {
                warnings.push(DirectWarning::NotConverged {
                    stage: "exploration",
                    evaluations: options.explore_evaluations,
                    gain: best.loglik - best.start_loglik,
                });
            }
            let estimate = best.end.clone();
            (
                estimate,
                l,
                sd,
                options.explore_particles,
                0,
                best.converged,
            )
        } else {
            let likelihood = Likelihood::new(model, data, options.particles, true)?;
            let common = |theta: &[f64]| likelihood.at(theta, finish_seed);
            let search = Search::new(&common, stop).with_patience(EXPLORE_PATIENCE);
            let start_loglik = search.evaluate(&best.end);
            let half: Vec<f64> = steps.iter().map(|s| s / 3.0).collect();
            let budget = options.evaluations.saturating_sub(1);
            let mut converged = start_loglik.is_finite()
                && search
                    .nelder_mead_restarted(&half, budget, FINISH_RESTART_GAIN)
                    .map_err(GradientEmError::InvalidOption)?;
            if converged {
                // a simplex stalls on a narrow ridge: reshape it by the local curvature
                let (last, rounds_converged) = search
                    .curvature_rounds(
                        &half,
                        options.evaluations.saturating_sub(search.evaluations()),
                        FINISH_RESTART_GAIN,
                        CURVATURE_ROUNDS,
                    )
                    .map_err(GradientEmError::InvalidOption)?;
                curvature = last;
                converged = rounds_converged;
            }
            let (end, end_loglik) = search.best();
            if !converged && !stop() {
                warnings.push(DirectWarning::NotConverged {
                    stage: "finishing",
                    evaluations: options.evaluations,
                    gain: end_loglik - start_loglik,
                });
            }
            let (l, sd) = scored(&|t, s| likelihood.at(t, s), &end, score_seed);
            (
                end,
                l,
                sd,
                options.particles,
                search.evaluations(),
                converged,
            )
        };
    if loglik_sd > NOISY_SD {
        warnings.push(DirectWarning::NoisyFilter {
            particles,
            sd: loglik_sd,
        });
    }
    let standard_errors = curvature.and_then(|c| standard_errors(model, &c));
    let interrupted = stop();
    if interrupted {
        warnings.push(DirectWarning::Interrupted);
    }
    Ok(DirectFit {
        estimate,
        loglik,
        loglik_sd,
        particles,
        starts: explored,
        chosen,
        finish_evaluations,
        converged,
        standard_errors,
        interrupted,
        warnings,
        timing: (explore_time, began.elapsed() - finished),
    })
}

/// The delta-method standard errors of the constrained parameters from a curvature on
/// the unconstrained scale: `J (-H)^-1 J'` with `J` the constrained map's Jacobian by
/// central differences.
fn standard_errors<G: GradientModel>(model: &G, curvature: &Curvature) -> Option<Vec<f64>> {
    curvature.information()?;
    let covariance = (-&curvature.hessian).cholesky()?.inverse();
    let z = &curvature.point;
    let d = z.len();
    let mut jacobian = nalgebra::DMatrix::zeros(d, d);
    for k in 0..d {
        let eps = 1e-6 * z[k].abs().max(1.0);
        let (mut up, mut down) = (z.clone(), z.clone());
        up[k] += eps;
        down[k] -= eps;
        let (a, b) = (model.constrained(&up), model.constrained(&down));
        for i in 0..d {
            jacobian[(i, k)] = (a[i] - b[i]) / (2.0 * eps);
        }
    }
    let mapped = &jacobian * covariance * jacobian.transpose();
    let se: Vec<f64> = (0..d).map(|i| mapped[(i, i)].sqrt()).collect();
    se.iter().all(|v| v.is_finite()).then_some(se)
}

fn check<G: GradientModel>(
    model: &G,
    starts: &[Vec<f64>],
    steps: &[f64],
    options: &DirectOptions,
) -> Result<(), GradientEmError> {
    let bad = |what: String| Err(GradientEmError::InvalidOption(what));
    let d = model.parameter_dim();
    if starts.is_empty() {
        return bad("the direct fit needs at least one start".into());
    }
    if let Some(k) = starts.iter().position(|s| s.len() != d) {
        return bad(format!(
            "start {k} has {} values for {d} parameters",
            starts[k].len()
        ));
    }
    if steps.len() != d || steps.iter().any(|s| !s.is_finite() || *s == 0.0) {
        return bad(format!(
            "the simplex steps must be {d} finite non-zero values, got {steps:?}"
        ));
    }
    if options.explore_particles < 2 || (options.particles == 1) {
        return bad("the direct fit's filters need at least 2 particles".into());
    }
    if options.explore_evaluations == 0 {
        return bad("explore_evaluations must be at least 1".into());
    }
    Ok(())
}

/// A warning for the best other start that ended within [`RIVAL_NATS`] of the chosen
/// one at a point more than 10 % away in some parameter, with a valley between them:
/// the exploration's log-likelihood half-way is [`VALLEY_NATS`] below both ends (on a
/// flat ridge of one maximum, where a weakly determined parameter differs by 10 %, it
/// is not).
fn rivals<G: GradientModel>(
    model: &G,
    explored: &[DirectStart],
    chosen: usize,
    loglik: impl Fn(&[f64]) -> f64,
) -> Vec<DirectWarning> {
    let best = &explored[chosen];
    let at = model.constrained(&best.end);
    let names = model.parameter_names();
    let mut rival: Option<DirectWarning> = None;
    let mut rival_loglik = f64::NEG_INFINITY;
    for (k, s) in explored.iter().enumerate() {
        // (a start at -inf is never a rival)
        let near = s.loglik.is_finite() && s.loglik > best.loglik - RIVAL_NATS;
        if k == chosen || !near || s.loglik <= rival_loglik {
            continue;
        }
        let other = model.constrained(&s.end);
        let (i, relative) = at
            .iter()
            .zip(&other)
            .map(|(a, b)| (a - b).abs() / a.abs().max(b.abs()).max(1e-12))
            .enumerate()
            .fold((0, 0.0), |m, (i, r)| if r > m.1 { (i, r) } else { m });
        let half_way: Vec<f64> = best
            .end
            .iter()
            .zip(&s.end)
            .map(|(a, b)| 0.5 * (a + b))
            .collect();
        if relative > 0.1 && loglik(&half_way) < s.loglik - VALLEY_NATS {
            rival_loglik = s.loglik;
            rival = Some(DirectWarning::RivalMaximum {
                start: k,
                gap: best.loglik - s.loglik,
                parameter: names.get(i).cloned().unwrap_or_default(),
                values: (at[i], other[i]),
            });
        }
    }
    rival.into_iter().collect()
}
