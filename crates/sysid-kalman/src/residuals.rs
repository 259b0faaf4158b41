//! Residual tests: sample autocorrelation, cross-correlation with the inputs, and the
//! Ljung-Box portmanteau statistic.

use crate::{KalmanError, LinearGaussianModel, Predictions, Record, Result};
use nalgebra::DMatrix;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// The sample autocorrelation `r_k`, `k = 0..=max_lag`, of `x` with its mean removed:
/// `r_k = sum_t (x_t - m)(x_{t+k} - m) / sum_t (x_t - m)^2` (statsmodels' `acf`
/// default, MATLAB `resid`). Lags at or beyond `x.len()` are 0. A constant series
/// gives `r_0 = 1` and zeros.
pub fn autocorrelation(x: &[f64], max_lag: usize) -> Vec<f64> {
    let n = x.len();
    let mean = x.iter().sum::<f64>() / n.max(1) as f64;
    let centred: Vec<f64> = x.iter().map(|v| v - mean).collect();
    let var: f64 = centred.iter().map(|v| v * v).sum();
    (0..=max_lag)
        .map(|k| {
            if k == 0 {
                return 1.0;
            }
            if k >= n || var == 0.0 {
                return 0.0;
            }
            centred[..n - k]
                .iter()
                .zip(&centred[k..])
                .map(|(a, b)| a * b)
                .sum::<f64>()
                / var
        })
        .collect()
}

/// The sample cross-correlation of `e` with an earlier `u`, for lags
/// `k = -max_lag..=max_lag` (index `k + max_lag`): `sum_t (e_t - m_e)(u_{t-k} - m_u)`
/// over `sqrt(sum (e - m_e)^2 sum (u - m_u)^2)`. Positive lags are the output error's
/// dependence on past inputs, the test of a model's input dynamics (MATLAB `resid`).
pub fn cross_correlation(e: &[f64], u: &[f64], max_lag: usize) -> Vec<f64> {
    let n = e.len().min(u.len());
    let centre = |x: &[f64]| {
        let mean = x[..n].iter().sum::<f64>() / n.max(1) as f64;
        x[..n].iter().map(|v| v - mean).collect::<Vec<f64>>()
    };
    let (e, u) = (centre(e), centre(u));
    let norm = (e.iter().map(|v| v * v).sum::<f64>() * u.iter().map(|v| v * v).sum::<f64>()).sqrt();
    (0..=2 * max_lag)
        .map(|i| {
            let k = i as isize - max_lag as isize;
            if norm == 0.0 || k.unsigned_abs() >= n {
                return 0.0;
            }
            let sum: f64 = (0..n)
                .filter_map(|t| {
                    let s = t as isize - k;
                    (0..n as isize).contains(&s).then(|| e[t] * u[s as usize])
                })
                .sum();
            sum / norm
        })
        .collect()
}

/// The Ljung-Box test that `x` is white up to lag `lags`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LjungBox {
    /// `Q = n (n + 2) sum_{k=1..h} r_k^2 / (n - k)`.
    pub statistic: f64,
    /// Degrees of freedom of its chi-square law: `h - fitted` (at least 1).
    pub df: usize,
    /// `P(chi2_df > Q)`: small values say the residuals are correlated.
    pub p_value: f64,
    /// The number of lags `h`.
    pub lags: usize,
}

/// The Ljung-Box statistic of `x` over `lags` lags, its p-value against a chi-square
/// law with `lags - fitted` degrees of freedom (statsmodels' `acorr_ljungbox` with
/// `model_df = fitted`; `fitted = 0` for the residuals of a state-space model, as
/// statsmodels' `test_serial_correlation` uses). `None` when `lags` is 0 or not below
/// the series' length.
pub fn ljung_box(x: &[f64], lags: usize, fitted: usize) -> Option<LjungBox> {
    let n = x.len();
    if lags == 0 || lags >= n {
        return None;
    }
    let r = autocorrelation(x, lags);
    let nf = n as f64;
    let statistic = nf
        * (nf + 2.0)
        * (1..=lags)
            .map(|k| r[k] * r[k] / (nf - k as f64))
            .sum::<f64>();
    let df = lags.saturating_sub(fitted).max(1);
    let p_value = ChiSquared::new(df as f64).map_or(f64::NAN, |chi| chi.sf(statistic));
    Some(LjungBox {
        statistic,
        df,
        p_value,
        lags,
    })
}

/// The tests of one output's one-step prediction errors (see [`ResidualTests`]).
#[derive(Debug, Clone, PartialEq)]
pub struct OutputResiduals {
    /// The output (0-based).
    pub output: usize,
    /// The steps tested: where the output is observed and its prediction determined.
    pub samples: usize,
    /// Autocorrelation of the standardised errors, lags `0..=lags`.
    pub acf: Vec<f64>,
    /// Per input, the cross-correlation of the errors with the earlier input, lags
    /// `-lags..=lags` (index `k + lags`).
    pub ccf: Vec<Vec<f64>>,
    /// The Ljung-Box test over `lags` lags.
    pub ljung_box: LjungBox,
}

