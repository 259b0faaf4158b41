//! Rejection draws for scalar Gaussian transitions, bounded by the nearest mean.
//!
//! # Algorithm
//! For equally weighted candidates `i` with transition means `m_i` and
//! `f(x~ | x_i) = N(x~; m_i, v)`, the largest candidate density belongs to the mean
//! nearest to `x~`, found in one vectorisable pass over the means. Each trial proposes
//! a candidate and accepts it with probability `f_i / g_i` for an envelope `g >= f`
//! (tested as `l_i - log g_i > -E`, `E ~ Exp(1)`), evaluating that single `l_i`; after
//! `trials` rejections the row is evaluated in full and drawn from exactly. Where the
//! step's means spread wider than a window, each row proposes from its window of
//! sorted means ([`super::window`]); elsewhere the proposal is uniform and
//! `g_i = max_j f_j`, with the random numbers, comparisons and fallback of the general
//! kernel ([`super::exact`]) and the same `max_j l_j` (the log-density falls
//! monotonically in `|x~ - m_i|`, also after rounding), so both give the same draws
//! there.
//!
//! # Complexity
//! Per draw O(M / 8) vector operations for the nearest mean, plus about
//! `sum g / sum f` single evaluations, plus O(M) for the rare fallbacks; O(M) per step
//! for the windows' sort. The general kernel evaluates all `M` densities of every draw.

use rand::RngExt;

use super::SmootherStats;
use super::backward::{PATH_BLOCK, backward_error};
use super::rounds::{OpenRows, draw_in_rounds, uniform_index};
use super::window::{BlockProposals, MeanBuckets};
use crate::SmcError;
use crate::model::ScalarGaussianKernel;
use crate::streams::Rng;
use crate::vexp::exp_shifted_sum;
use crate::weights::{DrawFailure, draw_from_weights};

/// The most points that one pass over the means takes: few enough lanes to stay in
/// registers.
const NEAREST_LANES: usize = 32;

/// For each `x_k` of `points` (at most [`PATH_BLOCK`]), the smallest `|x_k - m_i|`
/// over `means` into `nearest[k]` (the caller has checked both for NaN). Points are the
/// inner loop, up to [`NEAREST_LANES`] at a time in as few vectors of eight as hold
/// them: no horizontal reduction, and up to four independent dependency chains per
/// mean instead of one.
#[inline(always)]
fn nearest_distances(means: &[f64], points: &[f64], nearest: &mut [f64]) {
    let pieces = points
        .chunks(NEAREST_LANES)
        .zip(nearest.chunks_mut(NEAREST_LANES));
    for (points, nearest) in pieces {
        match points.len() {
            0..=8 => nearest_in_lanes::<8>(means, points, nearest),
            9..=16 => nearest_in_lanes::<16>(means, points, nearest),
            17..=24 => nearest_in_lanes::<24>(means, points, nearest),
            _ => nearest_in_lanes::<NEAREST_LANES>(means, points, nearest),
        }
    }
}

/// [`nearest_distances`] with `LANES >= points.len()` lanes.
#[inline(always)]
fn nearest_in_lanes<const LANES: usize>(means: &[f64], points: &[f64], nearest: &mut [f64]) {
    let rows = points.len();
    let mut x = [0.0; LANES];
    x[..rows].copy_from_slice(points);
    let mut b = [f64::INFINITY; LANES];
    for &m in means {
        for (bk, &xk) in b.iter_mut().zip(&x) {
            let d = (xk - m).abs();
            *bk = if d < *bk { d } else { *bk };
        }
    }
    nearest[..rows].copy_from_slice(&b[..rows]);
}

/// Whether a step's transition means can go to [`draw_block`]: none is NaN (else the
/// general kernel takes the step and reports the bad value).
pub(crate) fn means_usable(means: &[f64]) -> bool {
    !means.iter().any(|m| m.is_nan())
}

/// The largest log-densities of a block's rows and the distances they sit at, each
/// indexed by row (entries past the block's rows are 0).
pub(crate) struct RowMaxima {
    /// `max[k] = max_i log f(next_states[k] | mean_i)`.
    pub max: [f64; PATH_BLOCK],
    /// The distance from `next_states[k]` to the nearest mean.
    pub nearest: [f64; PATH_BLOCK],
}

/// For each `next_states[k]` of a block, its largest log-density from the nearest of
/// `means` (free of NaN, see [`means_usable`]), and that mean's distance; an error
/// names the row whose state is NaN or whose maximum is not finite.
#[inline(always)]
pub(crate) fn row_maxima(
    kernel: ScalarGaussianKernel,
    means: &[f64],
    next_states: &[f64],
    t: usize,
) -> Result<RowMaxima, SmcError> {
    let rows = next_states.len();
    debug_assert!(rows <= PATH_BLOCK, "a block has at most PATH_BLOCK paths");
    if let Some(k) = next_states.iter().position(|x| x.is_nan()) {
        return Err(backward_error(DrawFailure::Invalid, t, k));
    }
    let mut found = RowMaxima {
        max: [0.0; PATH_BLOCK],
        nearest: [0.0; PATH_BLOCK],
    };
    nearest_distances(means, next_states, &mut found.nearest[..rows]);
    for k in 0..rows {
        // the same number as the largest of the row's log-densities
        let row_max = kernel.log_density_at(found.nearest[k]);
        if row_max == f64::NEG_INFINITY {
            return Err(backward_error(DrawFailure::Degenerate, t, k));
        }
        if row_max.is_nan() || row_max == f64::INFINITY {
            return Err(backward_error(DrawFailure::Invalid, t, k));
        }
        found.max[k] = row_max;
    }
    Ok(found)
}

