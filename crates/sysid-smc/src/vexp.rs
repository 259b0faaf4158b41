//! Vectorised `exp` over slices: the kernel that dominates particle smoothers.
//!
//! # Algorithm
//! Range reduction `x = k ln 2 + r`, `|r| <= ln 2 / 2` (with `ln 2` split in a high and
//! a low part), a degree-12 Taylor polynomial for `e^r` in Horner form with fused
//! multiply-adds (truncation error below 2e-16 relative), and `2^k` assembled in the
//! exponent bits. Arguments below -708 give exactly 0 (no subnormal results), arguments
//! above 709 give the value at 709 (callers pass shifted log-weights, which are <= 0).
//!
//! The same source is compiled for AVX-512, for AVX2+FMA and for the baseline target;
//! the best one is picked at run time by [`dispatch`]. Every lane uses the same fused operations in the
//! same order, so the three versions give bit-identical results (the baseline's
//! `mul_add` is a correctly rounded `fma`), and a seed reproduces a run on any x86-64.
//!
//! # Complexity
//! About 20 vector instructions per 4 (AVX2) or 8 (AVX-512) values.

use crate::simd::{Kernel, dispatch};

const LOG2_E: f64 = std::f64::consts::LOG2_E;
/// `ln 2` rounded to 32 significant bits, so that `k * LN2_HI` is exact for `|k| < 2^20`.
pub(crate) const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
/// `ln 2 - LN2_HI`.
pub(crate) const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
/// 1.5 * 2^52: adding it rounds to an integer held in the low mantissa bits.
const ROUND_MAGIC: f64 = 6_755_399_441_055_744.0;
const MIN_ARG: f64 = -708.0;
const MAX_ARG: f64 = 709.0;

/// `1 / k!` for k = 12 down to 0.
const TAYLOR: [f64; 13] = [
    1.0 / 479_001_600.0,
    1.0 / 39_916_800.0,
    1.0 / 3_628_800.0,
    1.0 / 362_880.0,
    1.0 / 40_320.0,
    1.0 / 5_040.0,
    1.0 / 720.0,
    1.0 / 120.0,
    1.0 / 24.0,
    1.0 / 6.0,
    0.5,
    1.0,
    1.0,
];

#[inline(always)]
fn exp_lane(x: f64) -> f64 {
    let low = if x < MIN_ARG { MIN_ARG } else { x };
    let clamped = if low > MAX_ARG { MAX_ARG } else { low };
    let shifted = clamped.mul_add(LOG2_E, ROUND_MAGIC);
    let k = shifted - ROUND_MAGIC;
    let r = (-k).mul_add(LN2_LO, (-k).mul_add(LN2_HI, clamped));
    let mut p = TAYLOR[0];
    for &c in &TAYLOR[1..] {
        p = p.mul_add(r, c);
    }
    // The low bits of `shifted` hold k in two's complement; shifting them into the
    // exponent field and adding the bias gives 2^k.
    let scale = f64::from_bits((shifted.to_bits() << 52).wrapping_add(1023u64 << 52));
    if x < MIN_ARG { 0.0 } else { p * scale }
}

/// Replaces every `v[i]` by `exp(v[i] - shift)` and returns the sum of the results.
/// The sum uses eight interleaved partial sums combined in a fixed order.
#[inline(always)]
fn exp_shifted_sum_kernel(v: &mut [f64], shift: f64) -> f64 {
    for x in v.iter_mut() {
        *x = exp_lane(*x - shift);
    }
    let mut acc = [0.0f64; 8];
    let mut chunks = v.chunks_exact(8);
    for chunk in &mut chunks {
        for (a, x) in acc.iter_mut().zip(chunk) {
            *a += *x;
        }
    }
    for (a, x) in acc.iter_mut().zip(chunks.remainder()) {
        *a += *x;
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]))
}

/// The kernel as a [`Kernel`] for [`dispatch`].
struct ExpShiftedSum<'a> {
    values: &'a mut [f64],
    shift: f64,
}

impl Kernel for ExpShiftedSum<'_> {
    type Output = f64;

    #[inline(always)]
    fn run(self) -> f64 {
        exp_shifted_sum_kernel(self.values, self.shift)
    }
}

/// Replaces every `v[i]` by `exp(v[i] - shift)` and returns their sum.
///
/// With `shift = max v`, this is the stable way to turn log-weights into weights.
/// Values with `v[i] - shift < -708` become 0.
///
/// # Example
/// ```
/// let mut v = [0.0, -1.0, 1.0];
/// let sum = sysid_smc::exp_shifted_sum(&mut v, 1.0);
/// assert!((v[0] - (-1.0f64).exp()).abs() < 1e-16);
/// assert!((sum - (1.0 + (-1.0f64).exp() + (-2.0f64).exp())).abs() < 1e-15);
/// ```
pub fn exp_shifted_sum(v: &mut [f64], shift: f64) -> f64 {
    dispatch(ExpShiftedSum { values: v, shift })
}

/// The portable version, for tests that compare the dispatched kernels with it.
#[doc(hidden)]
pub fn exp_shifted_sum_portable(v: &mut [f64], shift: f64) -> f64 {
    exp_shifted_sum_kernel(v, shift)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_std_exp_to_two_ulps() {
        let mut worst = 0.0f64;
        let mut x = -707.9;
        while x < 708.0 {
            let mut v = [x];
            exp_shifted_sum(&mut v, 0.0);
            let rel = (v[0] - x.exp()).abs() / x.exp();
            worst = worst.max(rel);
            x += 0.0137;
        }
        assert!(worst < 4.5e-16, "worst relative error {worst:e}");
    }

    #[test]
    fn underflow_is_exact_zero_and_large_is_finite() {
        let mut v = [-709.0, -1e300, f64::NEG_INFINITY, 0.0];
        let sum = exp_shifted_sum(&mut v, 0.0);
        assert_eq!(&v[..3], &[0.0, 0.0, 0.0]);
        assert_eq!(sum, 1.0);
        let mut big = [1e6];
        exp_shifted_sum(&mut big, 0.0);
        assert!(big[0].is_finite());
    }

    #[test]
    fn dispatched_equals_portable_bit_for_bit() {
        let values: Vec<f64> = (0..1003).map(|i| -0.731 * i as f64 + 3.1).collect();
        let (mut a, mut b) = (values.clone(), values);
        let sa = exp_shifted_sum(&mut a, 1.25);
        let sb = exp_shifted_sum_portable(&mut b, 1.25);
        assert_eq!(sa.to_bits(), sb.to_bits());
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
    }
}
