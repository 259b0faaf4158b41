//! The closed-form M-step of affine EM.

use super::constraints::constrained_m_step;
use super::{AffineEmError, AffineEmSpec, AffineModel, AffineParams, AffineStatistics};
use crate::linear::Covariance;
use crate::regression::{Block, regress};
use nalgebra::DMatrix;
use sysid_linalg::psd_factor;

/// New coefficients and noise covariance of one block (state or output).
struct BlockFit {
    beta: DMatrix<f64>,
    pi: DMatrix<f64>,
}

/// One block's statistics, structure, spec and current values.
#[derive(Clone, Copy)]
struct BlockInput<'a> {
    name: &'static str,
    moments: &'a DMatrix<f64>,
    steps: f64,
    structure: &'a [Vec<usize>],
    /// Per row, the regressors whose coefficients are held at `current_beta`.
    held: &'a [Vec<usize>],
    estimate_beta: bool,
    covariance: Covariance,
    current_beta: &'a DMatrix<f64>,
    current_pi: &'a DMatrix<f64>,
}

/// Fits one block: the rows `targets` of `c = [alpha; target]` (with second moments
/// `moments` over `steps` steps) on their regressors.
///
/// Rows that share one regressor set and a full `Pi` form one multivariate regression;
/// with a diagonal (or fixed diagonal) `Pi`, every row is its own least-squares problem
/// on its own regressors, which is the exact maximiser since the rows' likelihoods
/// separate. A full `Pi` with rows on different regressors would need generalised
/// least squares and is refused.
fn fit_block(block: &BlockInput<'_>, regressors: usize) -> Result<BlockFit, AffineEmError> {
    let BlockInput {
        name,
        moments,
        steps,
        structure,
        held,
        estimate_beta,
        covariance,
        current_beta,
        current_pi,
    } = *block;
    let any_held = held.iter().any(|h| !h.is_empty());
    if let Some((row, j)) = held.iter().enumerate().find_map(|(row, h)| {
        h.iter()
            .find(|j| !structure.get(row).is_some_and(|used| used.contains(j)))
            .map(|&j| (row, j))
    }) {
        return Err(AffineEmError::InvalidParams(format!(
            "{name}: row {row} holds the coefficient of regressor {j}, which the row does not use"
        )));
    }
    let rows = structure.len();
    if steps <= 0.0 {
        return Err(AffineEmError::NoSteps { block: name });
    }
    let factor = psd_factor(name, moments)?;
    if !estimate_beta {
        // Only the covariance: the residual moments of the targets minus the fixed part.
        let fit = regress(
            &factor,
            &Block {
                targets: regressors..regressors + rows,
                free: Vec::new(),
                fixed: vec![(0..regressors, current_beta)],
            },
            steps,
        );
        let pi = match covariance {
            Covariance::Full => fit.cov,
            Covariance::Diagonal => DMatrix::from_diagonal(&fit.cov.diagonal()),
            Covariance::Fixed => current_pi.clone(),
        };
        return Ok(BlockFit {
            beta: current_beta.clone(),
            pi,
        });
    }
    let shared = structure.windows(2).all(|w| w[0] == w[1]);
    let pi_diagonal = (0..rows).all(|i| (0..rows).all(|j| i == j || current_pi[(i, j)] == 0.0));
    let separate = match covariance {
        Covariance::Diagonal => true,
        Covariance::Fixed => !shared && pi_diagonal,
        Covariance::Full => false,
    };
    let mut beta = DMatrix::zeros(rows, regressors);
    let mut pi = DMatrix::zeros(rows, rows);
    if separate || rows == 1 {
        for (r, used) in structure.iter().enumerate() {
            // held coefficients move to the left-hand side with their values
            let row_held = held.get(r).map(Vec::as_slice).unwrap_or(&[]);
            let known: Vec<(usize, DMatrix<f64>)> = row_held
                .iter()
                .map(|&j| (j, DMatrix::from_element(1, 1, current_beta[(r, j)])))
                .collect();
            let free: Vec<usize> = used
                .iter()
                .copied()
                .filter(|j| !row_held.contains(j))
                .collect();
            let fit = regress(
                &factor,
                &Block {
                    targets: regressors + r..regressors + r + 1,
                    free: free.clone(),
                    fixed: known.iter().map(|(j, g)| (*j..*j + 1, g)).collect(),
                },
                steps,
            );
            for (k, &j) in free.iter().enumerate() {
                beta[(r, j)] = fit.coef[(0, k)];
            }
            for &(j, ref g) in &known {
                beta[(r, j)] = g[(0, 0)];
            }
            pi[(r, r)] = fit.cov[(0, 0)];
        }
    } else if any_held {
        return Err(AffineEmError::Unsupported(format!(
            "{name}: held coefficients need a diagonal noise covariance (one regression per \
             row)"
        )));
    } else if shared {
        let used = &structure[0];
        let fit = regress(
            &factor,
            &Block {
                targets: regressors..regressors + rows,
                free: used.clone(),
                fixed: Vec::new(),
            },
            steps,
        );
        for r in 0..rows {
            for (k, &j) in used.iter().enumerate() {
                beta[(r, j)] = fit.coef[(r, k)];
            }
        }
        pi = fit.cov;
        if covariance == Covariance::Diagonal {
            pi = DMatrix::from_diagonal(&pi.diagonal());
        }
    } else {
        return Err(AffineEmError::Unsupported(format!(
            "{name}: a full or non-diagonal noise covariance with rows on different regressors \
             needs generalised least squares; make the covariance diagonal"
        )));
    }
    if covariance == Covariance::Fixed {
        pi = current_pi.clone();
    }
    Ok(BlockFit { beta, pi })
}

