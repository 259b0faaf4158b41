//! Your own model in Rust, with one impl: a state-space model with additive Gaussian
//! noise given by its mean maps, its noise variances and its initial law
//! ([`GaussianModel`]); [`Gaussian`] then gives every capability: the SMC model at a
//! parameter vector (filters, smoothers), the PMMH family and the gradient-EM form
//! (gradients by central differences).
//!
//! # Model
//! ```text
//! x_{t+1} = f(x_t, u_t, t; theta) + w_t,   w_t ~ N(0, diag q(theta))
//! y_t     = g(x_t, u_t, t; theta) + e_t,   e_t ~ N(0, diag r(theta))
//! x_0     ~ N(m(theta), diag p(theta))
//! ```
//! For equations that fit in a model file, [`ModelFile`](crate::ModelFile) does the
//! same and more (closed-form particle EM when affine, analytic gradients, compiled
//! evaluation over all particles); this is for what the file format cannot say (loops,
//! tables, an ODE solver inside `f`).

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use sysid_em::gradient::{GradientEmError, GradientModel};
use sysid_pmcmc::{ModelFamily, Support};
use sysid_smc::ModelError;
use sysid_smc::{
    InitialDensity, InitialSampler, ObservationDensity, ScalarGaussianKernel, StateSpace,
    TransitionBound, TransitionDensity, TransitionSampler,
};

/// A model with additive Gaussian noise, by its maps (see the module documentation).
/// `theta` is the vector of [`parameter_names`](Self::parameter_names).
///
/// # Example
/// A pendulum with friction, angle measured, `theta = (g/l, b, r)`:
/// ```
/// use sysid_modelfile::{Gaussian, GaussianModel};
/// use sysid_pmcmc::{ModelFamily, Support};
/// use sysid_smc::{FilterOptions, ParticleFilter, Series};
///
/// struct Pendulum;
/// impl GaussianModel for Pendulum {
///     fn state_dim(&self) -> usize { 2 }
///     fn output_dim(&self) -> usize { 1 }
///     fn parameter_names(&self) -> Vec<String> {
///         ["g_over_l", "b", "r"].map(String::from).to_vec()
///     }
///     fn supports(&self) -> Vec<Support> {
///         vec![Support::Positive, Support::Positive, Support::Positive]
///     }
///     fn transition_mean(&self, th: &[f64], _t: usize, x: &[f64], _u: &[f64], out: &mut [f64]) {
///         let dt = 0.05;
///         out[0] = x[0] + dt * x[1];
///         out[1] = x[1] - dt * (th[0] * x[0].sin() + th[1] * x[1]);
///     }
///     fn observation_mean(&self, _th: &[f64], _t: usize, x: &[f64], _u: &[f64], out: &mut [f64]) {
///         out[0] = x[0];
///     }
///     fn process_variances(&self, _th: &[f64], out: &mut [f64]) { out.copy_from_slice(&[1e-4, 1e-2]); }
///     fn measurement_variances(&self, th: &[f64], out: &mut [f64]) { out[0] = th[2]; }
///     fn initial(&self, _th: &[f64], mean: &mut [f64], var: &mut [f64]) {
///         mean.copy_from_slice(&[1.0, 0.0]);
///         var.copy_from_slice(&[0.01, 0.01]);
///     }
/// }
///
/// let family = Gaussian::new(Pendulum);
/// let truth = family.model(&[9.81, 0.5, 0.01])?; // every capability, from the one impl
/// let (_, y) = truth.simulate(200, &[], 3)?;
/// let mut pf = ParticleFilter::new(FilterOptions { particles: 500, ..Default::default() })?;
/// assert!(pf.run(&truth, &Series::new(&y, 1)?, 1)?.loglik.is_finite());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait GaussianModel: Send + Sync {
    /// Dimension of `x`.
    fn state_dim(&self) -> usize;
    /// Dimension of `y`.
    fn output_dim(&self) -> usize;
    /// Dimension of `u` (default 0).
    fn input_dim(&self) -> usize {
        0
    }
    /// The parameter names, in the order of `theta`.
    fn parameter_names(&self) -> Vec<String>;
    /// Where each parameter lives (default: the real line); PMMH and gradient EM move
    /// on the unconstrained scale.
    fn supports(&self) -> Vec<Support> {
        vec![Support::Real; self.parameter_names().len()]
    }
    /// Writes `f(x, u, t; theta)` into `out`.
    fn transition_mean(&self, theta: &[f64], t: usize, x: &[f64], u: &[f64], out: &mut [f64]);
    /// Writes `g(x, u, t; theta)` into `out`.
    fn observation_mean(&self, theta: &[f64], t: usize, x: &[f64], u: &[f64], out: &mut [f64]);
    /// Writes the process-noise variances `q(theta)` (positive) into `out`.
    fn process_variances(&self, theta: &[f64], out: &mut [f64]);
    /// Writes the measurement-noise variances `r(theta)` (positive) into `out`.
    fn measurement_variances(&self, theta: &[f64], out: &mut [f64]);
    /// Writes the initial law's means and variances (non-negative; 0 is a point mass).
    fn initial(&self, theta: &[f64], mean: &mut [f64], var: &mut [f64]);
}

