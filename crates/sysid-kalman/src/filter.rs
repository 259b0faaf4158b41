//! The square-root (array) Kalman filter: the default filter of this crate.

use crate::diffuse::{DeltaPosterior, DiffuseColumns, PartialPosterior};
use crate::{KalmanError, LinearGaussianModel, Record, Result, dense};
use nalgebra::{DMatrix, DVector};
use sysid_linalg::{
    LN_2PI, LogProduct, QrScratch, axpy, dot, solve_upper_rows, triangularize,
    triangularize_stacked_leading,
};

/// What a filter pass keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Keep {
    /// Only the log-likelihood (the cheapest pass).
    LoglikOnly,
    /// Everything the smoother needs.
    SmootherInputs,
}

/// The stored result of a square-root filter pass over one record.
///
/// Index `k = 0..T-1` is time `t = k + 1`. Predicted quantities exist for
/// `k = 0..=T` (`k = T` is the one-step-ahead prediction beyond the data).
#[derive(Debug, Clone, Default)]
pub struct FilterOutput {
    pub(crate) n: usize,
    pub(crate) t_len: usize,
    pub(crate) loglik: f64,
    /// `x_{t|t-1}`, (T+1) x n
    pub(crate) pred_mean: Vec<f64>,
    /// factor `U` with `U'U = P_{t|t-1}`, (T+1) x n x n
    pub(crate) pred_factor: Vec<f64>,
    /// `x_{t|t}`, T x n
    pub(crate) filt_mean: Vec<f64>,
    /// `J_t'` (transposed smoother gain), T x n x n
    pub(crate) gain_t: Vec<f64>,
    /// a square factor `X33` (not triangular) with `X33'X33 = Cov(x_t | y_{1:t}, x_{t+1})`,
    /// T x n x n
    pub(crate) cond_factor: Vec<f64>,
    /// whether step t reused the factor of step t-1 (steady state reached)
    pub(crate) reused: Vec<bool>,
    /// the means' derivatives in the diffuse part of the initial state (`q = 0`
    /// without one); the stored means and factors are those of `delta = 0`
    pub(crate) diffuse: DiffuseColumns,
    /// `delta` given the whole record (diffuse models)
    pub(crate) delta: Option<DeltaPosterior>,
}

impl FilterOutput {
    /// Log-likelihood `log p(y_{1:T})` of the record.
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
    /// Number of steps at which the covariance recursion was at a floating-point fixed
    /// point and the previous step's factor was reused (see
    /// [`KalmanWorkspace::set_steady_state_reuse`]).
    pub fn reused_steps(&self) -> usize {
        self.reused.iter().filter(|&&r| r).count()
    }
    /// Predicted mean `x_{k+1|k}` (index `k` in `0..=T`).
    ///
    /// With a diffuse initial state this is the limit of the mean as the diffuse
    /// variance grows; see [`diffuse_steps`](Self::diffuse_steps).
    pub fn predicted_mean(&self, k: usize) -> DVector<f64> {
        let mean = dense::vector_at(&self.pred_mean, k, self.n).clone_owned();
        self.with_delta_mean(mean, &self.diffuse.stored_pred, k, k)
    }
    /// Predicted covariance `P_{k+1|k}` (index `k` in `0..=T`), symmetric PSD by
    /// construction (`U'U`, plus `X V X'` for the determined diffuse part).
    pub fn predicted_covariance(&self, k: usize) -> DMatrix<f64> {
        let n = self.n;
        let u = &self.pred_factor[k * n * n..(k + 1) * n * n];
        let mut p = DMatrix::zeros(n, n);
        dense::mul_tn(p.as_mut_slice(), u, u, n, n, n, false, &mut Vec::new());
        self.with_delta_covariance(p, &self.diffuse.stored_pred, k, k)
    }
    /// Filtered mean `x_{k+1|k+1}` (index `k` in `0..T`).
    ///
    /// With a diffuse initial state this is the limit of the mean as the diffuse
    /// variance grows; see [`diffuse_steps`](Self::diffuse_steps).
    pub fn filtered_mean(&self, k: usize) -> DVector<f64> {
        let mean = dense::vector_at(&self.filt_mean, k, self.n).clone_owned();
        self.with_delta_mean(mean, &self.diffuse.stored_filt, k, k + 1)
    }
    /// Filtered covariance `P_{k+1|k+1} = X33'X33 + J P_{k+2|k+1} J'` (index `k` in
    /// `0..T`): a sum of PSD terms (plus `X V X'` for the determined diffuse part).
    pub fn filtered_covariance(&self, k: usize) -> DMatrix<f64> {
        let n = self.n;
        let nn = n * n;
        let x33 = &self.cond_factor[k * nn..(k + 1) * nn];
        let jt = &self.gain_t[k * nn..(k + 1) * nn];
        let u = &self.pred_factor[(k + 1) * nn..(k + 2) * nn];
        let mut p = DMatrix::zeros(n, n);
        let mut scratch = Vec::new();
        dense::mul_tn(p.as_mut_slice(), x33, x33, n, n, n, false, &mut scratch);
        let mut uj = vec![0.0; nn];
        dense::mul_nn(&mut uj, u, jt, n, n, n);
        dense::mul_tn(p.as_mut_slice(), &uj, &uj, n, n, n, true, &mut scratch);
        dense::symmetrize(p.as_mut_slice(), n);
        self.with_delta_covariance(p, &self.diffuse.stored_filt, k, k + 1)
    }

