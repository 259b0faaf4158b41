//! FFBSi with rejection sampling (Douc, Garivier, Moulines and Olsson 2011), with the
//! number of trials capped and an exact fallback draw (Dau and Chopin 2023).

use rand::RngExt;
use rand_distr::{Distribution, Exp1};

use super::SmootherStats;
use super::backward::{BackwardStep, backward_error};
use crate::model::TransitionBound;
use crate::resample::systematic;
use crate::streams::Rng;
use crate::weights::draw_from_log_weights;
use crate::{History, Series, SmcError};

pub(crate) struct RejectStep<'a, M> {
    pub model: &'a M,
    pub history: &'a History,
    pub data: &'a Series<'a>,
    pub tables: &'a ProposalTables,
    pub max_trials: usize,
    pub row: Vec<f64>,
    pub scratch: Vec<f64>,
    pub stats: SmootherStats,
}

/// Per-step tables for O(1) expected draws from `Cat(W_t)`: the cumulative weights and
/// a guide table (Chen and Asau 1974), `guide[j]` = the first particle whose cumulative
/// weight exceeds `j / M` of the total.
pub(crate) struct ProposalTables {
    particles: usize,
    cumulative: Vec<f64>,
    guide: Vec<usize>,
    last_positive: Vec<usize>,
}

impl ProposalTables {
    pub fn new(history: &History) -> Self {
        let (steps, m) = (history.steps(), history.particles());
        let mut cumulative = Vec::with_capacity(steps * m);
        let mut guide = vec![0usize; steps * m];
        let mut last_positive = Vec::with_capacity(steps);
        for t in 0..steps {
            let weights = history.weights(t);
            let mut acc = 0.0;
            cumulative.extend(weights.iter().map(|w| {
                acc += w;
                acc
            }));
            systematic(weights, 0.0, &mut guide[t * m..(t + 1) * m]);
            last_positive.push(weights.iter().rposition(|&w| w > 0.0).unwrap_or(0));
        }
        ProposalTables {
            particles: m,
            cumulative,
            guide,
            last_positive,
        }
    }

    /// Draws `i ~ Cat(W_t)` from a uniform in [0, 1).
    #[inline]
    fn draw(&self, t: usize, uniform: f64) -> usize {
        let m = self.particles;
        let cumulative = &self.cumulative[t * m..(t + 1) * m];
        let target = uniform * cumulative[m - 1];
        let j = ((uniform * m as f64) as usize).min(m - 1);
        let last = self.last_positive[t];
        let mut i = self.guide[t * m + j].min(last);
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
        'paths: for (k, (next, slot)) in next_states.chunks_exact(n).zip(out.iter_mut()).enumerate()
        {
            for _ in 0..self.max_trials {
                let i = self.tables.draw(t, rng.random());
                let value = log_f(&states[i * n..(i + 1) * n], next);
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
