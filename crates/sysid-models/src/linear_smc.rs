//! A linear Gaussian model of `sysid-kalman` used as an SMC model, so that particle
//! methods can be checked against the exact Kalman answer.

use nalgebra::DMatrix;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use sysid_kalman::LinearGaussianModel;
use sysid_linalg::{LinalgError, cholesky_upper};
use sysid_smc::{
    GuidedProposal, InitialDensity, InitialSampler, ObservationDensity, ScalarGaussianKernel,
    StateSpace, TransitionBound, TransitionDensity, TransitionSampler, fill_standard_normals,
};

const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// Largest state or output dimension the adapter takes (it keeps per-particle work on
/// the stack).
pub const MAX_DIM: usize = 16;

/// Why a linear Gaussian model cannot be used as an SMC model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum AdapterError {
    /// The bootstrap filter needs independent process and measurement noises.
    #[error("the SMC adapter needs S = 0 (independent process and measurement noise)")]
    CrossCovariance,
    /// Q or R is singular, so the transition or observation density does not exist.
    #[error("the SMC adapter needs a positive definite covariance: {0}")]
    Singular(#[from] LinalgError),
    /// A diffuse initial state (a flat prior) cannot be sampled.
    #[error(
        "particle methods need a proper initial law, and the model's initial state is diffuse: \
         give its mu and P1 (\"initial\": \"given\"), or use the exact diffuse Kalman commands"
    )]
    Diffuse,
    /// A dimension above [`MAX_DIM`].
    #[error("the SMC adapter takes at most {MAX_DIM} states and outputs, got n = {n}, p = {p}")]
    TooLarge {
        /// States.
        n: usize,
        /// Outputs.
        p: usize,
    },
}

/// `|L^{-1} r|^2` for a lower-triangular row-major `k x k` factor `L` (forward
/// substitution); `r` is overwritten by `L^{-1} r`.
#[inline]
pub(crate) fn whitened_norm2(lower: &[f64], k: usize, r: &mut [f64]) -> f64 {
    let mut norm2 = 0.0;
    for i in 0..k {
        let row = &lower[i * k..i * k + i];
        let s = r[i] - row.iter().zip(&r[..i]).map(|(l, v)| l * v).sum::<f64>();
        r[i] = s / lower[i * k + i];
        norm2 += r[i] * r[i];
    }
    norm2
}

/// Row-major copy of a matrix.
pub(crate) fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

/// The Gaussian update of a prior `N(m, P)` by `y = C x + e`, `e ~ N(0, R)`, in the
/// form the guided proposal needs (row-major): the gain `K = P C' S^{-1}`, a factor
/// `F` with `F F' = P - K C P`, and the factor of `S = C P C' + R` for `log p(y)`.
#[derive(Debug, Clone, PartialEq)]
struct Guide {
    gain: Vec<f64>,
    posterior_factor: Vec<f64>,
    s_lower: Vec<f64>,
    log_norm_s: f64,
}

impl Guide {
    fn new(prior: &DMatrix<f64>, c: &DMatrix<f64>, r: &DMatrix<f64>) -> Result<Self, AdapterError> {
        let s = c * prior * c.transpose() + r;
        let s_upper = cholesky_upper("C P C' + R", &s)?;
        let p = s.nrows();
        let pc = prior * c.transpose();
        // K = P C' S^{-1}: solve U'U K' = C P with the factor S = U'U
        let singular = || {
            AdapterError::Singular(LinalgError::NotPositiveDefinite {
                name: "C P C' + R".into(),
                pivot: 0,
                value: 0.0,
            })
        };
        let half = s_upper
            .transpose()
            .solve_lower_triangular(&pc.transpose())
            .ok_or_else(singular)?;
        let gain = s_upper
            .solve_upper_triangular(&half)
            .ok_or_else(singular)?
            .transpose();
        let posterior = prior - &gain * c * prior;
        let posterior = (&posterior + posterior.transpose()) * 0.5;
        // a factor by the symmetric eigen-decomposition (posterior may be singular)
        let eig = posterior.symmetric_eigen();
        let n = prior.nrows();
        let factor = DMatrix::from_fn(n, n, |i, j| {
            eig.eigenvectors[(i, j)] * eig.eigenvalues[j].max(0.0).sqrt()
        });
        let half_logdet: f64 = (0..p).map(|i| s_upper[(i, i)].ln()).sum();
        Ok(Guide {
            gain: row_major(&gain),
            posterior_factor: row_major(&factor),
            s_lower: row_major(&s_upper.transpose()),
            log_norm_s: -0.5 * p as f64 * LN_2PI - half_logdet,
        })
    }
}

