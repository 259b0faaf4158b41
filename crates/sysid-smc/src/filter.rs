//! The bootstrap particle filter.
//!
//! # Model
//! Any [`FilterModel`]: `x_0 ~ mu`, `x_{t+1} ~ f(. | x_t)`,
//! `y_t ~ g(. | x_t)`.
//!
//! # Algorithm
//! Propagate each particle through `f`, weight by `g(y_t | x_t)` in the log domain,
//! normalise with log-sum-exp, and resample when the effective sample size
//! `1 / sum W^2` falls below `ess_threshold * M` (a threshold of 1 resamples at every
//! step, the papers' choice). The log-likelihood estimate is
//! `log p(y_{0:T-1}) = sum_t log sum_i W_{t-1}^i g(y_t | x_t^i)` with `W_{t-1}` the
//! normalised weights carried into step `t` (uniform after a resampling), so it stays
//! correct when resampling is skipped; its exponential is unbiased for `p(y)`.
//! Steps whose outputs are all missing leave the weights unchanged.
//!
//! Particles are processed in fixed chunks of [`CHUNK`] particles, chunk `c` drawing
//! from the random stream `(seed, c + 1)` and resampling from stream `(seed, 0)`, so
//! the result is the same with any number of threads, in parallel or not.
//!
//! # Complexity
//! O(T M) time; O(M) memory, plus O(T M) for the stored history.
//!
//! # Example
//! ```
//! use sysid_smc::{FilterOptions, ParticleFilter, Series};
//! # use sysid_smc::{StateSpace, InitialSampler, TransitionSampler, ObservationDensity};
//! # use rand_distr::{Distribution, StandardNormal};
//! # struct RandomWalk;
//! # impl StateSpace for RandomWalk { fn state_dim(&self) -> usize { 1 } }
//! # impl InitialSampler for RandomWalk {
//! #     fn sample_initial<R: rand::Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
//! #         x[0] = StandardNormal.sample(rng);
//! #     }
//! # }
//! # impl TransitionSampler for RandomWalk {
//! #     fn sample_transition<R: rand::Rng + ?Sized>(&self, _: usize, x: &[f64], _: &[f64], next: &mut [f64], rng: &mut R) {
//! #         let w: f64 = StandardNormal.sample(rng);
//! #         next[0] = x[0] + w;
//! #     }
//! # }
//! # impl ObservationDensity for RandomWalk {
//! #     fn log_observation(&self, _: usize, x: &[f64], _: &[f64], y: &[f64]) -> f64 {
//! #         -0.5 * (y[0] - x[0]).powi(2) - 0.5 * (2.0 * std::f64::consts::PI).ln()
//! #     }
//! # }
//! let y = [0.3, 0.1, -0.4, 0.2];
//! let data = Series::new(&y, 1).unwrap();
//! let mut pf = ParticleFilter::new(FilterOptions { particles: 500, ..Default::default() }).unwrap();
//! let run = pf.run(&RandomWalk, &data, 42).unwrap();
//! assert!(run.loglik.is_finite());
//! assert_eq!(pf.means().len(), 4);
//! ```
//!
//! # References
//! Gordon, Salmond and Smith (1993); Schön, Wills and Ninness (2006), Algorithm 3.

use rayon::prelude::*;

use crate::model::FilterModel;
use crate::resample::{ResampleScratch, Resampling};
use crate::simd::Kernel;
use crate::streams::{Rng, stream};
use crate::weights::{effective_sample_size, normalise_log_weights};
use crate::{History, Series, SmcError};

/// Particles per random stream (and per parallel task).
pub const CHUNK: usize = 1024;

/// Settings of the bootstrap particle filter.
#[derive(Debug, Clone, PartialEq)]
pub struct FilterOptions {
    /// Number of particles M (>= 1). Default 1000.
    pub particles: usize,
    /// Resampling scheme. Default systematic.
    pub resampling: Resampling,
    /// Resample when ESS < `ess_threshold * M`; in (0, 1], and 1 resamples at every
    /// step. Default 1.
    pub ess_threshold: f64,
    /// Keep particles, weights and ancestors for the smoothers. Default false.
    pub store_history: bool,
    /// Run the particle chunks in parallel on the current rayon pool. The result does
    /// not depend on it. Default false.
    pub parallel: bool,
    /// Record the filtered mean and the effective sample size of every step
    /// ([`ParticleFilter::means`], [`ParticleFilter::ess`]). Default true. Estimators
    /// that need only the log-likelihood (PMMH) switch it off, which saves two passes
    /// over the weights per step; the log-likelihood and the history do not change.
    pub record_summaries: bool,
}