    /// With a diffuse initial state: the number of leading steps `k` after which
    /// part of the filtered state is still undetermined by `y_1..y_{k+1}` (its
    /// variance is infinite; [`filtered_undetermined`](Self::filtered_undetermined)
    /// says which states). 0 without a diffuse part.
    pub fn diffuse_steps(&self) -> usize {
        (0..self.t_len)
            .take_while(|&k| {
                self.partial_delta(k + 1)
                    .is_some_and(|d| d.undetermined.ncols() > 0)
            })
            .count()
    }

    /// Which states of `x_{k+1|k+1}` have an infinite variance (a component in a
    /// diffuse direction that `y_1..y_{k+1}` do not determine). Their entries of
    /// [`filtered_covariance`](Self::filtered_covariance) cover only the determined
    /// part.
    pub fn filtered_undetermined(&self, k: usize) -> Vec<bool> {
        let Some(delta) = self.partial_delta(k + 1) else {
            return vec![false; self.n];
        };
        let (n, q) = (self.n, self.diffuse.q);
        let x =
            DMatrix::from_column_slice(n, q, &self.diffuse.stored_filt[k * n * q..(k + 1) * n * q]);
        let seen = &x * &delta.undetermined;
        (0..n)
            .map(|i| seen.row(i).amax() > 1e-8 * x.row(i).amax())
            .collect()
    }

    /// With a diffuse initial state: the predicted state's derivative `X` (n x q) in
    /// the diffuse part at index `k` (`x_{k+1|k}`), and a basis (q x r) of the
    /// directions that `y_1..y_k` do not determine yet (`r = 0` once all are). `None`
    /// without a diffuse part.
    pub(crate) fn predicted_undetermined(&self, k: usize) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
        let delta = self.partial_delta(k)?;
        let (n, q) = (self.n, self.diffuse.q);
        let x =
            DMatrix::from_column_slice(n, q, &self.diffuse.stored_pred[k * n * q..(k + 1) * n * q]);
        Some((x, delta.undetermined))
    }

    /// `Cov(delta | first steps)` over the determined directions (None without a
    /// diffuse part).
    pub(crate) fn partial_delta_covariance(&self, steps: usize) -> Option<DMatrix<f64>> {
        self.partial_delta(steps).map(|d| d.covariance)
    }

    /// `delta` given the first `steps` observations (None without a diffuse part).
    fn partial_delta(&self, steps: usize) -> Option<PartialPosterior> {
        let q = self.diffuse.q;
        if q == 0 {
            return None;
        }
        if steps == 0 {
            return Some(PartialPosterior::new(&vec![0.0; q * q], &vec![0.0; q], q));
        }
        let t = steps - 1;
        Some(PartialPosterior::new(
            &self.diffuse.stored_info[t * q * q..(t + 1) * q * q],
            &self.diffuse.stored_score[t * q..(t + 1) * q],
            q,
        ))
    }

    /// `mean + X_k E[delta | first steps]` for the stored columns `x` at index `k`.
    fn with_delta_mean(
        &self,
        mut mean: DVector<f64>,
        x: &[f64],
        k: usize,
        steps: usize,
    ) -> DVector<f64> {
        if let Some(delta) = self.partial_delta(steps) {
            let (n, q) = (self.n, self.diffuse.q);
            let xk = DMatrix::from_column_slice(n, q, &x[k * n * q..(k + 1) * n * q]);
            mean += xk * delta.mean;
        }
        mean
    }

    /// `p + X_k Cov(delta | first steps) X_k'` (determined directions only).
    fn with_delta_covariance(
        &self,
        mut p: DMatrix<f64>,
        x: &[f64],
        k: usize,
        steps: usize,
    ) -> DMatrix<f64> {
        if let Some(delta) = self.partial_delta(steps) {
            let (n, q) = (self.n, self.diffuse.q);
            let xk = DMatrix::from_column_slice(n, q, &x[k * n * q..(k + 1) * n * q]);
            p += &xk * delta.covariance * xk.transpose();
            sysid_linalg::symmetrize(&mut p);
        }
        p
    }
}

