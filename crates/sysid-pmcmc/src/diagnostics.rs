//! Convergence diagnostics and posterior summaries.
//!
//! # Algorithm
//! Vehtari, Gelman, Simpson, Carpenter and Bürkner (2021), as Stan and ArviZ compute
//! them:
//! - **Rank normalisation**: the draws of every chain, split in halves, are replaced by
//!   `Phi^{-1}((r - 3/8) / (S + 1/4))` of their pooled ranks `r` (ties averaged), `S`
//!   draws in all; heavy tails and differing scales then cannot hide a chain that
//!   disagrees.
//! - **R-hat**: the larger of the split R-hat of the rank-normalised draws and of the
//!   rank-normalised folded draws `|theta - median|` (which sees chains that differ in
//!   spread). The split R-hat of halves of length `n` is
//!   `sqrt(((n-1)/n W + B/n) / W)`. Below 1.01 says the chains agree.
//! - **Bulk ESS**: the multi-chain effective sample size of the rank-normalised split
//!   chains: autocorrelations `rho_t = 1 - (W - mean_j gamma_j(t)) / var_plus` combined
//!   over chains, summed in pairs while positive and forced non-increasing (Geyer's
//!   initial monotone sequence), `ESS = M N / tau`.
//! - **Tail ESS**: the smaller of the ESS of the indicators `theta <= q_05` and
//!   `theta <= q_95`: how well the 90 % interval's ends are known.
//! - **Monte Carlo standard error** of a posterior mean: `sd / sqrt(ESS)` with Geyer's
//!   per-chain ESS of the draws themselves ([`effective_sample_size`], summed over
//!   chains).
//!
//! Draws that never change (a stuck sampler) have no ESS or R-hat: NaN.
//!
//! # Complexity
//! O(S log S) for the ranks; O(S L) for an ESS, `L` the number of lags summed.
//!
//! # References
//! Geyer (1992), *Practical Markov chain Monte Carlo*; Gelman et al. (2013), *Bayesian
//! Data Analysis*, 3rd ed., 11.4-11.5; Vehtari, Gelman, Simpson, Carpenter and Bürkner
//! (2021), *Rank-normalization, folding, and localization: an improved R-hat for
//! assessing convergence of MCMC*, Bayesian Analysis 16(2).

use crate::Chain;
use statrs::distribution::{ContinuousCDF, Normal};

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

/// The chains cut in halves (the first and the last `n / 2` draws of each), all of the
/// common half length.
fn split_chains(chains: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let half = chains.iter().map(|c| c.len() / 2).min().unwrap_or(0);
    chains
        .iter()
        .flat_map(|c| [c[..half].to_vec(), c[c.len() - half..].to_vec()])
        .collect()
}

/// The draws replaced by the normal scores of their pooled ranks (ties get the average
/// rank): `Phi^{-1}((r - 3/8) / (S + 1/4))`.
fn rank_normalised(chains: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut order: Vec<(f64, usize, usize)> = chains
        .iter()
        .enumerate()
        .flat_map(|(j, c)| c.iter().enumerate().map(move |(i, &v)| (v, j, i)))
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total = order.len() as f64;
    let normal = Normal::standard();
    let mut out: Vec<Vec<f64>> = chains.iter().map(|c| vec![0.0; c.len()]).collect();
    let mut start = 0;
    while start < order.len() {
        let mut end = start + 1;
        while end < order.len() && order[end].0 == order[start].0 {
            end += 1;
        }
        // ranks are 1-based; a run of ties shares their average
        let rank = (start + 1 + end) as f64 / 2.0;
        let z = normal.inverse_cdf((rank - 0.375) / (total + 0.25));
        for &(_, j, i) in &order[start..end] {
            out[j][i] = z;
        }
        start = end;
    }
    out
}

/// The split R-hat of chains already split (the classic formula on their halves).
fn rhat_of_halves(halves: &[Vec<f64>]) -> f64 {
    let n = halves.iter().map(Vec::len).min().unwrap_or(0);
    let m = halves.len();
    if n < 2 || m < 2 {
        return f64::NAN;
    }
    let means: Vec<f64> = halves
        .iter()
        .map(|h| h[..n].iter().sum::<f64>() / n as f64)
        .collect();
    let grand = means.iter().sum::<f64>() / m as f64;
    let between =
        n as f64 * means.iter().map(|x| (x - grand).powi(2)).sum::<f64>() / (m - 1) as f64;
    let within = halves
        .iter()
        .zip(&means)
        .map(|(h, mu)| h[..n].iter().map(|x| (x - mu).powi(2)).sum::<f64>() / (n - 1) as f64)
        .sum::<f64>()
        / m as f64;
    ((between / within + n as f64 - 1.0) / n as f64).sqrt()
}

/// The rank-normalised split R-hat (Vehtari et al. 2021): the larger of the bulk and
/// the folded (tail) R-hat. NaN for fewer than 4 draws per chain or draws that never
/// change.
pub fn rank_rhat(chains: &[Vec<f64>]) -> f64 {
    if constant(chains) {
        return f64::NAN;
    }
    let bulk = rhat_of_halves(&rank_normalised(&split_chains(chains)));
    let mut pooled: Vec<f64> = chains.iter().flatten().copied().collect();
    pooled.sort_by(f64::total_cmp);
    let median = quantile_sorted(&pooled, 0.5);
    let folded: Vec<Vec<f64>> = chains
        .iter()
        .map(|c| c.iter().map(|x| (x - median).abs()).collect())
        .collect();
    let tail = rhat_of_halves(&rank_normalised(&split_chains(&folded)));
    bulk.max(tail)
}

