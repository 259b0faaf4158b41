//! SQUAREM: squared extrapolation of the EM map (Varadhan and Roland 2008), kept
//! monotone.

use super::{LinearEm, LinearEmError, LinearEmSpec, m_step};
use crate::EmAlgorithm;
use nalgebra::DMatrix;
use sysid_kalman::{LinearGaussianModel, Record};

/// Linear EM accelerated by SQUAREM (scheme S3), as an [`EmAlgorithm`] whose every
/// step is one SQUAREM cycle.
///
/// # Algorithm
/// From `theta_0`: two EM steps `theta_1 = M(theta_0)`, `theta_2 = M(theta_1)`;
/// `r = theta_1 - theta_0`, `v = theta_2 - 2 theta_1 + theta_0`, the step length
/// `alpha = -|r| / |v|` (clamped to `[-alpha_max, -1]`) and the extrapolation
/// `theta' = theta_0 - 2 alpha r + alpha^2 v`, entry by entry over every matrix of the
/// model (fixed entries have `r = v = 0` and stay as they are). The cycle returns
/// `M(theta')`. `alpha = -1` gives `theta' = theta_2`, plain EM.
///
/// The safeguard keeps the run monotone, as exact EM: `theta'` is kept only when it is
/// a valid model in the spec's parameter set (PSD covariances, the variance floors)
/// and `log p(y | theta') >= log p(y | theta_1)`; otherwise the cycle falls back to
/// `theta' = theta_2`. Since `M` never lowers the likelihood, the cycle's result is at
/// least as likely as `theta_2`, hence as `theta_0`. `alpha_max` starts at 1, grows
/// fourfold whenever the clamp binds and shrinks fourfold after a fallback (the
/// defaults of Varadhan and Roland's `SQUAREM` package).
///
/// # Stopping
/// [`crate::EmAlgorithm::remaining_gain`] is Aitken's estimate from the plain EM
/// values `l(theta_0), l(theta_1), l(theta_2)`: how much plain EM would still gain
/// from `theta_2`, an upper estimate of what is left after the cycle (which ends at
/// least as high as `theta_2`).
///
/// # Cost
/// Three E-steps per cycle: `theta_0`, `theta_1`, and `theta'` with a likelihood-only
/// pass at `theta_2`, or `theta_2` itself after a fallback (whose extrapolation, if
/// valid, cost a fourth). Along the slow ridges where EM crawls (small variances,
/// offsets and levels that trade off) a cycle typically advances as far as tens of EM
/// steps.
///
/// # References
/// R. Varadhan and C. Roland, "Simple and globally convergent methods for
/// accelerating the convergence of any EM algorithm", Scand. J. Statistics 35, 2008.
pub struct SquaremLinearEm<'a> {
    em: LinearEm<'a>,
    alpha_max: f64,
    /// E-steps run so far.
    pub e_steps: usize,
    /// Cycles whose extrapolation was kept.
    pub accepted: usize,
    /// Aitken's estimate of the gain left after the last cycle's plain EM steps.
    remaining: Option<f64>,
}

impl<'a> SquaremLinearEm<'a> {
    /// SQUAREM-accelerated EM on `records` with the parameters of `spec` free.
    pub fn new(records: &'a [Record], spec: LinearEmSpec) -> Self {
        SquaremLinearEm {
            em: LinearEm::new(records, spec),
            alpha_max: 1.0,
            e_steps: 0,
            accepted: 0,
            remaining: None,
        }
    }

    fn em_step(
        &mut self,
        model: &LinearGaussianModel,
    ) -> Result<(LinearGaussianModel, f64), LinearEmError> {
        self.e_steps += 1;
        let (stats, loglik) = self.em.e_step(model)?;
        Ok((m_step(model, &stats, &self.em.spec)?, loglik))
    }

    /// `theta_0 - 2 alpha r + alpha^2 v` as a model in the spec, if it is one.
    fn extrapolate(
        &self,
        template: &LinearGaussianModel,
        theta: [&[DMatrix<f64>; PARTS]; 3],
        alpha: f64,
    ) -> Option<LinearGaussianModel> {
        let mixed: [DMatrix<f64>; PARTS] = std::array::from_fn(|k| {
            let (m0, m1, m2) = (&theta[0][k], &theta[1][k], &theta[2][k]);
            m0 - 2.0 * alpha * (m1 - m0) + alpha * alpha * (m2 - 2.0 * m1 + m0)
        });
        let model = from_parts(template, mixed)?;
        self.em.spec.check(&model).ok()?;
        Some(model)
    }
}