/// Buffers for the filter, smoother and statistics, allocated once and reused across
/// calls (and EM iterations): no allocation per time step.
#[derive(Debug, Clone, Default)]
pub struct KalmanWorkspace {
    /// the factor being updated: its first `p + n` rows (the rows that the partial
    /// triangularisation writes) by `c = p + 2n` columns, leading dimension
    /// `ldr = p + n`
    rbuf: Vec<f64>,
    ldr: usize,
    /// the state rows `[U C_o', U A', U]`, `rank x c`, leading dimension `n`
    xbuf: Vec<f64>,
    /// rows of `U` that are not zero (zero rows carry no uncertainty)
    u_rows: Vec<usize>,
    /// `U` restricted to `u_rows`, `rank x n`, leading dimension `n`
    u_compact: Vec<f64>,
    /// the initial `R` of a step for the pattern `noise_pattern`: the triangularised
    /// noise factor of `[e_o; w]` padded with the zero blocks, leading dimension `ldr`
    r_template: Vec<f64>,
    noise_pattern: Option<(u64, Vec<usize>)>,
    observed_mask: u64,
    noise_buf: Vec<f64>,
    qr: QrScratch,
    observed: Vec<usize>,
    eps: Vec<f64>,
    x_pred: Vec<f64>,
    u_pred: Vec<f64>,
    x_next: Vec<f64>,
    /// `A'` and `C'`, column-major (column j of `at` is row j of `A`)
    at: Vec<f64>,
    ct: Vec<f64>,
    /// `D u_t + h`
    du_h: Vec<f64>,
    /// `X23` by rows (`n x n`), the right-hand side of the gain solve
    gain_rows: Vec<f64>,
    pub(crate) filter: FilterOutput,
    pub(crate) smoother: crate::SmootherOutput,
    pub(crate) scratch: Vec<f64>,
    pub(crate) sums_buf: Vec<f64>,
    /// the `U` from which the factor in `rbuf` was computed
    u_used: Vec<f64>,
    prev_mask: u64,
    prev_observed: Vec<usize>,
    /// steady-state reuse switched off (see `set_steady_state_reuse`)
    no_reuse: bool,
    /// whether a pass records [`KalmanWorkspace::scalar_moments`]
    record_moments: bool,
    /// `(mean, ln sd)` of each observed value given the values before it
    moments: Vec<f64>,
}

impl KalmanWorkspace {
    /// An empty workspace; buffers grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    /// Switches the steady-state reuse on (the default) or off.
    ///
    /// The covariance recursion of a time-invariant model does not depend on the data
    /// and converges. Once the factor of `P_{t+1|t}` equals that of `P_{t|t-1}` to within
    /// `16 n eps` relative (below what the recursion's own rounding resolves; often the
    /// two are bit-for-bit equal) and the same outputs are observed, the filter reuses
    /// the previous step's whole factor (innovation factor, gain, conditional
    /// covariance) instead of recomputing it; the smoother does the same for its
    /// backward covariance recursion. Results agree with the full recursion to
    /// round-off (tested to 1e-12 relative, and bit for bit when the recursion reaches
    /// an exact fixed point) and are reproducible bit for bit. Missing data, inputs to a
    /// time-varying pattern, or a recursion still moving simply recompute. The error
    /// of freezing is at most of order `T 16 n eps` relative even if the recursion were
    /// not contracting. Switch it off to time or check the full recursion.
    pub fn set_steady_state_reuse(&mut self, on: bool) {
        self.no_reuse = !on;
    }