/// The M-step: the parameters maximising the expected complete-data log-likelihood
/// given the smoothed statistics.
///
/// # Algorithm
/// `beta = Psi Sigma^{-1}`, `Pi = Phi - Psi Sigma^{-1} Psi'` (ALGORITHMS.md 3), per
/// block and read off the triangular factor of the statistics (the Cholesky route of
/// `crate::regression`, no inverse formed, `Pi` PSD by construction). With structural
/// zeros and a diagonal `Pi`, one least-squares problem per row. The initial state, if
/// estimated: `mu = E[x_0]`, `P1 = E[x_0 x_0'] - mu mu'`. A model with
/// [`AffineModel::constraints`] gets the constrained M-step of `constraints.rs`
/// (weighted least squares over tied coefficients, bounded, alternated with the free
/// variances).
pub fn m_step<A: AffineModel>(
    model: &A,
    stats: &AffineStatistics,
    current: &AffineParams,
    spec: &AffineEmSpec,
) -> Result<AffineParams, AffineEmError> {
    if let Some(constraints) = model.constraints() {
        return constrained_m_step(model, stats, current, spec, &constraints).map(|(p, _)| p);
    }
    let r = model.regressor_dim();
    let (state_structure, output_structure) = (model.state_structure(), model.output_structure());
    let state = fit_block(
        &BlockInput {
            name: "state statistics",
            moments: &stats.state,
            steps: stats.state_steps,
            structure: &state_structure,
            held: &model.held_state_coefficients(),
            estimate_beta: spec.beta_x,
            covariance: spec.pi_x,
            current_beta: &current.beta_x,
            current_pi: &current.pi_x,
        },
        r,
    )?;
    let output = fit_block(
        &BlockInput {
            name: "output statistics",
            moments: &stats.output,
            steps: stats.output_steps,
            structure: &output_structure,
            held: &model.held_output_coefficients(),
            estimate_beta: spec.beta_y,
            covariance: spec.pi_y,
            current_beta: &current.beta_y,
            current_pi: &current.pi_y,
        },
        r,
    )?;
    let (mu, p1) = if spec.initial_state {
        let mu = stats.initial_mean.clone();
        let mut p1 = &stats.initial_second_moment - &mu * mu.transpose();
        sysid_linalg::symmetrize(&mut p1);
        (mu, p1)
    } else {
        (current.mu.clone(), current.p1.clone())
    };
    Ok(AffineParams {
        beta_x: state.beta,
        beta_y: output.beta,
        pi_x: state.pi,
        pi_y: output.pi,
        mu,
        p1,
    })
}
