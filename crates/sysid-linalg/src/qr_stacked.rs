use crate::{axpy, dot};

/// See [`crate::triangularize`]: the same tolerance, on squared norms.
const ZERO_PIVOT_REL_TOL_SQ: f64 = 1e-26;

/// Triangularisation of a triangular factor stacked on a dense block, in place.
///
/// # Model
/// Given `R` (`cols x cols`, upper triangular, column-major with leading dimension
/// `ldr`) and `X` (`rows_x x cols`, column-major with leading dimension `ldx`), finds
/// the upper-triangular `R+` with `R+' R+ = R'R + X'X`, i.e. the factor of the QR
/// decomposition of `[R; X]`, and writes it over `R`; `X` is destroyed. This is the
/// structure of a square-root filter update when the noise factor has been
/// triangularised once and only the state rows change (LAPACK's `tpqrt`).
///
/// Rows of `R` with a zero diagonal must be zero rows (the zero-pivot convention of
/// [`crate::triangularize`], which this function also applies to its output).
///
/// # Algorithm
/// One Householder reflection per column acting on the pivot row of `R` and the rows of
/// `X` only (the rows of `R` below the pivot are zero in that column), so each reflector
/// has `1 + rows_x` entries. A column whose remaining norm is below `1e-13` times its
/// initial norm gets a zero row.
///
/// # Complexity
/// `4 (1 + rows_x) cols^2 / 2` flops, no allocation.
///
/// # Example
/// ```
/// // R = [2], X = [[1.5]] -> R+ = [2.5]
/// let mut r = [2.0];
/// let mut x = [1.5];
/// sysid_linalg::triangularize_stacked(&mut r, 1, &mut x, 1, 1, 1);
/// assert!((r[0] - 2.5).abs() < 1e-15);
/// ```
///
/// # Panics
/// If the buffers are shorter than their shapes require (a programming error).
pub fn triangularize_stacked(
    r: &mut [f64],
    ldr: usize,
    x: &mut [f64],
    ldx: usize,
    rows_x: usize,
    cols: usize,
) {
    assert!(ldr >= cols && r.len() >= ldr * cols.saturating_sub(1) + cols);
    assert!(rows_x == 0 || (ldx >= rows_x && x.len() >= ldx * (cols - 1) + rows_x));
    // The common state dimensions get a copy compiled for a constant row count, so the
    // short dot/axpy loops unroll; the arithmetic (and so the result) is the same.
    match rows_x {
        1 => stacked_body(r, ldr, x, ldx, 1, cols),
        2 => stacked_body(r, ldr, x, ldx, 2, cols),
        3 => stacked_body(r, ldr, x, ldx, 3, cols),
        4 => stacked_body(r, ldr, x, ldx, 4, cols),
        5 => stacked_body(r, ldr, x, ldx, 5, cols),
        6 => stacked_body(r, ldr, x, ldx, 6, cols),
        7 => stacked_body(r, ldr, x, ldx, 7, cols),
        8 => stacked_body(r, ldr, x, ldx, 8, cols),
        _ => stacked_body(r, ldr, x, ldx, rows_x, cols),
    }
}

#[inline(always)]
fn stacked_body(r: &mut [f64], ldr: usize, x: &mut [f64], ldx: usize, rows_x: usize, cols: usize) {
    if rows_x > 0 {
        for j in 0..cols {
            let (head, tail) = x.split_at_mut((j + 1) * ldx);
            let v = &mut head[j * ldx..j * ldx + rows_x];
            let sigma = dot(v, v);
            if sigma == 0.0 {
                continue; // nothing to eliminate
            }
            // The reflectors preserve the norm of (R[0..=j, j]; X[:, j]), so this is the
            // norm of the original column; the remaining part is (R[j, j]; X[:, j]).
            let rj = &r[j * ldr..j * ldr + j + 1];
            let initial = dot(rj, rj) + sigma;
            let rjj = r[j * ldr + j];
            let norm_sq = rjj * rjj + sigma;
            if norm_sq <= ZERO_PIVOT_REL_TOL_SQ * initial {
                for k in j..cols {
                    r[k * ldr + j] = 0.0;
                }
                continue;
            }
            let norm = norm_sq.sqrt();
            let alpha = if rjj >= 0.0 { -norm } else { norm };
            let v0 = rjj - alpha;
            let tau = 1.0 / (norm_sq - alpha * rjj);
            for k in 0..cols - j - 1 {
                let col = j + 1 + k;
                let xk = &mut tail[k * ldx..k * ldx + rows_x];
                let rk = &mut r[col * ldr + j];
                let f = tau * (v0 * *rk + dot(v, xk));
                if f != 0.0 {
                    *rk -= f * v0;
                    axpy(-f, v, xk);
                }
            }
            r[j * ldr + j] = alpha;
        }
    }
    for j in 0..cols {
        if r[j * ldr + j] < 0.0 {
            for k in j..cols {
                r[k * ldr + j] = -r[k * ldr + j];
            }
        }
    }
}
