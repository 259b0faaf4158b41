//! The standard normal restricted to an interval: its log-probability and exact
//! draws, accurate far into the tails.
//!
//! # Algorithm
//! `ln P(alpha <= Z <= beta)` is taken from the upper tail `Q(x) = erfc(x / sqrt 2) / 2`
//! on the side away from the mode (so a tail interval does not cancel
//! `Phi(beta) - Phi(alpha)` in floating point), with the asymptotic series of `ln Q`
//! beyond `x = 30`, where `erfc` underflows. Draws are exact rejection samplers:
//! - an interval containing 0 and at least 2 wide: normal draws until one falls in
//!   (acceptance at least 0.47);
//! - a narrower one containing 0: a uniform proposal, accepted with probability
//!   `exp(-z^2 / 2)`;
//! - an interval in a tail, `0 <= alpha`: Robert's (1995) translated exponential
//!   proposal with rate `(alpha + sqrt(alpha^2 + 4)) / 2` when the interval is at
//!   least one mean step of it wide, else the uniform proposal accepted with
//!   probability `exp((alpha^2 - z^2) / 2)` (at least `e^{-3/2}`). The lower tail
//!   is the mirror image.
//!
//! # Complexity
//! O(1) per probability; a bounded expected number of uniform pairs per draw.
//!
//! # References
//! Robert (1995), *Simulation of truncated normal variables*, Statistics and
//! Computing 5; Abramowitz and Stegun 7.1.23 (the asymptotic series).

use rand::{Rng, RngExt};
use statrs::function::erf::erfc;

const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_7;

/// `ln Q(x)`, `Q(x) = P(Z > x)` for a standard normal `Z`.
pub(crate) fn ln_upper_tail(x: f64) -> f64 {
    if x == f64::INFINITY {
        return f64::NEG_INFINITY;
    }
    if x < 30.0 {
        return (0.5 * erfc(x * std::f64::consts::FRAC_1_SQRT_2)).ln();
    }
    // ln Q(x) = -x^2/2 - ln(x sqrt(2 pi)) + ln(1 - 1/x^2 + 3/x^4 - 15/x^6 + 105/x^8)
    let v = 1.0 / (x * x);
    let series = 1.0 - v * (1.0 - v * (3.0 - v * (15.0 - 105.0 * v)));
    -0.5 * x * x - x.ln() - LN_SQRT_2PI + series.ln()
}

/// `ln(1 - e^d)` for `d <= 0`, accurate for `d` near 0 and far below it.
fn ln_one_minus_exp(d: f64) -> f64 {
    if d > -std::f64::consts::LN_2 {
        (-d.exp_m1()).ln()
    } else {
        (-d.exp()).ln_1p()
    }
}

/// `ln P(alpha <= Z <= beta)` for a standard normal `Z` (`alpha <= beta`, either may
/// be infinite); `-inf` for an empty interval.
pub(crate) fn ln_interval_probability(alpha: f64, beta: f64) -> f64 {
    if alpha.partial_cmp(&beta) != Some(std::cmp::Ordering::Less) {
        return f64::NEG_INFINITY;
    }
    if alpha >= 0.0 {
        let (upper_a, upper_b) = (ln_upper_tail(alpha), ln_upper_tail(beta));
        if upper_a == f64::NEG_INFINITY {
            // beyond about 1e154 standard deviations: no mass in floating point
            return f64::NEG_INFINITY;
        }
        upper_a + ln_one_minus_exp(upper_b - upper_a)
    } else if beta <= 0.0 {
        ln_interval_probability(-beta, -alpha)
    } else {
        // 1 - P(Z < alpha) - P(Z > beta), both tails below one half
        (-(ln_upper_tail(-alpha).exp() + ln_upper_tail(beta).exp())).ln_1p()
    }
}

/// A uniform draw in `(0, 1]` (safe under a logarithm).
fn open_uniform<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    1.0 - rng.random::<f64>()
}

/// A draw of `Z` given `alpha <= Z <= beta` (`alpha < beta`, either may be infinite).
pub(crate) fn sample_interval<R: Rng + ?Sized>(alpha: f64, beta: f64, rng: &mut R) -> f64 {
    if alpha >= 0.0 {
        sample_upper(alpha, beta, rng)
    } else if beta <= 0.0 {
        -sample_upper(-beta, -alpha, rng)
    } else if beta - alpha >= 2.0 {
        loop {
            let z: f64 = rng.sample(rand_distr::StandardNormal);
            if alpha <= z && z <= beta {
                return z;
            }
        }
    } else {
        sample_uniform_proposal(alpha, beta, 0.0, rng)
    }
}

/// A draw of `Z` given `alpha <= Z <= beta` (both finite) by a uniform proposal,
/// accepted with probability `exp((mode^2 - z^2) / 2)`, where `mode` is the point of
/// the interval nearest 0 (the density's largest value there).
fn sample_uniform_proposal<R: Rng + ?Sized>(alpha: f64, beta: f64, mode: f64, rng: &mut R) -> f64 {
    loop {
        let z = alpha + (beta - alpha) * rng.random::<f64>();
        if open_uniform(rng).ln() <= 0.5 * (mode - z) * (mode + z) {
            return z;
        }
    }
}

