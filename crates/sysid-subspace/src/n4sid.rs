//! N4SID: combined deterministic-stochastic subspace identification.

use crate::SubspaceError;
use crate::input_fit::fit_inputs;
use crate::weighting::{WeightedSvd, Weighting, perp_projector};
use nalgebra::{DMatrix, DVector};
use sysid_kalman::{LinearGaussianModel, Record};

/// How the model order is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Order {
    /// This order.
    Fixed(usize),
    /// The order that minimises an information criterion over candidate orders
    /// `1 ..= min(p i - 1, 20)`: each candidate is identified in full and scored by
    /// its exact Gaussian log-likelihood on the record (Kalman filter) penalised by its
    /// number of free parameters (see [`OrderScore`] and [`Criterion`]). Candidates
    /// with an unstable `A` are scored but chosen only if no candidate is stable.
    Auto,
}

/// The information criterion of [`Order::Auto`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Criterion {
    /// Akaike's: `-2 ln L + 2 k`.
    Aic,
    /// Schwarz's Bayesian: `-2 ln L + k ln T` (penalises orders more; the default,
    /// since on measured records AIC keeps adding states that fit the estimation
    /// data's coloured noise).
    #[default]
    Bic,
}

/// What `B` and `D` are fitted for (MATLAB's `n4sidOptions('Focus', ...)`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Focus {
    /// `A, B, C, D` jointly by least squares on the state equations of the estimated
    /// state sequence, `[X_{t+1}; Y_t] = [[A, B], [C, D]] [X_t; U_t] + residual`
    /// (Verhaegen and Verdult 2007, as nfoursid and SIPPY do): consistent with the
    /// noise model, so the one-step predictor is good. The default.
    #[default]
    Prediction,
    /// `A, C` as above, then `B`, `D` (and the record's initial state) minimise the
    /// squared error of the noise-free simulated output, a linear least-squares
    /// problem given `A` and `C`: better long-horizon simulations, at some cost in
    /// one-step prediction when the model is simpler than the process.
    Simulation,
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
    /// The weighting of the SVD (default: [`Weighting::Moesp`]).
    pub weighting: Weighting,
    /// What `B` and `D` are fitted for (default: [`Focus::Prediction`]).
    pub focus: Focus,
    /// Enforce a stable `A`: when the least-squares estimate has a pole on or outside
    /// the unit circle, `A` is re-estimated by Maciejowski's (1995) padded shift
    /// equation `Gamma_i A = [Gamma_i(p+1:, :); 0]`, whose solution is always stable
    /// (at the price of some bias), and `B`, `D` are refitted to the state equations
    /// with it (as SIPPY's `A_stability`). Off by default: the result then reports
    /// the spectral radius, and callers should warn.
    pub stable: bool,
    /// The criterion of [`Order::Auto`] (default: [`Criterion::Bic`]).
    pub criterion: Criterion,
}

impl Default for N4sidOptions {
    fn default() -> Self {
        N4sidOptions {
            order: Order::Auto,
            block_rows: None,
            weighting: Weighting::Moesp,
            focus: Focus::Prediction,
            stable: false,
            criterion: Criterion::Bic,
        }
    }
}

/// How `B` and `D` were estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputMethod {
    /// Least squares on the noise-free simulated output given `A` and `C`, with the
    /// record's initial state as a nuisance parameter ([`Focus::Simulation`] with a
    /// stable `A`).
    Simulation,
    /// Least squares on the state equations of the estimated state sequence
    /// ([`Focus::Prediction`], and [`Focus::Simulation`] with an unstable `A`, whose
    /// simulation diverges).
    StateEquations,
}

/// One candidate order of [`Order::Auto`] with its score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrderScore {
    /// The order.
    pub order: usize,
    /// Exact log-likelihood of the identified model on the record (Kalman filter);
    /// `-inf` if the filter failed.
    pub loglik: f64,
    /// Free parameters of an innovation-form model of this order in a canonical basis:
    /// `n (2 p + m) + p m + p (p + 1) / 2` (`A`, `B`, `C`, `K`, `D` and the innovation
    /// covariance, less the `n^2` of the basis).
    pub parameters: usize,
    /// The criterion's value (smaller is better).
    pub criterion: f64,
    /// Spectral radius of this order's `A`.
    pub spectral_radius: f64,
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
    /// The weighting used.
    pub weighting: Weighting,
    /// All `p i` singular values of the weighted oblique projection, largest first.
    pub singular_values: Vec<f64>,
    /// Spectral radius of the estimated `A`: at least 1 means the model is unstable.
    pub spectral_radius: f64,
    /// `A` was re-estimated to be stable ([`N4sidOptions::stable`]).
    pub stabilised: bool,
    /// How `B` and `D` were estimated.
    pub input_method: InputMethod,
    /// The inputs' regressors were collinear (e.g. an input that repeats another, or a
    /// constant one): `B` and `D` are the minimum-norm least-squares solution.
    pub collinear_inputs: bool,
    /// The candidates scored by [`Order::Auto`] (empty for a fixed order).
    pub order_scores: Vec<OrderScore>,
}