/// A [`LinearGaussianModel`] seen through the SMC capability traits.
///
/// # Model
/// ```text
/// x_{t+1} = A x_t + B u_t + w_t,  w_t ~ N(0, Q)
/// y_t     = C x_t + D u_t + h + e_t,  e_t ~ N(0, R),   x_0 ~ N(mu, P1)
/// ```
/// with `S = 0`, `Q` and `R` positive definite (`P1` may be singular). Partially
/// missing outputs (NaN entries) use the marginal density of the observed entries.
///
/// # Example
/// ```
/// let smc = sysid_models::LinearGaussianSmc::new(&sysid_models::lgss()).unwrap();
/// assert_eq!(sysid_smc::StateSpace::state_dim(&smc), 1);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct LinearGaussianSmc {
    n: usize,
    m: usize,
    p: usize,
    a: Vec<f64>,
    b: Vec<f64>,
    c: Vec<f64>,
    d: Vec<f64>,
    h: Vec<f64>,
    mu: Vec<f64>,
    /// `F'` (row-major) with `F'F = P1`, so that `x_0 = mu + F' z`.
    initial: Vec<f64>,
    /// Lower Cholesky factor of Q, row-major.
    q_lower: Vec<f64>,
    /// Lower Cholesky factor of R, row-major.
    r_lower: Vec<f64>,
    r_full: Vec<f64>,
    /// Lower Cholesky factor of P1 (row-major) and the log normaliser of `N(mu, P1)`,
    /// when P1 is positive definite.
    p1_lower: Option<(Vec<f64>, f64)>,
    /// The locally optimal proposal from a state (`P = Q`) and for `x_0` (`P = P1`).
    guide_step: Guide,
    guide_initial: Guide,
    log_norm_q: f64,
    log_norm_r: f64,
}

impl LinearGaussianSmc {
    /// Wraps a model. Errors when `S != 0`, when the initial state is diffuse, when `Q`
    /// or `R` is not positive definite, or when a dimension exceeds [`MAX_DIM`].
    pub fn new(model: &LinearGaussianModel) -> Result<Self, AdapterError> {
        let (n, m, p) = (model.n(), model.m(), model.p());
        if n > MAX_DIM || p > MAX_DIM {
            return Err(AdapterError::TooLarge { n, p });
        }
        if model.has_cross_covariance() {
            return Err(AdapterError::CrossCovariance);
        }
        if model.is_diffuse() {
            return Err(AdapterError::Diffuse);
        }
        let q_upper = cholesky_upper("Q", model.q())?;
        let r_upper = cholesky_upper("R", model.r())?;
        let half_logdet = |u: &DMatrix<f64>| (0..u.nrows()).map(|i| u[(i, i)].ln()).sum::<f64>();
        Ok(LinearGaussianSmc {
            n,
            m,
            p,
            a: row_major(model.a()),
            b: row_major(model.b()),
            c: row_major(model.c()),
            d: row_major(model.d()),
            h: model.h().as_slice().to_vec(),
            mu: model.mu().as_slice().to_vec(),
            initial: row_major(&model.initial_factor().transpose()),
            log_norm_q: -0.5 * n as f64 * LN_2PI - half_logdet(&q_upper),
            log_norm_r: -0.5 * p as f64 * LN_2PI - half_logdet(&r_upper),
            q_lower: row_major(&q_upper.transpose()),
            r_lower: row_major(&r_upper.transpose()),
            r_full: row_major(model.r()),
            guide_step: Guide::new(model.q(), model.c(), model.r())?,
            guide_initial: Guide::new(model.p1(), model.c(), model.r())?,
            p1_lower: cholesky_upper("P1", model.p1()).ok().map(|u| {
                let norm = -0.5 * n as f64 * LN_2PI - half_logdet(&u);
                (row_major(&u.transpose()), norm)
            }),
        })
    }

