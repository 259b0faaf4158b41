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
//! from the random stream `(seed, c + 1)` and resampling from stream `(seed, 0)`. Each
//! step runs in three phases over the chunks: propagate and weigh (with each chunk's
//! largest log-weight), exponentiate (each chunk's sum, and the running sums of
//! systematic resampling), and normalise (each chunk's sum of squares and weighted
//! mean, and its share of the systematic ancestors; see [`crate::resample::systematic`]).
//! Between phases the chunk results are combined in chunk order. With M <= [`CHUNK`]
//! this is the plain whole-array computation; for any M the result is the same with
//! any number of threads.
//!
//! With [`FilterOptions::parallel`], a team of threads shares the chunks of every
//! phase. The team lives for the whole run and its helpers wait for the next phase by
//! spinning: a step at M = 10 000 is tens of microseconds, less than a rayon fork-join
//! costs to wake a sleeping worker on a small machine. Resampling schemes other than
//! systematic, and ESS-adaptive resampling, run on the leading thread.
//!
//! # Complexity
//! O(T M) time; O(M) memory, plus O(T M) for the stored history. In parallel, three
//! handshakes among the threads per step.
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

use rand::RngExt;

use crate::model::FilterModel;
use crate::resample::{ResampleScratch, Resampling};
use crate::simd::Kernel;
use crate::streams::{Rng, stream};
use crate::systematic::{
    BlockPlan, BlockSums, Marks, block_running_sums, last_positive, mark_block, plan_blocks,
};
use crate::team::Team;
use crate::variance::GenealogyVariance;
use crate::vexp::exp_shifted_sum;
use crate::weights::{max_value, sum_of_squares};
use crate::{History, Series, SmcError};

/// Particles per random stream (and per share of a thread), also the block of
/// systematic resampling's running sums.
pub const CHUNK: usize = crate::systematic::BLOCK;

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
    /// Share the particle chunks of every step among as many threads as the current
    /// rayon pool has (at most one per chunk of [`CHUNK`] particles). The result does
    /// not depend on it. Pays from a few chunks up (M = 10 000 on two threads: about 1.6x);
    /// leave it off when independent runs already fill the cores. Default false.
    pub parallel: bool,
    /// With `parallel`, use every thread of the pool even when the machine's
    /// processors are busy. Default false: the team is only as large as the processors
    /// free when the run starts (on Linux; elsewhere the pool's size), because a
    /// helper sharing a processor with another process made the filter slower than
    /// one thread (M = 10 000 on two processors, one busy: 1.4 to 6 times). Tests of
    /// the team set it.
    pub share_busy_processors: bool,
    /// Record the filtered mean and the effective sample size of every step
    /// ([`ParticleFilter::means`], [`ParticleFilter::ess`]). Default true. Estimators
    /// that need only the log-likelihood (PMMH) switch it off, which saves two passes
    /// over the weights per step; the log-likelihood and the history do not change.
    pub record_summaries: bool,
    /// Estimate the Monte Carlo variance of the log-likelihood from this run's
    /// genealogy, in spans of this many steps ([`FilterSummary::loglik_variance`],
    /// `variance.rs`). Default `None`: the estimate costs two index gathers per step.
    pub variance_block: Option<usize>,
}

