//! Eight xoshiro256++ generators in vector lanes, and the exact bit tricks that turn
//! their outputs into floating-point numbers: the shared core of the bulk draws
//! ([`crate::normals`], [`crate::trial_numbers`]).
//!
//! # Algorithm
//! * **Seeding.** Four 64-bit outputs `w_0..w_3` of the caller's generator seed the
//!   eight lanes: word `i` of lane `j` is the SplitMix64 finaliser (a bijection) of
//!   `w_i + (j + 1) * 0x9E3779B97F4A7C15`, so the lanes are distinct, well-mixed
//!   generators.
//! * **Uniforms.** The top 52 bits of an output make `1 + (w >> 12) 2^-52` in [1, 2)
//!   through the mantissa (no integer-to-float conversion, which the vector units lack
//!   for 64-bit integers).
//! * **Logarithm.** `u = 2^k m` with `m` in [sqrt(1/2), sqrt(2)), `s = (m - 1) / (m + 1)`,
//!   `ln m = 2 atanh(s) = 2 s (1 + s^2/3 + ... + s^18/19)` (`|s| <= 0.1716`, truncation
//!   below 1e-17 relative), `ln u = k ln 2 + ln m`.
//!
//! Every operation is a correctly rounded IEEE operation or an explicit `mul_add`, so
//! the lanes give the same bits compiled for any instruction set.
//!
//! # References
//! Blackman and Vigna (2021), "Scrambled linear pseudorandom number generators".

use crate::streams::{GOLDEN_GAMMA, splitmix_finaliser};
use crate::vexp::{LN2_HI, LN2_LO};

/// Generators per [`Lanes`].
pub(crate) const LANES: usize = 8;

pub(crate) const TWO_POW_52: f64 = 4_503_599_627_370_496.0;
/// The bits of `2^52`.
const MAGIC_BITS: u64 = 0x4330_0000_0000_0000;
const MANTISSA: u64 = (1 << 52) - 1;
const ONE_BITS: u64 = 1023 << 52;
/// The bits of sqrt(2) rounded down (a mantissa above it is halved).
const SQRT2_MANTISSA: u64 = 0x0006_a09e_667f_3bcd;

/// `1 / (2j + 1)` for j = 9 down to 0: `atanh(s) / s` in powers of `s^2`.
const ATANH: [f64; 10] = [
    1.0 / 19.0,
    1.0 / 17.0,
    1.0 / 15.0,
    1.0 / 13.0,
    1.0 / 11.0,
    1.0 / 9.0,
    1.0 / 7.0,
    1.0 / 5.0,
    1.0 / 3.0,
    1.0,
];

/// Four outputs of `rng`: the seed of one set of [`Lanes`].
#[inline]
pub(crate) fn seed_words<R: rand::Rng + ?Sized>(rng: &mut R) -> [u64; 4] {
    [
        rng.next_u64(),
        rng.next_u64(),
        rng.next_u64(),
        rng.next_u64(),
    ]
}

/// Eight xoshiro256++ generators, stored word by word so that a step is vector code.
pub(crate) struct Lanes {
    s: [[u64; LANES]; 4],
}

impl Lanes {
    #[inline(always)]
    pub(crate) fn seeded(words: [u64; 4]) -> Lanes {
        let mut s = [[0u64; LANES]; 4];
        for (row, w) in s.iter_mut().zip(words) {
            for (j, x) in row.iter_mut().enumerate() {
                *x = splitmix_finaliser(w.wrapping_add((j as u64 + 1).wrapping_mul(GOLDEN_GAMMA)));
            }
        }
        Lanes { s }
    }

    /// One output per lane.
    #[inline(always)]
    pub(crate) fn next(&mut self) -> [u64; LANES] {
        let [s0, s1, s2, s3] = &mut self.s;
        let mut out = [0u64; LANES];
        for j in 0..LANES {
            out[j] = s0[j]
                .wrapping_add(s3[j])
                .rotate_left(23)
                .wrapping_add(s0[j]);
            let t = s1[j] << 17;
            s2[j] ^= s0[j];
            s3[j] ^= s1[j];
            s1[j] ^= s2[j];
            s0[j] ^= s3[j];
            s2[j] ^= t;
            s3[j] = s3[j].rotate_left(45);
        }
        out
    }
}

/// `2^52` plus the integer `i < 2^52` held in the mantissa bits: `as_float(i) - 2^52`
/// converts `i` exactly without an integer-to-float instruction (AVX-512F and AVX2 have
/// none for 64-bit integers).
#[inline(always)]
pub(crate) fn integer_plus_two_pow_52(i: u64) -> f64 {
    f64::from_bits(MAGIC_BITS | i)
}

/// `(f, top)`: `f = 1 + (w >> 12) 2^-52` in [1, 2), and `w >> 12`.
#[inline(always)]
pub(crate) fn unit_interval_above_one(w: u64) -> (f64, u64) {
    let top = w >> 12;
    (f64::from_bits(ONE_BITS | top), top)
}

/// `-2 ln u` for `u = 2 - (1 + (a >> 12) 2^-52)` in (0, 1].
#[inline(always)]
pub(crate) fn minus_two_log(a: u64) -> f64 {
    let u = 2.0 - unit_interval_above_one(a).0;
    let bits = u.to_bits();
    let above = u64::from((bits & MANTISSA) > SQRT2_MANTISSA);
    // m in [sqrt(1/2), sqrt(2)): the mantissa with exponent 0, or -1 when above sqrt 2.
    let m = f64::from_bits((bits & MANTISSA) | (ONE_BITS - (above << 52)));
    // k = (biased exponent + above) - 1023, exactly.
    let k = integer_plus_two_pow_52((bits >> 52) + above) - (TWO_POW_52 + 1023.0);
    let s = (m - 1.0) / (m + 1.0);
    let z = s * s;
    let mut p = ATANH[0];
    for &c in &ATANH[1..] {
        p = p.mul_add(z, c);
    }
    let log_m = 2.0 * s * p;
    let log_u = k.mul_add(LN2_HI, k.mul_add(LN2_LO, log_m));
    -2.0 * log_u
}
