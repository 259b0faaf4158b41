//! The nonlinear benchmark model of seed 000 (Schön, Wills and Ninness 2006, sec. 6).

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use sysid_smc::ModelError;
use sysid_smc::{
    InitialDensity, InitialSampler, ObservationDensity, ScalarGaussianKernel, StateSpace,
    TransitionBound, TransitionDensity, TransitionSampler, add_scaled_normals, stream,
};

const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// The parameters of [`Nlbench`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NlbenchParams {
    /// Linear state coefficient `a`.
    pub a: f64,
    /// Coefficient `b` of `x / (1 + x^2)`.
    pub b: f64,
    /// Coefficient `c` of `cos(1.2 t)`.
    pub c: f64,
    /// Output coefficient `d` of `x^2`.
    pub d: f64,
    /// Process-noise variance `q`.
    pub q: f64,
    /// Measurement-noise variance `r`.
    pub r: f64,
    /// Mean of the initial state.
    pub mu: f64,
    /// Variance of the initial state.
    pub p1: f64,
}

impl NlbenchParams {
    /// The true parameters of the reference experiment (ALGORITHMS.md 3):
    /// `a = 0.5, b = 25, c = 8, d = 0.05, q = 0.01, r = 0.1`, `x_1 ~ N(0, 1)`.
    pub const TRUE: NlbenchParams = NlbenchParams {
        a: 0.5,
        b: 25.0,
        c: 8.0,
        d: 0.05,
        q: 0.01,
        r: 0.1,
        mu: 0.0,
        p1: 1.0,
    };
}

/// The classic nonlinear benchmark, in the form used by seed 000.
///
/// # Model
/// ```text
/// x_{t+1} = a x_t + b x_t / (1 + x_t^2) + c cos(1.2 (t + 1)) + w_t,   w_t ~ N(0, q)
/// y_t     = d x_t^2 + e_t,                                        e_t ~ N(0, r)
/// x_0 ~ N(mu, p1)
/// ```
/// **Time convention.** Indices are 0-based (`t = 0` is the first sample); the paper
/// counts from 1. The cosine uses the paper's time of the state being propagated, so
/// the transition from `x_t` (our index) uses `cos(1.2 (t + 1))`, which is the paper's
/// `x_{t+1} = ... + c cos(1.2 t)` with 1-based `t`.
///
/// Implements every SMC capability, with a vectorisable
/// [`log_transition_matrix`](TransitionDensity::log_transition_matrix) (transition
/// means computed once per call, then one fused quadratic per pair).
///
/// # Example
/// ```
/// use sysid_models::{Nlbench, NlbenchParams};
/// let model = Nlbench::new(NlbenchParams::TRUE).unwrap();
/// let sim = model.simulate(100, 1);
/// assert_eq!(sim.outputs.len(), 100);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nlbench {
    params: NlbenchParams,
    sd_q: f64,
    sd_r: f64,
    sd_p1: f64,
    half_inv_q: f64,
    half_inv_r: f64,
    log_norm_q: f64,
    log_norm_r: f64,
}

/// A simulated record of [`Nlbench`].
#[derive(Debug, Clone, PartialEq)]
pub struct NlbenchSimulation {
    /// States `x_0..x_{T-1}`.
    pub states: Vec<f64>,
    /// Outputs `y_0..y_{T-1}`.
    pub outputs: Vec<f64>,
}

