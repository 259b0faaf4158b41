//! FFBSi with rejection sampling (Douc, Garivier, Moulines and Olsson 2011), with the
//! number of trials capped and an exact fallback draw (Dau and Chopin 2023).
//!
//! # Algorithm
//! For a block of paths at step `t`, each trial proposes `i ~ Cat(W_t)` from an alias
//! table of the step's weights and accepts it with probability `f(x~ | x_t^i) / c`;
//! the trials run in rounds over the block's open paths ([`super::rounds`]). Paths
//! still open after `max_trials` draw exactly from `W_t^i f(x~ | x_t^i)`.
//!
//! The envelope `c` is each path's own largest density `max_i f(x~ | x_t^i)` when the
//! transition is scalar Gaussian ([`crate::TransitionDensity::scalar_gaussian_means`])
//! and there are at most [`ROW_BOUND_MAX_PARTICLES`] particles:
//! it belongs to the transition mean nearest to `x~`, found in one vector pass
//! ([`super::nearest`]). Otherwise `log c` is the model's [`TransitionBound`], and a
//! density above it is reported as [`SmcError::BoundViolated`] once the block's
//! rounds are done. The row's own maximum accepts far more often when the cloud of
//! means is wide against the transition noise (seed 000's benchmark, q = 0.01).
//!
//! Where, besides, a step's means spread wider than one window ([`super::window`]),
//! they are sorted into buckets with the running sums of their weights, and each path
//! proposes from its window of means instead: `i ∝ W_t^i max_j f_j` inside it,
//! `W_t^i f_out` outside it (`f_out <= e^-4 max_j f_j` bounds every density there),
//! found by bisecting the running sums ([`nearest::draw_weighted_block`]). On seed
//! 000's benchmark (M = 50) that takes 2.2-2.6 trials per path there instead of 4-10,
//! and the fallbacks fall from 1-4 % of the paths to under 0.5 %.
//!
//! # Complexity
//! O(M) per step for the table or the buckets (and the means), O(M / 8) vector
//! operations per path for the nearest mean, about `c / E[f]` trials per path (each
//! O(log W) for a window of W means), O(M) per fallback.

use rand::RngExt;

use super::SmootherStats;
use super::alias::AliasTable;
use super::backward::{DispatchedStep, backward_error};
use super::nearest;
use super::rounds::draw_in_rounds;
use super::window::{BlockProposals, MeanBuckets};
use crate::model::{ScalarGaussianKernel, TransitionBound};
use crate::streams::Rng;
use crate::weights::draw_from_log_weights;
use crate::{History, Series, SmcError};

/// The most filter particles for which each path's envelope is its own maximum: the
/// nearest-mean pass costs O(M) per path, which at M = 50 (seed 000's benchmark) is
/// repaid by the trials it saves (1000 EM iterations: 2.9-5.8 s against 3.8-7.0 s),
/// but not at M = 1000 (the `ffbsi_reject` benchmark: 24 ms against 18 ms, 11 % fewer
/// trials). The windows need that maximum too, so they are used only up to here.
/// (Not tried beyond: at M = 1000 with 100 paths, a step's O(M) bucket sort and
/// running sums would cost microseconds per step, like the alias table, which already
/// takes 30 % of that benchmark at about 5 us per step.)
const ROW_BOUND_MAX_PARTICLES: usize = 256;

pub(crate) struct RejectStep<'a, M> {
    pub model: &'a M,
    pub history: &'a History,
    pub data: &'a Series<'a>,
    pub max_trials: usize,
    pub row: Vec<f64>,
    pub scratch: Vec<f64>,
    /// The proposal table of the step being walked, built when the step changes
    /// (blocks walk in lockstep, so once per step for all of them).
    pub proposal: ProposalTable,
    /// For scalar Gaussian transitions: the transition means of the proposal table's
    /// step and the kernel, computed with the table (vectorised) instead of once per
    /// trial.
    pub means: Vec<f64>,
    pub kernel: Option<ScalarGaussianKernel>,
    /// `means` sorted into buckets, with the weights' running sums in their order,
    /// for the rows' proposal windows.
    pub buckets: MeanBuckets,
    /// Whether `buckets` holds the means of the proposal table's step (see
    /// [`MeanBuckets::build`]); the alias table is then not built.
    pub windowed: bool,
    pub proposals: BlockProposals,
    pub stats: SmootherStats,
}

impl<'a, M> RejectStep<'a, M> {
    pub fn new(
        model: &'a M,
        history: &'a History,
        data: &'a Series<'a>,
        max_trials: usize,
    ) -> Self {
        RejectStep {
            model,
            history,
            data,
            max_trials,
            row: Vec::new(),
            scratch: Vec::new(),
            proposal: ProposalTable::default(),
            means: Vec::new(),
            kernel: None,
            buckets: MeanBuckets::default(),
            windowed: false,
            proposals: BlockProposals::default(),
            stats: SmootherStats::default(),
        }
    }
}

