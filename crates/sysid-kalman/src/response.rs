//! The noise-free response of a model to a record's inputs, from the initial state
//! that fits the record best, and the fit figure that compares it with the outputs.

use crate::{KalmanError, LinearGaussianModel, Record, Result};
use nalgebra::{DMatrix, DVector};
use sysid_linalg::{QrScratch, triangularize};

/// A noise-free simulation of a record's inputs.
#[derive(Debug, Clone, PartialEq)]
pub struct Response {
    /// Simulated outputs `y_hat` (p x T).
    pub outputs: DMatrix<f64>,
    /// The initial state used.
    pub initial_state: DVector<f64>,
}

/// Time steps whose regressor rows are triangularised together.
const CHUNK: usize = 256;

impl LinearGaussianModel {
    /// The noise-free response `y_t = C x_t + D u_t + h`, `x_{t+1} = A x_t + B u_t`, to
    /// the record's inputs, started at `x0`, or (`None`) at the initial state that
    /// minimises `sum_t ||y_t - y_hat_t||^2` over the observed outputs (MATLAB
    /// `compare`'s `InitialCondition = 'estimate'`, and `shared/data/score_fit.py`'s
    /// protocol).
    ///
    /// # Algorithm
    /// The response is affine in `x0`: `y_hat_t = y0_t + C A^t x0`. The rows
    /// `[C A^t, y_t - y0_t]` of the observed outputs are absorbed into a running
    /// `(n + 1)`-column triangular factor (Householder, a chunk of steps at a time, so
    /// memory does not grow with `T`); `x0` is the minimum-norm least-squares solution
    /// (singular values below `max(pT, n) eps` of the largest are dropped, as numpy's
    /// `lstsq` does), so an unobservable direction is left at zero.
    ///
    /// # Errors
    /// [`KalmanError::SimulationDiverges`] when the simulation overflows (an unstable
    /// `A` over a long record); the record's own checks ([`Record::validate`]).
    pub fn response(&self, record: &Record, x0: Option<&DVector<f64>>) -> Result<Response> {
        record.validate(self, 0)?;
        let (n, p, t_len) = (self.n(), self.p(), record.len());
        let free = self.free_response(record, x0)?;
        if let Some(x0) = x0 {
            return Ok(Response {
                outputs: free,
                initial_state: x0.clone(),
            });
        }
        let cols = n + 1;
        let ld = cols + CHUNK * p;
        let mut buf = vec![0.0; ld * cols];
        let mut scratch = QrScratch::default();
        let mut filled = 0; // rows in use: the factor's `cols`, after the first chunk
        let mut power = self.c().clone();
        for t in 0..t_len {
            for i in 0..p {
                let y = record.y[(i, t)];
                if y.is_nan() {
                    continue;
                }
                for j in 0..n {
                    buf[j * ld + filled] = power[(i, j)];
                }
                buf[n * ld + filled] = y - free[(i, t)];
                filled += 1;
            }
            power = &power * self.a();
            if !power.iter().all(|v| v.is_finite()) {
                return Err(KalmanError::SimulationDiverges { time: t + 1 });
            }
            if filled + p > ld || t + 1 == t_len {
                triangularize(&mut buf, ld, filled, cols, &mut scratch);
                filled = filled.min(cols);
            }
        }
        let k = filled.min(n);
        let r = DMatrix::from_fn(k, n, |i, j| if j >= i { buf[j * ld + i] } else { 0.0 });
        let rhs = DVector::from_fn(k, |i, _| buf[n * ld + i]);
        let x0 = if k == 0 {
            DVector::zeros(n)
        } else {
            let svd = r.svd(true, true);
            let rows = (t_len * p).max(n) as f64;
            let tol = rows * f64::EPSILON * svd.singular_values.max();
            svd.solve(&rhs, tol).unwrap_or_else(|_| DVector::zeros(n))
        };
        let outputs = self.free_response(record, Some(&x0))?;
        Ok(Response {
            outputs,
            initial_state: x0,
        })
    }

    /// The response from `x0` (zero when `None`).
    fn free_response(&self, record: &Record, x0: Option<&DVector<f64>>) -> Result<DMatrix<f64>> {
        let (n, p, t_len) = (self.n(), self.p(), record.len());
        let mut x = x0.cloned().unwrap_or_else(|| DVector::zeros(n));
        let mut out = DMatrix::zeros(p, t_len);
        for t in 0..t_len {
            let u = record.u.column(t);
            let y = self.c() * &x + self.d() * u + self.h();
            if !y.iter().all(|v| v.is_finite()) {
                return Err(KalmanError::SimulationDiverges { time: t + 1 });
            }
            out.set_column(t, &y);
            x = self.a() * &x + self.b() * u;
        }
        Ok(out)
    }
}

/// The fit of `y_hat` to `y` per output, in percent, over the steps `from..T` where
/// `y` is observed: `100 (1 - ||y - y_hat|| / ||y - mean(y)||)` (100 is perfect, 0 is
/// as good as the mean, negative is worse): MATLAB `compare`'s NRMSE fit and
/// `shared/data/score_fit.py`'s figure. An output with no spread gives `-inf` unless
/// matched exactly (then 100).
pub fn fit_percent(y: &DMatrix<f64>, y_hat: &DMatrix<f64>, from: usize) -> Vec<f64> {
    (0..y.nrows())
        .map(|i| {
            let pairs: Vec<(f64, f64)> = (from..y.ncols())
                .map(|t| (y[(i, t)], y_hat[(i, t)]))
                .filter(|(v, _)| !v.is_nan())
                .collect();
            if pairs.is_empty() {
                return f64::NAN;
            }
            let mean = pairs.iter().map(|(v, _)| v).sum::<f64>() / pairs.len() as f64;
            let err: f64 = pairs.iter().map(|(v, h)| (v - h).powi(2)).sum();
            let dev: f64 = pairs.iter().map(|(v, _)| (v - mean).powi(2)).sum();
            if !err.is_finite() {
                f64::NEG_INFINITY
            } else if dev == 0.0 {
                if err == 0.0 { 100.0 } else { f64::NEG_INFINITY }
            } else {
                100.0 * (1.0 - (err / dev).sqrt())
            }
        })
        .collect()
}
