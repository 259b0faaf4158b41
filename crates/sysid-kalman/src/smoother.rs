//! The Rauch-Tung-Striebel smoother with lag-one covariances, and the EM statistics.

use crate::diffuse::DiffuseSmoothing;
use crate::filter::Keep;
use crate::{KalmanWorkspace, LinearGaussianModel, Record, Result, SufficientStatistics, dense};
use nalgebra::{DMatrix, DVector, DVectorView};
use sysid_linalg::dot;

/// Smoothed moments of one record. Index `k = 0..=T` is time `t = k + 1`
/// (`k = T` is `x_{T+1}` given all data).
#[derive(Debug, Clone, Default)]
pub struct SmootherOutput {
    pub(crate) n: usize,
    pub(crate) t_len: usize,
    pub(crate) loglik: f64,
    pub(crate) mean: Vec<f64>,
    pub(crate) cov: Vec<f64>,
    pub(crate) lag_one: Vec<f64>,
    /// whether `cov`/`lag_one` hold every step (false after a statistics-only pass)
    pub(crate) stored_moments: bool,
}

impl SmootherOutput {
    /// Log-likelihood of the record (from the forward pass).
    pub fn loglik(&self) -> f64 {
        self.loglik
    }
    /// Number of time steps `T`.
    pub fn len(&self) -> usize {
        self.t_len
    }
    /// Whether the record was empty.
    pub fn is_empty(&self) -> bool {
        self.t_len == 0
    }
    /// Smoothed mean `x_{k+1|T}`, `k` in `0..=T`.
    pub fn mean(&self, k: usize) -> DVectorView<'_, f64> {
        dense::vector_at(&self.mean, k, self.n)
    }
    /// Smoothed covariance `P_{k+1|T}`, `k` in `0..=T`.
    ///
    /// # Panics
    /// After [`KalmanWorkspace::accumulate_statistics`], which keeps only the
    /// statistics: call [`KalmanWorkspace::smooth`] for the moments.
    pub fn covariance(&self, k: usize) -> DMatrix<f64> {
        assert!(
            self.stored_moments,
            "smoothed covariances were not stored by this pass"
        );
        dense::matrix_at(&self.cov, k, self.n)
    }
    /// Lag-one covariance `M_{k+1|T} = Cov(x_{k+2}, x_{k+1} | y_{1:T})`, `k` in `0..T`.
    ///
    /// # Panics
    /// As [`covariance`](Self::covariance).
    pub fn lag_one_covariance(&self, k: usize) -> DMatrix<f64> {
        assert!(
            self.stored_moments,
            "lag-one covariances were not stored by this pass"
        );
        dense::matrix_at(&self.lag_one, k, self.n)
    }
}

impl KalmanWorkspace {
    /// Square-root filter and RTS smoother over one record.
    ///
    /// # Model
    /// See [`LinearGaussianModel`]; missing outputs are NaN entries.
    ///
    /// # Algorithm
    /// The forward pass triangularises, at every step, the pre-array
    /// `[[U C_o', U A', U], [L_{e,o}, L_w, 0]]` (U'U = P_{t|t-1}, L'L = [[Q, S], [S', R]],
    /// `o` the observed outputs). The resulting factor
    /// `[[X11, X12, X13], [0, X22, X23], [0, 0, X33]]` is the Cholesky factor of the
    /// covariance of `(y_t, x_{t+1}, x_t)` given `y_{1:t-1}`, so it contains the
    /// innovation factor (X11), the predicted factor `U_{t+1|t} = X22`, the smoother gain
    /// `J_t = X23' X22^{-T}` and the factor of `Cov(x_t | y_{1:t}, x_{t+1}) = X33'X33`;
    /// correlated noise (`S != 0`) and missing entries need no special case. Only the
    /// first two block columns are triangularised: the block left under `X23` is a
    /// square factor with the same product as `X33`, which is all the backward pass
    /// uses. The backward pass is
    /// ```text
    /// x_{t|T} = x_{t|t} + J_t (x_{t+1|T} - x_{t+1|t})
    /// P_{t|T} = X33'X33 + J_t P_{t+1|T} J_t'       (a sum of PSD terms)
    /// M_{t|T} = Cov(x_{t+1}, x_t | y) = P_{t+1|T} J_t'
    /// ```
    ///
    /// # Complexity
    /// `O(T (n + p)^3)` time, `O(T n^2)` memory, no allocation per step once the
    /// workspace has grown.
    ///
    /// # References
    /// Rauch, Tung, Striebel (1965); Kailath, Sayed, Hassibi, *Linear Estimation* (2000),
    /// array algorithms; Gibson and Ninness (2005).
    pub fn smooth(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
    ) -> Result<&SmootherOutput> {
        record.validate(model, 0)?;
        self.smooth_record(model, record, 0, None)?;
        Ok(&self.smoother)
    }

