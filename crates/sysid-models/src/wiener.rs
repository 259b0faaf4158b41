//! The blind Wiener system of seed 001 (ALGORITHMS.md 4) and its estimation model for
//! gradient EM.

use crate::wiener_guided::GuideForm;
use crate::wiener_observations::SortedObservations;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use sysid_em::gradient::{GradientEmError, GradientModel, Gradients, ObservationSum};
use sysid_smc::ModelError;
use sysid_smc::{
    InitialSampler, ObservationDensity, Series, StateSpace, Trajectories, TransitionBound,
    TransitionDensity, TransitionSampler, stream,
};

pub(crate) const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// `h1`: saturation at `lo` and `hi` (`lo <= hi`; NaN propagates, never a panic).
#[inline]
pub fn saturation(z: f64, lo: f64, hi: f64) -> f64 {
    if z < lo {
        lo
    } else if z > hi {
        hi
    } else {
        z
    }
}

/// `h2`: dead zone between `lo` and `hi` (slope 1 outside).
#[inline]
pub fn dead_zone(z: f64, lo: f64, hi: f64) -> f64 {
    if z < lo {
        z - lo
    } else if z > hi {
        z - hi
    } else {
        0.0
    }
}

/// The true blind Wiener system.
///
/// # Model
/// ```text
/// x_{t+1} = [[1, -0.9], [1, 0]] x_t + [1; 0] u_t,   u_t ~ N(0, 1), not observed
/// z_t     = [1, 0.3] x_t
/// y_t     = [h1(z_t); h2(z_t)] + e_t,                e_t ~ N(0, diag(r1, r2))
/// ```
/// `h1` saturates at `beta1 = -2` and `beta2 = 3`; `h2` is a dead zone between
/// `beta3 = -1.5` and `beta4 = 1`; `r1 = r2 = 0.01`; `x_0 = 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlindWiener;

/// A simulated record of [`BlindWiener`].
#[derive(Debug, Clone, PartialEq)]
pub struct WienerSimulation {
    /// Outputs `y_t`, time-major (`T x 2`).
    pub outputs: Vec<f64>,
    /// The linear part's output `z_t`.
    pub z: Vec<f64>,
}

impl BlindWiener {
    /// `A`.
    pub const A: [[f64; 2]; 2] = [[1.0, -0.9], [1.0, 0.0]];
    /// `C`.
    pub const C: [f64; 2] = [1.0, 0.3];
    /// The breakpoints `beta1..beta4`.
    pub const BETA: [f64; 4] = [-2.0, 3.0, -1.5, 1.0];
    /// The measurement-noise variances.
    pub const R: [f64; 2] = [0.01, 0.01];

    /// Simulates `steps` samples from the random stream `(seed, 0)`: per step the
    /// input, then the two measurement noises.
    pub fn simulate(steps: usize, seed: u64) -> WienerSimulation {
        let mut rng = stream(seed, 0);
        let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
        let (a, c, b) = (Self::A, Self::C, Self::BETA);
        let mut x = [0.0, 0.0];
        let mut outputs = Vec::with_capacity(2 * steps);
        let mut z = Vec::with_capacity(steps);
        for _ in 0..steps {
            let u = normal();
            let zt = c[0] * x[0] + c[1] * x[1];
            z.push(zt);
            outputs.push(saturation(zt, b[0], b[1]) + Self::R[0].sqrt() * normal());
            outputs.push(dead_zone(zt, b[2], b[3]) + Self::R[1].sqrt() * normal());
            x = [
                a[0][0] * x[0] + a[0][1] * x[1] + u,
                a[1][0] * x[0] + a[1][1] * x[1],
            ];
        }
        WienerSimulation { outputs, z }
    }

    /// `|G(e^{i omega})|` of the linear part from `u` to `z`.
    pub fn magnitude(omega: f64) -> f64 {
        let q = [[1.0, 0.0], [0.0, 0.0]];
        spectral_magnitude(&Self::A, &q, &Self::C, omega)
    }
}