/// Pseudo-inverse with the usual tolerance `max(r, c) eps s_max`.
pub(crate) fn pinv(m: &DMatrix<f64>) -> DMatrix<f64> {
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
/// `proj` is that projector; the result is `(O, L)` with `O = L c`.
fn oblique(
    a: &DMatrix<f64>,
    proj: &DMatrix<f64>,
    c: &DMatrix<f64>,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let (a_perp, c_perp) = (a * proj, c * proj);
    let weights = a_perp * pinv(&c_perp);
    (&weights * c, weights)
}

/// The states `Gamma^+ O_i` as a time series: column `c` is the state at time `i + c`
/// (0-based), for `c = 0 .. columns`, from the past `i` inputs and outputs before it.
/// `map` is `Gamma^+ L` with `O_i = L W_p`.
fn time_states(map: &DMatrix<f64>, centred: &Centred, i: usize, columns: usize) -> DMatrix<f64> {
    let (m, p) = (centred.u.nrows(), centred.y.nrows());
    let mut past = DVector::zeros((m + p) * i);
    let mut states = DMatrix::zeros(map.nrows(), columns);
    for c in 0..columns {
        for k in 0..i {
            for a in 0..m {
                past[k * m + a] = centred.u[(a, c + k)];
            }
            for b in 0..p {
                past[m * i + k * p + b] = centred.y[(b, c + k)];
            }
        }
        states.set_column(c, &(map * &past));
    }
    states
}

/// Identifies a linear Gaussian state-space model from one record by N4SID.
///
/// # Model
/// `x_{t+1} = A x_t + B u_t + w_t`, `y_t = C x_t + D u_t + h + e_t`, with
/// `[w; e] ~ N(0, [[Q, S], [S', R]])`; without inputs the purely stochastic case.
///
/// # Algorithm
/// Van Overschee and De Moor's (1996) unified framework with Verhaegen and Verdult's
/// (2007) state-sequence regression, as nfoursid and SIPPY compute it. Each signal is
/// centred and scaled to unit variance (the model is scaled back). The block Hankel
/// matrices of past and future inputs and outputs (`i` block rows) are stacked into
/// `H` (`2 (m + p) i x j`, `j = T - 2i + 1`) and factored once, `H = K Q'` with
/// orthonormal `Q` (a QR of `H'`, by faer); the projections work on the small `K`.
///
/// 1. The oblique projection `O_i = Y_f /_{U_f} W_p = L W_p` is weighted and factored,
///    `W1 O_i W2 = U S V'` ([`Weighting`]); `Gamma_i = W1^{-1} U_1 S_1^{1/2}`.
/// 2. The states `X = Gamma_i^+ L W_p`, a time series over the `j` Hankel columns,
///    give `[X_{t+1}; Y_t] = [[A, B], [C, D]] [X_t; U_t] + residual` by least squares;
///    `Q`, `R`, `S` are the residual covariance (a Gram matrix, so PSD by
///    construction). The earlier code took `X_{i+1}` from a second projection
///    `O_{i-1}` (algorithm 1); its `B`, `D` gave simulation fits far below zero on
///    measured records (the DaISy CD player arm: -212 % at n = 3, now 71.9 %).
/// 3. With [`N4sidOptions::stable`] and an unstable `A`, `A` solves Maciejowski's
///    padded shift equation instead (stable by construction) and `B`, `D` are refitted.
/// 4. With [`Focus::Simulation`] and a stable `A`, `B`, `D` (and the record's initial
///    state) minimise the squared error of the noise-free simulated output given `A`
///    and `C`, a linear least-squares problem; the noise is then the state residual
///    with the inputs' linear effect removed.
/// 5. `h = mean(y) - G(1) mean(u)` with `G(1) = C (I - A)^{-1} B + D`.
/// 6. [`Order::Auto`] runs 2-5 for every candidate order and keeps the one that
///    minimises the [`Criterion`] (each candidate's exact log-likelihood by the Kalman
///    filter); the singular values are returned for the user to inspect.
///
/// # Complexity
/// `O(T ((m + p) i)^2)` for the factorization, `O(((m + p) i)^3)` for the projections,
/// `O(T p (n + n m + p m)^2)` for the input least squares, and for [`Order::Auto`] one
/// Kalman filter per candidate.
///
/// # Errors
/// [`SubspaceError::MissingData`] (first NaN output), [`SubspaceError::TooFewSamples`],
/// [`SubspaceError::OrderTooLarge`], [`SubspaceError::InvalidOption`],
/// [`SubspaceError::ConstantOutput`], [`SubspaceError::Data`] for non-finite inputs or
/// mismatched lengths.
///
/// # References
/// P. Van Overschee and B. De Moor, *Subspace Identification for Linear Systems*,
/// Kluwer, 1996. M. Verhaegen and V. Verdult, *Filtering and System Identification*,
/// Cambridge, 2007. J. M. Maciejowski, "Guaranteed stability with subspace methods",
/// Systems & Control Letters 26, 1995.
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
    for out in 0..p {
        let row = record.y.row(out);
        if t_len > 0 && row.iter().all(|&v| v == row[0]) {
            return Err(SubspaceError::ConstantOutput {
                output: out + 1,
                value: row[0],
            });
        }
    }
    let scales = Scales::of(record);
    let scaled = scales.apply(record);
    let result = identify(&scaled, options)?;
    scales.undo(result)
}

