//! `lgss` for gradient EM: `theta = (phi, ln q, ln r)` with analytic gradients.

use nalgebra::dmatrix;
use sysid_em::gradient::{GradientEmError, GradientModel, Gradients};
use sysid_kalman::LinearGaussianModel;

use crate::LinearGaussianSmc;

const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// The scalar linear Gaussian model with unconstrained parameters
/// `theta = (phi, ln q, ln r)` (or `(phi, ln q)` with `r` fixed) and analytic
/// gradients, the exact reference case of gradient EM.
///
/// # Model
/// ```text
/// x_{t+1} = phi x_t + w_t,  w_t ~ N(0, q)
/// y_t     = x_t + e_t,      e_t ~ N(0, r),     x_0 ~ N(0, p1)
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LgssGradient {
    /// Variance of `x_0` (fixed).
    pub p1: f64,
    /// `Some(r)` holds the measurement variance fixed; `None` estimates it.
    pub fixed_r: Option<f64>,
}

impl LgssGradient {
    fn r(&self, theta: &[f64]) -> f64 {
        self.fixed_r.unwrap_or_else(|| theta[2].exp())
    }

    /// The linear Gaussian model at `theta`.
    pub fn linear_model(&self, theta: &[f64]) -> Result<LinearGaussianModel, GradientEmError> {
        LinearGaussianModel::builder(
            dmatrix![theta[0]],
            dmatrix![1.0],
            dmatrix![theta[1].exp()],
            dmatrix![self.r(theta)],
        )
        .p1(dmatrix![self.p1])
        .build()
        .map_err(|e| GradientEmError::InvalidParams(e.to_string()))
    }
}

/// [`LgssGradient`]'s parameters unpacked: `phi`, `1/q`, `ln q`, `r`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LgssParams {
    phi: f64,
    inv_q: f64,
    ln_q: f64,
    r: f64,
}

impl GradientModel for LgssGradient {
    type Smc = LinearGaussianSmc;
    type Params = LgssParams;

    fn unpack(&self, theta: &[f64]) -> LgssParams {
        LgssParams {
            phi: theta[0],
            inv_q: (-theta[1]).exp(),
            ln_q: theta[1],
            r: self.r(theta),
        }
    }

    fn gradients(&self) -> Gradients {
        Gradients::Analytic
    }

    fn parameter_dim(&self) -> usize {
        if self.fixed_r.is_some() { 2 } else { 3 }
    }

    fn state_dim(&self) -> usize {
        1
    }

    fn parameter_names(&self) -> Vec<String> {
        let names: &[&str] = if self.fixed_r.is_some() {
            &["phi", "q"]
        } else {
            &["phi", "q", "r"]
        };
        names.iter().map(|s| s.to_string()).collect()
    }

    fn constrained(&self, theta: &[f64]) -> Vec<f64> {
        let mut out = vec![theta[0], theta[1].exp()];
        if self.fixed_r.is_none() {
            out.push(theta[2].exp());
        }
        out
    }

    fn smc_model(&self, theta: &[f64]) -> Result<LinearGaussianSmc, GradientEmError> {
        LinearGaussianSmc::new(&self.linear_model(theta)?)
            .map_err(|e| GradientEmError::InvalidParams(e.to_string()))
    }

    fn log_initial(&self, _p: &LgssParams, x: &[f64]) -> f64 {
        -0.5 * (LN_2PI + self.p1.ln()) - 0.5 * x[0] * x[0] / self.p1
    }

    fn log_transition(
        &self,
        p: &LgssParams,
        _t: usize,
        x: &[f64],
        _u: &[f64],
        next: &[f64],
    ) -> f64 {
        let e = next[0] - p.phi * x[0];
        -0.5 * (LN_2PI + p.ln_q) - 0.5 * e * e * p.inv_q
    }

    fn log_observation(&self, p: &LgssParams, _t: usize, x: &[f64], _u: &[f64], y: &[f64]) -> f64 {
        let e = y[0] - x[0];
        -0.5 * (LN_2PI + p.r.ln()) - 0.5 * e * e / p.r
    }

    fn log_transition_gradient(
        &self,
        p: &LgssParams,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        let e = next[0] - p.phi * x[0];
        grad[0] += e * x[0] * p.inv_q;
        grad[1] += -0.5 + 0.5 * e * e * p.inv_q;
        self.log_transition(p, t, x, u, next)
    }

    fn log_observation_gradient(
        &self,
        p: &LgssParams,
        t: usize,
        x: &[f64],
        u: &[f64],
        y: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        if self.fixed_r.is_none() {
            let e = y[0] - x[0];
            grad[2] += -0.5 + 0.5 * e * e / p.r;
        }
        self.log_observation(p, t, x, u, y)
    }
}