impl Nlbench {
    /// The model with parameters `params`. Errors (naming the parameter) unless the
    /// coefficients are finite and the variances positive (`p1 >= 0`).
    pub fn new(params: NlbenchParams) -> Result<Self, ModelError> {
        let p = params;
        for (name, v) in [("a", p.a), ("b", p.b), ("c", p.c), ("d", p.d), ("mu", p.mu)] {
            if !v.is_finite() {
                return Err(format!("nlbench parameter {name} = {v} is not finite").into());
            }
        }
        for (name, v) in [("q", p.q), ("r", p.r)] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(
                    format!("nlbench variance {name} = {v} must be positive and finite").into(),
                );
            }
        }
        if !(p.p1 >= 0.0 && p.p1.is_finite()) {
            return Err(format!("nlbench variance p1 = {} must be >= 0 and finite", p.p1).into());
        }
        Ok(Nlbench {
            params,
            sd_q: p.q.sqrt(),
            sd_r: p.r.sqrt(),
            sd_p1: p.p1.sqrt(),
            half_inv_q: 0.5 / p.q,
            half_inv_r: 0.5 / p.r,
            log_norm_q: -0.5 * (LN_2PI + p.q.ln()),
            log_norm_r: -0.5 * (LN_2PI + p.r.ln()),
        })
    }

    /// The model at the true parameters.
    pub fn truth() -> Self {
        Nlbench::new(NlbenchParams::TRUE).expect("the true parameters are valid")
    }

    /// The parameters.
    pub fn params(&self) -> &NlbenchParams {
        &self.params
    }

    /// The input-free forcing `c cos(1.2 (t + 1))` of the transition from step `t`.
    #[inline]
    pub fn forcing(&self, t: usize) -> f64 {
        self.params.c * forcing_cosine(t)
    }

    /// The transition mean `a x + b x / (1 + x^2) + forcing`.
    #[inline]
    fn mean(&self, x: f64, forcing: f64) -> f64 {
        self.params.a * x + self.params.b * x / (1.0 + x * x) + forcing
    }

    /// Writes the transition means of `from` at step `t` into `means`.
    #[inline(always)]
    fn transition_means(
        &self,
        t: usize,
        from: &[f64],
        means: &mut Vec<f64>,
    ) -> ScalarGaussianKernel {
        let forcing = self.forcing(t);
        means.clear();
        means.extend(from.iter().map(|&x| self.mean(x, forcing)));
        self.transition_kernel()
    }

    /// The transition noise `N(0, q)` as a kernel of `(mean, next)`.
    #[inline(always)]
    fn transition_kernel(&self) -> ScalarGaussianKernel {
        ScalarGaussianKernel {
            log_norm: self.log_norm_q,
            half_inv_var: self.half_inv_q,
        }
    }

    /// `log N(next; mean, q)`.
    #[inline(always)]
    fn log_transition_density(&self, mean: f64, next: f64) -> f64 {
        self.transition_kernel().log_density(mean, next)
    }

    /// `log N(y; d x^2, r)`.
    #[inline(always)]
    fn log_observation_density(&self, x: f64, y: f64) -> f64 {
        let e = y - self.params.d * x * x;
        self.log_norm_r - self.half_inv_r * e * e
    }

    /// Simulates `steps` samples from the random stream `(seed, 0)`: the initial state,
    /// then per step the measurement noise and the process noise.
    pub fn simulate(&self, steps: usize, seed: u64) -> NlbenchSimulation {
        let mut rng = stream(seed, 0);
        let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
        let mut x = self.params.mu + self.sd_p1 * normal();
        let mut states = Vec::with_capacity(steps);
        let mut outputs = Vec::with_capacity(steps);
        for t in 0..steps {
            states.push(x);
            outputs.push(self.params.d * x * x + self.sd_r * normal());
            x = self.mean(x, self.forcing(t)) + self.sd_q * normal();
        }
        NlbenchSimulation { states, outputs }
    }
}

impl StateSpace for Nlbench {
    fn state_dim(&self) -> usize {
        1
    }
}

impl InitialSampler for Nlbench {
    #[inline]
    fn sample_initial<R: Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
        let z: f64 = StandardNormal.sample(rng);
        x[0] = self.params.mu + self.sd_p1 * z;
    }
}

