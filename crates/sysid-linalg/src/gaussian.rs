use nalgebra::DMatrix;

/// `ln(2 pi)`.
pub const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// `log det(U'U) = 2 sum_i log|U_ii|` for a triangular factor `U`.
///
/// A zero diagonal entry gives `-inf` (a singular covariance).
pub fn logdet_from_factor(u: &DMatrix<f64>) -> f64 {
    2.0 * (0..u.nrows().min(u.ncols()))
        .map(|i| u[(i, i)].abs().ln())
        .sum::<f64>()
}

/// Log-density of `N(mean, U'U)` at `x`, given the upper-triangular factor `U`,
/// as `-k/2 ln(2 pi) - sum ln|U_ii| - |U^{-T}(x - mean)|^2 / 2`.
///
/// Returns `-inf` when the covariance is singular and `x - mean` leaves its support
/// direction, never NaN for finite input.
///
/// # Example
/// ```
/// use nalgebra::{dmatrix, dvector};
/// let u = dmatrix![2.0];
/// let lp = sysid_linalg::gaussian_logpdf_from_factor(&dvector![1.0], &dvector![0.0], &u);
/// let exact = -0.5 * (2.0 * std::f64::consts::PI * 4.0).ln() - 0.5 * 0.25;
/// assert!((lp - exact).abs() < 1e-14);
/// ```
pub fn gaussian_logpdf_from_factor(
    x: &nalgebra::DVector<f64>,
    mean: &nalgebra::DVector<f64>,
    u: &DMatrix<f64>,
) -> f64 {
    let k = x.len();
    let mut r: Vec<f64> = (0..k).map(|i| x[i] - mean[i]).collect();
    // forward substitution U' z = r
    let mut quad = 0.0;
    for i in 0..k {
        let mut s = r[i];
        for j in 0..i {
            s -= u[(j, i)] * r[j];
        }
        let d = u[(i, i)];
        if d == 0.0 {
            if s != 0.0 {
                return f64::NEG_INFINITY;
            }
            r[i] = 0.0;
            continue;
        }
        r[i] = s / d;
        quad += r[i] * r[i];
    }
    let logdet_half: f64 = (0..k)
        .filter(|&i| u[(i, i)] != 0.0)
        .map(|i| u[(i, i)].abs().ln())
        .sum();
    -0.5 * (k as f64) * LN_2PI - logdet_half - 0.5 * quad
}
