use crate::LinalgError;
use nalgebra::DMatrix;

/// Replaces `m` by `(m + m') / 2`, in place.
///
/// # Panics
/// If `m` is not square (a programming error, never user input).
pub fn symmetrize(m: &mut DMatrix<f64>) {
    let n = m.nrows();
    assert_eq!(n, m.ncols(), "symmetrize needs a square matrix");
    for j in 0..n {
        for i in (j + 1)..n {
            let v = 0.5 * (m[(i, j)] + m[(j, i)]);
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
}

/// Checks that `m` is square and symmetric to a relative tolerance:
/// `|m_ij - m_ji| <= rel_tol * max(1, max_k |m_kk|)`.
pub fn check_symmetric(name: &str, m: &DMatrix<f64>, rel_tol: f64) -> Result<(), LinalgError> {
    let n = m.nrows();
    if n != m.ncols() {
        return Err(LinalgError::NotSquare {
            name: name.to_string(),
            rows: n,
            cols: m.ncols(),
        });
    }
    let scale = (0..n).map(|k| m[(k, k)].abs()).fold(1.0_f64, f64::max);
    for j in 0..n {
        for i in (j + 1)..n {
            let difference = (m[(i, j)] - m[(j, i)]).abs();
            if difference > rel_tol * scale {
                return Err(LinalgError::NotSymmetric {
                    name: name.to_string(),
                    row: i,
                    col: j,
                    difference,
                });
            }
        }
    }
    Ok(())
}

/// Checks that every entry of `m` is finite; the error names the first offending entry.
pub fn check_finite(name: &str, m: &DMatrix<f64>) -> Result<(), LinalgError> {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            let value = m[(i, j)];
            if !value.is_finite() {
                return Err(LinalgError::NonFinite {
                    name: name.to_string(),
                    row: i,
                    col: j,
                    value,
                });
            }
        }
    }
    Ok(())
}