    /// Number of outputs p.
    pub fn output_dim(&self) -> usize {
        self.p
    }

    /// Number of inputs m.
    pub fn input_dim(&self) -> usize {
        self.m
    }

    /// `out = M x` for a row-major `rows x cols` matrix, accumulated onto `out`.
    #[inline]
    fn add_product(m: &[f64], cols: usize, x: &[f64], out: &mut [f64]) {
        if cols == 0 {
            return;
        }
        for (o, row) in out.iter_mut().zip(m.chunks_exact(cols)) {
            *o += row.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
        }
    }

    /// `A x + B u` into `out`.
    #[inline]
    fn transition_mean(&self, x: &[f64], u: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        Self::add_product(&self.a, self.n, x, out);
        Self::add_product(&self.b, self.m, u, out);
    }

    /// The Gaussian log-density of the observed entries of `residual` under the
    /// corresponding block of R (computed on the fly; used only for partly missing y).
    fn partial_log_density(&self, residual: &[f64], y: &[f64]) -> f64 {
        let observed: Vec<usize> = (0..self.p).filter(|&i| !y[i].is_nan()).collect();
        let k = observed.len();
        let sub = DMatrix::from_fn(k, k, |i, j| self.r_full[observed[i] * self.p + observed[j]]);
        let upper = cholesky_upper("R", &sub).expect("a principal block of a PD matrix is PD");
        let lower = row_major(&upper.transpose());
        let mut r: Vec<f64> = observed.iter().map(|&i| residual[i]).collect();
        let norm2 = whitened_norm2(&lower, k, &mut r);
        let half_logdet: f64 = (0..k).map(|i| upper[(i, i)].ln()).sum();
        -0.5 * k as f64 * LN_2PI - half_logdet - 0.5 * norm2
    }
}

impl StateSpace for LinearGaussianSmc {
    fn state_dim(&self) -> usize {
        self.n
    }
}

impl InitialSampler for LinearGaussianSmc {
    fn sample_initial<R: Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
        let mut z = [0.0; MAX_DIM];
        for v in z[..self.n].iter_mut() {
            *v = StandardNormal.sample(rng);
        }
        x.copy_from_slice(&self.mu);
        Self::add_product(&self.initial, self.n, &z[..self.n], x);
    }
}

impl InitialDensity for LinearGaussianSmc {
    /// `log N(x; mu, P1)`. With a singular P1 there is no density against Lebesgue
    /// measure; the value is then taken against the point mass at `mu` (exact for
    /// `P1 = 0`, the only singular case the Gibbs samplers support): 0 at `mu`, `-inf`
    /// elsewhere.
    fn log_initial(&self, x: &[f64]) -> f64 {
        match &self.p1_lower {
            Some((lower, norm)) => {
                let mut residual = [0.0; MAX_DIM];
                let r = &mut residual[..self.n];
                for ((ri, &xi), &mi) in r.iter_mut().zip(x).zip(&self.mu) {
                    *ri = xi - mi;
                }
                norm - 0.5 * whitened_norm2(lower, self.n, r)
            }
            None if x == self.mu.as_slice() => 0.0,
            None => f64::NEG_INFINITY,
        }
    }
}

impl LinearGaussianSmc {
    /// `prior_mean` updated by `y` through `guide`: writes the posterior mean into `out`
    /// and returns `log p(y)`; `prior_mean` is the state's mean before the update.
    fn guided_update(
        &self,
        guide: &Guide,
        prior_mean: &[f64],
        u: &[f64],
        y: &[f64],
        out: &mut [f64],
    ) -> f64 {
        let (n, p) = (self.n, self.p);
        let mut innovation = [0.0; MAX_DIM];
        let e = &mut innovation[..p];
        e.copy_from_slice(&self.h);
        Self::add_product(&self.c, n, prior_mean, e);
        Self::add_product(&self.d, self.m, u, e);
        for (ei, &yi) in e.iter_mut().zip(y) {
            *ei = yi - *ei;
        }
        out.copy_from_slice(prior_mean);
        Self::add_product(&guide.gain, p, e, out);
        guide.log_norm_s - 0.5 * whitened_norm2(&guide.s_lower, p, e)
    }