impl Default for FilterOptions {
    fn default() -> Self {
        FilterOptions {
            particles: 1000,
            resampling: Resampling::Systematic,
            ess_threshold: 1.0,
            store_history: false,
            parallel: false,
            record_summaries: true,
        }
    }
}

impl FilterOptions {
    /// Checks the ranges of the options.
    pub fn check(&self) -> Result<(), SmcError> {
        if self.particles == 0 {
            return Err(SmcError::InvalidOption {
                name: "particles",
                reason: "must be at least 1".into(),
            });
        }
        if !(self.ess_threshold > 0.0 && self.ess_threshold <= 1.0) {
            return Err(SmcError::InvalidOption {
                name: "ess_threshold",
                reason: format!("{} is not in (0, 1]", self.ess_threshold),
            });
        }
        Ok(())
    }
}

/// Summary of one filter run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterSummary {
    /// The log-likelihood estimate `log p^(y)`.
    pub loglik: f64,
    /// Number of steps after which the filter resampled.
    pub resampled_steps: usize,
}

/// A bootstrap particle filter with its reusable buffers (the workspace).
///
/// See the [module documentation](self) for the algorithm.
#[derive(Debug, Clone)]
pub struct ParticleFilter {
    options: FilterOptions,
    states: Vec<f64>,
    previous: Vec<f64>,
    log_obs: Vec<f64>,
    log_weights: Vec<f64>,
    weights: Vec<f64>,
    ancestors: Vec<usize>,
    identity: Vec<usize>,
    scratch: ResampleScratch,
    rngs: Vec<Rng>,
    means: Vec<f64>,
    ess: Vec<f64>,
    history: History,
    has_history: bool,
}

impl ParticleFilter {
    /// A filter with checked options.
    pub fn new(options: FilterOptions) -> Result<Self, SmcError> {
        options.check()?;
        Ok(ParticleFilter {
            options,
            states: Vec::new(),
            previous: Vec::new(),
            log_obs: Vec::new(),
            log_weights: Vec::new(),
            weights: Vec::new(),
            ancestors: Vec::new(),
            identity: Vec::new(),
            scratch: ResampleScratch::default(),
            rngs: Vec::new(),
            means: Vec::new(),
            ess: Vec::new(),
            history: History::default(),
            has_history: false,
        })
    }

    /// The options.
    pub fn options(&self) -> &FilterOptions {
        &self.options
    }

    /// The filtered means `sum_i W_t^i x_t^i` of the last run, time-major (T x n);
    /// empty when [`FilterOptions::record_summaries`] is off.
    pub fn means(&self) -> &[f64] {
        &self.means
    }

    /// The effective sample size at each step of the last run (before resampling);
    /// empty when [`FilterOptions::record_summaries`] is off.
    pub fn ess(&self) -> &[f64] {
        &self.ess
    }

    /// The stored history of the last run, if `store_history` was set.
    pub fn history(&self) -> Option<&History> {
        self.has_history.then_some(&self.history)
    }

    /// Runs the filter on `data` with the random streams of `seed`.
    pub fn run<M: FilterModel + Sync>(
        &mut self,
        model: &M,
        data: &Series,
        seed: u64,
    ) -> Result<FilterSummary, SmcError> {
        crate::simd::dispatch(RunKernel {
            filter: self,
            model,
            data,
            seed,
        })
    }

    #[inline(always)]
    fn run_kernel<M: FilterModel + Sync>(
        &mut self,
        model: &M,
        data: &Series,
        seed: u64,
    ) -> Result<FilterSummary, SmcError> {
        let n = model.state_dim();
        let m = self.options.particles;
        let steps = data.steps();
        self.prepare(n, m, steps, seed);
        let uniform_log_weight = -(m as f64).ln();
        self.log_weights.fill(uniform_log_weight);
        let mut loglik = 0.0;
        let mut resampled_steps = 0;
        let mut resample_rng = stream(seed, 0);
        for t in 0..steps {
            self.propagate_and_weigh(model, data, t);
            let increment = self.reweight(t, data.is_missing(t))?;
            loglik += increment;
            let ess = self.record(n);
            if t + 1 < steps {
                if self.options.ess_threshold >= 1.0 || ess < self.options.ess_threshold * m as f64
                {
                    self.options.resampling.resample(
                        &self.weights,
                        &mut resample_rng,
                        &mut self.ancestors,
                        &mut self.scratch,
                    );
                    self.log_weights.fill(uniform_log_weight);
                    resampled_steps += 1;
                    if self.options.store_history {
                        self.history.mark_resampled(t);
                    }
                } else {
                    self.ancestors.copy_from_slice(&self.identity);
                }
                std::mem::swap(&mut self.states, &mut self.previous);
            }
        }
        Ok(FilterSummary {
            loglik,
            resampled_steps,
        })
    }

