/// A column whose remaining norm falls below this fraction of its initial norm is
/// treated as linearly dependent on the previous columns: its pivot is zero.
const ZERO_PIVOT_REL_TOL: f64 = 1e-13;

use crate::{axpy, dot};

/// Reusable scratch space for [`triangularize`]; grows to the largest problem seen and
/// is never shrunk, so a filter allocates it once.
#[derive(Debug, Clone, Default)]
pub struct QrScratch {
    pivot_rows: Vec<usize>,
    initial_norms: Vec<f64>,
}

const SKIPPED: usize = usize::MAX;

/// Householder triangularisation of a stacked pre-array, in place.
///
/// # Model
/// Given the `rows x cols` matrix `X` stored column-major in `a` with leading dimension
/// `ld >= max(rows, cols)`, finds an orthogonal `Theta` with `Theta X = [R; 0]` and writes
/// the upper-triangular `cols x cols` factor `R` into the first `cols` rows of `a`
/// (entries below the diagonal are zeroed; rows `cols..rows` are left unspecified).
/// `R'R = X'X`, which is what square-root filtering needs: if the rows of `X` are the
/// square-root factors of independent Gaussian vectors, `R` is the Cholesky factor of
/// the covariance of the stacked columns.
///
/// # Algorithm
/// Householder reflections, column by column. Two conventions make `R` a proper
/// (possibly singular) Cholesky factor:
/// * the diagonal of `R` is non-negative;
/// * a column that is numerically dependent on the previous ones (remaining norm below
///   `1e-13` times its initial norm), or that has no row left, gets a zero row in `R`
///   and consumes no Householder row. This is the Cholesky factor of a semi-definite
///   matrix, in which a zero-variance variable carries no information about the later
///   ones; [`crate::solve_upper`] uses the matching zero-pivot convention.
///
/// # Complexity
/// `2 rows cols^2 - 2/3 cols^3` flops, no allocation once `scratch` has grown.
///
/// # Example
/// ```
/// use sysid_linalg::{triangularize, QrScratch};
/// // X = [[3, 1], [4, 2]] (column-major)
/// let mut a = vec![3.0, 4.0, 1.0, 2.0];
/// triangularize(&mut a, 2, 2, 2, &mut QrScratch::default());
/// assert!((a[0] - 5.0).abs() < 1e-14);          // R_11 = |(3, 4)|
/// assert_eq!(a[1], 0.0);                         // below the diagonal
/// assert!((a[2] - 2.2).abs() < 1e-14);          // R_12 = (3*1 + 4*2) / 5
/// assert!((a[3] - 0.4).abs() < 1e-14);          // R_22
/// ```
///
/// # Panics
/// If `ld < max(rows, cols)` or `a` is shorter than `ld * cols` (programming errors).
pub fn triangularize(a: &mut [f64], ld: usize, rows: usize, cols: usize, scratch: &mut QrScratch) {
    assert!(ld >= rows.max(cols), "leading dimension too small");
    assert!(a.len() >= ld * cols, "buffer too small");
    if scratch.pivot_rows.len() < cols {
        scratch.pivot_rows.resize(cols, SKIPPED);
        scratch.initial_norms.resize(cols, 0.0);
    }
    for j in 0..cols {
        let col = &a[j * ld..j * ld + rows];
        scratch.initial_norms[j] = dot(col, col).sqrt();
    }
    let mut row = 0;
    let mut skipped_any = false;
    for j in 0..cols {
        if row >= rows {
            scratch.pivot_rows[j] = SKIPPED;
            skipped_any = true;
            continue;
        }
        let (head, tail) = a.split_at_mut((j + 1) * ld);
        let v = &mut head[j * ld + row..j * ld + rows];
        let norm = dot(v, v).sqrt();
        if norm == 0.0 || norm <= ZERO_PIVOT_REL_TOL * scratch.initial_norms[j] {
            scratch.pivot_rows[j] = SKIPPED;
            skipped_any = true;
            continue;
        }
        let x0 = v[0];
        let alpha = if x0 >= 0.0 { -norm } else { norm };
        v[0] = x0 - alpha;
        // v'v = 2 (norm^2 - alpha x0); H = I - tau v v'
        let tau = 1.0 / (norm * norm - alpha * x0);
        let trailing = cols - j - 1;
        for k in 0..trailing {
            let ak = &mut tail[k * ld + row..k * ld + rows];
            let f = tau * dot(v, ak);
            if f != 0.0 {
                axpy(-f, v, ak);
            }
        }
        v[0] = alpha;
        for x in v[1..].iter_mut() {
            *x = 0.0;
        }
        scratch.pivot_rows[j] = row;
        row += 1;
    }
    if skipped_any {
        place_rows(a, ld, cols, scratch);
    }
    // zero below the diagonal of the leading cols x cols block, make the diagonal >= 0
    for j in 0..cols {
        for i in (j + 1)..cols.min(ld) {
            a[j * ld + i] = 0.0;
        }
        if a[j * ld + j] < 0.0 {
            for k in j..cols {
                a[k * ld + j] = -a[k * ld + j];
            }
        }
    }
}

/// Moves the Householder rows to their column's position and writes zero rows for the
/// skipped (zero-pivot) columns, in place. Pivot rows never exceed their column index
/// and increase with it, so going from the last column down never overwrites a row
/// that is still to be moved.
fn place_rows(a: &mut [f64], ld: usize, cols: usize, scratch: &QrScratch) {
    for j in (0..cols).rev() {
        let r = scratch.pivot_rows[j];
        if r == j {
            continue;
        }
        for k in j..cols {
            a[k * ld + j] = if r == SKIPPED { 0.0 } else { a[k * ld + r] };
        }
    }
}
