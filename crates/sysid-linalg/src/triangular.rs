/// Solves `U X = B` in place (back substitution) for upper-triangular `U` (`n x n`,
/// column-major, leading dimension `ldu`) and `B` (`n x nrhs`, leading dimension `ldb`).
///
/// A zero diagonal entry of `U` (a zero row produced by [`crate::triangularize`] for a
/// zero-variance direction) sets that component of the solution to zero: the
/// generalised-inverse convention, which conditions on nothing in that direction.
///
/// # Complexity
/// `n^2 nrhs` flops.
///
/// # Example
/// ```
/// // U = [[2, 1], [0, 4]], b = [4, 8]  ->  x = [1.5, 2]
/// let u = [2.0, 0.0, 1.0, 4.0];
/// let mut b = [4.0, 8.0];
/// sysid_linalg::solve_upper(&u, 2, 2, &mut b, 2, 1);
/// assert_eq!(b, [1.0, 2.0]);
/// ```
pub fn solve_upper(u: &[f64], ldu: usize, n: usize, b: &mut [f64], ldb: usize, nrhs: usize) {
    // small sizes get a copy compiled for a constant n (same arithmetic, unrolled loops)
    match n {
        1 => solve_upper_body(u, ldu, 1, b, ldb, nrhs),
        2 => solve_upper_body(u, ldu, 2, b, ldb, nrhs),
        3 => solve_upper_body(u, ldu, 3, b, ldb, nrhs),
        4 => solve_upper_body(u, ldu, 4, b, ldb, nrhs),
        5 => solve_upper_body(u, ldu, 5, b, ldb, nrhs),
        6 => solve_upper_body(u, ldu, 6, b, ldb, nrhs),
        7 => solve_upper_body(u, ldu, 7, b, ldb, nrhs),
        8 => solve_upper_body(u, ldu, 8, b, ldb, nrhs),
        _ => solve_upper_body(u, ldu, n, b, ldb, nrhs),
    }
}

#[inline(always)]
fn solve_upper_body(u: &[f64], ldu: usize, n: usize, b: &mut [f64], ldb: usize, nrhs: usize) {
    // Row `i` of every right-hand side before row `i - 1` of any: each column's
    // arithmetic is the plain back substitution, but the columns' divisions, the
    // sequential chain of each column, now sit side by side and overlap.
    for i in (0..n).rev() {
        let d = u[i * ldu + i];
        let col = &u[i * ldu..i * ldu + i];
        for c in 0..nrhs {
            let x = &mut b[c * ldb..c * ldb + n];
            if d == 0.0 {
                x[i] = 0.0;
                continue;
            }
            let xi = x[i] / d;
            x[i] = xi;
            for (xk, uk) in x[..i].iter_mut().zip(col) {
                *xk -= uk * xi;
            }
        }
    }
}

/// [`solve_upper`] with `B` stored by rows: row `i` of `B` (`nrhs` values) at
/// `b[i * nrhs..(i + 1) * nrhs]`.
///
/// Every entry goes through the same operations in the same order as in
/// [`solve_upper`] on the column-major `B`, so the solution is the same bit for bit;
/// the row layout makes each step of the back substitution a whole-row operation
/// (divide row `i`, subtract multiples of it from the rows above), which vectorises,
/// and puts the right-hand sides' divisions side by side.
///
/// # Example
/// ```
/// // U = [[2, 1], [0, 4]], B = [[4, 2], [8, 4]] (by rows)  ->  X = [[1, 0.5], [2, 1]]
/// let u = [2.0, 0.0, 1.0, 4.0];
/// let mut b = [4.0, 2.0, 8.0, 4.0];
/// sysid_linalg::solve_upper_rows(&u, 2, 2, &mut b, 2);
/// assert_eq!(b, [1.0, 0.5, 2.0, 1.0]);
/// ```
#[inline(always)]
pub fn solve_upper_rows(u: &[f64], ldu: usize, n: usize, b: &mut [f64], nrhs: usize) {
    // the common widths get a copy compiled for a constant row length
    match nrhs {
        1 => solve_upper_rows_body(u, ldu, n, b, 1),
        2 => solve_upper_rows_body(u, ldu, n, b, 2),
        3 => solve_upper_rows_body(u, ldu, n, b, 3),
        4 => solve_upper_rows_body(u, ldu, n, b, 4),
        5 => solve_upper_rows_body(u, ldu, n, b, 5),
        6 => solve_upper_rows_body(u, ldu, n, b, 6),
        7 => solve_upper_rows_body(u, ldu, n, b, 7),
        8 => solve_upper_rows_body(u, ldu, n, b, 8),
        _ => solve_upper_rows_body(u, ldu, n, b, nrhs),
    }
}

#[inline(always)]
fn solve_upper_rows_body(u: &[f64], ldu: usize, n: usize, b: &mut [f64], nrhs: usize) {
    for i in (0..n).rev() {
        let d = u[i * ldu + i];
        let (above, rest) = b.split_at_mut(i * nrhs);
        let row = &mut rest[..nrhs];
        if d == 0.0 {
            row.fill(0.0);
            continue;
        }
        for v in row.iter_mut() {
            *v /= d;
        }
        for (k, &uk) in u[i * ldu..i * ldu + i].iter().enumerate() {
            for (t, &xi) in above[k * nrhs..(k + 1) * nrhs].iter_mut().zip(row.iter()) {
                *t -= uk * xi;
            }
        }
    }
}

/// Solves `U' X = B` in place (forward substitution) for upper-triangular `U`; same
/// layout and zero-pivot convention as [`solve_upper`].
///
/// # Example
/// ```
/// // U' = [[2, 0], [1, 4]], b = [2, 9]  ->  x = [1, 2]
/// let u = [2.0, 0.0, 1.0, 4.0];
/// let mut b = [2.0, 9.0];
/// sysid_linalg::solve_upper_transpose(&u, 2, 2, &mut b, 2, 1);
/// assert_eq!(b, [1.0, 2.0]);
/// ```
pub fn solve_upper_transpose(
    u: &[f64],
    ldu: usize,
    n: usize,
    b: &mut [f64],
    ldb: usize,
    nrhs: usize,
) {
    for c in 0..nrhs {
        let x = &mut b[c * ldb..c * ldb + n];
        for i in 0..n {
            let col = &u[i * ldu..i * ldu + i];
            let s = crate::dot(col, &x[..i]);
            let d = u[i * ldu + i];
            x[i] = if d == 0.0 { 0.0 } else { (x[i] - s) / d };
        }
    }
}
