//! Any [`AffineModel`] with Gaussian noise as an SMC model, built from its regressors
//! alone: the bootstrap filter, the backward smoothers, particle EM and the
//! likelihood-ranked starts of the robust driver then need no model-specific code.
//!
//! # Model
//! ```text
//! x_{t+1} = beta_x alpha(x_t, u_t, t) + w_t,  w_t ~ N(0, Pi_x)
//! y_t     = beta_y alpha(x_t, u_t, t) + e_t,  e_t ~ N(0, Pi_y),   x_0 ~ N(mu, P1)
//! ```
//! `Pi_x` and `Pi_y` positive definite, `P1` positive semi-definite (a singular `P1`
//! samples in its range; its density is then taken against the point mass at `mu`, as
//! for the other models). Outputs with NaN entries use the marginal density of the
//! observed entries.
//!
//! # Complexity
//! One regressor evaluation per particle and step (`O(n_alpha (n_x + n_y))` for the
//! means, `O(n_x^2)` for the whitening); the smoothers' `M x M` transition matrix
//! evaluates the regressors once per source particle.

use crate::linear_smc::{row_major, whitened_norm2};
use nalgebra::DMatrix;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use sysid_em::affine::{AffineEmError, AffineModel, AffineParams};
use sysid_linalg::{LN_2PI, cholesky_upper, psd_factor};
use sysid_smc::{
    InitialDensity, InitialSampler, ObservationDensity, StateSpace, TransitionBound,
    TransitionDensity, TransitionSampler,
};

/// Largest number of regressors the generic SMC model takes (per-particle work stays on
/// the stack).
pub const MAX_REGRESSORS: usize = 64;

/// `out = M a` for a row-major `rows x cols` matrix `M`.
#[inline]
fn product(m: &[f64], cols: usize, a: &[f64], out: &mut [f64]) {
    for (o, row) in out.iter_mut().zip(m.chunks_exact(cols)) {
        *o = row.iter().zip(a).map(|(x, y)| x * y).sum();
    }
}

/// A Gaussian with its lower Cholesky factor (row-major) and log normaliser.
#[derive(Debug, Clone, PartialEq)]
struct Noise {
    full: DMatrix<f64>,
    lower: Vec<f64>,
    log_norm: f64,
}

impl Noise {
    fn new(name: &str, cov: &DMatrix<f64>) -> Result<Self, AffineEmError> {
        let upper =
            cholesky_upper(name, cov).map_err(|e| AffineEmError::InvalidParams(e.to_string()))?;
        let k = cov.nrows();
        let half_logdet: f64 = (0..k).map(|i| upper[(i, i)].ln()).sum();
        Ok(Noise {
            full: cov.clone(),
            lower: row_major(&upper.transpose()),
            log_norm: -0.5 * k as f64 * LN_2PI - half_logdet,
        })
    }

    /// `log N(r; 0, cov)`; `r` is overwritten.
    #[inline]
    fn log_density(&self, r: &mut [f64]) -> f64 {
        self.log_norm - 0.5 * whitened_norm2(&self.lower, r.len(), r)
    }

    /// The log-density of the entries of `r` where `y` is observed, under the matching
    /// block of the covariance (only for partly missing outputs).
    fn log_marginal(&self, r: &[f64], y: &[f64]) -> f64 {
        let observed: Vec<usize> = (0..y.len()).filter(|&i| !y[i].is_nan()).collect();
        let sub = DMatrix::from_fn(observed.len(), observed.len(), |i, j| {
            self.full[(observed[i], observed[j])]
        });
        match Noise::new("Pi_y", &sub) {
            Ok(block) => {
                let mut e: Vec<f64> = observed.iter().map(|&i| r[i]).collect();
                block.log_density(&mut e)
            }
            // a principal block of a positive definite matrix is positive definite
            Err(_) => f64::NEG_INFINITY,
        }
    }
}

