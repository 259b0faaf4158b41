//! EM for nonlinear models affine in the parameters, with a particle-smoother E-step
//! (Schön, Wills and Ninness 2006).
//!
//! # Model
//! ```text
//! xi_t = [x_{t+1}; y_t] = beta alpha(x_t, u_t, t) + eta_t,  eta_t ~ N(0, blockdiag(Pi_x, Pi_y))
//! x_0 ~ N(mu, P1)
//! ```
//!
//! # Algorithm
//! Each iteration runs the bootstrap particle filter at the current parameters (its
//! log-likelihood estimate is the iteration's trace value), then a particle smoother
//! of `sysid-smc` through the additive-functional interface, accumulating the
//! smoothed second moments of `[alpha_t; x_{t+1}]` and `[alpha_t; y_t]`
//! ([`AffineStatistics`]), and the closed-form M-step ([`m_step`]). Iteration `k` uses
//! the random streams `(seed, 2k)` (filter) and `(seed, 2k + 1)` (smoother), so a run
//! is reproducible. The E-step is noisy, so the runner counts likelihood decreases
//! instead of stopping on them; use `tol = 0` for a fixed number of iterations.
//!
//! # Complexity
//! Per iteration: the filter O(T M) plus the smoother (Tanizaki O(T M^2), rejection
//! FFBSi expected O(T K)), plus O(T K (n_alpha + n)^2) for the statistics.
//!
//! # References
//! Schön, Wills and Ninness (2006), "Maximum likelihood nonlinear system estimation";
//! ALGORITHMS.md 3.

mod constraints;
mod fit;
mod model;
mod moments;
mod mstep;
mod overrelax;
mod polish;
mod psaem;
mod robust;
mod stats;

pub use constraints::{AffineConstraints, CoefficientSlot, TiedCoefficient};
pub use fit::{
    AffineFit, AffineFitOptions, AffineFitReport, AffineMethod, CheckedAffineFitOptions, fit_affine,
};
pub use model::{AffineModel, AffineParams, free_structure};
pub use mstep::m_step;
pub use polish::{CLIMB_GAIN, CLIMB_SDS, CURVATURE_ROUNDS, Polish, PolishCurvature};
pub use psaem::{Psaem, StepSizes};
pub use robust::{
    Extrapolation, LocalMaximum, RefineStop, RobustFit, RobustOptions, RobustTiming, StartOutcome,
    StartStatus, describe, fit_robust, fit_robust_until,
};
pub use stats::{AffineStatistics, StatisticsCollector};

use crate::EmAlgorithm;
use crate::linear::Covariance;
use crate::particle_pass::ParticlePass;
use sysid_smc::{Series, SmcError, Smoother};

/// Errors of affine EM.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum AffineEmError {
    /// The particle filter or smoother failed.
    #[error("{0}")]
    Smc(#[from] SmcError),
    /// A statistics matrix could not be factored.
    #[error("{0}")]
    Linalg(#[from] sysid_linalg::LinalgError),
    /// A block had no steps (e.g. every output missing).
    #[error("the {block} have no steps")]
    NoSteps {
        /// Which block.
        block: &'static str,
    },
    /// Parameters the model cannot use (a non-positive variance, wrong shapes).
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    /// An option out of its range.
    #[error("{name}: {reason}")]
    InvalidOption {
        /// The option, as [`AffineFitOptions`] spells it.
        name: &'static str,
        /// What is wrong with its value.
        reason: String,
    },
    /// A combination the closed-form M-step does not cover.
    #[error("unsupported: {0}")]
    Unsupported(String),
}

/// What affine EM estimates besides `beta`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AffineEmSpec {
    /// Estimate the state coefficients `beta_x` (else held at their current value).
    pub beta_x: bool,
    /// Estimate the output coefficients `beta_y`.
    pub beta_y: bool,
    /// Structure of the process-noise covariance (full, diagonal or fixed).
    pub pi_x: Covariance,
    /// Structure of the measurement-noise covariance.
    pub pi_y: Covariance,
    /// Estimate `mu` and `P1`.
    pub initial_state: bool,
}

impl Default for AffineEmSpec {
    /// Coefficients and diagonal noise covariances estimated, the initial state fixed.
    fn default() -> Self {
        AffineEmSpec {
            beta_x: true,
            beta_y: true,
            pi_x: Covariance::Diagonal,
            pi_y: Covariance::Diagonal,
            initial_state: false,
        }
    }
}

/// Affine EM as an [`EmAlgorithm`] for the shared runner.
pub struct AffineEm<'a, A, S> {
    model: &'a A,
    data: Series<'a>,
    smoother: S,
    spec: AffineEmSpec,
    pass: ParticlePass,
}

impl<'a, A: AffineModel, S: Smoother<A::Smc>> AffineEm<'a, A, S> {
    /// EM on `data` with `particles` filter particles (systematic resampling at every
    /// step) and the smoother `smoother`.
    pub fn new(
        model: &'a A,
        data: Series<'a>,
        particles: usize,
        smoother: S,
        spec: AffineEmSpec,
        seed: u64,
    ) -> Result<Self, AffineEmError> {
        if data.output_dim() != model.output_dim() {
            return Err(AffineEmError::InvalidParams(format!(
                "the data have {} outputs but the model has {}",
                data.output_dim(),
                model.output_dim()
            )));
        }
        Ok(AffineEm {
            model,
            data,
            smoother,
            spec,
            pass: ParticlePass::new(particles, seed)?,
        })
    }

    /// The E-step at `params`: the filter's log-likelihood estimate and the smoothed
    /// statistics.
    pub fn e_step(
        &mut self,
        params: &AffineParams,
    ) -> Result<(f64, AffineStatistics), AffineEmError> {
        let smc = self.model.smc_model(params)?;
        let pass = self.pass.run(&smc, &self.data, None)?;
        let mut collector = StatisticsCollector::new(self.model, &self.data);
        self.smoother.additive(
            &smc,
            pass.history,
            &self.data,
            pass.smoother_seed,
            &mut collector,
        )?;
        Ok((pass.loglik, collector.finish()))
    }
}

impl<A: AffineModel, S: Smoother<A::Smc>> EmAlgorithm for AffineEm<'_, A, S> {
    type Estimate = AffineParams;
    type Error = AffineEmError;

    fn step(&mut self, current: &AffineParams) -> Result<(AffineParams, f64), AffineEmError> {
        let (loglik, stats) = self.e_step(current)?;
        let next = m_step(self.model, &stats, current, &self.spec)?;
        Ok((next, loglik))
    }

    fn loglik(&mut self, estimate: &AffineParams) -> Result<f64, AffineEmError> {
        let smc = self.model.smc_model(estimate)?;
        Ok(self.pass.loglik(&smc, &self.data, None)?)
    }

    fn is_exact(&self) -> bool {
        false
    }
}