/// Every capability of a [`GaussianModel`]: a [`ModelFamily`] (PMMH, particle Gibbs),
/// a [`GradientModel`] (gradient EM, central differences on the unconstrained scale),
/// and through [`model`](ModelFamily::model) the SMC model at a parameter vector.
#[derive(Clone)]
pub struct Gaussian<M> {
    model: std::sync::Arc<M>,
}

impl<M: GaussianModel> std::fmt::Debug for Gaussian<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gaussian")
            .field("parameters", &self.model.parameter_names())
            .finish()
    }
}

impl<M: GaussianModel> std::fmt::Debug for GaussianSmc<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GaussianSmc")
            .field("parameters", &self.model.parameter_names())
            .field("theta", &self.theta)
            .finish()
    }
}

impl<M: GaussianModel> Gaussian<M> {
    /// Wraps `model`.
    pub fn new(model: M) -> Gaussian<M> {
        Gaussian {
            model: std::sync::Arc::new(model),
        }
    }

    /// The unconstrained vector of `theta` (each inside its support).
    pub fn unconstrained(&self, theta: &[f64]) -> Vec<f64> {
        self.model
            .supports()
            .iter()
            .zip(theta)
            .map(|(s, &v)| s.to_unconstrained(v))
            .collect()
    }
}

/// A [`GaussianModel`] at one parameter vector: the SMC model.
pub struct GaussianSmc<M> {
    model: std::sync::Arc<M>,
    theta: Vec<f64>,
    process: Vec<ScalarGaussianKernel>,
    process_sd: Vec<f64>,
    measurement: Vec<ScalarGaussianKernel>,
    measurement_sd: Vec<f64>,
    initial_mean: Vec<f64>,
    initial_var: Vec<f64>,
}

impl<M: GaussianModel> GaussianSmc<M> {
    fn new(model: std::sync::Arc<M>, theta: &[f64]) -> Result<GaussianSmc<M>, ModelError> {
        let names = model.parameter_names();
        if theta.len() != names.len() {
            return Err(format!(
                "{} parameters given, the model has {} ({})",
                theta.len(),
                names.len(),
                names.join(", ")
            )
            .into());
        }
        for ((name, s), &v) in names.iter().zip(model.supports()).zip(theta) {
            if !s.contains(v) {
                return Err(format!("{name} = {v} is outside its support {s:?}").into());
            }
        }
        let (n, p) = (model.state_dim(), model.output_dim());
        let mut q = vec![0.0; n];
        let mut r = vec![0.0; p];
        model.process_variances(theta, &mut q);
        model.measurement_variances(theta, &mut r);
        if let Some(v) = q.iter().chain(&r).find(|v| !(**v > 0.0 && v.is_finite())) {
            return Err(format!("a noise variance is {v}; each must be positive").into());
        }
        let (mut m, mut p1) = (vec![0.0; n], vec![0.0; n]);
        model.initial(theta, &mut m, &mut p1);
        if m.iter().chain(&p1).any(|v| !v.is_finite()) || p1.iter().any(|&v| v < 0.0) {
            return Err("the initial law needs finite means and non-negative variances".into());
        }
        let kernels = |v: &[f64]| {
            v.iter()
                .map(|&v| ScalarGaussianKernel::with_variance(v))
                .collect()
        };
        Ok(GaussianSmc {
            process: kernels(&q),
            process_sd: q.iter().map(|v| v.sqrt()).collect(),
            measurement: kernels(&r),
            measurement_sd: r.iter().map(|v| v.sqrt()).collect(),
            initial_mean: m,
            initial_var: p1,
            theta: theta.to_vec(),
            model,
        })
    }

    /// Simulates `steps` samples with the inputs `inputs` (time-major, `steps x m`)
    /// from the random stream `(seed, 0)`; returns the states and outputs, time-major.
    ///
    /// # Errors
    /// `inputs` of the wrong length, or a value that is not finite (the step).
    pub fn simulate(
        &self,
        steps: usize,
        inputs: &[f64],
        seed: u64,
    ) -> Result<(Vec<f64>, Vec<f64>), ModelError> {
        let observation = |t: usize, x: &[f64], u: &[f64], out: &mut [f64]| {
            self.model.observation_mean(&self.theta, t, x, u, out)
        };
        let inputs = (steps, inputs, self.model.input_dim());
        crate::shared::simulate(self, inputs, &self.measurement_sd, seed, observation)
    }
}

