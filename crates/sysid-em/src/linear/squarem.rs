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
/// Three E-steps per cycle (`theta_0`, `theta_1`, `theta'`; a fallback adds one for
/// `theta_2`) and one likelihood-only filter pass (`theta_2`). Along the slow ridges where EM crawls (small variances, offsets and
/// levels that trade off) a cycle typically advances as far as tens of EM steps.
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
        theta: [&LinearGaussianModel; 3],
        alpha: f64,
    ) -> Option<LinearGaussianModel> {
        let mix = |get: fn(&LinearGaussianModel) -> DMatrix<f64>| {
            let (m0, m1, m2) = (get(theta[0]), get(theta[1]), get(theta[2]));
            let r = &m1 - &m0;
            let v = &m2 - 2.0 * &m1 + &m0;
            m0 - 2.0 * alpha * r + alpha * alpha * v
        };
        let column = |m: DMatrix<f64>| m.column(0).clone_owned();
        let mut q = mix(|m| m.q().clone());
        let mut r = mix(|m| m.r().clone());
        let mut p1 = mix(|m| m.p1().clone());
        for cov in [&mut q, &mut r, &mut p1] {
            sysid_linalg::symmetrize(cov);
        }
        let model = theta[0]
            .to_builder()
            .a(mix(|m| m.a().clone()))
            .b(mix(|m| m.b().clone()))
            .c(mix(|m| m.c().clone()))
            .d(mix(|m| m.d().clone()))
            .h(column(mix(|m| {
                DMatrix::from_column_slice(m.p(), 1, m.h().as_slice())
            })))
            .mu(column(mix(|m| {
                DMatrix::from_column_slice(m.n(), 1, m.mu().as_slice())
            })))
            .q(q)
            .r(r)
            .s(mix(|m| m.s().clone()))
            .p1(p1)
            .build()
            .ok()?;
        self.em.spec.check(&model).ok()?;
        Some(model)
    }
}

/// The squared Euclidean distance between two models over all their matrices, and
/// the same of the second difference.
fn norms(theta: [&LinearGaussianModel; 3]) -> (f64, f64) {
    let parts = |m: &LinearGaussianModel| -> Vec<DMatrix<f64>> {
        vec![
            m.a().clone(),
            m.b().clone(),
            m.c().clone(),
            m.d().clone(),
            DMatrix::from_column_slice(m.p(), 1, m.h().as_slice()),
            m.q().clone(),
            m.r().clone(),
            m.s().clone(),
            DMatrix::from_column_slice(m.n(), 1, m.mu().as_slice()),
            m.p1().clone(),
        ]
    };
    let (p0, p1, p2) = (parts(theta[0]), parts(theta[1]), parts(theta[2]));
    let (mut r2, mut v2) = (0.0, 0.0);
    for k in 0..p0.len() {
        r2 += (&p1[k] - &p0[k]).norm_squared();
        v2 += (&p2[k] - 2.0 * &p1[k] + &p0[k]).norm_squared();
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
        let (theta1, l0) = self.em_step(theta0)?;
        let (theta2, l1) = self.em_step(&theta1)?;
        // the plain EM sequence's rate, for the stopping rule: one likelihood pass
        let l2 = self.em.loglik(&theta2)?;
        self.remaining = Some(crate::remaining_gain(l0, l1, l2));
        let (r2, v2) = norms([theta0, &theta1, &theta2]);
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
            && let Some(candidate) = self.extrapolate([theta0, &theta1, &theta2], alpha)
        {
            match self.em_step(&candidate) {
                Ok((next, l_candidate)) if l_candidate.is_finite() && l_candidate >= l1 => {
                    self.accepted += 1;
                    return Ok((next, l0));
                }
                _ => {}
            }
        }
        // fallback: plain EM (theta' = theta_2), and a shorter step next time
        if alpha < -1.0 {
            self.alpha_max = (self.alpha_max / 4.0).max(1.0);
        }
        let (next, _) = self.em_step(&theta2)?;
        Ok((next, l0))
    }

    fn loglik(&mut self, estimate: &LinearGaussianModel) -> Result<f64, LinearEmError> {
        self.em.loglik(estimate)
    }

    fn remaining_gain(&self) -> Option<f64> {
        self.remaining
    }
}