    fn prepare(&mut self, n: usize, m: usize, steps: usize, seed: u64) {
        self.states.resize(m * n, 0.0);
        self.previous.resize(m * n, 0.0);
        self.log_obs.resize(m, 0.0);
        self.log_weights.resize(m, 0.0);
        self.weights.resize(m, 0.0);
        self.identity.clear();
        self.identity.extend(0..m);
        self.ancestors.clear();
        self.ancestors.extend(0..m);
        let chunks = m.div_ceil(CHUNK);
        self.rngs.clear();
        self.rngs
            .extend((0..chunks).map(|c| stream(seed, c as u64 + 1)));
        self.means.clear();
        self.means.reserve(steps * n);
        self.ess.clear();
        self.ess.reserve(steps);
        self.has_history = self.options.store_history;
        if self.has_history {
            self.history.reset(n, m, steps);
        }
    }

    #[inline(always)]
    /// Draws `x_t` (from `mu` at `t = 0`, else from `f` given the resampled `x_{t-1}`)
    /// and evaluates `log g(y_t | x_t)`, chunk by chunk.
    fn propagate_and_weigh<M: FilterModel + Sync>(&mut self, model: &M, data: &Series, t: usize) {
        let n = model.state_dim();
        let step = StepInputs {
            model,
            data,
            t,
            missing: data.is_missing(t),
            previous: &self.previous,
            ancestors: &self.ancestors,
        };
        if self.options.parallel && self.rngs.len() > 1 {
            // A closure is compiled for the baseline target: dispatch again inside it so
            // that each chunk runs the vector kernels of this CPU.
            self.states
                .par_chunks_mut(CHUNK * n)
                .zip(self.log_obs.par_chunks_mut(CHUNK))
                .zip(self.rngs.par_iter_mut())
                .enumerate()
                .for_each(|(chunk, ((states, log_obs), rng))| {
                    crate::simd::dispatch(ChunkKernel {
                        step: &step,
                        chunk,
                        states,
                        log_obs,
                        rng,
                    })
                });
        } else {
            let chunks = self
                .states
                .chunks_mut(CHUNK * n)
                .zip(self.log_obs.chunks_mut(CHUNK))
                .zip(self.rngs.iter_mut());
            for (chunk, ((states, log_obs), rng)) in chunks.enumerate() {
                ChunkKernel {
                    step: &step,
                    chunk,
                    states,
                    log_obs,
                    rng,
                }
                .run();
            }
        }
    }

    #[inline(always)]
    /// Adds the observation log-densities to the carried log-weights, normalises, and
    /// returns the log-likelihood increment.
    fn reweight(&mut self, t: usize, missing: bool) -> Result<f64, SmcError> {
        if missing {
            // Weights carry over unchanged (already normalised).
            for (w, &l) in self.weights.iter_mut().zip(&self.log_weights) {
                *w = l.exp();
            }
            return Ok(0.0);
        }
        for (l, &lg) in self.log_weights.iter_mut().zip(&self.log_obs) {
            *l += lg;
        }
        let increment = normalise_log_weights(&self.log_weights, &mut self.weights)
            .unwrap_or(f64::NEG_INFINITY);
        if !increment.is_finite() {
            if increment == f64::NEG_INFINITY && !self.log_obs.iter().any(|v| v.is_nan()) {
                return Err(SmcError::DegenerateWeights { t });
            }
            // A NaN or +inf observation log-density (found only on this slow path).
            let (particle, &value) = self
                .log_obs
                .iter()
                .enumerate()
                .find(|(_, v)| v.is_nan() || **v == f64::INFINITY)
                .unwrap_or((0, &increment));
            return Err(SmcError::InvalidDensity {
                what: "observation log-density",
                t,
                particle,
                value,
            });
        }
        for l in self.log_weights.iter_mut() {
            *l -= increment;
        }
        Ok(increment)
    }

