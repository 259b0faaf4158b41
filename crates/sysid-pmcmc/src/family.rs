//! A parametrised family of state-space models: what the samplers move over.

use sysid_smc::ModelError;
use sysid_smc::{FilterModel, TransitionDensity};

use crate::{PmcmcError, Support};

/// A family of models `p_theta`, one per parameter vector `theta`.
///
/// The samplers know a family only through this trait: the parameter names (for
/// outputs), where each parameter lives (the random walks run on the unconstrained
/// scale of [`Support`]) and how to build the model. Building must be cheap: PMMH
/// builds a model per iteration.
///
/// # Example
/// The AR(1) family over `phi` in (-1, 1) with `q = 1`, sampled by PMMH:
/// ```
/// # use rand_distr::{Distribution, StandardNormal};
/// # use sysid_smc::*;
/// # /// x' = phi x + w (w ~ N(0, q)), y = x + e (e ~ N(0, 0.5)), x_0 ~ N(0, 1)
/// # #[derive(Clone)]
/// # struct Ar { phi: f64, q: f64 }
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
/// #         ScalarGaussianKernel::with_variance(0.5).log_density(x[0], y[0])
/// #     }
/// # }
/// # impl TransitionDensity for Ar {
/// #     fn log_transition(&self, _t: usize, x: &[f64], _u: &[f64], next: &[f64]) -> f64 {
/// #         ScalarGaussianKernel::with_variance(self.q).log_density(self.phi * x[0], next[0])
/// #     }
/// # }
/// use sysid_pmcmc::{ChainRun, IndependentPrior, ModelFamily, PmmhOptions, ScalarPrior, Support, pmmh};
/// struct ArFamily;
/// impl ModelFamily for ArFamily {
///     type Model = Ar;
///     fn parameter_names(&self) -> Vec<String> { vec!["phi".into()] }
///     fn supports(&self) -> Vec<Support> { vec![Support::Interval(-1.0, 1.0)] }
///     fn model(&self, theta: &[f64]) -> Result<Ar, sysid_smc::ModelError> {
///         Ok(Ar { phi: theta[0], q: 1.0 })
///     }
/// }
/// let y = [0.3, -0.4, 1.2, 0.8, 1.1, 0.2];
/// let prior = IndependentPrior::new(&["phi".into()], vec![ScalarPrior::Uniform { low: -1.0, high: 1.0 }])?;
/// let options = PmmhOptions { iterations: 200, burn_in: 50, particles: 50, ..PmmhOptions::default() };
/// let chains = pmmh(&ArFamily, &prior, &Series::new(&y, 1)?, &[0.5], &options, &ChainRun::new(1, 3))?;
/// assert!(chains[0].parameter(0).iter().all(|phi| phi.abs() < 1.0));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait ModelFamily: Sync {
    /// The model type the particle methods run.
    type Model: FilterModel + TransitionDensity + Sync;

    /// The parameter names, in order.
    fn parameter_names(&self) -> Vec<String>;

    /// The support of each parameter, in order.
    fn supports(&self) -> Vec<Support>;

    /// The model at `theta`, or why `theta` is not admissible. The samplers treat a
    /// refusal inside the chain as zero posterior density (the proposal is rejected)
    /// and at the start as an error.
    fn model(&self, theta: &[f64]) -> Result<Self::Model, ModelError>;

    /// Number of parameters.
    fn dim(&self) -> usize {
        self.supports().len()
    }
}

/// The supports and the maps between `theta` and the unconstrained `z`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Transform {
    supports: Vec<Support>,
}

impl Transform {
    pub(crate) fn new(supports: Vec<Support>) -> Self {
        Transform { supports }
    }

    /// `z` of `theta`, or the index of a parameter outside its support.
    pub(crate) fn to_unconstrained(&self, theta: &[f64], z: &mut [f64]) -> Result<(), usize> {
        for (k, ((s, &v), zk)) in self
            .supports
            .iter()
            .zip(theta)
            .zip(z.iter_mut())
            .enumerate()
        {
            if !s.contains(v) {
                return Err(k);
            }
            *zk = s.to_unconstrained(v);
        }
        Ok(())
    }

    /// `theta` of `z`, returning `log |d theta / d z|`.
    pub(crate) fn to_constrained(&self, z: &[f64], theta: &mut [f64]) -> f64 {
        let mut log_jacobian = 0.0;
        for ((s, &zk), v) in self.supports.iter().zip(z).zip(theta.iter_mut()) {
            let (value, lj) = s.from_unconstrained(zk);
            *v = value;
            log_jacobian += lj;
        }
        log_jacobian
    }
}

/// Checks a starting point: length, support, and that the family builds a model.
pub(crate) fn check_start<F: ModelFamily>(
    family: &F,
    theta: &[f64],
) -> Result<F::Model, PmcmcError> {
    let names = family.parameter_names();
    if theta.len() != names.len() {
        return Err(PmcmcError::DimensionMismatch {
            what: "initial parameters",
            expected: names.len(),
            found: theta.len(),
        });
    }
    for ((name, s), &v) in names.iter().zip(family.supports()).zip(theta) {
        if !s.contains(v) {
            return Err(PmcmcError::InadmissibleStart {
                reason: format!("{name} = {v} is outside its support {s:?}"),
            });
        }
    }
    family
        .model(theta)
        .map_err(|e| PmcmcError::InadmissibleStart { reason: e.reason })
}