/// One backward step of a block among equally weighted candidates: for each
/// `next_states[k]`, draws a candidate with probability ∝ `f(next_states[k] | candidate)`
/// and writes `pick(candidate)` to `out[k]`. `means` are the candidates' transition
/// means (free of NaN, see [`means_usable`]). Each row proposes up to `trials` times,
/// then draws exactly: from its window when `buckets` holds the means sorted (see
/// [`super::window`]; `proposals` is scratch for it), else uniformly. `row` is scratch
/// for the exact draw.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn draw_block(
    kernel: ScalarGaussianKernel,
    means: &[f64],
    buckets: Option<&MeanBuckets>,
    proposals: &mut BlockProposals,
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
    // the candidates as the trials see them: sorted, or as given
    let candidates = buckets.map_or(means, MeanBuckets::sorted);
    let distinct = buckets.map_or(means, MeanBuckets::distinct);
    let RowMaxima { max, nearest } = row_maxima(kernel, distinct, next_states, t)?;
    let open = match buckets {
        Some(buckets) => {
            proposals.prepare(buckets, kernel, next_states, &nearest, &max, false);
            let proposals = &*proposals;
            draw_in_rounds(
                trials,
                rng,
                |k, u| proposals.propose(k, u),
                |k, pos| {
                    kernel.log_density(candidates[pos], next_states[k])
                        - proposals.log_bound(k, pos)
                },
                out,
            )
        }
        None => draw_in_rounds(
            trials,
            rng,
            |_, u| uniform_index(u, m),
            |k, i| kernel.log_density(candidates[i], next_states[k]) - max[k],
            out,
        ),
    };
    stats.trials += open.trials;
    stats.density_evaluations += rows as u64 + open.trials;
    for k in open.rows() {
        let next = next_states[k];
        stats.fallbacks += 1;
        stats.density_evaluations += m as u64;
        row.clear();
        row.extend(
            candidates
                .iter()
                .map(|&mean| kernel.log_density(mean, next)),
        );
        exp_shifted_sum(row, max[k]);
        out[k] = draw_from_weights(row, rng.random())
            .ok_or_else(|| backward_error(DrawFailure::Invalid, t, k))?;
    }
    // sorted positions back to candidates
    for slot in out.iter_mut() {
        *slot = pick(buckets.map_or(*slot, |b| b.candidate(*slot)));
    }
    Ok(())
}

