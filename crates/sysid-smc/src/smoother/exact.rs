//! The exact O(M) backward draw per path: FFBSi's kernel, also Tanizaki's.

use rand::RngExt;

use super::SmootherStats;
use super::backward::{DispatchedStep, PATH_BLOCK, backward_error, gather};
use super::nearest;
use super::rounds::{draw_in_rounds, uniform_index};
use super::window::{BlockProposals, MeanBuckets};
use crate::model::{ScalarGaussianKernel, TransitionDensity};
use crate::streams::Rng;
use crate::vexp::exp_shifted_sum;
use crate::weights::{DrawFailure, checked_row_max, draw_from_weights, shift_rows_by_max};
use crate::{History, Series, SmcError};

/// Which filter cloud the backward kernel draws from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Cloud {
    /// The weighted filter particles `(x_t^i, W_t^i)` (FFBSi).
    Weighted,
    /// The equally weighted resampled particles `x_t^{a_{t+1}^i}` where the filter
    /// resampled after `t`, else the weighted ones (Tanizaki's smoother).
    Resampled,
}

/// Draws index `i` with probability proportional to `W_t^i f(x~_{t+1} | x_t^i)` for each
/// path, evaluating the whole block's transition log-densities at once.
///
/// With `rejection_trials = Some(k)` each draw first tries up to `k` times to propose
/// `i` uniformly and accept it with probability `W_t^i f_i / max_j (W_t^j f_j)`
/// (rejection against the row's own maximum: one Exp(1) variate per trial instead of
/// one exponential per candidate; the block's rows in rounds, see [`super::rounds`]),
/// then falls back to the exact draw. Both routes sample exactly the same distribution;
/// the first is several times cheaper when the candidates' densities are of similar
/// size.
pub(crate) struct ExactStep<'a, M> {
    pub model: &'a M,
    pub history: &'a History,
    pub data: &'a Series<'a>,
    pub cloud: Cloud,
    pub rejection_trials: Option<usize>,
    pub matrix: Vec<f64>,
    pub scratch: Vec<f64>,
    pub gathered: Vec<f64>,
    /// The step whose resampled cloud `gathered` holds (and, for scalar Gaussian
    /// transitions, whose transition means `means` and `kernel` are).
    pub cloud_step: Option<usize>,
    pub means: Vec<f64>,
    /// `means` sorted into buckets, for the rows' proposal windows.
    pub buckets: MeanBuckets,
    /// Whether `buckets` holds the means of `cloud_step` (see [`MeanBuckets::build`]).
    pub windowed: bool,
    pub proposals: BlockProposals,
    pub kernel: Option<ScalarGaussianKernel>,
    pub stats: SmootherStats,
}

impl<'a, M: TransitionDensity> ExactStep<'a, M> {
    pub fn new(model: &'a M, history: &'a History, data: &'a Series<'a>, cloud: Cloud) -> Self {
        ExactStep {
            model,
            history,
            data,
            cloud,
            rejection_trials: None,
            matrix: Vec::new(),
            scratch: Vec::new(),
            gathered: Vec::new(),
            cloud_step: None,
            means: Vec::new(),
            buckets: MeanBuckets::default(),
            windowed: false,
            proposals: BlockProposals::default(),
            kernel: None,
            stats: SmootherStats::default(),
        }
    }
}

impl<M: TransitionDensity> DispatchedStep for ExactStep<'_, M> {
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
        let resampled = self.cloud == Cloud::Resampled && self.history.resampled_after(t);
        // the blocks walk in lockstep: the cloud (and its means) serve all of them
        let fresh = self.cloud_step != Some(t);
        self.cloud_step = resampled.then_some(t);
        if resampled && fresh {
            self.gathered.resize(m * n, 0.0);
            gather(
                self.history,
                t,
                self.history.ancestors(t + 1),
                &mut self.gathered,
            );
        }
        let cloud: &[f64] = if resampled {
            &self.gathered
        } else {
            self.history.states(t)
        };
        if let (true, Some(trials)) = (resampled && n == 1, self.rejection_trials) {
            // equally weighted candidates: propose from each row's window of means
            if fresh {
                self.kernel = self
                    .model
                    .scalar_gaussian_means(t, self.data.input(t), cloud, &mut self.means)
                    .filter(ScalarGaussianKernel::is_proper)
                    .filter(|_| nearest::means_usable(&self.means));
                self.windowed = match self.kernel {
                    Some(kernel) => self.buckets.build(&self.means, kernel),
                    None => false,
                };
            }
            if let Some(kernel) = self.kernel {
                let ancestors = self.history.ancestors(t + 1);
                return nearest::draw_block(
                    kernel,
                    &self.means,
                    self.windowed.then_some(&self.buckets),
                    &mut self.proposals,
                    next_states,
                    trials,
                    t,
                    out,
                    |i| ancestors[i],
                    rng,
                    &mut self.matrix,
                    &mut self.stats,
                );
            }
        }
        self.matrix.resize(out.len() * m, 0.0);
        self.model.log_transition_matrix(
            t,
            self.data.input(t),
            cloud,
            next_states,
            &mut self.matrix,
            &mut self.scratch,
        );
        if !resampled {
            let log_weights = self.history.log_weights(t);
            for row in self.matrix.chunks_exact_mut(m) {
                for (l, &lw) in row.iter_mut().zip(log_weights) {
                    *l += lw;
                }
            }
        }
        let pick = |i: usize| {
            if resampled {
                self.history.ancestors(t + 1)[i]
            } else {
                i
            }
        };
        let Some(trials) = self.rejection_trials else {
            // One long exp over the whole block (rows shifted by their maxima first)
            // keeps the vector pipeline full; then one blocked scan per row.
            shift_rows_by_max(&mut self.matrix, m).map_err(|(k, f)| backward_error(f, t, k))?;
            exp_shifted_sum(&mut self.matrix, 0.0);
            for (k, (row, slot)) in self.matrix.chunks_exact(m).zip(out.iter_mut()).enumerate() {
                let i = draw_from_weights(row, rng.random())
                    .ok_or_else(|| backward_error(DrawFailure::Invalid, t, k))?;
                *slot = pick(i);
            }
            self.stats.density_evaluations += (out.len() * m) as u64;
            return Ok(());
        };
        let mut max = [0.0; PATH_BLOCK];
        for (k, row) in self.matrix.chunks_exact(m).enumerate() {
            max[k] = checked_row_max(row).map_err(|f| backward_error(f, t, k))?;
            // proposals may never visit a NaN entry: look for one explicitly
            if row.iter().fold(false, |nan, v| nan | v.is_nan()) {
                return Err(backward_error(DrawFailure::Invalid, t, k));
            }
        }
        let matrix = &self.matrix;
        let open = draw_in_rounds(
            trials,
            rng,
            |_, u| uniform_index(u, m),
            |k, i| matrix[k * m + i] - max[k],
            out,
        );
        self.stats.trials += open.trials;
        for k in open.rows() {
            self.stats.fallbacks += 1;
            let row = &mut self.matrix[k * m..(k + 1) * m];
            exp_shifted_sum(row, max[k]);
            out[k] = draw_from_weights(row, rng.random())
                .ok_or_else(|| backward_error(DrawFailure::Invalid, t, k))?;
        }
        for slot in out.iter_mut() {
            *slot = pick(*slot);
        }
        self.stats.density_evaluations += (out.len() * m) as u64;
        Ok(())
    }
}