    /// Smooths one record and adds its EM statistics to `stats`; returns its
    /// log-likelihood. `record_index` labels errors.
    pub fn accumulate_statistics(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        record_index: usize,
        stats: &mut SufficientStatistics,
    ) -> Result<f64> {
        record.validate(model, record_index)?;
        self.smooth_record(model, record, record_index, Some(stats))
    }

    /// Backward pass. With `stats`, the EM statistics are accumulated step by step and
    /// the smoothed covariances are kept only in rolling buffers (the statistics need
    /// them once); without, every moment is stored for the accessors.
    ///
    /// Both passes run compiled for the widest vector instructions the CPU has
    /// ([`sysid_linalg::simd`]; same bits).
    pub(crate) fn smooth_record(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        record_index: usize,
        stats: Option<&mut SufficientStatistics>,
    ) -> Result<f64> {
        sysid_linalg::simd::dispatch(SmoothingPasses {
            workspace: self,
            model,
            record,
            record_index,
            stats,
            terminal: None,
        })
    }

    /// Smooths one block of a longer record whose smoothed state after the block,
    /// `x_{T+1|all}` and its covariance (column-major), is `terminal` (`None`: the
    /// block ends the record). The moments are stored as by [`smooth`](Self::smooth).
    pub(crate) fn smooth_record_from(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        terminal: Option<(&[f64], &[f64])>,
    ) -> Result<f64> {
        sysid_linalg::simd::dispatch(SmoothingPasses {
            workspace: self,
            model,
            record,
            record_index: 0,
            stats: None,
            terminal,
        })
    }

