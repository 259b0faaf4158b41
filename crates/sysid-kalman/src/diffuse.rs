//! Exact diffuse initialisation: the directions `A_d` of the initial state whose
//! variance is infinite.
//!
//! # Algorithm
//! The initial state is `x_1 = mu + A_d delta + eta` with `eta ~ N(0, P1)` and
//! `delta ~ N(0, kappa I)`, `kappa -> infinity`. Given `delta`, the model is an
//! ordinary one with the proper prior `N(mu + A_d delta, P1)`: its covariances do not
//! depend on `delta` and its means are affine in it. So the square-root filter runs
//! once with `delta = 0`, and carries beside the mean the `n x q` matrix `X_t` of its
//! derivative in `delta` (de Jong's augmented filter, 1991): `X_1 = A_d`, and each
//! column follows the mean recursion without data, inputs or offset. The whitened
//! innovations are `eps_t(delta) = eps_t + E_t delta`, so
//! ```text
//! log p(y | delta) = log p(y | 0) + s' delta - delta' S delta / 2,
//! S = sum_t E_t' E_t,   s = - sum_t E_t' eps_t
//! ```
//! and integrating `delta` against `N(0, kappa I)` gives, as `kappa -> infinity`,
//! ```text
//! log L_d = lim (log p_kappa(y) + q/2 log kappa)
//!         = log p(y | 0) - log|S| / 2 + s' S^{-1} s / 2
//! ```
//! the diffuse log-likelihood of Durbin and Koopman (2012, eq. 7.4). Given the data,
//! `delta ~ N(S^{-1} s, S^{-1})`, so by the laws of total expectation and variance the
//! smoothed moments are those of the `delta = 0` pass plus
//! `X^s_t S^{-1} s` (means) and `X^s_t S^{-1} X^s_t'` (covariances), where `X^s_t`
//! follows the smoother's mean recursion; lag-one covariances gain
//! `X^s_{t+1} S^{-1} X^s_t'`.
//!
//! # References
//! de Jong, "The diffuse Kalman filter", Annals of Statistics 19 (1991);
//! Durbin and Koopman, *Time Series Analysis by State Space Methods*, 2nd ed. (2012),
//! ch. 5 and sec. 7.2.

use crate::{KalmanError, Result};
use nalgebra::{DMatrix, DVector};
use sysid_linalg::dot;

/// The augmented columns of one filter pass.
#[derive(Debug, Clone, Default)]
pub(crate) struct DiffuseColumns {
    pub(crate) q: usize,
    n: usize,
    /// `X_{t|t-1}`, n x q, column-major
    pub(crate) pred: Vec<f64>,
    next: Vec<f64>,
    /// whitened innovation responses `E_t`, one column of length `p_o` per direction
    /// (leading dimension `p`)
    eps: Vec<f64>,
    ld_eps: usize,
    /// `S` (q x q) and `s` (q), summed so far
    info: Vec<f64>,
    score: Vec<f64>,
    /// per step, when the filter keeps its output: `X_{t|t-1}` for `t = 1..=T+1`,
    /// `X_{t|t}`, and `S`, `s` after step `t`
    pub(crate) stored_pred: Vec<f64>,
    pub(crate) stored_filt: Vec<f64>,
    pub(crate) stored_info: Vec<f64>,
    pub(crate) stored_score: Vec<f64>,
    /// `S` and `s` summed value by value (for [`DiffuseColumns::moment`]).
    running_info: Vec<f64>,
    running_score: Vec<f64>,
}

