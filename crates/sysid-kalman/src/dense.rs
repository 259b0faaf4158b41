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

/// `c = op(a) b` or `c += op(a) b` for square `n x n` matrices, `op(a) = a'` when
/// `transpose_a`. Sizes up to 8 (the common state dimensions) run a kernel specialised
/// at compile time, which unrolls fully and keeps a column in registers; larger sizes
/// use the general routines.
#[inline(always)]
pub(crate) fn mul_square(
    c: &mut [f64],
    a: &[f64],
    b: &[f64],
    n: usize,
    transpose_a: bool,
    accumulate: bool,
    scratch: &mut Vec<f64>,
) {
    match n {
        1 => square_kernel::<1>(c, a, b, transpose_a, accumulate),
        2 => square_kernel::<2>(c, a, b, transpose_a, accumulate),
        3 => square_kernel::<3>(c, a, b, transpose_a, accumulate),
        4 => square_kernel::<4>(c, a, b, transpose_a, accumulate),
        5 => square_kernel::<5>(c, a, b, transpose_a, accumulate),
        6 => square_kernel::<6>(c, a, b, transpose_a, accumulate),
        7 => square_kernel::<7>(c, a, b, transpose_a, accumulate),
        8 => square_kernel::<8>(c, a, b, transpose_a, accumulate),
        _ => match (transpose_a, accumulate) {
            (true, acc) => mul_tn(c, a, b, n, n, n, acc, scratch),
            (false, false) => mul_nn(c, a, b, n, n, n),
            (false, true) => mul_nn_add(c, a, b, n, n, n),
        },
    }
}

#[inline(always)]
fn square_kernel<const N: usize>(
    c: &mut [f64],
    a: &[f64],
    b: &[f64],
    transpose_a: bool,
    accumulate: bool,
) {
    let (a, b, c) = (&a[..N * N], &b[..N * N], &mut c[..N * N]);
    // columns of op(a)
    let mut cols = [[0.0_f64; N]; N];
    for (l, col) in cols.iter_mut().enumerate() {
        for (i, v) in col.iter_mut().enumerate() {
            *v = if transpose_a {
                a[i * N + l]
            } else {
                a[l * N + i]
            };
        }
    }
    for j in 0..N {
        let mut out = [0.0_f64; N];
        if accumulate {
            out.copy_from_slice(&c[j * N..(j + 1) * N]);
        }
        for (l, col) in cols.iter().enumerate() {
            let blj = b[j * N + l];
            for i in 0..N {
                out[i] += col[i] * blj;
            }
        }
        c[j * N..(j + 1) * N].copy_from_slice(&out);
    }
}

/// `out = a v` with `a` (r x k, column-major), `v` (k), `out` (r): columns of `a` whose
/// entry of `v` is zero are skipped, so a sparse `v` costs only its non-zeros. Row
/// counts up to 8 run a copy compiled for a constant `r` (the axpy loops unroll into
/// registers); the arithmetic, and so the result, is the same.
#[inline(always)]
pub(crate) fn mul_vec_sparse(out: &mut [f64], a: &[f64], v: &[f64], r: usize) {
    match r {
        1 => mul_vec_sparse_body::<1>(out, a, v),
        2 => mul_vec_sparse_body::<2>(out, a, v),
        3 => mul_vec_sparse_body::<3>(out, a, v),
        4 => mul_vec_sparse_body::<4>(out, a, v),
        5 => mul_vec_sparse_body::<5>(out, a, v),
        6 => mul_vec_sparse_body::<6>(out, a, v),
        7 => mul_vec_sparse_body::<7>(out, a, v),
        8 => mul_vec_sparse_body::<8>(out, a, v),
        _ => {
            let out = &mut out[..r];
            out.fill(0.0);
            for (k, &vk) in v.iter().enumerate() {
                if vk != 0.0 {
                    sysid_linalg::axpy(vk, &a[k * r..(k + 1) * r], out);
                }
            }
        }
    }
}

#[inline(always)]
fn mul_vec_sparse_body<const R: usize>(out: &mut [f64], a: &[f64], v: &[f64]) {
    let mut acc = [0.0_f64; R];
    for (k, &vk) in v.iter().enumerate() {
        if vk != 0.0 {
            let col = &a[k * R..(k + 1) * R];
            for i in 0..R {
                acc[i] += vk * col[i];
            }
        }
    }
    out[..R].copy_from_slice(&acc);
}

/// Step `k` of a buffer that stores `n`-vectors one after another.
pub(crate) fn vector_at(buf: &[f64], k: usize, n: usize) -> nalgebra::DVectorView<'_, f64> {
    nalgebra::DVectorView::from_slice(&buf[k * n..(k + 1) * n], n)
}

/// Step `k` of a buffer that stores column-major `n x n` matrices one after another.
pub(crate) fn matrix_at(buf: &[f64], k: usize, n: usize) -> nalgebra::DMatrix<f64> {
    nalgebra::DMatrix::from_column_slice(n, n, &buf[k * n * n..(k + 1) * n * n])
}
