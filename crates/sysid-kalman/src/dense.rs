//! Allocation-free products of small column-major matrices stored in slices.
//! Shapes are passed explicitly; leading dimensions equal the row counts.

/// `c = a b` with `a` (r x k), `b` (k x s), `c` (r x s).
pub(crate) fn mul_nn(c: &mut [f64], a: &[f64], b: &[f64], r: usize, k: usize, s: usize) {
    for j in 0..s {
        let cj = &mut c[j * r..(j + 1) * r];
        cj.fill(0.0);
        for l in 0..k {
            let blj = b[j * k + l];
            if blj != 0.0 {
                for (ci, ai) in cj.iter_mut().zip(&a[l * r..(l + 1) * r]) {
                    *ci += ai * blj;
                }
            }
        }
    }
}

/// `c (+)= a' b` with `a` (k x r), `b` (k x s), `c` (r x s); adds when `accumulate`.
pub(crate) fn mul_tn(
    c: &mut [f64],
    a: &[f64],
    b: &[f64],
    k: usize,
    r: usize,
    s: usize,
    accumulate: bool,
) {
    for j in 0..s {
        let bj = &b[j * k..(j + 1) * k];
        for i in 0..r {
            let dot: f64 = a[i * k..(i + 1) * k]
                .iter()
                .zip(bj)
                .map(|(x, y)| x * y)
                .sum();
            let cij = &mut c[j * r + i];
            *cij = if accumulate { *cij + dot } else { dot };
        }
    }
}

/// Replaces the square `n x n` matrix in `m` by its symmetric part.
pub(crate) fn symmetrize(m: &mut [f64], n: usize) {
    for j in 0..n {
        for i in (j + 1)..n {
            let v = 0.5 * (m[j * n + i] + m[i * n + j]);
            m[j * n + i] = v;
            m[i * n + j] = v;
        }
    }
}
