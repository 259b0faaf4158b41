//! N4SID: combined deterministic-stochastic subspace identification.

use crate::SubspaceError;
use nalgebra::{DMatrix, DVector};
use sysid_kalman::{LinearGaussianModel, Record};

/// How the model order is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Order {
    /// This order.
    Fixed(usize),
    /// The order at the largest drop `ln s_k - ln s_{k+1}` of the singular values,
    /// `k = 1 .. min(p i - 1, 20)` (a clear gap between signal and noise singular values
    /// is what a user would look for in the returned singular values).
    Auto,
}

/// Options of [`n4sid`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct N4sidOptions {
    /// Model order (default: [`Order::Auto`]).
    pub order: Order,
    /// Number of block rows `i` of the Hankel matrices. Default: `max(10, ceil((n + 1) / p) + 1)`
    /// for a fixed order `n`, and 10 for [`Order::Auto`], reduced to the largest number
    /// the data allow, `floor((T + 1) / (2 (m + p) + 2))`. Must satisfy `p i > n`.
    pub block_rows: Option<usize>,
}

impl Default for N4sidOptions {
    fn default() -> Self {
        N4sidOptions {
            order: Order::Auto,
            block_rows: None,
        }
    }
}

/// The identified model and what a user needs to judge it.
#[derive(Debug, Clone)]
pub struct N4sidResult {
    /// The model: `A, B, C, D, h, Q, R, S`, with `mu = 0` and `P1` the sample second
    /// moment of the estimated state sequence.
    pub model: LinearGaussianModel,
    /// The chosen order.
    pub order: usize,
    /// The number of block rows used.
    pub block_rows: usize,
    /// All `p i` singular values of the oblique projection, largest first: the order
    /// is where they drop.
    pub singular_values: Vec<f64>,
    /// Spectral radius of the estimated `A`: at least 1 means the estimate is unstable
    /// (reported, not repaired: a Kalman filter runs on unstable models, and EM may
    /// start from one).
    pub spectral_radius: f64,
}

/// Pseudo-inverse with the usual tolerance `max(r, c) eps s_max`.
fn pinv(m: &DMatrix<f64>) -> DMatrix<f64> {
    if m.nrows() == 0 || m.ncols() == 0 {
        return DMatrix::zeros(m.ncols(), m.nrows());
    }
    let svd = m.clone().svd(true, true);
    let s_max = svd.singular_values.max();
    let tol = m.nrows().max(m.ncols()) as f64 * f64::EPSILON * s_max;
    svd.pseudo_inverse(tol)
        .unwrap_or_else(|_| DMatrix::zeros(m.ncols(), m.nrows()))
}

/// Stacks row blocks of `k`.
fn rows(k: &DMatrix<f64>, ranges: &[std::ops::Range<usize>]) -> DMatrix<f64> {
    let total: usize = ranges.iter().map(|r| r.len()).sum();
    let mut out = DMatrix::zeros(total, k.ncols());
    let mut at = 0;
    for r in ranges {
        out.rows_mut(at, r.len())
            .copy_from(&k.rows(r.start, r.len()));
        at += r.len();
    }
    out
}

/// Oblique projection of the row space of `a` onto that of `c` along that of `b`, in
/// coefficient space (rows are coefficients on orthonormal rows, so the Euclidean
/// geometry is that of the data): `(a P) (c P)^+ c`, `P` the projector onto the
/// orthogonal complement of the row space of `b`.
fn oblique(a: &DMatrix<f64>, b: &DMatrix<f64>, c: &DMatrix<f64>) -> DMatrix<f64> {
    let r = a.ncols();
    let mut proj = DMatrix::<f64>::identity(r, r);
    if b.nrows() > 0 {
        let svd = b.transpose().svd(true, false);
        let u = svd.u.expect("requested");
        let s_max = svd.singular_values.max();
        let tol = b.nrows().max(r) as f64 * f64::EPSILON * s_max;
        for (k, &s) in svd.singular_values.iter().enumerate() {
            if s > tol {
                let col = u.column(k);
                proj -= col * col.transpose();
            }
        }
    }
    let (a_perp, c_perp) = (a * &proj, c * &proj);
    a_perp * pinv(&c_perp) * c
}

