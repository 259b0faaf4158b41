//! Models affine in their parameters, and their parameter values.

use super::{AffineConstraints, AffineEmError};
use nalgebra::{DMatrix, DVector};
use sysid_smc::{FilterModel, TransitionDensity};

/// The parameters `theta = (beta, Pi, mu, P1)` of an [`AffineModel`], split into the
/// state block (rows of `x_{t+1}`) and the output block (rows of `y_t`):
/// ```text
/// x_{t+1} = beta_x alpha_t + w_t,  w_t ~ N(0, Pi_x)
/// y_t     = beta_y alpha_t + e_t,  e_t ~ N(0, Pi_y),   x_0 ~ N(mu, P1)
/// ```
/// Coefficients outside a row's regressor set (structural zeros) are zero.
#[derive(Debug, Clone, PartialEq)]
pub struct AffineParams {
    /// State coefficients, `n_x x n_alpha`.
    pub beta_x: DMatrix<f64>,
    /// Output coefficients, `n_y x n_alpha`.
    pub beta_y: DMatrix<f64>,
    /// Process-noise covariance, `n_x x n_x`.
    pub pi_x: DMatrix<f64>,
    /// Measurement-noise covariance, `n_y x n_y`.
    pub pi_y: DMatrix<f64>,
    /// Initial-state mean.
    pub mu: DVector<f64>,
    /// Initial-state covariance.
    pub p1: DMatrix<f64>,
}