/// `sqrt(C (e^{iw} I - A)^{-1} Q (e^{iw} I - A)^{-H} C')` for a 2-state system: the
/// magnitude of the linear part seen through its process noise (the input's gain for
/// `Q = B B'`).
pub fn spectral_magnitude(a: &[[f64; 2]; 2], q: &[[f64; 2]; 2], c: &[f64; 2], omega: f64) -> f64 {
    let v = output_row(a, c, omega);
    // v Q v^H (real, >= 0)
    let mut total = 0.0;
    for i in 0..2 {
        for j in 0..2 {
            // Re(v_i q_ij conj(v_j))
            total += q[i][j] * (v[i].0 * v[j].0 + v[i].1 * v[j].1);
        }
    }
    total.max(0.0).sqrt()
}

/// `v = C (e^{iw} I - A)^{-1}` for a 2-state system, as `(re, im)` pairs.
pub(crate) fn output_row(a: &[[f64; 2]; 2], c: &[f64; 2], omega: f64) -> [(f64, f64); 2] {
    // M = e^{iw} I - A = [[m00, m01], [m10, m11]] (complex); v = C M^{-1}
    let (cw, sw) = (omega.cos(), omega.sin());
    let m = [
        [(cw - a[0][0], sw), (-a[0][1], 0.0)],
        [(-a[1][0], 0.0), (cw - a[1][1], sw)],
    ];
    let mul = |x: (f64, f64), y: (f64, f64)| (x.0 * y.0 - x.1 * y.1, x.0 * y.1 + x.1 * y.0);
    let sub = |x: (f64, f64), y: (f64, f64)| (x.0 - y.0, x.1 - y.1);
    let det = sub(mul(m[0][0], m[1][1]), mul(m[0][1], m[1][0]));
    let norm = det.0 * det.0 + det.1 * det.1;
    let inv_det = (det.0 / norm, -det.1 / norm);
    // M^{-1} = adj(M) / det; v_j = sum_i c_i (M^{-1})_{ij}
    let adj = [
        [m[1][1], (-m[0][1].0, -m[0][1].1)],
        [(-m[1][0].0, -m[1][0].1), m[0][0]],
    ];
    [0, 1].map(|j| {
        let s = (
            c[0] * adj[0][j].0 + c[1] * adj[1][j].0,
            c[0] * adj[0][j].1 + c[1] * adj[1][j].1,
        );
        mul(s, inv_det)
    })
}

/// The estimation model of blind Wiener identification, for gradient EM.
///
/// # Model
/// ```text
/// x_{t+1} = A x_t + v_t,   v_t ~ N(0, Q)   (A, Q full: the unobserved input is noise)
/// z_t     = x_{t,1}                        (C = [1, 0], a choice of state basis)
/// y_t     = [h1(z_t; beta1, beta2); h2(z_t; beta3, beta4)] + e_t,  e_t ~ N(0, diag(r1, r2))
/// x_0 ~ N(0, p1 I)
/// ```
/// Unconstrained parameters (13): `A` row-major (4); `ln L11, L21, ln L22` of the
/// Cholesky factor `L` of `Q` (3); `beta1, ln(beta2 - beta1), beta3, ln(beta4 - beta3)`
/// (4, so the breakpoints stay ordered); `ln r1, ln r2` (2). Gradients are analytic.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WienerModel {
    /// Variance of each component of `x_0`.
    pub p1: f64,
}

impl Default for WienerModel {
    fn default() -> Self {
        WienerModel { p1: 10.0 }
    }
}

/// The natural parameters of [`WienerModel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WienerEstimate {
    /// `A`.
    pub a: [[f64; 2]; 2],
    /// `Q`.
    pub q: [[f64; 2]; 2],
    /// `beta1..beta4`.
    pub beta: [f64; 4],
    /// `r1, r2`.
    pub r: [f64; 2],
}