/// An [`AffineModel`] at given parameters, as an SMC model (filter, smoothers, particle
/// EM): the `Smc` type of a model that has no tuned SMC code of its own.
///
/// # Example
/// A scalar model `x' = a x + b sin(x) + w`, `y = c x + e`, built from its regressors
/// and run through the bootstrap filter:
/// ```
/// use nalgebra::{dmatrix, dvector};
/// use sysid_em::affine::{AffineEmError, AffineModel, AffineParams};
/// use sysid_models::GaussianAffineSmc;
/// use sysid_smc::{FilterOptions, ParticleFilter, Series};
///
/// #[derive(Clone)]
/// struct SineModel;
/// impl AffineModel for SineModel {
///     type Smc = GaussianAffineSmc<SineModel>;
///     fn state_dim(&self) -> usize { 1 }
///     fn output_dim(&self) -> usize { 1 }
///     fn regressor_dim(&self) -> usize { 2 }
///     fn regressors(&self, _t: usize, x: &[f64], _u: &[f64], out: &mut [f64]) {
///         out.copy_from_slice(&[x[0], x[0].sin()]);
///     }
///     fn output_structure(&self) -> Vec<Vec<usize>> { vec![vec![0]] }
///     fn smc_model(&self, p: &AffineParams) -> Result<Self::Smc, AffineEmError> {
///         GaussianAffineSmc::new(self.clone(), p)
///     }
/// }
///
/// let params = AffineParams {
///     beta_x: dmatrix![0.5, 0.8], beta_y: dmatrix![1.0, 0.0],
///     pi_x: dmatrix![0.1], pi_y: dmatrix![0.2], mu: dvector![0.0], p1: dmatrix![1.0],
/// };
/// let smc = SineModel.smc_model(&params)?;
/// let y = [0.3, -0.1, 0.4, 0.2];
/// let mut filter = ParticleFilter::new(FilterOptions { particles: 200, ..Default::default() })?;
/// let loglik = filter.run(&smc, &Series::new(&y, 1)?, 7)?.loglik;
/// assert!(loglik.is_finite());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianAffineSmc<A> {
    model: A,
    n: usize,
    p: usize,
    r: usize,
    beta_x: Vec<f64>,
    beta_y: Vec<f64>,
    process: Noise,
    measurement: Noise,
    mu: Vec<f64>,
    /// `F'` (row-major, `n x k`) with `F'F = P1`, so that `x_0 = mu + F' z`.
    initial: Vec<f64>,
    initial_rank: usize,
    /// `N(mu, P1)` when `P1` is positive definite.
    initial_density: Option<Noise>,
}

impl<A: AffineModel> GaussianAffineSmc<A> {
    /// The SMC model of `model` at `params`.
    ///
    /// # Errors
    /// Parameters of the wrong shape, non-finite coefficients, `Pi_x` or `Pi_y` not
    /// positive definite, `P1` not positive semi-definite, more than [`MAX_REGRESSORS`]
    /// regressors or more than [`crate::MAX_DIM`] states or outputs.
    pub fn new(model: A, params: &AffineParams) -> Result<Self, AffineEmError> {
        let (n, p, r) = (model.state_dim(), model.output_dim(), model.regressor_dim());
        let invalid = |s: String| Err(AffineEmError::InvalidParams(s));
        if r > MAX_REGRESSORS || n > crate::MAX_DIM || p > crate::MAX_DIM {
            return invalid(format!(
                "the generic affine SMC model takes at most {MAX_REGRESSORS} regressors and {} \
                 states and outputs, got {r} regressors, {n} states, {p} outputs",
                crate::MAX_DIM
            ));
        }
        let shapes_ok = params.beta_x.shape() == (n, r)
            && params.beta_y.shape() == (p, r)
            && params.pi_x.shape() == (n, n)
            && params.pi_y.shape() == (p, p)
            && params.mu.len() == n
            && params.p1.shape() == (n, n);
        if !shapes_ok {
            return invalid(format!(
                "expected beta_x {n}x{r}, beta_y {p}x{r}, Pi_x {n}x{n}, Pi_y {p}x{p}, mu {n}, \
                 P1 {n}x{n}"
            ));
        }
        let finite = |m: &[f64]| m.iter().all(|v| v.is_finite());
        if !(finite(params.beta_x.as_slice())
            && finite(params.beta_y.as_slice())
            && finite(params.mu.as_slice()))
        {
            return invalid("beta and mu must be finite".into());
        }
        let factor = psd_factor("P1", &params.p1)
            .map_err(|e| AffineEmError::InvalidParams(e.to_string()))?;
        Ok(GaussianAffineSmc {
            n,
            p,
            r,
            beta_x: row_major(&params.beta_x),
            beta_y: row_major(&params.beta_y),
            process: Noise::new("Pi_x", &params.pi_x)?,
            measurement: Noise::new("Pi_y", &params.pi_y)?,
            mu: params.mu.as_slice().to_vec(),
            initial: row_major(&factor.transpose()),
            initial_rank: factor.nrows(),
            initial_density: Noise::new("P1", &params.p1).ok(),
            model,
        })
    }