    /// Log-likelihood of one record, by the square-root filter without storage.
    ///
    /// # Errors
    /// Invalid record ([`Record::validate`]) or a singular innovation covariance.
    pub fn loglik(&mut self, model: &LinearGaussianModel, record: &Record) -> Result<f64> {
        self.loglik_of_record(model, record, 0)
    }

    /// [`loglik`](Self::loglik) of the record numbered `index` of a data set (its
    /// errors name that record).
    ///
    /// # Errors
    /// As [`loglik`](Self::loglik).
    pub fn loglik_of_record(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        index: usize,
    ) -> Result<f64> {
        record.validate(model, index)?;
        self.run(model, record, index, Keep::LoglikOnly)
    }

    /// Log-likelihood of one record and, in `moments`, the one-step conditional law of
    /// every observed output value: its mean and the logarithm of its standard
    /// deviation given all the values before it, in the filter's order (time by time,
    /// the observed outputs of a step in column order, each given the earlier ones of
    /// its step). Two entries per observed value: `[mean, ln sd, mean, ln sd, ...]`.
    ///
    /// The log-likelihood is `-sum (ln sd + (y - mean)^2 / (2 sd^2)) - N/2 ln 2 pi` over
    /// these values (plus the diffuse correction of a diffuse initial state), so their
    /// derivatives give the Fisher information of the parameters (Fisher scoring,
    /// Gauss-Newton for a Gaussian likelihood). `moments` is cleared first; `index`
    /// numbers the record in errors.
    ///
    /// # Errors
    /// As [`loglik`](Self::loglik).
    pub fn scalar_moments(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        index: usize,
        moments: &mut Vec<f64>,
    ) -> Result<f64> {
        record.validate(model, index)?;
        self.record_moments = true;
        std::mem::swap(&mut self.moments, moments);
        self.moments.clear();
        let result = self.run(model, record, index, Keep::LoglikOnly);
        std::mem::swap(&mut self.moments, moments);
        self.record_moments = false;
        result
    }

    /// Square-root filter pass over one record, keeping what the smoother needs.
    pub fn filter(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
    ) -> Result<&FilterOutput> {
        record.validate(model, 0)?;
        self.run(model, record, 0, Keep::SmootherInputs)?;
        Ok(&self.filter)
    }

    fn prepare(&mut self, model: &LinearGaussianModel, t_len: usize, keep: Keep) {
        let (n, p) = (model.n(), model.p());
        self.ldr = p + n;
        self.rbuf.resize(self.ldr * (p + 2 * n), 0.0);
        self.xbuf.resize(n * (p + 2 * n), 0.0);
        self.u_compact.resize(n * n, 0.0);
        self.noise_pattern = None;
        self.eps.resize(p, 0.0);
        self.x_pred.resize(n, 0.0);
        self.u_pred.resize(n * n, 0.0);
        self.x_next.resize(n, 0.0);
        self.du_h.resize(p, 0.0);
        self.gain_rows.resize(n * n, 0.0);
        self.observed.reserve(p);
        self.at.clear();
        self.at.extend(model.a().transpose().iter());
        self.ct.clear();
        self.ct.extend(model.c().transpose().iter());
        let f = &mut self.filter;
        f.n = n;
        f.t_len = t_len;
        if keep == Keep::SmootherInputs {
            f.pred_mean.resize((t_len + 1) * n, 0.0);
            f.pred_factor.resize((t_len + 1) * n * n, 0.0);
            f.filt_mean.resize(t_len * n, 0.0);
            f.gain_t.resize(t_len * n * n, 0.0);
            f.cond_factor.resize(t_len * n * n, 0.0);
            f.reused.clear();
            f.reused.resize(t_len, false);
        }
        self.u_used.resize(n * n, 0.0);
    }

    /// Triangularises the noise factor columns `[e_o, w]` for the current observed
    /// set (once per distinct pattern in a row of steps).
    fn update_noise_factor(&mut self, model: &LinearGaussianModel) {
        if let Some((mask, pattern)) = &self.noise_pattern
            && *mask == self.observed_mask
            && (model.p() <= 64 || *pattern == self.observed)
        {
            return;
        }
        let n = model.n();
        let l = model.noise_factor();
        let ell = l.nrows();
        let k = self.observed.len() + n;
        let ld = ell.max(k);
        self.noise_buf.clear();
        self.noise_buf.resize(ld * k, 0.0);
        let l_data = l.as_slice();
        let sources = self.observed.iter().map(|&o| n + o).chain(0..n);
        for (j, src) in sources.enumerate() {
            self.noise_buf[j * ld..j * ld + ell]
                .copy_from_slice(&l_data[src * ell..(src + 1) * ell]);
        }
        triangularize(&mut self.noise_buf, ld, ell, k, &mut self.qr);
        let ldr = self.ldr;
        self.r_template.clear();
        self.r_template.resize(ldr * (model.p() + 2 * n), 0.0);
        for j in 0..k {
            self.r_template[j * ldr..j * ldr + k]
                .copy_from_slice(&self.noise_buf[j * ld..j * ld + k]);
        }
        self.noise_pattern = Some((self.observed_mask, self.observed.clone()));
    }

