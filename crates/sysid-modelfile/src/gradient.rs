//! Any model file in the form of gradient EM (`sysid_em::gradient`, seed 001): the
//! M-step maximises the particle approximation of `Q` by BFGS over the free
//! parameters on their unconstrained scale (`ln v` for a positive one, a logit for
//! one with bounds).
//!
//! # Algorithm
//! The three log-densities are those of [`ExprSmc`] at the parameters; `Q`'s gradient
//! is by central differences (`Gradients::FiniteDifferences`).

use crate::{ExprSmc, ModelFile};
use sysid_em::gradient::{GradientEmError, GradientModel};
use sysid_pmcmc::{ModelFamily, Support};

/// A model file for gradient EM (see the module documentation).
#[derive(Debug, Clone)]
pub struct ExprGradient {
    file: ModelFile,
    supports: Vec<Support>,
}

impl ExprGradient {
    pub(crate) fn new(file: ModelFile) -> ExprGradient {
        let supports = file.supports();
        ExprGradient { file, supports }
    }

    /// The unconstrained vector of the free parameters `values` (each inside its
    /// bounds).
    pub fn unconstrained(&self, values: &[f64]) -> Vec<f64> {
        self.supports
            .iter()
            .zip(values)
            .map(|(s, &v)| s.to_unconstrained(v))
            .collect()
    }

    /// The model file.
    pub fn file(&self) -> &ModelFile {
        &self.file
    }
}

impl GradientModel for ExprGradient {
    type Smc = ExprSmc;
    /// The model at the parameters, or `None` where they give an invalid law (a
    /// variance expression that is not positive): its densities are then `-inf`.
    type Params = Option<ExprSmc>;

    fn parameter_dim(&self) -> usize {
        self.supports.len()
    }
    fn state_dim(&self) -> usize {
        self.file.spec().states.len()
    }
    fn parameter_names(&self) -> Vec<String> {
        self.file.free_names()
    }
    fn constrained(&self, theta: &[f64]) -> Vec<f64> {
        self.supports
            .iter()
            .zip(theta)
            .map(|(s, &z)| s.from_unconstrained(z).0)
            .collect()
    }
    fn smc_model(&self, theta: &[f64]) -> Result<ExprSmc, GradientEmError> {
        self.file
            .at(&self.constrained(theta))
            .map_err(GradientEmError::InvalidParams)
    }
    fn unpack(&self, theta: &[f64]) -> Option<ExprSmc> {
        self.file.at(&self.constrained(theta)).ok()
    }

    fn log_initial(&self, p: &Option<ExprSmc>, x: &[f64]) -> f64 {
        use sysid_smc::InitialDensity;
        p.as_ref().map_or(f64::NEG_INFINITY, |m| m.log_initial(x))
    }
    fn log_transition(
        &self,
        p: &Option<ExprSmc>,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &[f64],
    ) -> f64 {
        use sysid_smc::TransitionDensity;
        p.as_ref()
            .map_or(f64::NEG_INFINITY, |m| m.log_transition(t, x, u, next))
    }
    fn log_observation(
        &self,
        p: &Option<ExprSmc>,
        t: usize,
        x: &[f64],
        u: &[f64],
        y: &[f64],
    ) -> f64 {
        use sysid_smc::ObservationDensity;
        p.as_ref()
            .map_or(f64::NEG_INFINITY, |m| m.log_observation(t, x, u, y))
    }
}
