//! Convergence diagnostics and posterior summaries.
//!
//! # Algorithm
//! - **Effective sample size** of one chain: Geyer's initial monotone sequence
//!   estimator, `ESS = n / (-1 + 2 sum_k Gamma_k)` where `Gamma_k = rho_{2k} +
//!   rho_{2k+1}` are summed while positive and forced non-increasing (Geyer 1992).
//!   Across chains the ESS is the sum of the chains' values.
//! - **R-hat**: the split potential scale reduction factor (Gelman et al., *Bayesian
//!   Data Analysis*, 3rd ed., 11.4): each chain is cut in halves, and
//!   `R = sqrt(((n-1)/n W + B/n) / W)` over the halves. Values near 1 (below 1.01 to
//!   1.05) say the chains agree.
//! - **Monte Carlo standard error** of a posterior mean: `sd / sqrt(ESS)`.
//!
//! # Complexity
//! O(n L) per chain for the ESS, `L` the number of lags summed.
//!
//! # References
//! Geyer (1992), *Practical Markov chain Monte Carlo*; Gelman et al. (2013); Vehtari,
//! Gelman, Simpson, Carpenter and Bürkner (2021).

use crate::Chain;

/// The effective sample size of one chain's draws (Geyer's initial monotone sequence).
/// A constant chain gives `n` (nothing to estimate); fewer than 4 draws give `n`.
pub fn effective_sample_size(draws: &[f64]) -> f64 {
    let n = draws.len();
    if n < 4 {
        return n as f64;
    }
    let mean = draws.iter().sum::<f64>() / n as f64;
    let centred: Vec<f64> = draws.iter().map(|x| x - mean).collect();
    let autocovariance = |lag: usize| -> f64 {
        centred[..n - lag]
            .iter()
            .zip(&centred[lag..])
            .map(|(a, b)| a * b)
            .sum::<f64>()
            / n as f64
    };
    let c0 = autocovariance(0);
    if c0 <= 0.0 {
        return n as f64;
    }
    let mut sum = 0.0;
    let mut previous_pair = f64::INFINITY;
    let mut lag = 0;
    while lag + 1 < n {
        let pair = (autocovariance(lag) + autocovariance(lag + 1)) / c0;
        if pair <= 0.0 {
            break;
        }
        let pair = pair.min(previous_pair);
        sum += pair;
        previous_pair = pair;
        lag += 2;
    }
    let tau = (-1.0 + 2.0 * sum).max(1.0 / n as f64);
    n as f64 / tau
}

/// The split R-hat of several chains' draws of one parameter (each at least 4 long;
/// the halves use the common length).
pub fn split_rhat(chains: &[Vec<f64>]) -> f64 {
    let half = chains.iter().map(|c| c.len() / 2).min().unwrap_or(0);
    if half < 2 {
        return f64::NAN;
    }
    let halves: Vec<&[f64]> = chains
        .iter()
        .flat_map(|c| [&c[..half], &c[c.len() - half..]])
        .collect();
    let n = half as f64;
    let m = halves.len() as f64;
    let means: Vec<f64> = halves.iter().map(|h| h.iter().sum::<f64>() / n).collect();
    let grand = means.iter().sum::<f64>() / m;
    let between = n / (m - 1.0) * means.iter().map(|x| (x - grand).powi(2)).sum::<f64>();
    let within = halves
        .iter()
        .zip(&means)
        .map(|(h, mu)| h.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / (n - 1.0))
        .sum::<f64>()
        / m;
    if within == 0.0 {
        return if between == 0.0 { 1.0 } else { f64::INFINITY };
    }
    (((n - 1.0) / n * within + between / n) / within).sqrt()
}

/// A posterior summary of one parameter over several chains (burn-in dropped).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ParameterSummary {
    /// Parameter name.
    pub name: String,
    /// Posterior mean.
    pub mean: f64,
    /// Posterior standard deviation.
    pub sd: f64,
    /// Monte Carlo standard error of the mean, `sd / sqrt(ess)`.
    pub mcse: f64,
    /// Effective sample size, summed over chains.
    pub ess: f64,
    /// Split R-hat across chains.
    pub rhat: f64,
    /// 5 % quantile.
    pub q05: f64,
    /// Median.
    pub q50: f64,
    /// 95 % quantile.
    pub q95: f64,
}

