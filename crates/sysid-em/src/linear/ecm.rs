//! The conditional (ECM) M-step: fixed individual entries of `A`, `B`, `C`, `D`, and a
//! free cross-covariance `S`.

use super::floor_variances;
use super::mstep::{initial_state, structured};
use super::{Covariance, LinearEmError, LinearEmSpec};
use nalgebra::{DMatrix, DVector};
use sysid_kalman::{LinearGaussianModel, SufficientStatistics};
use sysid_linalg::psd_factor;

/// Which entries of `Gamma = [[A, B, 0], [C, D, h]]` (`(n + p) x (n + m + 1)`) are free.
fn free_mask(model: &LinearGaussianModel, spec: &LinearEmSpec) -> DMatrix<bool> {
    let (n, m, p) = (model.n(), model.m(), model.p());
    let f = &spec.fixed_entries;
    let free = |estimate: bool, mask: &Option<DMatrix<bool>>, i: usize, j: usize| {
        estimate && !mask.as_ref().is_some_and(|mk| mk[(i, j)])
    };
    DMatrix::from_fn(n + p, n + m + 1, |row, col| match (row < n, col) {
        (true, c) if c < n => free(spec.a, &f.a, row, c),
        (true, c) if c < n + m => free(spec.b, &f.b, row, c - n),
        (true, _) => false, // no state offset
        (false, c) if c < n => free(spec.c, &f.c, row - n, c),
        (false, c) if c < n + m => free(spec.d, &f.d, row - n, c - n),
        (false, _) => spec.h,
    })
}

fn gamma_of(model: &LinearGaussianModel) -> DMatrix<f64> {
    let (n, m, p) = (model.n(), model.m(), model.p());
    let mut g = DMatrix::zeros(n + p, n + m + 1);
    g.view_mut((0, 0), (n, n)).copy_from(model.a());
    g.view_mut((0, n), (n, m)).copy_from(model.b());
    g.view_mut((n, 0), (p, n)).copy_from(model.c());
    g.view_mut((n, n), (p, m)).copy_from(model.d());
    g.view_mut((n, n + m), (p, 1)).copy_from(model.h());
    g
}

/// The joint noise covariance `[[Q, S], [S', R]]`.
fn pi_of(model: &LinearGaussianModel) -> DMatrix<f64> {
    let (n, p) = (model.n(), model.p());
    let mut pi = DMatrix::zeros(n + p, n + p);
    pi.view_mut((0, 0), (n, n)).copy_from(model.q());
    pi.view_mut((0, n), (n, p)).copy_from(model.s());
    pi.view_mut((n, 0), (p, n))
        .copy_from(&model.s().transpose());
    pi.view_mut((n, n), (p, p)).copy_from(model.r());
    pi
}

