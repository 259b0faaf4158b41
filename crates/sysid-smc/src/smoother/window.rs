//! Windowed proposals for rejection draws among candidates with scalar Gaussian
//! transitions, equally weighted (Tanizaki's smoother) or weighted (rejection FFBSi).
//!
//! # Algorithm
//! The target of a row `x~` is `p_i ∝ f_i = N(x~; m_i, v)` over the candidates' means
//! `m_i`. A uniform proposal bounded by the row's largest density accepts
//! `sum_i f_i / (M max_j f_j)` of its trials, which is small when a few candidates
//! carry the row (a narrow transition among spread-out means). Here each step sorts
//! its means into [`MeanBuckets`] (a counting sort by equal-width buckets), and each
//! row takes the window of buckets that cover `[x~ - r, x~ + r]`, with
//! `r^2 = d^2 + 2 c v`, `d` the distance to the nearest mean and
//! `c` = [`WINDOW_LOG_RATIO`]. The envelope is
//!
//! ```text
//! g_i = max_j f_j                            inside the window,
//! g_i = min(max_j f_j, f at distance r')     outside it,
//! ```
//!
//! where `r'` is the distance from `x~` to the window's edges as rounded (a candidate
//! outside lies beyond an edge: the bucket of a number grows with it, also after
//! rounding, and so does the log-density's fall with the distance), so `g_i >= f_i`
//! for every candidate, bit for bit. A trial proposes `i ∝ g_i` from one uniform (the
//! window has mass `W`, each outside candidate `g_out / g_max`) and accepts it with
//! probability `f_i / g_i`. Outside candidates have at most `e^-c` of the largest
//! density, so a row needs about `(W + (M - W) e^-c) / sum_i (f_i / max_j f_j)` trials
//! instead of `M / sum_i (f_i / max_j f_j)`. On seed 000's benchmark (M = 50, v = 0.01)
//! that is about 2 trials per draw instead of 5 (truth) to 10 (a poor fit) without a
//! trial cap, and far fewer rows reach the exact fallback.
//!
//! Weighted candidates (target `p_i ∝ w_i f_i`) scale each envelope by the weight,
//! `w_i g_i`: the window's mass is its candidates' total weight, and a trial finds its
//! candidate by bisecting the running sums of the weights in sorted order
//! ([`BlockProposals::propose_weighted`]) instead of by one multiplication.
//!
//! Sorting and preparing the windows cost about as much as the trials they save when
//! most windows would hold every mean, so a step whose means lie within one window's
//! width keeps the uniform proposal ([`MeanBuckets::build`] tells which).
//!
//! # Complexity
//! O(M + B) per step for the buckets (B = 2M), plus O(M) for the running sums of
//! weights; O(1) per row for its window, and per trial O(1) (equal weights) or
//! O(log W) for a window of W candidates (weighted; O(log M) outside it).

use super::backward::PATH_BLOCK;
use crate::model::ScalarGaussianKernel;
use crate::vexp::exp_shifted_sum;

/// `c`: candidates outside a row's window have at most `e^-c` of the row's largest
/// density. On seed 000's benchmark (expected trials per draw computed from smoothed
/// paths at the truth and at a poor fit) 3-5 are equally good, about 1.9-2.1; 2 costs
/// 6-30 % more and 8 costs 14-16 % more.
pub(crate) const WINDOW_LOG_RATIO: f64 = 4.0;

/// Buckets per candidate.
const BUCKETS_PER_CANDIDATE: usize = 2;

