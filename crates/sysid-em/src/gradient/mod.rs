//! EM with a numerical M-step for models that are not affine in their parameters
//! (seed 001: Schön, Wills and Ninness; ALGORITHMS.md 4).
//!
//! # Model
//! Any [`GradientModel`]: `x_0 ~ mu_theta`, `x_{t+1} ~ f_theta(. | x_t)`,
//! `y_t ~ g_theta(. | x_t)`, with the log-densities (and, optionally, their gradients)
//! in the unconstrained parameters `theta`.
//!
//! # Algorithm
//! Iteration `k` at `theta_k`:
//! 1. **E-step.** Run the bootstrap filter (M particles, history kept) and draw `K`
//!    backward trajectories with a smoother of `sysid-smc` (FFBSi or rejection FFBSi).
//!    They stay fixed for the whole M-step, so `Q^` is a deterministic function.
//! 2. **M-step.** Maximise `Q^(theta) = I1 + I2 + I3` ([`q_hat`]) by BFGS with the
//!    More-Thuente line search (argmin), from `theta_k` ([`m_step`]); the value and
//!    gradient are computed in one pass and cached, and BFGS starts from the previous
//!    M-step's inverse-Hessian estimate (the identity at first). `Q^` never decreases
//!    within an M-step.
//!
//! A model whose dynamics are linear Gaussian can give their closed-form maximiser
//! ([`GradientModel::maximise_dynamics`]; the blind Wiener model does): the M-step then
//! sets the dynamics by least squares on the fixed trajectories and runs BFGS on `I3`
//! over the remaining parameters only. On fixed trajectories `I1 + I2` and `I3`
//! depend on disjoint parameters, so this reaches the same maximiser as BFGS over
//! everything, exactly in the dynamics and with fewer and cheaper evaluations. A
//! model can also prepare `I3` once per M-step
//! ([`GradientModel::prepare_observations`]; the Wiener model sorts the states), and
//! give `I3`'s exact maximiser (`ObservationSum::maximise`): then the M-step is exact
//! and needs no BFGS (`MStepOptions::exact_observations`).
//! Iteration `k` draws from the random
//! streams `(seed, 2k)` (filter) and `(seed, 2k + 1)` (smoother). The trace value is the
//! filter's log-likelihood estimate at `theta_k`; the E-step is noisy, so the runner
//! counts decreases instead of stopping on them.
//!
//! # Complexity
//! Per iteration: the filter O(T M), the smoother O(T K M) (FFBSi) or expected O(T K)
//! (rejection), and O(T K d) per `Q^` evaluation with analytic gradients (O(T K d^2)
//! with finite differences), times the BFGS evaluations.
//!
//! # References
//! Schön, Wills and Ninness (2011), *System identification of nonlinear state-space
//! models*, Automatica; Lindsten and Schön (2013); Nocedal and Wright (2006).

mod direct;
mod model;
mod mstep;
mod objective;

pub use direct::{
    DirectFit, DirectOptions, DirectStart, DirectWarning, NOISY_SD, RIVAL_NATS, fit_direct,
};
pub use model::{GradientModel, Gradients, ObservationSum, central_difference};
pub use mstep::{MStepOptions, MStepOutcome, m_step};
pub use objective::q_hat;

use crate::EmAlgorithm;
use crate::particle_pass::{Guide, ParticlePass, guide};
use sysid_smc::{GuidedProposal, Series, SmcError, Smoother};

/// Errors of gradient EM.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GradientEmError {
    /// The particle filter or smoother failed.
    #[error("{0}")]
    Smc(#[from] SmcError),
    /// Parameters the model cannot use.
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    /// An option is out of range.
    #[error("invalid option: {0}")]
    InvalidOption(String),
    /// `Q^` is not finite at the current parameters (the trajectories are impossible
    /// under them).
    #[error("Q^ is not finite at theta = {theta:?}")]
    NonFiniteQ {
        /// The parameters.
        theta: Vec<f64>,
    },
}