/// Summaries of every parameter of `chains` (which share names and burn-in); NaN
/// where the chains have no draws after the burn-in (stopped early).
pub fn summarise(chains: &[Chain]) -> Vec<ParameterSummary> {
    let Some(first) = chains.first() else {
        return Vec::new();
    };
    (0..first.dim())
        .map(|k| {
            let draws: Vec<Vec<f64>> = chains.iter().map(|c| c.parameter(k)).collect();
            let mut pooled: Vec<f64> = draws.iter().flatten().copied().collect();
            let count = pooled.len() as f64;
            let mean = pooled.iter().sum::<f64>() / count;
            let sd = (pooled.iter().map(|x| (x - mean).powi(2)).sum::<f64>()
                / (count - 1.0).max(1.0))
            .sqrt();
            let ess: f64 = draws.iter().map(|d| effective_sample_size(d)).sum();
            pooled.sort_by(f64::total_cmp);
            let quantile = |p: f64| {
                // no draws (a chain stopped during its burn-in): nothing to report
                if pooled.is_empty() {
                    return f64::NAN;
                }
                let position = p * (count - 1.0);
                let (lo, frac) = (position.floor() as usize, position.fract());
                let hi = (lo + 1).min(pooled.len() - 1);
                pooled[lo] * (1.0 - frac) + pooled[hi] * frac
            };
            ParameterSummary {
                name: first.names[k].clone(),
                mean,
                sd,
                mcse: sd / ess.sqrt(),
                ess,
                rhat: split_rhat(&draws),
                q05: quantile(0.05),
                q50: quantile(0.5),
                q95: quantile(0.95),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_distr::{Distribution, StandardNormal};

    /// An AR(1) chain with coefficient `phi` has integrated autocorrelation time
    /// `(1 + phi) / (1 - phi)`.
    fn ar1(phi: f64, n: usize, seed: u64) -> Vec<f64> {
        let mut rng = sysid_smc::stream(seed, 0);
        let mut x = 0.0;
        (0..n)
            .map(|_| {
                let e: f64 = StandardNormal.sample(&mut rng);
                x = phi * x + e;
                x
            })
            .collect()
    }

    /// A chain stopped during its burn-in has no draws to summarise: NaN, not a panic.
    #[test]
    fn summaries_of_chains_without_draws_are_nan() {
        let chain = Chain {
            names: vec!["a".into()],
            burn_in: 10,
            samples: vec![0.5; 3],
            log_likelihood: vec![-1.0; 3],
            log_prior: vec![0.0; 3],
            accepted: vec![true; 3],
            state_update_rate: None,
            state_mean: None,
            interrupted: true,
        };
        let s = summarise(&[chain.clone(), chain]);
        assert!(s[0].mean.is_nan() && s[0].q05.is_nan() && s[0].q95.is_nan());
    }

    #[test]
    fn ess_of_an_ar1_chain_matches_its_autocorrelation_time() {
        let n = 100_000;
        for phi in [0.0, 0.5, 0.9] {
            let expected = n as f64 * (1.0 - phi) / (1.0 + phi);
            let ess = effective_sample_size(&ar1(phi, n, 3));
            // the estimator's relative error is a few percent at this length
            assert!(
                (ess / expected - 1.0).abs() < 0.1,
                "phi {phi}: {ess} vs {expected}"
            );
        }
    }

    #[test]
    fn rhat_is_near_one_for_agreeing_chains_and_large_for_disagreeing_ones() {
        let a = ar1(0.5, 10_000, 1);
        let b = ar1(0.5, 10_000, 2);
        assert!((split_rhat(&[a.clone(), b.clone()]) - 1.0).abs() < 0.01);
        let shifted: Vec<f64> = b.iter().map(|x| x + 3.0).collect();
        assert!(split_rhat(&[a, shifted]) > 1.5);
    }
}
