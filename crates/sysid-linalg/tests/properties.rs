//! Property tests: factor reconstructions on random SPD / PSD matrices, the Gram
//! identity of the triangularisation, and triangular solves against residuals.

use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;
use sysid_linalg::*;

fn matrix(rows: usize, cols: usize) -> impl Strategy<Value = DMatrix<f64>> {
    proptest::collection::vec(-3.0..3.0_f64, rows * cols)
        .prop_map(move |v| DMatrix::from_vec(rows, cols, v))
}

/// Random SPD matrix G'G + 0.1 I of size n.
fn spd(n: usize) -> impl Strategy<Value = DMatrix<f64>> {
    matrix(n, n).prop_map(move |g| g.transpose() * &g + DMatrix::identity(n, n) * 0.1)
}

fn rel_err(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm() / b.norm().max(1e-300)
}

proptest! {
    #[test]
    fn cholesky_reconstructs(m in (1usize..8).prop_flat_map(spd)) {
        let u = cholesky_upper("M", &m).unwrap();
        prop_assert!(rel_err(&(u.transpose() * &u), &m) < 1e-12);
        for i in 0..u.nrows() {
            prop_assert!(u[(i, i)] > 0.0);
            for j in 0..i { prop_assert_eq!(u[(i, j)], 0.0); }
        }
    }

    #[test]
    fn psd_factor_reconstructs_rank_deficient(g in (1usize..6, 1usize..6)
            .prop_flat_map(|(r, n)| matrix(r, n))) {
        let m = g.transpose() * &g;
        let f = psd_factor("M", &m).unwrap();
        prop_assert!(f.nrows() <= m.nrows());
        prop_assert!((f.transpose() * &f - &m).norm() <= 1e-10 * m.norm().max(1.0));
    }

    #[test]
    fn triangularize_keeps_gram_matrix(x in (1usize..12, 1usize..8)
            .prop_flat_map(|(r, c)| matrix(r, c))) {
        let (rows, cols) = x.shape();
        let ld = rows.max(cols);
        let mut a = vec![0.0; ld * cols];
        for j in 0..cols { for i in 0..rows { a[j * ld + i] = x[(i, j)]; } }
        triangularize(&mut a, ld, rows, cols, &mut QrScratch::default());
        let r = DMatrix::from_fn(cols, cols, |i, j| a[j * ld + i]);
        for i in 0..cols {
            prop_assert!(r[(i, i)] >= 0.0);
            for j in 0..i { prop_assert_eq!(r[(i, j)], 0.0); }
        }
        let gram = x.transpose() * &x;
        prop_assert!((r.transpose() * &r - &gram).norm() <= 1e-12 * gram.norm().max(1.0));
        // for a full-column-rank X, R is the unique Cholesky factor of X'X
        if rows >= cols
            && let Ok(u) = cholesky_upper("G", &gram)
            && u.diagonal().min() > 1e-6 * u.diagonal().max()
        {
            prop_assert!(rel_err(&r, &u) < 1e-8);
        }
    }

    #[test]
    fn stacked_triangularisation_equals_the_general_one(
            (r0, x) in (1usize..7, 0usize..9).prop_flat_map(|(c, rx)| (matrix(c + 1, c), matrix(rx, c))),
            singular in proptest::bool::ANY) {
        let cols = r0.ncols();
        // a triangular factor with the zero-pivot convention (possibly singular)
        let mut g = r0.clone();
        if singular && cols > 1 { g.row_mut(0).fill(0.0); }
        let ld = (g.nrows()).max(cols);
        let mut buf = vec![0.0; ld * cols];
        for j in 0..cols { for i in 0..g.nrows() { buf[j * ld + i] = g[(i, j)]; } }
        triangularize(&mut buf, ld, g.nrows(), cols, &mut QrScratch::default());
        let r = DMatrix::from_fn(cols, cols, |i, j| buf[j * ld + i]);
        // stacked: [R; X]
        let mut r_buf = r.as_slice().to_vec();
        let mut x_buf = x.as_slice().to_vec();
        triangularize_stacked(&mut r_buf, cols, &mut x_buf, x.nrows().max(1), x.nrows(), cols);
        let stacked = DMatrix::from_column_slice(cols, cols, &r_buf);
        // the general kernel on the dense stack is the reference
        let full = DMatrix::from_fn(cols + x.nrows(), cols, |i, j| if i < cols { r[(i, j)] } else { x[(i - cols, j)] });
        let ldf = full.nrows().max(cols);
        let mut fb = vec![0.0; ldf * cols];
        for j in 0..cols { for i in 0..full.nrows() { fb[j * ldf + i] = full[(i, j)]; } }
        triangularize(&mut fb, ldf, full.nrows(), cols, &mut QrScratch::default());
        let reference = DMatrix::from_fn(cols, cols, |i, j| fb[j * ldf + i]);
        let gram = full.transpose() * &full;
        let scale = gram.norm().max(1.0);
        prop_assert!((stacked.transpose() * &stacked - &gram).norm() <= 1e-12 * scale);
        for i in 0..cols {
            prop_assert!(stacked[(i, i)] >= 0.0);
            for j in 0..i { prop_assert_eq!(stacked[(i, j)], 0.0); }
            if stacked[(i, i)] == 0.0 {
                prop_assert!(stacked.row(i).iter().all(|&v| v == 0.0));
            }
        }
        if reference.diagonal().min() > 1e-6 * reference.diagonal().max() {
            prop_assert!(rel_err(&stacked, &reference) < 1e-8);
        }
    }

    #[test]
    fn leading_triangularisation_is_the_full_one_stopped_early(
            (r0, x, pivots) in (1usize..9, 1usize..10)
                .prop_flat_map(|(c, rx)| (matrix(c, c), matrix(rx, c), 0..=c)),
            ldx_pad in 0usize..3) {
        // R: the upper triangle of r0; the full triangularisation is the reference
        let cols = r0.ncols();
        let rows_x = x.nrows();
        let r = DMatrix::from_fn(cols, cols, |i, j| if i <= j { r0[(i, j)] } else { 0.0 });
        let ldx = rows_x + ldx_pad;
        let mut x_buf = vec![0.0; ldx * cols];
        for j in 0..cols { for i in 0..rows_x { x_buf[j * ldx + i] = x[(i, j)]; } }
        let mut full_r = r.as_slice().to_vec();
        let mut full_x = x_buf.clone();
        triangularize_stacked(&mut full_r, cols, &mut full_x, ldx, rows_x, cols);
        // the leading kernel sees R's first `pivots` rows only (R's other rows zero)
        let mut lead_r = vec![f64::NAN; cols * cols];
        for j in 0..cols { for i in 0..pivots.min(j + 1) { lead_r[j * cols + i] = r[(i, j)]; } }
        let mut lead_x = x_buf.clone();
        triangularize_stacked_leading(&mut lead_r, cols, &mut lead_x, ldx, rows_x, pivots, cols);
        // rows 0..pivots: the same reflectors in the same order, so the same bits
        for j in 0..cols {
            for i in 0..pivots.min(j + 1) {
                prop_assert_eq!(lead_r[j * cols + i].to_bits(), full_r[j * cols + i].to_bits());
            }
        }
        // trailing block: Z'Z equals the Gram matrix of what R+'R+ leaves over
        let k = cols - pivots;
        let z = DMatrix::from_fn(rows_x, k, |i, j| lead_x[(pivots + j) * ldx + i]);
        let top = DMatrix::from_fn(pivots, cols, |i, j| if i <= j { lead_r[j * cols + i] } else { 0.0 });
        let mut recon = top.transpose() * &top;
        let ztz = z.transpose() * &z;
        for a in 0..k { for b in 0..k { recon[(pivots + a, pivots + b)] += ztz[(a, b)]; } }
        // rows of R from `pivots` on were taken as zero
        let rtop = DMatrix::from_fn(cols, cols, |i, j| if i < pivots { r[(i, j)] } else { 0.0 });
        let gram = rtop.transpose() * &rtop + x.transpose() * &x;
        prop_assert!((recon - &gram).norm() <= 1e-12 * gram.norm().max(1.0));
    }

    #[test]
    fn row_layout_solve_is_the_column_layout_solve(
            (u, b) in (1usize..10, 1usize..10).prop_flat_map(|(n, k)| (matrix(n, n), matrix(n, k))),
            zero_pivot in proptest::option::of(0usize..10)) {
        let n = u.nrows();
        let mut u = DMatrix::from_fn(n, n, |i, j| if i < j { u[(i, j)] } else if i == j { 1.0 + u[(i, i)].abs() } else { 0.0 });
        if let Some(z) = zero_pivot.filter(|&z| z < n) { u[(z, z)] = 0.0; }
        let nrhs = b.ncols();
        let mut by_columns = b.as_slice().to_vec();
        solve_upper(u.as_slice(), n, n, &mut by_columns, n, nrhs);
        let mut by_rows: Vec<f64> = (0..n).flat_map(|i| (0..nrhs).map(move |c| (i, c))).map(|(i, c)| b[(i, c)]).collect();
        solve_upper_rows(u.as_slice(), n, n, &mut by_rows, nrhs);
        for i in 0..n {
            for c in 0..nrhs {
                prop_assert_eq!(by_rows[i * nrhs + c].to_bits(), by_columns[c * n + i].to_bits());
            }
        }
    }

    #[test]
    fn triangular_solves_have_small_residuals(m in (1usize..8).prop_flat_map(spd),
                                              seed in proptest::collection::vec(-5.0..5.0_f64, 8)) {
        let n = m.nrows();
        let u = cholesky_upper("M", &m).unwrap();
        let b = DVector::from_iterator(n, seed.iter().copied().take(n));
        let mut x = b.clone();
        solve_upper(u.as_slice(), n, n, x.as_mut_slice(), n, 1);
        prop_assert!((&u * &x - &b).norm() <= 1e-9 * b.norm().max(1.0) * u.norm());
        let mut y = b.clone();
        solve_upper_transpose(u.as_slice(), n, n, y.as_mut_slice(), n, 1);
        prop_assert!((u.transpose() * &y - &b).norm() <= 1e-9 * b.norm().max(1.0) * u.norm());
    }

    #[test]
    fn logpdf_matches_dense_formula(m in (1usize..6).prop_flat_map(spd),
                                    xs in proptest::collection::vec(-5.0..5.0_f64, 6)) {
        let n = m.nrows();
        let u = cholesky_upper("M", &m).unwrap();
        let x = DVector::from_iterator(n, xs.iter().copied().take(n));
        let mean = DVector::zeros(n);
        let lp = gaussian_logpdf_from_factor(&x, &mean, &u);
        let inv = m.clone().try_inverse().unwrap();
        let quad = (x.transpose() * inv * &x)[(0, 0)];
        let exact = -0.5 * (n as f64) * LN_2PI - 0.5 * m.determinant().ln() - 0.5 * quad;
        prop_assert!((lp - exact).abs() < 1e-8 * exact.abs().max(1.0));
        prop_assert!((logdet_from_factor(&u) - m.determinant().ln()).abs() < 1e-8 * (1.0 + m.determinant().ln().abs()));
    }
}