impl WienerEstimate {
    /// The unconstrained parameter vector, or why the values cannot be represented
    /// (a `Q` that is not positive definite, unordered breakpoints, a variance <= 0).
    pub fn theta(&self) -> Result<Vec<f64>, ModelError> {
        let q = self.q;
        let l11 = q[0][0].sqrt();
        if l11.is_nan() || l11 <= 0.0 {
            return Err(format!("Q11 = {} is not positive", q[0][0]).into());
        }
        let l21 = q[1][0] / l11;
        let l22_sq = q[1][1] - l21 * l21;
        if l22_sq.is_nan() || l22_sq <= 0.0 {
            return Err("Q is not positive definite".into());
        }
        let [b1, b2, b3, b4] = self.beta;
        if !(b2 > b1 && b4 > b3) {
            return Err(format!("breakpoints {:?} are not ordered", self.beta).into());
        }
        if !(self.r[0] > 0.0 && self.r[1] > 0.0) {
            return Err(format!("variances {:?} must be positive", self.r).into());
        }
        Ok(vec![
            self.a[0][0],
            self.a[0][1],
            self.a[1][0],
            self.a[1][1],
            l11.ln(),
            l21,
            0.5 * l22_sq.ln(),
            b1,
            (b2 - b1).ln(),
            b3,
            (b4 - b3).ln(),
            self.r[0].ln(),
            self.r[1].ln(),
        ])
    }

    /// The values of an unconstrained vector.
    pub fn from_theta(theta: &[f64]) -> Self {
        let p = Unpacked::new(theta);
        WienerEstimate {
            a: p.a,
            q: [
                [p.l11 * p.l11, p.l11 * p.l21],
                [p.l11 * p.l21, p.l21 * p.l21 + p.l22 * p.l22],
            ],
            beta: p.beta,
            r: p.r,
        }
    }

    /// `sqrt(C (e^{iw} - A)^{-1} Q (.)^H C')` with `C = [1, 0]`.
    pub fn magnitude(&self, omega: f64) -> f64 {
        spectral_magnitude(&self.a, &self.q, &[1.0, 0.0], omega)
    }
}

/// [`WienerModel`]'s parameters unpacked once per evaluation of `Q^`.
#[derive(Debug, Clone, Copy)]
pub struct Unpacked {
    pub(crate) a: [[f64; 2]; 2],
    pub(crate) l11: f64,
    pub(crate) l21: f64,
    pub(crate) l22: f64,
    pub(crate) gap_sat: f64,
    pub(crate) gap_dead: f64,
    pub(crate) beta: [f64; 4],
    pub(crate) r: [f64; 2],
    /// `-ln(2 pi) - ln L11 - ln L22`
    transition_norm: f64,
    /// `-0.5 ln(2 pi r_i)`
    pub(crate) observation_norm: [f64; 2],
    inv_l11: f64,
    inv_l22: f64,
    pub(crate) inv_r: [f64; 2],
}

impl Unpacked {
    pub(crate) fn new(theta: &[f64]) -> Self {
        let (gap_sat, gap_dead) = (theta[8].exp(), theta[10].exp());
        Unpacked {
            a: [[theta[0], theta[1]], [theta[2], theta[3]]],
            l11: theta[4].exp(),
            l21: theta[5],
            l22: theta[6].exp(),
            gap_sat,
            gap_dead,
            beta: [theta[7], theta[7] + gap_sat, theta[9], theta[9] + gap_dead],
            r: [theta[11].exp(), theta[12].exp()],
            transition_norm: -LN_2PI - theta[4] - theta[6],
            inv_l11: (-theta[4]).exp(),
            inv_l22: (-theta[6]).exp(),
            inv_r: [(-theta[11]).exp(), (-theta[12]).exp()],
            observation_norm: [-0.5 * (LN_2PI + theta[11]), -0.5 * (LN_2PI + theta[12])],
        }
    }

    /// `w = L^{-1} (next - A x)` and `log N(next; A x, Q)`.
    #[inline]
    fn transition(&self, x: &[f64], next: &[f64]) -> ([f64; 2], f64) {
        let a = &self.a;
        let e0 = next[0] - (a[0][0] * x[0] + a[0][1] * x[1]);
        let e1 = next[1] - (a[1][0] * x[0] + a[1][1] * x[1]);
        let w0 = e0 * self.inv_l11;
        let w1 = (e1 - self.l21 * w0) * self.inv_l22;
        let value = self.transition_norm - 0.5 * (w0 * w0 + w1 * w1);
        ([w0, w1], value)
    }

