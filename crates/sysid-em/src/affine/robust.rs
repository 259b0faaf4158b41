//! Particle EM that finds the maximum from a rough start: several short starts with
//! the noise variances estimated from an inflated value, a runaway guard, the best
//! start chosen by a large-M particle log-likelihood, then a long refinement with
//! more particles whose last iterates are averaged.
//!
//! # Why
//! At a rough start a small-M bootstrap filter loses the state, and with the noise
//! variances held small EM crawls, or drifts into a local maximum that explains the
//! data by noise (measurement variance near the output's variance). Estimating the
//! noise from an inflated start acts as an annealing that adapts to the fit: the
//! filter follows the data in the first iterations and the regression lands near a
//! maximum within a few dozen iterations. Which maximum depends on the start, so
//! several starts are explored and ranked by an accurate log-likelihood; the winner is
//! refined with more particles (a small-M E-step biases the noise variances upward)
//! and its Monte Carlo noise is averaged out (Polyak-Ruppert averaging).
//!
//! # Algorithm
//! 1. Starts: the user's, and `starts - 1` more with each estimated coefficient of
//!    `beta` multiplied by an independent `U[1 - spread, 1 + spread]` (stream
//!    `(seed, k)`; coefficients the spec holds, and the model's known ones
//!    ([`AffineModel::held_state_coefficients`]), stay at the user's values);
//!    every noise variance starts at `noise_inflation` times the user's, and is
//!    estimated (diagonal, or full if the spec says full), the measurement noise only
//!    after the first `hold_output_noise` iterations (before, a filter lost at a rough
//!    start makes the outputs look like noise, and the first M-step would set the
//!    measurement variance to the outputs' variance: a local maximum that explains
//!    nothing). Optionally (`max_escalations`, off by default), a start at which a
//!    bootstrap filter explains the outputs worse than white noise has its process
//!    noise multiplied by `escalation` until the filter follows them.
//! 2. Successive halving: every live start runs `explore_iterations` of affine EM with
//!    `explore_particles`; each is scored by a bootstrap filter with
//!    `select_particles` particles on common random numbers at the average of its
//!    last quarter of iterates; the better half goes on with twice the iterations,
//!    until one is left. A start whose process-noise variance grows past
//!    `runaway_factor` times its start after `runaway_after` iterations is stopped
//!    and reported as a runaway. The scored starts, grouped by estimates within 10 %
//!    of each other in every coefficient, are the table of local maxima
//!    ([`RobustFit::maxima`]).
//! 3. Refinement: the survivor, with the user's spec (a noise the user holds is put
//!    back at the user's value here), runs `refine_iterations` with
//!    `refine_particles`; the estimate returned is the average of the last half of
//!    its iterates (Polyak-Ruppert averaging), scored by the large filter.
//!
//! Starts run in parallel (rayon) with their own random streams, so the result is the
//! same on any number of threads.
//!
//! # Complexity
//! `starts x explore_iterations` E-steps at `explore_particles`, plus
//! `refine_iterations` at `refine_particles`, plus `starts + 1` filters at
//! `select_particles`; the [`RobustFit::timing`] split reports each part.
//!
//! # References
//! Schön, Wills and Ninness (2006) (the EM); Polyak and Juditsky (1992) (averaging).

use super::overrelax;
use super::polish::{Polish, polish};
use super::{AffineEm, AffineEmError, AffineEmSpec, AffineModel, AffineParams, free_structure};
use crate::EmAlgorithm;
use crate::FitRun;
use crate::linear::Covariance;
use crate::particle_pass::ParticlePass;
use nalgebra::DMatrix;
use rand::RngExt;
use rayon::prelude::*;
use std::time::{Duration, Instant};
use sysid_smc::{Series, Smoother, stream};

