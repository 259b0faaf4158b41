//! The output of one Markov chain.

/// The draws of one chain, burn-in included (summaries skip it).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Chain {
    /// The parameter names.
    pub names: Vec<String>,
    /// Number of leading iterations that are burn-in.
    pub burn_in: usize,
    /// The parameter draws, iteration-major (`iterations x dim`).
    pub samples: Vec<f64>,
    /// Per iteration, the log-likelihood attached to the current state: PMMH's
    /// particle estimate; particle Gibbs's complete-data `log p(x, y | theta)`.
    pub log_likelihood: Vec<f64>,
    /// Per iteration, `log p(theta)` of the current state.
    pub log_prior: Vec<f64>,
    /// Per iteration, whether the parameter proposal was accepted (always true for
    /// exact Gibbs draws).
    pub accepted: Vec<bool>,
    /// Particle Gibbs only: per time step, the fraction of the post-burn-in
    /// iterations in which the sampled state `x_t` changed.
    pub state_update_rate: Option<Vec<f64>>,
    /// Particle Gibbs only: the posterior mean of each state `x_t` (time-major
    /// `T x n`) over the post-burn-in iterations.
    pub state_mean: Option<Vec<f64>>,
    /// The chain was stopped before its iterations were done
    /// ([`ChainObserver::should_stop`](crate::ChainObserver::should_stop)); its draws are
    /// those made until then.
    pub interrupted: bool,
}

impl Chain {
    /// Number of parameters.
    pub fn dim(&self) -> usize {
        self.names.len()
    }

    /// Number of iterations, burn-in included.
    pub fn iterations(&self) -> usize {
        self.accepted.len()
    }

    /// The draws of parameter `k` after burn-in.
    pub fn parameter(&self, k: usize) -> Vec<f64> {
        let d = self.dim();
        self.samples
            .chunks_exact(d)
            .skip(self.burn_in)
            .map(|row| row[k])
            .collect()
    }

    /// The parameters at iteration `i`.
    pub fn sample(&self, i: usize) -> &[f64] {
        let d = self.dim();
        &self.samples[i * d..(i + 1) * d]
    }

    /// The acceptance rate after burn-in.
    pub fn acceptance_rate(&self) -> f64 {
        let kept = &self.accepted[self.burn_in.min(self.accepted.len())..];
        if kept.is_empty() {
            return f64::NAN;
        }
        kept.iter().filter(|&&a| a).count() as f64 / kept.len() as f64
    }
}
