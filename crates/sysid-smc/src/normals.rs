//! Standard normal draws in bulk: eight xoshiro256++ lanes and the Box–Muller
//! transform, vectorised.
//!
//! A particle filter's transition draws need one `N(0, 1)` variable per particle and
//! step. Drawn one at a time (a ziggurat over one xoshiro stream) they cost 3-5 ns each
//! on the reference machine, about a third of a bootstrap filter step; drawn here, in
//! vector lanes, about a tenth of that.
//!
//! # Algorithm
//! 1. **Seeding.** One call takes four 64-bit outputs `w_0..w_3` of the caller's
//!    generator, whatever the number of draws, and seeds eight xoshiro256++ lanes:
//!    word `i` of lane `j` is the SplitMix64 finaliser (a bijection) of
//!    `w_i + (j + 1) * 0x9E3779B97F4A7C15`, so the lanes are distinct, well-mixed
//!    generators (the lane code is shared with the rejection trials' numbers).
//! 2. **Uniforms.** Each round every lane gives two outputs `a, b`, whose top 52 bits
//!    make `u = 1 - (a >> 12) 2^-52` in (0, 1] and `v = (b >> 12) 2^-52` in [0, 1).
//! 3. **Box–Muller.** `sqrt(-2 ln u) (cos 2 pi v, sin 2 pi v)` are two independent
//!    `N(0, 1)` draws. The largest possible value is `sqrt(2 * 52 ln 2) = 8.49`
//!    (a tail of probability 2e-17 is cut).
//!    * `ln u`: `u = 2^k m` with `m` in [sqrt(1/2), sqrt(2)), `s = (m - 1) / (m + 1)`,
//!      `ln m = 2 atanh(s) = 2 s (1 + s^2/3 + ... + s^18/19)` (`|s| <= 0.1716`,
//!      truncation below 1e-17 relative), `ln u = k ln 2 + ln m`.
//!    * `cos, sin (2 pi v)`: `q = round(4 v)`, `theta = 2 pi (v - q/4)` in
//!      [-pi/4, pi/4] (the subtraction is exact), Taylor polynomials to `theta^15`
//!      and `theta^16` (truncation below 1e-16), then the rotation by `q` quarter
//!      turns.
//! 4. **Order.** Round `r` writes lane `j`'s cosine draw to `16 r + j` and its sine
//!    draw to `16 r + 8 + j`; a last partial round is computed in full and cut.
//!
//! Every operation is a correctly rounded IEEE operation or an explicit `mul_add`, and
//! the same source is compiled for AVX-512, AVX2+FMA and the baseline target (chosen
//! at run time), so the draws are bit-identical on every x86-64 machine.
//!
//! # Complexity
//! About 110 vector instructions per round of 16 draws, plus ~40 ns of seeding per call.
//!
//! # References
//! Box and Muller (1958), "A note on the generation of random normal deviates".
//! Blackman and Vigna (2021), "Scrambled linear pseudorandom number generators".

use crate::lanes::{
    LANES, Lanes, TWO_POW_52, integer_plus_two_pow_52, minus_two_log, seed_words,
    unit_interval_above_one,
};
use crate::simd::{Kernel, dispatch};

/// Draws per round: a cosine and a sine draw per lane.
const ROUND: usize = 2 * LANES;

const TWO_PI: f64 = std::f64::consts::TAU;

/// `(-1)^j / (2j + 1)!` for j = 7 down to 0: `sin(x) / x` in powers of `x^2`.
const SIN: [f64; 8] = [
    -1.0 / 1_307_674_368_000.0,
    1.0 / 6_227_020_800.0,
    -1.0 / 39_916_800.0,
    1.0 / 362_880.0,
    -1.0 / 5_040.0,
    1.0 / 120.0,
    -1.0 / 6.0,
    1.0,
];
/// `(-1)^j / (2j)!` for j = 8 down to 0: `cos(x)` in powers of `x^2`.
const COS: [f64; 9] = [
    1.0 / 20_922_789_888_000.0,
    -1.0 / 87_178_291_200.0,
    1.0 / 479_001_600.0,
    -1.0 / 3_628_800.0,
    1.0 / 40_320.0,
    -1.0 / 720.0,
    1.0 / 24.0,
    -0.5,
    1.0,
];