/// The means of a step sorted by equal-width buckets over `[min, max]` (stably, so
/// the order depends only on the means).
#[derive(Debug, Default)]
pub(crate) struct MeanBuckets {
    low: f64,
    /// Buckets per unit of the means (0 when the means are all equal or not finite:
    /// then one bucket holds them all).
    scale: f64,
    last_bucket: usize,
    /// First sorted position of each bucket, and the count after the last.
    starts: Vec<u32>,
    /// The candidate (index into the means) at each sorted position.
    order: Vec<u32>,
    /// The means in sorted order.
    sorted: Vec<f64>,
    /// `sorted` without repeats of a value next to itself.
    distinct: Vec<f64>,
    /// The buckets of the means in their given order (scratch of the sort).
    scratch: Vec<u32>,
    /// Running sums of the candidates' weights in sorted order, when they are
    /// weighted: `cumulative[p]` sums the positions before `p` (`M + 1` entries).
    cumulative: Vec<f64>,
}

impl MeanBuckets {
    /// Sorts `means` (free of NaN, at most `u32::MAX` of them) into buckets when
    /// windows pay for their cost, that is when the means spread over more than the
    /// width `2 sqrt(2 c v)` of the narrowest window (`v` the kernel's variance);
    /// returns whether it did. (Otherwise most windows would hold every mean, and a
    /// uniform proposal bounded by the row maximum needs no sorting nor preparing: on
    /// seed 000's benchmark this choice made the smoother about 20 % faster than
    /// windows at every step.)
    #[inline(always)]
    pub fn build(&mut self, means: &[f64], kernel: ScalarGaussianKernel) -> bool {
        let m = means.len();
        // (plain comparisons: the means are free of NaN)
        let (mut low, mut high) = (f64::INFINITY, f64::NEG_INFINITY);
        for &x in means {
            low = if x < low { x } else { low };
            high = if x > high { x } else { high };
        }
        let spread = high - low;
        // (false without means, and for a NaN spread: all means at the same infinity)
        let wide = spread > 0.0 && spread * spread * kernel.half_inv_var > 4.0 * WINDOW_LOG_RATIO;
        if !wide {
            return false;
        }
        let buckets = (BUCKETS_PER_CANDIDATE * m).max(1);
        self.low = low;
        self.scale = if spread > 0.0 && spread.is_finite() {
            buckets as f64 / spread
        } else {
            0.0
        };
        self.last_bucket = buckets - 1;
        // each mean's bucket, then the counts of the buckets as running sums: `starts[b]`
        // is bucket `b`'s first sorted position
        let mut bucket_of = std::mem::take(&mut self.scratch);
        bucket_of.clear();
        bucket_of.extend(means.iter().map(|&x| self.bucket(x) as u32));
        self.starts.clear();
        self.starts.resize(buckets + 1, 0);
        for &b in &bucket_of {
            self.starts[b as usize + 1] += 1;
        }
        let mut total = 0;
        for start in &mut self.starts {
            total += *start;
            *start = total;
        }
        // scatter, stably, with `starts[b]` as bucket `b`'s next free position; after
        // it each holds the start of the next bucket: shift them back
        self.order.resize(m, 0);
        self.sorted.resize(m, 0.0);
        for (i, (&b, &x)) in bucket_of.iter().zip(means).enumerate() {
            let slot = &mut self.starts[b as usize];
            self.order[*slot as usize] = i as u32;
            self.sorted[*slot as usize] = x;
            *slot += 1;
        }
        self.starts.copy_within(0..buckets, 1);
        self.starts[0] = 0;
        self.scratch = bucket_of;
        // (copies of a particle are neighbours in the candidates' order, which the
        // stable sort keeps)
        self.distinct.clear();
        let mut last = None;
        for &x in &self.sorted {
            if last != Some(x) {
                self.distinct.push(x);
            }
            last = Some(x);
        }
        true
    }

    /// The bucket of `x`: non-decreasing in `x`, also after rounding (a difference, a
    /// product with a non-negative scale and [`index_at`]).
    #[inline(always)]
    fn bucket(&self, x: f64) -> usize {
        index_at((x - self.low) * self.scale, self.last_bucket)
    }

    /// Sums the candidates' `weights` (non-negative, finite; one per mean) in sorted
    /// order, for [`BlockProposals::propose_weighted`].
    #[inline(always)]
    pub fn cumulate_weights(&mut self, weights: &[f64]) {
        self.cumulative.clear();
        self.cumulative.push(0.0);
        let mut total = 0.0;
        for &i in &self.order {
            total += weights[i as usize];
            self.cumulative.push(total);
        }
    }