impl DiffuseColumns {
    /// Starts a pass: `X_1 = A_d`; `store` sizes the per-step arrays for `t_len` steps.
    pub(crate) fn start(&mut self, diffuse: &DMatrix<f64>, p: usize, t_len: usize, store: bool) {
        let (n, q) = diffuse.shape();
        self.n = n;
        self.q = q;
        self.pred.clear();
        self.pred.extend_from_slice(diffuse.as_slice());
        self.next.resize(n * q, 0.0);
        self.ld_eps = p;
        self.eps.resize(p * q, 0.0);
        self.info.clear();
        self.info.resize(q * q, 0.0);
        self.score.clear();
        self.score.resize(q, 0.0);
        self.running_info.clear();
        self.running_info.resize(q * q, 0.0);
        self.running_score.clear();
        self.running_score.resize(q, 0.0);
        let (s_pred, s_filt, s_info, s_score) = if store {
            ((t_len + 1) * n * q, t_len * n * q, t_len * q * q, t_len * q)
        } else {
            (0, 0, 0, 0)
        };
        self.stored_pred.resize(s_pred, 0.0);
        self.stored_filt.resize(s_filt, 0.0);
        self.stored_info.resize(s_info, 0.0);
        self.stored_score.resize(s_score, 0.0);
        if store && q > 0 {
            self.stored_pred[..n * q].copy_from_slice(&self.pred);
        }
    }

    /// Whitens the response of the observed output `j` (row `oi` of `C`, transposed in
    /// `c_row`) to each direction: `E[j] = (-c_row' X - sum_{i<j} r[i] E[i]) / diag`,
    /// where `r` holds the factor's row `j` left of the diagonal. `eps_j` is the
    /// whitened innovation of the `delta = 0` pass.
    pub(crate) fn whiten(&mut self, j: usize, c_row: &[f64], r: &[f64], diag: f64, eps_j: f64) {
        let (n, ld) = (self.n, self.ld_eps);
        for c in 0..self.q {
            let col = &self.eps[c * ld..c * ld + j];
            let e = -dot(c_row, &self.pred[c * n..(c + 1) * n]) - dot(r, col);
            let w = e / diag;
            self.eps[c * ld + j] = w;
            self.score[c] -= w * eps_j;
        }
    }

    /// The one-step law of the observed output `j` just whitened by
    /// [`DiffuseColumns::whiten`] under the diffuse prior, given the values before it:
    /// `(mean, ln sd)` from the `delta = 0` pass's `mean0` and `diag`, or `None` while
    /// the value still sees an undetermined direction of `delta` (its variance is
    /// infinite: it is one of the values the diffuse likelihood conditions on).
    ///
    /// Given `delta`, the whitened innovation `w + E delta` is standard normal; given
    /// the values before, `delta ~ N(S^+ s, S^+)` on the determined directions, so
    /// `w ~ N(-E S^+ s, 1 + E S^+ E')`.
    pub(crate) fn moment(&mut self, j: usize, mean0: f64, diag: f64, w: f64) -> Option<(f64, f64)> {
        let (q, ld) = (self.q, self.ld_eps);
        let e = DVector::from_fn(q, |c, _| self.eps[c * ld + j]);
        let posterior = PartialPosterior::new(&self.running_info, &self.running_score, q);
        let unseen = posterior.undetermined.tr_mul(&e).norm();
        let law = (unseen <= 1e-8 * e.norm().max(f64::MIN_POSITIVE)).then(|| {
            let shift = e.dot(&posterior.mean);
            let spread = 1.0 + e.dot(&(&posterior.covariance * &e));
            (mean0 - diag * shift, diag.abs().ln() + 0.5 * spread.ln())
        });
        for c in 0..q {
            for d in 0..q {
                self.running_info[c * q + d] += e[c] * e[d];
            }
            self.running_score[c] -= e[c] * w;
        }
        law
    }