impl Default for FilterOptions {
    fn default() -> Self {
        FilterOptions {
            particles: 1000,
            resampling: Resampling::Systematic,
            ess_threshold: 1.0,
            store_history: false,
            parallel: false,
            share_busy_processors: false,
            record_summaries: true,
            variance_block: None,
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
    /// The single-run estimate of `Var(loglik)` (with
    /// [`FilterOptions::variance_block`]).
    pub loglik_variance: Option<f64>,
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
    next_ancestors: Vec<usize>,
    identity: Vec<usize>,
    running_sums: Vec<f64>,
    chunk_sums: Vec<ChunkSums>,
    chunk_means: Vec<f64>,
    plan: Vec<BlockPlan>,
    scratch: ResampleScratch,
    rngs: Vec<Rng>,
    means: Vec<f64>,
    ess: Vec<f64>,
    history: History,
    has_history: bool,
    variance: GenealogyVariance,
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
            next_ancestors: Vec::new(),
            identity: Vec::new(),
            running_sums: Vec::new(),
            chunk_sums: Vec::new(),
            chunk_means: Vec::new(),
            plan: Vec::new(),
            scratch: ResampleScratch::default(),
            rngs: Vec::new(),
            means: Vec::new(),
            ess: Vec::new(),
            history: History::default(),
            has_history: false,
            variance: GenealogyVariance::default(),
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
    ///
    /// With [`FilterOptions::parallel`], the chunks of every step are shared among a
    /// team of as many threads as the current rayon pool has (at most one per chunk),
    /// kept for the whole run; the result is the same bit for bit.
    pub fn run<M: FilterModel + Sync>(
        &mut self,
        model: &M,
        data: &Series,
        seed: u64,
    ) -> Result<FilterSummary, SmcError> {
        self.prepare(model.state_dim(), data.steps(), seed);
        // a helper without a processor of its own slows the team down (another
        // process, or the caller's other threads, e.g. parallel PMMH chains, are busy):
        // the team is only as large as the processors free now
        let members = if self.options.parallel && self.rngs.len() > 1 {
            // (looked at before rayon's pool is touched: a pool that starts now has
            // its threads running for a moment)
            let free = if self.options.share_busy_processors {
                usize::MAX
            } else {
                crate::busy::free_processors().unwrap_or(usize::MAX)
            };
            rayon::current_num_threads().min(self.rngs.len()).min(free)
        } else {
            1
        };
        if members <= 1 {
            return crate::simd::dispatch(RunKernel {
                filter: self,
                model,
                data,
                seed,
                team: None,
            });
        }
        let team = Team::new();
        std::thread::scope(|scope| {
            for _ in 1..members {
                let team = &team;
                scope.spawn(move || {
                    team.serve(|command: Command, chunk| {
                        // SAFETY: this member claimed the chunk: until the leader's
                        // `run` returns it alone touches the chunk's entries (see
                        // `SharedBuffers`)
                        unsafe { command.run_chunks(model, data, (chunk, chunk + 1), true) }
                    })
                });
            }
            let _stop = team.stop_on_drop();
            // (the leader's steps are dispatched to this CPU's vector set: a closure
            // body is compiled for the baseline target)
            crate::simd::dispatch(RunKernel {
                filter: self,
                model,
                data,
                seed,
                team: Some(&team),
            })
        })
    }

    #[inline(always)]
    fn run_steps<M: FilterModel>(
        &mut self,
        model: &M,
        data: &Series,
        seed: u64,
        team: Option<&Team<Command>>,
    ) -> Result<FilterSummary, SmcError> {
        let n = model.state_dim();
        let m = self.options.particles;
        let steps = data.steps();
        let always = self.options.ess_threshold >= 1.0;
        let blocked_systematic = always && self.options.resampling == Resampling::Systematic;
        let summaries = self.options.record_summaries || !always;
        let uniform_log_weight = -(m as f64).ln();
        self.log_weights.fill(uniform_log_weight);
        let mut reset_log_weight = None;
        let mut loglik = 0.0;
        let mut resampled_steps = 0;
        let mut resample_rng = stream(seed, 0);
        for t in 0..steps {
            let more = t + 1 < steps;
            let propagate = Phase::Propagate {
                t,
                reset_log_weight,
            };
            self.execute(model, data, propagate, team);
            let running_sums = blocked_systematic && more;
            let normalisation = self.exponentiate(model, data, t, running_sums, team)?;
            if let Some((_, increment)) = normalisation {
                loglik += increment;
            }
            let marks = running_sums.then(|| self.plan_systematic(resample_rng.random()));
            let normalise = Phase::Normalise {
                normalisation,
                square_sums: summaries,
                means: self.options.record_summaries,
                marks,
            };
            self.execute(model, data, normalise, team);
            let ess = self.record(n, summaries);
            if self.options.variance_block.is_some() {
                self.variance.observe(t, &self.weights);
            }
            reset_log_weight = None;
            if more {
                let resample = always || ess < self.options.ess_threshold * m as f64;
                if marks.is_some() {
                    std::mem::swap(&mut self.ancestors, &mut self.next_ancestors);
                } else if resample {
                    self.options.resampling.resample(
                        &self.weights,
                        &mut resample_rng,
                        &mut self.ancestors,
                        &mut self.scratch,
                    );
                } else {
                    self.ancestors.copy_from_slice(&self.identity);
                }
                if self.options.variance_block.is_some() {
                    self.variance.advance(&self.ancestors);
                }
                if resample {
                    reset_log_weight = Some(uniform_log_weight);
                    resampled_steps += 1;
                    if self.options.store_history {
                        self.history.mark_resampled(t);
                    }
                }
                std::mem::swap(&mut self.states, &mut self.previous);
            }
        }
        let loglik_variance = self
            .options
            .variance_block
            .map(|_| self.variance.finish(&self.weights));
        Ok(FilterSummary {
            loglik,
            resampled_steps,
            loglik_variance,
        })
    }

    fn prepare(&mut self, n: usize, steps: usize, seed: u64) {
        let m = self.options.particles;
        let chunks = m.div_ceil(CHUNK);
        self.states.resize(m * n, 0.0);
        self.previous.resize(m * n, 0.0);
        self.log_obs.resize(m, 0.0);
        self.log_weights.resize(m, 0.0);
        self.weights.resize(m, 0.0);
        self.running_sums.resize(m, 0.0);
        self.identity.clear();
        self.identity.extend(0..m);
        self.ancestors.clear();
        self.ancestors.extend(0..m);
        self.next_ancestors.resize(m, 0);
        self.chunk_sums.resize(chunks, ChunkSums::default());
        self.chunk_means.resize(chunks * n, 0.0);
        self.rngs.clear();
        self.rngs
            .extend((0..chunks).map(|c| stream(seed, c as u64 + 1)));
        self.means.clear();
        self.means.reserve(steps * n);
        self.ess.clear();
        self.ess.reserve(steps);
        if let Some(block) = self.options.variance_block {
            self.variance.start(block, m);
        }
        self.has_history = self.options.store_history;
        if self.has_history {
            self.history.reset(n, m, steps);
        }
    }

    /// Runs one phase of a step on every chunk: shared with the team when there is
    /// one (the leader takes the first share), else chunk by chunk on this thread.
    #[inline(always)]
    fn execute<M: FilterModel>(
        &mut self,
        model: &M,
        data: &Series,
        phase: Phase,
        team: Option<&Team<Command>>,
    ) {
        let command = Command {
            phase,
            buffers: self.shared_buffers(),
        };
        let chunks = command.buffers.chunks;
        match team {
            Some(team) => {
                // SAFETY: until `run` returns, every member touches only the chunks it
                // claimed, and the leader touches the buffers only through `command`
                team.run(command, chunks, |command, chunk| unsafe {
                    command.run_chunks(model, data, (chunk, chunk + 1), false)
                });
            }
            // SAFETY: no other thread holds the buffers
            None => unsafe { command.run_chunks(model, data, (0, chunks), false) },
        }
    }

    /// The buffers of the current step as raw parts, for [`Self::execute`].
    fn shared_buffers(&mut self) -> SharedBuffers {
        SharedBuffers {
            state_dim: self.states.len() / self.options.particles,
            particles: self.options.particles,
            chunks: self.rngs.len(),
            states: self.states.as_mut_ptr(),
            previous: self.previous.as_ptr(),
            log_obs: self.log_obs.as_mut_ptr(),
            log_weights: self.log_weights.as_mut_ptr(),
            weights: self.weights.as_mut_ptr(),
            running_sums: self.running_sums.as_mut_ptr(),
            ancestors: self.ancestors.as_ptr(),
            next_ancestors: self.next_ancestors.as_mut_ptr(),
            rngs: self.rngs.as_mut_ptr(),
            chunk_sums: self.chunk_sums.as_mut_ptr(),
            chunk_means: self.chunk_means.as_mut_ptr(),
            plan: self.plan.as_ptr(),
        }
    }

    /// Exponentiates the log-weights shifted by their maximum and returns the scale
    /// that normalises them and the log-likelihood increment `log sum_i W_{t-1}^i g_i`;
    /// at a step whose outputs are missing, exponentiates the (normalised) log-weights
    /// as they are and returns None.
    #[inline(always)]
    fn exponentiate<M: FilterModel>(
        &mut self,
        model: &M,
        data: &Series,
        t: usize,
        running_sums: bool,
        team: Option<&Team<Command>>,
    ) -> Result<Option<(f64, f64)>, SmcError> {
        let shift = if data.is_missing(t) {
            None
        } else {
            // (the maximum of the chunk maxima is the maximum, in any order)
            let max = self
                .chunk_sums
                .iter()
                .fold(f64::NEG_INFINITY, |m, s| if s.max > m { s.max } else { m });
            if max == f64::NEG_INFINITY {
                return Err(self.density_error(t, max));
            }
            Some(max)
        };
        let phase = Phase::Exponentiate {
            shift,
            running_sums,
        };
        self.execute(model, data, phase, team);
        let Some(max) = shift else {
            return Ok(None);
        };
        let total = in_chunk_order(&self.chunk_sums, |s| s.exp_sum);
        let increment = max + total.ln();
        if !increment.is_finite() {
            return Err(self.density_error(t, increment));
        }
        Ok(Some((1.0 / total, increment)))
    }

    /// Why the log-likelihood increment of step `t` is not finite.
    fn density_error(&self, t: usize, increment: f64) -> SmcError {
        if increment == f64::NEG_INFINITY && !self.log_obs.iter().any(|v| v.is_nan()) {
            return SmcError::DegenerateWeights { t };
        }
        // A NaN or +inf observation log-density (found only on this slow path).
        let (particle, &value) = self
            .log_obs
            .iter()
            .enumerate()
            .find(|(_, v)| v.is_nan() || **v == f64::INFINITY)
            .unwrap_or((0, &increment));
        SmcError::InvalidDensity {
            what: "observation log-density",
            t,
            particle,
            value,
        }
    }

    /// Plans systematic resampling by blocks from the chunks' running sums, with the
    /// uniform `u`.
    fn plan_systematic(&mut self, u: f64) -> SystematicMarks {
        let last = last_positive(&self.weights);
        let marks = plan_blocks(
            &self.weights,
            self.chunk_sums.iter().map(|s| s.running),
            CHUNK,
            u,
            self.options.particles,
            last,
            &mut self.plan,
        );
        SystematicMarks { marks, last }
    }

    /// Combines the chunks' summaries of step `t`: stores the filtered mean and the ESS
    /// (with `record_summaries`) and the history (with `store_history`); returns the
    /// ESS, or NaN when it is neither recorded nor needed (resampling at every step).
    #[inline(always)]
    fn record(&mut self, n: usize, summaries: bool) -> f64 {
        let ess = if summaries {
            1.0 / in_chunk_order(&self.chunk_sums, |s| s.square_sum)
        } else {
            f64::NAN
        };
        if self.options.record_summaries {
            let start = self.means.len();
            self.means.extend_from_slice(&self.chunk_means[..n]);
            for chunk in self.chunk_means.chunks_exact(n).skip(1) {
                for (mean, &part) in self.means[start..].iter_mut().zip(chunk) {
                    *mean += part;
                }
            }
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

/// The sum of one value of every chunk, in chunk order (the first value as is).
#[inline(always)]
fn in_chunk_order(sums: &[ChunkSums], value: impl Fn(&ChunkSums) -> f64) -> f64 {
    sums.iter().map(value).reduce(|a, b| a + b).unwrap_or(0.0)
}

/// What one chunk reports of the phases of a step, combined in chunk order.
#[derive(Debug, Clone, Copy, Default)]
struct ChunkSums {
    /// The largest log-weight (after `Propagate`).
    max: f64,
    /// The sum of the shifted exponentials (after `Exponentiate`).
    exp_sum: f64,
    /// The running sums of the weights (after `Exponentiate`, when systematic
    /// resampling runs by blocks).
    running: BlockSums,
    /// The sum of squared normalised weights (after `Normalise`).
    square_sum: f64,
}

/// The systematic resampling of a step, by blocks of chunks.
#[derive(Debug, Clone, Copy)]
struct SystematicMarks {
    marks: Marks,
    last: usize,
}

/// One phase of a filter step; every chunk runs it on its particles.
#[derive(Debug, Clone, Copy)]
enum Phase {
    /// Draw `x_t` (from `mu` at `t = 0`, else from `f` given the resampled
    /// `x_{t-1}`), evaluate `log g(y_t | x_t)` and add it to the log-weights (reset
    /// first to the given uniform value after a resampling); record the chunk's
    /// largest log-weight.
    Propagate {
        t: usize,
        reset_log_weight: Option<f64>,
    },
    /// Weights `exp(l - shift)` and their sum, or `exp(l)` at a step whose outputs are
    /// missing (`shift` None); with `running_sums`, also the systematic running sums.
    Exponentiate {
        shift: Option<f64>,
        running_sums: bool,
    },
    /// Scale the weights and shift the log-weights by the increment (unless the step
    /// is missing); the chunk's sum of squared weights and weighted mean; the chunk's
    /// ancestors by systematic resampling.
    Normalise {
        normalisation: Option<(f64, f64)>,
        square_sums: bool,
        means: bool,
        marks: Option<SystematicMarks>,
    },
}

/// A phase with the buffers it works on: what the leader sends its team.
#[derive(Clone, Copy)]
struct Command {
    phase: Phase,
    buffers: SharedBuffers,
}

/// The buffers of one step as raw parts, shared by the members of a filter team.
///
/// During the leader's `Team::run` each member writes only the entries of the chunks
/// it claimed (states, log-densities, log-weights, weights, running
/// sums, generator, chunk sums and means) and its chunks' slot ranges of the next
/// ancestors; every member reads `previous`, `ancestors`, `plan` and the data, which
/// nothing writes in that window. Outside it the leader owns every buffer.
#[derive(Clone, Copy)]
struct SharedBuffers {
    state_dim: usize,
    particles: usize,
    chunks: usize,
    states: *mut f64,
    previous: *const f64,
    log_obs: *mut f64,
    log_weights: *mut f64,
    weights: *mut f64,
    running_sums: *mut f64,
    ancestors: *const usize,
    next_ancestors: *mut usize,
    rngs: *mut Rng,
    chunk_sums: *mut ChunkSums,
    chunk_means: *mut f64,
    plan: *const BlockPlan,
}

// SAFETY: the pointers are used only under the access rules above, which the team's
// release/acquire handshakes order between threads.
unsafe impl Send for SharedBuffers {}

impl Command {
    /// Runs the phase on the chunks `[first, last)`. A caller compiled for the
    /// baseline target (a team helper's thread body) passes `dispatch`, so that each
    /// chunk goes through the vector dispatch; the run's leader already runs inside it
    /// (see [`RunKernel`]) and has the chunks' work inlined instead, without a feature
    /// test and an out-of-line call per chunk and phase (about 10 % of a step's time at
    /// 16 particles). The same instructions either way, so the same bits.
    ///
    /// # Safety
    /// No other thread may touch these chunks' entries, nor write the shared reads,
    /// while it runs; the pointers must be those of live buffers of the step's sizes.
    #[inline(always)]
    unsafe fn run_chunks<M: FilterModel>(
        self,
        model: &M,
        data: &Series,
        (first, last): (usize, usize),
        dispatch: bool,
    ) {
        for chunk in first..last {
            let kernel = PhaseKernel {
                command: self,
                model,
                data,
                chunk,
            };
            if dispatch {
                crate::simd::dispatch(kernel);
            } else {
                kernel.run();
            }
        }
    }
}

/// One chunk's work in one phase, as a [`Kernel`].
struct PhaseKernel<'a, 's, M> {
    command: Command,
    model: &'a M,
    data: &'a Series<'s>,
    chunk: usize,
}

impl<M: FilterModel> Kernel for PhaseKernel<'_, '_, M> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        let Command { phase, buffers: b } = self.command;
        let (n, m, chunk) = (b.state_dim, b.particles, self.chunk);
        let first = chunk * CHUNK;
        let len = CHUNK.min(m - first);
        // SAFETY: `run_chunks`' contract: this chunk's entries are this thread's alone,
        // and the shared reads are not written while it runs
        let (states, log_weights, weights, sums) = unsafe {
            (
                std::slice::from_raw_parts_mut(b.states.add(first * n), len * n),
                std::slice::from_raw_parts_mut(b.log_weights.add(first), len),
                std::slice::from_raw_parts_mut(b.weights.add(first), len),
                &mut *b.chunk_sums.add(chunk),
            )
        };
        match phase {
            Phase::Propagate {
                t,
                reset_log_weight,
            } => {
                // SAFETY: as above
                let (log_obs, rng, previous, parents) = unsafe {
                    (
                        std::slice::from_raw_parts_mut(b.log_obs.add(first), len),
                        &mut *b.rngs.add(chunk),
                        std::slice::from_raw_parts(b.previous, m * n),
                        std::slice::from_raw_parts(b.ancestors.add(first), len),
                    )
                };
                let data = self.data;
                if t == 0 {
                    self.model.sample_initials(states, rng);
                } else {
                    let input = data.input(t - 1);
                    let model = self.model;
                    model.sample_transitions(t - 1, input, previous, parents, states, rng);
                }
                if let Some(uniform) = reset_log_weight {
                    log_weights.fill(uniform);
                }
                if data.is_missing(t) {
                    log_obs.fill(0.0);
                } else {
                    let (input, output) = (data.input(t), data.output(t));
                    self.model
                        .log_observations(t, input, output, states, log_obs);
                    for (l, &lg) in log_weights.iter_mut().zip(log_obs.iter()) {
                        *l += lg;
                    }
                    sums.max = max_value(log_weights);
                }
            }
            Phase::Exponentiate {
                shift,
                running_sums,
            } => {
                match shift {
                    Some(shift) => {
                        weights.copy_from_slice(log_weights);
                        sums.exp_sum = exp_shifted_sum(weights, shift);
                    }
                    None => {
                        for (w, &l) in weights.iter_mut().zip(log_weights.iter()) {
                            *w = l.exp();
                        }
                    }
                }
                if running_sums {
                    // SAFETY: as above
                    let running =
                        unsafe { std::slice::from_raw_parts_mut(b.running_sums.add(first), len) };
                    sums.running = block_running_sums(weights, running);
                }
            }
            Phase::Normalise {
                normalisation,
                square_sums,
                means,
                marks,
            } => {
                if let Some((scale, increment)) = normalisation {
                    for w in weights.iter_mut() {
                        *w *= scale;
                    }
                    for l in log_weights.iter_mut() {
                        *l -= increment;
                    }
                }
                if square_sums {
                    sums.square_sum = sum_of_squares(weights);
                }
                if means {
                    // SAFETY: as above
                    let mean =
                        unsafe { std::slice::from_raw_parts_mut(b.chunk_means.add(chunk * n), n) };
                    weighted_mean(states, weights, mean);
                }
                if let Some(SystematicMarks { marks, last }) = marks {
                    // SAFETY: as above; the plan gives each chunk its own slot range
                    let (plan, running, out) = unsafe {
                        let plan = &*b.plan.add(chunk);
                        (
                            plan,
                            std::slice::from_raw_parts(b.running_sums.add(first), len),
                            std::slice::from_raw_parts_mut(
                                b.next_ancestors.add(plan.first_slot),
                                plan.end_slot - plan.first_slot,
                            ),
                        )
                    };
                    mark_block(running, first, last, plan, &marks, out);
                }
            }
        }
    }
}

struct RunKernel<'f, 'm, 'd, 's, 't, M> {
    filter: &'f mut ParticleFilter,
    model: &'m M,
    data: &'d Series<'s>,
    seed: u64,
    team: Option<&'t Team<Command>>,
}

impl<M: FilterModel> Kernel for RunKernel<'_, '_, '_, '_, '_, M> {
    type Output = Result<FilterSummary, SmcError>;

    #[inline(always)]
    fn run(self) -> Self::Output {
        self.filter
            .run_steps(self.model, self.data, self.seed, self.team)
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