    #[inline(always)]
    fn smooth_record_body(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        record_index: usize,
        stats: Option<&mut SufficientStatistics>,
        terminal: Option<(&[f64], &[f64])>,
    ) -> Result<f64> {
        let loglik = self.run_body(model, record, record_index, Keep::SmootherInputs)?;
        let n = model.n();
        let nn = n * n;
        let t_len = record.len();
        let keep_moments = stats.is_none();
        let f = &self.filter;
        let s = &mut self.smoother;
        s.n = n;
        s.t_len = t_len;
        s.loglik = loglik;
        s.mean.resize((t_len + 1) * n, 0.0);
        let (cov_len, lag_len) = if keep_moments {
            ((t_len + 1) * nn, t_len * nn)
        } else {
            (2 * nn, nn)
        };
        s.cov.resize(cov_len, 0.0);
        s.lag_one.resize(lag_len, 0.0);
        s.stored_moments = keep_moments;
        // slots of P_{t|T}, P_{t+1|T} and M_t in the stored or rolling buffers
        let cov_slot = |t: usize| if keep_moments { t } else { t % 2 };
        let lag_slot = |t: usize| if keep_moments { t } else { 0 };
        if let Some((mean, cov)) = terminal {
            s.mean[t_len * n..].copy_from_slice(mean);
            let slot = cov_slot(t_len);
            s.cov[slot * nn..(slot + 1) * nn].copy_from_slice(cov);
        } else {
            s.mean[t_len * n..].copy_from_slice(&f.pred_mean[t_len * n..]);
            let u = &f.pred_factor[t_len * nn..];
            let slot = cov_slot(t_len);
            dense::mul_tn(
                &mut s.cov[slot * nn..(slot + 1) * nn],
                u,
                u,
                n,
                n,
                n,
                false,
                &mut self.scratch,
            );
        }
        let mut sums = stats
            .as_ref()
            .map(|st| MomentSums::new(st.dim(), t_len, n, &mut self.sums_buf));
        let mut diffuse = f
            .delta
            .as_ref()
            .map(|delta| DiffuseSmoothing::new(delta, &f.diffuse, t_len, keep_moments));
        // a step's moments corrected for the diffuse part (statistics only)
        let mut corrected = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut diff = vec![0.0; n];
        for t in (0..t_len).rev() {
            let jt = &f.gain_t[t * nn..(t + 1) * nn];
            for (i, di) in diff.iter_mut().enumerate() {
                *di = s.mean[(t + 1) * n + i] - f.pred_mean[(t + 1) * n + i];
            }
            for i in 0..n {
                s.mean[t * n + i] = f.filt_mean[t * n + i] + dot(&jt[i * n..(i + 1) * n], &diff);
            }
            let (cur, next) = (cov_slot(t), cov_slot(t + 1));
            // Steady state: if step t+1 reused the forward factor (same J and X33) and
            // P_{t+1|T} has settled (equals P_{t+2|T} to round-off), P_{t|T} and M_t are
            // taken equal to P_{t+1|T} and M_{t+1}. In the rolling buffers they are
            // already in place.
            let reuse = t + 1 < t_len && f.reused[t + 1] && {
                let after = if keep_moments { t + 2 } else { cur };
                crate::filter::settled(
                    &s.cov[after * nn..(after + 1) * nn],
                    &s.cov[next * nn..(next + 1) * nn],
                    n,
                )
            };
            if reuse {
                if keep_moments {
                    s.cov.copy_within((t + 1) * nn..(t + 2) * nn, t * nn);
                    s.lag_one.copy_within((t + 1) * nn..(t + 2) * nn, t * nn);
                }
            } else {
                let (p_t, p_next) = two_slots(&mut s.cov, cur, next, nn);
                let lag = &mut s.lag_one[lag_slot(t) * nn..(lag_slot(t) + 1) * nn];
                dense::mul_square(lag, p_next, jt, n, false, false, &mut self.scratch);
                let x33 = &f.cond_factor[t * nn..(t + 1) * nn];
                dense::mul_square(p_t, x33, x33, n, true, false, &mut self.scratch);
                dense::mul_square(p_t, jt, lag, n, true, true, &mut self.scratch);
                dense::symmetrize(p_t, n);
            }
            let (p_t, p_next) = two_slots(&mut s.cov, cur, next, nn);
            let lag = &s.lag_one[lag_slot(t) * nn..(lag_slot(t) + 1) * nn];
            if let Some(dx) = diffuse.as_mut() {
                dx.step(t, jt);
            }
            if let Some(sums) = sums.as_mut() {
                let x = &s.mean[t * n..(t + 2) * n];
                match diffuse.as_ref() {
                    None => sums.add_step(model, record, t, x, p_t, p_next, lag),
                    Some(dx) => {
                        let (x_c, p_t_c, p_next_c, lag_c) = &mut corrected;
                        for (buf, from) in [
                            (&mut *x_c, x),
                            (p_t_c, &*p_t),
                            (p_next_c, &*p_next),
                            (lag_c, lag),
                        ] {
                            buf.clear();
                            buf.extend_from_slice(from);
                        }
                        dx.correct_mean(&mut x_c[..n], 0);
                        dx.correct_mean(&mut x_c[n..], 1);
                        dx.correct_covariance(p_t_c, 0, 0);
                        dx.correct_covariance(p_next_c, 1, 1);
                        dx.correct_covariance(lag_c, 1, 0);
                        sums.add_step(model, record, t, x_c, p_t_c, p_next_c, lag_c);
                    }
                }
            }
            if t > 0
                && let Some(dx) = diffuse.as_mut()
            {
                dx.shift();
            }
        }
        if let (Some(stats), Some(sums)) = (stats, sums) {
            let mut x1 = s.mean[..n].to_vec();
            let mut p1 = s.cov[cov_slot(0) * nn..(cov_slot(0) + 1) * nn].to_vec();
            if let Some(dx) = diffuse.as_ref() {
                dx.correct_mean(&mut x1, 0);
                dx.correct_covariance(&mut p1, 0, 0);
            }
            stats.observe_initial(&x1, &p1);
            sums.finish(stats);
        } else if let Some(dx) = diffuse.as_ref() {
            dx.correct_stored(&mut s.mean, &mut s.cov, &mut s.lag_one);
        }
        Ok(loglik)
    }
}

/// The forward and backward passes as a [`Kernel`](sysid_linalg::simd::Kernel).
struct SmoothingPasses<'w, 'm, 'r, 's> {
    workspace: &'w mut KalmanWorkspace,
    model: &'m LinearGaussianModel,
    record: &'r Record,
    record_index: usize,
    stats: Option<&'s mut SufficientStatistics>,
    terminal: Option<(&'s [f64], &'s [f64])>,
}