/// Each signal's standard deviation over the record (1 for a constant input): N4SID
/// identifies the signals scaled to unit variance, so that the SVD's weighting does
/// not depend on the units of the columns (as SIPPY does), and the model is scaled
/// back.
struct Scales {
    u: DVector<f64>,
    y: DVector<f64>,
    steps: usize,
}

impl Scales {
    fn of(record: &Record) -> Scales {
        let sd = |m: &DMatrix<f64>| {
            DVector::from_fn(m.nrows(), |a, _| {
                let row = m.row(a);
                let mean = row.mean();
                let var =
                    row.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / row.len().max(1) as f64;
                if var > 0.0 && var.is_finite() {
                    var.sqrt()
                } else {
                    1.0
                }
            })
        };
        Scales {
            u: sd(&record.u),
            y: sd(&record.y),
            steps: record.len(),
        }
    }

    fn apply(&self, record: &Record) -> Record {
        Record::new(
            DMatrix::from_fn(record.u.nrows(), record.len(), |a, t| {
                record.u[(a, t)] / self.u[a]
            }),
            DMatrix::from_fn(record.y.nrows(), record.len(), |b, t| {
                record.y[(b, t)] / self.y[b]
            }),
        )
    }

    /// The model of the scaled signals as a model of the original ones:
    /// `B Su^-1`, `Sy C`, `Sy D Su^-1`, `Sy h`, `Sy R Sy`, `S Sy`; the log-likelihoods
    /// gain the Jacobian `-T sum ln sy`.
    fn undo(&self, mut result: N4sidResult) -> Result<N4sidResult, SubspaceError> {
        let model = &result.model;
        let (su_inv, sy) = (
            DMatrix::from_diagonal(&self.u.map(|v| 1.0 / v)),
            DMatrix::from_diagonal(&self.y),
        );
        result.model = model
            .to_builder()
            .b(model.b() * &su_inv)
            .c(&sy * model.c())
            .d(&sy * model.d() * &su_inv)
            .h(&sy * model.h())
            .r({
                let mut r = &sy * model.r() * &sy;
                sysid_linalg::symmetrize(&mut r);
                r
            })
            .s(model.s() * &sy)
            .build()
            .map_err(|e| {
                SubspaceError::Numerical(format!("the model scaled back is invalid: {e}"))
            })?;
        let jacobian = self.steps as f64 * self.y.iter().map(|v| v.ln()).sum::<f64>();
        for score in &mut result.order_scores {
            score.loglik -= jacobian;
            score.criterion += 2.0 * jacobian;
        }
        Ok(result)
    }
}

