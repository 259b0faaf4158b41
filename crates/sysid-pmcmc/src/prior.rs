//! Prior distributions: a small trait and the common families.
//!
//! # Model
//! [`ScalarPrior`] gives `log p(theta_k)` for one parameter; [`IndependentPrior`]
//! multiplies them. Densities come from `statrs` (0.19). Families and their
//! parametrisations:
//!
//! | family | density | hyperparameters |
//! | --- | --- | --- |
//! | `normal` | `N(mean, sd^2)` | `mean`, `sd > 0` |
//! | `log_normal` | `ln theta ~ N(mu, sigma^2)` | `mu`, `sigma > 0` |
//! | `gamma` | `theta^(shape-1) e^(-rate theta)` | `shape > 0`, `rate > 0` |
//! | `inverse_gamma` | `theta^(-shape-1) e^(-scale / theta)` | `shape > 0`, `scale > 0` |
//! | `uniform` | flat on `(low, high)` | `low < high` |
//! | `beta` | `theta^(a-1) (1-theta)^(b-1)` | `a > 0`, `b > 0` |
//! | `flat` | improper, 1 everywhere | none |
//!
//! In a prior file (JSON) each entry reads like `{"family": "normal", "mean": 0,
//! "sd": 1}`.

use serde::{Deserialize, Serialize};
use statrs::distribution::{Beta, Continuous, Gamma, InverseGamma, LogNormal, Normal, Uniform};

use crate::{PmcmcError, Support};

/// A prior on the whole parameter vector.
///
/// # Example
/// A prior that makes two parameters exchangeable (`theta_0, theta_1` iid `N(0, 1)`)
/// and requires `theta_0 < theta_1` (an ordered pair):
/// ```
/// use sysid_pmcmc::Prior;
/// struct Ordered;
/// impl Prior for Ordered {
///     fn log_density(&self, theta: &[f64]) -> f64 {
///         if theta[0] < theta[1] {
///             -0.5 * (theta[0] * theta[0] + theta[1] * theta[1])
///         } else {
///             f64::NEG_INFINITY
///         }
///     }
/// }
/// assert_eq!(Ordered.log_density(&[1.0, 0.0]), f64::NEG_INFINITY);
/// ```
pub trait Prior: Sync {
    /// `log p(theta)`; `-inf` outside the support.
    fn log_density(&self, theta: &[f64]) -> f64;
}

/// A prior on one scalar parameter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "family", rename_all = "snake_case", deny_unknown_fields)]
pub enum ScalarPrior {
    /// `N(mean, sd^2)`.
    Normal {
        /// Mean.
        mean: f64,
        /// Standard deviation.
        sd: f64,
    },
    /// `ln theta ~ N(mu, sigma^2)`.
    LogNormal {
        /// Mean of `ln theta`.
        mu: f64,
        /// Standard deviation of `ln theta`.
        sigma: f64,
    },
    /// Gamma with shape and rate (mean `shape / rate`).
    Gamma {
        /// Shape.
        shape: f64,
        /// Rate.
        rate: f64,
    },
    /// Inverse gamma with shape and scale (mean `scale / (shape - 1)`).
    InverseGamma {
        /// Shape.
        shape: f64,
        /// Scale.
        scale: f64,
    },
    /// Uniform on `(low, high)`.
    Uniform {
        /// Lower end.
        low: f64,
        /// Upper end.
        high: f64,
    },
    /// Beta on `(0, 1)`.
    Beta {
        /// First shape.
        a: f64,
        /// Second shape.
        b: f64,
    },
    /// The improper flat prior.
    Flat,
}

impl ScalarPrior {
    /// Checks the hyperparameters; `parameter` names the parameter in the error.
    pub fn check(&self, parameter: &str) -> Result<(), PmcmcError> {
        let bad = |reason: String| PmcmcError::InvalidPrior {
            parameter: parameter.to_string(),
            reason,
        };
        let result = match *self {
            ScalarPrior::Normal { mean, sd } => {
                Normal::new(mean, sd).map(|_| ()).map_err(|e| e.to_string())
            }
            ScalarPrior::LogNormal { mu, sigma } => LogNormal::new(mu, sigma)
                .map(|_| ())
                .map_err(|e| e.to_string()),
            ScalarPrior::Gamma { shape, rate } => Gamma::new(shape, rate)
                .map(|_| ())
                .map_err(|e| e.to_string()),
            ScalarPrior::InverseGamma { shape, scale } => InverseGamma::new(shape, scale)
                .map(|_| ())
                .map_err(|e| e.to_string()),
            ScalarPrior::Uniform { low, high } => Uniform::new(low, high)
                .map(|_| ())
                .map_err(|e| e.to_string()),
            ScalarPrior::Beta { a, b } => Beta::new(a, b).map(|_| ()).map_err(|e| e.to_string()),
            ScalarPrior::Flat => Ok(()),
        };
        result.map_err(bad)
    }

    /// Where the density is positive.
    pub fn support(&self) -> Support {
        match *self {
            ScalarPrior::Normal { .. } | ScalarPrior::Flat => Support::Real,
            ScalarPrior::LogNormal { .. }
            | ScalarPrior::Gamma { .. }
            | ScalarPrior::InverseGamma { .. } => Support::Positive,
            ScalarPrior::Uniform { low, high } => Support::Interval(low, high),
            ScalarPrior::Beta { .. } => Support::Interval(0.0, 1.0),
        }
    }