/// Settings of [`fit_robust`]; the defaults are the measured choice of
/// `docs/particle-em.md` (seed 000's study: T = 1000).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobustOptions {
    /// Number of starts (the user's and `starts - 1` perturbed ones). Default 8.
    pub starts: usize,
    /// Half-width of the multiplicative perturbation of the coefficients. Default 0.5.
    pub spread: f64,
    /// Factor on the user's noise variances at every start. Default 10.
    pub noise_inflation: f64,
    /// EM iterations of every start in the first round of the halving (doubled at
    /// every round). Default 50.
    pub explore_iterations: usize,
    /// Particles of the exploration E-steps. Default 50.
    pub explore_particles: usize,
    /// Iterations of every start during which the measurement-noise covariance is
    /// held at its inflated start, so that a start cannot explain the outputs away as
    /// noise before its filter has followed them. Default 10.
    pub hold_output_noise: usize,
    /// Iterations before the runaway guard looks. Default 50.
    pub runaway_after: usize,
    /// A process-noise variance above this factor times its start is a runaway.
    /// Default 10.
    pub runaway_factor: f64,
    /// Particles of the filter that ranks the starts and scores the result. Default 1000.
    pub select_particles: usize,
    /// EM iterations of the refinement. Default 600.
    pub refine_iterations: usize,
    /// Particles of the refinement E-steps. Default 100.
    pub refine_particles: usize,
    /// Factor on a start's process noise, applied up to `max_escalations` times, while
    /// the bootstrap filter at the start explains the outputs worse than white noise
    /// (a start whose dynamics run away from the data leaves the filter lost however
    /// long EM runs, and its M-step then fails). Default 10.
    pub escalation: f64,
    /// See `escalation`. Default 0 (off): seed 000's study and the pendulum study
    /// converge without it (the pendulum's 6 first runs gave the same estimates with
    /// 0 and 3), and on nlbench it fires at almost every start (a 50-particle filter
    /// at a rough start explains `y = d x^2` worse than white noise), changing a
    /// measured default. Turn it on when starts fail with degenerate weights or a
    /// singular noise estimate.
    pub max_escalations: usize,
    /// Particles of the filter whose log-likelihood, on common random numbers, is
    /// maximised directly from the refined estimate (the polish, `polish.rs`); 0 skips
    /// the polish. Default 10 000: on seed 000's benchmark a 1000-particle filter at the
    /// truth loses the state in 2 runs of 9, a 10 000-particle one has sd 0.6.
    pub polish_particles: usize,
    /// Evaluations (filters) the polish's Nelder–Mead may spend. Default 300.
    pub polish_evaluations: usize,
    /// Extrapolate the refinement's drift in its first three quarters, keeping a jump only when
    /// the ranking filter (on common random numbers) gains a nat (`overrelax.rs`).
    /// Default true: on the two-tank model with a held small process noise EM crawls
    /// for 2500 iterations along a ridge.
    pub extrapolate: bool,
    /// Run the starts in parallel. Default true.
    pub parallel: bool,
}

impl Default for RobustOptions {
    fn default() -> Self {
        RobustOptions {
            starts: 8,
            spread: 0.5,
            noise_inflation: 10.0,
            explore_iterations: 50,
            explore_particles: 50,
            hold_output_noise: 10,
            runaway_after: 50,
            runaway_factor: 10.0,
            select_particles: 1000,
            refine_iterations: 600,
            refine_particles: 100,
            escalation: 10.0,
            max_escalations: 0,
            polish_particles: 10_000,
            polish_evaluations: 300,
            extrapolate: true,
            parallel: true,
        }
    }
}

impl RobustOptions {
    /// Checks the settings.
    ///
    /// # Errors
    /// A zero count, a spread outside `[0, 1)`, a non-positive or non-finite factor.
    pub fn check(&self) -> Result<(), AffineEmError> {
        let bad = |what: &str| Err(AffineEmError::InvalidParams(format!("robust EM: {what}")));
        if self.starts == 0 || self.explore_iterations == 0 || self.refine_iterations == 0 {
            return bad("starts, explore_iterations and refine_iterations must be at least 1");
        }
        if self.explore_particles < 2
            || self.refine_particles < 2
            || self.select_particles < 2
            || self.polish_particles == 1
        {
            return bad("every particle count must be at least 2 (the polish's: 0 skips it)");
        }
        if !(0.0..1.0).contains(&self.spread) {
            return bad("spread must be in [0, 1)");
        }
        let inflation_ok = self.noise_inflation.is_finite() && self.noise_inflation > 0.0;
        let runaway_ok = self.runaway_factor.is_finite() && self.runaway_factor > 1.0;
        let escalation_ok = self.escalation.is_finite() && self.escalation > 1.0;
        if !(inflation_ok && runaway_ok && escalation_ok) {
            return bad("noise_inflation must be positive, runaway_factor and escalation above 1");
        }
        Ok(())
    }
}

/// How one start's exploration ended.
#[derive(Debug, Clone, PartialEq)]
pub enum StartStatus {
    /// It ran all its iterations and won the halving.
    Explored,
    /// It was scored below the better half at this round (1-based) and dropped.
    Dropped {
        /// The round.
        round: usize,
    },
    /// A noise variance grew past the guard at this iteration; stopped there.
    Runaway {
        /// The iteration (1-based).
        iteration: usize,
    },
    /// An E- or M-step failed (e.g. the filter lost every particle).
    Failed(String),
}

/// One start: where it began, where it ended, and its score.
#[derive(Debug, Clone)]
pub struct StartOutcome {
    /// The start (noise inflated).
    pub start: AffineParams,
    /// The average of the last quarter of its iterates (the last iterate of a runaway;
    /// the start on a failure).
    pub estimate: AffineParams,
    /// The large filter's log-likelihood at `estimate` at its last round (`None` for
    /// runaways and failures, which are not scored).
    pub loglik: Option<f64>,
    /// EM iterations it made.
    pub iterations: usize,
    /// How it ended.
    pub status: StartStatus,
    /// How many times its process noise was multiplied by a further
    /// [`RobustOptions::escalation`] before exploring, because the filter could not
    /// follow the outputs at the start (0: the inflated start was followable).
    pub noise_escalations: usize,
}