/// `(cos 2 pi v, sin 2 pi v)` for `v = (b >> 12) 2^-52` in [0, 1).
#[inline(always)]
fn cos_sin_turn(b: u64) -> (f64, f64) {
    let (f, top) = unit_interval_above_one(b);
    let v = f - 1.0;
    // q = round(4 v) in 0..=4, from the integer: (top + 2^49) >> 50.
    let q = (top + (1 << 49)) >> 50;
    let r = v - 0.25 * (integer_plus_two_pow_52(q) - TWO_POW_52);
    let x = r * TWO_PI;
    let x2 = x * x;
    let mut sp = SIN[0];
    for &c in &SIN[1..] {
        sp = sp.mul_add(x2, c);
    }
    let mut cp = COS[0];
    for &c in &COS[1..] {
        cp = cp.mul_add(x2, c);
    }
    rotate(cp, q, x * sp)
}

/// Rotates `(cos x, sin x)` by `q` quarter turns: `(cos, sin) -> (-sin, cos)` per turn.
#[inline(always)]
fn rotate(cos: f64, q: u64, sin: f64) -> (f64, f64) {
    let quarter = q & 3;
    let odd = quarter & 1 == 1;
    let (a, b) = if odd { (sin, cos) } else { (cos, sin) };
    let flip_a = u64::from(quarter == 1 || quarter == 2) << 63;
    let flip_b = u64::from(quarter >= 2) << 63;
    (
        f64::from_bits(a.to_bits() ^ flip_a),
        f64::from_bits(b.to_bits() ^ flip_b),
    )
}

/// One round: 16 draws, lane `j`'s cosine draw at `j`, its sine draw at `8 + j`.
#[inline(always)]
fn round(lanes: &mut Lanes) -> [f64; ROUND] {
    let a = lanes.next();
    let b = lanes.next();
    let mut out = [0.0; ROUND];
    let (cos_half, sin_half) = out.split_at_mut(LANES);
    for j in 0..LANES {
        let radius = minus_two_log(a[j]).sqrt();
        let (c, s) = cos_sin_turn(b[j]);
        cos_half[j] = radius * c;
        sin_half[j] = radius * s;
    }
    out
}

/// Writes (`scale = None`) or adds `scale` times (`Some(scale)`) the draws to `out`.
#[inline(always)]
fn apply(draws: &[f64], scale: Option<f64>, out: &mut [f64]) {
    match scale {
        None => out.copy_from_slice(&draws[..out.len()]),
        Some(scale) => {
            for (x, z) in out.iter_mut().zip(draws) {
                *x += scale * z;
            }
        }
    }
}

/// `out[k] = z_k` or `out[k] += scale z_k`.
struct NormalKernel<'a> {
    words: [u64; 4],
    out: &'a mut [f64],
    scale: Option<f64>,
}

impl Kernel for NormalKernel<'_> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        let NormalKernel { words, out, scale } = self;
        let mut lanes = Lanes::seeded(words);
        let mut rounds = out.chunks_exact_mut(ROUND);
        // Two loops, so that each has a fixed-size body without a branch on `scale`
        // (plain loops: closures would not be inlined into the vector kernel).
        if scale.is_none() {
            for chunk in &mut rounds {
                apply(&round(&mut lanes), None, chunk);
            }
        } else {
            for chunk in &mut rounds {
                apply(&round(&mut lanes), scale, chunk);
            }
        }
        let rest = rounds.into_remainder();
        if !rest.is_empty() {
            apply(&round(&mut lanes), scale, rest);
        }
    }
}

impl<'a> NormalKernel<'a> {
    /// The kernel seeded from four outputs of `rng`.
    fn seeded<R: rand::Rng + ?Sized>(rng: &mut R, out: &'a mut [f64], scale: Option<f64>) -> Self {
        NormalKernel {
            words: seed_words(rng),
            out,
            scale,
        }
    }
}

/// Fills `out` with independent `N(0, 1)` draws, taking four outputs of `rng`.
///
/// # Example
/// ```
/// let mut rng = sysid_smc::stream(1, 0);
/// let mut z = vec![0.0; 10_000];
/// sysid_smc::fill_standard_normals(&mut rng, &mut z);
/// let mean = z.iter().sum::<f64>() / 1e4;
/// assert!(mean.abs() < 0.04);
/// ```
pub fn fill_standard_normals<R: rand::Rng + ?Sized>(rng: &mut R, out: &mut [f64]) {
    dispatch(NormalKernel::seeded(rng, out, None));
}