    #[inline]
    fn outputs(&self, z: f64) -> [f64; 2] {
        let b = self.beta;
        [saturation(z, b[0], b[1]), dead_zone(z, b[2], b[3])]
    }

    #[inline]
    fn observation(&self, z: f64, y: &[f64]) -> f64 {
        let h = self.outputs(z);
        let mut total = 0.0;
        for i in 0..2 {
            if !y[i].is_nan() {
                let e = y[i] - h[i];
                total += self.observation_norm[i] - 0.5 * e * e * self.inv_r[i];
            }
        }
        total
    }
}

impl GradientModel for WienerModel {
    type Smc = WienerSmc;
    type Params = Unpacked;

    fn unpack(&self, theta: &[f64]) -> Unpacked {
        Unpacked::new(theta)
    }

    fn gradients(&self) -> Gradients {
        Gradients::Analytic
    }

    fn parameter_dim(&self) -> usize {
        13
    }

    fn state_dim(&self) -> usize {
        2
    }

    fn parameter_names(&self) -> Vec<String> {
        [
            "a11", "a12", "a21", "a22", "q11", "q21", "q22", "beta1", "beta2", "beta3", "beta4",
            "r1", "r2",
        ]
        .map(String::from)
        .to_vec()
    }

    fn constrained(&self, theta: &[f64]) -> Vec<f64> {
        let e = WienerEstimate::from_theta(theta);
        let mut out = vec![e.a[0][0], e.a[0][1], e.a[1][0], e.a[1][1]];
        out.extend([e.q[0][0], e.q[1][0], e.q[1][1]]);
        out.extend(e.beta);
        out.extend(e.r);
        out
    }

    fn smc_model(&self, theta: &[f64]) -> Result<WienerSmc, GradientEmError> {
        if theta.len() != 13 || theta.iter().any(|v| !v.is_finite()) {
            return Err(GradientEmError::InvalidParams(format!(
                "the Wiener model needs 13 finite parameters, got {theta:?}"
            )));
        }
        let p = Unpacked::new(theta);
        Ok(WienerSmc {
            p,
            sd_p1: self.p1.sqrt(),
            guide: p.guide_form(p.l11 * p.l11, [true, true]),
        })
    }

    /// `A` and `Q` by least squares of `x_{t+1}` on `x_t` over every path and step:
    /// `A = S10 S00^-1` (a Cholesky solve) and `Q` the mean outer product of the
    /// residuals (PSD by construction). `x_0`'s law has no free parameter, so this is
    /// the exact maximiser of `I1 + I2` over entries 0..7.
    fn maximise_dynamics(&self, paths: &Trajectories, theta: &mut [f64]) -> Option<Vec<usize>> {
        let pairs = paths.paths() * paths.steps().checked_sub(1)?;
        if pairs < 2 || theta.len() != 13 {
            return None;
        }
        let mut s00 = [[0.0; 2]; 2];
        let mut s10 = [[0.0; 2]; 2];
        for_each_pair(paths, |x, next| {
            for i in 0..2 {
                for j in 0..2 {
                    s00[i][j] += x[i] * x[j];
                    s10[i][j] += next[i] * x[j];
                }
            }
        });
        let l = cholesky2(&s00)?;
        let a = [solve_cholesky2(l, s10[0]), solve_cholesky2(l, s10[1])];
        let mut q = [[0.0; 2]; 2];
        for_each_pair(paths, |x, next| {
            let e = [
                next[0] - (a[0][0] * x[0] + a[0][1] * x[1]),
                next[1] - (a[1][0] * x[0] + a[1][1] * x[1]),
            ];
            for i in 0..2 {
                for j in 0..2 {
                    q[i][j] += e[i] * e[j];
                }
            }
        });
        q.iter_mut().flatten().for_each(|v| *v /= pairs as f64);
        let (l11, l21, l22) = cholesky2(&q)?;
        let dynamics = [a[0][0], a[0][1], a[1][0], a[1][1], l11.ln(), l21, l22.ln()];
        if dynamics.iter().any(|v| !v.is_finite()) {
            return None;
        }
        theta[..7].copy_from_slice(&dynamics);
        Some((0..7).collect())
    }