/// A local maximum found by one or more starts.
#[derive(Debug, Clone)]
pub struct LocalMaximum {
    /// The best estimate of the starts that reached it.
    pub estimate: AffineParams,
    /// Its large-filter log-likelihood.
    pub loglik: f64,
    /// How many starts reached it.
    pub starts: usize,
}

/// Where the time went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RobustTiming {
    /// Exploration of the starts (summed over starts, whatever the threads).
    pub explore: Duration,
    /// The large filters ranking the starts and scoring the result.
    pub select: Duration,
    /// The refinement.
    pub refine: Duration,
    /// The polish.
    pub polish: Duration,
}

/// The refinement's extrapolated jumps ([`RobustOptions::extrapolate`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Extrapolation {
    /// Jumps tried.
    pub tried: usize,
    /// Jumps taken.
    pub taken: usize,
    /// The refinement iteration after the last jump taken (0: none); the estimate
    /// averages the iterates after it.
    pub last: usize,
}

/// How the refinement ended: it always runs its iterations (a noisy E-step has no
/// reliable per-iteration stopping rule) and returns the average of the last half;
/// the averages of the last two quarters tell whether the iterates had settled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RefineStop {
    /// Every coefficient's average changed by less than 1 % between the last two
    /// quarters: the iterates fluctuate around a fixed point.
    Settled {
        /// The largest relative change.
        change: f64,
    },
    /// Some coefficient was still drifting (EM crawling along a ridge): the estimate
    /// is not the maximum yet.
    StillMoving {
        /// The largest relative change.
        change: f64,
    },
}

/// The result of [`fit_robust`].
#[derive(Debug, Clone)]
pub struct RobustFit {
    /// The estimate: the refined, averaged one, polished when
    /// [`RobustOptions::polish_particles`] is not 0.
    pub estimate: AffineParams,
    /// Its log-likelihood: by the polish's filter (the mean of independent runs) when it
    /// ran, else by the selection filter.
    pub loglik: f64,
    /// Particles of the filter behind [`RobustFit::loglik`].
    pub loglik_particles: usize,
    /// What the polish did (`None` when it was off or the run was interrupted first).
    pub polish: Option<Polish>,
    /// Whether the refinement's iterates had settled.
    pub stop: RefineStop,
    /// The estimate the refinement started from, and its log-likelihood.
    pub selected: LocalMaximum,
    /// Every start, in order.
    pub starts: Vec<StartOutcome>,
    /// The distinct local maxima, best first.
    pub maxima: Vec<LocalMaximum>,
    /// The refinement's iterates.
    pub refine_trace: Vec<AffineParams>,
    /// The refinement's extrapolated jumps.
    pub extrapolation: Extrapolation,
    /// The refinement's E-step log-likelihood estimates (at the iterate before each).
    pub refine_loglik: Vec<f64>,
    /// Reasons not to trust the result: a runner-up elsewhere that is about as good, a
    /// refinement that had not settled or that lost likelihood. (Runaway starts are
    /// normal in exploration: they are in [`RobustFit::starts`].)
    pub warnings: Vec<String>,
    /// Where the time went.
    pub timing: RobustTiming,
    /// Whether [`fit_robust_until`]'s [`FitRun::stop`] ended the run early.
    pub interrupted: bool,
}

/// Two maxima closer than this (nats) are not clearly separated.
const SEPARATION_NATS: f64 = 3.0;

/// Largest relative change of a coefficient's average between the last two quarters
/// of the refinement for it to count as settled.
const SETTLED: f64 = 0.01;

/// Estimates within this relative distance in every coefficient are one maximum.
const SAME_MAXIMUM: f64 = 0.1;

/// Runs robust particle EM on `model` and `data` from `start` (see the module docs).
/// `spec` is what the user estimates; `smoother` is the E-step smoother.
///
/// # Errors
/// Invalid options or start; every start failing; the refinement failing at its
/// first iteration.
pub fn fit_robust<A, S>(
    model: &A,
    data: Series<'_>,
    start: &AffineParams,
    spec: &AffineEmSpec,
    smoother: &S,
    options: &RobustOptions,
    seed: u64,
) -> Result<RobustFit, AffineEmError>
where
    A: AffineModel,
    S: Smoother<A::Smc> + Clone + Send + Sync,
{
    fit_robust_until(
        model,
        data,
        start,
        spec,
        smoother,
        options,
        &FitRun::new(seed),
    )
}

