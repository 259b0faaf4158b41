//! Offspring counts of every resampling scheme: unbiased (E[count_i] = N w_i within
//! Monte Carlo error) and, for the low-variance schemes, less variable than multinomial.

use rand::RngExt;
use sysid_smc::resample::ResampleScratch;
use sysid_smc::{Resampling, stream};

/// Per-particle mean and variance of the offspring counts over `reps` resamplings.
fn offspring_moments(
    scheme: Resampling,
    weights: &[f64],
    n: usize,
    reps: u64,
) -> (Vec<f64>, Vec<f64>) {
    let m = weights.len();
    let mut sum = vec![0.0; m];
    let mut sum2 = vec![0.0; m];
    let mut out = vec![0usize; n];
    let mut counts = vec![0usize; m];
    let mut scratch = ResampleScratch::default();
    let mut rng = stream(99, scheme as u64);
    for _ in 0..reps {
        scheme.resample(weights, &mut rng, &mut out, &mut scratch);
        counts.fill(0);
        for &a in &out {
            counts[a] += 1;
        }
        for i in 0..m {
            sum[i] += counts[i] as f64;
            sum2[i] += (counts[i] * counts[i]) as f64;
        }
    }
    let r = reps as f64;
    let mean: Vec<f64> = sum.iter().map(|s| s / r).collect();
    let var = sum2
        .iter()
        .zip(&mean)
        .map(|(s2, mu)| s2 / r - mu * mu)
        .collect();
    (mean, var)
}

fn random_weights(m: usize, seed: u64) -> Vec<f64> {
    let mut rng = stream(seed, 0);
    let raw: Vec<f64> = (0..m)
        .map(|i| {
            if i % 7 == 3 {
                0.0
            } else {
                rng.random::<f64>().powi(3)
            }
        })
        .collect();
    let total: f64 = raw.iter().sum();
    raw.iter().map(|w| w / total).collect()
}

#[test]
fn offspring_counts_are_unbiased_for_every_scheme() {
    let weights = random_weights(40, 1);
    let n = 40;
    let reps = 20_000;
    for scheme in Resampling::ALL {
        let (mean, var) = offspring_moments(scheme, &weights, n, reps);
        for (i, (&mu, &w)) in mean.iter().zip(&weights).enumerate() {
            let expected = n as f64 * w;
            // Standard error from the multinomial variance (an upper bound for the
            // other schemes), floored for particles with tiny weight.
            let se = (n as f64 * w * (1.0 - w) / reps as f64).sqrt().max(1e-3);
            assert!(
                (mu - expected).abs() < 4.5 * se,
                "{} particle {i}: mean {mu}, expected {expected}, var {}",
                scheme.name(),
                var[i]
            );
        }
        for (i, &w) in weights.iter().enumerate() {
            if w == 0.0 {
                assert_eq!(mean[i], 0.0, "{}: zero weight resampled", scheme.name());
            }
        }
    }
}

#[test]
fn low_variance_schemes_beat_multinomial() {
    let weights = random_weights(40, 2);
    let total_var = |s| {
        offspring_moments(s, &weights, 40, 5_000)
            .1
            .iter()
            .sum::<f64>()
    };
    let multinomial = total_var(Resampling::Multinomial);
    for scheme in [
        Resampling::Stratified,
        Resampling::Systematic,
        Resampling::Residual,
    ] {
        let v = total_var(scheme);
        assert!(
            v < 0.8 * multinomial,
            "{}: {v} vs multinomial {multinomial}",
            scheme.name()
        );
    }
}

#[test]
fn different_output_size_from_input_size() {
    let weights = random_weights(13, 3);
    for scheme in Resampling::ALL {
        let (mean, _) = offspring_moments(scheme, &weights, 100, 4_000);
        let total: f64 = mean.iter().sum();
        assert!((total - 100.0).abs() < 1e-9, "{}", scheme.name());
    }
}