    /// The model whose regressors this SMC model evaluates.
    pub fn model(&self) -> &A {
        &self.model
    }

    /// `beta_x alpha(x, u, t)` into `out`.
    #[inline]
    fn transition_mean(&self, t: usize, x: &[f64], u: &[f64], out: &mut [f64]) {
        let mut alpha = [0.0; MAX_REGRESSORS];
        let alpha = &mut alpha[..self.r];
        self.model.regressors(t, x, u, alpha);
        product(&self.beta_x, self.r, alpha, out);
    }
}

impl<A: AffineModel> StateSpace for GaussianAffineSmc<A> {
    fn state_dim(&self) -> usize {
        self.n
    }
}

impl<A: AffineModel> InitialSampler for GaussianAffineSmc<A> {
    fn sample_initial<R: Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
        let k = self.initial_rank;
        let mut z = [0.0; crate::MAX_DIM];
        for v in z[..k].iter_mut() {
            *v = StandardNormal.sample(rng);
        }
        x.copy_from_slice(&self.mu);
        if k > 0 {
            for (xi, row) in x.iter_mut().zip(self.initial.chunks_exact(k)) {
                *xi += row.iter().zip(&z[..k]).map(|(a, b)| a * b).sum::<f64>();
            }
        }
    }
}

impl<A: AffineModel> InitialDensity for GaussianAffineSmc<A> {
    /// `log N(x; mu, P1)`; with a singular `P1`, against the point mass at `mu`.
    fn log_initial(&self, x: &[f64]) -> f64 {
        match &self.initial_density {
            Some(noise) => {
                let mut r = [0.0; crate::MAX_DIM];
                let r = &mut r[..self.n];
                for ((ri, &xi), &mi) in r.iter_mut().zip(x).zip(&self.mu) {
                    *ri = xi - mi;
                }
                noise.log_density(r)
            }
            None if x == self.mu.as_slice() => 0.0,
            None => f64::NEG_INFINITY,
        }
    }
}

impl<A: AffineModel> TransitionSampler for GaussianAffineSmc<A> {
    fn sample_transition<R: Rng + ?Sized>(
        &self,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
        rng: &mut R,
    ) {
        let n = self.n;
        self.transition_mean(t, x, u, next);
        let mut z = [0.0; crate::MAX_DIM];
        for v in z[..n].iter_mut() {
            *v = StandardNormal.sample(rng);
        }
        for (i, xi) in next.iter_mut().enumerate() {
            let row = &self.process.lower[i * n..i * n + i + 1];
            *xi += row.iter().zip(&z[..=i]).map(|(l, v)| l * v).sum::<f64>();
        }
    }
}

impl<A: AffineModel> ObservationDensity for GaussianAffineSmc<A> {
    fn log_observation(&self, t: usize, x: &[f64], u: &[f64], y: &[f64]) -> f64 {
        let mut alpha = [0.0; MAX_REGRESSORS];
        let alpha = &mut alpha[..self.r];
        self.model.regressors(t, x, u, alpha);
        let mut e = [0.0; crate::MAX_DIM];
        let e = &mut e[..self.p];
        product(&self.beta_y, self.r, alpha, e);
        for (ei, &yi) in e.iter_mut().zip(y) {
            *ei = yi - *ei;
        }
        match y.iter().filter(|v| v.is_nan()).count() {
            0 => self.measurement.log_density(e),
            missing if missing == y.len() => 0.0,
            _ => self.measurement.log_marginal(e, y),
        }
    }
}