#[test]
fn cholesky_reports_the_failing_pivot() {
    let m = DMatrix::from_row_slice(3, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 0.0, 2.0, 1.0]);
    match cholesky_upper("Q", &m) {
        Err(LinalgError::NotPositiveDefinite { name, pivot, .. }) => {
            assert_eq!(name, "Q");
            assert_eq!(pivot, 2);
        }
        other => panic!("expected NotPositiveDefinite, got {other:?}"),
    }
}

#[test]
fn psd_checks_name_the_matrix() {
    let indefinite = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
    assert!(matches!(psd_factor("R", &indefinite),
        Err(LinalgError::NotPositiveSemiDefinite { ref name, eigenvalue }) if name == "R" && eigenvalue < -0.9));
    let asymmetric = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 1.0]);
    assert!(matches!(psd_factor("P1", &asymmetric),
        Err(LinalgError::NotSymmetric { ref name, row: 1, col: 0, .. }) if name == "P1"));
    let nan = DMatrix::from_row_slice(2, 2, &[1.0, f64::NAN, f64::NAN, 1.0]);
    assert!(matches!(
        psd_factor("Q", &nan),
        Err(LinalgError::NonFinite { row: 1, col: 0, .. })
    ));
    let zero = DMatrix::<f64>::zeros(3, 3);
    assert_eq!(psd_factor("Q", &zero).unwrap().nrows(), 0);
}