    /// `log p(theta)`, `-inf` outside the support. Hyperparameters must have passed
    /// [`check`](Self::check); otherwise the value is NaN.
    pub fn log_density(&self, theta: f64) -> f64 {
        if !self.support().contains(theta) {
            return f64::NEG_INFINITY;
        }
        let value = match *self {
            ScalarPrior::Normal { mean, sd } => Normal::new(mean, sd).map(|d| d.ln_pdf(theta)).ok(),
            ScalarPrior::LogNormal { mu, sigma } => {
                LogNormal::new(mu, sigma).map(|d| d.ln_pdf(theta)).ok()
            }
            ScalarPrior::Gamma { shape, rate } => {
                Gamma::new(shape, rate).map(|d| d.ln_pdf(theta)).ok()
            }
            ScalarPrior::InverseGamma { shape, scale } => InverseGamma::new(shape, scale)
                .map(|d| d.ln_pdf(theta))
                .ok(),
            ScalarPrior::Uniform { low, high } => {
                Uniform::new(low, high).map(|d| d.ln_pdf(theta)).ok()
            }
            ScalarPrior::Beta { a, b } => Beta::new(a, b).map(|d| d.ln_pdf(theta)).ok(),
            ScalarPrior::Flat => Some(0.0),
        };
        value.unwrap_or(f64::NAN)
    }
}

/// Independent priors, one per parameter, in the family's parameter order.
#[derive(Debug, Clone, PartialEq)]
pub struct IndependentPrior {
    priors: Vec<ScalarPrior>,
}

impl IndependentPrior {
    /// Checks every prior (`names` label the errors; same length as `priors`).
    pub fn new(names: &[String], priors: Vec<ScalarPrior>) -> Result<Self, PmcmcError> {
        if names.len() != priors.len() {
            return Err(PmcmcError::DimensionMismatch {
                what: "priors",
                expected: names.len(),
                found: priors.len(),
            });
        }
        for (name, prior) in names.iter().zip(&priors) {
            prior.check(name)?;
        }
        Ok(IndependentPrior { priors })
    }

    /// The priors, in parameter order.
    pub fn priors(&self) -> &[ScalarPrior] {
        &self.priors
    }
}

impl Prior for IndependentPrior {
    fn log_density(&self, theta: &[f64]) -> f64 {
        self.priors
            .iter()
            .zip(theta)
            .map(|(p, &v)| p.log_density(v))
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LN_2PI: f64 = 1.837_877_066_409_345_5;

    #[test]
    fn log_densities_match_the_closed_forms() {
        let normal = ScalarPrior::Normal { mean: 1.0, sd: 2.0 };
        // (2 - 1)^2 / (2 * 2^2) = 0.125
        assert!((normal.log_density(2.0) - (-0.5 * LN_2PI - 2f64.ln() - 0.125)).abs() < 1e-12);
        // inverse gamma(shape 3, scale 2) at 0.5: 3 ln 2 - ln Gamma(3) - 4 ln 0.5 - 4
        let ig = ScalarPrior::InverseGamma {
            shape: 3.0,
            scale: 2.0,
        };
        let closed = 3.0 * 2f64.ln() - 2f64.ln() - 4.0 * 0.5f64.ln() - 4.0;
        assert!((ig.log_density(0.5) - closed).abs() < 1e-12);
        // gamma(shape 2, rate 3) at 0.5: 2 ln 3 - ln Gamma(2) + ln 0.5 - 1.5
        let g = ScalarPrior::Gamma {
            shape: 2.0,
            rate: 3.0,
        };
        assert!((g.log_density(0.5) - (2.0 * 3f64.ln() + 0.5f64.ln() - 1.5)).abs() < 1e-12);
        assert_eq!(g.log_density(-1.0), f64::NEG_INFINITY);
        let u = ScalarPrior::Uniform {
            low: -1.0,
            high: 1.0,
        };
        assert!((u.log_density(0.3) + 2f64.ln()).abs() < 1e-15);
        assert_eq!(u.log_density(1.5), f64::NEG_INFINITY);
    }

    #[test]
    fn bad_hyperparameters_name_the_parameter() {
        let names = vec!["q".to_string()];
        let err = IndependentPrior::new(
            &names,
            vec![ScalarPrior::Gamma {
                shape: -1.0,
                rate: 1.0,
            }],
        )
        .unwrap_err();
        assert!(err.to_string().contains("prior of `q`"), "{err}");
        let err = IndependentPrior::new(&names, vec![]).unwrap_err();
        assert!(matches!(err, PmcmcError::DimensionMismatch { .. }));
    }

    #[test]
    fn priors_read_from_json() {
        let p: ScalarPrior =
            serde_json::from_str(r#"{"family": "inverse_gamma", "shape": 2, "scale": 0.1}"#)
                .unwrap();
        assert_eq!(
            p,
            ScalarPrior::InverseGamma {
                shape: 2.0,
                scale: 0.1
            }
        );
        assert!(serde_json::from_str::<ScalarPrior>(r#"{"family": "normal", "mean": 0}"#).is_err());
    }
}