    #[inline(always)]
    /// Stores the filtered mean and the ESS (with `record_summaries`) and the history
    /// (with `store_history`) of step `t`; returns the ESS, or NaN when it is neither
    /// recorded nor needed (resampling at every step).
    fn record(&mut self, n: usize) -> f64 {
        let adaptive = self.options.ess_threshold < 1.0;
        let ess = if self.options.record_summaries || adaptive {
            effective_sample_size(&self.weights)
        } else {
            f64::NAN // not needed: the filter resamples at every step
        };
        if self.options.record_summaries {
            let start = self.means.len();
            self.means.resize(start + n, 0.0);
            weighted_mean(&self.states, &self.weights, &mut self.means[start..]);
            self.ess.push(ess);
        }
        if self.has_history {
            self.history.push(
                &self.states,
                &self.weights,
                &self.log_weights,
                &self.ancestors,
            );
        }
        ess
    }
}

/// What every chunk of step `t` shares.
struct StepInputs<'a, 's, M> {
    model: &'a M,
    data: &'a Series<'s>,
    t: usize,
    missing: bool,
    previous: &'a [f64],
    ancestors: &'a [usize],
}

/// One chunk's work at a step: draw its particles and evaluate their observation
/// log-densities. A [`Kernel`], so that the parallel path can dispatch each chunk.
struct ChunkKernel<'k, 'a, 's, M> {
    step: &'k StepInputs<'a, 's, M>,
    chunk: usize,
    states: &'k mut [f64],
    log_obs: &'k mut [f64],
    rng: &'k mut Rng,
}

impl<M: FilterModel> Kernel for ChunkKernel<'_, '_, '_, M> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        let StepInputs {
            model,
            data,
            t,
            missing,
            previous,
            ancestors,
        } = *self.step;
        if t == 0 {
            model.sample_initials(self.states, self.rng);
        } else {
            let first = self.chunk * CHUNK;
            let parents = &ancestors[first..first + self.log_obs.len()];
            model.sample_transitions(
                t - 1,
                data.input(t - 1),
                previous,
                parents,
                self.states,
                self.rng,
            );
        }
        if missing {
            self.log_obs.fill(0.0);
        } else {
            model.log_observations(t, data.input(t), data.output(t), self.states, self.log_obs);
        }
    }
}

struct RunKernel<'f, 'm, 'd, 's, M> {
    filter: &'f mut ParticleFilter,
    model: &'m M,
    data: &'d Series<'s>,
    seed: u64,
}

impl<M: FilterModel + Sync> Kernel for RunKernel<'_, '_, '_, '_, M> {
    type Output = Result<FilterSummary, SmcError>;

    #[inline(always)]
    fn run(self) -> Self::Output {
        self.filter.run_kernel(self.model, self.data, self.seed)
    }
}

#[inline(always)]
/// `out = sum_i w_i x_i` over particle-major `states`, with four interleaved partial
/// sums per coordinate (a fixed order, so the result is reproducible).
fn weighted_mean(states: &[f64], weights: &[f64], out: &mut [f64]) {
    let n = out.len();
    if n == 1 {
        let mut acc = [0.0f64; 4];
        let mut chunks = states.chunks_exact(4).zip(weights.chunks_exact(4));
        for (x, w) in &mut chunks {
            for k in 0..4 {
                acc[k] += w[k] * x[k];
            }
        }
        let done = (weights.len() / 4) * 4;
        let tail: f64 = states[done..]
            .iter()
            .zip(&weights[done..])
            .map(|(x, w)| x * w)
            .sum();
        out[0] = (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail;
        return;
    }
    let mut partial = [[0.0f64; 4]; MEAN_DIM_LIMIT];
    if n > MEAN_DIM_LIMIT {
        out.fill(0.0);
        for (x, &w) in states.chunks_exact(n).zip(weights) {
            for (acc, &xi) in out.iter_mut().zip(x) {
                *acc += w * xi;
            }
        }
        return;
    }
    let mut groups = states.chunks_exact(4 * n).zip(weights.chunks_exact(4));
    for (x, w) in &mut groups {
        for (lane, (&wl, xl)) in w.iter().zip(x.chunks_exact(n)).enumerate() {
            for (d, &xi) in xl.iter().enumerate() {
                partial[d][lane] += wl * xi;
            }
        }
    }
    let done = (weights.len() / 4) * 4;
    for (x, &w) in states[done * n..].chunks_exact(n).zip(&weights[done..]) {
        for (d, &xi) in x.iter().enumerate() {
            partial[d][0] += w * xi;
        }
    }
    for (d, o) in out.iter_mut().enumerate() {
        let p = partial[d];
        *o = (p[0] + p[1]) + (p[2] + p[3]);
    }
}

/// State dimensions up to which the filtered mean uses interleaved partial sums.
const MEAN_DIM_LIMIT: usize = 16;
