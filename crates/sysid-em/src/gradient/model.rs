//! What a model provides to gradient EM: the three log-densities in `theta` and their
//! gradients.

use super::GradientEmError;
use sysid_smc::{FilterModel, TransitionDensity};

/// A state-space model for EM with a numerical M-step (ALGORITHMS.md 4).
///
/// `theta` is the model's **unconstrained** parameter vector (log-variances, Cholesky
/// factors with log diagonals, ordered breakpoints as a first value and log gaps, ...);
/// the model maps it to its natural parameters ([`constrained`](Self::constrained)).
/// BFGS then needs no bounds.
///
/// The gradient methods add `d/dtheta` of the log-density into `grad` and return the
/// value. Their defaults are central finite differences of the value methods (step
/// `1e-5 max(1, |theta_i|)`); models override them with analytic gradients, which are
/// faster and exact.
pub trait GradientModel: Sync {
    /// The particle model at `theta`, for the E-step.
    type Smc: FilterModel + TransitionDensity + Sync;

    /// Number of parameters.
    fn parameter_dim(&self) -> usize;
    /// State dimension.
    fn state_dim(&self) -> usize;
    /// Names of the natural parameters (for traces and outputs).
    fn parameter_names(&self) -> Vec<String>;
    /// The natural parameters of `theta`, in the order of the names.
    fn constrained(&self, theta: &[f64]) -> Vec<f64>;
    /// The particle model at `theta`; errors on values it cannot use.
    fn smc_model(&self, theta: &[f64]) -> Result<Self::Smc, GradientEmError>;

    /// `log mu_theta(x_0)`.
    fn log_initial(&self, theta: &[f64], x: &[f64]) -> f64;
    /// `log f_theta(next | x, u_t, t)`.
    fn log_transition(&self, theta: &[f64], t: usize, x: &[f64], u: &[f64], next: &[f64]) -> f64;
    /// `log g_theta(y | x, u_t, t)` (`y` may hold NaN entries: missing).
    fn log_observation(&self, theta: &[f64], t: usize, x: &[f64], u: &[f64], y: &[f64]) -> f64;

    /// `log mu_theta(x_0)`, adding its gradient into `grad`.
    fn log_initial_gradient(&self, theta: &[f64], x: &[f64], grad: &mut [f64]) -> f64 {
        central_difference(theta, grad, |th| self.log_initial(th, x))
    }

    /// `log f_theta(next | x)`, adding its gradient into `grad`.
    fn log_transition_gradient(
        &self,
        theta: &[f64],
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        central_difference(theta, grad, |th| self.log_transition(th, t, x, u, next))
    }

    /// `log g_theta(y | x)`, adding its gradient into `grad`.
    fn log_observation_gradient(
        &self,
        theta: &[f64],
        t: usize,
        x: &[f64],
        u: &[f64],
        y: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        central_difference(theta, grad, |th| self.log_observation(th, t, x, u, y))
    }
}

/// `f(theta)`, adding the central-difference gradient of `f` into `grad`.
pub fn central_difference(theta: &[f64], grad: &mut [f64], f: impl Fn(&[f64]) -> f64) -> f64 {
    let mut shifted = theta.to_vec();
    for (i, g) in grad.iter_mut().enumerate() {
        let h = 1e-5 * theta[i].abs().max(1.0);
        shifted[i] = theta[i] + h;
        let up = f(&shifted);
        shifted[i] = theta[i] - h;
        let down = f(&shifted);
        shifted[i] = theta[i];
        *g += (up - down) / (2.0 * h);
    }
    f(theta)
}
