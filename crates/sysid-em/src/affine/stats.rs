//! The E-step statistics of affine EM, accumulated as an additive functional.

use super::AffineModel;
use super::moments::PathMoments;
use nalgebra::{DMatrix, DVector};
use sysid_linalg::simd::{Kernel, dispatch};
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

/// Feeds smoothed pairs `(x_t, x_{t+1})` into [`AffineStatistics`].
///
/// Per step it sums the outer products of `[alpha; x_{t+1}]` over the paths once and
/// derives the output block from the same sums (`alpha alpha'` is shared; the output
/// `y_t` is the same on every path), then adds the step's totals times the weight.
pub struct StatisticsCollector<'a, A> {
    model: &'a A,
    data: &'a Series<'a>,
    stats: AffineStatistics,
    /// The step's `[alpha; x_{t+1}]` by component: column `i` holds component `i` of
    /// every path.
    columns: Vec<f64>,
    /// The step's sums over the paths of the products of the columns (upper triangle,
    /// column-major) and of each column (the first `r` are the regressors' sums).
    step_sum: Vec<f64>,
    column_sums: Vec<f64>,
    moments: PathMoments,
}

impl<'a, A: AffineModel> StatisticsCollector<'a, A> {
    /// A collector with zero statistics.
    pub fn new(model: &'a A, data: &'a Series<'a>) -> Self {
        let (r, n, p) = (model.regressor_dim(), model.state_dim(), model.output_dim());
        StatisticsCollector {
            model,
            data,
            stats: AffineStatistics::zeros(r, n, p),
            columns: Vec::new(),
            step_sum: vec![0.0; (r + n) * (r + n)],
            column_sums: vec![0.0; r + n],
            moments: PathMoments::default(),
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
        self.add_step(t, x, next, x.len(), weight);
    }

    fn add_step(
        &mut self,
        t: usize,
        states: &[f64],
        next: Option<&[f64]>,
        state_dim: usize,
        weight: f64,
    ) {
        dispatch(StepKernel {
            collector: self,
            t,
            states,
            next,
            state_dim,
            weight,
        });
    }
}

/// One step of [`StatisticsCollector::add_step`], compiled for the CPU's vector set
/// (the regressors and the step's sums over the paths are short vector loops).
struct StepKernel<'c, 'a, 's, A> {
    collector: &'c mut StatisticsCollector<'a, A>,
    t: usize,
    states: &'s [f64],
    next: Option<&'s [f64]>,
    state_dim: usize,
    weight: f64,
}

impl<A: AffineModel> Kernel for StepKernel<'_, '_, '_, A> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        self.collector
            .accumulate(self.t, self.states, self.next, self.state_dim, self.weight);
    }
}

impl<A: AffineModel> StatisticsCollector<'_, A> {
    #[inline(always)]
    fn accumulate(
        &mut self,
        t: usize,
        states: &[f64],
        next: Option<&[f64]>,
        state_dim: usize,
        weight: f64,
    ) {
        let (r, n) = (self.model.regressor_dim(), state_dim);
        let paths = states.len() / n;
        // Sums over the paths of [alpha; x_{t+1}][alpha; x_{t+1}]' (alpha alpha' alone
        // at the last step) and of alpha.
        let k = if next.is_some() { r + n } else { r };
        self.columns.resize(k * paths, 0.0);
        self.model.regressor_columns(
            t,
            states,
            self.data.input(t),
            &mut self.columns[..r * paths],
        );
        if let Some(next) = next {
            for (path, x) in next.chunks_exact(n).enumerate() {
                for (i, &v) in x.iter().enumerate() {
                    self.columns[(r + i) * paths + path] = v;
                }
            }
        }
        self.moments.sum(
            &self.columns,
            paths,
            k,
            &mut self.step_sum,
            &mut self.column_sums,
        );
        let total_weight = weight * paths as f64;
        if t == 0 {
            let s = &mut self.stats;
            for x in states.chunks_exact(n) {
                for (i, &xi) in x.iter().enumerate() {
                    s.initial_mean[i] += weight * xi;
                    for (j, &xj) in x.iter().enumerate() {
                        s.initial_second_moment[(i, j)] += weight * xi * xj;
                    }
                }
            }
        }
        if next.is_some() {
            let state = self.stats.state.as_mut_slice();
            for (m, &v) in state.iter_mut().zip(&self.step_sum[..k * k]) {
                *m += weight * v;
            }
            self.stats.state_steps += total_weight;
        }
        let y = self.data.output(t);
        if !y.iter().any(|v| v.is_nan()) {
            // [alpha; y] block: alpha alpha' from the step sums, alpha y' = (sum alpha) y',
            // y y' once per path.
            let out_k = r + y.len();
            let output = self.stats.output.as_mut_slice();
            for j in 0..r {
                for i in 0..=j {
                    output[j * out_k + i] += weight * self.step_sum[j * k + i];
                }
            }
            for (jy, &yj) in y.iter().enumerate() {
                let column = &mut output[(r + jy) * out_k..(r + jy + 1) * out_k];
                for (c, &a) in column[..r].iter_mut().zip(&self.column_sums[..r]) {
                    *c += weight * a * yj;
                }
                for (c, &yi) in column[r..=r + jy].iter_mut().zip(y) {
                    *c += total_weight * yi * yj;
                }
            }
            self.stats.output_steps += total_weight;
        }
    }
}