impl OutputResiduals {
    /// The 95 % bound of a white series' correlations, `1.96 / sqrt(samples)`.
    pub fn bound_95(&self) -> f64 {
        1.96 / (self.samples as f64).sqrt()
    }

    /// How many autocorrelations at lags `1..=lags` lie beyond [`Self::bound_95`].
    pub fn acf_beyond_bound(&self) -> usize {
        let bound = self.bound_95();
        self.acf[1..].iter().filter(|r| r.abs() > bound).count()
    }

    /// Per input, how many cross-correlations lie beyond [`Self::bound_95`].
    pub fn ccf_beyond_bound(&self) -> Vec<usize> {
        let bound = self.bound_95();
        self.ccf
            .iter()
            .map(|r| r.iter().filter(|v| v.abs() > bound).count())
            .collect()
    }
}

/// Are a model's one-step prediction errors white and independent of the inputs?
/// Per output, the autocorrelation of the standardised innovations, their
/// cross-correlation with each input, and the Ljung-Box test (MATLAB's `resid`,
/// statsmodels' `test_serial_correlation`).
#[derive(Debug, Clone, PartialEq)]
pub struct ResidualTests {
    /// The lags tested.
    pub lags: usize,
    /// One entry per output.
    pub outputs: Vec<OutputResiduals>,
}

impl ResidualTests {
    /// The tests of one-step predictions (`predictions.horizon == 1`) of `record`, over
    /// `lags` lags, on the steps where an output is observed and its prediction
    /// determined.
    ///
    /// # Errors
    /// [`KalmanError::TooManyLags`] when `lags` is 0 or not below an output's usable
    /// residuals; [`KalmanError::Dimension`] when the predictions are not of `record`.
    pub fn of(predictions: &Predictions, record: &Record, lags: usize) -> Result<Self> {
        let (p, t_len) = predictions.standardised.shape();
        if t_len != record.len() || p != record.y.nrows() {
            return Err(KalmanError::Dimension {
                name: "predictions".into(),
                expected_rows: record.y.nrows(),
                expected_cols: record.len(),
                rows: p,
                cols: t_len,
            });
        }
        let mut standardised = predictions.standardised.clone();
        for (z, sd) in standardised.iter_mut().zip(predictions.sd.iter()) {
            if !sd.is_finite() {
                *z = f64::NAN;
            }
        }
        ResidualTests::of_standardised(&standardised, &record.u, lags)
    }

    /// The tests of standardised one-step prediction errors (`p x T`; a non-finite
    /// entry is a step without a usable error) against the inputs (`m x T`), over
    /// `lags` lags: for predictors other than the Kalman filter (a particle filter's).
    ///
    /// # Errors
    /// [`KalmanError::TooManyLags`] when `lags` is 0 or not below an output's usable
    /// errors; [`KalmanError::Dimension`] when the inputs have another length.
    pub fn of_standardised(
        standardised: &DMatrix<f64>,
        inputs: &DMatrix<f64>,
        lags: usize,
    ) -> Result<Self> {
        let (p, t_len) = standardised.shape();
        if inputs.ncols() != t_len {
            return Err(KalmanError::Dimension {
                name: "inputs".into(),
                expected_rows: inputs.nrows(),
                expected_cols: t_len,
                rows: inputs.nrows(),
                cols: inputs.ncols(),
            });
        }
        let mut outputs = Vec::with_capacity(p);
        for i in 0..p {
            let steps: Vec<usize> = (0..t_len)
                .filter(|&t| standardised[(i, t)].is_finite())
                .collect();
            let e: Vec<f64> = steps.iter().map(|&t| standardised[(i, t)]).collect();
            let ljung_box = ljung_box(&e, lags, 0).ok_or(KalmanError::TooManyLags {
                lags,
                usable: e.len(),
                output: i + 1,
            })?;
            let ccf = (0..inputs.nrows())
                .map(|j| {
                    let u: Vec<f64> = steps.iter().map(|&t| inputs[(j, t)]).collect();
                    cross_correlation(&e, &u, lags)
                })
                .collect();
            outputs.push(OutputResiduals {
                output: i,
                samples: e.len(),
                acf: autocorrelation(&e, lags),
                ccf,
                ljung_box,
            });
        }
        Ok(ResidualTests { lags, outputs })
    }