/// The multi-chain effective sample size of chains of equal length (Stan's and
/// ArviZ's estimator: within- and between-chain variance, Geyer's initial monotone
/// sequence).
fn multi_chain_ess(chains: &[Vec<f64>]) -> f64 {
    let m = chains.len();
    let n = chains.iter().map(Vec::len).min().unwrap_or(0);
    if m == 0 || n < 4 {
        return f64::NAN;
    }
    let means: Vec<f64> = chains
        .iter()
        .map(|c| c[..n].iter().sum::<f64>() / n as f64)
        .collect();
    // the mean over chains of the (biased) autocovariance at `lag`
    let autocovariance = |lag: usize| -> f64 {
        chains
            .iter()
            .zip(&means)
            .map(|(c, mu)| {
                c[..n - lag]
                    .iter()
                    .zip(&c[lag..n])
                    .map(|(a, b)| (a - mu) * (b - mu))
                    .sum::<f64>()
                    / n as f64
            })
            .sum::<f64>()
            / m as f64
    };
    let mean_var = autocovariance(0) * n as f64 / (n - 1) as f64;
    let mut var_plus = mean_var * (n - 1) as f64 / n as f64;
    if m > 1 {
        let grand = means.iter().sum::<f64>() / m as f64;
        var_plus += means.iter().map(|x| (x - grand).powi(2)).sum::<f64>() / (m - 1) as f64;
    }
    if var_plus.is_nan() || var_plus <= 0.0 {
        return f64::NAN;
    }
    let rho = |lag: usize| 1.0 - (mean_var - autocovariance(lag)) / var_plus;
    let mut rho_hat = vec![0.0; n];
    rho_hat[0] = 1.0;
    let (mut even, mut odd) = (1.0, rho(1));
    rho_hat[1] = odd;
    // Geyer's initial positive sequence
    let mut t = 1;
    while t < n - 3 && even + odd > 0.0 {
        even = rho(t + 1);
        odd = rho(t + 2);
        if even + odd >= 0.0 {
            rho_hat[t + 1] = even;
            rho_hat[t + 2] = odd;
        }
        t += 2;
    }
    let draws = (m * n) as f64;
    let floor = 1.0 / draws.log10();
    if t == 1 {
        // anticorrelated at lag 1 already: the sum is empty
        return draws / floor;
    }
    let max_t = t - 2;
    if even > 0.0 {
        rho_hat[max_t + 1] = even;
    }
    // ... made monotone
    let mut t = 1;
    while t + 2 <= max_t {
        if rho_hat[t + 1] + rho_hat[t + 2] > rho_hat[t - 1] + rho_hat[t] {
            rho_hat[t + 1] = (rho_hat[t - 1] + rho_hat[t]) / 2.0;
            rho_hat[t + 2] = rho_hat[t + 1];
        }
        t += 2;
    }
    let tau = -1.0 + 2.0 * rho_hat[..=max_t].iter().sum::<f64>() + rho_hat[max_t + 1];
    draws / tau.max(floor)
}

/// The bulk effective sample size (rank-normalised split chains). NaN for draws that
/// never change.
pub fn bulk_ess(chains: &[Vec<f64>]) -> f64 {
    if constant(chains) {
        return f64::NAN;
    }
    multi_chain_ess(&rank_normalised(&split_chains(chains)))
}

/// The tail effective sample size: the smaller ESS of the indicators of the 5 % and
/// 95 % quantiles. NaN for draws that never change.
pub fn tail_ess(chains: &[Vec<f64>]) -> f64 {
    if constant(chains) {
        return f64::NAN;
    }
    let mut pooled: Vec<f64> = chains.iter().flatten().copied().collect();
    pooled.sort_by(f64::total_cmp);
    [0.05, 0.95]
        .map(|p| {
            let q = quantile_sorted(&pooled, p);
            let below: Vec<Vec<f64>> = chains
                .iter()
                .map(|c| c.iter().map(|&x| f64::from(u8::from(x <= q))).collect())
                .collect();
            multi_chain_ess(&split_chains(&below))
        })
        .into_iter()
        .fold(f64::INFINITY, f64::min)
}

/// Whether the draws never change (to round-off of their size): a stuck sampler.
fn constant(chains: &[Vec<f64>]) -> bool {
    let (lo, hi) = chains
        .iter()
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
    let spread = hi - lo;
    spread.is_nan() || spread <= 1e-12 * lo.abs().max(hi.abs())
}

/// The `p` quantile of sorted values, interpolated linearly (NumPy's default); NaN
/// when there are none.
fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let position = p * (sorted.len() - 1) as f64;
    let (lo, frac) = (position.floor() as usize, position.fract());
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] * (1.0 - frac) + sorted[hi] * frac
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
    /// Effective sample size of the draws for their mean (Geyer, summed over chains).
    pub ess: f64,
    /// Bulk effective sample size (rank-normalised; Vehtari et al. 2021).
    pub ess_bulk: f64,
    /// Tail effective sample size (of the 5 % and 95 % quantiles).
    pub ess_tail: f64,
    /// Rank-normalised split R-hat across chains (the larger of bulk and folded).
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
            // no draws (a chain stopped during its burn-in): NaN, nothing to report
            let quantile = |p: f64| quantile_sorted(&pooled, p);
            let any = !pooled.is_empty();
            ParameterSummary {
                name: first.names[k].clone(),
                mean,
                sd,
                mcse: sd / ess.sqrt(),
                ess,
                ess_bulk: if any { bulk_ess(&draws) } else { f64::NAN },
                ess_tail: if any { tail_ess(&draws) } else { f64::NAN },
                rhat: if any { rank_rhat(&draws) } else { f64::NAN },
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