impl sysid_linalg::simd::Kernel for SmoothingPasses<'_, '_, '_, '_> {
    type Output = Result<f64>;

    #[inline(always)]
    fn run(self) -> Self::Output {
        self.workspace.smooth_record_body(
            self.model,
            self.record,
            self.record_index,
            self.stats,
            self.terminal,
        )
    }
}

/// Mutable views of two distinct `nn`-sized slots of `buf`.
fn two_slots(buf: &mut [f64], a: usize, b: usize, nn: usize) -> (&mut [f64], &mut [f64]) {
    debug_assert_ne!(a, b);
    if a < b {
        let (lo, hi) = buf.split_at_mut(b * nn);
        (&mut lo[a * nn..(a + 1) * nn], &mut hi[..nn])
    } else {
        let (lo, hi) = buf.split_at_mut(a * nn);
        (&mut hi[..nn], &mut lo[b * nn..(b + 1) * nn])
    }
}

/// Streaming accumulation of the EM statistics during the backward pass: the
/// conditional means of `c_t = [x_t; u_t; 1; x_{t+1}; y_t]` go into a `T x dim` matrix
/// `M` and the covariances are summed, so the statistics receive
/// `sum_t Cov(c_t) + M'M` in one batch at the end (one matrix product instead of `T`
/// rank-one updates).
struct MomentSums<'a> {
    dim: usize,
    t_len: usize,
    means: &'a mut [f64],
    cov: &'a mut [f64],
    sum_p: &'a mut [f64],
    sum_p_next: &'a mut [f64],
    sum_lag: &'a mut [f64],
}

impl<'a> MomentSums<'a> {
    fn new(dim: usize, t_len: usize, n: usize, buf: &'a mut Vec<f64>) -> Self {
        let nn = n * n;
        buf.clear();
        buf.resize(t_len * dim + dim * dim + 3 * nn, 0.0);
        let (means, rest) = buf.split_at_mut(t_len * dim);
        let (cov, rest) = rest.split_at_mut(dim * dim);
        let (sum_p, rest) = rest.split_at_mut(nn);
        let (sum_p_next, sum_lag) = rest.split_at_mut(nn);
        MomentSums {
            dim,
            t_len,
            means,
            cov,
            sum_p,
            sum_p_next,
            sum_lag,
        }
    }

    /// Adds step `t`; `x` holds `[x_{t|T}; x_{t+1|T}]`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn add_step(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        t: usize,
        x: &[f64],
        p_t: &[f64],
        p_next: &[f64],
        lag: &[f64],
    ) {
        let (n, m, p) = (model.n(), model.m(), model.p());
        let (dim, t_len) = (self.dim, self.t_len);
        let (ou, o1, oxn, oy) = (n, n + m, n + m + 1, 2 * n + m + 1);
        let means = &mut *self.means;
        for i in 0..n {
            means[i * t_len + t] = x[i];
            means[(oxn + i) * t_len + t] = x[n + i];
        }
        for i in 0..m {
            means[(ou + i) * t_len + t] = record.u[(i, t)];
        }
        means[o1 * t_len + t] = 1.0;
        let y_t = record.y.column(t);
        for i in 0..p {
            means[(oy + i) * t_len + t] = y_t[i];
        }
        for (acc, v) in self.sum_p.iter_mut().zip(p_t) {
            *acc += v;
        }
        for (acc, v) in self.sum_p_next.iter_mut().zip(p_next) {
            *acc += v;
        }
        for (acc, v) in self.sum_lag.iter_mut().zip(lag) {
            *acc += v;
        }
        if !y_t.iter().any(|v| v.is_nan()) {
            return;
        }
        // missing outputs: exact conditional moments through (x_t, x_{t+1})
        let cond = missing_output_conditional(model, record.u.column(t).as_slice(), y_t.as_slice());
        let mut joint = DMatrix::zeros(2 * n, 2 * n);
        for j in 0..n {
            for i in 0..n {
                joint[(i, j)] = p_t[j * n + i];
                joint[(n + i, n + j)] = p_next[j * n + i];
                joint[(n + i, j)] = lag[j * n + i];
                joint[(j, n + i)] = lag[j * n + i];
            }
        }
        let xs = DVector::from_column_slice(x);
        let y_mean = &cond.gain * &xs + &cond.offset;
        let cross = &cond.gain * &joint; // Cov(y_mis, (x_t, x_{t+1}))
        let y_cov = &cross * cond.gain.transpose() + &cond.residual_cov;
        let cov = &mut *self.cov;
        for (a, &yi) in cond.missing.iter().enumerate() {
            means[(oy + yi) * t_len + t] = y_mean[a];
            for j in 0..2 * n {
                let cj = if j < n { j } else { oxn + j - n };
                cov[cj * dim + oy + yi] += cross[(a, j)];
                cov[(oy + yi) * dim + cj] += cross[(a, j)];
            }
            for (b, &yk) in cond.missing.iter().enumerate() {
                cov[(oy + yk) * dim + oy + yi] += y_cov[(a, b)];
            }
        }
    }

    /// Writes the summed state covariances into the `dim x dim` sum and hands the batch
    /// to `stats`.
    fn finish(self, stats: &mut SufficientStatistics) {
        let n = self.sum_p.len().isqrt();
        let (dim, oxn) = (self.dim, stats.xi_range().start);
        for j in 0..n {
            for i in 0..n {
                self.cov[j * dim + i] += self.sum_p[j * n + i];
                self.cov[(oxn + j) * dim + oxn + i] += self.sum_p_next[j * n + i];
                self.cov[j * dim + oxn + i] += self.sum_lag[j * n + i]; // Cov(x_{t+1,i}, x_{t,j})
                self.cov[(oxn + j) * dim + i] += self.sum_lag[i * n + j];
            }
        }
        stats.observe_batch(self.means, self.t_len, self.cov);
    }
}

