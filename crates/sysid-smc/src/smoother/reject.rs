//! FFBSi with rejection sampling (Douc, Garivier, Moulines and Olsson 2011), with the
//! number of trials capped and an exact fallback draw (Dau and Chopin 2023).

use rand::RngExt;
use rand_distr::{Distribution, Exp1};

use super::SmootherStats;
use super::backward::{BackwardStep, backward_error};
use crate::model::{ScalarGaussianKernel, TransitionBound};
use crate::resample::systematic_from_cumulative;
use crate::streams::Rng;
use crate::weights::draw_from_log_weights;
use crate::{History, Series, SmcError};

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
            stats: SmootherStats::default(),
        }
    }
}

/// A table for O(1) expected draws from `Cat(W_t)` at one step: the cumulative weights
/// and a guide table (Chen and Asau 1974), `guide[j]` = the first particle whose
/// cumulative weight exceeds `j / M` of the total. Built in O(M) when the step changes;
/// it stays in the cache while the blocks' trials hit it at random.
#[derive(Default)]
pub(crate) struct ProposalTable {
    step: Option<usize>,
    cumulative: Vec<f64>,
    guide: Vec<usize>,
    last_positive: usize,
}

impl ProposalTable {
    /// Makes the table that of step `t`; `false` when it already was.
    fn prepare(&mut self, history: &History, t: usize) -> bool {
        if self.step == Some(t) {
            return false;
        }
        let weights = history.weights(t);
        let mut acc = 0.0;
        self.cumulative.clear();
        self.cumulative.extend(weights.iter().map(|w| {
            acc += w;
            acc
        }));
        self.last_positive = weights.iter().rposition(|&w| w > 0.0).unwrap_or(0);
        self.guide.resize(weights.len(), 0);
        systematic_from_cumulative(&self.cumulative, self.last_positive, 0.0, &mut self.guide);
        self.step = Some(t);
        true
    }

    /// Draws `i ~ Cat(W_t)` from a uniform in [0, 1).
    #[inline]
    fn draw(&self, uniform: f64) -> usize {
        let cumulative = &self.cumulative[..];
        let m = cumulative.len();
        let target = uniform * cumulative[m - 1];
        let j = ((uniform * m as f64) as usize).min(m - 1);
        let last = self.last_positive;
        let mut i = self.guide[j].min(last);
        while i > 0 && cumulative[i - 1] > target {
            i -= 1;
        }
        while i < last && cumulative[i] <= target {
            i += 1;
        }
        i
    }
}

impl<M: TransitionBound> BackwardStep for RejectStep<'_, M> {
    fn step(
        &mut self,
        t: usize,
        next_states: &[f64],
        _next_indices: &[usize],
        out: &mut [usize],
        rng: &mut Rng,
    ) -> Result<(), SmcError> {
        let n = self.history.state_dim();
        let m = self.history.particles();
        let u = self.data.input(t);
        let states = self.history.states(t);
        let log_bound = self.model.log_transition_bound(t, u);
        let log_f = self.model.log_transition_at(t, u);
        if self.proposal.prepare(self.history, t) {
            self.kernel = if n == 1 {
                self.model
                    .scalar_gaussian_means(t, u, states, &mut self.means)
                    .filter(ScalarGaussianKernel::is_proper)
            } else {
                None
            };
        }
        let kernel = self.kernel;
        'paths: for (k, (next, slot)) in next_states.chunks_exact(n).zip(out.iter_mut()).enumerate()
        {
            for _ in 0..self.max_trials {
                let i = self.proposal.draw(rng.random());
                let value = match kernel {
                    Some(kernel) => kernel.log_density(self.means[i], next[0]),
                    None => log_f(&states[i * n..(i + 1) * n], next),
                };
                self.stats.trials += 1;
                self.stats.density_evaluations += 1;
                if value > log_bound {
                    return Err(SmcError::BoundViolated {
                        t,
                        log_density: value,
                        log_bound,
                    });
                }
                // Accept with probability exp(value - log_bound): an Exp(1) variable
                // exceeds log_bound - value with exactly that probability.
                let e: f64 = Exp1.sample(rng);
                if e > log_bound - value {
                    *slot = i;
                    continue 'paths;
                }
            }
            self.stats.fallbacks += 1;
            self.stats.density_evaluations += m as u64;
            self.row.resize(m, 0.0);
            self.model
                .log_transition_matrix(t, u, states, next, &mut self.row, &mut self.scratch);
            for (l, &lw) in self.row.iter_mut().zip(self.history.log_weights(t)) {
                *l += lw;
            }
            *slot = draw_from_log_weights(&mut self.row, rng.random())
                .map_err(|f| backward_error(f, t, k))?;
        }
        Ok(())
    }

    fn stats(&self) -> SmootherStats {
        self.stats
    }
}