    /// Records which rows of the `n x n` factor `u_pred` are non-zero, and copies them
    /// into `u_compact`.
    #[inline(always)]
    fn compact_factor(&mut self, n: usize, triangular: bool) {
        self.u_rows.clear();
        for i in 0..n {
            let nonzero = if triangular {
                self.u_pred[i * n + i] != 0.0
            } else {
                (0..n).any(|k| self.u_pred[k * n + i] != 0.0)
            };
            if nonzero {
                self.u_rows.push(i);
            }
        }
        let rank = self.u_rows.len();
        for k in 0..n {
            for (r, &i) in self.u_rows.iter().enumerate() {
                self.u_compact[k * rank + r] = self.u_pred[k * n + i];
            }
        }
    }

    /// The forward pass. `record_index` only labels errors. Runs compiled for the
    /// widest vector instructions the CPU has ([`sysid_linalg::simd`]; same bits).
    pub(crate) fn run(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        record_index: usize,
        keep: Keep,
    ) -> Result<f64> {
        let loglik = sysid_linalg::simd::dispatch(ForwardPass {
            workspace: self,
            model,
            record,
            record_index,
            keep,
        })?;
        // The diffuse log-likelihood does not depend on mu along the diffuse directions
        // (delta absorbs the shift), but it is computed as log p(y | delta = 0) plus a
        // correction, which cancel when the data put delta far from 0 (a record in
        // other units than mu, or a tiny R): then the pass is run once more from mu
        // moved to the posterior mean of delta, where the correction is small.
        if keep == Keep::LoglikOnly
            && !self.record_moments
            && let Some(delta) = &self.filter.delta
            && 0.5 * delta.factor.tr_mul(&delta.mean).norm_squared() > RECENTRE_NATS
        {
            let shift = model.diffuse() * &delta.mean;
            let centred = model
                .to_builder()
                .mu(model.mu() + shift)
                .build()
                .expect("moving mu keeps a valid model");
            return sysid_linalg::simd::dispatch(ForwardPass {
                workspace: self,
                model: &centred,
                record,
                record_index,
                keep,
            });
        }
        Ok(loglik)
    }