    /// The observability canonical form, with the process noise moved to the
    /// minimum-phase side; the law of `z` (hence of the outputs) is unchanged, up to
    /// the initial-state prior.
    ///
    /// 1. **Basis.** `x' = O x`, `O = [[1, 0], [a11, a12]]` (the second state is the
    ///    noise-free prediction of the next `z`): `A' = O A O^-1` is the companion
    ///    matrix `[[0, 1], [-det A, tr A]]` and `Q' = O Q O'`. The basis, which the
    ///    data cannot identify, then cannot drift.
    /// 2. **Noise.** In that form `z_{t+2} - tr z_{t+1} + det z_t` is an MA(1)
    ///    process whose autocovariances `g0 = (1 + tr^2) Q11 + Q22 - 2 tr Q12` and
    ///    `g1 = Q12 - tr Q11` are all the data can see. Every `Q` with the same
    ///    `(g0, g1)` is `Q11 = s`, `Q12 = g1 + tr s`, `Q22 = g0 + 2 tr g1 + (tr^2 - 1) s`,
    ///    positive semi-definite for `s` between the squares `s-` and `s+` of the
    ///    MA(1) factors: `s+` is the minimum-phase (innovations) form, `s-` the
    ///    maximum-phase one. Given `z`'s past, the second state is tracked with error
    ///    factor `g1 / s` per step, above 1 in modulus near `s-`: there a particle
    ///    filter loses the second state and EM stalls (measured: realisations ending
    ///    with `Q11` near 0 and magnitude errors of 0.15-0.25). The canonical `Q` takes
    ///    `s = s+ - MARGIN (s+ - s-)`, close to the innovations form but positive
    ///    definite, so that the backward kernel of the smoother stays proper.
    ///
    /// `theta` is returned unchanged when `a12` is zero relative to `A` (the basis is
    /// not observable); step 2 is skipped when `s+ = s-` (a spectral zero on the unit
    /// circle).
    fn canonical(&self, mut theta: Vec<f64>) -> Vec<f64> {
        if theta.len() != 13 {
            return theta;
        }
        let [a11, a12, a21, a22] = [theta[0], theta[1], theta[2], theta[3]];
        let scale = a11.abs() + a12.abs() + a21.abs() + a22.abs();
        if a12.abs().partial_cmp(&(1e-12 * scale)) != Some(std::cmp::Ordering::Greater) {
            return theta;
        }
        let (l11, l21) = (theta[4].exp(), theta[5]);
        let trace = a11 + a22;
        // L' = O L (lower triangular; a negative a12 flips the second state)
        let mut noise = (theta[4], a11 * l11 + a12 * l21, theta[6] + a12.abs().ln());
        if let Some(minimum_phase) = minimum_phase_noise(trace, noise) {
            noise = minimum_phase;
        }
        let canonical = [
            0.0,
            1.0,
            a12 * a21 - a11 * a22,
            trace,
            noise.0,
            noise.1,
            noise.2,
        ];
        if canonical.iter().all(|v| v.is_finite()) {
            theta[..7].copy_from_slice(&canonical);
        }
        theta
    }