    /// Adds `E'E` of this step to `S`, and moves the columns to the next time:
    /// `X_{t+1|t} = A X_{t|t-1} + X12' E`; with `store`, also keeps
    /// `X_{t|t} = X_{t|t-1} + X13' E` and the sums at step `t`. `factor` is the step's
    /// triangularised array (leading dimension `ld`, `po` observed outputs): the
    /// column of state `i` holds `X12` from row `po + i`, `X13` from row `po + n + i`.
    pub(crate) fn advance(
        &mut self,
        t: usize,
        po: usize,
        a: &[f64],
        factor: &[f64],
        ld: usize,
        store: bool,
    ) {
        let (n, q, ld_e) = (self.n, self.q, self.ld_eps);
        let x12 = |i: usize| &factor[(po + i) * ld..(po + i) * ld + po];
        let x13 = |i: usize| &factor[(po + n + i) * ld..(po + n + i) * ld + po];
        for c in 0..q {
            for d in 0..=c {
                let v = dot(
                    &self.eps[c * ld_e..c * ld_e + po],
                    &self.eps[d * ld_e..d * ld_e + po],
                );
                self.info[c * q + d] += v;
                if d != c {
                    self.info[d * q + c] += v;
                }
            }
        }
        for c in 0..q {
            let e = &self.eps[c * ld_e..c * ld_e + po];
            let xp = &self.pred[c * n..(c + 1) * n];
            let xn = &mut self.next[c * n..(c + 1) * n];
            crate::dense::mul_vec_sparse(xn, a, xp, n);
            for (i, v) in xn.iter_mut().enumerate() {
                *v += dot(x12(i), e);
            }
            if store {
                let xf = &mut self.stored_filt[(t * q + c) * n..(t * q + c + 1) * n];
                for (i, v) in xf.iter_mut().enumerate() {
                    *v = xp[i] + dot(x13(i), e);
                }
            }
        }
        std::mem::swap(&mut self.pred, &mut self.next);
        if store {
            let qq = q * q;
            self.stored_info[t * qq..(t + 1) * qq].copy_from_slice(&self.info);
            self.stored_score[t * q..(t + 1) * q].copy_from_slice(&self.score);
            self.stored_pred[(t + 1) * n * q..(t + 2) * n * q].copy_from_slice(&self.pred);
        }
    }

    /// The posterior of `delta` after the whole record, and the log-likelihood's
    /// correction `-log|S| / 2 + s'S^{-1}s / 2`.
    ///
    /// # Errors
    /// [`KalmanError::DiffuseNotIdentified`] when `S` is singular (relative to its
    /// largest eigenvalue, below `1e-10`).
    pub(crate) fn finish(&self, record: usize) -> Result<(DeltaPosterior, f64)> {
        let posterior = DeltaPosterior::new(&self.info, &self.score, self.q)
            .ok_or_else(|| self.not_identified(record))?;
        Ok((posterior.clone(), posterior.loglik_correction))
    }

    fn not_identified(&self, record: usize) -> KalmanError {
        let rank = determined_directions(&self.info, self.q);
        KalmanError::DiffuseNotIdentified {
            record,
            directions: self.q,
            rank,
        }
    }
}

/// Eigenvalues of `S` below this fraction of the largest count as zero: the data do
/// not determine that direction of `delta`.
const IDENTIFIED: f64 = 1e-10;

/// How many directions of `delta` the information `S` (q x q) determines.
fn determined_directions(info: &[f64], q: usize) -> usize {
    let s = DMatrix::from_column_slice(q, q, info);
    let eig = s.symmetric_eigenvalues();
    let top = eig.max().max(0.0);
    eig.iter()
        .filter(|&&v| v > IDENTIFIED * top && top > 0.0)
        .count()
}

/// `delta | y ~ N(S^{-1} s, S^{-1})` with `S = G G'` (Cholesky).
#[derive(Debug, Clone)]
pub(crate) struct DeltaPosterior {
    /// `S^{-1} s`
    pub(crate) mean: DVector<f64>,
    /// lower Cholesky factor `G` of `S`
    pub(crate) factor: DMatrix<f64>,
    pub(crate) loglik_correction: f64,
}

impl DeltaPosterior {
    /// `None` when `S` is not positive definite to [`IDENTIFIED`].
    fn new(info: &[f64], score: &[f64], q: usize) -> Option<Self> {
        if determined_directions(info, q) < q {
            return None;
        }
        let s = DMatrix::from_column_slice(q, q, info);
        let chol = s.cholesky()?;
        let g = chol.l();
        let score = DVector::from_column_slice(score);
        let white = g.solve_lower_triangular(&score)?;
        let mean = chol.solve(&score);
        let logdet: f64 = g.diagonal().iter().map(|v| v.ln()).sum();
        Some(DeltaPosterior {
            mean,
            factor: g,
            loglik_correction: -logdet + 0.5 * white.norm_squared(),
        })
    }

