//! How well a model reproduces a record: its noise-free simulation or its k-step
//! predictions, scored by the fit per output (MATLAB's `compare`).

use crate::{KalmanError, LinearGaussianModel, Record, Result, fit_percent};
use nalgebra::DMatrix;
use std::fmt;
use std::str::FromStr;

/// What a model is asked to reproduce of a record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Horizon {
    /// The noise-free simulation of the inputs from the initial state that fits the
    /// record best ([`LinearGaussianModel::response`]); `inf` in text.
    Simulation,
    /// `k`-step-ahead predictions (`k >= 1`, [`LinearGaussianModel::predict`]).
    Steps(usize),
}

impl FromStr for Horizon {
    type Err = KalmanError;

    /// `inf` (also `Inf`, `infinity`) or a positive integer.
    fn from_str(text: &str) -> Result<Self> {
        let bad = |message: String| KalmanError::BadOption {
            name: "horizon",
            message,
        };
        match text.trim() {
            "inf" | "Inf" | "infinity" => Ok(Horizon::Simulation),
            other => match other.parse::<usize>() {
                Ok(0) => Err(bad("must be at least 1, or inf".into())),
                Ok(k) => Ok(Horizon::Steps(k)),
                Err(_) => Err(bad(format!(
                    "{other:?} is neither a positive integer nor inf"
                ))),
            },
        }
    }
}

impl fmt::Display for Horizon {
    /// What the outputs are: `simulation`, `one-step predictions`, `k-step predictions`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Horizon::Simulation => f.write_str("simulation"),
            Horizon::Steps(1) => f.write_str("one-step predictions"),
            Horizon::Steps(k) => write!(f, "{k}-step predictions"),
        }
    }
}

/// A model's reproduction of a record and its fit (see [`LinearGaussianModel::compare`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// What was reproduced.
    pub horizon: Horizon,
    /// Steps at the start not scored.
    pub burn_in: usize,
    /// The model's outputs (p x T), in the units of the scored record.
    pub outputs: DMatrix<f64>,
    /// The fit per output in percent ([`fit_percent`]) from step `burn_in + 1`.
    pub fit_percent: Vec<f64>,
}

impl Comparison {
    /// The mean of the outputs' fits.
    pub fn mean_fit_percent(&self) -> f64 {
        self.fit_percent.iter().sum::<f64>() / self.fit_percent.len().max(1) as f64
    }
}

impl LinearGaussianModel {
    /// Reproduces `record` (`horizon`) and scores the fit from step `burn_in + 1`. For
    /// a model fitted on detrended data, `trend` is the outputs' trend at the record's
    /// times (p x T): it is added back to the record and to the model's outputs, so the
    /// fit is in the data's units.
    ///
    /// # Errors
    /// [`KalmanError::BadOption`] when `burn_in` leaves no step to score, a horizon of
    /// 0, or a trend of the wrong shape; those of [`LinearGaussianModel::response`] and
    /// [`LinearGaussianModel::predict`].
    pub fn compare(
        &self,
        record: &Record,
        horizon: Horizon,
        burn_in: usize,
        trend: Option<&DMatrix<f64>>,
    ) -> Result<Comparison> {
        if record.len() <= burn_in {
            return Err(KalmanError::BadOption {
                name: "burn_in",
                message: format!(
                    "{burn_in} leaves no step of the record's {} to score",
                    record.len()
                ),
            });
        }
        if let Some(trend) = trend
            && trend.shape() != record.y.shape()
        {
            return Err(KalmanError::Dimension {
                name: "output trend".into(),
                expected_rows: record.y.nrows(),
                expected_cols: record.len(),
                rows: trend.nrows(),
                cols: trend.ncols(),
            });
        }
        let outputs = match horizon {
            Horizon::Simulation => self.response(record, None)?.outputs,
            Horizon::Steps(0) => {
                return Err(KalmanError::BadOption {
                    name: "horizon",
                    message: "must be at least 1, or inf".into(),
                });
            }
            Horizon::Steps(k) => self.predict(record, k)?.mean,
        };
        let (measured, outputs) = match trend {
            Some(trend) => (&record.y + trend, outputs + trend),
            None => (record.y.clone(), outputs),
        };
        Ok(Comparison {
            horizon,
            burn_in,
            fit_percent: fit_percent(&measured, &outputs, burn_in),
            outputs,
        })
    }
}