/// Adds `scale` times independent `N(0, 1)` draws to every entry of `out` (the draws
/// of [`fill_standard_normals`] for the same generator state), taking four outputs of
/// `rng`.
pub fn add_scaled_normals<R: rand::Rng + ?Sized>(rng: &mut R, scale: f64, out: &mut [f64]) {
    dispatch(NormalKernel::seeded(rng, out, Some(scale)));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream;

    #[test]
    fn logarithm_and_turn_match_std() {
        let mut worst_log = 0.0f64;
        let mut worst_trig = 0.0f64;
        let mut rng = stream(3, 0);
        for i in 0..200_000u64 {
            // Random words, plus the edges: u = 1, u = 2^-52, v = 0, v near 1/4 steps.
            let a = match i {
                0 => u64::MAX,
                1 => 0,
                _ => rand::Rng::next_u64(&mut rng),
            };
            let b = match i {
                0 => 0,
                1 => u64::MAX,
                2 => 1 << 62,
                3 => (1 << 62) - (1 << 12),
                _ => rand::Rng::next_u64(&mut rng),
            };
            let u = 1.0 - (a >> 12) as f64 / TWO_POW_52;
            let exact = -2.0 * u.ln();
            let got = minus_two_log(a);
            worst_log = worst_log.max((got - exact).abs() / exact.max(1e-300));
            let v = (b >> 12) as f64 / TWO_POW_52;
            let (c, s) = cos_sin_turn(b);
            let angle = TWO_PI * v;
            worst_trig = worst_trig.max((c - angle.cos()).abs().max((s - angle.sin()).abs()));
        }
        assert!(worst_log < 1e-15, "ln: worst relative error {worst_log:e}");
        assert!(
            worst_trig < 1e-15,
            "cos/sin: worst absolute error {worst_trig:e}"
        );
        assert_eq!(minus_two_log(0), 0.0);
        assert_eq!(cos_sin_turn(0), (1.0, 0.0));
    }

    #[test]
    fn dispatched_equals_portable_bit_for_bit() {
        for len in [0, 1, 15, 16, 17, 1000, 1024] {
            let (mut a, mut b) = (vec![0.0; len], vec![0.0; len]);
            fill_standard_normals(&mut stream(5, 1), &mut a);
            // the kernel as compiled for the baseline target, without dispatch
            NormalKernel::seeded(&mut stream(5, 1), &mut b, None).run();
            assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
        }
    }

    #[test]
    fn add_scaled_adds_the_same_draws() {
        let mut z = vec![0.0; 100];
        fill_standard_normals(&mut stream(8, 2), &mut z);
        let mut x: Vec<f64> = (0..100).map(|i| i as f64).collect();
        add_scaled_normals(&mut stream(8, 2), 0.5, &mut x);
        for (i, (x, z)) in x.iter().zip(&z).enumerate() {
            assert_eq!(x.to_bits(), (i as f64 + 0.5 * z).to_bits());
        }
    }

    #[test]
    fn a_prefix_is_the_start_of_a_longer_fill() {
        let (mut short, mut long) = (vec![0.0; 37], vec![0.0; 64]);
        fill_standard_normals(&mut stream(2, 0), &mut short);
        fill_standard_normals(&mut stream(2, 0), &mut long);
        assert_eq!(short[..], long[..37]);
    }

    /// Kolmogorov-Smirnov against N(0, 1), the tail mass beyond 3, and the correlation
    /// of neighbouring draws (within a round, across rounds and across calls).
    #[test]
    fn draws_are_independent_standard_normals() {
        use statrs::distribution::{ContinuousCDF, Normal};
        let n = 1 << 20;
        let mut rng = stream(11, 0);
        let mut z = vec![0.0; n];
        // Calls of 1000 draws, so that call boundaries are tested too.
        for block in z.chunks_mut(1000) {
            fill_standard_normals(&mut rng, block);
        }
        let lag_correlation = |lag: usize| {
            let s: f64 = z.windows(lag + 1).map(|w| w[0] * w[lag]).sum();
            s / (n - lag) as f64
        };
        let bound = 4.0 / (n as f64).sqrt();
        for lag in [1, 8, 15, 16, 1000] {
            let r = lag_correlation(lag);
            assert!(r.abs() < bound, "lag {lag}: correlation {r}");
        }
        let beyond_3 = z.iter().filter(|x| x.abs() > 3.0).count() as f64;
        let p = 2.0 * (1.0 - Normal::standard().cdf(3.0));
        let sd = (n as f64 * p * (1.0 - p)).sqrt();
        assert!(
            (beyond_3 - n as f64 * p).abs() < 4.0 * sd,
            "{beyond_3} beyond 3"
        );
        z.sort_by(f64::total_cmp);
        let normal = Normal::standard();
        let d = z
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                let f = normal.cdf(x);
                (f - i as f64 / n as f64).max((i + 1) as f64 / n as f64 - f)
            })
            .fold(0.0, f64::max);
        // The 0.999 quantile of sqrt(n) D is 1.95.
        assert!(d * (n as f64).sqrt() < 1.95, "KS statistic {d}");
    }
}