    /// `W = X G^{-T}` (n x q) for `X` (n x q, column-major), so `W W' = X S^{-1} X'`.
    pub(crate) fn whiten_columns(&self, x: &[f64], n: usize) -> DMatrix<f64> {
        let q = self.factor.nrows();
        let xt = DMatrix::from_column_slice(n, q, x).transpose();
        let wt = self
            .factor
            .solve_lower_triangular(&xt)
            .expect("the factor of a positive definite S has a non-zero diagonal");
        wt.transpose()
    }
}

/// Moments of `delta` given the first steps of a record, where `S` may still be
/// singular: the limit of the posterior mean (`S^+ s`), the covariance `S^+` on the
/// determined directions, and a basis of the undetermined ones (variance infinite).
#[derive(Debug, Clone)]
pub(crate) struct PartialPosterior {
    pub(crate) mean: DVector<f64>,
    pub(crate) covariance: DMatrix<f64>,
    pub(crate) undetermined: DMatrix<f64>,
}

impl PartialPosterior {
    pub(crate) fn new(info: &[f64], score: &[f64], q: usize) -> Self {
        let s = DMatrix::from_column_slice(q, q, info);
        let eig = s.symmetric_eigen();
        let top = eig.eigenvalues.max().max(0.0);
        let mut covariance = DMatrix::zeros(q, q);
        let mut undetermined = Vec::new();
        for (k, &lambda) in eig.eigenvalues.iter().enumerate() {
            let v = eig.eigenvectors.column(k);
            if top > 0.0 && lambda > IDENTIFIED * top {
                covariance += (v * v.transpose()) / lambda;
            } else {
                undetermined.push(v.clone_owned());
            }
        }
        let mean = &covariance * DVector::from_column_slice(score);
        let undetermined = if undetermined.is_empty() {
            DMatrix::zeros(q, 0)
        } else {
            DMatrix::from_columns(&undetermined)
        };
        PartialPosterior {
            mean,
            covariance,
            undetermined,
        }
    }
}

/// Every step's `W` (n x q) and `X^s` (n x q, column-major), `t = 0..=T`.
type KeptColumns = (Vec<DMatrix<f64>>, Vec<Vec<f64>>);

/// The smoother's side of the diffuse initialisation: the columns
/// `X^s_t = X_{t|t} + J_t (X^s_{t+1} - X_{t+1|t})` run backwards beside the means, and
/// each step's moments of the `delta = 0` pass are corrected by `delta`'s posterior.
pub(crate) struct DiffuseSmoothing<'a> {
    delta: &'a DeltaPosterior,
    cols: &'a DiffuseColumns,
    n: usize,
    /// `X^s` of the current step `t` and of `t + 1` (n x q, column-major)
    cur: Vec<f64>,
    next: Vec<f64>,
    /// `W = X^s G^{-T}` of the current step and of `t + 1`
    w_cur: DMatrix<f64>,
    w_next: DMatrix<f64>,
    /// every step's `W` and `X^s`, for [`correct_stored`](Self::correct_stored)
    kept: Option<KeptColumns>,
}

impl<'a> DiffuseSmoothing<'a> {
    /// Starts at `t = T` (`x_{T+1}`, whose smoothed columns are the predicted ones).
    /// `keep` keeps every step's columns for [`correct_stored`](Self::correct_stored).
    pub(crate) fn new(
        delta: &'a DeltaPosterior,
        cols: &'a DiffuseColumns,
        t_len: usize,
        keep: bool,
    ) -> Self {
        let (n, q) = (cols.n, cols.q);
        let next = cols.stored_pred[t_len * n * q..(t_len + 1) * n * q].to_vec();
        let w_next = delta.whiten_columns(&next, n);
        let kept = keep.then(|| {
            let mut w = vec![DMatrix::zeros(0, 0); t_len + 1];
            let mut x = vec![Vec::new(); t_len + 1];
            w[t_len] = w_next.clone();
            x[t_len] = next.clone();
            (w, x)
        });
        DiffuseSmoothing {
            delta,
            cols,
            n,
            cur: vec![0.0; n * q],
            next,
            w_cur: DMatrix::zeros(n, q),
            w_next,
            kept,
        }
    }