    /// The running sums of [`MeanBuckets::cumulate_weights`].
    #[inline(always)]
    pub fn cumulative(&self) -> &[f64] {
        &self.cumulative
    }

    /// The means in sorted order.
    #[inline(always)]
    pub fn sorted(&self) -> &[f64] {
        &self.sorted
    }

    /// The means in sorted order without adjacent repeats: the same set of values.
    #[inline(always)]
    pub fn distinct(&self) -> &[f64] {
        &self.distinct
    }

    /// The candidate at sorted position `pos`.
    #[inline(always)]
    pub fn candidate(&self, pos: usize) -> usize {
        self.order[pos] as usize
    }
}

/// `floor(x)` clamped to `[0, last]`, and 0 for NaN: non-decreasing in `x`.
#[inline(always)]
fn index_at(x: f64, last: usize) -> usize {
    let cap = last as f64;
    let low = if x > 0.0 { x } else { 0.0 };
    let clamped = if low < cap { low } else { cap };
    // SAFETY: `clamped` is finite and in [0, last], which a usize holds
    unsafe { clamped.to_int_unchecked::<usize>() }
}

/// The proposals `i ∝ g_i` of a block's rows (see the module's algorithm), prepared
/// for their trials; one array per field, so that preparing them vectorises.
#[derive(Debug)]
pub(crate) struct BlockProposals {
    /// Each row's window: sorted positions `[first, first + width)`.
    first: [usize; PATH_BLOCK],
    width: [usize; PATH_BLOCK],
    /// `M - W`.
    outside: [usize; PATH_BLOCK],
    /// The window's share of the proposal before scaling by `g_max`: its width, or
    /// its candidates' total weight when they are weighted.
    inside_mass: [f64; PATH_BLOCK],
    /// The inside mass plus the outside one times `g_out / g_max`.
    total_mass: [f64; PATH_BLOCK],
    /// `g_max / g_out` (infinite when `g_out` underflows).
    inverse_outside_mass: [f64; PATH_BLOCK],
    /// `log g_max` and `log g_out`.
    log_bound_inside: [f64; PATH_BLOCK],
    log_bound_outside: [f64; PATH_BLOCK],
}

impl Default for BlockProposals {
    fn default() -> Self {
        BlockProposals {
            first: [0; PATH_BLOCK],
            width: [0; PATH_BLOCK],
            outside: [0; PATH_BLOCK],
            inside_mass: [0.0; PATH_BLOCK],
            total_mass: [0.0; PATH_BLOCK],
            inverse_outside_mass: [0.0; PATH_BLOCK],
            log_bound_inside: [0.0; PATH_BLOCK],
            log_bound_outside: [0.0; PATH_BLOCK],
        }
    }
}

