//! EM sufficient statistics: the smoothed joint second-moment matrix.

use nalgebra::{DMatrix, DVector};

/// Accumulator of the smoothed second moments that the EM M-step needs.
///
/// # Model
/// With `z_t = [x_t; u_t; 1]` and `xi_t = [x_{t+1}; y_t]`, the joint vector
/// `c_t = [z_t; xi_t]` has dimension `2n + m + 1 + p` and
/// ```text
/// H = sum_t E{ c_t c_t' | y } = [[N Sigma, N Psi'], [N Psi, N Phi]]
/// ```
/// summed over `t = 1..T` of every record (the complete data include `x_{T+1}`, as in
/// Gibson and Ninness). Missing outputs enter through their exact conditional moments,
/// so the same `H` serves EM with missing data. The initial-state moments
/// `sum E{x_1}` and `sum E{x_1 x_1'}` over records are kept for the `mu`, `P1` update.
///
/// `observe_*` adds one step or record; [`merge`](Self::merge) adds another accumulator
/// (e.g. from another record or thread): statistics of independent records add up.
#[derive(Debug, Clone, PartialEq)]
pub struct SufficientStatistics {
    n: usize,
    m: usize,
    p: usize,
    second_moment: DMatrix<f64>,
    steps: usize,
    records: usize,
    initial_mean_sum: DVector<f64>,
    initial_second_moment_sum: DMatrix<f64>,
}

impl SufficientStatistics {
    /// An empty accumulator for `n` states, `m` inputs and `p` outputs.
    pub fn new(n: usize, m: usize, p: usize) -> Self {
        let dim = 2 * n + m + 1 + p;
        SufficientStatistics {
            n,
            m,
            p,
            second_moment: DMatrix::zeros(dim, dim),
            steps: 0,
            records: 0,
            initial_mean_sum: DVector::zeros(n),
            initial_second_moment_sum: DMatrix::zeros(n, n),
        }
    }

    /// Dimension of `c_t`: `2n + m + 1 + p`.
    pub fn dim(&self) -> usize {
        self.second_moment.nrows()
    }
    /// `(n, m, p)`.
    pub fn dims(&self) -> (usize, usize, usize) {
        (self.n, self.m, self.p)
    }
    /// Number of time steps `N` summed.
    pub fn steps(&self) -> usize {
        self.steps
    }
    /// Number of records summed.
    pub fn records(&self) -> usize {
        self.records
    }
    /// Index range of `z = [x_t; u_t; 1]` within `c_t`.
    pub fn z_range(&self) -> std::ops::Range<usize> {
        0..self.n + self.m + 1
    }
    /// Index range of `xi = [x_{t+1}; y_t]` within `c_t`.
    pub fn xi_range(&self) -> std::ops::Range<usize> {
        self.n + self.m + 1..self.dim()
    }
    /// The summed joint second moment `H` (`dim x dim`, symmetric).
    pub fn second_moment(&self) -> &DMatrix<f64> {
        &self.second_moment
    }
    /// `sum_records E{x_1 | y}`.
    pub fn initial_mean_sum(&self) -> &DVector<f64> {
        &self.initial_mean_sum
    }
    /// `sum_records E{x_1 x_1' | y}`.
    pub fn initial_second_moment_sum(&self) -> &DMatrix<f64> {
        &self.initial_second_moment_sum
    }

    /// `Sigma = (1/N) sum E{z z'}`.
    pub fn sigma(&self) -> DMatrix<f64> {
        let z = self.z_range();
        self.block(z.clone(), z)
    }
    /// `Psi = (1/N) sum E{xi z'}`.
    pub fn psi(&self) -> DMatrix<f64> {
        self.block(self.xi_range(), self.z_range())
    }
    /// `Phi = (1/N) sum E{xi xi'}`.
    pub fn phi(&self) -> DMatrix<f64> {
        let xi = self.xi_range();
        self.block(xi.clone(), xi)
    }