/// How many matrices [`parts`] lists.
const PARTS: usize = 10;

/// A model's matrices in a fixed order, vectors as columns: `A, B, C, D, h, Q, R, S,
/// mu, P1` (what SQUAREM extrapolates, entry by entry).
fn parts(m: &LinearGaussianModel) -> [DMatrix<f64>; PARTS] {
    let column = |v: &nalgebra::DVector<f64>| DMatrix::from_column_slice(v.len(), 1, v.as_slice());
    [
        m.a().clone(),
        m.b().clone(),
        m.c().clone(),
        m.d().clone(),
        column(m.h()),
        m.q().clone(),
        m.r().clone(),
        m.s().clone(),
        column(m.mu()),
        m.p1().clone(),
    ]
}

/// The model with the matrices of [`parts`] (covariances symmetrised), if valid.
fn from_parts(
    template: &LinearGaussianModel,
    parts: [DMatrix<f64>; PARTS],
) -> Option<LinearGaussianModel> {
    let [a, b, c, d, h, mut q, mut r, s, mu, mut p1] = parts;
    for cov in [&mut q, &mut r, &mut p1] {
        sysid_linalg::symmetrize(cov);
    }
    template
        .to_builder()
        .a(a)
        .b(b)
        .c(c)
        .d(d)
        .h(h.column(0).clone_owned())
        .q(q)
        .r(r)
        .s(s)
        .mu(mu.column(0).clone_owned())
        .p1(p1)
        .build()
        .ok()
}

/// The squared norms of `r = theta_1 - theta_0` and `v = theta_2 - 2 theta_1 + theta_0`
/// over all the matrices.
fn norms(theta: [&[DMatrix<f64>; PARTS]; 3]) -> (f64, f64) {
    let (mut r2, mut v2) = (0.0, 0.0);
    for ((m0, m1), m2) in theta[0].iter().zip(theta[1]).zip(theta[2]) {
        r2 += (m1 - m0).norm_squared();
        v2 += (m2 - 2.0 * m1 + m0).norm_squared();
    }
    (r2, v2)
}

impl EmAlgorithm for SquaremLinearEm<'_> {
    type Estimate = LinearGaussianModel;
    type Error = LinearEmError;

    fn step(
        &mut self,
        theta0: &LinearGaussianModel,
    ) -> Result<(LinearGaussianModel, f64), LinearEmError> {
        // A failure after theta_0's E-step hands back the model whose E-step failed:
        // the runner's next step fails on it at once and returns theta_0 with its
        // log-likelihood, the last good model, instead of losing the start.
        let (theta1, l0) = self.em_step(theta0)?;
        let (theta2, l1) = match self.em_step(&theta1) {
            Ok(v) => v,
            Err(_) => return Ok((theta1, l0)),
        };
        let listed = [parts(theta0), parts(&theta1), parts(&theta2)];
        let theta = [&listed[0], &listed[1], &listed[2]];
        let (r2, v2) = norms(theta);
        let mut alpha = if v2 > 0.0 && r2 > 0.0 {
            -(r2 / v2).sqrt()
        } else {
            -1.0
        };
        if alpha <= -self.alpha_max {
            alpha = -self.alpha_max;
            self.alpha_max *= 4.0;
        }
        let alpha = alpha.min(-1.0);
        if alpha < -1.0
            && let Some(candidate) = self.extrapolate(theta0, theta, alpha)
        {
            match self.em_step(&candidate) {
                Ok((next, l_candidate)) if l_candidate.is_finite() && l_candidate >= l1 => {
                    self.accepted += 1;
                    // the plain EM sequence's third value, for the stopping rule: one
                    // likelihood pass
                    if let Ok(l2) = self.em.loglik(&theta2) {
                        self.remaining = Some(crate::remaining_gain(l0, l1, l2));
                    }
                    return Ok((next, l0));
                }
                _ => {}
            }
        }
        // fallback: plain EM (theta' = theta_2), and a shorter step next time
        if alpha < -1.0 {
            self.alpha_max = (self.alpha_max / 4.0).max(1.0);
        }
        let (next, l2) = match self.em_step(&theta2) {
            Ok(v) => v,
            Err(_) => return Ok((theta2, l0)),
        };
        self.remaining = Some(crate::remaining_gain(l0, l1, l2));
        Ok((next, l0))
    }

    fn loglik(&mut self, estimate: &LinearGaussianModel) -> Result<f64, LinearEmError> {
        self.em.loglik(estimate)
    }

    fn remaining_gain(&self) -> Option<f64> {
        self.remaining
    }
}
