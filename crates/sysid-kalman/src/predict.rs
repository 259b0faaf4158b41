//! `k`-step-ahead predictions of a record's outputs, their uncertainty, and the
//! prediction errors.

use crate::{KalmanError, KalmanWorkspace, LinearGaussianModel, Record, Result};
use nalgebra::{DMatrix, DVector};

/// `k`-step-ahead predictions `y_{t|t-k} = E[y_t | y_1..y_{t-k}, u_1..u_t]` of one
/// record (index `t = 0..T-1` is time `t + 1`).
#[derive(Debug, Clone, PartialEq)]
pub struct Predictions {
    /// The horizon `k >= 1`.
    pub horizon: usize,
    /// Predicted outputs (p x T).
    pub mean: DMatrix<f64>,
    /// Their standard deviations `sqrt(diag(C P_{t|t-k} C' + R))` (p x T): the
    /// uncertainty of the prediction of a new measurement. Infinite where the data do
    /// not yet determine a diffuse initial state's effect on that output.
    pub sd: DMatrix<f64>,
    /// Prediction errors `y_t - y_{t|t-k}` (p x T; NaN where `y_t` is missing); for
    /// `k = 1` the innovations.
    pub errors: DMatrix<f64>,
    /// Errors divided by their standard deviations, output by output (p x T; NaN
    /// where `y_t` is missing, 0 where the standard deviation is infinite).
    pub standardised: DMatrix<f64>,
    /// Covariances `C P_{t|t-k} C' + R` of each step's prediction (p x p each).
    pub covariances: Vec<DMatrix<f64>>,
    /// The record's log-likelihood under the model (from the same filter pass).
    pub loglik: f64,
}

impl LinearGaussianModel {
    /// `horizon`-step-ahead predictions of the record's outputs from its initial state
    /// (`mu`, `P1` and any diffuse directions), by the square-root Kalman filter: the
    /// predicted state `x_{t-k+1|t-k}` is run `k - 1` steps forward without data
    /// (`x <- A x + B u`, `P <- A P A' + Q`), and mapped to the outputs. The first
    /// `k - 1` steps are predicted from the initial state alone. For `k = 1` the
    /// errors are the innovations and the covariances the innovation covariances,
    /// statsmodels' `forecasts_error` and `forecasts_error_cov`.
    ///
    /// # Errors
    /// Those of the filter ([`KalmanWorkspace::filter`]); a `horizon` of zero is
    /// treated as 1.
    pub fn predict(&self, record: &Record, horizon: usize) -> Result<Predictions> {
        let k = horizon.max(1);
        let (n, p, t_len) = (self.n(), self.p(), record.len());
        let mut ws = KalmanWorkspace::new();
        let f = ws.filter(self, record)?;
        let mut pred = Predictions {
            horizon: k,
            mean: DMatrix::zeros(p, t_len),
            sd: DMatrix::zeros(p, t_len),
            errors: DMatrix::zeros(p, t_len),
            standardised: DMatrix::zeros(p, t_len),
            covariances: Vec::with_capacity(t_len),
            loglik: f.loglik(),
        };
        for t in 0..t_len {
            // the last data used: steps before `base`, whose predicted state is index base
            let base = (t + 1).saturating_sub(k);
            let mut x: DVector<f64> = f.predicted_mean(base);
            let mut cov = f.predicted_covariance(base);
            let mut response = DMatrix::<f64>::identity(n, n); // d x_t / d x_base
            for j in base..t {
                let u = record.u.column(j);
                x = self.a() * &x + self.b() * u;
                cov = self.a() * &cov * self.a().transpose() + self.q();
                response = self.a() * response;
            }
            sysid_linalg::symmetrize(&mut cov);
            let u = record.u.column(t);
            let mean = self.c() * &x + self.d() * u + self.h();
            let mut out_cov = self.c() * cov * self.c().transpose() + self.r();
            sysid_linalg::symmetrize(&mut out_cov);
            // an output is undetermined if it depends on a diffuse direction the data
            // have not pinned down yet
            let undetermined = f.predicted_undetermined(base).map(|(xd, basis)| {
                let effect = self.c() * response * xd;
                let seen = &effect * basis;
                (0..p)
                    .map(|i| seen.ncols() > 0 && seen.row(i).amax() > 1e-8 * effect.row(i).amax())
                    .collect::<Vec<bool>>()
            });
            for i in 0..p {
                let infinite = undetermined.as_ref().is_some_and(|u| u[i]);
                let sd = if infinite {
                    f64::INFINITY
                } else {
                    out_cov[(i, i)].max(0.0).sqrt()
                };
                let error = record.y[(i, t)] - mean[i];
                pred.mean[(i, t)] = mean[i];
                pred.sd[(i, t)] = sd;
                pred.errors[(i, t)] = error;
                pred.standardised[(i, t)] = match (error.is_nan(), infinite) {
                    (true, _) => f64::NAN,
                    (false, true) => 0.0,
                    (false, false) if sd == 0.0 && error == 0.0 => 0.0,
                    (false, false) => error / sd,
                };
            }
            pred.covariances.push(out_cov);
        }
        Ok(pred)
    }
}