/// The proposal `Cat(W_t)` of the step being walked: an alias table, built in O(M)
/// when the step changes; it stays in the cache while the blocks' trials hit it at
/// random.
#[derive(Default)]
pub(crate) struct ProposalTable {
    step: Option<usize>,
    table: AliasTable,
}

impl ProposalTable {
    /// Makes this the proposal of step `t`, building its alias table only with
    /// `build_table` (windowed steps draw from the weights' running sums instead).
    fn prepare(&mut self, history: &History, t: usize, build_table: bool) {
        if build_table {
            self.table.build(history.weights(t));
        }
        self.step = Some(t);
    }

    /// Whether the proposal is that of step `t`.
    fn is_at(&self, t: usize) -> bool {
        self.step == Some(t)
    }

    /// Draws `i ~ Cat(W_t)` from a uniform in [0, 1).
    #[inline(always)]
    fn draw(&self, uniform: f64) -> usize {
        self.table.draw(uniform)
    }
}

impl<M: TransitionBound> DispatchedStep for RejectStep<'_, M> {
    fn step_stats(&self) -> SmootherStats {
        self.stats
    }

    #[inline(always)]
    fn step_body(
        &mut self,
        t: usize,
        next_states: &[f64],
        out: &mut [usize],
        rng: &mut Rng,
    ) -> Result<(), SmcError> {
        let n = self.history.state_dim();
        let m = self.history.particles();
        let u = self.data.input(t);
        let states = self.history.states(t);
        let log_bound = self.model.log_transition_bound(t, u);
        let log_f = self.model.log_transition_at(t, u);
        let row_bounds = m <= ROW_BOUND_MAX_PARTICLES;
        if !self.proposal.is_at(t) {
            self.kernel = if n == 1 {
                self.model
                    .scalar_gaussian_means(t, u, states, &mut self.means)
                    .filter(ScalarGaussianKernel::is_proper)
                    .filter(|_| nearest::means_usable(&self.means))
            } else {
                None
            };
            self.windowed = match self.kernel {
                Some(kernel) if row_bounds => self.buckets.build(&self.means, kernel),
                _ => false,
            };
            if self.windowed {
                self.buckets.cumulate_weights(self.history.weights(t));
            }
            self.proposal.prepare(self.history, t, !self.windowed);
        }
        let (means, proposal) = (&self.means, &self.proposal);
        // a log-density above the bound, if any (the model's bound is wrong): the last
        // one seen, a select per trial; the largest (`max`, with its NaN handling) would
        // put a dependency chain of several cycles through the trial loop
        let mut violation = f64::NEG_INFINITY;
        let mut ratio = |value: f64| {
            if value > log_bound {
                violation = value;
            }
            // accepted with probability exp(value - log_bound)
            value - log_bound
        };
        // one copy of the trial loop per kind of density, so that the density is
        // inlined into it
        let open = match self.kernel {
            Some(kernel) if self.windowed => {
                // each row's window of sorted means, bounded by its own maximum
                self.stats.density_evaluations += out.len() as u64;
                nearest::draw_weighted_block(
                    kernel,
                    &self.buckets,
                    &mut self.proposals,
                    next_states,
                    self.max_trials,
                    t,
                    out,
                    rng,
                )?
            }
            Some(kernel) if row_bounds => {
                // each row's own maximum: exact, so no density can exceed it
                self.stats.density_evaluations += out.len() as u64;
                let row_max = nearest::row_maxima(kernel, means, next_states, t)?.max;
                draw_in_rounds(
                    self.max_trials,
                    rng,
                    |_, u| proposal.draw(u),
                    |k, i| kernel.log_density(means[i], next_states[k]) - row_max[k],
                    out,
                )
            }
            Some(kernel) => draw_in_rounds(
                self.max_trials,
                rng,
                |_, u| proposal.draw(u),
                |k, i| ratio(kernel.log_density(means[i], next_states[k])),
                out,
            ),
            None => draw_in_rounds(
                self.max_trials,
                rng,
                |_, u| proposal.draw(u),
                |k, i| {
                    ratio(log_f(
                        &states[i * n..(i + 1) * n],
                        &next_states[k * n..(k + 1) * n],
                    ))
                },
                out,
            ),
        };
        self.stats.trials += open.trials;
        self.stats.density_evaluations += open.trials;
        if violation > log_bound {
            return Err(SmcError::BoundViolated {
                t,
                log_density: violation,
                log_bound,
            });
        }
        for k in open.rows() {
            self.stats.fallbacks += 1;
            self.stats.density_evaluations += m as u64;
            self.row.resize(m, 0.0);
            let next = &next_states[k * n..(k + 1) * n];
            self.model
                .log_transition_matrix(t, u, states, next, &mut self.row, &mut self.scratch);
            for (l, &lw) in self.row.iter_mut().zip(self.history.log_weights(t)) {
                *l += lw;
            }
            out[k] = draw_from_log_weights(&mut self.row, rng.random())
                .map_err(|f| backward_error(f, t, k))?;
        }
        Ok(())
    }
}