/// [`fit_robust`] that ends early when `run.stop()` turns true (e.g. on Ctrl-C), checked
/// after every EM iteration: the exploration ends with the ranking so far, the
/// refinement with the iterates so far, and the result (scored, averaged as usual) has
/// [`RobustFit::interrupted`] set and says so in its warnings.
///
/// # Errors
/// As [`fit_robust`].
pub fn fit_robust_until<A, S>(
    model: &A,
    data: Series<'_>,
    start: &AffineParams,
    spec: &AffineEmSpec,
    smoother: &S,
    options: &RobustOptions,
    run: &FitRun<'_>,
) -> Result<RobustFit, AffineEmError>
where
    A: AffineModel,
    S: Smoother<A::Smc> + Clone + Send + Sync,
{
    let (seed, stop) = (run.seed, run.stop);
    options.check()?;
    model.smc_model(start)?;
    let explore_spec = AffineEmSpec {
        pi_x: explored(spec.pi_x),
        pi_y: explored(spec.pi_y),
        ..*spec
    };
    let baseline = white_noise_loglik(&data);
    let mut starts = (0..options.starts)
        .map(|k| {
            let params = perturbed(model, start, spec, options, k, seed);
            let check_seed = stream(seed, (2 * options.starts + 1 + k) as u64).random();
            let (params, escalations) =
                followable(model, &data, params, options, baseline, check_seed);
            let em_seed = stream(seed, (options.starts + 1 + k) as u64).random();
            Explorer::new(
                model,
                data,
                params,
                &explore_spec,
                smoother,
                options,
                em_seed,
            )
            .map(|mut x| {
                x.outcome.noise_escalations = escalations;
                x
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    // rank on common random numbers: the same filter seed for every candidate
    let select_seed = stream(seed, u64::MAX).random::<u64>();
    let score = |params: &AffineParams| -> Option<f64> {
        let smc = model.smc_model(params).ok()?;
        let mut pass = ParticlePass::new(options.select_particles, select_seed).ok()?;
        pass.loglik(&smc, &data, None)
            .ok()
            .filter(|l| l.is_finite())
    };
    let mut timing = RobustTiming::default();
    let mut iterations = options.explore_iterations;
    let mut round = 1;
    // the last round's ranking: the winner and the runner-up went equally far
    let mut last_round: Vec<(usize, f64)> = Vec::new();
    // the best point any round scored: (estimate, loglik, start, round)
    let mut best_seen: Option<(AffineParams, f64, usize, usize)> = None;
    loop {
        let live: Vec<usize> = (0..starts.len())
            .filter(|&k| starts[k].outcome.status == StartStatus::Explored)
            .collect();
        if live.len() <= 1 && round > 1 {
            break;
        }
        let advance = |x: &mut Explorer<'_, A, S>| {
            let began = Instant::now();
            x.advance(iterations, options, stop);
            if x.outcome.status == StartStatus::Explored {
                x.outcome.loglik = None;
                let scored = Instant::now();
                x.outcome.loglik = score(&x.outcome.estimate);
                (scored - began, scored.elapsed())
            } else {
                (began.elapsed(), Duration::ZERO)
            }
        };
        let spent: Vec<(Duration, Duration)> = if options.parallel {
            starts
                .par_iter_mut()
                .enumerate()
                .filter(|(k, _)| live.contains(k))
                .map(|(_, x)| advance(x))
                .collect()
        } else {
            starts
                .iter_mut()
                .enumerate()
                .filter(|(k, _)| live.contains(k))
                .map(|(_, x)| advance(x))
                .collect()
        };
        for (explore, select) in spent {
            timing.explore += explore;
            timing.select += select;
        }
        let mut ranked: Vec<(usize, f64)> = live
            .iter()
            .filter_map(|&k| starts[k].outcome.loglik.map(|l| (k, l)))
            .collect();
        ranked.sort_by(|x, y| y.1.total_cmp(&x.1));
        if let Some(&(k, l)) = ranked.first()
            && best_seen.as_ref().is_none_or(|b| l > b.1)
        {
            best_seen = Some((starts[k].outcome.estimate.clone(), l, k, round));
        }
        // scored starts that are not ranked (runaways, failures) are already out
        for &k in &live {
            if starts[k].outcome.status == StartStatus::Explored
                && starts[k].outcome.loglik.is_none()
            {
                starts[k].outcome.status = StartStatus::Failed("could not be scored".into());
            }
        }
        if ranked.len() <= 1 {
            break;
        }
        if stop() {
            // interrupted: the best so far goes on (to a refinement that stops too)
            for &(k, _) in &ranked[1..] {
                starts[k].outcome.status = StartStatus::Dropped { round };
            }
            last_round = ranked;
            break;
        }
        for &(k, _) in &ranked[ranked.len().div_ceil(2)..] {
            starts[k].outcome.status = StartStatus::Dropped { round };
        }
        last_round = ranked;
        iterations *= 2;
        round += 1;
    }
    let outcomes: Vec<StartOutcome> = starts.into_iter().map(|x| x.outcome).collect();
    let maxima = local_maxima(model, &outcomes);
    let mut warnings = Vec::new();
    let best = match outcomes
        .iter()
        .find(|o| o.status == StartStatus::Explored && o.loglik.is_some())
    {
        Some(winner) => LocalMaximum {
            estimate: winner.estimate.clone(),
            loglik: winner.loglik.unwrap_or(f64::NEG_INFINITY),
            starts: 1,
        },
        None => {
            // every start ran away or failed: refine the best-scored runaway, if any,
            // and say so (an error would leave the user with nothing to look at)
            let began = Instant::now();
            let runaway = outcomes
                .iter()
                .filter(|o| matches!(o.status, StartStatus::Runaway { .. }))
                .filter_map(|o| score(&o.estimate).map(|l| (o, l)))
                .max_by(|x, y| x.1.total_cmp(&y.1));
            timing.select += began.elapsed();
            let Some((outcome, loglik)) = runaway else {
                let reasons: Vec<String> = outcomes
                    .iter()
                    .enumerate()
                    .map(|(k, o)| format!("start {}: {}", k + 1, describe(&o.status)))
                    .collect();
                return Err(AffineEmError::InvalidParams(format!(
                    "robust EM: no start could be explored ({})",
                    reasons.join("; ")
                )));
            };
            warnings.push(format!(
                "no start explored to the end: every one ran away or failed; the \
                 refinement started from the best runaway by log-likelihood ({loglik:.2}), \
                 whose process noise had grown past {} times its start: check the model \
                 and the start before trusting the estimate",
                options.runaway_factor
            ));
            LocalMaximum {
                estimate: outcome.estimate.clone(),
                loglik,
                starts: 1,
            }
        }
    };
    if let Some(&(k, second)) = last_round.get(1)
        && best.loglik - second < SEPARATION_NATS
        && !same_maximum(model, &outcomes[k].estimate, &best.estimate)
    {
        warnings.push(format!(
            "the chosen start ({:.2}) is not clearly better than the runner-up of the last \
             round ({second:.2}, start {}), which is elsewhere: the data may not tell them \
             apart",
            best.loglik,
            k + 1
        ));
    }
    // refinement: the user's spec, a held noise back at the user's value
    let mut current = best.estimate.clone();
    if spec.pi_x == Covariance::Fixed {
        current.pi_x = start.pi_x.clone();
    }
    if spec.pi_y == Covariance::Fixed {
        current.pi_y = start.pi_y.clone();
    }
    if let Some(constraints) = model.constraints() {
        for &i in &constraints.held_process_variances {
            current.pi_x[(i, i)] = start.pi_x[(i, i)];
        }
        for &j in &constraints.held_measurement_variances {
            current.pi_y[(j, j)] = start.pi_y[(j, j)];
        }
    }
    let began = Instant::now();
    let mut em = AffineEm::new(
        model,
        data,
        options.refine_particles,
        smoother.clone(),
        *spec,
        stream(seed, options.starts as u64).random(),
    )?;
    let mut trace = Vec::with_capacity(options.refine_iterations);
    let mut refine_loglik = Vec::with_capacity(options.refine_iterations);
    let mut overrelaxation = overrelax::Overrelaxation::new();
    let mut extrapolation = Extrapolation::default();
    for iteration in 1..=options.refine_iterations {
        if stop() {
            break;
        }
        match em.step(&current) {
            Ok((next, l)) => {
                trace.push(next.clone());
                refine_loglik.push(l);
                current = next;
                if options.extrapolate
                    && iteration % overrelax::BLOCK == 0
                    && iteration <= options.refine_iterations * 3 / 4
                {
                    let mean = average(&trace[trace.len() - overrelax::BLOCK / 2..]);
                    if let Some(jump) = overrelaxation.propose(model, spec, &mean) {
                        extrapolation.tried += 1;
                        let scored = Instant::now();
                        let gain = score(&jump)
                            .zip(score(&mean))
                            .map_or(f64::NEG_INFINITY, |(a, b)| a - b);
                        timing.select += scored.elapsed();
                        if gain >= overrelax::JUMP_GAIN {
                            overrelaxation.taken(trace.len());
                            extrapolation.taken += 1;
                            extrapolation.last = iteration;
                            current = jump;
                        } else {
                            overrelaxation.refused();
                        }
                    }
                }
            }
            Err(e) if iteration == 1 => return Err(e),
            Err(e) => {
                warnings.push(format!(
                    "the refinement stopped at iteration {iteration}: {e}; the average of \
                     the iterates so far is returned"
                ));
                break;
            }
        }
    }
    timing.refine = began.elapsed();
    let interrupted = stop();
    if interrupted {
        warnings.push(format!(
            "interrupted after {} of {} refinement iterations: the estimate is {}, not the \
             finished fit",
            trace.len(),
            options.refine_iterations,
            if trace.is_empty() {
                "the best start's exploration"
            } else {
                "the average of the refinement so far"
            }
        ));
    }
    // the iterates after the last jump (jumps stop after three quarters: at least the
    // last quarter is plain EM)
    let after_jump = overrelaxation.last_jump.min(trace.len());
    let estimate = if trace.is_empty() {
        best.estimate.clone()
    } else {
        average(&trace[(trace.len() / 2).max(after_jump).min(trace.len() - 1)..])
    };
    let settled = refine_stop(model, &trace[after_jump..]);
    if let RefineStop::StillMoving { change } = settled
        && !interrupted
    {
        warnings.push(format!(
            "the refinement had not settled: a coefficient's average moved by {:.1} % \
             between the last two quarters of its {} iterations (more than {:.1} %); run \
             more iterations",
            100.0 * change,
            trace.len(),
            100.0 * SETTLED
        ));
    }
    let began = Instant::now();
    let loglik = score(&estimate).ok_or_else(|| {
        AffineEmError::InvalidParams("robust EM: the refined estimate cannot be scored".into())
    })?;
    timing.select += began.elapsed();
    if loglik < best.loglik - SEPARATION_NATS {
        warnings.push(format!(
            "the refinement lowered the log-likelihood from {:.2} to {loglik:.2}",
            best.loglik
        ));
    }
    // never an answer worse than a point the exploration scored: EM along a ridge the
    // data cannot see (inseparable parameters) can walk downhill, and a variance can run
    // away
    let (estimate, loglik) = match best_seen {
        Some((seen, seen_loglik, k, round)) if loglik < seen_loglik - SEPARATION_NATS => {
            warnings.push(format!(
                "the fit ended at a log-likelihood of {loglik:.2}, below {seen_loglik:.2}, \
                 which start {} reached in round {round} of the exploration: that point is \
                 returned instead; the iterations lost likelihood, which happens when \
                 parameters cannot be separated or a variance runs away",
                k + 1
            ));
            (seen, seen_loglik)
        }
        _ => (estimate, loglik),
    };
    let (estimate, loglik, loglik_particles, polish) = if options.polish_particles == 0 || stop() {
        (estimate, loglik, options.select_particles, None)
    } else {
        let began = Instant::now();
        let outcome = polished(
            model,
            data,
            &estimate,
            spec,
            options,
            stream(seed, u64::MAX - 1).random(),
            stop,
            &mut warnings,
        );
        timing.polish = began.elapsed();
        match outcome {
            Ok((polished, report)) if report.loglik > report.start_loglik => {
                (polished, report.loglik, report.particles, Some(report))
            }
            Ok((_, report)) => {
                let l = report.start_loglik;
                (estimate, l, report.particles, Some(report))
            }
            // the fit stands without its check: said, not an error
            Err(e) => {
                warnings.push(format!(
                    "the estimate could not be checked by the {}-particle filter ({e}): it \
                     is the EM refinement's, scored by the {}-particle filter",
                    options.polish_particles, options.select_particles
                ));
                (estimate, loglik, options.select_particles, None)
            }
        }
    };
    Ok(RobustFit {
        estimate,
        loglik,
        loglik_particles,
        polish,
        stop: settled,
        selected: best,
        starts: outcomes,
        maxima,
        refine_trace: trace,
        extrapolation,
        refine_loglik,
        warnings,
        timing,
        interrupted,
    })
}

/// Runs the polish and adds its warnings: a budget spent before the simplex converged,
/// a filter too noisy to compare points.
#[allow(clippy::too_many_arguments)]
fn polished<A: AffineModel>(
    model: &A,
    data: Series<'_>,
    estimate: &AffineParams,
    spec: &AffineEmSpec,
    options: &RobustOptions,
    seed: u64,
    stop: &dyn Fn() -> bool,
    warnings: &mut Vec<String>,
) -> Result<(AffineParams, Polish), AffineEmError> {
    let (polished, report) = polish(
        model,
        data,
        estimate,
        spec,
        options.polish_particles,
        options.polish_evaluations,
        seed,
        stop,
    )?;
    if report.interrupted {
        warnings.push(format!(
            "interrupted during the polish after {} filters: the best point so far is \
             returned",
            report.evaluations
        ));
    } else if !report.converged && report.loglik - report.start_loglik > 1.0 {
        warnings.push(format!(
            "the direct maximisation of the {}-particle log-likelihood spent its {} \
             evaluations before converging (it had gained {:.1} nats over the EM \
             estimate): the estimate may still be below the maximum; raise the polish's \
             evaluations",
            report.particles,
            options.polish_evaluations,
            report.loglik - report.start_loglik
        ));
    }
    if report.loglik_sd > LOGLIK_SD_LIMIT {
        warnings.push(format!(
            "the {}-particle filter that scores the estimate has a Monte Carlo sd of {:.2} \
             nats (above {LOGLIK_SD_LIMIT}): it cannot rank nearby points, so the polish may \
             have stopped early or moved by noise; raise the polish's particles",
            report.particles, report.loglik_sd
        ));
    }
    Ok((polished, report))
}

/// The log-likelihood sd (nats) above which the polish's filter is called too noisy.
const LOGLIK_SD_LIMIT: f64 = 1.0;

/// The log-likelihood of the outputs as independent Gaussian noise around each
/// channel's mean (every observed entry): what a model that explains nothing scores.
fn white_noise_loglik(data: &Series<'_>) -> f64 {
    let p = data.output_dim();
    let mut total = 0.0;
    for i in 0..p {
        let values: Vec<f64> = (0..data.steps())
            .map(|t| data.output(t)[i])
            .filter(|v| !v.is_nan())
            .collect();
        let k = values.len() as f64;
        if values.len() < 2 {
            continue;
        }
        let mean = values.iter().sum::<f64>() / k;
        let var = values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / k;
        if var > 0.0 {
            total += -0.5 * k * ((2.0 * std::f64::consts::PI * var).ln() + 1.0);
        }
    }
    total
}

/// `start` with its process noise multiplied by `options.escalation` until the
/// bootstrap filter at `explore_particles` explains the outputs better than white
/// noise (at most `max_escalations` times); returns the start and the count.
fn followable<A: AffineModel>(
    model: &A,
    data: &Series<'_>,
    mut start: AffineParams,
    options: &RobustOptions,
    baseline: f64,
    seed: u64,
) -> (AffineParams, usize) {
    let follows = |params: &AffineParams| -> bool {
        let Ok(smc) = model.smc_model(params) else {
            return true; // not this check's business: the start fails with its reason
        };
        let Ok(mut pass) = ParticlePass::new(options.explore_particles, seed) else {
            return true;
        };
        matches!(pass.loglik(&smc, data, None), Ok(l) if l.is_finite() && l > baseline)
    };
    let mut escalations = 0;
    while escalations < options.max_escalations && !follows(&start) {
        start.pi_x *= options.escalation;
        escalations += 1;
    }
    (start, escalations)
}

/// The state rows' estimated coefficients (structure without the held ones).
fn free_state<A: AffineModel>(model: &A) -> Vec<Vec<usize>> {
    free_structure(&model.state_structure(), &model.held_state_coefficients())
}

/// The output rows' estimated coefficients.
fn free_output<A: AffineModel>(model: &A) -> Vec<Vec<usize>> {
    free_structure(&model.output_structure(), &model.held_output_coefficients())
}

/// A fixed noise covariance is estimated (diagonally) during exploration.
fn explored(covariance: Covariance) -> Covariance {
    match covariance {
        Covariance::Fixed => Covariance::Diagonal,
        other => other,
    }
}

/// Start `k`: the user's (`k = 0`) or a copy with the estimated coefficients
/// perturbed; noise inflated.
fn perturbed<A: AffineModel>(
    model: &A,
    start: &AffineParams,
    spec: &AffineEmSpec,
    options: &RobustOptions,
    k: usize,
    seed: u64,
) -> AffineParams {
    let mut params = start.clone();
    params.pi_x *= options.noise_inflation;
    params.pi_y *= options.noise_inflation;
    if k == 0 {
        return params;
    }
    let mut rng = stream(seed, k as u64);
    let mut shake = |beta: &mut DMatrix<f64>, structure: &[Vec<usize>]| {
        for (row, used) in structure.iter().enumerate() {
            for &j in used {
                beta[(row, j)] *= rng.random_range(1.0 - options.spread..=1.0 + options.spread);
            }
        }
    };
    // only what is estimated: a coefficient the user holds stays at the user's value
    if spec.beta_x {
        shake(&mut params.beta_x, &free_state(model));
    }
    if spec.beta_y {
        shake(&mut params.beta_y, &free_output(model));
    }
    // a shared coefficient moves as one, inside its bounds
    if let Some(constraints) = model.constraints() {
        constraints.project(&mut params);
    }
    params
}

/// One start of the halving: its EM (whose random streams continue across rounds),
/// its current estimate and its recent iterates.
struct Explorer<'a, A: AffineModel, S> {
    em: AffineEm<'a, A, S>,
    current: AffineParams,
    /// Runaway limits of the process-noise variances.
    limits: Vec<f64>,
    outcome: StartOutcome,
}

impl<'a, A: AffineModel, S: Smoother<A::Smc> + Clone> Explorer<'a, A, S> {
    fn new(
        model: &'a A,
        data: Series<'a>,
        start: AffineParams,
        spec: &AffineEmSpec,
        smoother: &S,
        options: &RobustOptions,
        seed: u64,
    ) -> Result<Self, AffineEmError> {
        let em = AffineEm::new(
            model,
            data,
            options.explore_particles,
            smoother.clone(),
            *spec,
            seed,
        )?;
        // the process noise only: the measurement noise jumps at the first iterations
        // of a good start too (the filter is lost there and the outputs look like noise)
        let limits = start
            .pi_x
            .diagonal()
            .iter()
            .map(|v| v * options.runaway_factor)
            .collect();
        Ok(Explorer {
            em,
            current: start.clone(),
            limits,
            outcome: StartOutcome {
                estimate: start.clone(),
                start,
                loglik: None,
                iterations: 0,
                status: StartStatus::Explored,
                noise_escalations: 0,
            },
        })
    }

    /// Runs `iterations` more; the estimate is the average of the last quarter.
    fn advance(&mut self, iterations: usize, options: &RobustOptions, stop: &dyn Fn() -> bool) {
        let mut trace = Vec::with_capacity(iterations);
        for _ in 0..iterations {
            if stop() {
                break;
            }
            match self.em.step(&self.current) {
                Ok((next, _)) => {
                    self.current = next;
                    if self.outcome.iterations < options.hold_output_noise {
                        self.current.pi_y = self.outcome.start.pi_y.clone();
                    }
                }
                Err(e) => {
                    self.outcome.status = StartStatus::Failed(e.to_string());
                    return;
                }
            }
            self.outcome.iterations += 1;
            trace.push(self.current.clone());
            let grown = self
                .current
                .pi_x
                .diagonal()
                .iter()
                .zip(&self.limits)
                .any(|(v, l)| v > l);
            if self.outcome.iterations >= options.runaway_after && grown {
                self.outcome.estimate = self.current.clone();
                self.outcome.status = StartStatus::Runaway {
                    iteration: self.outcome.iterations,
                };
                return;
            }
        }
        if trace.is_empty() {
            // stopped before this round's first iteration: the estimate so far stands
            self.outcome.estimate = self.current.clone();
            return;
        }
        let tail = trace.len() - (trace.len() / 4).max(1);
        self.outcome.estimate = average(&trace[tail..]);
    }
}

/// The entry-wise average of parameter sets (each a valid set, so the average is: the
/// covariances' average is PSD).
fn average(sets: &[AffineParams]) -> AffineParams {
    let mut sum = sets[0].clone();
    for p in &sets[1..] {
        sum.beta_x += &p.beta_x;
        sum.beta_y += &p.beta_y;
        sum.pi_x += &p.pi_x;
        sum.pi_y += &p.pi_y;
        sum.mu += &p.mu;
        sum.p1 += &p.p1;
    }
    let n = sets.len() as f64;
    AffineParams {
        beta_x: sum.beta_x / n,
        beta_y: sum.beta_y / n,
        pi_x: sum.pi_x / n,
        pi_y: sum.pi_y / n,
        mu: sum.mu / n,
        p1: sum.p1 / n,
    }
}

/// Whether two estimates agree within [`SAME_MAXIMUM`] in every free coefficient.
fn same_maximum<A: AffineModel>(model: &A, a: &AffineParams, b: &AffineParams) -> bool {
    let close = |x: f64, y: f64| (x - y).abs() <= SAME_MAXIMUM * x.abs().max(y.abs());
    let block = |ba: &DMatrix<f64>, bb: &DMatrix<f64>, structure: &[Vec<usize>]| {
        structure
            .iter()
            .enumerate()
            .all(|(row, used)| used.iter().all(|&j| close(ba[(row, j)], bb[(row, j)])))
    };
    block(&a.beta_x, &b.beta_x, &free_state(model))
        && block(&a.beta_y, &b.beta_y, &free_output(model))
}

/// Whether the refinement's iterates settled (see [`RefineStop`]).
fn refine_stop<A: AffineModel>(model: &A, trace: &[AffineParams]) -> RefineStop {
    let quarter = trace.len() / 4;
    if quarter == 0 {
        return RefineStop::StillMoving {
            change: f64::INFINITY,
        };
    }
    let third = average(&trace[trace.len() - 2 * quarter..trace.len() - quarter]);
    let fourth = average(&trace[trace.len() - quarter..]);
    let mut change: f64 = 0.0;
    for (a, b, structure) in [
        (&third.beta_x, &fourth.beta_x, free_state(model)),
        (&third.beta_y, &fourth.beta_y, free_output(model)),
    ] {
        for (row, used) in structure.iter().enumerate() {
            for &j in used {
                let (x, y) = (a[(row, j)], b[(row, j)]);
                let scale = x.abs().max(y.abs());
                if scale > 0.0 {
                    change = change.max((x - y).abs() / scale);
                }
            }
        }
    }
    if change < SETTLED {
        RefineStop::Settled { change }
    } else {
        RefineStop::StillMoving { change }
    }
}

/// The scored starts grouped into local maxima, best first.
fn local_maxima<A: AffineModel>(model: &A, outcomes: &[StartOutcome]) -> Vec<LocalMaximum> {
    let mut scored: Vec<(&AffineParams, f64)> = outcomes
        .iter()
        .filter_map(|o| o.loglik.map(|l| (&o.estimate, l)))
        .collect();
    scored.sort_by(|x, y| y.1.total_cmp(&x.1));
    let mut maxima: Vec<LocalMaximum> = Vec::new();
    for (estimate, loglik) in scored {
        match maxima
            .iter_mut()
            .find(|m| same_maximum(model, &m.estimate, estimate))
        {
            Some(m) => m.starts += 1,
            None => maxima.push(LocalMaximum {
                estimate: estimate.clone(),
                loglik,
                starts: 1,
            }),
        }
    }
    maxima
}

/// A status in a few words.
pub fn describe(status: &StartStatus) -> String {
    match status {
        StartStatus::Explored => "explored".into(),
        StartStatus::Dropped { round } => format!("dropped after round {round}"),
        StartStatus::Runaway { iteration } => format!("runaway at iteration {iteration}"),
        StartStatus::Failed(e) => format!("failed: {e}"),
    }
}