    /// The guided step from `x`: writes the mean of `p(x_{t+1} | x, y_next)` into `out`
    /// and returns `log p(y_next | x)`.
    fn guided_step(
        &self,
        x: &[f64],
        u: &[f64],
        u_next: &[f64],
        y_next: &[f64],
        out: &mut [f64],
    ) -> f64 {
        let mut mean = [0.0; MAX_DIM];
        self.transition_mean(x, u, &mut mean[..self.n]);
        self.guided_update(&self.guide_step, &mean[..self.n], u_next, y_next, out)
    }

    /// `mean + F z` with `z ~ N(0, I)`.
    fn add_noise<R: Rng + ?Sized>(guide: &Guide, n: usize, x: &mut [f64], rng: &mut R) {
        let mut z = [0.0; MAX_DIM];
        for v in z[..n].iter_mut() {
            *v = StandardNormal.sample(rng);
        }
        Self::add_product(&guide.posterior_factor, n, &z[..n], x);
    }
}

/// The locally optimal proposal of the linear Gaussian model: a Kalman measurement
/// update of the transition (or of `N(mu, P1)` at `t = 0`) by the next output.
impl GuidedProposal for LinearGaussianSmc {
    fn sample_initial_guided<R: Rng + ?Sized>(
        &self,
        u: &[f64],
        y: &[f64],
        x: &mut [f64],
        rng: &mut R,
    ) {
        self.guided_update(&self.guide_initial, &self.mu, u, y, x);
        Self::add_noise(&self.guide_initial, self.n, x, rng);
    }

    fn log_initial_predictive(&self, u: &[f64], y: &[f64]) -> f64 {
        let mut out = [0.0; MAX_DIM];
        self.guided_update(&self.guide_initial, &self.mu, u, y, &mut out[..self.n])
    }

    fn log_predictive(
        &self,
        _t: usize,
        x: &[f64],
        u: &[f64],
        u_next: &[f64],
        y_next: &[f64],
    ) -> f64 {
        let mut out = [0.0; MAX_DIM];
        self.guided_step(x, u, u_next, y_next, &mut out[..self.n])
    }

    fn sample_guided<R: Rng + ?Sized>(
        &self,
        _t: usize,
        x: &[f64],
        u: &[f64],
        u_next: &[f64],
        y_next: &[f64],
        next: &mut [f64],
        rng: &mut R,
    ) {
        self.guided_step(x, u, u_next, y_next, next);
        Self::add_noise(&self.guide_step, self.n, next, rng);
    }
}

impl TransitionSampler for LinearGaussianSmc {
    fn sample_transition<R: Rng + ?Sized>(
        &self,
        _t: usize,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
        rng: &mut R,
    ) {
        let mut z = [0.0; MAX_DIM];
        for v in z[..self.n].iter_mut() {
            *v = StandardNormal.sample(rng);
        }
        self.transition_mean(x, u, next);
        Self::add_product(&self.q_lower, self.n, &z[..self.n], next);
    }

    /// `next_k = A x_{parents[k]} + B u + L z_k` with the `z` drawn in bulk
    /// ([`fill_standard_normals`], one call per block of particles).
    fn sample_transitions<R: Rng + ?Sized>(
        &self,
        _t: usize,
        u: &[f64],
        from: &[f64],
        parents: &[usize],
        next: &mut [f64],
        rng: &mut R,
    ) {
        let n = self.n;
        let mut z = [0.0; NORMALS_PER_BLOCK];
        let per_block = NORMALS_PER_BLOCK / n;
        for (block, parents) in next
            .chunks_mut(per_block * n)
            .zip(parents.chunks(per_block))
        {
            let z = &mut z[..block.len()];
            fill_standard_normals(rng, z);
            for ((x, &p), z) in block
                .chunks_exact_mut(n)
                .zip(parents)
                .zip(z.chunks_exact(n))
            {
                self.transition_mean(&from[p * n..(p + 1) * n], u, x);
                Self::add_product(&self.q_lower, n, z, x);
            }
        }
    }
}

