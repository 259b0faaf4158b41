//! The closed-form M-step of linear EM (the Cholesky route of Gibson and Ninness).

use super::{Covariance, LinearEmError, LinearEmSpec, floor_output_noise, floor_variances};
use crate::regression::fit_block;
use nalgebra::{DMatrix, DVector};
use sysid_kalman::{LinearGaussianModel, SufficientStatistics};
use sysid_linalg::psd_factor;

/// The M-step's noise covariance with the spec's structure and variance floor.
pub(super) fn structured(
    cov: DMatrix<f64>,
    structure: Covariance,
    initial: &DMatrix<f64>,
    floor: f64,
) -> DMatrix<f64> {
    match structure {
        Covariance::Full => floor_variances(cov, structure, floor),
        Covariance::Diagonal => {
            floor_variances(DMatrix::from_diagonal(&cov.diagonal()), structure, floor)
        }
        Covariance::Fixed => initial.clone(),
    }
}

/// The M-step: the parameters that maximise the expected complete-data log-likelihood
/// given the smoothed statistics, subject to `spec` (everything not estimated keeps its
/// value in `model`).
///
/// # Algorithm
/// With `S = 0` the state and output equations decouple, and within each the rows
/// share their regressors, so the maximiser is one least-squares regression per block
/// (Gibson and Ninness 2005; Blocker 2008): `x_{t+1}` minus its fixed part on the free
/// columns of `[x_t; u_t]`, and `y_t` minus its fixed part on the free columns of
/// `[x_t; u_t; 1]`, each by the Cholesky route (`crate::regression`). A diagonal `Q` or `R`
/// keeps the diagonal of the residual covariance (the rows are then independent
/// regressions with the same regressors, so the coefficients do not change). The
/// initial state: `mu = mean E{x_1}`, `P1 = mean E{(x_1 - mu)(x_1 - mu)'}` over records.
/// With `spec.min_variance > 0`, a free `Q` or `R` is the constrained maximiser
/// ([`floor_variances`]); the regression coefficients do not depend on it.
///
/// Fixed individual entries or a free `S` switch to the conditional route
/// (`ecm`): a generalised least-squares step for the free entries of
/// `[[A, B, 0], [C, D, h]]` given the current noise covariance, then the noise
/// covariance given the new coefficients; each is an exact conditional maximum, so the
/// likelihood still cannot decrease.
///
/// # Errors
/// [`LinearEmError::Unsupported`] when `Q` or `R` is estimated while the model has a
/// non-zero fixed `S`, or when the conditional route meets a singular noise covariance;
/// [`LinearEmError::InvalidSpec`]; [`LinearEmError::NoSteps`] for empty statistics;
/// [`LinearEmError::Kalman`] if the new model fails validation (it should not).
pub fn m_step(
    model: &LinearGaussianModel,
    stats: &SufficientStatistics,
    spec: &LinearEmSpec,
) -> Result<LinearGaussianModel, LinearEmError> {
    spec.check(model)?;
    if spec.needs_ecm() {
        return super::ecm::m_step_ecm(model, stats, spec);
    }
    let (n, m, p) = (model.n(), model.m(), model.p());
    if model.has_cross_covariance() && (spec.q != Covariance::Fixed || spec.r != Covariance::Fixed)
    {
        return Err(LinearEmError::Unsupported(
            "estimating Q or R of a model with a non-zero cross-covariance S".into(),
        ));
    }
    if stats.steps() == 0 || stats.records() == 0 {
        return Err(LinearEmError::NoSteps);
    }
    let steps = stats.steps() as f64;
    let (ox, ou, o1, oxn, oy) = (0, n, n + m, n + m + 1, 2 * n + m + 1);
    let factor = psd_factor("H (smoothed second moments)", stats.second_moment())?;
    let mut builder = model.to_builder();

    // ---- state block: x_{t+1} on [x_t; u_t] ----
    if spec.a || spec.b || spec.q != Covariance::Fixed {
        let groups = [
            (spec.a, ox..ox + n, model.a()),
            (spec.b, ou..ou + m, model.b()),
        ];
        let (coef, cov) = fit_block(&factor, oxn..oxn + n, &groups, steps);
        if let Some(a) = coef[0].clone() {
            builder = builder.a(a);
        }
        if let Some(b) = coef[1].clone() {
            builder = builder.b(b);
        }
        builder = builder.q(structured(cov, spec.q, model.q(), spec.min_variance));
    }

    // ---- output block: y_t on [x_t; u_t; 1] ----
    if spec.c || spec.d || spec.h || spec.r != Covariance::Fixed {
        let h_column = DMatrix::from_column_slice(p, 1, model.h().as_slice());
        let groups = [
            (spec.c, ox..ox + n, model.c()),
            (spec.d, ou..ou + m, model.d()),
            (spec.h, o1..o1 + 1, &h_column),
        ];
        let (coef, cov) = fit_block(&factor, oy..oy + p, &groups, steps);
        if let Some(c) = coef[0].clone() {
            builder = builder.c(c);
        }
        if let Some(d) = coef[1].clone() {
            builder = builder.d(d);
        }
        if let Some(h) = &coef[2] {
            builder = builder.h(h.column(0).clone_owned());
        }
        builder = builder.r(floor_output_noise(
            structured(cov, spec.r, model.r(), spec.min_variance),
            spec.r,
            spec.output_noise_floor.as_ref(),
        ));
    }

    builder = initial_state(builder, model, stats, spec);
    Ok(builder.build()?)
}

/// The initial-state update: `mu = mean E{x_1}` and
/// `P1 = mean E{(x_1 - mu)(x_1 - mu)'}` over records, where the spec frees them.
pub(super) fn initial_state(
    mut builder: sysid_kalman::ModelBuilder,
    model: &LinearGaussianModel,
    stats: &SufficientStatistics,
    spec: &LinearEmSpec,
) -> sysid_kalman::ModelBuilder {
    let records = stats.records() as f64;
    let s1 = stats.initial_mean_sum();
    let s2 = stats.initial_second_moment_sum();
    let mu: DVector<f64> = if spec.mu {
        s1 / records
    } else {
        model.mu().clone()
    };
    if spec.mu {
        builder = builder.mu(mu.clone());
    }
    if spec.p1 {
        // mean E{(x1 - mu)(x1 - mu)'} = (S2 - S1 mu' - mu S1') / K + mu mu'
        let mut p1 =
            (s2 - s1 * mu.transpose() - &mu * s1.transpose()) / records + &mu * mu.transpose();
        sysid_linalg::symmetrize(&mut p1);
        builder = builder.p1(p1);
    }
    builder
}