/// One ECM iteration.
///
/// # Algorithm
/// With `xi = [x_{t+1}; y_t] = Gamma z + eta`, `z = [x_t; u_t; 1]`, `eta ~ N(0, Pi)`:
/// 1. coefficients given the current `Pi`: the expected complete-data log-likelihood
///    is `-1/2 tr(Pi^{-1} (H_xixi - Gamma H_zxi - H_xiz Gamma' + Gamma H_zz Gamma'))`, whose
///    gradient in the free entries vanishes at
///    `[(H_zz (x) Pi^{-1})]_FF gamma_F = [vec(Pi^{-1} H_xiz) - (H_zz (x) Pi^{-1}) gamma_fixed]_F`
///    (generalised least squares, column-major `vec`);
/// 2. `Pi` given the new `Gamma`: the residual second moment
///    `E = [-Gamma, I] H [-Gamma, I]' / N` (a Gram matrix through a factor of `H`), used
///    whole when `S` is free, else block by block with the structure of `Q` and `R`.
pub(super) fn m_step_ecm(
    model: &LinearGaussianModel,
    stats: &SufficientStatistics,
    spec: &LinearEmSpec,
) -> Result<LinearGaussianModel, LinearEmError> {
    let (n, m, p) = (model.n(), model.m(), model.p());
    if stats.steps() == 0 || stats.records() == 0 {
        return Err(LinearEmError::NoSteps);
    }
    if !spec.s
        && model.has_cross_covariance()
        && (spec.q != Covariance::Fixed || spec.r != Covariance::Fixed)
    {
        return Err(LinearEmError::Unsupported(
            "estimating Q or R of a model with a non-zero fixed cross-covariance S".into(),
        ));
    }
    let (k, q) = (n + m + 1, n + p);
    let h = stats.second_moment();
    let h_zz = h.view((0, 0), (k, k));
    let h_xiz = h.view((k, 0), (q, k));
    let pi_inv = pi_of(model)
        .cholesky()
        .map(|c| c.inverse())
        .ok_or_else(|| {
            LinearEmError::Unsupported(
                "fixed entries or a free S need a non-singular noise covariance [[Q, S], [S', R]]"
                    .into(),
            )
        })?;
    // ---- 1. free entries of Gamma by generalised least squares ----
    let mut gamma = gamma_of(model);
    let mask = free_mask(model, spec);
    let free: Vec<(usize, usize)> = (0..k)
        .flat_map(|j| (0..q).map(move |i| (i, j)))
        .filter(|&(i, j)| mask[(i, j)])
        .collect();
    if !free.is_empty() {
        let rhs_full = &pi_inv * h_xiz; // vec(Pi^{-1} H_xiz)
        let m_entry =
            |(i, j): (usize, usize), (r, l): (usize, usize)| h_zz[(j, l)] * pi_inv[(i, r)];
        let nf = free.len();
        let mut m_ff = DMatrix::zeros(nf, nf);
        let mut b = DVector::zeros(nf);
        for (a, &fa) in free.iter().enumerate() {
            b[a] = rhs_full[fa];
            for (c, &fc) in free.iter().enumerate() {
                m_ff[(a, c)] = m_entry(fa, fc);
            }
            for l in 0..k {
                for r in 0..q {
                    if !mask[(r, l)] && gamma[(r, l)] != 0.0 {
                        b[a] -= m_entry(fa, (r, l)) * gamma[(r, l)];
                    }
                }
            }
        }
        let solution = match m_ff.clone().cholesky() {
            Some(ch) => ch.solve(&b),
            None => {
                // a regressor without variation (e.g. an input that is always zero):
                // the minimum-norm solution keeps those coefficients at zero
                let svd = m_ff.svd(true, true);
                let tol = nf as f64 * f64::EPSILON * svd.singular_values.max();
                svd.solve(&b, tol)
                    .map_err(|e| LinearEmError::Unsupported(e.to_string()))?
            }
        };
        for (a, &(i, j)) in free.iter().enumerate() {
            gamma[(i, j)] = solution[a];
        }
    }
    // ---- 2. the noise covariance given Gamma ----
    let factor = psd_factor("H (smoothed second moments)", h)?;
    let mut w = DMatrix::zeros(q, k + q);
    w.view_mut((0, 0), (q, k)).copy_from(&(-&gamma));
    w.view_mut((0, k), (q, q)).fill_with_identity();
    let x = &factor * w.transpose();
    let mut e = x.transpose() * x / stats.steps() as f64;
    sysid_linalg::symmetrize(&mut e);
    let mut builder = model
        .to_builder()
        .a(gamma.view((0, 0), (n, n)).clone_owned())
        .b(gamma.view((0, n), (n, m)).clone_owned())
        .c(gamma.view((n, 0), (p, n)).clone_owned())
        .d(gamma.view((n, n), (p, m)).clone_owned())
        .h(gamma.view((n, n + m), (p, 1)).column(0).clone_owned());
    let e_ss = e.view((0, 0), (n, n)).clone_owned();
    let e_oo = e.view((n, n), (p, p)).clone_owned();
    if spec.s {
        let e = floor_variances(e, Covariance::Full, spec.min_variance);
        builder = builder
            .q(e.view((0, 0), (n, n)).clone_owned())
            .r(e.view((n, n), (p, p)).clone_owned())
            .s(e.view((0, n), (n, p)).clone_owned());
    } else {
        builder = builder
            .q(structured(e_ss, spec.q, model.q(), spec.min_variance))
            .r(super::floor_output_noise(
                structured(e_oo, spec.r, model.r(), spec.min_variance),
                spec.r,
                spec.output_noise_floor.as_ref(),
            ));
    }
    builder = initial_state(builder, model, stats, spec);
    Ok(builder.build()?)
}