/// A nonlinear state-space model affine in its parameters (ALGORITHMS.md 3):
/// `xi_t = [x_{t+1}; y_t] = beta alpha(x_t, u_t, t) + eta_t`, `eta_t ~ N(0, Pi)`
/// with `Pi` block-diagonal (independent process and measurement noise, as the
/// bootstrap filter needs).
///
/// The model supplies the regressors `alpha`, which regressors each row uses, and an
/// SMC model for given parameters (the particle E-step runs on it).
///
/// # Example
/// The AR(1) model `x' = phi x + w`, `y = x + e` in affine form: one regressor `x`,
/// `beta_x = [phi]` estimated, `beta_y = [1]` known (held); particle EM then has a
/// closed-form M-step. (A model file gives this form by itself:
/// `sysid_modelfile::ModelFile::affine`.)
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
/// use nalgebra::{dmatrix, dvector};
/// use sysid_em::affine::{AffineEm, AffineEmError, AffineEmSpec, AffineModel, AffineParams};
/// use sysid_em::{EmOptions, run_em};
/// struct ArAffine;
/// impl AffineModel for ArAffine {
///     type Smc = Ar;
///     fn state_dim(&self) -> usize { 1 }
///     fn output_dim(&self) -> usize { 1 }
///     fn regressor_dim(&self) -> usize { 1 }
///     fn regressors(&self, _t: usize, x: &[f64], _u: &[f64], out: &mut [f64]) {
///         out[0] = x[0];
///     }
///     fn held_output_coefficients(&self) -> Vec<Vec<usize>> { vec![vec![0]] }
///     fn smc_model(&self, p: &AffineParams) -> Result<Ar, AffineEmError> {
///         Ok(Ar { phi: p.beta_x[(0, 0)], q: p.pi_x[(0, 0)], r: p.pi_y[(0, 0)] })
///     }
/// }
/// let truth = Ar { phi: 0.9, q: 1.0, r: 0.5 };
/// let (mut x, mut y, mut rng) = ([0.0], Vec::new(), stream(4, 0));
/// for _ in 0..300 {
///     let e: f64 = StandardNormal.sample(&mut rng);
///     y.push(x[0] + 0.5f64.sqrt() * e);
///     let mut next = [0.0];
///     truth.sample_transition(0, &x, &[], &mut next, &mut rng);
///     x = next;
/// }
/// let start = AffineParams {
///     beta_x: dmatrix![0.5], beta_y: dmatrix![1.0], pi_x: dmatrix![1.0], pi_y: dmatrix![0.5],
///     mu: dvector![0.0], p1: dmatrix![1.0],
/// };
/// let spec = AffineEmSpec { pi_x: sysid_em::linear::Covariance::Fixed,
///     pi_y: sysid_em::linear::Covariance::Fixed, ..AffineEmSpec::default() };
/// let mut em = AffineEm::new(&ArAffine, Series::new(&y, 1)?, 100, Tanizaki::default(), spec, 1)?;
/// let options = EmOptions { max_iterations: 20, tol: 0.0, ..EmOptions::default() }.check()?;
/// let fit = run_em(&mut em, start, &options, &mut ());
/// assert!((fit.estimate.beta_x[(0, 0)] - 0.9).abs() < 0.15);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait AffineModel: Sync {
    /// The SMC model at given parameters.
    type Smc: FilterModel + TransitionDensity + Sync;

    /// Dimension of `x`.
    fn state_dim(&self) -> usize;
    /// Dimension of `y`.
    fn output_dim(&self) -> usize;
    /// Dimension of `alpha`.
    fn regressor_dim(&self) -> usize;
    /// Writes `alpha(x_t, u_t, t)` into `out`.
    fn regressors(&self, t: usize, x: &[f64], u: &[f64], out: &mut [f64]);

    /// Writes the regressors of several states at step `t` (path-major, stride
    /// `state_dim`) by component: `columns[i * paths + k]` is component `i` of path
    /// `k`'s regressor vector. The E-step's statistics are sums over paths of products
    /// of these columns. The default transposes [`regressors`](Self::regressors) path
    /// by path; models override it to write the columns directly (vectorised).
    fn regressor_columns(&self, t: usize, states: &[f64], u: &[f64], columns: &mut [f64]) {
        let (n, r) = (self.state_dim(), self.regressor_dim());
        let paths = states.len() / n;
        let mut alpha = vec![0.0; r];
        for (k, x) in states.chunks_exact(n).enumerate() {
            self.regressors(t, x, u, &mut alpha);
            for (i, &a) in alpha.iter().enumerate() {
                columns[i * paths + k] = a;
            }
        }
    }

    /// The regressors each state row uses (default: all).
    fn state_structure(&self) -> Vec<Vec<usize>> {
        vec![(0..self.regressor_dim()).collect(); self.state_dim()]
    }

    /// The regressors each output row uses (default: all).
    fn output_structure(&self) -> Vec<Vec<usize>> {
        vec![(0..self.regressor_dim()).collect(); self.output_dim()]
    }

    /// The coefficients of each state row that are known: held at their values in the
    /// parameters, never estimated nor perturbed (default: none). Each must be in the
    /// row's [`state_structure`](Self::state_structure). For the known parts of a
    /// model, such as a kinematic row `theta' = theta + dt omega` or the identity part
    /// of an Euler step `omega' = omega + dt (...)`.
    fn held_state_coefficients(&self) -> Vec<Vec<usize>> {
        vec![Vec::new(); self.state_dim()]
    }

    /// The known coefficients of each output row (see
    /// [`held_state_coefficients`](Self::held_state_coefficients)); default: none.
    fn held_output_coefficients(&self) -> Vec<Vec<usize>> {
        vec![Vec::new(); self.output_dim()]
    }

    /// Coefficients tied together or bounded, and noise variances held inside an
    /// estimated block ([`AffineConstraints`]); default `None`: every estimated
    /// coefficient is a parameter of its own, unbounded, and a noise block is
    /// estimated or held whole. With constraints, the M-step is the constrained one
    /// (`constraints.rs`) and the robust driver keeps its starts inside them.
    fn constraints(&self) -> Option<AffineConstraints> {
        None
    }

    /// The SMC model at `params`; errors on invalid values (e.g. a non-positive
    /// variance).
    fn smc_model(&self, params: &AffineParams) -> Result<Self::Smc, AffineEmError>;
}

/// Each row's regressors whose coefficients are estimated: its structure without its
/// held coefficients.
pub fn free_structure(structure: &[Vec<usize>], held: &[Vec<usize>]) -> Vec<Vec<usize>> {
    structure
        .iter()
        .enumerate()
        .map(|(row, used)| {
            let held = held.get(row).map(Vec::as_slice).unwrap_or(&[]);
            used.iter().copied().filter(|j| !held.contains(j)).collect()
        })
        .collect()
}