impl<M: GaussianModel> StateSpace for GaussianSmc<M> {
    fn state_dim(&self) -> usize {
        self.model.state_dim()
    }
}

impl<M: GaussianModel> InitialSampler for GaussianSmc<M> {
    fn sample_initial<R: Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
        for ((xi, &m), &v) in x.iter_mut().zip(&self.initial_mean).zip(&self.initial_var) {
            let z: f64 = StandardNormal.sample(rng);
            *xi = m + v.sqrt() * z;
        }
    }
}

impl<M: GaussianModel> InitialDensity for GaussianSmc<M> {
    fn log_initial(&self, x: &[f64]) -> f64 {
        crate::shared::log_initial(x, &self.initial_mean, &self.initial_var)
    }
}

impl<M: GaussianModel> TransitionSampler for GaussianSmc<M> {
    fn sample_transition<R: Rng + ?Sized>(
        &self,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
        rng: &mut R,
    ) {
        self.model.transition_mean(&self.theta, t, x, u, next);
        for (xn, sd) in next.iter_mut().zip(&self.process_sd) {
            let z: f64 = StandardNormal.sample(rng);
            *xn += sd * z;
        }
    }
}

impl<M: GaussianModel> ObservationDensity for GaussianSmc<M> {
    fn log_observation(&self, t: usize, x: &[f64], u: &[f64], y: &[f64]) -> f64 {
        let mut mean = vec![0.0; y.len()];
        self.model.observation_mean(&self.theta, t, x, u, &mut mean);
        mean.iter()
            .zip(y)
            .zip(&self.measurement)
            .filter(|((_, y), _)| !y.is_nan())
            .map(|((&g, &y), k)| k.log_density(g, y))
            .sum()
    }
}

impl<M: GaussianModel> TransitionDensity for GaussianSmc<M> {
    fn log_transition(&self, t: usize, x: &[f64], u: &[f64], next: &[f64]) -> f64 {
        let mut mean = vec![0.0; next.len()];
        self.model.transition_mean(&self.theta, t, x, u, &mut mean);
        mean.iter()
            .zip(next)
            .zip(&self.process)
            .map(|((&f, &xn), k)| k.log_density(f, xn))
            .sum()
    }
}

impl<M: GaussianModel> TransitionBound for GaussianSmc<M> {
    fn log_transition_bound(&self, _t: usize, _u: &[f64]) -> f64 {
        self.process.iter().map(|k| k.log_norm).sum()
    }
}

impl<M: GaussianModel> ModelFamily for Gaussian<M> {
    type Model = GaussianSmc<M>;

    fn parameter_names(&self) -> Vec<String> {
        self.model.parameter_names()
    }
    fn supports(&self) -> Vec<Support> {
        self.model.supports()
    }
    fn model(&self, theta: &[f64]) -> Result<GaussianSmc<M>, ModelError> {
        GaussianSmc::new(self.model.clone(), theta)
    }
}

impl<M: GaussianModel> GradientModel for Gaussian<M> {
    type Smc = GaussianSmc<M>;
    /// The model at the parameters (`None` where they are not admissible: densities
    /// `-inf`).
    type Params = Option<GaussianSmc<M>>;

    fn parameter_dim(&self) -> usize {
        self.model.parameter_names().len()
    }
    fn state_dim(&self) -> usize {
        self.model.state_dim()
    }
    fn parameter_names(&self) -> Vec<String> {
        self.model.parameter_names()
    }
    fn constrained(&self, theta: &[f64]) -> Vec<f64> {
        self.model
            .supports()
            .iter()
            .zip(theta)
            .map(|(s, &z)| s.from_unconstrained(z).0)
            .collect()
    }
    fn smc_model(&self, theta: &[f64]) -> Result<GaussianSmc<M>, GradientEmError> {
        self.model(&self.constrained(theta))
            .map_err(|e| GradientEmError::InvalidParams(e.reason))
    }
    fn unpack(&self, theta: &[f64]) -> Option<GaussianSmc<M>> {
        self.model(&self.constrained(theta)).ok()
    }
    fn log_initial(&self, p: &Option<GaussianSmc<M>>, x: &[f64]) -> f64 {
        p.as_ref().map_or(f64::NEG_INFINITY, |m| m.log_initial(x))
    }
    fn log_transition(
        &self,
        p: &Option<GaussianSmc<M>>,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &[f64],
    ) -> f64 {
        p.as_ref()
            .map_or(f64::NEG_INFINITY, |m| m.log_transition(t, x, u, next))
    }
    fn log_observation(
        &self,
        p: &Option<GaussianSmc<M>>,
        t: usize,
        x: &[f64],
        u: &[f64],
        y: &[f64],
    ) -> f64 {
        p.as_ref()
            .map_or(f64::NEG_INFINITY, |m| m.log_observation(t, x, u, y))
    }
}