    /// Adds the corrections to every stored smoothed mean (`(T+1) x n`), covariance
    /// (`(T+1) x n x n`) and lag-one covariance (`T x n x n`), once the backward pass
    /// (which needs the `delta = 0` moments) is over.
    pub(crate) fn correct_stored(&self, mean: &mut [f64], cov: &mut [f64], lag: &mut [f64]) {
        let Some((w, x)) = &self.kept else {
            return;
        };
        let (n, q) = (self.n, self.cols.q);
        let nn = n * n;
        for (t, (w_t, x_t)) in w.iter().zip(x).enumerate() {
            for c in 0..q {
                sysid_linalg::axpy(
                    self.delta.mean[c],
                    &x_t[c * n..(c + 1) * n],
                    &mut mean[t * n..(t + 1) * n],
                );
            }
            let outer = w_t * w_t.transpose();
            add_to(&mut cov[t * nn..(t + 1) * nn], &outer);
            if t + 1 < w.len() {
                let outer = &w[t + 1] * w_t.transpose();
                add_to(&mut lag[t * nn..(t + 1) * nn], &outer);
            }
        }
    }

    /// Computes step `t`'s columns; `jt` is `J_t'` (n x n, column-major).
    pub(crate) fn step(&mut self, t: usize, jt: &[f64]) {
        let (n, q) = (self.n, self.cols.q);
        let mut diff = vec![0.0; n];
        for c in 0..q {
            let pred = &self.cols.stored_pred[((t + 1) * q + c) * n..((t + 1) * q + c + 1) * n];
            let filt = &self.cols.stored_filt[(t * q + c) * n..(t * q + c + 1) * n];
            for i in 0..n {
                diff[i] = self.next[c * n + i] - pred[i];
            }
            for i in 0..n {
                self.cur[c * n + i] = filt[i] + dot(&jt[i * n..(i + 1) * n], &diff);
            }
        }
        self.w_cur = self.delta.whiten_columns(&self.cur, n);
        if let Some((w, x)) = self.kept.as_mut() {
            w[t] = self.w_cur.clone();
            x[t] = self.cur.clone();
        }
    }

    /// Moves to the previous step (after [`step`](Self::step) and its uses).
    pub(crate) fn shift(&mut self) {
        std::mem::swap(&mut self.cur, &mut self.next);
        std::mem::swap(&mut self.w_cur, &mut self.w_next);
    }

    /// `x + X^s E[delta]` for the current (`which = 0`) or next (`1`) step, in place.
    pub(crate) fn correct_mean(&self, x: &mut [f64], which: usize) {
        let (n, q) = (self.n, self.cols.q);
        let cols = if which == 0 { &self.cur } else { &self.next };
        for c in 0..q {
            sysid_linalg::axpy(self.delta.mean[c], &cols[c * n..(c + 1) * n], x);
        }
    }

    /// `p + W_a W_b'` in place (n x n, column-major), where `a`, `b` pick the current
    /// (0) or next (1) step: `(0, 0)` for `P_{t|T}`, `(1, 1)` for `P_{t+1|T}`, `(1, 0)`
    /// for the lag-one `Cov(x_{t+1}, x_t)`.
    pub(crate) fn correct_covariance(&self, p: &mut [f64], a: usize, b: usize) {
        let pick = |k: usize| if k == 0 { &self.w_cur } else { &self.w_next };
        add_to(p, &(pick(a) * pick(b).transpose()));
    }
}

/// `p += m` for a column-major slice of `m`'s size.
fn add_to(p: &mut [f64], m: &DMatrix<f64>) {
    for (v, add) in p.iter_mut().zip(m.iter()) {
        *v += add;
    }
}