impl BlockProposals {
    /// Prepares the proposals of the rows `next_states` (at most [`PATH_BLOCK`]) with
    /// their largest log-densities `row_max` at the nearest distances `nearest`: each
    /// row's window covers `[x - r, x + r]`, `r = sqrt(nearest^2 + 2 c v)`. With
    /// `weighted`, each candidate's envelope is scaled by its weight (summed by
    /// [`MeanBuckets::cumulate_weights`]), for [`BlockProposals::propose_weighted`].
    ///
    /// A candidate outside lies in a bucket before that of `x - r` (so below `x - r`,
    /// the bucket growing with the number, also after rounding, and its residual
    /// `x - m` rounds to at least `x - (x - r)`), or after that of `x + r` (likewise):
    /// its log-density is at most the kernel's at the smaller of the two rounded
    /// distances, bit for bit.
    #[inline(always)]
    pub fn prepare(
        &mut self,
        buckets: &MeanBuckets,
        kernel: ScalarGaussianKernel,
        next_states: &[f64],
        nearest: &[f64],
        row_max: &[f64],
        weighted: bool,
    ) {
        let m = buckets.sorted.len();
        let rows = next_states.len();
        let (nearest, row_max) = (&nearest[..rows], &row_max[..rows]);
        let least_radius_squared = WINDOW_LOG_RATIO / kernel.half_inv_var;
        // the buckets of the edges and the bound outside, in one pass
        let (mut low_bucket, mut high_bucket) = ([0; PATH_BLOCK], [0; PATH_BLOCK]);
        let mut ratio = [0.0; PATH_BLOCK];
        for k in 0..rows {
            let (x, max) = (next_states[k], row_max[k]);
            let radius = (nearest[k] * nearest[k] + least_radius_squared).sqrt();
            let (below, above) = (x - radius, x + radius);
            low_bucket[k] = buckets.bucket(below);
            high_bucket[k] = buckets.bucket(above) + 1;
            let (from_below, from_above) = (x - below, above - x);
            let edge = if from_below < from_above {
                from_below
            } else {
                from_above
            };
            let at_edge = kernel.log_density_at(edge);
            let bound = if at_edge < max { at_edge } else { max };
            self.log_bound_inside[k] = max;
            self.log_bound_outside[k] = bound;
            ratio[k] = bound - max;
        }
        for k in 0..rows {
            let first = buckets.starts[low_bucket[k]] as usize;
            let width = buckets.starts[high_bucket[k]] as usize - first;
            self.first[k] = first;
            self.width[k] = width;
            self.outside[k] = m - width;
        }
        exp_shifted_sum(&mut ratio[..rows], 0.0);
        for (k, &r) in ratio[..rows].iter().enumerate() {
            let (inside, outside) = if weighted {
                let cumulative = &buckets.cumulative;
                let (first, width) = (self.first[k], self.width[k]);
                let inside = cumulative[first + width] - cumulative[first];
                (inside, (cumulative[m] - inside).max(0.0))
            } else {
                (self.width[k] as f64, self.outside[k] as f64)
            };
            self.inside_mass[k] = inside;
            self.total_mass[k] = inside + outside * r;
            self.inverse_outside_mass[k] = 1.0 / r;
            if self.total_mass[k].is_nan() || self.total_mass[k] <= 0.0 {
                // no proposal at all (a window of zero weights, the outside
                // underflowing): every trial is rejected, for the exact draw
                self.log_bound_inside[k] = f64::INFINITY;
                self.log_bound_outside[k] = f64::INFINITY;
            }
        }
    }

    /// Row `k`'s sorted position proposed by a uniform in [0, 1): the window's
    /// positions each with mass 1, the others each with mass `g_out / g_max`.
    #[inline(always)]
    pub fn propose(&self, k: usize, uniform: f64) -> usize {
        let z = uniform * self.total_mass[k];
        let (first, width, outside) = (self.first[k], self.width[k], self.outside[k]);
        let width_mass = width as f64;
        // both candidates, then a select: which one applies is a coin toss
        let inside = first + index_at(z, width.saturating_sub(1));
        // (a NaN from 0 * inf, at an edge of probability ~2^-53, gives 0)
        let j = index_at(
            (z - width_mass) * self.inverse_outside_mass[k],
            outside.saturating_sub(1),
        );
        let beyond = j + if j < first { 0 } else { width };
        std::hint::select_unpredictable(z < width_mass || outside == 0, inside, beyond)
    }