    /// The states' `z` sorted once per output, with prefix sums: an evaluation of `I3`
    /// costs four binary searches (module `wiener_observations`).
    fn prepare_observations<'a>(
        &self,
        paths: &'a Trajectories,
        data: &'a Series<'a>,
    ) -> Option<Box<dyn ObservationSum + 'a>> {
        Some(Box::new(SortedObservations::new(paths, data)))
    }

    fn log_initial(&self, _p: &Unpacked, x: &[f64]) -> f64 {
        -LN_2PI - self.p1.ln() - 0.5 * (x[0] * x[0] + x[1] * x[1]) / self.p1
    }

    fn log_transition(&self, p: &Unpacked, _t: usize, x: &[f64], _u: &[f64], next: &[f64]) -> f64 {
        p.transition(x, next).1
    }

    fn log_observation(&self, p: &Unpacked, _t: usize, x: &[f64], _u: &[f64], y: &[f64]) -> f64 {
        p.observation(x[0], y)
    }

    #[inline]
    fn log_transition_gradient(
        &self,
        p: &Unpacked,
        _t: usize,
        x: &[f64],
        _u: &[f64],
        next: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        let ([w0, w1], value) = p.transition(x, next);
        // Q^{-1} e = L^{-T} w
        let v1 = w1 * p.inv_l22;
        let v0 = (w0 - p.l21 * v1) * p.inv_l11;
        grad[0] += v0 * x[0];
        grad[1] += v0 * x[1];
        grad[2] += v1 * x[0];
        grad[3] += v1 * x[1];
        grad[4] += -1.0 + w0 * w0 - w0 * w1 * p.l21 * p.inv_l22;
        grad[5] += w0 * w1 * p.inv_l22;
        grad[6] += -1.0 + w1 * w1;
        value
    }

    #[inline]
    fn log_observation_gradient(
        &self,
        p: &Unpacked,
        _t: usize,
        x: &[f64],
        _u: &[f64],
        y: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        let z = x[0];
        let h = p.outputs(z);
        let b = p.beta;
        if !y[0].is_nan() {
            let e = y[0] - h[0];
            let dh = e * p.inv_r[0]; // d log g / d h1
            // h1 = beta1 below, beta2 = beta1 + gap above
            if z < b[0] {
                grad[7] += dh;
            } else if z > b[1] {
                grad[7] += dh;
                grad[8] += dh * p.gap_sat;
            }
            grad[11] += -0.5 + 0.5 * e * e * p.inv_r[0];
        }
        if !y[1].is_nan() {
            let e = y[1] - h[1];
            let dh = e * p.inv_r[1];
            // h2 = z - beta3 below, z - beta4 = z - beta3 - gap above
            if z < b[2] {
                grad[9] -= dh;
            } else if z > b[3] {
                grad[9] -= dh;
                grad[10] -= dh * p.gap_dead;
            }
            grad[12] += -0.5 + 0.5 * e * e * p.inv_r[1];
        }
        p.observation(z, y)
    }
}

/// Calls `f(x_t, x_{t+1})` for every path and step of two-dimensional `paths`.
fn for_each_pair(paths: &Trajectories, mut f: impl FnMut(&[f64], &[f64])) {
    for t in 0..paths.steps().saturating_sub(1) {
        for (x, next) in paths
            .states(t)
            .chunks_exact(2)
            .zip(paths.states(t + 1).chunks_exact(2))
        {
            f(x, next);
        }
    }
}

/// `(L11, L21, L22)` of the Cholesky factor of a symmetric 2x2 matrix, if it is
/// positive definite.
fn cholesky2(m: &[[f64; 2]; 2]) -> Option<(f64, f64, f64)> {
    let l11 = m[0][0].sqrt();
    if l11.is_nan() || l11 <= 0.0 {
        return None;
    }
    let l21 = m[1][0] / l11;
    let l22 = (m[1][1] - l21 * l21).sqrt();
    (l22 > 0.0).then_some((l11, l21, l22))
}

/// `v` with `L L' v = b`.
fn solve_cholesky2((l11, l21, l22): (f64, f64, f64), b: [f64; 2]) -> [f64; 2] {
    let w0 = b[0] / l11;
    let w1 = (b[1] - l21 * w0) / l22;
    let v1 = w1 / l22;
    [(w0 - l21 * v1) / l11, v1]
}

/// How far from the innovations form the canonical process noise stays, as a
/// fraction of the range of equivalent noises (see `WienerModel::canonical`).
const MARGIN: f64 = 0.1;

/// The equivalent noise of a companion-form `A` (trace `trace`) closest to the
/// innovations form, as `(ln L11, L21, ln L22)` from the same; `None` when the
/// range of equivalent noises is a single point.
fn minimum_phase_noise(
    trace: f64,
    (ln_l11, l21, ln_l22): (f64, f64, f64),
) -> Option<(f64, f64, f64)> {
    let (l11, l22) = (ln_l11.exp(), ln_l22.exp());
    let (q11, q12, q22) = (l11 * l11, l11 * l21, l21 * l21 + l22 * l22);
    let g0 = (1.0 + trace * trace) * q11 + q22 - 2.0 * trace * q12;
    let g1 = q12 - trace * q11;
    let spread = (g0 * g0 - 4.0 * g1 * g1).max(0.0).sqrt();
    // s = s+ - MARGIN (s+ - s-)
    let s = 0.5 * (g0 + spread) - MARGIN * spread;
    // Q22 - Q12^2 / Q11 = (s+ - s)(s - s-) / s
    let schur = MARGIN * (1.0 - MARGIN) * spread * spread / s;
    if !(s > 0.0 && schur > 0.0 && schur.is_finite()) {
        return None;
    }
    let l11 = s.sqrt();
    Some((0.5 * s.ln(), (g1 + trace * s) / l11, 0.5 * schur.ln()))
}

