//! What a model provides to gradient EM: the three log-densities at given parameters
//! and, optionally, their gradients.

use super::GradientEmError;
use sysid_smc::{FilterModel, Series, Trajectories, TransitionDensity};

/// How the gradient of `Q^` is obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Gradients {
    /// The model's `*_gradient` methods (exact and cheap).
    Analytic,
    /// Central differences of `Q^` as a whole, `2 d` extra evaluations of `Q^` (step
    /// `1e-5 max(1, |theta_i|)`).
    FiniteDifferences,
}

/// A state-space model for EM with a numerical M-step (ALGORITHMS.md 4).
///
/// `theta` is the model's **unconstrained** parameter vector (log-variances, Cholesky
/// factors with log diagonals, ordered breakpoints as a first value and log gaps, ...);
/// [`unpack`](Self::unpack) turns it into whatever the densities need (once per
/// evaluation of `Q^`, not once per term), and [`constrained`](Self::constrained)
/// into the natural parameters. BFGS then needs no bounds.
///
/// The gradient methods add `d/dtheta` of the log-density into `grad` and return the
/// value; they are called only when [`gradients`](Self::gradients) says
/// [`Gradients::Analytic`]. Their defaults add nothing.
///
/// # Example
/// The AR(1) model with `theta = (phi, ln q)` (`r = 0.5` known), gradients by finite
/// differences (the default). (A model file gives this form by itself, with analytic
/// gradients: `sysid_modelfile::ModelFile::gradient`.)
/// ```
/// # use rand_distr::{Distribution, StandardNormal};
/// # use sysid_smc::*;
/// # /// x' = phi x + w (w ~ N(0, q)), y = x + e (e ~ N(0, r)), x_0 ~ N(0, 1)
/// # #[derive(Clone)]
/// # struct Ar { phi: f64, q: f64, r: f64 }
/// # impl StateSpace for Ar { fn state_dim(&self) -> usize { 1 } }
/// # impl InitialSampler for Ar {
/// #     fn sample_initial<R: rand::Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
/// #         x[0] = StandardNormal.sample(rng);
/// #     }
/// # }
/// # impl TransitionSampler for Ar {
/// #     fn sample_transition<R: rand::Rng + ?Sized>(
/// #         &self, _t: usize, x: &[f64], _u: &[f64], next: &mut [f64], rng: &mut R,
/// #     ) {
/// #         let w: f64 = StandardNormal.sample(rng);
/// #         next[0] = self.phi * x[0] + self.q.sqrt() * w;
/// #     }
/// # }
/// # impl ObservationDensity for Ar {
/// #     fn log_observation(&self, _t: usize, x: &[f64], _u: &[f64], y: &[f64]) -> f64 {
/// #         ScalarGaussianKernel::with_variance(self.r).log_density(x[0], y[0])
/// #     }
/// # }
/// # impl TransitionDensity for Ar {
/// #     fn log_transition(&self, _t: usize, x: &[f64], _u: &[f64], next: &[f64]) -> f64 {
/// #         ScalarGaussianKernel::with_variance(self.q).log_density(self.phi * x[0], next[0])
/// #     }
/// # }
/// use sysid_em::gradient::{GradientEmError, GradientModel};
/// struct ArGradient;
/// impl GradientModel for ArGradient {
///     type Smc = Ar;
///     type Params = Ar;
///     fn parameter_dim(&self) -> usize { 2 }
///     fn state_dim(&self) -> usize { 1 }
///     fn parameter_names(&self) -> Vec<String> { vec!["phi".into(), "q".into()] }
///     fn constrained(&self, theta: &[f64]) -> Vec<f64> { vec![theta[0], theta[1].exp()] }
///     fn smc_model(&self, theta: &[f64]) -> Result<Ar, GradientEmError> { Ok(self.unpack(theta)) }
///     fn unpack(&self, theta: &[f64]) -> Ar { Ar { phi: theta[0], q: theta[1].exp(), r: 0.5 } }
///     fn log_initial(&self, _p: &Ar, x: &[f64]) -> f64 {
///         ScalarGaussianKernel::with_variance(1.0).log_density(0.0, x[0])
///     }
///     fn log_transition(&self, p: &Ar, t: usize, x: &[f64], u: &[f64], next: &[f64]) -> f64 {
///         p.log_transition(t, x, u, next)
///     }
///     fn log_observation(&self, p: &Ar, t: usize, x: &[f64], u: &[f64], y: &[f64]) -> f64 {
///         p.log_observation(t, x, u, y)
///     }
/// }
/// let p = ArGradient.unpack(&[0.9, 0.0]);
/// assert_eq!(ArGradient.constrained(&[0.9, 0.0]), [0.9, 1.0]);
/// assert!(ArGradient.log_transition(&p, 0, &[1.0], &[], &[0.9]) > ArGradient.log_transition(&p, 0, &[1.0], &[], &[3.0]));
/// ```
pub trait GradientModel: Sync {
    /// The particle model at `theta`, for the E-step.
    type Smc: FilterModel + TransitionDensity + Sync;
    /// The parameters unpacked for the densities.
    type Params;

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
    /// `theta` unpacked for the densities.
    fn unpack(&self, theta: &[f64]) -> Self::Params;
    /// Whether the `*_gradient` methods are implemented. Default: finite differences.
    fn gradients(&self) -> Gradients {
        Gradients::FiniteDifferences
    }