    /// [`run`](Self::run) as compiled into the caller (a dispatched kernel).
    #[inline(always)]
    pub(crate) fn run_body(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        record_index: usize,
        keep: Keep,
    ) -> Result<f64> {
        let (n, p) = (model.n(), model.p());
        let t_len = record.len();
        let diffuse = model.is_diffuse();
        if keep == Keep::LoglikOnly && n == 1 && p == 1 && !diffuse && !self.record_moments {
            return crate::scalar::loglik(model, record, record_index, !self.no_reuse);
        }
        self.prepare(model, t_len, keep);
        let store = keep == Keep::SmootherInputs;
        self.filter.diffuse.start(model.diffuse(), p, t_len, store);
        self.filter.delta = None;
        let nn = n * n;
        let (a, b, d, h) = (model.a(), model.b(), model.d(), model.h());
        self.x_pred.copy_from_slice(model.mu().as_slice());
        self.u_pred
            .copy_from_slice(model.initial_factor().as_slice());
        let mut triangular = false;
        if store {
            self.filter.pred_mean[..n].copy_from_slice(&self.x_pred);
            self.filter.pred_factor[..nn].copy_from_slice(&self.u_pred);
        }
        let mut quad_sum = 0.0;
        let mut observed_sum = 0usize;
        let mut logdet = LogProduct::new();
        for t in 0..t_len {
            let y_t = record.y.column(t);
            let u_t = record.u.column(t);
            let u_t = u_t.as_slice();
            self.observed.clear();
            self.observed_mask = 0;
            for (i, &v) in y_t.iter().enumerate() {
                if !v.is_nan() {
                    self.observed.push(i);
                    self.observed_mask |= 1u64.wrapping_shl(i as u32 % 64);
                }
            }
            let po = self.observed.len();
            let k_noise = po + n;
            let cols = k_noise + if store { n } else { 0 };
            let ld = self.ldr;
            let reuse = !self.no_reuse
                && t > 0
                && self.observed_mask == self.prev_mask
                && (p <= 64 || self.observed == self.prev_observed)
                && settled(&self.u_pred, &self.u_used, n);
            if !reuse {
                self.update_noise_factor(model);
                self.compact_factor(n, triangular);
                // ---- R = [[triangularised [L_e,o, L_w], 0], [0, 0]] ----
                let pre = &mut self.rbuf;
                pre[..ld * cols].copy_from_slice(&self.r_template[..ld * cols]);
                // ---- X = U_nz [C_o', A', I] (rank rows) ----
                let rank = self.u_rows.len();
                let ldx = n;
                let uc = &self.u_compact[..rank * n];
                let xb = &mut self.xbuf;
                let mut fill = |j: usize, v: &[f64]| {
                    dense::mul_vec_sparse(&mut xb[j * ldx..j * ldx + rank], uc, v, rank);
                };
                for (j, &oi) in self.observed.iter().enumerate() {
                    fill(j, &self.ct[oi * n..(oi + 1) * n]);
                }
                for j in 0..n {
                    fill(po + j, &self.at[j * n..(j + 1) * n]);
                }
                if store {
                    for k in 0..n {
                        let j = k_noise + k;
                        xb[j * ldx..j * ldx + rank].copy_from_slice(&uc[k * rank..(k + 1) * rank]);
                    }
                }
                // The noise columns are eliminated; the last n (stored) columns keep
                // [X13; X23] in R and leave Z (rank x n, Z'Z = X33'X33) in X: the
                // smoother needs only the product, so Z is not triangularised.
                triangularize_stacked_leading(pre, ld, xb, ldx, rank, k_noise, cols);
                // u_pred is overwritten by X22 below (this branch's condition), so
                // its old value moves to u_used instead of being copied.
                std::mem::swap(&mut self.u_used, &mut self.u_pred);
                self.prev_mask = self.observed_mask;
                self.prev_observed.clone_from(&self.observed);
            }
            let pre = &self.rbuf;
            // ---- innovation, whitened by X11' ----
            self.du_h.copy_from_slice(h.as_slice());
            for (k, &uk) in u_t.iter().enumerate() {
                axpy(uk, &d.as_slice()[k * p..(k + 1) * p], &mut self.du_h);
            }
            for (j, &oi) in self.observed.iter().enumerate() {
                let e = y_t[oi]
                    - self.du_h[oi]
                    - dot(&self.ct[oi * n..(oi + 1) * n], &self.x_pred)
                    - dot(&pre[j * ld..j * ld + j], &self.eps[..j]);
                let diag = pre[j * ld + j];
                if diag == 0.0 {
                    return Err(KalmanError::SingularInnovation {
                        record: record_index,
                        time: t + 1,
                        output: oi + 1,
                    });
                }
                let w = e / diag;
                if !w.is_finite() {
                    return Err(KalmanError::Overflow {
                        record: record_index,
                        time: t + 1,
                    });
                }
                self.eps[j] = w;
                if diffuse {
                    let c_row = &self.ct[oi * n..(oi + 1) * n];
                    self.filter
                        .diffuse
                        .whiten(j, c_row, &pre[j * ld..j * ld + j], diag, w);
                }
                if self.record_moments {
                    let law = if diffuse {
                        // a value that still sees an undetermined direction is
                        // conditioned on: constant moments, no information
                        self.filter
                            .diffuse
                            .moment(j, y_t[oi] - e, diag, w)
                            .unwrap_or((y_t[oi], 0.0))
                    } else {
                        (y_t[oi] - e, diag.abs().ln())
                    };
                    self.moments.push(law.0);
                    self.moments.push(law.1);
                }
                quad_sum += w * w;
                logdet.push(diag);
            }
            observed_sum += po;
            // ---- x_{t+1|t} = A x + B u + X12' eps ----
            dense::mul_vec_sparse(&mut self.x_next, a.as_slice(), &self.x_pred, n);
            for (k, &uk) in u_t.iter().enumerate() {
                axpy(uk, &b.as_slice()[k * n..(k + 1) * n], &mut self.x_next);
            }
            for i in 0..n {
                self.x_next[i] += dot(&pre[(po + i) * ld..(po + i) * ld + po], &self.eps[..po]);
            }
            if diffuse {
                self.filter
                    .diffuse
                    .advance(t, po, a.as_slice(), pre, ld, store);
            }
            if store {
                let f = &mut self.filter;
                // x_{t|t} = x_{t|t-1} + X13' eps
                for i in 0..n {
                    let x13 = &pre[(po + n + i) * ld..(po + n + i) * ld + po];
                    f.filt_mean[t * n + i] = self.x_pred[i] + dot(x13, &self.eps[..po]);
                }
                // J' = X22^{-1} X23, and X33 (or the previous step's, when reused)
                f.reused[t] = reuse;
                if reuse {
                    f.gain_t.copy_within((t - 1) * nn..t * nn, t * nn);
                    f.cond_factor.copy_within((t - 1) * nn..t * nn, t * nn);
                } else {
                    let cond = &mut f.cond_factor[t * nn..(t + 1) * nn];
                    let rank = self.u_rows.len();
                    // X23 by rows, solved in that layout (whole-row operations), then
                    // stored by columns
                    let rows = &mut self.gain_rows;
                    for j in 0..n {
                        let src = (po + n + j) * ld + po;
                        for i in 0..n {
                            rows[i * n + j] = pre[src + i];
                        }
                        let z = &self.xbuf[(k_noise + j) * n..(k_noise + j) * n + rank];
                        cond[j * n..j * n + rank].copy_from_slice(z);
                        cond[j * n + rank..(j + 1) * n].fill(0.0);
                    }
                    solve_upper_rows(&pre[po * ld + po..], ld, n, rows, n);
                    let gain = &mut f.gain_t[t * nn..(t + 1) * nn];
                    for j in 0..n {
                        for i in 0..n {
                            gain[j * n + i] = rows[i * n + j];
                        }
                    }
                }
            }
            // ---- U_{t+1|t} = X22 (unchanged when the factor was reused) ----
            if !reuse {
                for j in 0..n {
                    let src = (po + j) * ld + po;
                    self.u_pred[j * n..(j + 1) * n].copy_from_slice(&pre[src..src + n]);
                }
            }
            triangular = true;
            std::mem::swap(&mut self.x_pred, &mut self.x_next);
            if store {
                let f = &mut self.filter;
                f.pred_mean[(t + 1) * n..(t + 2) * n].copy_from_slice(&self.x_pred);
                f.pred_factor[(t + 1) * nn..(t + 2) * nn].copy_from_slice(&self.u_pred);
            }
        }
        let mut loglik = -0.5 * (observed_sum as f64) * LN_2PI - logdet.ln() - 0.5 * quad_sum;
        if diffuse {
            let (delta, correction) = self.filter.diffuse.finish(record_index)?;
            loglik += correction;
            self.filter.delta = Some(delta);
        }
        self.filter.loglik = loglik;
        Ok(loglik)
    }
}

