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
    triangularize_stacked_leading(r, ldr, x, ldx, rows_x, cols, cols);
}

/// [`triangularize_stacked`] stopped after the first `pivots` columns, in place.
///
/// # Model
/// `R` (`pivots x cols` used, upper triangular in its first `pivots` columns) stacked
/// on `X` (`rows_x x cols`) as in [`triangularize_stacked`], with the rows of `R` from
/// `pivots` on taken as zero (they are neither read nor written, so `ldr >= pivots`
/// suffices). One reflector per column `j < pivots` gives
/// ```text
/// Q' [R; X] = [[R+_11, R+_12], [0, Z]],   R+ = [R+_11, R+_12] (pivots x cols)
/// ```
/// with `R+_11` upper triangular (non-negative diagonal) written over `R`, and the
/// trailing `rows_x x (cols - pivots)` block `Z` written over the last columns of `X`.
/// Then `R+'R+ + [0, Z]'[0, Z] = R'R + X'X`. When only `Z'Z` is needed from the trailing
/// block (a covariance), stopping here saves its triangularisation: the reflectors of
/// the last columns are the end of the sequential chain of the whole factorisation.
///
/// # Complexity
/// `4 (1 + rows_x) (cols - j - 1)` flops for each column `j < pivots`, no allocation.
///
/// # Panics
/// If `pivots > cols` or the buffers are shorter than their shapes require (a
/// programming error).
#[inline(always)]
pub fn triangularize_stacked_leading(
    r: &mut [f64],
    ldr: usize,
    x: &mut [f64],
    ldx: usize,
    rows_x: usize,
    pivots: usize,
    cols: usize,
) {
    assert!(pivots <= cols);
    assert!(ldr >= pivots && (cols == 0 || r.len() >= ldr * (cols - 1) + pivots));
    assert!(rows_x == 0 || (ldx >= rows_x && x.len() >= ldx * (cols - 1) + rows_x));
    if rows_x > 0 {
        for j in 0..pivots {
            let (head, tail) = x.split_at_mut(((j + 1) * ldx).min(x.len()));
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
            let later = cols - j - 1;
            // (for the last column there is no later column, and maybe no slice)
            let pivot_row = r.get_mut((j + 1) * ldr + j..).unwrap_or_default();
            // The common state dimensions get a copy compiled for a constant row count,
            // so the short dot/axpy loops unroll; the arithmetic (and so the result) is
            // the same.
            match rows_x {
                1 => reflect_columns(&local::<1>(v), v0, tau, pivot_row, ldr, tail, ldx, later),
                2 => reflect_columns(&local::<2>(v), v0, tau, pivot_row, ldr, tail, ldx, later),
                3 => reflect_columns(&local::<3>(v), v0, tau, pivot_row, ldr, tail, ldx, later),
                4 => reflect_columns(&local::<4>(v), v0, tau, pivot_row, ldr, tail, ldx, later),
                5 => reflect_columns(&local::<5>(v), v0, tau, pivot_row, ldr, tail, ldx, later),
                6 => reflect_columns(&local::<6>(v), v0, tau, pivot_row, ldr, tail, ldx, later),
                7 => reflect_columns(&local::<7>(v), v0, tau, pivot_row, ldr, tail, ldx, later),
                8 => reflect_columns(&local::<8>(v), v0, tau, pivot_row, ldr, tail, ldx, later),
                _ => reflect_columns(v, v0, tau, pivot_row, ldr, tail, ldx, later),
            }
            r[j * ldr + j] = alpha;
        }
    }
    for j in 0..pivots {
        if r[j * ldr + j] < 0.0 {
            for k in j..cols {
                r[k * ldr + j] = -r[k * ldr + j];
            }
        }
    }
}

/// A copy of the first `R` entries of `v` (a constant count): for the common state
/// dimensions the reflector's X part is taken out of X, because the compiler cannot
/// tell that the stores to the later columns leave it unchanged and would reload it
/// for every column; the constant length also lets the short loops unroll.
#[inline(always)]
fn local<const R: usize>(v: &[f64]) -> [f64; R] {
    let mut copy = [0.0_f64; R];
    copy.copy_from_slice(&v[..R]);
    copy
}

/// Applies the reflector `I - tau (v0; v)(v0; v)'` to `count` later columns: the
/// pivot-row entries `pivot_row[k * ldr]` and the X parts `x[k * ldx..][..v.len()]`.
/// A zero `f` is applied like any other (it leaves the column as it was).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn reflect_columns(
    v: &[f64],
    v0: f64,
    tau: f64,
    pivot_row: &mut [f64],
    ldr: usize,
    x: &mut [f64],
    ldx: usize,
    count: usize,
) {
    let rows = v.len();
    for k in 0..count {
        let xk = &mut x[k * ldx..k * ldx + rows];
        let rk = &mut pivot_row[k * ldr];
        let f = tau * (v0 * *rk + dot(v, xk));
        *rk -= f * v0;
        axpy(-f, v, xk);
    }
}