    fn block(&self, rows: std::ops::Range<usize>, cols: std::ops::Range<usize>) -> DMatrix<f64> {
        let scale = 1.0 / self.steps.max(1) as f64;
        self.second_moment
            .view((rows.start, cols.start), (rows.len(), cols.len()))
            .clone_owned()
            * scale
    }

    /// Adds one step: `H += covariance + mean mean'`, where `mean` and the symmetric
    /// `covariance` are the conditional moments of `c_t` (column-major `dim x dim`).
    pub fn observe_step(&mut self, mean: &[f64], covariance: &[f64]) {
        let dim = self.dim();
        debug_assert_eq!(mean.len(), dim);
        debug_assert_eq!(covariance.len(), dim * dim);
        let h = self.second_moment.as_mut_slice();
        for j in 0..dim {
            let mj = mean[j];
            let hj = &mut h[j * dim..(j + 1) * dim];
            for ((hij, &cij), &mi) in hj.iter_mut().zip(&covariance[j * dim..]).zip(mean) {
                *hij += cij + mi * mj;
            }
        }
        self.steps += 1;
    }

    /// Adds `steps` steps at once: `H += covariance_sum + M'M`, where `means` is the
    /// column-major `steps x dim` matrix whose row `t` is the conditional mean of `c_t`
    /// and `covariance_sum` (column-major `dim x dim`) is `sum_t Cov(c_t)`.
    pub fn observe_batch(&mut self, means: &[f64], steps: usize, covariance_sum: &[f64]) {
        let dim = self.dim();
        let h = self.second_moment.as_mut_slice();
        for j in 0..dim {
            let mj = &means[j * steps..(j + 1) * steps];
            for i in 0..=j {
                let v = sysid_linalg::dot(&means[i * steps..(i + 1) * steps], mj)
                    + covariance_sum[j * dim + i];
                h[j * dim + i] += v;
                if i != j {
                    h[i * dim + j] += v;
                }
            }
        }
        self.steps += steps;
    }

    /// Adds one step observed without uncertainty (e.g. a sampled trajectory of a
    /// particle smoother, with `weight`): `H += weight c c'`. Counts as `weight` of a
    /// step only in the sense that callers must observe weights summing to one per step
    /// and then call [`count_steps`](Self::count_steps).
    pub fn observe_weighted_sample(&mut self, c: &[f64], weight: f64) {
        let dim = self.dim();
        let h = self.second_moment.as_mut_slice();
        for j in 0..dim {
            let wj = weight * c[j];
            for (hij, &ci) in h[j * dim..(j + 1) * dim].iter_mut().zip(c) {
                *hij += ci * wj;
            }
        }
    }

    /// Adds `k` to the step count (pairs with [`observe_weighted_sample`](Self::observe_weighted_sample)).
    pub fn count_steps(&mut self, k: usize) {
        self.steps += k;
    }

    /// Adds the smoothed initial-state moments of one record.
    pub fn observe_initial(&mut self, mean: &[f64], covariance: &[f64]) {
        let n = self.n;
        for j in 0..n {
            self.initial_mean_sum[j] += mean[j];
            for i in 0..n {
                self.initial_second_moment_sum[(i, j)] += covariance[j * n + i] + mean[i] * mean[j];
            }
        }
        self.records += 1;
    }

    /// Adds the statistics of another accumulator of the same dimensions.
    ///
    /// # Panics
    /// If the dimensions differ (a programming error).
    pub fn merge(&mut self, other: &SufficientStatistics) {
        assert_eq!(
            self.dims(),
            other.dims(),
            "merging statistics of different models"
        );
        self.second_moment += &other.second_moment;
        self.steps += other.steps;
        self.records += other.records;
        self.initial_mean_sum += &other.initial_mean_sum;
        self.initial_second_moment_sum += &other.initial_second_moment_sum;
    }
}
