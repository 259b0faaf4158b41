//! Draws from the conjugate conditionals that exact Gibbs parameter steps need: the
//! Gaussian of a linear regression's coefficients given its precision, and the
//! inverse gamma of a noise variance.

use nalgebra::{DMatrix, DVector};
use rand_distr::{Distribution, Gamma, StandardNormal};
use sysid_smc::ModelError;
use sysid_smc::Rng;

/// A draw from `N(P^{-1} b, P^{-1})` for a symmetric positive definite precision `P`
/// and `b = rhs`: with `P = L L'`, the mean solves `P m = b` and `L^{-T} eps` (`eps`
/// standard normal) has covariance `P^{-1}`. No inverse is formed.
///
/// # Errors
/// `P` not positive definite (`what` names it in the message).
pub fn gaussian_from_precision(
    precision: DMatrix<f64>,
    rhs: &DVector<f64>,
    what: &str,
    rng: &mut Rng,
) -> Result<DVector<f64>, ModelError> {
    let chol = precision
        .cholesky()
        .ok_or_else(|| format!("the conditional precision of {what} is not positive definite"))?;
    let mean = chol.solve(rhs);
    let eps = DVector::from_fn(rhs.len(), |_, _| StandardNormal.sample(rng));
    let offset = chol
        .l()
        .transpose()
        .solve_upper_triangular(&eps)
        .ok_or_else(|| format!("a singular Cholesky factor of {what}'s precision"))?;
    Ok(mean + offset)
}

/// A draw from `IG(shape, scale)` as the reciprocal of a `Gamma(shape, rate = scale)`.
///
/// # Errors
/// A shape or scale that is not positive and finite.
pub fn inverse_gamma(shape: f64, scale: f64, rng: &mut Rng) -> Result<f64, ModelError> {
    let gamma = Gamma::new(shape, 1.0 / scale)
        .map_err(|e| format!("{e} (shape {shape}, scale {scale})"))?;
    Ok(1.0 / gamma.sample(rng))
}