impl InitialDensity for Nlbench {
    /// `log N(x; mu, p1)`; with `p1 = 0` the initial state is `mu` exactly, so the
    /// log-density (against the point mass) is 0 at `mu` and `-inf` elsewhere.
    fn log_initial(&self, x: &[f64]) -> f64 {
        let p = &self.params;
        if p.p1 == 0.0 {
            return if x[0] == p.mu { 0.0 } else { f64::NEG_INFINITY };
        }
        let e = x[0] - p.mu;
        -0.5 * (LN_2PI + p.p1.ln()) - 0.5 * e * e / p.p1
    }
}

impl TransitionSampler for Nlbench {
    #[inline]
    fn sample_transition<R: Rng + ?Sized>(
        &self,
        t: usize,
        x: &[f64],
        _u: &[f64],
        next: &mut [f64],
        rng: &mut R,
    ) {
        let z: f64 = StandardNormal.sample(rng);
        next[0] = self.mean(x[0], self.forcing(t)) + self.sd_q * z;
    }

    #[inline(always)]
    fn sample_transitions<R: Rng + ?Sized>(
        &self,
        t: usize,
        _u: &[f64],
        from: &[f64],
        parents: &[usize],
        next: &mut [f64],
        rng: &mut R,
    ) {
        let forcing = self.forcing(t);
        // gather first (bounds-checked), then the mean with vector divisions
        for (x, &p) in next.iter_mut().zip(parents) {
            *x = from[p];
        }
        for x in next.iter_mut() {
            *x = self.mean(*x, forcing);
        }
        add_scaled_normals(rng, self.sd_q, next);
    }
}

impl ObservationDensity for Nlbench {
    #[inline]
    fn log_observation(&self, _t: usize, x: &[f64], _u: &[f64], y: &[f64]) -> f64 {
        self.log_observation_density(x[0], y[0])
    }

    #[inline(always)]
    fn log_observations(&self, _t: usize, _u: &[f64], y: &[f64], states: &[f64], out: &mut [f64]) {
        for (lg, &x) in out.iter_mut().zip(states) {
            *lg = self.log_observation_density(x, y[0]);
        }
    }
}

impl TransitionDensity for Nlbench {
    #[inline]
    fn log_transition(&self, t: usize, x: &[f64], _u: &[f64], next: &[f64]) -> f64 {
        self.log_transition_density(self.mean(x[0], self.forcing(t)), next[0])
    }

    fn log_transition_at<'a>(
        &'a self,
        t: usize,
        _u: &'a [f64],
    ) -> impl Fn(&[f64], &[f64]) -> f64 + 'a {
        let forcing = self.forcing(t);
        move |x, next| self.log_transition_density(self.mean(x[0], forcing), next[0])
    }

    #[inline(always)]
    fn scalar_gaussian_means(
        &self,
        t: usize,
        _u: &[f64],
        from: &[f64],
        means: &mut Vec<f64>,
    ) -> Option<ScalarGaussianKernel> {
        Some(self.transition_means(t, from, means))
    }
}

impl TransitionBound for Nlbench {
    fn log_transition_bound(&self, _t: usize, _u: &[f64]) -> f64 {
        self.log_norm_q
    }
}

/// `cos(1.2 (t + 1))`, the same number as computing it, from a table shared by every
/// model for `t` below [`FORCING_TABLE`]: particle EM and the smoothers ask for it
/// thousands of times per step index (a libm `cos` was ~3 % of a particle EM run).
pub(crate) fn forcing_cosine(t: usize) -> f64 {
    static TABLE: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    let direct = |t: usize| (1.2 * (t as f64 + 1.0)).cos();
    match TABLE
        .get_or_init(|| (0..FORCING_TABLE).map(direct).collect())
        .get(t)
    {
        Some(&c) => c,
        None => direct(t),
    }
}

/// Steps whose forcing cosine is tabulated (64 KiB).
const FORCING_TABLE: usize = 8192;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_forcing_table_gives_the_computed_cosines() {
        for t in (0..FORCING_TABLE + 100).step_by(7) {
            let direct = (1.2 * (t as f64 + 1.0)).cos();
            assert_eq!(forcing_cosine(t).to_bits(), direct.to_bits(), "t = {t}");
        }
    }
}
