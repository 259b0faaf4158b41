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
/// `a'` is formed in `scratch` so that the product runs in the vectorisable column
/// (axpy) form rather than as a sequence of dot products.
#[allow(clippy::too_many_arguments)]
pub(crate) fn mul_tn(
    c: &mut [f64],
    a: &[f64],
    b: &[f64],
    k: usize,
    r: usize,
    s: usize,
    accumulate: bool,
    scratch: &mut Vec<f64>,
) {
    scratch.resize(r * k, 0.0);
    for i in 0..r {
        for l in 0..k {
            scratch[l * r + i] = a[i * k + l];
        }
    }
    if accumulate {
        mul_nn_add(c, scratch, b, r, k, s);
    } else {
        mul_nn(c, scratch, b, r, k, s);
    }
}

/// `c += a b` with `a` (r x k), `b` (k x s), `c` (r x s).
pub(crate) fn mul_nn_add(c: &mut [f64], a: &[f64], b: &[f64], r: usize, k: usize, s: usize) {
    for j in 0..s {
        let cj = &mut c[j * r..(j + 1) * r];
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