/// [`n4sid`] on validated, scaled data.
fn identify(record: &Record, options: &N4sidOptions) -> Result<N4sidResult, SubspaceError> {
    let (m, p, t_len) = (record.u.nrows(), record.y.nrows(), record.len());
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

    // ---- O_i = Y_f /_{U_f} W_p and the weighted SVD ----
    let y_future = rows(&k, &[y_rows(i, 2 * i)]);
    let perp = perp_projector(&rows(&k, &[u_rows(i, 2 * i)]), r_h);
    let (o_i, o_weights) = oblique(&y_future, &perp, &rows(&k, &[u_rows(0, i), y_rows(0, i)]));
    let svd = WeightedSvd::new(options.weighting, &o_i, &perp, &(&y_future * &perp), j);
    let singular_values = svd.singular_values.clone();
    let usable = singular_values.iter().filter(|&&s| s > 0.0).count();
    let centred = Centred {
        u: DMatrix::from_fn(m, t_len, |a, t| record.u[(a, t)] - u_mean[a]),
        y: DMatrix::from_fn(p, t_len, |b, t| record.y[(b, t)] - y_mean[b]),
        u_mean,
        y_mean,
    };
    let projections = Projections {
        svd: &svd,
        o_weights: &o_weights,
        block_rows: i,
        columns: j,
    };
    let candidates: Vec<usize> = match options.order {
        Order::Fixed(n) => vec![n],
        Order::Auto => (1..=usable.min(p * i - 1).min(AUTO_MAX_ORDER)).collect(),
    };
    if candidates.is_empty() || candidates.iter().any(|&n| n > usable) {
        return Err(SubspaceError::OrderTooLarge {
            order: candidates.first().copied().unwrap_or(1),
            block_rows: i,
            max: usable,
        });
    }
    let mut order_scores = Vec::new();
    // the best stable candidate, and the best of all (kept only if none is stable)
    let mut best: Option<(f64, Estimate)> = None;
    let mut best_unstable: Option<(f64, Estimate)> = None;
    let mut workspace = sysid_kalman::KalmanWorkspace::new();
    for &n in &candidates {
        let estimate = estimate_order(n, &projections, &centred, options)?;
        if candidates.len() == 1 {
            best = Some((0.0, estimate));
            break;
        }
        let loglik = workspace
            .loglik(&estimate.model, record)
            .ok()
            .filter(|l| l.is_finite())
            .unwrap_or(f64::NEG_INFINITY);
        let parameters = n * (2 * p + m) + p * m + p * (p + 1) / 2;
        let penalty = match options.criterion {
            Criterion::Aic => 2.0,
            Criterion::Bic => (t_len as f64).ln(),
        };
        let criterion = -2.0 * loglik + penalty * parameters as f64;
        order_scores.push(OrderScore {
            order: n,
            loglik,
            parameters,
            criterion,
            spectral_radius: estimate.spectral_radius,
        });
        let slot = if estimate.spectral_radius < 1.0 {
            &mut best
        } else {
            &mut best_unstable
        };
        if slot.as_ref().is_none_or(|(c, _)| criterion < *c) {
            *slot = Some((criterion, estimate));
        }
    }
    let (_, estimate) = best.or(best_unstable).expect("at least one candidate");
    Ok(N4sidResult {
        order: estimate.model.n(),
        model: estimate.model,
        block_rows: i,
        weighting: options.weighting,
        singular_values,
        spectral_radius: estimate.spectral_radius,
        stabilised: estimate.stabilised,
        input_method: estimate.input_method,
        collinear_inputs: estimate.collinear_inputs,
        order_scores,
    })
}

/// The largest order [`Order::Auto`] considers.
pub const AUTO_MAX_ORDER: usize = 20;

/// The record with its means removed, and the means.
struct Centred {
    u: DMatrix<f64>,
    y: DMatrix<f64>,
    u_mean: DVector<f64>,
    y_mean: DVector<f64>,
}

/// What every candidate order is computed from.
struct Projections<'a> {
    svd: &'a WeightedSvd,
    /// `L` with `O_i = L W_p`.
    o_weights: &'a DMatrix<f64>,
    block_rows: usize,
    /// `j`, the Hankel matrices' column count.
    columns: usize,
}

/// One order's model.
struct Estimate {
    model: LinearGaussianModel,
    spectral_radius: f64,
    stabilised: bool,
    input_method: InputMethod,
    collinear_inputs: bool,
}

/// The largest eigenvalue modulus of `a` (0 for an empty matrix); a model is stable
/// when it is below 1.
pub use sysid_kalman::spectral_radius;