/// `y_mis = gain [x_t; x_{t+1}] + offset + nu`, `nu ~ N(0, residual_cov)` independent
/// of the states and the observed data.
struct MissingConditional {
    missing: Vec<usize>,
    gain: DMatrix<f64>,
    offset: DVector<f64>,
    residual_cov: DMatrix<f64>,
}

/// Conditional law of the missing outputs of one step given `(x_t, x_{t+1})` and the
/// observed outputs of that step: with `ebar = [w_t; e_o]`,
/// `e_mis = G ebar + nu`, `G = Cov(e_mis, ebar) Cov(ebar)^+`, and
/// `w_t = x_{t+1} - A x_t - B u_t`, `e_o = y_o - C_o x_t - D_o u_t - h_o`.
/// Allocates: used only at steps with missing entries.
fn missing_output_conditional(
    model: &LinearGaussianModel,
    u: &[f64],
    y: &[f64],
) -> MissingConditional {
    let (n, p) = (model.n(), model.p());
    let observed: Vec<usize> = (0..p).filter(|&i| !y[i].is_nan()).collect();
    let missing: Vec<usize> = (0..p).filter(|&i| y[i].is_nan()).collect();
    let (a, b, c, d, q, r, s, h) = (
        model.a(),
        model.b(),
        model.c(),
        model.d(),
        model.q(),
        model.r(),
        model.s(),
        model.h(),
    );
    let no = observed.len();
    let k = n + no;
    // Cov(ebar) and Cov(e_mis, ebar)
    let mut var_bar = DMatrix::zeros(k, k);
    var_bar.view_mut((0, 0), (n, n)).copy_from(q);
    for (jj, &oj) in observed.iter().enumerate() {
        for i in 0..n {
            var_bar[(i, n + jj)] = s[(i, oj)];
            var_bar[(n + jj, i)] = s[(i, oj)];
        }
        for (ii, &oi) in observed.iter().enumerate() {
            var_bar[(n + ii, n + jj)] = r[(oi, oj)];
        }
    }
    let nm = missing.len();
    let mut cov_mb = DMatrix::zeros(nm, k);
    for (a_i, &mi) in missing.iter().enumerate() {
        for i in 0..n {
            cov_mb[(a_i, i)] = s[(i, mi)];
        }
        for (jj, &oj) in observed.iter().enumerate() {
            cov_mb[(a_i, n + jj)] = r[(mi, oj)];
        }
    }
    let scale = var_bar.amax().max(f64::MIN_POSITIVE);
    let g = if cov_mb.amax() == 0.0 {
        DMatrix::zeros(nm, k)
    } else {
        let pinv = var_bar
            .clone()
            .pseudo_inverse(1e-12 * scale)
            .unwrap_or_else(|_| DMatrix::zeros(k, k));
        &cov_mb * pinv
    };
    let mut residual_cov = DMatrix::zeros(nm, nm);
    for (a_i, &mi) in missing.iter().enumerate() {
        for (b_i, &mk) in missing.iter().enumerate() {
            residual_cov[(a_i, b_i)] = r[(mi, mk)];
        }
    }
    residual_cov -= &g * cov_mb.transpose();
    sysid_linalg::symmetrize(&mut residual_cov);
    let g_w = g.columns(0, n);
    let g_o = g.columns(n, no);
    let c_o = DMatrix::from_fn(no, n, |i, j| c[(observed[i], j)]);
    let c_m = DMatrix::from_fn(nm, n, |i, j| c[(missing[i], j)]);
    let mut gain = DMatrix::zeros(nm, 2 * n);
    gain.columns_mut(0, n)
        .copy_from(&(c_m - g_w * a - g_o * &c_o));
    gain.columns_mut(n, n).copy_from(&g_w);
    let u = DVector::from_column_slice(u);
    let du = d * &u;
    let bu = b * &u;
    let resid_o = DVector::from_fn(no, |i, _| y[observed[i]] - du[observed[i]] - h[observed[i]]);
    let offset =
        DVector::from_fn(nm, |i, _| du[missing[i]] + h[missing[i]]) - g_w * bu + g_o * resid_o;
    MissingConditional {
        missing,
        gain,
        offset,
        residual_cov,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use rand::SeedableRng;
    use rand::rngs::Xoshiro256PlusPlus;
    use rand_distr::{Distribution, StandardNormal};

    fn gaussian(rng: &mut Xoshiro256PlusPlus, r: usize, c: usize) -> DMatrix<f64> {
        DMatrix::from_fn(r, c, |_, _| StandardNormal.sample(rng))
    }

    /// The passes run through `simd::dispatch` (wide instructions on a CPU that has
    /// them) and compiled for the baseline target (the bodies called directly) give
    /// the same bits: missing data, inputs, correlated noise and state dimensions with
    /// and without the constant-size kernels.
    #[test]
    fn dispatched_passes_give_the_baseline_bits() {
        for (seed, n) in [(1_u64, 3), (2, 8), (3, 11)] {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
            let (p, m) = (2, 1);
            let g = gaussian(&mut rng, n, n);
            let a = &g * (0.9 / g.norm());
            let noise = gaussian(&mut rng, n + p, n + p);
            let joint = &noise * noise.transpose() + DMatrix::identity(n + p, n + p) * 0.05;
            let model = LinearGaussianModel::builder(
                a,
                gaussian(&mut rng, p, n),
                joint.view((0, 0), (n, n)).clone_owned(),
                joint.view((n, n), (p, p)).clone_owned(),
            )
            .b(gaussian(&mut rng, n, m))
            .s(joint.view((0, n), (n, p)).clone_owned())
            .build()
            .unwrap();
            let u = gaussian(&mut rng, m, 150);
            let mut record = model.simulate(&u, &mut rng).unwrap().record;
            for t in (0..150).step_by(9) {
                record.y[(t % p, t)] = f64::NAN;
            }
            let mut dispatched = KalmanWorkspace::new();
            let mut baseline = KalmanWorkspace::new();
            let ll_d = dispatched.smooth_record(&model, &record, 0, None).unwrap();
            let ll_b = baseline
                .smooth_record_body(&model, &record, 0, None, None)
                .unwrap();
            assert_eq!(ll_d.to_bits(), ll_b.to_bits(), "n = {n}: log-likelihood");
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let (sd, sb) = (&dispatched.smoother, &baseline.smoother);
            assert_eq!(bits(&sd.mean), bits(&sb.mean), "n = {n}: smoothed means");
            assert_eq!(
                bits(&sd.cov),
                bits(&sb.cov),
                "n = {n}: smoothed covariances"
            );
            assert_eq!(bits(&sd.lag_one), bits(&sb.lag_one), "n = {n}: lag-one");
            let mut stats_d = SufficientStatistics::new(n, m, p);
            let mut stats_b = SufficientStatistics::new(n, m, p);
            dispatched
                .smooth_record(&model, &record, 0, Some(&mut stats_d))
                .unwrap();
            baseline
                .smooth_record_body(&model, &record, 0, Some(&mut stats_b), None)
                .unwrap();
            assert_eq!(
                bits(stats_d.second_moment().as_slice()),
                bits(stats_b.second_moment().as_slice()),
                "n = {n}: EM statistics"
            );
        }
    }
}