    /// A closed-form maximiser of the dynamics terms `I1 + I2` of `Q^` on fixed
    /// trajectories, for models that have one (a linear Gaussian transition: a
    /// regression of `x_{t+1}` on `x_t`).
    ///
    /// It writes the maximiser into the dynamics' entries of `theta` and returns their
    /// indices; the M-step then maximises `I3` by BFGS over the other entries only
    /// (block-coordinate ascent, so `Q^` still cannot decrease, and each BFGS
    /// evaluation skips the transition terms). `None`, the default, leaves `theta`
    /// alone and BFGS maximises `Q^` over every entry; a model also returns `None` when
    /// the closed form does not exist for these trajectories (a singular moment
    /// matrix).
    ///
    /// Contract: `log mu` and `log f` depend on no entry outside the returned ones,
    /// and `log g` on none of them.
    fn maximise_dynamics(&self, paths: &Trajectories, theta: &mut [f64]) -> Option<Vec<usize>> {
        let _ = (paths, theta);
        None
    }

    /// An evaluator of `I3` on fixed trajectories, prepared once per M-step, for the
    /// BFGS that follows [`maximise_dynamics`](Self::maximise_dynamics) (for example
    /// from the states sorted once, so that an evaluation costs a few binary searches
    /// instead of a pass over every path and step). `None`, the default: the generic
    /// sum of [`log_observation_gradient`](Self::log_observation_gradient) terms.
    fn prepare_observations<'a>(
        &self,
        paths: &'a Trajectories,
        data: &'a Series<'a>,
    ) -> Option<Box<dyn ObservationSum + 'a>> {
        let _ = (paths, data);
        None
    }

    /// An equivalent parameter vector in the model's canonical form, applied to every
    /// M-step's result, for models with parameters the data cannot identify (a state
    /// basis): without it EM can drift along that direction until the values
    /// overflow. It must leave the distribution of the outputs unchanged (up to the
    /// initial-state prior). Default: `theta` unchanged.
    fn canonical(&self, theta: Vec<f64>) -> Vec<f64> {
        theta
    }

    /// `log mu_theta(x_0)`.
    fn log_initial(&self, p: &Self::Params, x: &[f64]) -> f64;
    /// `log f_theta(next | x, u_t, t)`.
    fn log_transition(&self, p: &Self::Params, t: usize, x: &[f64], u: &[f64], next: &[f64])
    -> f64;
    /// `log g_theta(y | x, u_t, t)` (`y` may hold NaN entries: missing).
    fn log_observation(&self, p: &Self::Params, t: usize, x: &[f64], u: &[f64], y: &[f64]) -> f64;

    /// `log mu_theta(x_0)`, adding its gradient into `grad`.
    fn log_initial_gradient(&self, p: &Self::Params, x: &[f64], grad: &mut [f64]) -> f64 {
        let _ = grad;
        self.log_initial(p, x)
    }

    /// `log f_theta(next | x)`, adding its gradient into `grad`.
    fn log_transition_gradient(
        &self,
        p: &Self::Params,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        let _ = grad;
        self.log_transition(p, t, x, u, next)
    }

    /// `log g_theta(y | x)`, adding its gradient into `grad`.
    fn log_observation_gradient(
        &self,
        p: &Self::Params,
        t: usize,
        x: &[f64],
        u: &[f64],
        y: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        let _ = grad;
        self.log_observation(p, t, x, u, y)
    }
}

/// `I3(theta) = (1/K) sum_k sum_t log g_theta(y_t | x_t^k)` on the trajectories it was
/// prepared from ([`GradientModel::prepare_observations`]).
///
/// # Example
/// For `y = x + e`, `e ~ N(0, exp(z))`, with `z` the model's only observation
/// parameter (entry 1 of `theta`), `I3` depends on the paths only through the mean
/// squared residual, computed once:
/// ```
/// use sysid_em::gradient::ObservationSum;
/// struct Residuals { mean_square: f64, count: f64 }
/// impl ObservationSum for Residuals {
///     fn value_and_gradient(&self, theta: &[f64], grad: &mut [f64]) -> f64 {
///         let (r, n) = (theta[1].exp(), self.count);
///         grad.fill(0.0);
///         grad[1] = -0.5 * n + 0.5 * n * self.mean_square / r;
///         -0.5 * n * ((2.0 * std::f64::consts::PI * r).ln() + self.mean_square / r)
///     }
///     fn maximise(&self, theta: &mut [f64]) -> bool {
///         theta[1] = self.mean_square.ln(); // r = the mean squared residual
///         true
///     }
/// }
/// let sum = Residuals { mean_square: 0.5, count: 100.0 };
/// let mut theta = [0.9, 0.0];
/// assert!(sum.maximise(&mut theta));
/// let mut grad = [0.0; 2];
/// sum.value_and_gradient(&theta, &mut grad);
/// assert!(grad[1].abs() < 1e-12);
/// ```
pub trait ObservationSum {
    /// `I3(theta)`, adding its gradient into `grad` (all of `theta`'s entries).
    fn value_and_gradient(&self, theta: &[f64], grad: &mut [f64]) -> f64;

    /// Sets `theta`'s observation entries to the exact maximiser of `I3`, where it has
    /// one, and says whether it did (then the M-step needs no BFGS). Default: `false`,
    /// `theta` untouched.
    fn maximise(&self, theta: &mut [f64]) -> bool {
        let _ = theta;
        false
    }
}

/// `f(theta)`, writing the central-difference gradient of `f` into `grad` (step
/// `1e-5 max(1, |theta_i|)`).
pub fn central_difference(theta: &[f64], grad: &mut [f64], f: impl Fn(&[f64]) -> f64) -> f64 {
    let mut shifted = theta.to_vec();
    for (i, g) in grad.iter_mut().enumerate() {
        let h = 1e-5 * theta[i].abs().max(1.0);
        shifted[i] = theta[i] + h;
        let up = f(&shifted);
        shifted[i] = theta[i] - h;
        let down = f(&shifted);
        shifted[i] = theta[i];
        *g = (up - down) / (2.0 * h);
    }
    f(theta)
}