/// A draw of `Z` given `0 <= alpha <= Z <= beta`.
fn sample_upper<R: Rng + ?Sized>(alpha: f64, beta: f64, rng: &mut R) -> f64 {
    let rate = 0.5 * (alpha + (alpha * alpha + 4.0).sqrt());
    if beta - alpha >= 1.0 / rate {
        loop {
            let z = alpha - open_uniform(rng).ln() / rate;
            let accept = open_uniform(rng).ln() <= -0.5 * (z - rate) * (z - rate);
            if z <= beta && accept {
                return z;
            }
        }
    } else {
        sample_uniform_proposal(alpha, beta, alpha, rng)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `ln P(alpha <= Z <= beta)` by Simpson's rule on 20 000 panels of the density
    /// relative to its largest value on the interval (finite intervals only).
    fn simpson(alpha: f64, beta: f64) -> f64 {
        let peak = if alpha > 0.0 {
            alpha
        } else if beta < 0.0 {
            beta
        } else {
            0.0
        };
        let f = |z: f64| (-0.5 * (z * z - peak * peak)).exp();
        let n = 20_000;
        let h = (beta - alpha) / n as f64;
        let mut sum = f(alpha) + f(beta);
        for k in 1..n {
            sum += f(alpha + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
        }
        (sum * h / 3.0).ln() - 0.5 * peak * peak - LN_SQRT_2PI
    }

    #[test]
    fn interval_probabilities_match_quadrature_from_the_centre_to_far_tails() {
        for &(a, b) in &[
            (-1.0, 1.0),
            (-0.3, 0.2),
            (0.5, 3.0),
            (-4.0, -3.9),
            (5.0, 9.0),
            (29.0, 31.0),
            (40.0, 40.5),
            (-60.0, -52.0),
        ] {
            let exact = ln_interval_probability(a, b);
            let reference = simpson(a, b);
            assert!(
                (exact - reference).abs() < 1e-9 * reference.abs().max(1.0),
                "[{a}, {b}]: {exact} against {reference}"
            );
        }
    }

    #[test]
    fn half_lines_and_the_whole_line() {
        assert!(ln_interval_probability(f64::NEG_INFINITY, f64::INFINITY).abs() < 1e-15);
        assert!((ln_interval_probability(0.0, f64::INFINITY) - 0.5f64.ln()).abs() < 1e-15);
        assert!((ln_interval_probability(f64::NEG_INFINITY, 0.0) - 0.5f64.ln()).abs() < 1e-15);
        // Q(1.959963984540054) = 0.025; statrs 0.19's erfc is good to about 1e-10
        // relative (checked against scipy 1.17.1's norm.logsf)
        let q = ln_interval_probability(1.959_963_984_540_054, f64::INFINITY);
        assert!((q - 0.025f64.ln()).abs() < 1e-9, "{q}");
        // the series and erfc agree where both hold
        let (below, above) = (ln_upper_tail(30.0 - 1e-12), ln_upper_tail(30.0));
        assert!((below - above).abs() < 1e-9, "{below} {above}");
        assert_eq!(ln_interval_probability(2.0, 2.0), f64::NEG_INFINITY);
        // intervals too far out for x^2 are empty, not NaN
        assert_eq!(ln_interval_probability(1e200, 2e200), f64::NEG_INFINITY);
        assert_eq!(
            ln_interval_probability(-f64::INFINITY, -1e200),
            f64::NEG_INFINITY
        );
        assert_eq!(
            ln_interval_probability(f64::INFINITY, f64::INFINITY),
            f64::NEG_INFINITY
        );
    }

    /// Each sampler branch: the draws lie in the interval and their mean and
    /// variance match the truncated normal's (by quadrature) within 4 Monte Carlo
    /// standard errors.
    #[test]
    fn draws_have_the_truncated_moments() {
        let mut rng = sysid_smc::stream(11, 0);
        for &(a, b) in &[
            (-1.0, 2.5),   // normal proposal
            (-0.4, 0.9),   // uniform around the mode
            (0.5, 4.0),    // exponential proposal
            (3.0, 3.2),    // uniform in the tail
            (-7.0, -6.0),  // mirrored exponential
            (12.0, 1e300), // far tail
        ] {
            let n = 40_000;
            let draws: Vec<f64> = (0..n).map(|_| sample_interval(a, b, &mut rng)).collect();
            assert!(draws.iter().all(|&z| a <= z && z <= b));
            let mean = draws.iter().sum::<f64>() / n as f64;
            let var = draws.iter().map(|z| (z - mean).powi(2)).sum::<f64>() / n as f64;
            // moments by quadrature on [a, min(b, a + 40)]
            let hi = b.min(a + 40.0);
            let steps = 40_000;
            let h = (hi - a) / steps as f64;
            let peak = if a > 0.0 {
                a
            } else if hi < 0.0 {
                hi
            } else {
                0.0
            };
            let (mut m0, mut m1, mut m2) = (0.0, 0.0, 0.0);
            for k in 0..steps {
                let z = a + (k as f64 + 0.5) * h;
                let w = (-0.5 * (z * z - peak * peak)).exp();
                m0 += w;
                m1 += w * z;
                m2 += w * z * z;
            }
            let (true_mean, true_var) = (m1 / m0, m2 / m0 - (m1 / m0).powi(2));
            let se_mean = (true_var / n as f64).sqrt();
            let se_var = true_var * (2.0 / n as f64).sqrt() * 1.5;
            assert!(
                (mean - true_mean).abs() < 4.0 * se_mean,
                "[{a}, {b}] mean {mean} vs {true_mean}"
            );
            assert!(
                (var - true_var).abs() < 4.0 * se_var,
                "[{a}, {b}] var {var} vs {true_var}"
            );
        }
    }
}
