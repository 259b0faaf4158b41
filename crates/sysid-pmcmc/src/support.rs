//! Where a parameter lives, and the map to the real line the random walks use.
//!
//! # Model
//! | support | unconstrained `z` | inverse | `log |d theta / d z|` |
//! | --- | --- | --- | --- |
//! | `Real` | `theta` | `z` | 0 |
//! | `Positive` | `ln theta` | `e^z` | `z` |
//! | `Interval(a, b)` | `logit((theta - a) / (b - a))` | `a + (b - a) s(z)` | `ln(b - a) + ln s(z) + ln(1 - s(z))` |
//!
//! with `s` the logistic function. A random walk on `z` targets the posterior of `z`,
//! which is the posterior of `theta` times the Jacobian.

use serde::{Deserialize, Serialize};

/// The support of one parameter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Support {
    /// The whole real line.
    Real,
    /// `(0, inf)`.
    Positive,
    /// The open interval `(low, high)`.
    Interval(f64, f64),
}

impl Support {
    /// Whether `theta` is inside the support.
    pub fn contains(self, theta: f64) -> bool {
        match self {
            Support::Real => theta.is_finite(),
            Support::Positive => theta > 0.0 && theta.is_finite(),
            Support::Interval(a, b) => theta > a && theta < b,
        }
    }

    /// The unconstrained coordinate of `theta` (which must be inside the support).
    pub fn to_unconstrained(self, theta: f64) -> f64 {
        match self {
            Support::Real => theta,
            Support::Positive => theta.ln(),
            Support::Interval(a, b) => {
                let s = (theta - a) / (b - a);
                (s / (1.0 - s)).ln()
            }
        }
    }

    /// `theta` of an unconstrained coordinate, and `log |d theta / d z|`.
    pub fn from_unconstrained(self, z: f64) -> (f64, f64) {
        match self {
            Support::Real => (z, 0.0),
            Support::Positive => (z.exp(), z),
            Support::Interval(a, b) => {
                // ln s = -ln(1 + e^-z), ln(1 - s) = -ln(1 + e^z), computed stably
                let ln_s = -softplus(-z);
                let ln_1ms = -softplus(z);
                (a + (b - a) * ln_s.exp(), (b - a).ln() + ln_s + ln_1ms)
            }
        }
    }
}

/// `ln(1 + e^x)` without overflow.
fn softplus(x: f64) -> f64 {
    if x > 0.0 {
        x + (-x).exp().ln_1p()
    } else {
        x.exp().ln_1p()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_jacobians_match_finite_differences() {
        for (support, theta) in [
            (Support::Real, -1.3),
            (Support::Positive, 0.37),
            (Support::Interval(-1.0, 1.0), 0.9),
            (Support::Interval(2.0, 5.0), 2.1),
        ] {
            let z = support.to_unconstrained(theta);
            let (back, log_jac) = support.from_unconstrained(z);
            assert!((back - theta).abs() < 1e-12, "{support:?}");
            let h = 1e-6;
            let derivative = (support.from_unconstrained(z + h).0
                - support.from_unconstrained(z - h).0)
                / (2.0 * h);
            assert!((derivative.ln() - log_jac).abs() < 1e-6, "{support:?}");
        }
        assert!(!Support::Positive.contains(0.0));
        assert!(!Support::Interval(0.0, 1.0).contains(1.0));
        // far in the tails the interval map stays finite
        let (theta, log_jac) = Support::Interval(0.0, 1.0).from_unconstrained(800.0);
        assert!(theta <= 1.0 && log_jac.is_finite());
    }
}