/// [`WienerModel`] at fixed parameters, as a particle model.
#[derive(Debug, Clone, Copy)]
pub struct WienerSmc {
    pub(crate) p: Unpacked,
    pub(crate) sd_p1: f64,
    /// The guided proposal's constants for fully observed steps.
    pub(crate) guide: GuideForm,
}

impl StateSpace for WienerSmc {
    fn state_dim(&self) -> usize {
        2
    }
}

impl InitialSampler for WienerSmc {
    fn sample_initial<R: Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
        for v in x.iter_mut() {
            let e: f64 = StandardNormal.sample(rng);
            *v = self.sd_p1 * e;
        }
    }
}

impl TransitionSampler for WienerSmc {
    fn sample_transition<R: Rng + ?Sized>(
        &self,
        _t: usize,
        x: &[f64],
        _u: &[f64],
        next: &mut [f64],
        rng: &mut R,
    ) {
        let (e0, e1): (f64, f64) = (StandardNormal.sample(rng), StandardNormal.sample(rng));
        let a = &self.p.a;
        next[0] = a[0][0] * x[0] + a[0][1] * x[1] + self.p.l11 * e0;
        next[1] = a[1][0] * x[0] + a[1][1] * x[1] + self.p.l21 * e0 + self.p.l22 * e1;
    }
}

impl ObservationDensity for WienerSmc {
    fn log_observation(&self, _t: usize, x: &[f64], _u: &[f64], y: &[f64]) -> f64 {
        self.p.observation(x[0], y)
    }
}

impl TransitionDensity for WienerSmc {
    fn log_transition(&self, _t: usize, x: &[f64], _u: &[f64], next: &[f64]) -> f64 {
        self.p.transition(x, next).1
    }
}

impl TransitionBound for WienerSmc {
    fn log_transition_bound(&self, _t: usize, _u: &[f64]) -> f64 {
        self.p.transition_norm
    }
}

/// The frequency grid of the Wiener magnitude comparisons: `pi k / 64`, `k = 1..64`.
pub fn wiener_frequency_grid() -> Vec<f64> {
    (1..=64)
        .map(|k| std::f64::consts::PI * k as f64 / 64.0)
        .collect()
}

