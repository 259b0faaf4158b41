//! The E-step statistics of affine EM, accumulated as an additive functional.

use super::AffineModel;
use nalgebra::{DMatrix, DVector};
use sysid_smc::{AdditiveFunctional, Series};

/// Smoothed second moments of `[alpha_t; x_{t+1}]` (state block, `t < T - 1`) and of
/// `[alpha_t; y_t]` (output block, every `t` with an observed `y_t`), with their
/// weights, and the first two moments of `x_0`.
///
/// With `Phi`, `Psi`, `Sigma` of ALGORITHMS.md 3, the state block's matrix is
/// `N_x [[Sigma, Psi_x'], [Psi_x, Phi_x]]`, and likewise for the output block.
#[derive(Debug, Clone, PartialEq)]
pub struct AffineStatistics {
    /// Second moments of `[alpha; x_{t+1}]`, summed over steps.
    pub state: DMatrix<f64>,
    /// Weight (number of steps) of the state block.
    pub state_steps: f64,
    /// Second moments of `[alpha; y_t]`, summed over observed steps.
    pub output: DMatrix<f64>,
    /// Weight of the output block.
    pub output_steps: f64,
    /// `E[x_0]`.
    pub initial_mean: DVector<f64>,
    /// `E[x_0 x_0']`.
    pub initial_second_moment: DMatrix<f64>,
}

impl AffineStatistics {
    /// Zero statistics for the given dimensions.
    pub fn zeros(regressors: usize, states: usize, outputs: usize) -> Self {
        AffineStatistics {
            state: DMatrix::zeros(regressors + states, regressors + states),
            state_steps: 0.0,
            output: DMatrix::zeros(regressors + outputs, regressors + outputs),
            output_steps: 0.0,
            initial_mean: DVector::zeros(states),
            initial_second_moment: DMatrix::zeros(states, states),
        }
    }

    /// Copies the upper triangles (where accumulation writes) to the lower ones.
    pub(crate) fn finish(&mut self) {
        for m in [&mut self.state, &mut self.output] {
            let k = m.nrows();
            for j in 0..k {
                for i in j + 1..k {
                    m[(i, j)] = m[(j, i)];
                }
            }
        }
    }
}

/// Adds `weight * v v'` to the upper triangle of `m`.
#[inline]
fn add_outer_upper(m: &mut DMatrix<f64>, v: &[f64], weight: f64) {
    let k = v.len();
    for j in 0..k {
        let wj = weight * v[j];
        let column = &mut m.as_mut_slice()[j * k..j * k + j + 1];
        for (c, &vi) in column.iter_mut().zip(v) {
            *c += wj * vi;
        }
    }
}

/// Feeds smoothed pairs `(x_t, x_{t+1})` into [`AffineStatistics`].
pub struct StatisticsCollector<'a, A> {
    model: &'a A,
    data: &'a Series<'a>,
    stats: AffineStatistics,
    state_vector: Vec<f64>,
    output_vector: Vec<f64>,
}

impl<'a, A: AffineModel> StatisticsCollector<'a, A> {
    /// A collector with zero statistics.
    pub fn new(model: &'a A, data: &'a Series<'a>) -> Self {
        let (r, n, p) = (model.regressor_dim(), model.state_dim(), model.output_dim());
        StatisticsCollector {
            model,
            data,
            stats: AffineStatistics::zeros(r, n, p),
            state_vector: vec![0.0; r + n],
            output_vector: vec![0.0; r + p],
        }
    }

    /// The accumulated statistics, with symmetric matrices.
    pub fn finish(mut self) -> AffineStatistics {
        self.stats.finish();
        self.stats
    }
}

impl<A: AffineModel> AdditiveFunctional for StatisticsCollector<'_, A> {
    fn add(&mut self, t: usize, x: &[f64], next: Option<&[f64]>, weight: f64) {
        let r = self.model.regressor_dim();
        let u = self.data.input(t);
        self.model.regressors(t, x, u, &mut self.state_vector[..r]);
        if t == 0 {
            let s = &mut self.stats;
            for (i, &xi) in x.iter().enumerate() {
                s.initial_mean[i] += weight * xi;
                for (j, &xj) in x.iter().enumerate() {
                    s.initial_second_moment[(i, j)] += weight * xi * xj;
                }
            }
        }
        let y = self.data.output(t);
        if !y.iter().any(|v| v.is_nan()) {
            let (alpha, rest) = self.output_vector.split_at_mut(r);
            alpha.copy_from_slice(&self.state_vector[..r]);
            rest.copy_from_slice(y);
            add_outer_upper(&mut self.stats.output, &self.output_vector, weight);
            self.stats.output_steps += weight;
        }
        if let Some(next) = next {
            self.state_vector[r..].copy_from_slice(next);
            add_outer_upper(&mut self.stats.state, &self.state_vector, weight);
            self.stats.state_steps += weight;
        }
    }
}
