//! Rejection draws for scalar Gaussian transitions, bounded by the nearest mean.
//!
//! # Algorithm
//! For equally weighted candidates `i` with transition means `m_i` and
//! `f(x~ | x_i) = N(x~; m_i, v)`, the largest candidate density belongs to the mean
//! nearest to `x~`, found in one vectorisable pass over the means. Each trial proposes
//! `i ~ U{1..M}` and accepts it with probability `f_i / max_j f_j` (tested as
//! `l_i - max > -E`, `E ~ Exp(1)`), evaluating that single `l_i`; after `trials`
//! rejections the row is evaluated in full and drawn from exactly. The random numbers
//! used, the comparisons and the fallback are those of the general kernel
//! ([`super::exact`]), and `max_j l_j` is the same number (the log-density falls
//! monotonically in `|x~ - m_i|`, also after rounding), so both give the same draws.
//!
//! # Complexity
//! Per draw O(M / 8) vector operations for the nearest mean, plus about
//! `M max f / sum f` single evaluations, plus O(M) for the rare fallbacks; the general
//! kernel evaluates all `M` densities of every draw.

use rand::RngExt;

use super::SmootherStats;
use super::backward::{PATH_BLOCK, backward_error};
use super::rounds::{draw_in_rounds, uniform_index};
use crate::SmcError;
use crate::model::ScalarGaussianKernel;
use crate::streams::Rng;
use crate::vexp::exp_shifted_sum;
use crate::weights::{DrawFailure, draw_from_weights};

/// For each `x_k` of `points`, the smallest `|x_k - m_i|` over `means` into
/// `nearest[k]` (the caller has checked both for NaN). Points are the inner loop, a
/// whole block at a time (four vectors of eight): no horizontal reduction, and four
/// independent dependency chains per mean instead of one.
#[inline(always)]
fn nearest_distances(means: &[f64], points: &[f64], nearest: &mut [f64]) {
    const LANES: usize = PATH_BLOCK;
    for (xs, best) in points.chunks(LANES).zip(nearest.chunks_mut(LANES)) {
        let mut x = [0.0; LANES];
        x[..xs.len()].copy_from_slice(xs);
        let mut b = [f64::INFINITY; LANES];
        for &m in means {
            for (bk, &xk) in b.iter_mut().zip(&x) {
                let d = (xk - m).abs();
                *bk = if d < *bk { d } else { *bk };
            }
        }
        best.copy_from_slice(&b[..xs.len()]);
    }
}

/// Whether a step's transition means can go to [`draw_block`]: none is NaN (else the
/// general kernel takes the step and reports the bad value).
pub(crate) fn means_usable(means: &[f64]) -> bool {
    !means.iter().any(|m| m.is_nan())
}

/// For each `next_states[k]` of a block, `max[k] = max_i log f(next_states[k] | mean_i)`
/// from the nearest of `means` (free of NaN, see [`means_usable`]); an error names the
/// row whose state is NaN or whose maximum is not finite.
#[inline(always)]
pub(crate) fn row_maxima(
    kernel: ScalarGaussianKernel,
    means: &[f64],
    next_states: &[f64],
    t: usize,
    max: &mut [f64],
) -> Result<(), SmcError> {
    let rows = next_states.len();
    debug_assert!(rows <= PATH_BLOCK, "a block has at most PATH_BLOCK paths");
    if let Some(k) = next_states.iter().position(|x| x.is_nan()) {
        return Err(backward_error(DrawFailure::Invalid, t, k));
    }
    let mut nearest = [0.0; PATH_BLOCK];
    nearest_distances(means, next_states, &mut nearest[..rows]);
    for k in 0..rows {
        // the same number as the largest of the row's log-densities
        let row_max = kernel.log_density_at(nearest[k]);
        if row_max == f64::NEG_INFINITY {
            return Err(backward_error(DrawFailure::Degenerate, t, k));
        }
        if row_max.is_nan() || row_max == f64::INFINITY {
            return Err(backward_error(DrawFailure::Invalid, t, k));
        }
        max[k] = row_max;
    }
    Ok(())
}

/// One backward step of a block: for each `next_states[k]`, draws a candidate index
/// with probability ∝ `f(next_states[k] | candidate)` and writes `pick(index)` to
/// `out[k]`. `means` must be free of NaN (see [`means_usable`]); `row` is scratch for
/// the fallback.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn draw_block(
    kernel: ScalarGaussianKernel,
    means: &[f64],
    next_states: &[f64],
    trials: usize,
    t: usize,
    out: &mut [usize],
    pick: impl Fn(usize) -> usize,
    rng: &mut Rng,
    row: &mut Vec<f64>,
    stats: &mut SmootherStats,
) -> Result<(), SmcError> {
    let m = means.len();
    let rows = next_states.len();
    let mut max = [0.0; PATH_BLOCK];
    row_maxima(kernel, means, next_states, t, &mut max[..rows])?;
    let open = draw_in_rounds(
        trials,
        rng,
        |u| uniform_index(u, m),
        |k, i| kernel.log_density(means[i], next_states[k]) - max[k],
        out,
    );
    stats.trials += open.trials;
    stats.density_evaluations += rows as u64 + open.trials;
    for k in open.rows() {
        let next = next_states[k];
        stats.fallbacks += 1;
        stats.density_evaluations += m as u64;
        row.clear();
        row.extend(means.iter().map(|&mean| kernel.log_density(mean, next)));
        exp_shifted_sum(row, max[k]);
        out[k] = draw_from_weights(row, rng.random())
            .ok_or_else(|| backward_error(DrawFailure::Invalid, t, k))?;
    }
    for slot in out.iter_mut() {
        *slot = pick(*slot);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nearest_distance(means: &[f64], x: f64) -> f64 {
        let mut d = [0.0];
        nearest_distances(means, &[x], &mut d);
        d[0]
    }

    #[test]
    fn nearest_distance_matches_a_scan_over_blocks_of_any_length() {
        let means: Vec<f64> = (0..19).map(|i| i as f64 * 0.5).collect();
        assert_eq!(nearest_distance(&means, 3.1), 0.10000000000000009);
        assert_eq!(nearest_distance(&means, 100.0), 100.0 - 9.0);
        for len in [1, 7, 8, 11, 31, 32] {
            let points: Vec<f64> = (0..len).map(|k| k as f64 * 0.83 - 1.0).collect();
            let mut d = vec![0.0; len];
            nearest_distances(&means, &points, &mut d);
            for (k, &x) in points.iter().enumerate() {
                let scan = means
                    .iter()
                    .map(|m| (x - m).abs())
                    .fold(f64::INFINITY, f64::min);
                assert_eq!(d[k], scan, "{len} points, point {k}");
            }
        }
    }

    #[test]
    fn the_nearest_mean_gives_the_row_maximum_bit_for_bit() {
        let kernel = ScalarGaussianKernel::with_variance(0.0137);
        let means: Vec<f64> = (0..53)
            .map(|i| ((i * 7919) % 101) as f64 * 0.0317 - 1.3)
            .collect();
        for j in 0..200 {
            let next = j as f64 * 0.0191 - 2.0;
            let nearest = nearest_distance(&means, next);
            let row_max = means
                .iter()
                .map(|&m| kernel.log_density(m, next))
                .fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(kernel.log_density_at(nearest).to_bits(), row_max.to_bits());
        }
    }
}