/// A diffuse pass whose correction's quadratic term `s' S^{-1} s / 2` exceeds this many
/// nats is run again from the posterior mean of `delta` (the two terms it cancels
/// against are then small: derivatives by differences need about 1e-12 nats).
const RECENTRE_NATS: f64 = 1e2;

/// The forward pass as a [`Kernel`](sysid_linalg::simd::Kernel).
struct ForwardPass<'w, 'm, 'r> {
    workspace: &'w mut KalmanWorkspace,
    model: &'m LinearGaussianModel,
    record: &'r Record,
    record_index: usize,
    keep: Keep,
}

impl sysid_linalg::simd::Kernel for ForwardPass<'_, '_, '_> {
    type Output = Result<f64>;

    #[inline(always)]
    fn run(self) -> Self::Output {
        self.workspace
            .run_body(self.model, self.record, self.record_index, self.keep)
    }
}

/// Whether the square-root recursion has settled: `max |a - b| <= 16 n eps max |b|`,
/// a change below what the recursion's own rounding can resolve (`n` is the state
/// dimension). An exactly zero `b` requires an exactly zero `a`.
#[inline(always)]
pub(crate) fn settled(a: &[f64], b: &[f64], n: usize) -> bool {
    let scale = b.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let tol = 16.0 * n as f64 * f64::EPSILON * scale;
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}