    /// Row `k`'s sorted position proposed by a uniform in [0, 1) among weighted
    /// candidates (`cumulative`, their running sums from
    /// [`MeanBuckets::cumulative`]): the window's positions each with their weight,
    /// the others each with their weight times `g_out / g_max`.
    #[inline(always)]
    pub fn propose_weighted(&self, k: usize, uniform: f64, cumulative: &[f64]) -> usize {
        let z = uniform * self.total_mass[k];
        let (first, width) = (self.first[k], self.width[k]);
        let inside_mass = self.inside_mass[k];
        let below = cumulative[first];
        // a running sum to find, and the positions to look among
        let (sum, low, high) = if z < inside_mass {
            (below + z, first, first + width)
        } else {
            // (a NaN from 0 * inf, at an edge of probability ~2^-53, gives `low`)
            let beyond = (z - inside_mass) * self.inverse_outside_mass[k];
            let sum = if beyond < below {
                beyond
            } else {
                beyond + inside_mass
            };
            (sum, 0, cumulative.len() - 1)
        };
        // the last position at or below the sum (the one whose weight spans it), by a
        // branch-free bisection
        let (mut pos, mut len) = (low, high - low);
        while len > 1 {
            let half = len / 2;
            pos = std::hint::select_unpredictable(cumulative[pos + half] <= sum, pos + half, pos);
            len -= half;
        }
        pos
    }

