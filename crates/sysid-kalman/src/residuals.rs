//! Residual tests: sample autocorrelation, cross-correlation with the inputs, and the
//! Ljung-Box portmanteau statistic.

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