impl<A: AffineModel> TransitionDensity for GaussianAffineSmc<A> {
    fn log_transition(&self, t: usize, x: &[f64], u: &[f64], next: &[f64]) -> f64 {
        let mut e = [0.0; crate::MAX_DIM];
        let e = &mut e[..self.n];
        self.transition_mean(t, x, u, e);
        for (ei, &v) in e.iter_mut().zip(next) {
            *ei = v - *ei;
        }
        self.process.log_density(e)
    }

    /// The means of every source particle once (stored by component), then for each
    /// target the whitened residuals of all sources at once, component by component
    /// (loops over the sources that the compiler vectorises).
    fn log_transition_matrix(
        &self,
        t: usize,
        u: &[f64],
        from: &[f64],
        to: &[f64],
        out: &mut [f64],
        scratch: &mut Vec<f64>,
    ) {
        let n = self.n;
        let m = from.len() / n;
        // scratch: means by component (n x m), then the whitened residuals (n x m)
        scratch.resize(2 * n * m, 0.0);
        let (means, whitened) = scratch.split_at_mut(n * m);
        let mut mean = [0.0; crate::MAX_DIM];
        for (i, x) in from.chunks_exact(n).enumerate() {
            self.transition_mean(t, x, u, &mut mean[..n]);
            for k in 0..n {
                means[k * m + i] = mean[k];
            }
        }
        let lower = &self.process.lower;
        for (row, next) in out.chunks_exact_mut(m).zip(to.chunks_exact(n)) {
            row.fill(self.process.log_norm);
            for k in 0..n {
                let inverse = 1.0 / lower[k * n + k];
                let (done, rest) = whitened.split_at_mut(k * m);
                let z = &mut rest[..m];
                for (zi, &mi) in z.iter_mut().zip(&means[k * m..(k + 1) * m]) {
                    *zi = next[k] - mi;
                }
                for j in 0..k {
                    let l = lower[k * n + j];
                    for (zi, &zj) in z.iter_mut().zip(&done[j * m..(j + 1) * m]) {
                        *zi -= l * zj;
                    }
                }
                for (value, zi) in row.iter_mut().zip(z.iter_mut()) {
                    *zi *= inverse;
                    *value -= 0.5 * *zi * *zi;
                }
            }
        }
    }
}