/// Identifies a linear Gaussian state-space model from one record by N4SID.
///
/// # Model
/// `x_{t+1} = A x_t + B u_t + w_t`, `y_t = C x_t + D u_t + h + e_t`, with
/// `[w; e] ~ N(0, [[Q, S], [S', R]])`; without inputs the purely stochastic case.
///
/// # Algorithm
/// Van Overschee and De Moor (1996), with unit weights. Means are removed first. The
/// block Hankel matrices of past and future inputs and outputs (`i` block rows) are
/// stacked into `H` (`2 (m + p) i x j`, `j = T - 2i + 1`) and factored once, `H = K Q'`
/// with orthonormal `Q` (a QR of `H'`, by faer). Every later step works on the small
/// `K`: the oblique projection `O_i = Y_f /_{U_f} W_p`, its SVD (the returned singular
/// values), the extended observability matrix `Gamma_i = U_1 S_1^{1/2}`, the state
/// sequences `X_i = Gamma_i^+ O_i` and `X_{i+1} = Gamma_{i-1}^+ O_{i-1}`, and the least
/// squares `[X_{i+1}; Y_{i|i}] = [[A, B], [C, D]] [X_i; U_{i|i}] + residual`, whose
/// residual covariance gives `[[Q, S], [S', R]]` (a Gram matrix, so PSD by
/// construction). `h = mean(y) - G(1) mean(u)` with `G(1) = C (I - A)^{-1} B + D`.
///
/// # Complexity
/// `O(T ((m + p) i)^2)` for the factorization, `O(((m + p) i)^3)` for the rest.
///
/// # Errors
/// [`SubspaceError::MissingData`] (first NaN output), [`SubspaceError::TooFewSamples`],
/// [`SubspaceError::OrderTooLarge`], [`SubspaceError::InvalidOption`],
/// [`SubspaceError::Data`] for non-finite inputs or mismatched lengths.
///
/// # References
/// P. Van Overschee and B. De Moor, *Subspace Identification for Linear Systems*,
/// Kluwer, 1996.
pub fn n4sid(record: &Record, options: &N4sidOptions) -> Result<N4sidResult, SubspaceError> {
    let (m, p, t_len) = (record.u.nrows(), record.y.nrows(), record.len());
    if p == 0 {
        return Err(SubspaceError::NoOutputs);
    }
    if record.u.ncols() != t_len {
        return Err(sysid_kalman::KalmanError::LengthMismatch {
            record: 0,
            input_steps: record.u.ncols(),
            output_steps: t_len,
        }
        .into());
    }
    for t in 0..t_len {
        for i in 0..p {
            let v = record.y[(i, t)];
            if v.is_nan() {
                return Err(SubspaceError::MissingData {
                    time: t + 1,
                    output: i + 1,
                });
            }
            if !v.is_finite() {
                return Err(non_finite(t, "output", i, v));
            }
        }
        for i in 0..m {
            let v = record.u[(i, t)];
            if !v.is_finite() {
                return Err(non_finite(t, "input", i, v));
            }
        }
    }
    // Block rows: the user's choice, or a default that is shrunk to what the data
    // allow (T >= 2 (m + p) i + 2 i - 1 samples are needed for the factorization).
    let feasible = |i: usize| 2 * (m + p) * i + 2 * i - 1 <= t_len;
    let i_max = (t_len + 1) / (2 * (m + p) + 2);
    let i = match (options.block_rows, options.order) {
        (Some(i), _) => i,
        (None, Order::Fixed(n)) => 10.max((n + 1).div_ceil(p) + 1).min(i_max.max(2)),
        (None, Order::Auto) => 10.min(i_max.max(2)),
    };
    if i < 2 {
        return Err(SubspaceError::InvalidOption(format!(
            "block rows must be at least 2, got {i}"
        )));
    }
    if let Order::Fixed(n) = options.order {
        if n == 0 {
            return Err(SubspaceError::InvalidOption(
                "order must be at least 1".into(),
            ));
        }
        if n >= p * i {
            // with default block rows, report what the data allow at most
            let max = if options.block_rows.is_none() {
                (p * i_max).saturating_sub(1)
            } else {
                p * i - 1
            };
            return Err(SubspaceError::OrderTooLarge {
                order: n,
                block_rows: i,
                max,
            });
        }
    }
    let r_h = 2 * (m + p) * i;
    let needed = r_h + 2 * i - 1;
    if !feasible(i) {
        return Err(SubspaceError::TooFewSamples {
            block_rows: i,
            needed,
            got: t_len,
        });
    }
    let j = t_len - 2 * i + 1;

    // ---- remove means, factor H' = Q R once (faer), K = R' ----
    let u_mean = DVector::from_fn(m, |a, _| record.u.row(a).mean());
    let y_mean = DVector::from_fn(p, |b, _| record.y.row(b).mean());
    let ht = faer::Mat::<f64>::from_fn(j, r_h, |c, row| {
        if row < 2 * m * i {
            let (k, a) = (row / m, row % m);
            record.u[(a, k + c)] - u_mean[a]
        } else {
            let row = row - 2 * m * i;
            let (k, b) = (row / p, row % p);
            record.y[(b, k + c)] - y_mean[b]
        }
    });
    let r = ht.qr().thin_R().to_owned();
    let k = DMatrix::from_fn(r_h, r_h, |row, col| r[(col, row)]);
    let u_rows = |k0: usize, k1: usize| k0 * m..k1 * m;
    let y_rows = |k0: usize, k1: usize| 2 * m * i + k0 * p..2 * m * i + k1 * p;

    // ---- O_i = Y_f /_{U_f} W_p and its SVD ----
    let o_i = oblique(
        &rows(&k, &[y_rows(i, 2 * i)]),
        &rows(&k, &[u_rows(i, 2 * i)]),
        &rows(&k, &[u_rows(0, i), y_rows(0, i)]),
    );
    let svd = o_i.clone().svd(true, false);
    let u_svd = svd.u.expect("requested");
    let mut order_idx: Vec<usize> = (0..svd.singular_values.len()).collect();
    order_idx.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let singular_values: Vec<f64> = order_idx.iter().map(|&k| svd.singular_values[k]).collect();
    let n = match options.order {
        Order::Fixed(n) => n,
        Order::Auto => auto_order(&singular_values, 20),
    };
    if n > singular_values.len() || singular_values[n - 1] <= 0.0 {
        return Err(SubspaceError::OrderTooLarge {
            order: n,
            block_rows: i,
            max: singular_values.iter().filter(|&&s| s > 0.0).count(),
        });
    }
    let gamma = DMatrix::from_fn(p * i, n, |row, col| {
        u_svd[(row, order_idx[col])] * singular_values[col].sqrt()
    });
    let x_i = pinv(&gamma) * &o_i;
    // ---- X_{i+1} from O_{i-1} = Y_f^- /_{U_f^-} W_p^+ ----
    let o_prev = oblique(
        &rows(&k, &[y_rows(i + 1, 2 * i)]),
        &rows(&k, &[u_rows(i + 1, 2 * i)]),
        &rows(&k, &[u_rows(0, i + 1), y_rows(0, i + 1)]),
    );
    let gamma_prev = gamma.rows(0, p * (i - 1)).clone_owned();
    let x_next = pinv(&gamma_prev) * o_prev;

    // ---- least squares for [[A, B], [C, D]] and the residual covariance ----
    let mut lhs = DMatrix::zeros(n + p, r_h);
    lhs.rows_mut(0, n).copy_from(&x_next);
    lhs.rows_mut(n, p).copy_from(&rows(&k, &[y_rows(i, i + 1)]));
    let mut rhs = DMatrix::zeros(n + m, r_h);
    rhs.rows_mut(0, n).copy_from(&x_i);
    rhs.rows_mut(n, m).copy_from(&rows(&k, &[u_rows(i, i + 1)]));
    let theta = &lhs * pinv(&rhs);
    let residual = &lhs - &theta * &rhs;
    let mut noise = &residual * residual.transpose() / j as f64;
    sysid_linalg::symmetrize(&mut noise);
    let a = theta.view((0, 0), (n, n)).clone_owned();
    let b = theta.view((0, n), (n, m)).clone_owned();
    let c = theta.view((n, 0), (p, n)).clone_owned();
    let d = theta.view((n, n), (p, m)).clone_owned();
    let mut p1 = &x_i * x_i.transpose() / j as f64;
    sysid_linalg::symmetrize(&mut p1);
    // h = mean(y) - G(1) mean(u)
    let h = if m == 0 {
        y_mean.clone()
    } else {
        match (DMatrix::<f64>::identity(n, n) - &a)
            .lu()
            .solve(&(&b * &u_mean))
        {
            Some(x) => &y_mean - &c * x - &d * &u_mean,
            None => y_mean.clone(),
        }
    };
    let model = LinearGaussianModel::builder(
        a.clone(),
        c,
        noise.view((0, 0), (n, n)).clone_owned(),
        noise.view((n, n), (p, p)).clone_owned(),
    )
    .b(b)
    .d(d)
    .s(noise.view((0, n), (n, p)).clone_owned())
    .h(h)
    .p1(p1)
    .build()
    .map_err(|e| SubspaceError::Numerical(format!("the estimated model is invalid: {e}")))?;
    let spectral_radius = a
        .complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max);
    Ok(N4sidResult {
        model,
        order: n,
        block_rows: i,
        singular_values,
        spectral_radius,
    })
}

fn non_finite(t: usize, what: &'static str, index: usize, value: f64) -> SubspaceError {
    sysid_kalman::KalmanError::NonFiniteData {
        record: 0,
        time: t + 1,
        what,
        index: index + 1,
        value,
    }
    .into()
}

/// The order at the largest drop of `ln s_k - ln s_{k+1}`, `k = 1..=min(len - 1, cap)`.
pub fn auto_order(singular_values: &[f64], cap: usize) -> usize {
    let last = (singular_values.len().saturating_sub(1)).min(cap).max(1);
    let ln = |s: f64| {
        if s > 0.0 {
            s.ln()
        } else {
            f64::MIN_POSITIVE.ln() - 100.0
        }
    };
    (1..=last)
        .max_by(|&a, &b| {
            let ga =
                ln(singular_values[a - 1]) - ln(singular_values.get(a).copied().unwrap_or(0.0));
            let gb =
                ln(singular_values[b - 1]) - ln(singular_values.get(b).copied().unwrap_or(0.0));
            ga.total_cmp(&gb).then(b.cmp(&a))
        })
        .unwrap_or(1)
}