/// Gradient EM as an [`EmAlgorithm`] for the shared runner; the estimate is the
/// unconstrained parameter vector.
pub struct GradientEm<'a, G: GradientModel, S> {
    model: &'a G,
    data: Series<'a>,
    smoother: S,
    pass: ParticlePass,
    guide: Option<Guide<G::Smc>>,
    options: MStepOptions,
    last: Option<MStepOutcome>,
    hold_dynamics_for: usize,
    steps_done: usize,
}

impl<'a, G: GradientModel, S: Smoother<G::Smc>> GradientEm<'a, G, S> {
    /// Gradient EM on `data` with a `particles`-particle filter and `smoother` (which
    /// sets the number of trajectories).
    pub fn new(
        model: &'a G,
        data: Series<'a>,
        particles: usize,
        smoother: S,
        options: MStepOptions,
        seed: u64,
    ) -> Result<Self, GradientEmError> {
        Ok(GradientEm {
            model,
            data,
            smoother,
            pass: ParticlePass::new(particles, seed)?,
            guide: None,
            options,
            last: None,
            hold_dynamics_for: 0,
            steps_done: 0,
        })
    }

    /// Holds the dynamics at their starting values for the first `iterations`
    /// M-steps (see [`MStepOptions::hold_dynamics`]), so that a poor first E-step
    /// (the observation model far off) does not drag a good linear start (N4SID's)
    /// along; later M-steps update everything. Each held M-step is still a
    /// generalised EM step (`Q^` does not decrease).
    pub fn hold_dynamics_for(mut self, iterations: usize) -> Self {
        self.hold_dynamics_for = iterations;
        self
    }

    /// Runs the E-step's filter fully adapted ([`sysid_smc::GuidedFilter`]) instead of
    /// bootstrap, for a model with a tractable locally optimal proposal: its particles
    /// are drawn where the observations allow, which keeps a small particle system on
    /// the state when the output noise is small compared with the process noise (the
    /// blind Wiener model). The final log-likelihood uses the same filter.
    pub fn with_guided_filter(mut self) -> Self
    where
        G::Smc: GuidedProposal,
    {
        self.guide = Some(guide::<G::Smc>());
        self
    }

    /// What the last M-step did.
    pub fn last_m_step(&self) -> Option<&MStepOutcome> {
        self.last.as_ref()
    }
}

impl<G: GradientModel, S: Smoother<G::Smc>> EmAlgorithm for GradientEm<'_, G, S> {
    type Estimate = Vec<f64>;
    type Error = GradientEmError;

    fn step(&mut self, current: &Vec<f64>) -> Result<(Vec<f64>, f64), GradientEmError> {
        if current.len() != self.model.parameter_dim() {
            return Err(GradientEmError::InvalidParams(format!(
                "{} parameters given, the model has {}",
                current.len(),
                self.model.parameter_dim()
            )));
        }
        let smc = self.model.smc_model(current)?;
        let pass = self.pass.run(&smc, &self.data, self.guide)?;
        let loglik = pass.loglik;
        let (paths, _) =
            self.smoother
                .trajectories(&smc, pass.history, &self.data, pass.smoother_seed)?;
        let warm = self.last.as_mut().and_then(|m| m.inverse_hessian.take());
        let options = MStepOptions {
            hold_dynamics: self.options.hold_dynamics || self.steps_done < self.hold_dynamics_for,
            ..self.options
        };
        self.steps_done += 1;
        let outcome = m_step(self.model, &paths, &self.data, current, &options, warm)?;
        let next = self.model.canonical(outcome.theta.clone());
        self.last = Some(outcome);
        Ok((next, loglik))
    }

    fn loglik(&mut self, estimate: &Vec<f64>) -> Result<f64, GradientEmError> {
        let smc = self.model.smc_model(estimate)?;
        Ok(self.pass.loglik(&smc, &self.data, self.guide)?)
    }

    fn is_exact(&self) -> bool {
        false
    }
}