/// The normals drawn per call in [`LinearGaussianSmc::sample_transitions`].
const NORMALS_PER_BLOCK: usize = 512;

impl ObservationDensity for LinearGaussianSmc {
    fn log_observation(&self, _t: usize, x: &[f64], u: &[f64], y: &[f64]) -> f64 {
        let p = self.p;
        let mut residual = [0.0; MAX_DIM];
        let r = &mut residual[..p];
        r.copy_from_slice(&self.h);
        Self::add_product(&self.c, self.n, x, r);
        Self::add_product(&self.d, self.m, u, r);
        for (ri, &yi) in r.iter_mut().zip(y) {
            *ri = yi - *ri;
        }
        if y.iter().any(|v| v.is_nan()) {
            return self.partial_log_density(r, y);
        }
        self.log_norm_r - 0.5 * whitened_norm2(&self.r_lower, p, r)
    }
}

impl TransitionDensity for LinearGaussianSmc {
    fn log_transition(&self, _t: usize, x: &[f64], u: &[f64], next: &[f64]) -> f64 {
        let n = self.n;
        let mut residual = [0.0; MAX_DIM];
        let r = &mut residual[..n];
        self.transition_mean(x, u, r);
        for (ri, &xi) in r.iter_mut().zip(next) {
            *ri = xi - *ri;
        }
        self.log_norm_q - 0.5 * whitened_norm2(&self.q_lower, n, r)
    }

    fn log_transition_matrix(
        &self,
        t: usize,
        u: &[f64],
        from: &[f64],
        to: &[f64],
        out: &mut [f64],
        scratch: &mut Vec<f64>,
    ) {
        if let Some(kernel) = self.scalar_gaussian_means(t, u, from, scratch) {
            kernel.log_density_matrix(scratch, to, out);
            return;
        }
        let n = self.n;
        let count = from.len() / n;
        scratch.resize(from.len(), 0.0);
        for (mean, x) in scratch.chunks_exact_mut(n).zip(from.chunks_exact(n)) {
            self.transition_mean(x, u, mean);
        }
        let mut residual = [0.0; MAX_DIM];
        for (row, next) in out.chunks_exact_mut(count).zip(to.chunks_exact(n)) {
            for (value, mean) in row.iter_mut().zip(scratch.chunks_exact(n)) {
                let r = &mut residual[..n];
                for ((ri, &xi), &mi) in r.iter_mut().zip(next).zip(mean) {
                    *ri = xi - mi;
                }
                *value = self.log_norm_q - 0.5 * whitened_norm2(&self.q_lower, n, r);
            }
        }
    }

    fn scalar_gaussian_means(
        &self,
        _t: usize,
        u: &[f64],
        from: &[f64],
        means: &mut Vec<f64>,
    ) -> Option<ScalarGaussianKernel> {
        if self.n != 1 {
            return None;
        }
        means.resize(from.len(), 0.0);
        for (mean, x) in means.iter_mut().zip(from) {
            self.transition_mean(std::slice::from_ref(x), u, std::slice::from_mut(mean));
        }
        Some(self.scalar_kernel())
    }
}

impl LinearGaussianSmc {
    /// The transition noise of a scalar state as a kernel of `(mean, next)`.
    fn scalar_kernel(&self) -> ScalarGaussianKernel {
        ScalarGaussianKernel {
            log_norm: self.log_norm_q,
            half_inv_var: 0.5 / (self.q_lower[0] * self.q_lower[0]),
        }
    }
}

impl TransitionBound for LinearGaussianSmc {
    fn log_transition_bound(&self, _t: usize, _u: &[f64]) -> f64 {
        self.log_norm_q
    }
}
