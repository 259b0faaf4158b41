/// Inner product `sum_i a_i b_i` of two slices of equal length, with four independent
/// accumulators so that the compiler can vectorise it (a plain iterator `sum` is a
/// sequential chain of dependent additions). Summation order differs from the naive
/// loop by round-off only, and is fixed, so results are reproducible.
///
/// # Example
/// ```
/// assert_eq!(sysid_linalg::dot(&[1.0, 2.0, 3.0], &[4.0, 5.0, 6.0]), 32.0);
/// ```
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let len = a.len().min(b.len());
    let (a, b) = (&a[..len], &b[..len]);
    let mut acc = [0.0_f64; 4];
    let chunks = len / 4;
    for c in 0..chunks {
        let (x, y) = (&a[4 * c..4 * c + 4], &b[4 * c..4 * c + 4]);
        acc[0] += x[0] * y[0];
        acc[1] += x[1] * y[1];
        acc[2] += x[2] * y[2];
        acc[3] += x[3] * y[3];
    }
    let mut tail = 0.0;
    for i in 4 * chunks..len {
        tail += a[i] * b[i];
    }
    (acc[0] + acc[2]) + (acc[1] + acc[3]) + tail
}

/// `y += alpha x` over slices of equal length.
#[inline]
pub fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += alpha * xi;
    }
}
