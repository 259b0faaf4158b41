//! Least squares from second moments by the Cholesky route, shared by the M-steps.
//!
//! Given a factor `F'F = H` of the second-moment matrix of a vector `c`, a regression
//! of some entries of `c` (the targets) on others (the regressors) is read off the
//! triangular factor of `F L'`, where `L` selects `[regressors; targets]`: no normal
//! equations are formed and the residual covariance is a Gram matrix, PSD by
//! construction.

use nalgebra::DMatrix;
use sysid_linalg::{QrScratch, solve_upper, triangularize};

/// A regression block: `target = xi_rows - sum_fixed G_j z_j`, regressed on the free
/// regressors of `z`.
pub(crate) struct Block<'a> {
    /// indices (in `c = [x; u; 1; x+; y]`) of the block's left-hand side
    pub targets: std::ops::Range<usize>,
    /// indices of the free regressors
    pub free: Vec<usize>,
    /// fixed regressors: (index range in `c`, coefficient matrix rows x range)
    pub fixed: Vec<(std::ops::Range<usize>, &'a DMatrix<f64>)>,
}

/// Result of a block regression: coefficients of the free regressors
/// (`rows x free.len()`) and the residual covariance.
pub(crate) struct Fit {
    pub coef: DMatrix<f64>,
    pub cov: DMatrix<f64>,
}

/// Regresses one block by the Cholesky route: with `F'F = H` and `L` the linear map
/// from `c` to `[free regressors; target]`, the triangular factor `R` of `F L'`
/// satisfies `R'R = L H L'`; then `Gamma' = R11^{-1} R12` and
/// `Pi = R22' R22 / N`, a Gram matrix, so PSD by construction, and no inverse formed.
pub(crate) fn regress(factor: &DMatrix<f64>, block: &Block<'_>, steps: f64) -> Fit {
    let dim = factor.ncols();
    let (f, k) = (block.free.len(), block.targets.len());
    let cols = f + k;
    let mut l = DMatrix::<f64>::zeros(cols, dim);
    for (row, &j) in block.free.iter().enumerate() {
        l[(row, j)] = 1.0;
    }
    for (i, target) in block.targets.clone().enumerate() {
        l[(f + i, target)] = 1.0;
        for (range, g) in &block.fixed {
            for (jj, j) in range.clone().enumerate() {
                l[(f + i, j)] -= g[(i, jj)];
            }
        }
    }
    let x = factor * l.transpose(); // rows(F) x cols
    let rows = x.nrows();
    let ld = rows.max(cols);
    let mut buf = vec![0.0; ld * cols];
    for j in 0..cols {
        buf[j * ld..j * ld + rows].copy_from_slice(x.column(j).as_slice());
    }
    triangularize(&mut buf, ld, rows, cols, &mut QrScratch::default());
    // Gamma' = R11^{-1} R12 (zero pivots: a regressor with no variation gets 0)
    let mut r12 = DMatrix::<f64>::zeros(f, k);
    for j in 0..k {
        for i in 0..f {
            r12[(i, j)] = buf[(f + j) * ld + i];
        }
    }
    if f > 0 {
        solve_upper(&buf, ld, f, r12.as_mut_slice(), f, k);
    }
    let mut r22 = DMatrix::<f64>::zeros(k, k);
    for j in 0..k {
        for i in 0..=j {
            r22[(i, j)] = buf[(f + j) * ld + f + i];
        }
    }
    let mut cov = r22.transpose() * &r22 / steps;
    sysid_linalg::symmetrize(&mut cov);
    Fit {
        coef: r12.transpose(),
        cov,
    }
}

/// Regresses the rows `targets` of `c` on regressor groups `(estimate, range in c,
/// current coefficients)`: estimated groups are free regressors, the others are moved
/// to the left-hand side with their current coefficients. Returns the new coefficients
/// of each estimated group (`None` for fixed ones) and the residual covariance.
pub(crate) fn fit_block(
    factor: &DMatrix<f64>,
    targets: std::ops::Range<usize>,
    groups: &[(bool, std::ops::Range<usize>, &DMatrix<f64>)],
    steps: f64,
) -> (Vec<Option<DMatrix<f64>>>, DMatrix<f64>) {
    let mut free = Vec::new();
    let mut fixed = Vec::new();
    for (estimate, range, current) in groups {
        if *estimate {
            free.extend(range.clone());
        } else {
            fixed.push((range.clone(), *current));
        }
    }
    let fit = regress(
        factor,
        &Block {
            targets,
            free,
            fixed,
        },
        steps,
    );
    let mut col = 0;
    let coef = groups
        .iter()
        .map(|(estimate, range, _)| {
            estimate.then(|| {
                let block = fit.coef.columns(col, range.len()).clone_owned();
                col += range.len();
                block
            })
        })
        .collect();
    (coef, fit.cov)
}
