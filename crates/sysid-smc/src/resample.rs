//! Resampling schemes: small functions over normalised weights.
//!
//! Each scheme writes `out.len()` ancestor indices drawn so that the expected number of
//! copies of particle `i` is `out.len() * w_i` (unbiased). Stratified, systematic and
//! residual resampling have a smaller offspring variance than multinomial.
//! Systematic, stratified and multinomial output is sorted.
//!
//! # References
//! Douc, Cappé and Moulines (2005), "Comparison of resampling schemes for particle
//! filtering". Chopin and Papaspiliopoulos (2020), *An Introduction to Sequential Monte
//! Carlo*, ch. 9.

use rand::RngExt;
use rand_distr::{Distribution, Exp1};

pub use crate::systematic::systematic;

/// The resampling scheme of a particle filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Resampling {
    /// Independent draws from `Cat(w)` (via sorted uniforms, O(N)).
    Multinomial,
    /// One uniform per stratum `[k/N, (k+1)/N)`.
    Stratified,
    /// One uniform shared by all strata: the lowest variance in practice.
    #[default]
    Systematic,
    /// `floor(N w_i)` deterministic copies, the rest multinomial.
    Residual,
}

impl Resampling {
    /// All schemes, for tests and command-line help.
    pub const ALL: [Resampling; 4] = [
        Resampling::Multinomial,
        Resampling::Stratified,
        Resampling::Systematic,
        Resampling::Residual,
    ];

    /// The lower-case name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Resampling::Multinomial => "multinomial",
            Resampling::Stratified => "stratified",
            Resampling::Systematic => "systematic",
            Resampling::Residual => "residual",
        }
    }

    /// Parses a [`name`](Self::name).
    pub fn from_name(name: &str) -> Option<Resampling> {
        Resampling::ALL.into_iter().find(|s| s.name() == name)
    }

    /// Draws ancestors with this scheme. `scratch` is reused between calls.
    #[inline(always)]
    pub fn resample<R: rand::Rng + ?Sized>(
        self,
        weights: &[f64],
        rng: &mut R,
        out: &mut [usize],
        scratch: &mut ResampleScratch,
    ) {
        match self {
            Resampling::Multinomial => multinomial(weights, rng, out, &mut scratch.spacings),
            Resampling::Stratified => stratified(weights, rng, out),
            Resampling::Systematic => systematic(weights, rng.random(), out),
            Resampling::Residual => residual(weights, rng, out, scratch),
        }
    }
}

/// Reusable buffers of the multinomial and residual schemes.
#[derive(Debug, Clone, Default)]
pub struct ResampleScratch {
    spacings: Vec<f64>,
    residuals: Vec<f64>,
}

/// Assigns sorted positions (in units of the total weight) to ancestors by one merge of
/// the positions with the cumulative weights, O(N + M).
#[inline]
fn assign_sorted(weights: &[f64], positions: impl Iterator<Item = f64>, out: &mut [usize]) {
    let last = weights.iter().rposition(|&w| w > 0.0).unwrap_or(0);
    let mut i = 0;
    let mut upper = weights[0];
    for (slot, p) in out.iter_mut().zip(positions) {
        while upper <= p && i < last {
            i += 1;
            upper += weights[i];
        }
        *slot = i;
    }
}

/// Stratified resampling: positions `(k + u_k) / N` with independent uniforms.
pub fn stratified<R: rand::Rng + ?Sized>(weights: &[f64], rng: &mut R, out: &mut [usize]) {
    let total: f64 = weights.iter().sum();
    let step = total / out.len() as f64;
    let positions = (0..out.len()).map(|k| (k as f64 + rng.random::<f64>()) * step);
    assign_sorted(weights, positions, out);
}

/// Multinomial resampling: `N` independent draws, produced as sorted uniforms from the
/// normalised partial sums of `N + 1` exponential variables.
pub fn multinomial<R: rand::Rng + ?Sized>(
    weights: &[f64],
    rng: &mut R,
    out: &mut [usize],
    scratch: &mut Vec<f64>,
) {
    let n = out.len();
    scratch.clear();
    let mut sum = 0.0;
    for _ in 0..=n {
        let e: f64 = Exp1.sample(rng);
        sum += e;
        scratch.push(sum);
    }
    let total: f64 = weights.iter().sum();
    let scale = total / sum;
    assign_sorted(weights, scratch[..n].iter().map(|s| s * scale), out);
}

/// Residual resampling: `floor(N w_i)` copies of each particle, then the remaining
/// `R = N - sum floor(N w_i)` draws multinomially from the residual weights.
pub fn residual<R: rand::Rng + ?Sized>(
    weights: &[f64],
    rng: &mut R,
    out: &mut [usize],
    scratch: &mut ResampleScratch,
) {
    let n = out.len();
    let total: f64 = weights.iter().sum();
    let residual_weights = &mut scratch.residuals;
    residual_weights.clear();
    let mut filled = 0;
    for (i, &w) in weights.iter().enumerate() {
        let expected = n as f64 * w / total;
        let copies = (expected.floor() as usize).min(n - filled);
        out[filled..filled + copies].fill(i);
        filled += copies;
        residual_weights.push(expected - copies as f64);
    }
    if filled < n {
        multinomial(
            residual_weights,
            rng,
            &mut out[filled..],
            &mut scratch.spacings,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::streams::stream;

    #[test]
    fn every_scheme_keeps_a_point_mass() {
        let w = [0.0, 0.0, 1.0, 0.0];
        let mut out = [9usize; 5];
        let mut scratch = ResampleScratch::default();
        for scheme in Resampling::ALL {
            scheme.resample(&w, &mut stream(1, 0), &mut out, &mut scratch);
            assert_eq!(out, [2; 5], "{}", scheme.name());
        }
    }

    #[test]
    fn residual_gives_the_floor_copies() {
        let w = [0.5, 0.3, 0.2];
        let mut out = [0usize; 10];
        residual(
            &w,
            &mut stream(2, 0),
            &mut out,
            &mut ResampleScratch::default(),
        );
        let counts: Vec<usize> = (0..3)
            .map(|i| out.iter().filter(|&&a| a == i).count())
            .collect();
        assert_eq!(counts, [5, 3, 2]);
    }

    #[test]
    fn systematic_positions_are_exact_for_equal_weights() {
        let w = [0.25; 4];
        let mut out = [0usize; 4];
        systematic(&w, 0.5, &mut out);
        assert_eq!(out, [0, 1, 2, 3]);
    }

    #[test]
    fn names_round_trip() {
        for s in Resampling::ALL {
            assert_eq!(Resampling::from_name(s.name()), Some(s));
        }
        assert_eq!(Resampling::from_name("bogus"), None);
    }
}
