//! The fully adapted ("guided") particle filter, with a stored history for the
//! smoothers.
//!
//! # Model
//! Any [`FilterModel`] with a [`TransitionDensity`] and a [`GuidedProposal`]: the
//! predictive density `p(y_t | x_{t-1})` and the locally optimal proposal
//! `p(x_t | x_{t-1}, y_t)` are tractable (linear Gaussian observations, or a
//! piecewise-linear output of a Gaussian state such as the blind Wiener model).
//!
//! # Algorithm
//! At a fully observed step `t`, draw the ancestors multinomially with weights
//! `W_{t-1}^i p(y_t | x_{t-1}^i)` and each particle from `p(x_t | x_{t-1}^{a}, y_t)`; the
//! new weights are then all `1 / M`, and `log p(y_t | y_{0:t-1})` is estimated by
//! `log sum_i W_{t-1}^i p(y_t | x_{t-1}^i)`. Steps with a missing output are bootstrap
//! steps. This is the unconditional sweep of [`ConditionalSmc::sample_guided`], so
//! both samplers share one implementation.
//!
//! Where the bootstrap filter puts particles by the prediction alone and weights them
//! afterwards, this one puts them where the observation allows: with precise
//! observations (small output noise) far fewer particles keep track of the state.
//!
//! The [`History`] holds the particles, the (uniform, at guided steps) weights and
//! the ancestors. No step is marked resampled: the ancestors of step `t + 1` were
//! drawn with the predictive weights, not as an equally weighted resample of step `t`,
//! so the smoothers use the weighted cloud of step `t` itself.
//!
//! # Complexity
//! O(T M) calls of the model's predictive density and proposal; O(T M n) memory.
//!
//! # Example
//! See `sysid_models::LinearGaussianSmc`, which implements [`GuidedProposal`]; the
//! filter runs as `GuidedFilter::new(100)?.run(&model, &data, seed)?`.
//!
//! # References
//! Pitt and Shephard (1999), *Filtering via simulation: auxiliary particle filters*;
//! Doucet, Godsill and Andrieu (2000), *On sequential Monte Carlo sampling methods for
//! Bayesian filtering*.

use crate::conditional::{ConditionalSmc, CsmcKernel};
use crate::model::{FilterModel, GuidedProposal, TransitionDensity};
use crate::{History, Series, SmcError, stream};

/// A fully adapted particle filter with its reusable buffers.
#[derive(Debug, Clone)]
pub struct GuidedFilter {
    sweep: ConditionalSmc,
    history: History,
    has_history: bool,
}

impl GuidedFilter {
    /// A filter with `particles >= 2` particles.
    pub fn new(particles: usize) -> Result<Self, SmcError> {
        Ok(GuidedFilter {
            sweep: ConditionalSmc::new(particles, CsmcKernel::Plain)?,
            history: History::default(),
            has_history: false,
        })
    }

    /// Number of particles M.
    pub fn particles(&self) -> usize {
        self.sweep.particles()
    }

    /// Runs the filter on `data` with the random stream of `seed`; returns the
    /// log-likelihood estimate `log p^(y)` and keeps the history.
    ///
    /// Errors when every particle gives the data zero predictive density, and when
    /// the model returns NaN densities.
    pub fn run<M: FilterModel + TransitionDensity + GuidedProposal>(
        &mut self,
        model: &M,
        data: &Series,
        seed: u64,
    ) -> Result<f64, SmcError> {
        self.has_history = false;
        let loglik = self
            .sweep
            .filter_guided(model, data, &mut stream(seed, 0))?;
        self.sweep.write_history(&mut self.history);
        self.has_history = true;
        Ok(loglik)
    }

    /// The history of the last successful run.
    pub fn history(&self) -> Option<&History> {
        self.has_history.then_some(&self.history)
    }
}