/// Steps 2-4 of [`n4sid`] at order `n`.
fn estimate_order(
    n: usize,
    pr: &Projections<'_>,
    centred: &Centred,
    options: &N4sidOptions,
) -> Result<Estimate, SubspaceError> {
    let (m, p, i) = (centred.u.nrows(), centred.y.nrows(), pr.block_rows);
    let gamma = pr.svd.observability(n);
    let gamma_pinv = pinv(&gamma);
    // the states X_i = Gamma^+ O_i as a time series over the Hankel columns
    let states = time_states(&(&gamma_pinv * pr.o_weights), centred, i, pr.columns);
    let cols = pr.columns - 1;
    let x_now = states.columns(0, cols).clone_owned();
    let x_after = states.columns(1, cols).clone_owned();
    let y_now = centred.y.columns(i, cols).clone_owned();
    let u_now = centred.u.columns(i, cols).clone_owned();
    // [X_{t+1}; Y_t] = [[A, B], [C, D]] [X_t; U_t] + residual
    let mut lhs = DMatrix::zeros(n + p, cols);
    lhs.rows_mut(0, n).copy_from(&x_after);
    lhs.rows_mut(n, p).copy_from(&y_now);
    let mut rhs = DMatrix::zeros(n + m, cols);
    rhs.rows_mut(0, n).copy_from(&x_now);
    rhs.rows_mut(n, m).copy_from(&u_now);
    let theta = &lhs * pinv(&rhs);
    let mut a = theta.view((0, 0), (n, n)).clone_owned();
    let c = theta.view((n, 0), (p, n)).clone_owned();
    let mut b = theta.view((0, n), (n, m)).clone_owned();
    let mut d = theta.view((n, n), (p, m)).clone_owned();
    let mut radius = spectral_radius(&a);
    let mut stabilised = false;
    if options.stable && radius >= 1.0 {
        // Maciejowski: Gamma_i A = [Gamma_i(p+1:, :); 0] has a stable solution; B and
        // D are then re-fitted to the state equations with this A
        let mut padded = DMatrix::zeros(p * i, n);
        padded
            .rows_mut(0, p * (i - 1))
            .copy_from(&gamma.rows(p, p * (i - 1)));
        a = &gamma_pinv * padded;
        radius = spectral_radius(&a);
        stabilised = true;
        let u_pinv = pinv(&u_now);
        b = (&x_after - &a * &x_now) * &u_pinv;
        d = (&y_now - &c * &x_now) * &u_pinv;
    }
    let mut input_method = InputMethod::StateEquations;
    let mut collinear_inputs = m > 0 && rank(&u_now) < m;
    if m > 0 && options.focus == Focus::Simulation && radius < 1.0 {
        let fit = fit_inputs(&a, &c, &centred.u, &centred.y);
        b = fit.b;
        d = fit.d;
        input_method = InputMethod::Simulation;
        collinear_inputs = fit.rank_deficient;
    }
    let mut residual = DMatrix::zeros(n + p, cols);
    residual
        .rows_mut(0, n)
        .copy_from(&(&x_after - &a * &x_now - &b * &u_now));
    residual
        .rows_mut(n, p)
        .copy_from(&(&y_now - &c * &x_now - &d * &u_now));
    if input_method == InputMethod::Simulation {
        // B and D were not fitted to the state equations: the noise is what the
        // residuals leave after any linear effect of the inputs at the same time, so
        // that it does not carry the difference of the two input estimates
        let on_inputs = &residual * pinv(&u_now);
        residual -= on_inputs * &u_now;
    }
    let mut noise = &residual * residual.transpose() / cols as f64;
    sysid_linalg::symmetrize(&mut noise);
    let mut p1 = &x_now * x_now.transpose() / cols as f64;
    sysid_linalg::symmetrize(&mut p1);
    // h = mean(y) - G(1) mean(u)
    let h = if m == 0 {
        centred.y_mean.clone()
    } else {
        match (DMatrix::<f64>::identity(n, n) - &a)
            .lu()
            .solve(&(&b * &centred.u_mean))
        {
            Some(x) => &centred.y_mean - &c * x - &d * &centred.u_mean,
            None => centred.y_mean.clone(),
        }
    };
    let model = LinearGaussianModel::builder(
        a,
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
    Ok(Estimate {
        model,
        spectral_radius: radius,
        stabilised,
        input_method,
        collinear_inputs,
    })
}

/// Numerical rank of `m`'s rows.
fn rank(m: &DMatrix<f64>) -> usize {
    if m.nrows() == 0 || m.ncols() == 0 {
        return 0;
    }
    let s = m.transpose().singular_values();
    let tol = m.nrows().max(m.ncols()) as f64 * f64::EPSILON * s.max() * 1e3;
    s.iter().filter(|&&v| v > tol).count()
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