#[test]
fn dependent_column_gets_zero_row_and_solves_ignore_it() {
    // columns: c0, c1 = 2 c0, c2 independent
    let x = DMatrix::from_row_slice(3, 3, &[1.0, 2.0, 0.0, 1.0, 2.0, 1.0, 0.0, 0.0, 1.0]);
    let mut a = x.as_slice().to_vec();
    triangularize(&mut a, 3, 3, 3, &mut QrScratch::default());
    let r = DMatrix::from_column_slice(3, 3, &a);
    assert_eq!(
        r.row(1).iter().copied().collect::<Vec<_>>(),
        vec![0.0, 0.0, 0.0]
    );
    let gram = x.transpose() * &x;
    assert!((r.transpose() * &r - gram).norm() < 1e-12);
    let mut b = vec![1.0, 0.0, 1.0];
    solve_upper(&a, 3, 3, &mut b, 3, 1);
    assert!(b.iter().all(|v| v.is_finite()));
    assert_eq!(b[1], 0.0);
}

#[test]
fn more_columns_than_rows() {
    let x = DMatrix::from_row_slice(1, 3, &[3.0, 1.0, 2.0]);
    let mut a = vec![0.0; 9];
    for j in 0..3 {
        a[j * 3] = x[(0, j)];
    }
    triangularize(&mut a, 3, 1, 3, &mut QrScratch::default());
    let r = DMatrix::from_column_slice(3, 3, &a);
    assert!((r.transpose() * &r - x.transpose() * &x).norm() < 1e-12);
    assert_eq!(r[(1, 1)], 0.0);
    assert_eq!(r[(2, 2)], 0.0);
}
