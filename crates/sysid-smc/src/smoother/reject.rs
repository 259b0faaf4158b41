//! FFBSi with rejection sampling (Douc, Garivier, Moulines and Olsson 2011), with the
//! number of trials capped and an exact fallback draw (Dau and Chopin 2023).

use rand::RngExt;

use super::SmootherStats;
use super::backward::{BackwardStep, backward_error};
use crate::model::TransitionBound;
use crate::streams::Rng;
use crate::weights::draw_from_log_weights;
use crate::{History, Series, SmcError};

pub(crate) struct RejectStep<'a, M> {
    pub model: &'a M,
    pub history: &'a History,
    pub data: &'a Series<'a>,
    /// Cumulative filter weights, T x M.
    pub cumulative: &'a [f64],
    pub max_trials: usize,
    pub row: Vec<f64>,
    pub scratch: Vec<f64>,
    pub stats: SmootherStats,
}

/// The cumulative sums of the filter weights at every step (T x M).
pub(crate) fn cumulative_weights(history: &History) -> Vec<f64> {
    let mut out = Vec::with_capacity(history.steps() * history.particles());
    for t in 0..history.steps() {
        let mut acc = 0.0;
        out.extend(history.weights(t).iter().map(|w| {
            acc += w;
            acc
        }));
    }
    out
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
        let cumulative = &self.cumulative[t * m..(t + 1) * m];
        let total = cumulative[m - 1];
        let last_positive = self
            .history
            .weights(t)
            .iter()
            .rposition(|&w| w > 0.0)
            .unwrap_or(0);
        let log_bound = self.model.log_transition_bound(t, u);
        'paths: for (k, (next, slot)) in next_states.chunks_exact(n).zip(out.iter_mut()).enumerate()
        {
            for _ in 0..self.max_trials {
                let target = rng.random::<f64>() * total;
                let i = cumulative
                    .partition_point(|&c| c <= target)
                    .min(last_positive);
                let log_f = self
                    .model
                    .log_transition(t, &states[i * n..(i + 1) * n], u, next);
                self.stats.trials += 1;
                self.stats.density_evaluations += 1;
                if log_f > log_bound {
                    return Err(SmcError::BoundViolated {
                        t,
                        log_density: log_f,
                        log_bound,
                    });
                }
                if rng.random::<f64>() < (log_f - log_bound).exp() {
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