/// The error of an estimated linear part's normalised magnitude: both magnitudes on
/// [`wiener_frequency_grid`] are divided by their root mean square (the scale is not
/// identifiable), and the error is the root mean square of the difference (0 for a
/// perfect shape; 1 is as large as the response itself).
pub fn normalised_magnitude_error(estimate: &WienerEstimate) -> f64 {
    let grid = wiener_frequency_grid();
    let truth: Vec<f64> = grid.iter().map(|&w| BlindWiener::magnitude(w)).collect();
    let fitted: Vec<f64> = grid.iter().map(|&w| estimate.magnitude(w)).collect();
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let (nt, nf) = (rms(&truth), rms(&fitted));
    let diff: Vec<f64> = truth
        .iter()
        .zip(&fitted)
        .map(|(a, b)| b / nf - a / nt)
        .collect();
    rms(&diff)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_magnitude_does_not_depend_on_the_state_basis() {
        // the true system in the basis where C = [1, 0]: T = [[1, 0.3], [0, 1]]
        let a = BlindWiener::A;
        let t = [[1.0, 0.3], [0.0, 1.0]];
        let t_inv = [[1.0, -0.3], [0.0, 1.0]];
        let mul = |x: [[f64; 2]; 2], y: [[f64; 2]; 2]| {
            let mut out = [[0.0; 2]; 2];
            for i in 0..2 {
                for j in 0..2 {
                    out[i][j] = x[i][0] * y[0][j] + x[i][1] * y[1][j];
                }
            }
            out
        };
        let a2 = mul(mul(t, a), t_inv);
        // B = e1 and T e1 = e1, so Q = B B' stays [[1, 0], [0, 0]]
        let estimate = WienerEstimate {
            a: a2,
            q: [[1.0, 0.0], [0.0, 0.0]],
            beta: BlindWiener::BETA,
            r: BlindWiener::R,
        };
        for k in 1..20 {
            let w = 0.15 * k as f64;
            let (x, y) = (estimate.magnitude(w), BlindWiener::magnitude(w));
            assert!((x - y).abs() < 1e-12 * y, "{w}: {x} vs {y}");
        }
        // and against a direct evaluation of |C (e^{iw} - A)^{-1} B| at w = 0:
        // (I - A)^{-1} e1 = [[0, 0.9], [-1, 1]]^{-1}... solved by hand: x = (I - A)^{-1} e1
        // with (I - A) = [[0, 0.9], [-1, 1]]: x2 = x1, 0.9 x2 = 1 -> x = [1/0.9, 1/0.9]
        let direct = (1.0 + 0.3) / 0.9;
        assert!((BlindWiener::magnitude(0.0) - direct).abs() < 1e-12);
    }

    /// The canonical form keeps the spectrum, the nonlinearity and the noise
    /// variances, makes `A` a companion matrix, puts the process noise on the
    /// minimum-phase side, and is its own fixed point; a negative `a12` (a flipped
    /// second state) too.
    #[test]
    fn the_canonical_basis_keeps_the_model() {
        let model = WienerModel::default();
        for a12 in [4.6, -0.02] {
            let estimate = WienerEstimate {
                a: [[0.29, a12], [-0.15 * 4.6 / a12, 0.72]],
                q: [[0.8, 0.3], [0.3, 0.5]],
                beta: BlindWiener::BETA,
                r: BlindWiener::R,
            };
            let theta = estimate.theta().unwrap();
            let canonical = model.canonical(theta.clone());
            let c = WienerEstimate::from_theta(&canonical);
            assert_eq!(c.a[0], [0.0, 1.0]);
            // the observation entries of theta are untouched
            assert_eq!(canonical[7..], theta[7..]);
            let det = 0.29 * 0.72 + 0.15 * 4.6;
            assert!((c.a[1][0] + det).abs() < 1e-12 && (c.a[1][1] - 1.01).abs() < 1e-12);
            for k in 0..20 {
                let w = 0.15 * k as f64;
                let (x, y) = (c.magnitude(w), estimate.magnitude(w));
                assert!((x - y).abs() < 1e-10 * y, "{w}: {x} vs {y}");
            }
            // the second state is tracked stably given z's past: |g1 / s| < 1
            let trace = c.a[1][1];
            let g1 = c.q[0][1] - trace * c.q[0][0];
            assert!((g1 / c.q[0][0]).abs() < 1.0, "{:?}", c.q);
            let again = model.canonical(canonical.clone());
            for (x, y) in again.iter().zip(&canonical) {
                assert!((x - y).abs() < 1e-12 * y.abs().max(1.0));
            }
        }
        // an unobservable basis is left alone
        let mut theta = WienerEstimate::from_theta(&[0.0; 13]).theta().unwrap();
        theta[1] = 0.0;
        assert_eq!(model.canonical(theta.clone()), theta);
    }

    #[test]
    fn saturation_and_dead_zone() {
        assert_eq!(saturation(-3.0, -2.0, 3.0), -2.0);
        assert_eq!(saturation(5.0, -2.0, 3.0), 3.0);
        assert_eq!(saturation(0.5, -2.0, 3.0), 0.5);
        assert_eq!(dead_zone(-2.0, -1.5, 1.0), -0.5);
        assert_eq!(dead_zone(2.0, -1.5, 1.0), 1.0);
        assert_eq!(dead_zone(0.0, -1.5, 1.0), 0.0);
        assert!(saturation(f64::NAN, -1.0, 1.0).is_nan());
    }
}
