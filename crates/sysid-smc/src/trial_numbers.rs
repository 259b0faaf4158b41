//! Uniform and exponential pairs in bulk, for rejection trials.
//!
//! A rejection trial needs a uniform (to propose a candidate) and an `Exp(1)` variable
//! (the test `log ratio > -E`). Drawn one at a time from one xoshiro stream (a
//! conversion and a ziggurat) the pair costs several nanoseconds and sits on the
//! trial's dependency chain through the generator state; here the pairs come from
//! eight vector lanes, a buffer at a time, and a trial only loads them.
//!
//! # Algorithm
//! [`TrialNumbers`] hands out runs of pairs from a buffer of [`CHUNK`] (a run that does
//! not fit in what is left drops the rest). An empty buffer is refilled from eight
//! xoshiro256++ lanes seeded by four outputs of the caller's generator
//! ([`crate::lanes`]): round `r` takes two outputs `a, b` of each lane `j`, and pair
//! `8 r + j` is
//!
//! ```text
//! u = (b >> 12) 2^-52            in [0, 1)
//! E = -ln(1 - (a >> 12) 2^-52)   in [0, 52 ln 2]
//! ```
//!
//! (the exponential's tail beyond `52 ln 2 = 36.04`, of probability `2^-52`, is cut).
//! The pairs depend only on the caller's generator, and a fresh [`TrialNumbers`] takes
//! nothing from it until its first pair is asked for.
//!
//! # Complexity
//! About 70 vector instructions per round of eight pairs, plus ~40 ns of seeding per
//! refill.

use crate::lanes::{LANES, Lanes, minus_two_log, seed_words, unit_interval_above_one};
use crate::simd::{Kernel, dispatch};

/// Pairs per refill.
pub(crate) const CHUNK: usize = 128;

/// A buffer of `(uniform, exponential)` pairs, refilled from the caller's generator.
pub(crate) struct TrialNumbers {
    uniforms: [f64; CHUNK],
    exponentials: [f64; CHUNK],
    next: usize,
}

impl TrialNumbers {
    /// An empty buffer: the first run taken refills it.
    pub fn new() -> Self {
        TrialNumbers {
            uniforms: [0.0; CHUNK],
            exponentials: [0.0; CHUNK],
            next: CHUNK,
        }
    }

    /// The next `n <= CHUNK` pairs, contiguous: `(uniforms, exponentials)`. When fewer
    /// than `n` are left, the rest of the buffer is dropped and it is refilled.
    #[inline(always)]
    pub fn take<R: rand::Rng + ?Sized>(&mut self, rng: &mut R, n: usize) -> (&[f64], &[f64]) {
        debug_assert!(n <= CHUNK, "at most a buffer's worth of pairs at once");
        if self.next + n > CHUNK {
            self.refill(rng);
        }
        let from = self.next;
        self.next += n;
        (
            &self.uniforms[from..from + n],
            &self.exponentials[from..from + n],
        )
    }

    #[inline(never)]
    fn refill<R: rand::Rng + ?Sized>(&mut self, rng: &mut R) {
        dispatch(PairKernel {
            words: seed_words(rng),
            uniforms: &mut self.uniforms,
            exponentials: &mut self.exponentials,
        });
        self.next = 0;
    }
}

/// Fills a buffer's pairs from lanes seeded by `words`.
struct PairKernel<'a> {
    words: [u64; 4],
    uniforms: &'a mut [f64; CHUNK],
    exponentials: &'a mut [f64; CHUNK],
}