/// The rejection trials of a block among weighted candidates: for each
/// `next_states[k]`, up to `trials` proposals from its window of `buckets` (the means
/// sorted, with the weights' running sums from [`MeanBuckets::cumulate_weights`];
/// `proposals` is scratch), each accepted with probability `f_i / g_i`, so that an
/// accepted candidate has probability ∝ `w_i f(next_states[k] | candidate i)`.
/// Writes the candidates (not sorted positions) to `out` and returns the rows left
/// open, for the caller's exact draw; an error names a row whose state is NaN or whose
/// largest density is not finite.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn draw_weighted_block(
    kernel: ScalarGaussianKernel,
    buckets: &MeanBuckets,
    proposals: &mut BlockProposals,
    next_states: &[f64],
    trials: usize,
    t: usize,
    out: &mut [usize],
    rng: &mut Rng,
) -> Result<OpenRows, SmcError> {
    let RowMaxima { max, nearest } = row_maxima(kernel, buckets.distinct(), next_states, t)?;
    proposals.prepare(buckets, kernel, next_states, &nearest, &max, true);
    let proposals = &*proposals;
    let (sorted, cumulative) = (buckets.sorted(), buckets.cumulative());
    let open = draw_in_rounds(
        trials,
        rng,
        |k, u| proposals.propose_weighted(k, u, cumulative),
        |k, pos| {
            // (a position of zero weight is proposed only by rounding)
            if cumulative[pos + 1] > cumulative[pos] {
                kernel.log_density(sorted[pos], next_states[k]) - proposals.log_bound(k, pos)
            } else {
                f64::NEG_INFINITY
            }
        },
        out,
    );
    // sorted positions back to candidates (the open rows' are the caller's to draw)
    for slot in out.iter_mut() {
        *slot = buckets.candidate(*slot);
    }
    Ok(open)
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

    /// Each row's draws, windowed or uniform, with a trial cap that sends some rows to
    /// the exact draw, land on the candidates with their exact probabilities
    /// `f_i / sum_j f_j` (within 4.5 binomial standard errors per candidate). The means
    /// put a group of candidates just outside a window and repeat some (as a resampled
    /// cloud does), so both parts of the envelope carry visible mass.
    #[test]
    fn block_draws_have_the_exact_probabilities() {
        let kernel = ScalarGaussianKernel::with_variance(0.01);
        let mut means = vec![0.0, 0.0, 0.0, -0.1];
        means.extend((0..20).map(|i| 0.30 + 0.015 * i as f64));
        means.extend([5.0; 10]);
        let m = means.len();
        let mut buckets = MeanBuckets::default();
        assert!(buckets.build(&means, kernel));
        let mut proposals = BlockProposals::default();
        let mut row = Vec::new();
        for windowed in [true, false] {
            for (x, trials) in [(0.0, 8), (0.0, 2), (0.45, 8), (2.5, 8), (5.02, 3)] {
                let next = [x; PATH_BLOCK];
                let mut counts = vec![0usize; m];
                let mut stats = SmootherStats::default();
                let blocks = 3000;
                for block in 0..blocks {
                    let mut out = [0usize; PATH_BLOCK];
                    draw_block(
                        kernel,
                        &means,
                        windowed.then_some(&buckets),
                        &mut proposals,
                        &next,
                        trials,
                        0,
                        &mut out,
                        |i| i,
                        &mut crate::stream(77, block),
                        &mut row,
                        &mut stats,
                    )
                    .unwrap();
                    for &i in &out {
                        counts[i] += 1;
                    }
                }
                let f: Vec<f64> = means
                    .iter()
                    .map(|&mu| kernel.log_density(mu, x).exp())
                    .collect();
                assert_frequencies(&counts, &f, &format!("windowed {windowed}, x {x}"));
                if (x, trials) == (0.0, 2) {
                    assert!(stats.fallbacks > 0, "{stats:?}");
                }
            }
        }
    }

    /// Each candidate's share of `counts` is its share of `target` (unnormalised)
    /// within 4.5 binomial standard errors.
    fn assert_frequencies(counts: &[usize], target: &[f64], label: &str) {
        let total: f64 = target.iter().sum();
        let draws = counts.iter().sum::<usize>() as f64;
        for (i, (&c, &t)) in counts.iter().zip(target).enumerate() {
            let p = t / total;
            let se = (p * (1.0 - p) / draws).sqrt();
            let freq = c as f64 / draws;
            assert!(
                (freq - p).abs() <= 4.5 * se + 1e-12,
                "{label}, candidate {i}: {freq} vs {p}"
            );
        }
    }

    /// Weighted block draws, the open rows drawn exactly here: each candidate with
    /// its probability `w_i f_i / sum_j w_j f_j`, within 4.5 binomial standard errors,
    /// zero weights never.
    #[test]
    fn weighted_block_draws_have_the_exact_probabilities() {
        let kernel = ScalarGaussianKernel::with_variance(0.01);
        let mut means = vec![0.0, 0.0, 0.0, -0.1];
        means.extend((0..20).map(|i| 0.33 + 0.015 * i as f64));
        means.extend([-0.33; 5]);
        means.extend([2.0; 10]);
        means.push(-1.0);
        let m = means.len();
        // (the 25 means just outside the window of a row at 0 (its edges at about
        // +-0.28, the buckets 0.0375 wide), on both sides, carry heavy weights, so
        // that its draws often land outside the window)
        let weights: Vec<f64> = (0..m)
            .map(|i| {
                let heavy = if (4..29).contains(&i) { 20.0 } else { 1.0 };
                heavy
                    * match i % 5 {
                        0 => 0.0,
                        1 => 3.0,
                        2 => 0.01,
                        _ => 1.0,
                    }
            })
            .collect();
        let mut buckets = MeanBuckets::default();
        assert!(buckets.build(&means, kernel));
        buckets.cumulate_weights(&weights);
        let mut proposals = BlockProposals::default();
        for (x, trials) in [(0.0, 8), (0.0, 2), (0.45, 8), (1.2, 8), (2.02, 3)] {
            let next = [x; PATH_BLOCK];
            let target: Vec<f64> = means
                .iter()
                .zip(&weights)
                .map(|(&mu, &w)| w * kernel.log_density(mu, x).exp())
                .collect();
            let mut counts = vec![0usize; m];
            let (mut fallbacks, blocks) = (0, 3000);
            for block in 0..blocks {
                let mut out = [0usize; PATH_BLOCK];
                let mut rng = crate::stream(78, block);
                let open = draw_weighted_block(
                    kernel,
                    &buckets,
                    &mut proposals,
                    &next,
                    trials,
                    0,
                    &mut out,
                    &mut rng,
                )
                .unwrap();
                for k in open.rows() {
                    fallbacks += 1;
                    out[k] = draw_from_weights(&target, rng.random()).unwrap();
                }
                for &i in &out {
                    counts[i] += 1;
                }
            }
            assert_frequencies(&counts, &target, &format!("x {x}"));
            if (x, trials) == (0.0, 2) {
                assert!(fallbacks > 0);
            }
        }
    }
}