    /// Row `k`'s log-envelope at sorted position `pos`: `log g_max` inside its window,
    /// `log g_out` outside.
    #[inline(always)]
    pub fn log_bound(&self, k: usize, pos: usize) -> f64 {
        let inside = pos.wrapping_sub(self.first[k]) < self.width[k];
        if inside {
            self.log_bound_inside[k]
        } else {
            self.log_bound_outside[k]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn means() -> Vec<f64> {
        (0..53)
            .map(|i| ((i * 7919) % 101) as f64 * 0.0317 - 1.3 + if i % 9 == 0 { 20.0 } else { 0.0 })
            .collect()
    }

    #[test]
    fn buckets_sort_the_means_stably_by_bucket() {
        let means = means();
        let mut buckets = MeanBuckets::default();
        assert!(buckets.build(&means, ScalarGaussianKernel::with_variance(0.01)));
        let m = means.len();
        let mut seen = vec![false; m];
        for pos in 0..m {
            let i = buckets.candidate(pos);
            assert!(!seen[i]);
            seen[i] = true;
            assert_eq!(buckets.sorted()[pos], means[i]);
            if pos > 0 {
                let j = buckets.candidate(pos - 1);
                let (bj, bi) = (buckets.bucket(means[j]), buckets.bucket(means[i]));
                assert!(
                    bj < bi || (bj == bi && j < i),
                    "positions {} and {pos}",
                    pos - 1
                );
            }
        }
        for b in 0..=buckets.last_bucket {
            let (s, e) = (buckets.starts[b] as usize, buckets.starts[b + 1] as usize);
            assert!((s..e).all(|p| buckets.bucket(buckets.sorted()[p]) == b));
        }
        assert_eq!(buckets.starts[buckets.last_bucket + 1] as usize, m);
    }

    /// The window of one row `x` with the given `nearest` distance (which sets the
    /// radius) and row maximum: `(first, width, log bound outside)`.
    fn window(
        buckets: &MeanBuckets,
        kernel: ScalarGaussianKernel,
        x: f64,
        nearest: f64,
        row_max: f64,
    ) -> (usize, usize, f64) {
        let mut p = BlockProposals::default();
        p.prepare(buckets, kernel, &[x], &[nearest], &[row_max], false);
        (p.first[0], p.width[0], p.log_bound_outside[0])
    }

    #[test]
    fn means_closer_than_a_window_are_not_sorted_and_infinite_ones_share_a_bucket() {
        let mut buckets = MeanBuckets::default();
        let kernel = ScalarGaussianKernel::with_variance(1e-4);
        // (the narrowest window is 2 sqrt(8e-4) = 0.0566 wide)
        assert!(!buckets.build(&[2.0; 5], kernel));
        assert!(!buckets.build(&[], kernel));
        assert!(!buckets.build(&[2.0, 2.02, 2.056], kernel));
        assert!(buckets.build(&[2.0, 2.02, 2.057], kernel));
        let means = [1.0, f64::INFINITY, -3.0];
        assert!(buckets.build(&means, kernel));
        let (first, width, _) = window(&buckets, kernel, 0.0, 0.0, 0.0);
        assert_eq!((first, width), (0, means.len()));
    }

    /// Every candidate outside a row's window has a log-density at most the window's
    /// outside bound, and the window holds every candidate within the radius.
    #[test]
    fn the_outside_bound_holds_for_every_candidate() {
        let means = means();
        let mut buckets = MeanBuckets::default();
        let mut partial = 0;
        for variance in [0.0137, 1e-6] {
            let kernel = ScalarGaussianKernel::with_variance(variance);
            assert!(buckets.build(&means, kernel));
            let spread = WINDOW_LOG_RATIO / kernel.half_inv_var;
            for j in 0..2000 {
                let x = j as f64 * 0.0131 - 3.0;
                let nearest = means
                    .iter()
                    .map(|m| (x - m).abs())
                    .fold(f64::INFINITY, f64::min);
                let row_max = kernel.log_density_at(nearest);
                // (the distance passed sets the radius: the true one and larger ones)
                for distance in [nearest, nearest + 0.05, nearest + 0.3, 40.0] {
                    let radius = (distance * distance + spread).sqrt();
                    let (first, width, bound) = window(&buckets, kernel, x, distance, row_max);
                    assert!(bound <= row_max);
                    partial += usize::from(width > 0 && width < means.len());
                    for (pos, &mean) in buckets.sorted().iter().enumerate() {
                        let l = kernel.log_density(mean, x);
                        let inside = pos >= first && pos < first + width;
                        if !inside {
                            assert!(l <= bound, "x {x}, radius {radius}, pos {pos}");
                        }
                        if (x - mean).abs() < radius * (1.0 - 1e-12) {
                            assert!(inside, "x {x}, radius {radius}, pos {pos}");
                        }
                    }
                }
            }
        }
        assert!(
            partial > 4000,
            "windows that hold only some of the means: {partial}"
        );
    }

    /// The proposals of `rows` among `means` (sorted in `buckets`), with the rows'
    /// nearest distances and maxima by a plain scan.
    fn prepared(
        buckets: &MeanBuckets,
        kernel: ScalarGaussianKernel,
        means: &[f64],
        rows: &[f64],
        weighted: bool,
    ) -> (BlockProposals, Vec<f64>, Vec<f64>) {
        let nearest: Vec<f64> = rows
            .iter()
            .map(|x| {
                means
                    .iter()
                    .map(|m| (x - m).abs())
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        let row_max: Vec<f64> = nearest.iter().map(|&d| kernel.log_density_at(d)).collect();
        let mut p = BlockProposals::default();
        p.prepare(buckets, kernel, rows, &nearest, &row_max, weighted);
        (p, nearest, row_max)
    }

    /// The proposal gives each window position mass 1 and each other position the
    /// outside ratio: a fine grid of uniforms lands on them in those proportions.
    #[test]
    fn proposals_follow_the_envelope() {
        let kernel = ScalarGaussianKernel::with_variance(0.01);
        let means: Vec<f64> = (0..11).map(|i| i as f64 * 0.1).collect();
        let mut buckets = MeanBuckets::default();
        assert!(buckets.build(&means, kernel));
        // rows at, between and beyond the means; one far off, where the window holds
        // every mean, and one whose outside mass underflows
        let rows = [0.0, 0.43, 1.0, 0.5, -3.0, 0.2];
        let (mut p, _, _) = prepared(&buckets, kernel, &means, &rows, false);
        // (an underflowing outside mass for the last row)
        p.log_bound_outside[5] = -2000.0;
        p.total_mass[5] = p.width[5] as f64;
        p.inverse_outside_mass[5] = f64::INFINITY;
        let mut partial = 0;
        for (k, &x) in rows.iter().enumerate() {
            let ratio = (p.log_bound_outside[k] - p.log_bound_inside[k]).exp();
            let width = p.width[k];
            partial += usize::from(width > 0 && width < means.len());
            let n = 1_000_000;
            let mut counts = vec![0usize; means.len()];
            for j in 0..n {
                counts[p.propose(k, (j as f64 + 0.5) / n as f64)] += 1;
            }
            let total = width as f64 + (means.len() - width) as f64 * ratio;
            for (pos, &c) in counts.iter().enumerate() {
                let inside = pos >= p.first[k] && pos < p.first[k] + width;
                let bound = [p.log_bound_outside[k], p.log_bound_inside[k]][usize::from(inside)];
                assert_eq!(p.log_bound(k, pos), bound);
                let expected = if inside { 1.0 } else { ratio } / total;
                let freq = c as f64 / n as f64;
                assert!(
                    (freq - expected).abs() < 2.0 / n as f64,
                    "row {x}, pos {pos}: {freq} vs {expected}"
                );
            }
            assert!(p.propose(k, 1.0 - f64::EPSILON / 2.0) < means.len());
        }
        assert!(partial >= 3, "windows that hold some of the means");
    }

    /// Weighted candidates: each window position is proposed with its weight, each
    /// other with its weight times the outside ratio, zero weights never; a window
    /// whose weights are all zero proposes outside it only.
    #[test]
    fn weighted_proposals_follow_the_envelope() {
        let kernel = ScalarGaussianKernel::with_variance(0.01);
        // (listed out of order, so that sorted positions differ from candidates)
        let means: Vec<f64> = (0..13).map(|i| ((i * 5) % 13) as f64 * 0.1).collect();
        let weights: Vec<f64> = (0..13)
            .map(|i| {
                if i % 4 == 1 {
                    0.0
                } else {
                    1.0 + (i % 3) as f64
                }
            })
            .collect();
        let mut buckets = MeanBuckets::default();
        assert!(buckets.build(&means, kernel));
        buckets.cumulate_weights(&weights);
        let sorted_weights: Vec<f64> = (0..means.len())
            .map(|pos| weights[buckets.candidate(pos)])
            .collect();
        let rows = [0.0, 0.43, 1.2, 0.6, -3.0];
        let (mut p, nearest, row_max) = prepared(&buckets, kernel, &means, &rows, true);
        let mut partial = 0;
        for (k, &x) in rows.iter().enumerate() {
            let ratio = (p.log_bound_outside[k] - p.log_bound_inside[k]).exp();
            let (first, width) = (p.first[k], p.width[k]);
            partial += usize::from(width > 0 && width < means.len());
            let inside = |pos: usize| pos >= first && pos < first + width;
            let envelope = |pos: usize| sorted_weights[pos] * if inside(pos) { 1.0 } else { ratio };
            let total: f64 = (0..means.len()).map(envelope).sum();
            let n = 1_000_000;
            let mut counts = vec![0usize; means.len()];
            for j in 0..n {
                let u = (j as f64 + 0.5) / n as f64;
                counts[p.propose_weighted(k, u, buckets.cumulative())] += 1;
            }
            for (pos, &c) in counts.iter().enumerate() {
                let (freq, expected) = (c as f64 / n as f64, envelope(pos) / total);
                assert!(
                    (freq - expected).abs() < 2.0 / n as f64,
                    "row {x}, pos {pos}: {freq} vs {expected}"
                );
            }
        }
        assert!(partial >= 3, "windows that hold some of the means");
        // zero weights throughout the first row's window
        let mut zero_inside = weights.clone();
        for pos in p.first[0]..p.first[0] + p.width[0] {
            zero_inside[buckets.candidate(pos)] = 0.0;
        }
        buckets.cumulate_weights(&zero_inside);
        p.prepare(&buckets, kernel, &rows[..1], &nearest, &row_max, true);
        assert!(p.total_mass[0] > 0.0);
        for j in 0..1000 {
            let pos = p.propose_weighted(0, (j as f64 + 0.5) / 1000.0, buckets.cumulative());
            assert!(zero_inside[buckets.candidate(pos)] > 0.0, "pos {pos}");
        }
    }
}