    /// What the tests say is wrong with the model: correlated errors (Ljung-Box
    /// p < 0.05), or errors correlated with an input at more lags than chance allows.
    pub fn warnings(&self) -> Vec<ResidualWarning> {
        let mut warnings = Vec::new();
        // 5 % of the lags fall outside by chance: flag a count above the binomial mean
        // plus two standard deviations (about its 97.5 % quantile)
        let trials = (2 * self.lags + 1) as f64;
        let chance = 0.05 * trials + 2.0 * (0.05 * 0.95 * trials).sqrt() + 1.0;
        for o in &self.outputs {
            if o.ljung_box.p_value < 0.05 {
                warnings.push(ResidualWarning::Correlated {
                    output: o.output,
                    p_value: o.ljung_box.p_value,
                    lags: o.ljung_box.lags,
                });
            }
            for (input, &count) in o.ccf_beyond_bound().iter().enumerate() {
                if count as f64 > chance {
                    warnings.push(ResidualWarning::InputCorrelated {
                        output: o.output,
                        input,
                        count,
                        lags: 2 * self.lags + 1,
                    });
                }
            }
        }
        warnings
    }
}

impl LinearGaussianModel {
    /// The residual tests of this model's one-step predictions of `record`
    /// ([`ResidualTests::of`] on [`LinearGaussianModel::predict`] with horizon 1).
    ///
    /// # Errors
    /// Those of the filter and of [`ResidualTests::of`].
    pub fn residual_tests(&self, record: &Record, lags: usize) -> Result<ResidualTests> {
        ResidualTests::of(&self.predict(record, 1)?, record, lags)
    }
}

/// What a [`ResidualTests`] finds wrong with a model. Outputs and inputs are 0-based;
/// [`ResidualWarning::message`] names them.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum ResidualWarning {
    /// The output's errors are correlated: the model misses dynamics.
    Correlated {
        /// The output.
        output: usize,
        /// The Ljung-Box p-value.
        p_value: f64,
        /// Lags tested.
        lags: usize,
    },
    /// The output's errors are correlated with an earlier input.
    InputCorrelated {
        /// The output.
        output: usize,
        /// The input.
        input: usize,
        /// Lags beyond the 95 % bound.
        count: usize,
        /// Lags tested (`2 lags + 1`).
        lags: usize,
    },
}

impl ResidualWarning {
    /// The warning with the outputs and inputs called by these names (`y1`, `u1`, ...
    /// where a name is missing).
    pub fn message(&self, outputs: &[String], inputs: &[String]) -> String {
        self.message_advising(outputs, inputs, "try a higher order")
    }

    /// [`ResidualWarning::message`] with `advice` for correlated errors instead of a
    /// linear model's ("try a higher order"): a model file's is about its equations
    /// and its process noise.
    pub fn message_advising(&self, outputs: &[String], inputs: &[String], advice: &str) -> String {
        let name = |names: &[String], k: usize, prefix: char| {
            names
                .get(k)
                .cloned()
                .unwrap_or_else(|| format!("{prefix}{}", k + 1))
        };
        match self {
            ResidualWarning::Correlated {
                output,
                p_value,
                lags,
            } => format!(
                "the one-step errors of {} are correlated (Ljung-Box p = {p_value:.2e} over \
                 {lags} lags): the model misses dynamics of the data; {advice}",
                name(outputs, *output, 'y')
            ),
            ResidualWarning::InputCorrelated {
                output,
                input,
                count,
                lags,
            } => format!(
                "the one-step errors of {} are correlated with {} at {count} of {lags} lags \
                 beyond the 95 % bound: the model misses input dynamics",
                name(outputs, *output, 'y'),
                name(inputs, *input, 'u')
            ),
        }
    }
}

impl std::fmt::Display for ResidualWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message(&[], &[]))
    }
}

#[cfg(test)]
mod tests {
    use super::{autocorrelation, cross_correlation, ljung_box};

    fn series(n: usize) -> Vec<f64> {
        (0..n).map(|t| ((t * t) as f64 * 0.37).sin()).collect()
    }

    #[test]
    fn the_cross_correlation_of_a_series_with_itself_is_its_autocorrelation() {
        let x = series(80);
        let acf = autocorrelation(&x, 6);
        let ccf = cross_correlation(&x, &x, 6);
        for k in -6_isize..=6 {
            let got = ccf[(k + 6) as usize];
            let want = acf[k.unsigned_abs()];
            assert!((got - want).abs() < 1e-12, "lag {k}: {got} vs {want}");
        }
    }

    #[test]
    fn an_input_delayed_by_three_steps_peaks_at_lag_three() {
        let u = series(200);
        let e: Vec<f64> = (0..200)
            .map(|t| if t >= 3 { u[t - 3] } else { 0.0 })
            .collect();
        let ccf = cross_correlation(&e, &u, 5);
        let peak = (0..ccf.len())
            .max_by(|&a, &b| ccf[a].total_cmp(&ccf[b]))
            .unwrap();
        assert_eq!(peak as isize - 5, 3, "{ccf:?}");
        assert!(ccf[8] > 0.95);
    }

    #[test]
    fn ljung_box_refuses_lags_it_cannot_compute() {
        let x = series(10);
        assert!(ljung_box(&x, 0, 0).is_none());
        assert!(ljung_box(&x, 10, 0).is_none());
        let lb = ljung_box(&x, 3, 5).unwrap();
        assert_eq!(lb.df, 1, "at least one degree of freedom");
    }
}