impl Predictions {
    /// Per output, the root mean square of the standardised errors over the steps where
    /// the output is observed: about 1 for a model that describes its own uncertainty,
    /// above 1 for one that is too confident. 0 for an output never observed.
    pub fn standardised_rms(&self) -> Vec<f64> {
        self.standardised
            .row_iter()
            .map(|row| {
                let (sum, count) = row
                    .iter()
                    .filter(|v| v.is_finite())
                    .fold((0.0, 0usize), |(s, c), v| (s + v * v, c + 1));
                (sum / count.max(1) as f64).sqrt()
            })
            .collect()
    }

    /// How many predictions (output and step) have an infinite standard deviation: they
    /// depend on a diffuse initial state that the data have not yet determined.
    pub fn undetermined(&self) -> usize {
        self.sd.iter().filter(|v| v.is_infinite()).count()
    }

    /// What should temper a reading of these predictions.
    pub fn warnings(&self) -> Vec<PredictionWarning> {
        match self.undetermined() {
            0 => Vec::new(),
            count => vec![PredictionWarning::Undetermined { count }],
        }
    }
}

/// Why some predictions should be read with care.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum PredictionWarning {
    /// Predictions that depend on the diffuse initial state before the data determine
    /// it; their standard deviation is infinite.
    Undetermined {
        /// How many (output, step) pairs.
        count: usize,
    },
}

impl std::fmt::Display for PredictionWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PredictionWarning::Undetermined { count } => write!(
                f,
                "{count} prediction(s) depend on the diffuse initial state before the data \
                 determine it: their standard deviation is inf"
            ),
        }
    }
}

/// Outputs beyond the end of a record (see [`LinearGaussianModel::forecast`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Forecast {
    /// `E[y_{T+j} | y_1..y_T]`, `j = 1..=steps` (p x steps).
    pub mean: DMatrix<f64>,
    /// Their standard deviations (p x steps).
    pub sd: DMatrix<f64>,
    /// Their covariances `C P_{T+j|T} C' + R` (p x p each).
    pub covariances: Vec<DMatrix<f64>>,
}

impl Forecast {
    /// Two-sided prediction intervals of probability `level` for each forecast output,
    /// from the normal law of the forecast: `mean -+ z sd` with `z` the normal quantile
    /// of `(1 + level) / 2`.
    ///
    /// # Errors
    /// [`KalmanError::BadOption`] unless `0 < level < 1`.
    pub fn intervals(&self, level: f64) -> Result<ForecastIntervals> {
        let z = ForecastIntervals::half_width(level)?;
        Ok(ForecastIntervals {
            level,
            z,
            lower: self.mean.zip_map(&self.sd, |m, s| m - z * s),
            upper: self.mean.zip_map(&self.sd, |m, s| m + z * s),
        })
    }
}

