use crate::{LinalgError, check_finite, check_symmetric};
use nalgebra::{DMatrix, SymmetricEigen};

/// Relative tolerance used to accept a symmetric matrix as symmetric.
const SYMMETRY_TOL: f64 = 1e-10;
/// Eigenvalues above `-PSD_TOL * max|lambda|` are accepted as non-negative.
const PSD_TOL: f64 = 1e-10;

/// Upper-triangular Cholesky factor `U` with `M = U'U`.
///
/// Only the upper triangle of `m` is read. Returns
/// [`LinalgError::NotPositiveDefinite`] naming `name` and the failing pivot, never panics.
///
/// # Complexity
/// `n^3 / 3` multiply-adds.
///
/// # Example
/// ```
/// use nalgebra::dmatrix;
/// let m = dmatrix![4.0, 2.0; 2.0, 3.0];
/// let u = sysid_linalg::cholesky_upper("M", &m).unwrap();
/// assert!((u.transpose() * &u - m).norm() < 1e-12);
/// assert!(sysid_linalg::cholesky_upper("M", &dmatrix![1.0, 2.0; 2.0, 1.0]).is_err());
/// ```
pub fn cholesky_upper(name: &str, m: &DMatrix<f64>) -> Result<DMatrix<f64>, LinalgError> {
    let n = m.nrows();
    if n != m.ncols() {
        return Err(LinalgError::NotSquare {
            name: name.to_string(),
            rows: n,
            cols: m.ncols(),
        });
    }
    check_finite(name, m)?;
    let mut u = DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        let mut d = m[(j, j)];
        for k in 0..j {
            d -= u[(k, j)] * u[(k, j)];
        }
        if d.is_nan() || d <= 0.0 {
            return Err(LinalgError::NotPositiveDefinite {
                name: name.to_string(),
                pivot: j,
                value: d,
            });
        }
        let ujj = d.sqrt();
        u[(j, j)] = ujj;
        for i in (j + 1)..n {
            let mut s = m[(j, i)];
            for k in 0..j {
                s -= u[(k, j)] * u[(k, i)];
            }
            u[(j, i)] = s / ujj;
        }
    }
    Ok(u)
}

/// A square-root factor `F` (r x n, r <= n) with `F'F = M` of a symmetric positive
/// semi-definite matrix.
///
/// # Algorithm
/// The Cholesky factor when `M` is positive definite (it keeps widely different scales
/// exact); otherwise `F = diag(sqrt(lambda)) V'` from the symmetric eigendecomposition,
/// with the rows of zero eigenvalues dropped, so a rank-deficient `M` gives fewer rows.
///
/// # Errors
/// Non-square, non-finite, non-symmetric (relative tolerance 1e-10), or an eigenvalue
/// below `-1e-10 max|lambda|` ([`LinalgError::NotPositiveSemiDefinite`]).
///
/// # Example
/// ```
/// use nalgebra::dmatrix;
/// let m = dmatrix![1.0, 1.0; 1.0, 1.0]; // rank one
/// let f = sysid_linalg::psd_factor("Q", &m).unwrap();
/// assert_eq!(f.nrows(), 1);
/// assert!((f.transpose() * &f - m).norm() < 1e-12);
/// ```
pub fn psd_factor(name: &str, m: &DMatrix<f64>) -> Result<DMatrix<f64>, LinalgError> {
    check_finite(name, m)?;
    check_symmetric(name, m, SYMMETRY_TOL)?;
    if let Ok(u) = cholesky_upper(name, m) {
        return Ok(u);
    }
    let n = m.nrows();
    let eig = SymmetricEigen::new(m.clone());
    let max_abs = eig.eigenvalues.iter().fold(0.0_f64, |a, &l| a.max(l.abs()));
    let min = eig
        .eigenvalues
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    if min < -PSD_TOL * max_abs {
        return Err(LinalgError::NotPositiveSemiDefinite {
            name: name.to_string(),
            eigenvalue: min,
        });
    }
    let cutoff = (n as f64) * f64::EPSILON * max_abs;
    let kept: Vec<usize> = (0..n).filter(|&i| eig.eigenvalues[i] > cutoff).collect();
    let mut f = DMatrix::<f64>::zeros(kept.len(), n);
    for (row, &i) in kept.iter().enumerate() {
        let s = eig.eigenvalues[i].sqrt();
        for j in 0..n {
            f[(row, j)] = s * eig.eigenvectors[(j, i)];
        }
    }
    Ok(f)
}

/// Checks that a symmetric matrix is positive semi-definite (same tolerances as
/// [`psd_factor`]), without keeping the factor.
pub fn check_psd(name: &str, m: &DMatrix<f64>) -> Result<(), LinalgError> {
    psd_factor(name, m).map(|_| ())
}