impl Kernel for PairKernel<'_> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        let mut lanes = Lanes::seeded(self.words);
        for r in 0..CHUNK / LANES {
            let a = lanes.next();
            let b = lanes.next();
            // fixed-size rounds, so that the lane loop compiles to vector code
            let (mut u, mut e) = ([0.0; LANES], [0.0; LANES]);
            for j in 0..LANES {
                u[j] = unit_interval_above_one(b[j]).0 - 1.0;
                e[j] = 0.5 * minus_two_log(a[j]);
            }
            self.uniforms[r * LANES..(r + 1) * LANES].copy_from_slice(&u);
            self.exponentials[r * LANES..(r + 1) * LANES].copy_from_slice(&e);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream;

    fn pairs(seed: u64, n: usize) -> Vec<(f64, f64)> {
        let mut rng = stream(seed, 0);
        let mut numbers = TrialNumbers::new();
        (0..n)
            .map(|_| {
                let (u, e) = numbers.take(&mut rng, 1);
                (u[0], e[0])
            })
            .collect()
    }

    #[test]
    fn dispatched_equals_portable_bit_for_bit() {
        let mut rng = stream(4, 2);
        let words = seed_words(&mut rng);
        let (mut u, mut e) = ([0.0; CHUNK], [0.0; CHUNK]);
        PairKernel {
            words,
            uniforms: &mut u,
            exponentials: &mut e,
        }
        .run();
        // the same pairs through the dispatched refill
        let mut numbers = TrialNumbers::new();
        let (a, b) = numbers.take(&mut stream(4, 2), CHUNK);
        for k in 0..CHUNK {
            assert_eq!(a[k].to_bits(), u[k].to_bits(), "uniform {k}");
            assert_eq!(b[k].to_bits(), e[k].to_bits(), "exponential {k}");
        }
    }

    /// Kolmogorov-Smirnov of the uniforms against U[0, 1) and of the exponentials
    /// against Exp(1), and the correlation of `u` with `E` and of neighbours (within a
    /// round, across rounds and across refills).
    #[test]
    fn pairs_are_independent_uniforms_and_exponentials() {
        let n = 1 << 19;
        let drawn = pairs(13, n);
        let (mut u, mut e): (Vec<f64>, Vec<f64>) = drawn.iter().copied().unzip();
        let centred = |x: &[f64], mean: f64| x.iter().map(|v| v - mean).collect::<Vec<_>>();
        let (cu, ce) = (centred(&u, 0.5), centred(&e, 1.0));
        // sd of U is 1/sqrt(12), of Exp(1) is 1
        let correlation = |a: &[f64], b: &[f64], lag: usize, sd: f64| {
            let s: f64 = a.iter().zip(&b[lag..]).map(|(x, y)| x * y).sum();
            s / (n - lag) as f64 / sd
        };
        let bound = 4.0 / (n as f64).sqrt();
        let su = 1.0 / 12f64.sqrt();
        assert!(correlation(&cu, &ce, 0, su).abs() < bound, "u with E");
        for lag in [1, 8, CHUNK - 1, CHUNK, CHUNK + 1] {
            let r = correlation(&cu, &cu, lag, su * su);
            assert!(r.abs() < bound, "uniforms, lag {lag}: {r}");
            let r = correlation(&ce, &ce, lag, 1.0);
            assert!(r.abs() < bound, "exponentials, lag {lag}: {r}");
        }
        let ks = |x: &mut Vec<f64>, cdf: &dyn Fn(f64) -> f64| {
            x.sort_by(f64::total_cmp);
            x.iter()
                .enumerate()
                .map(|(i, &v)| {
                    let f = cdf(v);
                    (f - i as f64 / n as f64).max((i + 1) as f64 / n as f64 - f)
                })
                .fold(0.0, f64::max)
                * (n as f64).sqrt()
        };
        // The 0.999 quantile of sqrt(n) D is 1.95.
        let d = ks(&mut u, &|v| v);
        assert!(d < 1.95, "uniform KS {d}");
        let d = ks(&mut e, &|v| 1.0 - (-v).exp());
        assert!(d < 1.95, "exponential KS {d}");
        assert!(u[0] >= 0.0 && u[n - 1] < 1.0);
        assert!(e[0] >= 0.0 && e[n - 1] <= 52.0 * std::f64::consts::LN_2 + 1e-12);
    }

    /// Runs are consecutive pairs of the buffer; one that does not fit in what is left
    /// starts a new buffer (the next four outputs of the caller's generator).
    #[test]
    fn runs_are_consecutive_and_a_run_that_does_not_fit_refills() {
        let all = pairs(3, 2 * CHUNK);
        let mut rng = stream(3, 0);
        let mut numbers = TrialNumbers::new();
        let first = CHUNK * 5 / 8;
        let (u, _) = numbers.take(&mut rng, first);
        assert_eq!(u[first - 1].to_bits(), all[first - 1].0.to_bits());
        let (u, _) = numbers.take(&mut rng, CHUNK - first);
        assert_eq!(
            u[CHUNK - first - 1].to_bits(),
            all[CHUNK - 1].0.to_bits(),
            "exactly fills the buffer"
        );
        let (u, _) = numbers.take(&mut rng, 10);
        assert_eq!(u[0].to_bits(), all[CHUNK].0.to_bits(), "the next buffer");
        let (u, _) = numbers.take(&mut rng, CHUNK - 4);
        assert_eq!(
            u[0].to_bits(),
            pairs_after_two_refills(),
            "did not fit: refilled"
        );
    }

    /// The first uniform of the third buffer of `stream(3, 0)`.
    fn pairs_after_two_refills() -> u64 {
        pairs(3, 2 * CHUNK + 1)[2 * CHUNK].0.to_bits()
    }

    #[test]
    fn refills_take_four_outputs_each() {
        use rand::Rng;
        let mut rng = stream(6, 1);
        let mut numbers = TrialNumbers::new();
        for _ in 0..CHUNK + 1 {
            numbers.take(&mut rng, 1);
        }
        let mut reference = stream(6, 1);
        for _ in 0..8 {
            reference.next_u64();
        }
        assert_eq!(rng.next_u64(), reference.next_u64());
    }
}