impl ForecastIntervals {
    /// The half-width in standard deviations of an interval of probability `level`:
    /// the normal quantile of `(1 + level) / 2`.
    ///
    /// # Errors
    /// [`KalmanError::BadOption`] unless `0 < level < 1`.
    pub fn half_width(level: f64) -> Result<f64> {
        use statrs::distribution::{ContinuousCDF, Normal};
        if !(level > 0.0 && level < 1.0) {
            return Err(KalmanError::BadOption {
                name: "level",
                message: format!("{level} is not a probability strictly between 0 and 1"),
            });
        }
        Ok(Normal::standard().inverse_cdf(0.5 + level / 2.0))
    }
}

/// Prediction intervals of a [`Forecast`] (see [`Forecast::intervals`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ForecastIntervals {
    /// Their probability.
    pub level: f64,
    /// The normal quantile: the half-width in standard deviations.
    pub z: f64,
    /// Lower bounds (p x steps).
    pub lower: DMatrix<f64>,
    /// Upper bounds (p x steps).
    pub upper: DMatrix<f64>,
}

impl LinearGaussianModel {
    /// Forecasts `steps` outputs beyond the record, given the future inputs
    /// (`m x steps`; `0 x steps` for a model without inputs): the filter's last
    /// predicted state `x_{T+1|T}` run forward without data, as statsmodels'
    /// `get_forecast`.
    ///
    /// # Errors
    /// Those of the filter; [`KalmanError::Dimension`] when `future_inputs` is not
    /// `m x steps`; [`KalmanError::SimulationDiverges`] if the forecast overflows.
    pub fn forecast(
        &self,
        record: &Record,
        future_inputs: &DMatrix<f64>,
        steps: usize,
    ) -> Result<Forecast> {
        let (m, p) = (self.m(), self.p());
        if future_inputs.nrows() != m || future_inputs.ncols() != steps {
            return Err(KalmanError::Dimension {
                name: "future inputs".into(),
                expected_rows: m,
                expected_cols: steps,
                rows: future_inputs.nrows(),
                cols: future_inputs.ncols(),
            });
        }
        if let Some((j, _)) = future_inputs
            .iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite())
        {
            return Err(KalmanError::NonFiniteData {
                record: 0,
                time: record.len() + j / m.max(1) + 1,
                what: "input",
                index: j % m.max(1) + 1,
                value: future_inputs[j],
            });
        }
        let mut ws = KalmanWorkspace::new();
        let f = ws.filter(self, record)?;
        let t_len = record.len();
        let mut x: DVector<f64> = f.predicted_mean(t_len);
        let mut cov = f.predicted_covariance(t_len);
        let mut out = Forecast {
            mean: DMatrix::zeros(p, steps),
            sd: DMatrix::zeros(p, steps),
            covariances: Vec::with_capacity(steps),
        };
        for j in 0..steps {
            let u = future_inputs.column(j);
            let mean = self.c() * &x + self.d() * u + self.h();
            let mut out_cov = self.c() * &cov * self.c().transpose() + self.r();
            sysid_linalg::symmetrize(&mut out_cov);
            if !mean.iter().chain(out_cov.iter()).all(|v| v.is_finite()) {
                return Err(KalmanError::SimulationDiverges {
                    time: t_len + j + 1,
                });
            }
            out.mean.set_column(j, &mean);
            for i in 0..p {
                out.sd[(i, j)] = out_cov[(i, i)].max(0.0).sqrt();
            }
            out.covariances.push(out_cov);
            x = self.a() * &x + self.b() * u;
            cov = self.a() * &cov * self.a().transpose() + self.q();
            sysid_linalg::symmetrize(&mut cov);
        }
        Ok(out)
    }
}
