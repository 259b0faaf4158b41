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

/// For each `x_k` of `points`, the smallest `|x_k - m_i|` over `means` (NaN entries
/// skipped) into `nearest[k]`, and whether any distance of `x_k` was NaN into `nan[k]`.
/// Points are the inner loop (eight at a time), so there is no horizontal reduction.
#[inline(always)]
fn nearest_distances(means: &[f64], points: &[f64], nearest: &mut [f64], nan: &mut [bool]) {
    const LANES: usize = 8;
    for ((xs, best), bad) in points
        .chunks(LANES)
        .zip(nearest.chunks_mut(LANES))
        .zip(nan.chunks_mut(LANES))
    {
        let mut x = [0.0; LANES];
        x[..xs.len()].copy_from_slice(xs);
        let mut b = [f64::INFINITY; LANES];
        let mut n = [false; LANES];
        for &m in means {
            for ((bk, nk), &xk) in b.iter_mut().zip(n.iter_mut()).zip(&x) {
                let d = (xk - m).abs();
                *nk |= d.is_nan();
                *bk = if d < *bk { d } else { *bk };
            }
        }
        best.copy_from_slice(&b[..xs.len()]);
        bad.copy_from_slice(&n[..xs.len()]);
    }
}

/// One backward step of a block: for each `next_states[k]`, draws a candidate index
/// with probability ∝ `f(next_states[k] | candidate)` and writes `pick(index)` to
/// `out[k]`. `row` is scratch for the fallback.
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
    let mut nearest = [0.0; PATH_BLOCK];
    let mut nan = [false; PATH_BLOCK];
    let rows = next_states.len();
    debug_assert!(rows <= PATH_BLOCK, "a block has at most PATH_BLOCK paths");
    nearest_distances(means, next_states, &mut nearest[..rows], &mut nan[..rows]);
    let mut max = [0.0; PATH_BLOCK];
    for k in 0..rows {
        // the same number as the largest of the row's log-densities
        let row_max = kernel.log_density_at(nearest[k]);
        if row_max == f64::NEG_INFINITY {
            return Err(backward_error(DrawFailure::Degenerate, t, k));
        }
        if nan[k] || row_max.is_nan() || row_max == f64::INFINITY {
            return Err(backward_error(DrawFailure::Invalid, t, k));
        }
        max[k] = row_max;
    }
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

    fn nearest_distance(means: &[f64], x: f64) -> (f64, bool) {
        let (mut d, mut nan) = ([0.0], [false]);
        nearest_distances(means, &[x], &mut d, &mut nan);
        (d[0], nan[0])
    }

    #[test]
    fn nearest_distance_skips_nan_and_reports_it() {
        let means: Vec<f64> = (0..19).map(|i| i as f64 * 0.5).collect();
        assert_eq!(nearest_distance(&means, 3.1), (0.10000000000000009, false));
        assert_eq!(nearest_distance(&means, 100.0).0, 100.0 - 9.0);
        let mut with_nan = means.clone();
        with_nan[17] = f64::NAN;
        let (d, nan) = nearest_distance(&with_nan, 8.4);
        assert!(nan);
        assert!((d - 0.4).abs() < 1e-12, "{d}");
        let points: Vec<f64> = (0..11).map(|k| k as f64 * 0.83).collect();
        let (mut d, mut nan) = (vec![0.0; 11], vec![true; 11]);
        nearest_distances(&means, &points, &mut d, &mut nan);
        for (k, &x) in points.iter().enumerate() {
            assert_eq!((d[k], nan[k]), nearest_distance(&means, x));
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
            let (nearest, _) = nearest_distance(&means, next);
            let row_max = means
                .iter()
                .map(|&m| kernel.log_density(m, next))
                .fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(kernel.log_density_at(nearest).to_bits(), row_max.to_bits());
        }
    }
}