impl<A: AffineModel> TransitionBound for GaussianAffineSmc<A> {
    /// The Gaussian's value at its mean, `-n/2 ln(2 pi) - ln det(Pi_x) / 2`.
    fn log_transition_bound(&self, _t: usize, _u: &[f64]) -> f64 {
        self.process.log_norm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{LinearAffine, LinearGaussianSmc};
    use nalgebra::{dmatrix, dvector};
    use rand::SeedableRng;
    use rand::rngs::Xoshiro256PlusPlus;

    /// The linear model as an affine model served by the generic SMC model.
    #[derive(Clone)]
    struct Linear(LinearAffine);

    impl AffineModel for Linear {
        type Smc = GaussianAffineSmc<Linear>;
        fn state_dim(&self) -> usize {
            self.0.state_dim()
        }
        fn output_dim(&self) -> usize {
            self.0.output_dim()
        }
        fn regressor_dim(&self) -> usize {
            self.0.regressor_dim()
        }
        fn regressors(&self, t: usize, x: &[f64], u: &[f64], out: &mut [f64]) {
            self.0.regressors(t, x, u, out)
        }
        fn smc_model(&self, p: &AffineParams) -> Result<Self::Smc, AffineEmError> {
            GaussianAffineSmc::new(self.clone(), p)
        }
    }

    fn two_state() -> (Linear, AffineParams) {
        let model = sysid_kalman::LinearGaussianModel::builder(
            dmatrix![0.8, 0.2; -0.3, 0.6],
            dmatrix![1.0, 0.5; 0.0, 1.0],
            dmatrix![0.3, 0.1; 0.1, 0.2],
            dmatrix![0.5, -0.2; -0.2, 0.4],
        )
        .mu(dvector![0.4, -1.0])
        .p1(dmatrix![1.0, 0.3; 0.3, 0.8])
        .build()
        .unwrap();
        let (affine, params) = LinearAffine::new(&model).unwrap();
        (Linear(affine), params)
    }

    /// Every density equals the linear Gaussian SMC adapter's (an independent dense
    /// implementation through `sysid-kalman`'s model) at random points.
    #[test]
    fn densities_equal_the_linear_adapter_on_a_linear_model() {
        let (linear, params) = two_state();
        let generic = linear.smc_model(&params).unwrap();
        let reference = LinearGaussianSmc::new(&linear.0.model(&params).unwrap()).unwrap();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let mut draw = || -> f64 { StandardNormal.sample(&mut rng) };
        for t in 0..20 {
            let x = [draw(), draw()];
            let next = [draw(), draw()];
            let y = [draw(), if t % 3 == 0 { f64::NAN } else { draw() }];
            let pairs = [
                (
                    generic.log_transition(t, &x, &[], &next),
                    reference.log_transition(t, &x, &[], &next),
                ),
                (
                    generic.log_observation(t, &x, &[], &y),
                    reference.log_observation(t, &x, &[], &y),
                ),
                (generic.log_initial(&x), reference.log_initial(&x)),
            ];
            for (a, b) in pairs {
                assert!((a - b).abs() < 1e-12, "t {t}: {a} vs {b}");
            }
        }
        assert_eq!(
            generic.log_observation(0, &[0.1, 0.2], &[], &[f64::NAN, f64::NAN]),
            0.0
        );
    }

    /// The smoothers' matrix is the pairwise density, and the bound is the maximum.
    #[test]
    fn transition_matrix_and_bound() {
        let (linear, params) = two_state();
        let smc = linear.smc_model(&params).unwrap();
        let from = [0.1, -0.4, 1.2, 0.3, -2.0, 0.5];
        let to = [0.0, 0.0, 1.0, -1.0];
        let mut out = vec![0.0; 6];
        smc.log_transition_matrix(4, &[], &from, &to, &mut out, &mut Vec::new());
        for (j, next) in to.chunks(2).enumerate() {
            for (i, x) in from.chunks(2).enumerate() {
                let direct = smc.log_transition(4, x, &[], next);
                assert!((out[j * 3 + i] - direct).abs() < 1e-12);
                assert!(direct <= smc.log_transition_bound(4, &[]));
            }
        }
    }

    /// Draws have the model's moments: mean and covariance of 200 000 transitions from
    /// one state within 5 Monte Carlo standard errors.
    #[test]
    fn transition_draws_have_the_models_moments() {
        let (linear, params) = two_state();
        let smc = linear.smc_model(&params).unwrap();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(11);
        let x = [1.0, -2.0];
        let mean = &params.beta_x * dvector![1.0, -2.0];
        let draws = 200_000;
        let (mut s, mut ss) = ([0.0; 2], [[0.0; 2]; 2]);
        let mut next = [0.0; 2];
        for _ in 0..draws {
            smc.sample_transition(0, &x, &[], &mut next, &mut rng);
            for i in 0..2 {
                let ei = next[i] - mean[i];
                s[i] += ei;
                for j in 0..2 {
                    ss[i][j] += ei * (next[j] - mean[j]);
                }
            }
        }
        let k = draws as f64;
        for (i, (&sum, products)) in s.iter().zip(&ss).enumerate() {
            let q = params.pi_x[(i, i)];
            assert!((sum / k).abs() < 5.0 * (q / k).sqrt(), "mean {i}");
            for (j, &product) in products.iter().enumerate() {
                let cov = product / k;
                let var_of_product = params.pi_x[(i, i)] * params.pi_x[(j, j)]
                    + params.pi_x[(i, j)] * params.pi_x[(i, j)];
                let se = (var_of_product / k).sqrt();
                assert!(
                    (cov - params.pi_x[(i, j)]).abs() < 5.0 * se,
                    "cov {i}{j}: {cov}"
                );
            }
        }
    }

    #[test]
    fn refuses_bad_parameters() {
        let (linear, params) = two_state();
        let mut bad = params.clone();
        bad.pi_x = dmatrix![1.0, 2.0; 2.0, 1.0];
        assert!(linear.smc_model(&bad).is_err());
        let mut bad = params.clone();
        bad.beta_x[(0, 0)] = f64::NAN;
        assert!(linear.smc_model(&bad).is_err());
        let mut bad = params;
        bad.mu = dvector![0.0];
        assert!(linear.smc_model(&bad).is_err());
    }
}
